"""The jog wheel learned from MIDI: base rate, the demonstration, an optimiser comparison.

1. Base rate (``--base-rate N``): N uniformly random parameter vectors within
   the task's bounds (numpy seed ``--seed``), each a full trial; the share that
   reaches the target from MIDI, the same share judged by the plant's true
   wheel angle (never scored; logged beside), and the largest |MIDI - true|
   turn at the end against one tick.
2. Optimisers (``--optimizers ... --seeds ... --trials B``): ``run_inhand``
   (the ``handle-drake inhand --task jog_wheel`` machinery) per optimiser and
   seed until the target or the budget: trials to target, best MIDI score, the
   best trial's true turn.

Run: ``python benchmarks/bench_jog_wheel.py --base-rate 36 --optimizers ipso random
--seeds 41 42 43 --trials 30``; writes ``benchmarks/results/jog_wheel.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.apps.inhand.experiment import run_inhand  # noqa: E402
from handle_drake.apps.inhand.jog_wheel import JogWheelTask, JogWheelTrial, MidiJogEvaluator  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "jog_wheel.json"


def base_rate(n: int, seed: int, target_deg: float) -> dict:
    trial = JogWheelTrial(JogWheelTask(target_deg=target_deg))
    bounds = trial.bounds
    rng = np.random.default_rng(seed)
    rows = []
    demo = trial.evaluate(trial.config.demonstration())
    for _ in range(n):
        x = rng.uniform(bounds[:, 0], bounds[:, 1])
        o = trial.evaluate(x)
        true_reached = o.checks_passed == trial.config.n_parts and \
            o.true_turn_deg >= trial.config.target_deg
        rows.append(dict(x=[float(v) for v in x], score=o.score, midi_turn_deg=o.turn_deg,
                         true_turn_deg=o.true_turn_deg, reached=o.reached_target,
                         true_reached=bool(true_reached), wall_time=o.wall_time))
        print(f"  score {o.score:6.3f}  MIDI {o.turn_deg:+7.2f} deg  true "
              f"{o.true_turn_deg:+7.2f} deg  {'reached' if o.reached_target else ''}",
              flush=True)
    tick = MidiJogEvaluator(trial.config).tick_deg
    err = [abs(r["midi_turn_deg"] - r["true_turn_deg"]) for r in rows]
    return dict(n=n, seed=seed, target_deg=trial.config.target_deg,
                reached=sum(r["reached"] for r in rows),
                true_reached=sum(r["true_reached"] for r in rows),
                base_rate=float(np.mean([r["reached"] for r in rows])),
                max_abs_midi_minus_true_deg=float(max(err)), tick_deg=tick,
                median_wall_time=float(np.median([r["wall_time"] for r in rows])),
                demonstration=dict(score=demo.score, midi_turn_deg=demo.turn_deg,
                                   true_turn_deg=demo.true_turn_deg,
                                   reached=demo.reached_target),
                trials=rows)


def optimisers(names, seeds, trials: int, db: Path, target_deg: float) -> list:
    out = []
    for name in names:
        for seed in seeds:
            run = run_inhand("jog_wheel", name, trials, 1, seed, db, 10, progress=False,
                             target_deg=target_deg)
            s = run.summary()
            best = max((r for r in run.records if r.status == "done"), key=lambda r: r.metric)
            out.append(dict(optimizer=name, seed=seed, target_deg=target_deg, trials=s["done"],
                            trials_to_target=s["trials_to_target"], best_score=s["best_score"],
                            best_midi_turn_deg=best.contacts["turn_deg"],
                            best_true_turn_deg=best.contacts["true_turn_deg"]))
            print(out[-1], flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base-rate", type=int, default=0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--optimizers", nargs="*", default=[])
    p.add_argument("--seeds", nargs="+", type=int, default=[41, 42, 43])
    p.add_argument("--trials", type=int, default=30)
    p.add_argument("--target-deg", type=float, default=JogWheelTask.target_deg,
                   help="the wheel's net turn to reach (deg, default %(default)s)")
    p.add_argument("--db", type=Path, default=Path("out/inhand/jog_wheel.sqlite"))
    p.add_argument("--out", type=Path, default=RESULTS)
    add_page_arguments(p, "inhand", published={"seeds": 3, "trials": 30})
    args = p.parse_args(argv)
    try:
        JogWheelTask(target_deg=args.target_deg)
    except ValueError as error:
        p.error(f"--target-deg: {error}")
    run = ResultsRun("Jog wheel: base rate and optimisers (MIDI ticks only)", args)
    result = json.loads(args.out.read_text()) if args.out.exists() else {}
    if args.base_rate:
        result["base_rate"] = base_rate(args.base_rate, args.seed, args.target_deg)
    if args.optimizers:
        result["optimisers"] = optimisers(args.optimizers, args.seeds, args.trials, args.db,
                                          args.target_deg)
    table = []
    if "base_rate" in result:
        table.append({"optimizer": "random (base rate)", **{
            k: v for k, v in result["base_rate"].items() if k not in ("trials", "demonstration")}})
    table += result.get("optimisers", [])
    run.finish(table, result, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
