"""Convergence of the in-hand finger tasks' results in the time step (issue 45, item 1).

Every hand-written reference motion (``convergence.reference_motions``) re-simulated at
its task's default step and at 1/2 and 1/4 of it by
``handle_drake.apps.inhand.convergence.resimulate`` (its own build, reads the plant at
every step). Prints the table and writes its section of docs/results/inhand.md and
``benchmarks/results/inhand_convergence.json``.

Published budget (``handle_drake.base.results``): every reference motion (no ``--only``)
at each task's own step (no ``--step``), the tasks' own limits and stiffness; any other
run writes ``out/results/``. ``--fresh N`` is another kind of run with its own section:
each reference's success over N fresh perturbed physics (published at N >= 20).

Run: ``python benchmarks/bench_inhand_convergence.py [--effort-limits menagerie]
[--step 0.002] [--only NAME] [--fresh N]``.
"""

from __future__ import annotations

import argparse
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
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "inhand_convergence.json"
FRESH_RESULTS = RESULTS.with_name("inhand_convergence_fresh.json")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--effort-limits", default="menagerie", choices=("sheet", "menagerie"))
    p.add_argument("--step", type=float, default=None,
                   help="the default step (s); default: each task's own")
    p.add_argument("--only", default=None, help="run the reference motions whose name "
                   "contains this")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--fresh", type=int, default=0, metavar="N",
                   help="instead: each reference's success over N fresh perturbed physics "
                        "(screw_cap.fresh_success, the task's ranges)")
    p.add_argument("--stiffness", type=float, default=None,
                   help="the object's point-contact stiffness (N/m; 0: Drake's default); "
                   "default: the task's")
    # the published table: every reference at its task's own step, limits and stiffness
    add_page_arguments(p, "inhand", published={"only": False, "step": False,
                                               "stiffness": False,
                                               "effort_limits": "menagerie"})
    args = p.parse_args(argv)
    if args.step is not None and not 1e-4 <= args.step <= 0.01:
        print(f"--step: expected a value in [0.0001, 0.01] s, got {args.step}", file=sys.stderr)
        return 2
    if args.fresh < 0:
        print(f"--fresh: expected a count >= 0, got {args.fresh}", file=sys.stderr)
        return 2
    if args.stiffness is not None and not args.stiffness >= 0:
        print(f"--stiffness: expected a value >= 0 N/m, got {args.stiffness}", file=sys.stderr)
        return 2
    motions = reference_motions(args.effort_limits)
    if args.only is not None and not any(args.only in name for name in motions):
        print(f"--only: no reference motion's name contains {args.only!r} (names: "
              f"{'; '.join(motions)})", file=sys.stderr)
        return 2
    # --fresh: its own kind of run, its own section (published from 20 draws; --only picks
    # the references worth it: those that converge)
    fresh_budget = {"fresh": 20, "step": False, "stiffness": False,
                    "effort_limits": "menagerie"}
    run = (ResultsRun("In-hand references: success over fresh perturbed physics", args,
                      section="--fresh", published=fresh_budget) if args.fresh else
           ResultsRun("In-hand references: convergence in the time step", args))
    rows, shown = [], []
    for name, (trial, x) in motions.items():
        if args.only and args.only not in name:
            continue
        if args.fresh:
            fresh = fresh_success(trial.config, x, args.fresh)
            rows.append(dict(name=name, **fresh))
            shown.append({"reference": name, "target": trial.config.target_deg,
                          "success": f"{100 * fresh['success']:.0f} % of {args.fresh}",
                          "turns (deg)": f"{min(fresh['turns']):.1f}-{max(fresh['turns']):.1f}"})
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
        shown.append({
            "reference": name, "step, limits": f"{1e3 * step:g} ms, {scenario.effort_limits}",
            "target": trial.config.target_deg,
            **{k: f"{r.turn_deg:.1f} ({'yes' if r.reached else 'no'})"
               for k, r in zip(("h", "h/2", "h/4"), runs, strict=True)},
            "converged": "yes" if ok else "NO",
            "hand on bottle (N, h/4)": (f"{runs[-1].welded_peak:.1f}"
                                        if not trial.config.free else "no welded body"),
            "per-digit peak normal (N, h/4: step / 10 ms)": peaks})
        print(f"| {name} | {1e3 * step:g} ms, {scenario.effort_limits} | "
              f"{trial.config.target_deg:g} | {turns} | "
              f"{'yes' if ok else 'NO'} | {runs[-1].welded_peak:.1f} | {peaks} |", flush=True)
    data = dict(effort_limits=args.effort_limits, step=args.step, stiffness=args.stiffness,
                fresh=args.fresh, only=args.only, rows=rows)
    out = args.out if not args.fresh or args.out != RESULTS else FRESH_RESULTS
    run.finish(shown, data, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
