"""In-hand babbling: trial speed against the bare plant, and the optimiser table.

1. Speed (``--speed``): one in-hand trial (station, GistMotionSource, checks,
   reset from the settled context) against the bare plant simulating the same
   scenario over the same time from the same state (MultibodyPlant +
   SceneGraph, the hand's PD inputs fed by a TrajectorySource of the same
   frames: no Python system), against the bare plant replaying the trial's own
   plant inputs (its driver's rate-limited desired states and the reversed
   weight: the same physics, final object pose checked equal), against building
   the trial's diagram anew, and the same trial with an instrumented object (the
   JoyWarrior model in it); every case once per round, ratios of medians. With
   ``--baseline REV`` the trial of git revision REV and this tree's trial are
   also timed, each in a worker process (``benchmarks/support/trial_worker.py``),
   the outcome checked identical, after/before paired by round.
   ``--instructions``: the instructions each of the trial, its two floors (and with
   ``--baseline`` the revision's trial) executes per run, counted by valgrind in a
   process of its own (``benchmarks/support/instructions.py``): exact, where the times
   of identical code vary by +-5 % between processes here.
2. Table (``--table``): optimiser x task x seed runs of ``run_inhand`` (all
   runs in one SQLite log, resumable: whatever already ran is read back), each
   until a trial reaches the target or the budget is spent. Per optimiser and
   task: median (range) of the best held rotation, share of held trials, trials
   to the target (median over seeds; runs that did not reach it count as the
   budget and are listed).

The table's trials run where ``--executor`` says (``local`` with ``--workers``,
``dask`` LocalCluster, ``dask://HOST:PORT``: ``handle_drake.learning.cluster``).

Run: ``python benchmarks/bench_inhand.py --speed [--instructions] [--baseline REV] --table
[--trials N] [--seeds 0 1 2] [--evaluation old]``;
writes ``benchmarks/results/inhand.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "support"))  # helpers, not benchmarks

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.apps.inhand.experiment import plot_learning_curve, run_inhand  # noqa: E402
from handle_drake.apps.inhand.task import EVALUATIONS, TASKS, InHandTask, InHandTrial  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments, table_rows  # noqa: E402
from handle_drake.learning.cluster import add_executor_arguments, trial_executor  # noqa: E402
from handle_drake.learning.optim.population import INHAND_OPTIMIZERS  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "inhand.json"


def speed(rounds: int, baseline: str | None = None) -> dict:
    from floors import inhand_bare, inhand_replay
    from speed import OWN, paired, speed_table
    from trial_worker import BaselineTrial, outcome_dict, stroke

    trial = InHandTrial()
    x = stroke(trial.gist)  # the hand-written full stroke
    trial._build()
    # the trial simulates its motion, then (when it ran to the end) 0.5 s of reversed weight
    mine = trial.evaluate(x)
    reversed_test = mine.survived_reversal is not None
    sim = trial.config.total_time + (trial.config.reverse_time if reversed_test else 0.0)
    bare = inhand_bare(trial, x, sim)
    replay, identical = inhand_replay(trial, x, sim)
    print(f"replay of the trial's plant inputs: final object pose identical to the "
          f"trial's: {identical}", flush=True)
    instrumented = InHandTrial(InHandTask(accelerometer="joywarrior24f14"))
    instrumented._build()
    cases = {"trial (reset, checks)": lambda: trial.evaluate(x).wall_time,
             "bare plant, same frames": bare,
             "bare plant, the trial's own inputs (replay)": replay,
             "trial built anew": lambda: _fresh(trial, x),
             "trial, instrumented object": lambda: instrumented.evaluate(x).wall_time}
    # the trial and its two floors again, each in a worker process of its own
    workers = {"trial (reset, checks)" + OWN: BaselineTrial(None, "inhand", {}),
               "bare plant, same frames" + OWN: BaselineTrial(None, "inhand:bare", {}),
               "bare plant, replay" + OWN: BaselineTrial(None, "inhand:replay", {})}
    out, times = speed_table(cases, workers, rounds, trial="trial (reset, checks)",
                             floor="bare plant, same frames", sim_time=sim, kind="inhand",
                             options={}, baseline=baseline, outcome=outcome_dict(mine))
    out.update(replay_final_pose_identical=identical,
               trial_over_replay=paired(times, "trial (reset, checks)",
                                        "bare plant, the trial's own inputs (replay)",
                                        "trial / replay, in the bench's process"),
               own_worker_trial_over_replay=paired(
                   times, "trial (reset, checks)" + OWN, "bare plant, replay" + OWN,
                   "trial / replay, each in its own worker"))
    return out


def _speed_note(out: dict) -> str:
    """The trial's ratios to its floors (paired by round: median, the median's 95 %
    interval, rounds' range) and the target (<= 1.10x the bare plant, own workers)."""
    from speed import ci_text, judge

    parts = []
    for key, label in (("own_worker_trial_over_bare", "trial / bare plant, own workers"),
                       ("own_worker_trial_over_replay", "trial / replay, own workers"),
                       ("trial_over_replay", "trial / replay, bench's process")):
        r = out[key]
        parts.append(f"{label} {r['median']:.3f}x {ci_text(r['ci95'])}"
                     f" ({min(r['rounds']):.3f}-{max(r['rounds']):.3f})")
    return ("CPU, paired by round, median [its 95 % bootstrap interval] (rounds' range): "
            + "; ".join(parts) + ". Target: trial <= 1.10x the bare plant (own workers): "
            + judge(out["own_worker_trial_over_bare"], 1.10) + ".")


