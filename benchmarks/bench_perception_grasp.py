"""Grasps planned from the camera against grasps planned from the truth.

For every grasp class's object of ``handle_drake.apps.planning.cli.CLASS_OBJECTS``
(cuboids and spheres, the kinds the planner grasps upright), at ``--poses``
seeded table poses each (anywhere within 10 cm of the table's centre, any
yaw): the tabletop Kinect (``diagrams/tabletop_perception.yaml``) perceives
the object, and the class's grasp is planned twice, on the true pose and size
and on the perceived ones; each plan is executed open loop and reactively on
the true object. Success = held through the 13 cm lift.

Run: ``python benchmarks/bench_perception_grasp.py [--poses 3] [--workers 2]
[--executor local|dask|dask://HOST:PORT]`` (the cases run where ``--executor`` says:
``handle_drake.learning.cluster``); prints the pose errors and a success table and writes
``benchmarks/results/perception_grasp.json``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning.cluster import add_executor_arguments, trial_executor  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "perception_grasp.json"


def trial(case):
    grasp_class, kind, size, x, y, yaw, seed = case
    from pydrake.common.schema import Transform

    from handle_drake.apps.perception.grasping import perceive_object
    from handle_drake.apps.planning.execution import run_plan
    from handle_drake.grasp.planning import plan_grasp, resting_pose
    from handle_drake.scenario import ObjectConfig
    from handle_drake.trial.simulate import held_through_lift

    out = dict(grasp_class=grasp_class, kind=kind, size=size, x=x, y=y, yaw=yaw)
    X_WO_true = resting_pose(kind, size, (x, y), yaw)
    truth = ObjectConfig(kind=kind, size=size, X_WO=Transform(X_WO_true), on_table=False)
    sources = {"truth": (size, X_WO_true)}
    try:
        perceived = perceive_object(kind, size, xy=(x, y), yaw=yaw, seed=seed)
        out["errors"] = perceived.errors()
        sources["perceived"] = (perceived.size, perceived.X_WO)
    except ValueError as error:  # not seen: a failed grasp from perception
        out["errors"] = None
        out["perceived"] = {"planned": False, "error": str(error)[:120],
                            "open_loop": False, "reactive": False}
    for source, (plan_size, X_WO) in sources.items():
        try:
            plan = plan_grasp(grasp_class, (kind, plan_size), X_WO)
        except ValueError as error:
            out[source] = {"planned": False, "error": str(error)[:120],
                           "open_loop": False, "reactive": False}
            continue
        out[source] = {"planned": True}
        for mode, reactive in (("open_loop", False), ("reactive", True)):
            result = run_plan(plan, reactive=reactive, world_object=truth)
            out[source][mode] = held_through_lift(result)
    return out


def main(argv=None) -> int:
    from handle_drake.apps.planning.cli import CLASS_OBJECTS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    add_executor_arguments(parser)
    add_page_arguments(parser, "perception", published={"poses": 3})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Grasps planned from perception against the true pose", args)
    rng = np.random.default_rng(args.seed)
    cases = []
    for grasp_class, (kind, size) in CLASS_OBJECTS.items():
        if kind not in ("cuboid", "sphere"):
            continue
        for _ in range(args.poses):
            r, a = 0.10 * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
            cases.append((grasp_class, kind, size, r * math.cos(a), r * math.sin(a),
                          float(rng.uniform(-math.pi, math.pi)), int(rng.integers(1 << 30))))
    rows = []
    with trial_executor(args.executor, args.workers,
                        connect_timeout=args.connect_timeout) as pool:
        for i, row in enumerate(pool.map(trial, cases)):
            rows.append(row)
            print(f"[{i + 1}/{len(cases)}] {row['grasp_class']} done", flush=True)
    print(f"{'class':20s} {'kind':7s} {'xy mm':>6s} {'z mm':>6s} {'yaw deg':>7s} "
          f"{'size mm':>7s}  truth open/react  perceived open/react")
    counts = {(s, m): 0 for s in ("truth", "perceived") for m in ("open_loop", "reactive")}
    for row in rows:
        e = row["errors"] or {"xy_mm": float("nan"), "z_mm": float("nan"), "yaw_deg": None,
                              "size_mm": float("nan")}
        yaw = "-" if e["yaw_deg"] is None else f"{e['yaw_deg']:+.1f}"
        flags = []
        for source in ("truth", "perceived"):
            for mode in ("open_loop", "reactive"):
                held = bool(row[source][mode])
                counts[source, mode] += held
                flags.append("H" if held else ".")
        print(f"{row['grasp_class']:20s} {row['kind']:7s} {e['xy_mm']:6.1f} {e['z_mm']:+6.1f} "
              f"{yaw:>7s} {e['size_mm']:+7.1f}  {flags[0]:>5s}/{flags[1]:<6s} "
              f"{flags[2]:>9s}/{flags[3]}")
    n = len(rows)
    seen = [r["errors"] for r in rows if r["errors"] is not None]
    missed = sorted({f"{r['grasp_class']} ({r['kind']} {r['size'] * 100:.1f} cm)"
                     for r in rows if r["errors"] is None})
    print(f"\nobjects detected: {len(seen)}/{n}; not seen: {', '.join(missed) or 'none'}")
    xy = [e["xy_mm"] for e in seen]
    yaws = [abs(e["yaw_deg"]) for e in seen if e["yaw_deg"] is not None]
    print(f"\npose error: xy median {np.median(xy):.1f} mm (max {np.max(xy):.1f}); "
          f"|yaw| median {np.median(yaws) if yaws else float('nan'):.1f} deg")
    for (source, mode), held in counts.items():
        print(f"held, planned from {source:9s} {mode:9s}: {held}/{n}")
    gap = counts["truth", "open_loop"] - counts["perceived", "open_loop"]
    recovered = counts["perceived", "reactive"] - counts["perceived", "open_loop"]
    print(f"gap truth -> perception (open loop): {gap}; recovered by the reactive approach: "
          f"{recovered}")
    results_run.finish(
        [{"grasp_class": r["grasp_class"], "kind": r["kind"], **(r["errors"] or {}),
          **{f"{s} {m}": bool(r[s][m]) for s in ("truth", "perceived")
             for m in ("open_loop", "reactive")}} for r in rows],
        {"rows": rows, "counts": {f"{s}/{m}": v for (s, m), v in counts.items()}}, RESULTS)
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
