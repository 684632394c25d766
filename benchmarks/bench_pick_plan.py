"""Pick planning time per pick, as a ratio to a floor measured in the same run, and the
arm's IK solves each plan made (issue 49 item 2: planning <= 2 s per pick including any
search, never past its own budget).

Each ``--scenes`` entry is planned (``handle_drake.apps.pick.cli.pick(execute=False)``:
perceive, build the arm's reach model, plan; not simulated):
``hamburg:SEEDS`` the Hamburg table's scenes (``random_scene``, spheres and cuboids) from
perception; ``sorter:SEEDS`` the shape sorter's (``diagrams/sorter_setup.yaml``, every
kind), each kind of the scene from the true poses; ``sizes:SEEDS`` the Hamburg scenes'
nearest cuboid at off-catalogue sizes (``--sizes``, cm: the grasp database has 6 cm),
from the true poses. ``eval`` stands for the held-out block (``EVALUATION_SEEDS`` on the
Hamburg table, ``SORTER_SEEDS`` on the sorter); development seeds otherwise.

The floor: one arm IK solve of a reachable pose (the hand where the arm's joints put it
0.1 rad from the start, solved from the start configuration; the kinematic and the
collision stage), timed ``FLOOR_REPEATS`` times before each plan and the median of all
taken. The plan's wall time (the plan phase less the arm's collision model of the
scene, ``ArmReach``, built once per scene and reported apart) is reported in seconds
and as a ratio to the floor; the IK solves (``PickPlan.ik_solves``, a path
search counted as 20) do not depend on the machine.

Run: python benchmarks/bench_pick_plan.py [--scenes hamburg:0-19,sorter:600-619]
     [--sizes 5.35,6.55,7.0] [--out out/bench]; the published table (docs/results/pick.md):
     ``--scenes sizes:eval,sorter:eval,hamburg:eval``.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import os
from pathlib import Path

import numpy as np

from handle_drake.base.results import ResultsRun, add_page_arguments

ROOT = Path(__file__).resolve().parents[1]
FLOOR_REPEATS = 5
#: The published table's scenes: the held-out blocks (nothing tuned on them).
PUBLISHED = "sizes:eval,sorter:eval,hamburg:eval"


def _seeds(table: str, text: str) -> list[int]:
    from handle_drake.apps.pick.scenes import EVALUATION_SEEDS, SORTER_SEEDS

    if text == "eval":
        return list(SORTER_SEEDS if table == "sorter" else EVALUATION_SEEDS)
    out = []
    for part in text.split(";"):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def parse_scenes(text: str) -> list[tuple[str, list[int]]]:
    """``TABLE:SEEDS,...`` (TABLE one of hamburg, sorter, sizes; SEEDS ``A-B``, ``A;B``
    or ``eval``); ValueError naming ``--scenes``."""
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        table, _, seeds = item.partition(":")
        if table not in ("hamburg", "sorter", "sizes") or not seeds:
            raise ValueError(f"--scenes: expected TABLE:SEEDS with TABLE hamburg, sorter or "
                             f"sizes, got {item!r}")
        try:
            out.append((table, _seeds(table, seeds)))
        except ValueError:
            raise ValueError(f"--scenes: {item!r}: seeds must be A-B, A;B or eval") from None
    return out


def floor_seconds(scenario) -> float:
    """The median time of one arm IK solve of a reachable pose (see the module doc)."""
    from handle_drake.apps.pick.reach import ArmReach

    reach = ArmReach(scenario)
    q0 = np.asarray(scenario.hand.mount.initial_position or np.zeros(6), dtype=float)
    q_hand = np.zeros(len(reach.hand_spec.joint_names))
    X = reach.hand_pose(q0 + 0.1, q_hand)
    times = []
    for _ in range(FLOOR_REPEATS):
        result = reach.solve(X, q0, q_hand)
        if not result.ok:
            raise RuntimeError("the floor's IK pose was not reached")
        times.append(result.seconds)
    return float(np.median(times))


def _plans(table: str, seeds, sizes):
    """``(label, scenario, pick keyword arguments)`` of each plan of a --scenes entry."""
    from handle_drake.apps.pick.scenes import SORTER_KINDS, random_scene
    from handle_drake.scenario import LoadScenario

    setup = "sorter_setup.yaml" if table == "sorter" else "hamburg_setup.yaml"
    base = LoadScenario(filename=ROOT / "diagrams" / setup)
    for seed in seeds:
        if table == "sorter":
            scene = random_scene(base, seed, SORTER_KINDS)
            for kind in dict.fromkeys(o.kind for o in [scene.object, *scene.objects]):
                yield f"sorter {seed} {kind}", scene, dict(true_poses=True, kind=kind)
        elif table == "hamburg":
            yield f"hamburg {seed}", random_scene(base, seed), dict(true_poses=False)
        else:
            scene = random_scene(base, seed)
            objects = [scene.object, *scene.objects]
            for size in sizes:
                resized = [dc.replace(o, size=size / 100) if o.kind == "cuboid" else o
                           for o in objects]
                yield (f"sizes {seed} {size} cm", dc.replace(scene, object=resized[0],
                                                            objects=resized[1:]),
                       dict(true_poses=True, kind="cuboid"))


def main(argv=None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="hamburg:0-19,sorter:600-619,sizes:0-9")
    parser.add_argument("--sizes", default="5.35,6.55,7.0",
                        help="cuboid sizes (cm) of the sizes: scenes")
    parser.add_argument("--out", default="out/bench")
    add_page_arguments(parser, "pick", published={"scenes": PUBLISHED})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Pick planning time per pick: ratio to an IK solve, IK solves",
                             args)
    try:
        scenes = parse_scenes(args.scenes)
        sizes = [float(s) for s in args.sizes.split(",")]
    except ValueError as error:
        parser.error(str(error))

    from handle_drake.apps.pick.cli import pick
    from handle_drake.apps.pick.plan import PLAN_IK_BUDGET, default_grasp_database
    from handle_drake.scenario import LoadScenario

    default_grasp_database()
    floor_scenario = LoadScenario(filename=ROOT / "diagrams" / "hamburg_setup.yaml")
    rows, floors = [], []
    for table, seeds in scenes:
        for label, scene, kwargs in _plans(table, seeds, sizes):
            floors.append(floor_seconds(floor_scenario))
            result = pick(scene, execute=False, **kwargs)
            phase = [p for p in result["phases"] if p["phase"] == "plan"]
            if not phase:
                continue  # nothing pickable seen: no plan made
            model = result.get("reach_model_s", 0.0)
            row = dict(label=label, table=table, kind=result.get("kind"),
                       plan_s=phase[0]["wall_s"] - model, model_s=model,
                       ik_solves=result.get("ik_solves"),
                       planned="grasp_class" in result, source=result.get("grasp_source"),
                       outcome=result["outcome"][:160], load=os.getloadavg()[0])
            rows.append(row)
            print(f"{label:28s} {row['plan_s']:6.2f} s (model {model:4.2f} s)  "
                  f"IK {row['ik_solves']}  "
                  f"{row['source']}  {row['outcome'][:60]}", flush=True)
    floor = float(np.median(floors))
    print(f"\nfloor (one arm IK solve): median {1000 * floor:.1f} ms over {len(floors)} "
          f"x {FLOOR_REPEATS}; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("plans                    n  median s  p90 s  max s  <=2 s  median/floor  "
          "max/floor  IK median  IK max  IK budget")
    groups = {"all": rows}
    for r in rows:
        groups.setdefault(r["table"] + (" planned" if r["planned"] else " no pick"),
                          []).append(r)
    summary = {}
    for name, mine in groups.items():
        if not mine:
            continue
        t = np.array([r["plan_s"] for r in mine])
        ik = [r["ik_solves"] for r in mine if r["ik_solves"] is not None]
        summary[name] = dict(n=len(mine), median_s=float(np.median(t)),
                             p90_s=float(np.percentile(t, 90)), max_s=float(t.max()),
                             at_most_2s=int((t <= 2.0).sum()),
                             median_ratio=float(np.median(t) / floor),
                             p90_ratio=float(np.percentile(t, 90) / floor),
                             max_ratio=float(t.max() / floor),
                             model_median_s=float(np.median([r["model_s"] for r in mine])),
                             ik_median=float(np.median(ik)) if ik else None,
                             ik_max=int(max(ik)) if ik else None)
        s = summary[name]
        print(f"{name:22s} {s['n']:3d}  {s['median_s']:8.2f} {s['p90_s']:6.2f} "
              f"{s['max_s']:6.2f} {s['at_most_2s']:4d}/{s['n']:<3d} {s['median_ratio']:10.0f} "
              f"{s['max_ratio']:10.0f}  {s['ik_median']}  {s['ik_max']}  {PLAN_IK_BUDGET}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "pick_plan_ratio.json"
    table = [dict(plans=name, **{k: (round(v, 2) if isinstance(v, float) else v)
                                 for k, v in s.items()}) for name, s in summary.items()]
    results_run.finish(table, {"floor_s": floor, "floors": floors, "summary": summary,
                               "rows": rows}, path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
