"""Convergence of the in-hand finger tasks' results in the time step (issue 45, item 1).

Every hand-written reference motion (``convergence.reference_motions``) and, with
``--scenarios FILE.json``, any logged trial scenarios (a JSON list of ``{"name", "task",
"target_deg", "scenario"}``) re-simulated at the default step and at 1/2 and 1/4 of it by
``handle_drake.apps.inhand.convergence.resimulate`` (its own build, reads the plant at
every step). Prints the table of docs/results/inhand.md and writes
``benchmarks/results/inhand_convergence.json``.

Run: ``python benchmarks/bench_inhand_convergence.py [--effort-limits menagerie]
[--step 0.002] [--only NAME]``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import dataclasses as dc  # noqa: E402

from handle_drake.apps.inhand.convergence import (  # noqa: E402
    converged,
    reference_motions,
    resimulate,
)
from handle_drake.apps.inhand.screw_cap import fresh_success  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "inhand_convergence.json"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--effort-limits", default="menagerie", choices=("sheet", "menagerie"))
    p.add_argument("--step", type=float, default=None,
                   help="the default step (s); default: each task's own")
    p.add_argument("--only", default="", help="run the reference motions whose name "
                   "contains this")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--fresh", type=int, default=0, metavar="N",
                   help="instead: each reference's success over N fresh perturbed physics "
                        "(screw_cap.fresh_success, the task's ranges)")
    p.add_argument("--stiffness", type=float, default=None,
                   help="the object's point-contact stiffness (N/m; 0: Drake's default); "
                   "default: the task's")
    args = p.parse_args(argv)
    if args.step is not None and not 1e-4 <= args.step <= 0.01:
        print(f"--step: expected a value in [0.0001, 0.01] s, got {args.step}", file=sys.stderr)
        return 2
    rows = []
    for name, (trial, x) in reference_motions(args.effort_limits).items():
        if args.only and args.only not in name:
            continue
        if args.fresh:
            fresh = fresh_success(trial.config, x, args.fresh)
            rows.append(dict(name=name, **fresh))
            print(f"| {name} | {trial.config.target_deg:g} | {100 * fresh['success']:.0f} % of "
                  f"{args.fresh} | {min(fresh['turns']):.1f}-{max(fresh['turns']):.1f} |",
                  flush=True)
            continue
        step = args.step or trial.config.time_step
        scenario = dc.replace(trial.scenario(x), time_step=step)
        if args.stiffness is not None:
            scenario = dc.replace(scenario, cap=dc.replace(scenario.cap,
                                                           point_stiffness=args.stiffness))
        runs = [resimulate(scenario, step / f, target_deg=trial.config.target_deg)
                for f in (1, 2, 4)]
        ok = converged(runs)
        rows.append(dict(name=name, target_deg=trial.config.target_deg, converged=ok,
                         runs=[r.as_dict() for r in runs]))
        turns = " | ".join(f"{r.turn_deg:.1f} ({'yes' if r.reached else 'no'})" for r in runs)
        peaks = ", ".join(f"{d} {v:.1f} / {runs[-1].digit_peak_normal_10ms[d]:.1f}"
                          for d, v in runs[-1].digit_peak_normal.items() if v)
        print(f"| {name} | {1e3 * step:g} ms, {scenario.effort_limits} | "
              f"{trial.config.target_deg:g} | {turns} | "
              f"{'yes' if ok else 'NO'} | {runs[-1].welded_peak:.1f} | {peaks} |", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(dict(effort_limits=args.effort_limits, step=args.step,
                                        stiffness=args.stiffness,
                                        rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