def instructions(args) -> dict:
    """The trial and its floors' instructions per run (``support/instructions.py``: exact,
    where their times vary by +-5 % between processes), each in a process of its own
    under callgrind; with ``--baseline`` also the trial of that git revision. Written to a
    section and a JSON of their own."""
    from instructions import write_section

    cases = {"trial (reset, checks)": ("inhand", {}, None),
             "bare plant, same frames": ("inhand:bare", {}, None),
             "bare plant, replay": ("inhand:replay", {}, None)}
    if args.baseline:
        cases[f"trial (reset, checks) at {args.baseline}"] = ("inhand", {}, args.baseline)
    return write_section("In-hand trial: instructions per run against the bare plant", args,
                         cases, {"bare": "bare plant, same frames",
                                 "replay": "bare plant, replay"},
                         args.out.with_name("inhand_instructions.json"))


def _fresh(trial, x):
    start = time.perf_counter()
    InHandTrial(trial.config).evaluate(x)  # a new trial object builds its own diagram
    return time.perf_counter() - start


def table(tasks, optimizers, seeds, trials, targets, db, workers, n_particles,
          executor=None, evaluation="incremental") -> list[dict]:
    rows = []
    for target in targets:
        for task in tasks:
            for optimizer in optimizers:
                runs, logged = [], []
                for seed in seeds:
                    start = time.perf_counter()
                    run = run_inhand(task, optimizer, trials, workers, seed, db, n_particles,
                                     progress=False, executor=executor,
                                     target_deg=float(target), evaluation=evaluation)
                    logged.append(run)
                    s = run.summary()
                    s["seed"], s["elapsed"] = seed, time.perf_counter() - start
                    done = [r for r in run.records if r.status == "done"]
                    if done:  # how the best motion ends when run to the end
                        best = max(done, key=lambda r: r.metric)
                        full = run.trial.evaluate(best.parameters, early_stop=False)
                        s["best_full_rotation_deg"] = full.rotation_deg
                        s["best_full_held"] = full.held
                    runs.append(s)
                    print(f"{task} {target} deg {evaluation} {optimizer} seed {seed}: "
                          f"{json.dumps(s)}",
                          flush=True)
                figure = plot_learning_curve(
                    logged, Path(db).parent / f"curve-{task}-{evaluation}-{target:g}deg-"
                                              f"{optimizer}.png",
                    f"{task}, target {target:g} deg held: {optimizer} ({evaluation})")
                reached = [s["trials_to_target"] for s in runs]
                best = [s.get("best_held_rotation_deg", float("nan")) for s in runs]
                best = [b if b == b else float("nan") for b in best] or [float("nan")]
                rows.append({
                    "task": task, "target_deg": target, "optimizer": optimizer,
                    "evaluation": evaluation,
                    "seeds": seeds, "budget": trials,
                    "best_held_rotation_deg_median": float(np.nanmedian(best)),
                    "best_held_rotation_deg_range": [float(np.nanmin(best)),
                                                     float(np.nanmax(best))],
                    "share_held_median": float(np.median([s.get("share_held", 0) for s in runs])),
                    "best_full": [(round(s.get("best_full_rotation_deg", float("nan")), 1),
                                   s.get("best_full_held")) for s in runs],
                    "trials_to_target": reached,
                    "trials_to_target_median": float(np.median(
                        [r if r is not None else trials for r in reached])),
                    "reached": sum(r is not None for r in reached),
                    "figure": str(figure),
                    "runs": runs})
    print(f"\n{'task':18s} {'tgt':>4s} {'optimizer':9s} {'best held rot (deg)':>22s} "
          f"{'held share':>10s} {'to target':>16s}  best trial run to the end (deg, held)")
    for r in rows:
        lo, hi = r["best_held_rotation_deg_range"]
        print(f"{r['task']:18s} {r['target_deg']:4g} {r['optimizer']:9s} "
              f"{r['best_held_rotation_deg_median']:7.1f} ({lo:5.1f}-{hi:5.1f}) "
              f"{r['share_held_median']:10.2f} {str(r['trials_to_target']):>16s}  "
              f"{r['best_full']}")
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--speed", action="store_true")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--baseline", default=None, metavar="REV",
                   help="with --speed: also time the trial of git revision REV (a worker "
                        "process on its handle_drake), every round, its outcome checked; "
                        "with --instructions: also count it")
    p.add_argument("--instructions", action="store_true",
                   help="count the instructions of the trial and its floors (valgrind; "
                        "with --baseline REV also that revision's trial)")
    p.add_argument("--table", action="store_true")
    p.add_argument("--tasks", nargs="+", default=list(TASKS), choices=list(TASKS))
    p.add_argument("--optimizers", nargs="+", default=list(INHAND_OPTIMIZERS),
                   choices=list(INHAND_OPTIMIZERS))
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--trials", type=int, default=1000)
    p.add_argument("--targets", nargs="+", type=float, default=[30.0])
    p.add_argument("--particles", type=int, default=10)
    p.add_argument("--evaluation", choices=EVALUATIONS, default="incremental")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--db", type=Path, default=Path("out/inhand/bench.sqlite"))
    p.add_argument("--out", type=Path, default=RESULTS)
    add_executor_arguments(p)
    add_page_arguments(p, "inhand")
    args = p.parse_args(argv)
    # the published budget of each kind of run: --speed's rounds, --table's seeds
    published = {"only_instructions": {}, "speed": {"rounds": 16},
                 "table": {"seeds": 3}}
    kinds = [k for k in ("speed", "table") if getattr(args, k)] or ["only_instructions"]
    run = ResultsRun("In-hand tasks: speed and optimisers' trials to target", args,
                     published={k: v for kind in kinds for k, v in published[kind].items()})
    result = {"machine": {"python": sys.version.split()[0], "platform": platform.platform(),
                          "cpus": os.cpu_count()}}
    if args.out.exists():
        result = {**json.loads(args.out.read_text()), **result}
    if args.speed:
        result["speed"] = speed(args.rounds, args.baseline)
    if args.instructions:
        instructions(args)
        if not (args.speed or args.table):
            return 0
    if args.table:
        key = "table_" + "_".join(f"{t:g}" for t in args.targets) + f"_{args.evaluation}"
        with trial_executor(args.executor, args.workers,
                            connect_timeout=args.connect_timeout) as executor:
            result[key] = table(args.tasks, args.optimizers, args.seeds, args.trials,
                                args.targets, args.db, None, args.particles, executor,
                                args.evaluation)
    printed, notes = [], []
    if args.speed:
        printed += table_rows(result["speed"], "speed")
        notes.append(_speed_note(result["speed"]))
        print(notes[-1])
    if args.table:
        printed += table_rows(result[key], "task")
    run.finish(printed, result, args.out, notes=notes)
    print(f"wrote {run.output(args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
