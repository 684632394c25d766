"""Pick and place on seeded random scenes of the Hamburg table (issue 33 targets).

For each seed (``--seeds``, default 0-19) the scene of 2-5 objects
(:func:`handle_drake.apps.pick.scenes.random_scene`) is picked once from perception
and once from the true poses (``--modes``), the nearest pickable object each
time, through :func:`handle_drake.apps.pick.cli.pick`. Prints the success table
(per mode and per kind), the planning times (grasp planner, arm IK, joint
paths), the simulation's real-time rate next to a floor measured in the same
run (the bare station, arm and hand only, no objects or box), and the load;
writes JSON.

``--seeds eval`` is the held-out block (``scenes.EVALUATION_SEEDS``, nothing tuned on
it); ``--time-steps 0.001,0.0005`` simulates each pick at each plant step and prints
whether the verdicts agree (the physics converged); the grasp of each pick is counted by
where it came from (stored, adapted to the perceived size, searched).

Run: python benchmarks/bench_pick.py [--seeds 0-19|eval] [--modes perceived,true]
     [--time-steps 0.001] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from handle_drake.base.results import ResultsRun, add_page_arguments, table_rows


def _seeds(text: str) -> list[int]:
    if text == "eval":
        from handle_drake.apps.pick.scenes import EVALUATION_SEEDS

        return list(EVALUATION_SEEDS)
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def _floor_rate(scenario) -> float:
    """Real-time rate of the station with the arm and hand only (1 s simulated)."""
    import dataclasses as dc

    from pydrake.systems.analysis import Simulator

    from handle_drake.station import MakeHandStation

    bare = dc.replace(scenario, object=None, objects=[], sorting_box=None, cameras=[])
    simulator = Simulator(MakeHandStation(bare))
    start = time.perf_counter()
    simulator.AdvanceTo(1.0)
    return 1.0 / (time.perf_counter() - start)


def _with_time_step(scenario, step: float):
    """``scenario`` with its plant's time step ``step`` (s)."""
    import copy
    import dataclasses as dc

    config = copy.deepcopy(scenario.plant_config)
    config.time_step = float(step)
    return dc.replace(scenario, plant_config=config)


