"""The in-hand turn from what the hand senses against the plant's (issue 47, items 3-4).

The screw cap's clear-placement stroke and the fingertip cylinder's two strokes (hand-written,
and ipso's learned best, ``convergence.LEARNED_TWO_STROKES``) run with
``ScrewCapTask(score="estimated", accelerometer=DEVICE)``: per trial the plant's turn at
the end, the touch estimate's (taxels and joints: ``devices/taxels/turn.ContactTurn``; the free
cylinder's fused with the accelerometer) and
the accelerometer's (``GravityTurn``), their relative errors and whether each is within
``--tolerance`` (10 %). ``--step-scale 0.5`` re-runs at half the task's step. Prints a
Markdown table (and writes ``--json``); it writes no results page.

``--lean``: instead, the rule against leaning on the welded bottle scored from the taxels
(``SensedTurn.welded_max``) against the plant's contact results (``welded_force_truth``),
per screw-cap placement (``screw_cap.PLACEMENTS``), a short trial each: the demonstration's
parameters, stopped at the first failed check.

Run: ``python tools/inhand_sensed.py [--device joywarrior24f14] [--lean]
[--step-scale 1] [--json out/results/inhand_sensed.json]``.
"""

from __future__ import annotations

import argparse
import dataclasses as dc
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from handle_drake.apps.inhand.convergence import reference_motions
from handle_drake.apps.inhand.screw_cap import PLACEMENTS, ScrewCapTask, ScrewCapTrial

ROWS = ("screw cap, clear placement, stroke", "fingertip cylinder, two strokes",
        "fingertip cylinder, two strokes, ipso's best (seed 100)")


def _row(name, trial, x, device, step_scale, tolerance) -> dict:
    c = trial.config
    t = ScrewCapTrial(dc.replace(c, score="estimated", accelerometer=device,
                                 time_step=c.time_step * step_scale))
    wall = time.perf_counter()
    o = t.evaluate(x, early_stop=False)
    plant, touch, gravity = o.sensed_series[-1]
    err = {k: float("nan") if v is None else abs(v - plant) / max(abs(plant), 1e-9)
           for k, v in (("touch", touch), ("gravity", gravity))}
    return dict(name=name, time_step=t.config.time_step, plant_deg=plant, touch_deg=touch,
                gravity_deg=gravity, touch_rel=err["touch"], gravity_rel=err["gravity"],
                touch_ok=err["touch"] <= tolerance, gravity_ok=err["gravity"] <= tolerance,
                score=o.score, reached=o.reached_target, wall_s=time.perf_counter() - wall)


def _lean_rows(step_scale: float) -> list[dict]:
    """Per placement: the bottle's force (N) from the taxels and from the plant, the lean
    flags (the plant's: ``welded_force_truth > lean_force``) and the bodies."""
    rows = []
    for name, preset in PLACEMENTS.items():
        task = ScrewCapTask(**preset, score="estimated")
        trial = ScrewCapTrial(dc.replace(task, time_step=task.time_step * step_scale))
        o = trial.evaluate(trial.gist.initial_parameters())
        rows.append(dict(name=name, time_step=trial.config.time_step, sim_s=o.sim_time,
                         sensed_n=o.welded_force_max, plant_n=o.welded_force_truth,
                         sensed_leaned=o.leaned_on_welded,
                         plant_leaned=o.welded_force_truth > task.lean_force,
                         bodies=o.welded_bodies))
    print("| placement | step (ms) | trial (s) | taxels (N) | plant (N) | leaned: taxels, plant |"
          " bodies (taxels) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {1e3 * r['time_step']:g} | {r['sim_s']:.2f} | "
              f"{r['sensed_n']:.1f} | {r['plant_n']:.1f} | {r['sensed_leaned']}, "
              f"{r['plant_leaned']} | {', '.join(r['bodies'])} |")
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="joywarrior24f14",
                   help="the object's accelerometer; '' for none (the touch alone; with one, "
                        "a free object's touch is fused with it)")
    p.add_argument("--step-scale", type=float, default=1.0, choices=(1.0, 0.5, 0.25))
    p.add_argument("--tolerance", type=float, default=0.10)
    p.add_argument("--json", type=Path, default=None)
    p.add_argument("--lean", action="store_true",
                   help="the lean on the welded bottle from the taxels against the plant")
    args = p.parse_args(argv)
    load0 = os.getloadavg()[0]
    if args.lean:
        rows = _lean_rows(args.step_scale)
        print(f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end")
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(rows, indent=1, default=float))
        return 0 if all(r["sensed_leaned"] == r["plant_leaned"] for r in rows) else 1
    motions = reference_motions()
    rows = [_row(n, *motions[n], args.device, args.step_scale, args.tolerance) for n in ROWS]
    print(f"load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end")
    print("| trial | step (ms) | plant (deg) | touch (deg, err) | accelerometer (deg, err) |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {1e3 * r['time_step']:g} | {r['plant_deg']:.1f} | "
              f"{r['touch_deg']:.1f} ({100 * r['touch_rel']:.0f} %"
              f"{', met' if r['touch_ok'] else ''}) | " + ("none" if r["gravity_deg"] is None
                                                           else f"{r['gravity_deg']:.1f} "
              f"({100 * r['gravity_rel']:.0f} %{', met' if r['gravity_ok'] else ''})") + " |")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1, default=float))
    return 0 if all(np.isfinite([r["touch_deg"] for r in rows])) else 1


if __name__ == "__main__":
    sys.exit(main())
