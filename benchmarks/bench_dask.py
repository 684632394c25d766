"""Trials per second on the local process pool and on Dask, 1 and 2 workers, side by side.

Workloads (each case once per round, ``--rounds`` rounds; the executors are
opened afresh every round (new worker processes: the same trials' CPU time
differs by about 15 % from one process to another here) and warmed up, so
every worker has built its diagram before the clock starts; within a round
each workload runs on the four executors back to back, local and Dask
alternating, in the reverse order every other round:
local x1, Dask x1, local x2, Dask x2, then Dask x2, local x2, Dask x1, local x1):

- ``random``: a random-search run of real grasp trials (Barrett hand,
  sphere, 2-D offset: ``handle-drake babble --strategy random``) through
  ``run_experiment``, SQLite log included;
- ``pso``: a "PSO iteration" as the optimiser sees it, a batch of ``K``
  independent grasp trials submitted together and waited for, ``--iterations``
  times;
- ``inhand_pso``: the in-hand PSO itself (Algorithm 2, ``handle-drake inhand
  --optimizer ipso``: cylinder rotation, ``K`` particles, ``--iterations``
  iterations) through ``run_inhand``, SQLite log included; its trials take
  0.2-2 s (the early stop of eqs. 47-49), so an iteration waits for its
  slowest particle;
- ``noop``: the floor, a trial that returns at once, through the bare
  executor (submit + result) and through ``run_experiment`` (plus the ask,
  the three SQLite transactions of a trial and the tell);
- ``hardware``: the machine's own ceiling, no executor and no project
  scheduling: one process, then two at once, each running the same list of
  grasp trials in a loop after building its diagram. Its efficiency (one
  process's time over the slower of two) is what two cores give two
  independent trial loops; no executor can beat it.

Reported: trials/s per case (median of the rounds), parallel efficiency =
(trials/s at 2 workers / trials/s at 1) / 2 per executor and Dask / local per
workload and worker count, each the median of its per-round ratios (the two
cases of a ratio ran next to each other) with their range; the workers' busy
fraction (the trials' own wall time over the case's time x workers: what the
executor and the runner leave idle); Dask's per-task overhead against the
local pool (no-op seconds per task), and what the scheduler's per-task cost
implies for 100 workers with trials of 0.1 s and 3 s. The machine's load
average is recorded with every case: other processes on a small machine
depress the efficiency (two workers need two idle cores).

Targets (issue 14): Dask within 10 % of the local pool; efficiency at 2
workers >= 0.85 for random search and for a PSO iteration.

Run: ``python benchmarks/bench_dask.py [--quick]``; prints the table and
writes ``benchmarks/results/dask.json``; ``--summarise FILE.json`` prints the
table of a saved run again.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from concurrent.futures import wait
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.apps.babbling.babbling import CachedTrial  # noqa: E402
from handle_drake.apps.inhand.experiment import run_inhand  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning import run_experiment  # noqa: E402
from handle_drake.learning.cluster import LocalPool, trial_executor  # noqa: E402
from handle_drake.learning.executors import TrialResult, _evaluate  # noqa: E402
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig  # noqa: E402

CONFIG = GraspTrialConfig(hand="barrett", object="sphere", space="offset")
EXECUTORS = ("local", "dask")
WORKERS = (1, 2)


def noop(x, seed: int = 0) -> float:
    """The floor: a trial that costs nothing."""
    return 0.0


class ThreadClock:
    """``objective`` that also reports the CPU seconds of the thread that ran the trial.

    The trial's wall time over that CPU time is what the trial lost inside its
    process, waiting: for the GIL (a Dask worker's event loop runs beside it),
    or for a core (other processes on a loaded machine).
    """

    def __init__(self, objective):
        self.objective = objective

    def __call__(self, x, seed: int = 0):
        start = time.thread_time()
        value = self.objective(x, seed=seed)
        cpu = time.thread_time() - start
        result = value if isinstance(value, TrialResult) else TrialResult(value)
        return TrialResult(result.metric, {"cpu": cpu, "contacts": result.contacts},
                           result.scenario)


def _load() -> float:
    return round(os.getloadavg()[0], 2)


class Case:
    """One case's outcome: trials/s, the workers' busy fraction and the trials' wall
    time over their threads' CPU time, less 1 (None: not measured)."""

    def __init__(self, n_trials, elapsed, trial_seconds=None, workers=1, cpu_seconds=None):
        self.tps = n_trials / elapsed
        self.busy = None if trial_seconds is None else trial_seconds / (elapsed * workers)
        self.wait = None if not cpu_seconds else trial_seconds / cpu_seconds - 1


def _cpu(contacts) -> float:
    """The thread CPU seconds a :class:`ThreadClock` trial reported (JSON text or dict)."""
    if isinstance(contacts, str):
        contacts = json.loads(contacts)
    return contacts["cpu"] if isinstance(contacts, dict) and "cpu" in contacts else 0.0


def _random_run(executor, objective, bounds, n_trials, tag, workers) -> Case:
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        result = run_experiment(objective, bounds, "random", n_trials, 0,
                                Path(folder) / "t.sqlite", executor=executor, progress=False,
                                run_id=tag)
        elapsed = time.perf_counter() - start
    return Case(n_trials, elapsed, sum(r.wall_time for r in result.trials), workers,
                sum(_cpu(r.contacts) for r in result.trials))


def _pso_iterations(executor, objective, bounds, k, iterations, seed, workers=1) -> Case:
    rng = np.random.default_rng(seed)
    shipped = executor.ship(objective) if hasattr(executor, "ship") else objective
    busy = cpu = 0.0
    start = time.perf_counter()
    for _ in range(iterations):
        swarm = rng.uniform(bounds[:, 0], bounds[:, 1], size=(k, len(bounds)))
        futures = [executor.submit(_evaluate, shipped, x, seed, True) for x in swarm]
        wait(futures)
        for future in futures:
            assert future.result()["status"] == "done", future.result().get("error")
            busy += future.result()["wall_time"]
            cpu += _cpu(future.result()["contacts"])
    return Case(k * iterations, time.perf_counter() - start, busy, workers, cpu)


def _inhand_pso(executor, k, iterations, seed, workers=1) -> Case:
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        run = run_inhand("cylinder_rotation", "ipso", k * iterations, None, seed,
                         Path(folder) / "t.sqlite", k, progress=False, executor=executor)
        elapsed = time.perf_counter() - start
    assert all(r.status == "done" for r in run.records), [r.error for r in run.records]
    return Case(len(run.records), elapsed, sum(r.wall_time for r in run.records), workers)


def _bare_noop(executor, n_tasks) -> Case:
    shipped = executor.ship(noop) if hasattr(executor, "ship") else noop
    x = np.zeros(2)
    start = time.perf_counter()
    futures = [executor.submit(_evaluate, shipped, x, 0, True) for _ in range(n_tasks)]
    wait(futures)
    return Case(n_tasks, time.perf_counter() - start)


def _hardware_loop(config, xs, barrier, results):
    """One process of the hardware floor: build, wait for the others, time the loop."""
    pin_blas()
    objective = CachedTrial(config)
    objective(xs[0], seed=0)  # builds the diagram before the clock starts
    barrier.wait()
    start = time.perf_counter()
    for i, x in enumerate(xs):
        objective(x, seed=i)
    results.put(time.perf_counter() - start)


def _hardware(processes: int, xs) -> float:
    """Trials/s of ``processes`` independent trial loops (each runs all of ``xs``).

    A loop process that dies stops the measurement at once (its partners, waiting
    at the barrier, are terminated) instead of leaving them waiting for ever.
    """
    import multiprocessing
    import queue

    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(processes), ctx.Queue()
    procs = [ctx.Process(target=_hardware_loop, args=(CONFIG, xs, barrier, results))
             for _ in range(processes)]
    for proc in procs:
        proc.start()
    times = []
    try:
        while len(times) < processes:
            try:
                times.append(results.get(timeout=1.0))
            except queue.Empty:
                failed = [proc.exitcode for proc in procs if proc.exitcode not in (None, 0)]
                if failed:
                    raise RuntimeError(f"hardware floor: a loop process exited with "
                                       f"{failed[0]}") from None
    finally:
        for proc in procs:
            if len(times) < processes:
                proc.terminate()
            proc.join()
    if any(proc.exitcode != 0 for proc in procs):
        raise RuntimeError(f"hardware floor: a loop process exited with "
                           f"{[proc.exitcode for proc in procs]}")
    return processes * len(xs) / max(times)


WORKLOADS = ("random", "pso", "inhand_pso", "noop_executor", "noop_runner")
RUNNER_IN_FLIGHT = 4  # random search at 2 workers: a trial running and one queued per worker


def _spread(values) -> dict:
    return dict(median=statistics.median(values), min=min(values), max=max(values))


def _paired(samples: dict, top: tuple, bottom: tuple, scale=1.0) -> list:
    """Per-round ratios top / bottom (rounds paired by position), times ``scale``."""
    return [a / b * scale for a, b in zip(samples[top], samples[bottom], strict=False)]


def summarise(samples: dict, loads: dict, busy: dict | None = None,
              in_flight: int = RUNNER_IN_FLIGHT, wait: dict | None = None) -> dict:
    """The table, the overheads and the 100-worker projection from per-case samples
    (``{(workload, executor, workers): [trials/s per round]}``) and, when given, the
    workers' busy fractions and the trials' waits per round; prints them.
    ``in_flight``: the runner's trials in flight in the no-op runner case at 2
    workers (4; 2 before the runner queued a trial per worker)."""
    busy, wait = busy or {}, wait or {}
    median = {key: statistics.median(values) for key, values in samples.items()}
    rows = []
    for name in (*WORKLOADS, "hardware"):
        for kind in (("none",) if name == "hardware" else EXECUTORS):
            if (name, kind, 1) not in median:  # a saved run from before the floor
                continue
            one, two = median[(name, kind, 1)], median[(name, kind, 2)]
            efficiency = _spread(_paired(samples, (name, kind, 2), (name, kind, 1), 0.5))
            ratios = {}
            for w in WORKERS:
                local = (name, "local", w)
                ratios[w] = (_spread(_paired(samples, (name, kind, w), local))
                             if local in samples else _spread([1.0]))
            rows.append(dict(
                workload=name, executor=kind, tps_1=one, tps_2=two,
                efficiency_2=efficiency["median"], vs_local_1=ratios[1]["median"],
                vs_local_2=ratios[2]["median"], load=loads[(name, kind, 2)],
                efficiency_2_range=[efficiency["min"], efficiency["max"]],
                vs_local_1_range=[ratios[1]["min"], ratios[1]["max"]],
                vs_local_2_range=[ratios[2]["min"], ratios[2]["max"]],
                **{f"busy_{w}": statistics.median(busy[(name, kind, w)])
                   for w in WORKERS if busy.get((name, kind, w))},
                **{f"wait_{w}": statistics.median(wait[(name, kind, w)])
                   for w in WORKERS if wait.get((name, kind, w))}))
    overhead = {w: 1 / median[("noop_executor", "dask", w)]
                - 1 / median[("noop_executor", "local", w)] for w in WORKERS}
    # The scheduler handles tasks one after another: its cost per task (the
    # no-op seconds per task at 2 workers, 1000 tasks in flight; an upper bound:
    # it includes the client and the workers' share of two cores) caps the
    # cluster's rate. The runner does its part of every trial (ask, the three
    # SQLite transactions, tell) one after another in the client: its cost is
    # the no-op trial through the runner on the local pool (whose own cost is
    # ~0.4 ms). With 100 workers 100 trials are in flight, so these costs are
    # capacities; the no-op runner on Dask (``in_flight`` trials in flight) gives
    # a trial's latency through the runner.
    per_task = 1 / median[("noop_executor", "dask", 2)]
    per_trial_client = 1 / median[("noop_runner", "local", 2)]
    per_trial_latency = 1 / median[("noop_runner", "dask", 2)] * in_flight
    projection = {}
    for trial_s in (0.1, 3.0):
        demand = 100 / trial_s  # tasks/s that 100 busy workers need
        for label, cost in (("scheduler", per_task), ("runner", per_trial_client),
                            ("both", max(per_task, per_trial_client))):
            projection[f"{trial_s:g}s_{label}"] = dict(
                tasks_per_s_needed=demand, capacity_tasks_per_s=1 / cost,
                utilisation=demand * cost, efficiency_bound=min(1.0, 1 / (demand * cost)))

    print()
    print(f"{'workload':14s} {'executor':8s} {'1 worker':>10s} {'2 workers':>10s} "
          f"{'efficiency':>10s} {'/local x1':>10s} {'/local x2':>10s}  load (x2 cases)")
    for row in rows:
        print(f"{row['workload']:14s} {row['executor']:8s} {row['tps_1']:10.2f} "
              f"{row['tps_2']:10.2f} {row['efficiency_2']:10.2f} {row['vs_local_1']:10.3f} "
              f"{row['vs_local_2']:10.3f}  {row['load']}")
    print("\nPer-round spread (min-max of the paired ratios whose medians are above); the "
          "workers' busy fraction and the trials' wait (wall / thread CPU - 1), medians:")
    print(f"{'workload':14s} {'executor':8s} {'efficiency':>12s} {'/local x1':>12s} "
          f"{'/local x2':>12s} {'busy x1':>8s} {'busy x2':>8s} {'wait x1':>8s} {'wait x2':>8s}")
    for row in rows:
        spread = "  ".join(f"{row[key][0]:5.2f}-{row[key][1]:<5.2f}" for key in
                           ("efficiency_2_range", "vs_local_1_range", "vs_local_2_range"))
        busy_text = " ".join(f"{row[f'{k}_{w}']:8.3f}" if f"{k}_{w}" in row else f"{'':8s}"
                             for k in ("busy", "wait") for w in WORKERS)
        print(f"{row['workload']:14s} {row['executor']:8s} {spread} {busy_text}")
    print("\nDask overhead per task over the local pool (no-op): "
          + ", ".join(f"{w} worker(s) {overhead[w] * 1e3:+.2f} ms" for w in WORKERS))
    print(f"Dask per-task cost (no-op, 2 workers, pipelined): {per_task * 1e3:.2f} ms; the "
          f"runner's own cost per trial (ask, SQLite, tell): {per_trial_client * 1e3:.2f} ms; "
          f"a no-op trial's latency through the runner on Dask: "
          f"{per_trial_latency * 1e3:.2f} ms")
    for key, value in projection.items():
        print(f"100 workers, trials of {key.replace('_', ' ')}: need "
              f"{value['tasks_per_s_needed']:.0f}/s, capacity "
              f"{value['capacity_tasks_per_s']:.0f}/s, efficiency bound "
              f"{value['efficiency_bound']:.2f}")
    return dict(table=rows, dask_overhead_per_task_s=overhead, dask_per_task_s=per_task,
                runner_per_trial_s=per_trial_client, dask_trial_latency_s=per_trial_latency,
                projection_100_workers=projection)


def _order(round_index: int) -> list:
    """The four executors of a workload in one round: local and Dask alternate, each
    ratio's two cases are neighbours, and every other round runs the reverse order."""
    order = [(kind, workers) for workers in WORKERS for kind in EXECUTORS]
    return order if round_index % 2 == 0 else order[::-1]


def _open_executors(stack, objective, bounds) -> dict:
    """The four executors of a round (closed with ``stack``, in reverse order: each
    Dask executor holds its Dask settings while open), warmed up: every worker has
    built its diagram before the clock starts."""
    opened = {}
    for kind in EXECUTORS:
        for workers in WORKERS:
            # The local pool with 1 worker too (not the inline executor that
            # `--executor local --workers 1` gives): the same costs as with 2.
            if kind == "local":
                executor = LocalPool(workers)
                stack.callback(executor.shutdown, wait=True, cancel_futures=True)
            else:
                executor = stack.enter_context(trial_executor("dask", workers))
            opened[(kind, workers)] = executor
            _pso_iterations(executor, objective, bounds, 2 * workers, 2, seed=99)
            _inhand_pso(executor, 2 * workers, 1, seed=99)
            _bare_noop(executor, 20)
    return opened


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer trials and rounds")
    parser.add_argument("--rounds", type=int, default=None, help="rounds (default 3, quick 2)")
    parser.add_argument("--trials", type=int, default=None,
                        help="grasp trials per random-search case (default 60, quick 16)")
    parser.add_argument("--swarm", type=int, default=8, help="K: particles per PSO iteration")
    parser.add_argument("--iterations", type=int, default=None,
                        help="PSO iterations per case (default 6, quick 2)")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "dask.json")
    parser.add_argument("--summarise", type=Path, default=None, metavar="JSON",
                        help="print the table of a saved run (its samples) and exit")
    add_page_arguments(parser, "dask", published={"quick": False, "rounds": 3})
    args = parser.parse_args(argv)
    run = ResultsRun("Dask cluster against local workers: trials/s and efficiency", args)
    key = lambda text: (*text.split("|")[:2], int(text.split("|")[2]))  # noqa: E731
    if args.summarise is not None:
        saved = json.loads(args.summarise.read_text())
        summarise({key(k): v for k, v in saved["samples"].items()},
                  {key(k): v for k, v in saved["loads"].items()},
                  {key(k): v for k, v in saved.get("busy", {}).items()},
                  saved.get("runner_in_flight", 2),
                  {key(k): v for k, v in saved.get("wait", {}).items()})
        return 0
    rounds = args.rounds or (2 if args.quick else 3)
    n_random = args.trials or (16 if args.quick else 60)
    iterations = args.iterations or (2 if args.quick else 6)
    n_noop = 200 if args.quick else 1000
    objective = ThreadClock(CachedTrial(CONFIG))
    bounds = GraspTrial(CONFIG).bounds
    print(f"bench_dask: {GraspTrial(CONFIG).name}, {rounds} round(s), {n_random} random trials, "
          f"{iterations} PSO iterations of {args.swarm}, load average {_load()}", flush=True)

    samples: dict[tuple, list] = {}
    loads: dict[tuple, list] = {}
    busy: dict[tuple, list] = {}
    waits: dict[tuple, list] = {}
    floor_xs = np.random.default_rng(7).uniform(
        bounds[:, 0], bounds[:, 1], size=(max(4, n_random // 4), len(bounds)))
    for r in range(rounds):
        # Fresh worker processes every round: the same trials' CPU time moves by
        # about 15 % from one process to the next on this VM (a paired probe), so
        # executors kept for the whole run would pair the same two processes in
        # every round and the per-round ratios would not average that out.
        with contextlib.ExitStack() as stack:
            opened = _open_executors(stack, objective, bounds)
            for workers in WORKERS:
                before = _load()
                value = _hardware(workers, floor_xs)
                samples.setdefault(("hardware", "none", workers), []).append(value)
                loads.setdefault(("hardware", "none", workers), []).append([before, _load()])
                print(f"  round {r + 1}: {'hardware':14s} none  x{workers}: {value:8.2f} "
                      f"trials/s (load {before} -> {_load()})", flush=True)
            for name in WORKLOADS:
                for kind, workers in _order(r):
                    executor, tag = opened[(kind, workers)], f"{kind}{workers}-r{r}"
                    before = _load()
                    if name == "random":
                        outcome = _random_run(executor, objective, bounds, n_random, tag, workers)
                    elif name == "pso":
                        outcome = _pso_iterations(executor, objective, bounds, args.swarm,
                                                  iterations, r, workers)
                    elif name == "inhand_pso":
                        outcome = _inhand_pso(executor, args.swarm, iterations, r, workers)
                    elif name == "noop_executor":
                        outcome = _bare_noop(executor, n_noop)
                    else:
                        outcome = _random_run(executor, noop, bounds, n_noop // 4, "noop-" + tag,
                                              workers)
                    samples.setdefault((name, kind, workers), []).append(outcome.tps)
                    loads.setdefault((name, kind, workers), []).append([before, _load()])
                    if outcome.busy is not None and not name.startswith("noop"):
                        busy.setdefault((name, kind, workers), []).append(outcome.busy)
                    if outcome.wait is not None:
                        waits.setdefault((name, kind, workers), []).append(outcome.wait)
                    print(f"  round {r + 1}: {name:14s} {kind:5s} x{workers}: "
                          f"{outcome.tps:8.2f} trials/s"
                          + ("" if outcome.busy is None else f", busy {outcome.busy:.3f}")
                          + ("" if outcome.wait is None else f", wait {outcome.wait:.3f}")
                          + f" (load {before} -> {_load()})", flush=True)

    result = dict(
        benchmark="dask", config=str(CONFIG), rounds=rounds, random_trials=n_random,
        pso=dict(swarm=args.swarm, iterations=iterations), noop_tasks=n_noop,
        order="per round and workload: " + ", ".join(f"{k} x{w}" for k, w in _order(0))
              + "; reversed every other round",
        samples={"|".join(map(str, k)): v for k, v in samples.items()},
        loads={"|".join(map(str, k)): v for k, v in loads.items()},
        busy={"|".join(map(str, k)): v for k, v in busy.items()},
        wait={"|".join(map(str, k)): v for k, v in waits.items()},
        runner_in_flight=RUNNER_IN_FLIGHT,
        **summarise(samples, loads, busy, RUNNER_IN_FLIGHT, waits),
        targets=dict(dask_vs_local=">= 0.90",
                     efficiency_2=">= 0.85 (random, pso, inhand_pso)"),
        machine=dict(cpus=os.cpu_count(), python=sys.version.split()[0],
                     platform=platform.platform()))
    run.finish(result["table"], result, args.out)
    print(f"\nwritten to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
