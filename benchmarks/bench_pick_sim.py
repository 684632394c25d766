"""Simulation speed of pick runs, side by side (issue 33): each seeded Hamburg scene's
true-pose pick (:func:`handle_drake.apps.pick.cli.pick`'s plan) is simulated in one
process once per mode, next to the floor (the station with the arm and hand alone, 1 s)
measured just before. Modes: ``every`` (every collision pair simulated,
``execute_pick``'s default), ``filtered`` (``filter_contacts=True``: the pairs of
``filter_idle_contacts`` excluded), ``welded`` (the filter, and the bystanders welded
where they rest). Each mode's outcome and the picked object's final position are
compared with the first mode's. With ``--census`` the contact pairs of every 20th step
are counted by what touches what (arm, hand, table, box lid / walls / floor, the
picked object, the bystanders; an object's feet apart). Prints tables, writes JSON.

Run: python benchmarks/bench_pick_sim.py [--seeds 0-9] [--modes every,filtered]
     [--census] [--out out/bench]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
from pathlib import Path

import numpy as np
from bench_pick import _floor_rate, _seeds  # the same seeds syntax and arm-and-hand floor

from handle_drake.base.results import ResultsRun, add_page_arguments

MODES = ("every", "filtered", "welded")
CENSUS_EVERY = 20  # steps


def _group(plant, inspector, geometry, target) -> str:
    body = plant.GetBodyFromFrameId(inspector.GetFrameId(geometry))
    instance = plant.GetModelInstanceName(body.model_instance())
    name = inspector.GetName(geometry).split("::")[-1]
    if instance == "sorting_box":
        return "box " + ("lid" if name.startswith("lid") else
                         "wall" if name.startswith("wall") else "floor")
    if instance == "object" or instance.startswith("object_"):
        who = "target" if instance == target else "bystander"
        return who + (" foot" if name.startswith("foot") else "")
    return instance


def _census(counts, target):
    """A monitor for ``execute_pick``: counts the point pairs of every CENSUS_EVERY-th
    step by group pair into ``counts`` (``counts["steps"]``: the steps counted)."""
    step = [0]

    def monitor(station, context):
        step[0] += 1
        if step[0] % CENSUS_EVERY:
            return
        query = station.GetOutputPort("query_object").Eval(context)
        plant = station.GetSubsystemByName("plant")
        inspector = query.inspector()
        counts["steps"] += 1
        for pair in query.ComputePointPairPenetration():
            key = " / ".join(sorted((_group(plant, inspector, pair.id_A, target),
                                     _group(plant, inspector, pair.id_B, target))))
            counts[key] += 1

    return monitor


def main(argv=None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-9")
    parser.add_argument("--modes", default="every,filtered",
                        help=f"comma-separated, of {', '.join(MODES)}")
    parser.add_argument("--census", action="store_true",
                        help="count the contact pairs per step (first mode's run)")
    parser.add_argument("--out", default="out/bench")
    add_page_arguments(parser, "pick", published={"seeds": 20})
    args = parser.parse_args(argv)
    modes = args.modes.split(",")
    if not modes or any(m not in MODES for m in modes):
        parser.error(f"--modes: expected a comma-separated list of {', '.join(MODES)}, "
                     f"got {args.modes!r}")
    results_run = ResultsRun("Pick simulation: every collision pair against the filter", args)

    import handle_drake.apps.pick.execute as execute
    from handle_drake.apps.pick.cli import pick
    from handle_drake.apps.pick.scenes import random_scene
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    base = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    original = execute.execute_pick
    rows, census = [], collections.Counter()
    for seed in _seeds(args.seeds):
        scenario = random_scene(base, seed)
        runs = {}

        def each(scenario, plan, html=None, runs=runs, **options):
            runs["floor"] = _floor_rate(scenario)
            for k, mode in enumerate(modes):
                monitor = _census(census, plan.target) if args.census and k == 0 else None
                runs[mode] = original(scenario, plan, still_bystanders=(mode == "welded"),
                                      filter_contacts=(mode != "every"), monitor=monitor,
                                      **options)
            return runs[modes[0]]

        execute.execute_pick = each
        try:
            result = pick(scenario, true_poses=True)
        finally:
            execute.execute_pick = original
        row = dict(seed=seed, kind=result.get("kind"), grasp_class=result.get("grasp_class"),
                   load=os.getloadavg()[0])
        if "floor" in runs:
            first = runs[modes[0]]
            row["floor"] = runs["floor"]
            line = f"seed {seed:2d} {row['kind']:7s} floor {row['floor']:.2f}x"
            for mode in modes:
                r = runs[mode]
                row[mode] = dict(in_box=r.in_box, rate=r.real_time_rate, reason=r.reason,
                                 p_final=r.p_WO_final.tolist(),
                                 dp_final=float(np.max(np.abs(r.p_WO_final - first.p_WO_final))))
                line += (f" | {mode} {r.real_time_rate:.2f}x {'in' if r.in_box else 'OUT'}"
                         f" dp {row[mode]['dp_final']:.1e}")
            print(line + f" | load {row['load']:.1f}", flush=True)
        else:
            print(f"seed {seed:2d} {result['outcome']}", flush=True)
        rows.append(row)
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "pick_sim.json").write_text(json.dumps(
            dict(rows=rows, census=dict(census)), indent=1, default=str))
    done = [r for r in rows if "floor" in r]
    if done:
        for mode in modes:
            rates = np.array([r[mode]["rate"] for r in done])
            ratio = np.array([r[mode]["rate"] / r["floor"] for r in done])
            print(f"{mode:8s} in the box {sum(r[mode]['in_box'] for r in done)}/{len(done)}; "
                  f"rate median {np.median(rates):.2f}x, ratio to floor median "
                  f"{np.median(ratio):.2f}; final position vs {modes[0]}: max "
                  f"{max(r[mode]['dp_final'] for r in done):.1e} m")
        for mode in modes[1:]:
            speedup = [r[mode]["rate"] / r[modes[0]]["rate"] for r in done]
            print(f"{mode} / {modes[0]} rate: median {np.median(speedup):.2f} "
                  f"(min {np.min(speedup):.2f}, max {np.max(speedup):.2f})")
    if census["steps"]:
        steps = census.pop("steps")
        print(f"\ncontact pairs per step ({steps} steps counted, mode {modes[0]})")
        for key, n in census.most_common():
            print(f"  {n / steps:6.2f}  {key}")
        census["steps"] = steps
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    results_run.finish(
        [{k: v for k, v in r.items() if k not in MODES}
         | {f"{mode} {k}": v for mode in modes for k, v in r.get(mode, {}).items()
            if k != "p_final"}
         for r in rows], dict(rows=rows, census=dict(census)),
        Path(args.out) / "pick_sim.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
