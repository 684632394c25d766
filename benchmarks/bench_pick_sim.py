"""Simulation speed of pick runs, side by side (issue 33): each seeded Hamburg scene's
true-pose pick (:func:`handle_drake.apps.pick.cli.pick`'s plan) is simulated twice in one
process, with the other objects free bodies (as before) and welded where they rest
(``execute_pick``'s default, ``still_bystanders``), next to the floor (the station with
the arm and hand alone, 1 s) measured just before; and the grasp planner's time per pick,
cold (first pick of a kind and size in the process) and warm (its hand-IK answer cached).
Prints a table, writes JSON.

Run: python benchmarks/bench_pick_sim.py [--seeds 0-19] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
from bench_pick import _floor_rate, _seeds  # the same seeds syntax and arm-and-hand floor

from handle_drake.base.results import ResultsRun, add_page_arguments


def main(argv=None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-19")
    parser.add_argument("--out", default="out/bench")
    add_page_arguments(parser, "pick")
    args = parser.parse_args(argv)
    results_run = ResultsRun("Pick simulation: bystanders free against welded", args)

    import handle_drake.apps.pick.execute as execute
    from handle_drake.apps.pick.cli import pick
    from handle_drake.apps.pick.scenes import random_scene
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    base = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    original = execute.execute_pick
    rows, seen = [], set()
    for seed in _seeds(args.seeds):
        scenario = random_scene(base, seed)
        runs = {}

        def both(scenario, plan, html=None, runs=runs, **options):
            runs["floor"] = _floor_rate(scenario)
            runs["free"] = original(scenario, plan, still_bystanders=False, **options)
            runs["welded"] = original(scenario, plan, still_bystanders=True, **options)
            return runs["welded"]

        execute.execute_pick = both
        try:
            result = pick(scenario, true_poses=True)
        finally:
            execute.execute_pick = original
        key = result.get("kind")  # every scene object of a kind has one size
        row = dict(seed=seed, kind=result.get("kind"), grasp_class=result.get("grasp_class"),
                   grasp_s=result.get("planning_s", {}).get("grasp"),
                   ik_path_s=(result["planning_s"]["ik"] + result["planning_s"]["path"]
                              if "planning_s" in result else None),
                   warm=key in seen, load=os.getloadavg()[0])
        seen.add(key)
        if runs:
            row.update(floor=runs["floor"],
                       free=dict(in_box=runs["free"].in_box, rate=runs["free"].real_time_rate,
                                 reason=runs["free"].reason),
                       welded=dict(in_box=runs["welded"].in_box,
                                   rate=runs["welded"].real_time_rate,
                                   reason=runs["welded"].reason))
            print(f"seed {seed:2d} {row['kind']:7s} {row['grasp_class']:18s} grasp "
                  f"{row['grasp_s']:6.2f} s ({'warm' if row['warm'] else 'cold'}) | floor "
                  f"{row['floor']:.2f}x free {row['free']['rate']:.2f}x "
                  f"{'in' if row['free']['in_box'] else 'OUT'} | welded "
                  f"{row['welded']['rate']:.2f}x {'in' if row['welded']['in_box'] else 'OUT'}"
                  f" | load {row['load']:.1f}", flush=True)
        else:
            print(f"seed {seed:2d} {result['outcome']}", flush=True)
        rows.append(row)
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "pick_sim.json").write_text(json.dumps(rows, indent=1, default=str))
    done = [r for r in rows if "floor" in r]
    if done:
        for mode in ("free", "welded"):
            rates = np.array([r[mode]["rate"] for r in done])
            ratio = np.array([r[mode]["rate"] / r["floor"] for r in done])
            print(f"{mode:7s} in the box {sum(r[mode]['in_box'] for r in done)}/{len(done)}; "
                  f"rate median {np.median(rates):.2f}x, ratio to floor median "
                  f"{np.median(ratio):.2f}")
        speedup = [r["welded"]["rate"] / r["free"]["rate"] for r in done]
        print(f"welded / free rate: median {np.median(speedup):.2f} "
              f"(min {np.min(speedup):.2f}, max {np.max(speedup):.2f})")
        for warm in (False, True):
            g = [r["grasp_s"] for r in done if r["warm"] is warm]
            if g:
                print(f"grasp planner {'warm' if warm else 'cold'}: median {np.median(g):.2f} s,"
                      f" max {np.max(g):.2f} s ({len(g)} picks)")
        total = [r["grasp_s"] + r["ik_path_s"] for r in done if r["warm"]]
        if total:
            print(f"whole plan (grasp + IK + paths), warm: median {np.median(total):.2f} s, "
                  f"max {np.max(total):.2f} s, <= 2 s in {sum(t <= 2 for t in total)}/"
                  f"{len(total)}")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    results_run.finish(
        [{k: v for k, v in r.items() if k not in ("free", "welded")}
         | {f"{mode} {k}": v for mode in ("free", "welded") for k, v in r.get(mode, {}).items()}
         for r in rows], rows, Path(args.out) / "pick_sim.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