def main(argv=None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-19")
    parser.add_argument("--modes", default="perceived,true")
    parser.add_argument("--out", default="out/bench")
    parser.add_argument("--close", default="reactive", choices=("reactive", "scripted"),
                        help="the hand's close (handle-drake pick --scripted-close)")
    parser.add_argument("--no-correction", action="store_true",
                        help="release without measuring the object in the hand "
                             "(handle-drake pick --no-release-correction)")
    parser.add_argument("--time-steps", default=None, metavar="DT[,DT...]",
                        help="plant time steps (s) to simulate each pick at (default: the "
                             "scenario's); with two or more, the verdicts are compared")
    parser.add_argument("--plan-only", action="store_true",
                        help="plan each pick, do not simulate it (planning times only)")
    add_page_arguments(parser, "pick", published={"seeds": 20, "modes": 2})
    args = parser.parse_args(argv)
    results_run = (ResultsRun("Pick planning time per pick (grasp database, arm IK, paths)",
                              args, section="--plan-only") if args.plan_only else
                   ResultsRun("Pick and place on the arm: objects in the box", args))

    from handle_drake.apps.pick.cli import pick
    from handle_drake.apps.pick.plan import default_grasp_database
    from handle_drake.apps.pick.scenes import random_scene
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    start = time.perf_counter()
    database = default_grasp_database()
    db_load = time.perf_counter() - start
    print(f"grasp database: {len(database)} entries, loaded in {db_load:.3f} s")
    base = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    floor = float("nan") if args.plan_only else _floor_rate(base)
    steps = [None] if args.time_steps is None else [float(v) for v in
                                                     args.time_steps.split(",")]
    rows = []
    for seed in _seeds(args.seeds):
        for step in steps:
            scenario = base if step is None else _with_time_step(base, step)
            scenario = random_scene(scenario, seed)
            for mode in args.modes.split(","):
                start = time.perf_counter()
                result = pick(scenario, true_poses=(mode == "true"),
                              execute=not args.plan_only, close=args.close,
                              correct_release=not args.no_correction)
                result.update(seed=seed, mode=mode, total_s=time.perf_counter() - start,
                              load=os.getloadavg()[0],
                              time_step=scenario.plant_config.time_step)
                rows.append(result)
                print(f"seed {seed:2d} {mode:9s} dt {result['time_step']:.4g} "
                      f"{result.get('true_kind', '-'):7s} "
                      f"{result.get('grasp_class', '-'):18s} "
                      f"{result.get('grasp_source', '-'):8s} {result['outcome']}", flush=True)
            partial = Path(args.out) / "pick_partial.json"
            partial.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(json.dumps(rows, indent=1, default=str))  # survives a stop
    print("\nmode       in the box   sphere   cuboid")
    summary = {}
    for mode, step in [(m, t) for m in args.modes.split(",") for t in steps]:
        mine = [r for r in rows if r["mode"] == mode and (
            step is None or r["time_step"] == step)]
        if step is not None and len(steps) > 1:
            mode = f"{mode} dt {step:g}"
        ok = [r for r in mine if r.get("in_box")]
        per_kind = {k: (sum(1 for r in ok if r.get("true_kind") == k),
                        sum(1 for r in mine if r.get("true_kind") == k))
                    for k in ("sphere", "cuboid")}
        summary[mode] = {"in_box": len(ok), "runs": len(mine), "per_kind": per_kind}
        print(f"{mode:10s} {len(ok):3d}/{len(mine):<3d}      "
              + "   ".join(f"{a}/{b}" for a, b in per_kind.values()))
    if len(steps) > 1:
        verdicts = {}
        for r in rows:
            verdicts.setdefault((r["seed"], r["mode"]), {})[r["time_step"]] = bool(
                r.get("in_box"))
        same = sum(len(set(v.values())) == 1 for v in verdicts.values())
        flips = [k for k, v in verdicts.items() if len(set(v.values())) > 1]
        summary["time_steps"] = {"same_verdict": same, "picks": len(verdicts),
                                 "flipped": flips}
        print(f"time steps {steps}: the same verdict in {same}/{len(verdicts)} picks; "
              f"flipped: {flips}")
    planned = [r for r in rows if "planning_s" in r]
    sources = {}
    for r in planned:
        sources[r.get("grasp_source")] = sources.get(r.get("grasp_source"), 0) + 1
    if planned:
        print(f"grasp sources: {sources}")
    timing = []
    if planned:
        for key in ("grasp", "ik", "path"):
            values = [r["planning_s"][key] for r in planned]
            print(f"planning {key:5s}: median {np.median(values):.2f} s, "
                  f"max {np.max(values):.2f} s")
        ik_path = [r["planning_s"]["ik"] + r["planning_s"]["path"] for r in planned]
        print(f"IK + paths: median {np.median(ik_path):.2f} s, max {np.max(ik_path):.2f} s")
        whole = [sum(r["planning_s"].values()) for r in planned]
        for stage, values in (("grasp", [r["planning_s"]["grasp"] for r in planned]),
                              ("arm IK", [r["planning_s"]["ik"] for r in planned]),
                              ("paths", [r["planning_s"]["path"] for r in planned]),
                              ("whole plan", whole),
                              ("arm collision model", [r["reach_model_s"] for r in planned])):
            timing.append({"stage": stage, "median_s": float(np.median(values)),
                           "p90_s": float(np.percentile(values, 90)),
                           "max_s": float(np.max(values)),
                           "at_most_2s": f"{sum(v <= 2.0 for v in values)}/{len(values)}"})
        print(f"whole plan (grasp + IK + paths): median {np.median(whole):.2f} s, "
              f"90 % {np.percentile(whole, 90):.2f} s, max {np.max(whole):.2f} s; "
              f"<= 2 s in {sum(w <= 2.0 for w in whole)}/{len(whole)}; grasp stored in "
              f"{sum(bool(r.get('grasp_stored')) for r in planned)}/{len(planned)}")
        model = [r["reach_model_s"] for r in planned]
        print(f"arm collision model per scene (ArmReach): median {np.median(model):.2f} s, "
              f"max {np.max(model):.2f} s")
    simulated = [r for r in rows if "sim_s" in r]
    if simulated:
        rate = np.median([r["sim_s"] / r["wall_s"] for r in simulated])
        print(f"simulation: median {rate:.2f}x real time; floor (arm + hand alone) "
              f"{floor:.2f}x; ratio {rate / floor:.2f}")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / ("pick_plan.json" if args.plan_only else "pick.json")
    results_run.finish(timing if args.plan_only else table_rows(summary, "mode"),
                       {"summary": summary, "floor_rate": floor, "rows": rows,
                        "grasp_db_load_s": db_load}, path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
