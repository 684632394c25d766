"""Logged trials per second: the SQLite trial log with group commits against a commit per write.

Cases, each once per round (``--rounds``), in the reverse order every other
round, each on a new database file in ``--folder`` (default: the system's
temporary folder, here on the same ext4 disk as the work tree, so fsync is
real):

- ``runner grouped``: ``run_experiment`` of a random search with a no-op
  trial (returns 0 at once) on the inline executor, the log in group commits
  (the default: a transaction per ``COMMIT_EVERY`` finished trials or
  ``COMMIT_SECONDS`` s): ask, three trial writes, evaluate, tell, per trial;
- ``runner per write``: the same with ``commit_every=None``, one transaction
  (one WAL fsync) per write, three per trial: the log before issue 34;
- ``log grouped`` / ``log per write``: the log alone (``add_pending``,
  ``mark_running``, ``mark_done`` per trial, no optimiser, no executor).

Reported: trials per second per case (median of rounds, with the range),
trials per CPU second of this process (what one idle core would give: on a
shared machine the wall-clock rate is this times the share of a core the
process got, and the waits for fsync), the
grouped/per-write ratio per round (the two ran back to back), and the load
average before each case. The target (issue 34): ``runner grouped`` >= 2000
logged trials per second on this machine.

Run: ``python benchmarks/bench_trial_log.py [--quick]``; prints the table,
writes ``benchmarks/results/trial_log.json``; its last line reads
``logged trials per second: N`` (runner grouped, median).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas

pin_blas(force=False)

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning import InlineExecutor, TrialLog, run_experiment  # noqa: E402
from handle_drake.learning.loop import COMMIT_EVERY, COMMIT_SECONDS  # noqa: E402

BOUNDS = [[-1.0, 1.0], [-1.0, 1.0]]
CASES = ("runner grouped", "runner per write", "log grouped", "log per write")


def noop(x) -> float:
    return 0.0


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _runner(folder, n, grouped) -> float:
    db = Path(folder) / f"runner-{grouped}-{time.monotonic_ns()}.sqlite"
    options = {} if grouped else {"commit_every": None}
    start, cpu = time.perf_counter(), time.process_time()
    result = run_experiment(noop, BOUNDS, "random", n, 0, db, executor=InlineExecutor(),
                            progress=False, objective_name="noop", **options)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    assert result.n_done == n, result
    return n / elapsed, n / cpu


def _log_only(folder, n, grouped) -> float:
    db = Path(folder) / f"log-{grouped}-{time.monotonic_ns()}.sqlite"
    with TrialLog(db) as log:
        log.create_run("noop", "random", BOUNDS, 0, "noop")
        start, cpu = time.perf_counter(), time.process_time()
        group = log.grouped(COMMIT_EVERY, COMMIT_SECONDS) if grouped else None
        if group is not None:
            group.__enter__()
        for i in range(n):
            log.add_pending("noop", i, [0.0, 0.0], i)
            log.mark_running("noop", i)
            log.mark_done("noop", i, 0.0, wall_time=0.0)
        if group is not None:
            group.__exit__(None, None, None)
        elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
        assert len(log.trials("noop", "done")) == n
    return n / elapsed, n / cpu


def _spread(values) -> dict:
    return dict(median=statistics.median(values), min=min(values), max=max(values))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer trials and rounds")
    parser.add_argument("--rounds", type=int, default=None, help="rounds (default 5, quick 2)")
    parser.add_argument("--folder", type=Path, default=None,
                        help="where the databases go (default: a temporary folder)")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "trial_log.json")
    add_page_arguments(parser, "trial_log", published={"quick": False, "rounds": 5})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Trial log: logged trials per second, grouped against per write",
                             args)
    rounds = args.rounds or (2 if args.quick else 5)
    n_grouped = 1000 if args.quick else 5000
    n_write = 100 if args.quick else 300  # ~3 fsyncs a trial: fewer, same rate
    sizes = {"runner grouped": n_grouped, "runner per write": n_write,
             "log grouped": n_grouped, "log per write": n_write}
    print(f"bench_trial_log: {rounds} round(s), groups of {COMMIT_EVERY} trials or "
          f"{COMMIT_SECONDS} s; load average {_load()} ({os.cpu_count()} cpus)", flush=True)
    samples: dict[str, list] = {c: [] for c in CASES}
    cpu_rates: dict[str, list] = {c: [] for c in CASES}
    loads: dict[str, list] = {c: [] for c in CASES}
    ratios: dict[str, list] = {"runner": [], "log": []}
    with tempfile.TemporaryDirectory(dir=args.folder) as folder:
        for r in range(rounds):
            order = CASES if r % 2 == 0 else CASES[::-1]
            got = {}
            for case in order:
                before = _load()
                kind, grouped = case.split()[0], case.endswith("grouped")
                run = _runner if kind == "runner" else _log_only
                got[case], per_cpu = run(folder, sizes[case], grouped)
                samples[case].append(got[case])
                cpu_rates[case].append(per_cpu)
                loads[case].append(before)
                print(f"  round {r + 1}: {case:17s} {got[case]:9.1f} trials/s, "
                      f"{per_cpu:9.1f} per CPU second ({sizes[case]} trials, load {before})",
                      flush=True)
            for kind in ratios:
                ratios[kind].append(got[f"{kind} grouped"] / got[f"{kind} per write"])

    table = {c: dict(_spread(samples[c]), per_cpu_second=_spread(cpu_rates[c]),
                     load=_spread(loads[c])) for c in CASES}
    print("\n| case | trials/s median | min | max | per CPU second (median) | load (median) |")
    print("|---|---|---|---|---|---|")
    for c in CASES:
        t = table[c]
        print(f"| {c} | {t['median']:.0f} | {t['min']:.0f} | {t['max']:.0f} | "
              f"{t['per_cpu_second']['median']:.0f} | {t['load']['median']:.2f} |")
    for kind, values in ratios.items():
        s = _spread(values)
        print(f"{kind}: grouped / per write = {s['median']:.1f}x "
              f"(rounds {s['min']:.1f}-{s['max']:.1f})")
    result = dict(
        benchmark="trial_log", rounds=rounds, trials=sizes, commit_every=COMMIT_EVERY,
        commit_seconds=COMMIT_SECONDS, samples=samples, per_cpu_second=cpu_rates, loads=loads,
        ratios=ratios,
        table=table, target="runner grouped >= 2000 logged trials/s",
        machine=dict(cpus=os.cpu_count(), python=sys.version.split()[0],
                     platform=platform.platform()))
    results_run.finish([{"case": c, "trials/s median": t["median"], "min": t["min"],
                         "max": t["max"], "per CPU second (median)": t["per_cpu_second"]["median"],
                         "load (median)": t["load"]["median"]} for c, t in table.items()],
                       result, args.out)
    print(f"\nwritten to {results_run.output(args.out)}")
    print(f"per-write commit rate (before issue 34), same run: "
          f"{table['runner per write']['median']:.0f} trials/s")
    print(f"logged trials per second: {table['runner grouped']['median']:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
