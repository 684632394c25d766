"""Efficiency at scale: many threaded Dask workers running sleep trials through the runner and log.

A big cluster is stood in for by a ``distributed.LocalCluster`` with
``processes=False`` (scheduler, workers and client in this process, one
thread per worker slot): its trials are ``time.sleep(T)`` (``T`` = 0.05,
0.5, 1 s), which hold no core and no GIL, so what is measured is the
project's path for a trial on a cluster: ``run_experiment`` (random search:
ask, three trial writes in the SQLite log with group commits, tell), the
:class:`~handle_drake.learning.cluster.DaskExecutor` bridge, and Dask's
client, scheduler and worker machinery, with ``W`` = 8, 32 and 128 worker
threads (``W/8`` workers of 8 threads; ``worker-saturation`` 1.0 as our
LocalCluster). Each case runs ``--waves`` x ``W`` trials: ideally
``waves x T`` s, so

    efficiency = (trials x T) / (elapsed x W)

(1.0: every worker slept from the start to the end). Cases alternate in
order every round (``--rounds``), the load average is kept with each.

Where the bound comes from: for every case the CPU time of each thread of
this process is read from ``/proc/self/task`` before and after and grouped:
``client loop`` (the runner's thread: ask, log, tell, waiting), ``dask loop``
(the event loop thread that runs the scheduler, the workers' and the
client's comms), ``dask callbacks`` (Dask's thread that hands results to the
runner), ``trial threads`` (the workers' executors: the sleeps and their
wrappers), ``other``; divided by the trials it is the per-task cost of each.
All of it shares one GIL here, so the per-trial sum is the serial cost
``c``, and the ceiling is ``1 / c`` trials/s per core this process gets.
The log's own share is measured alone (``log grouped``: the three writes of
a trial in group commits, no optimiser, no executor).

Paper extrapolation to 1000 workers: on a real cluster the scheduler is its
own process and the client another; a run of ``W`` workers with trials of
``T`` s needs ``W / T`` trials/s, and each serial resource caps it at
``1 / (its CPU per task)``. With the per-task costs measured here
(the dask loop stands for scheduler + comms, the client loop + callbacks for
the client process) the predicted efficiency is
``min(1, cap x T / W)`` for the tightest cap; the table prints it for
W = 128 and 1000 and T = 0.05 ... 1 s, beside the measured 128.

Diagnosis of the scheduler's hand-off: ``--saturation 1.0 1.25`` runs every case with each
``distributed.scheduler.worker-saturation`` (1.0: a worker thread that finishes waits for
the scheduler to send it the next queued task; 1.25: each 8-thread worker also holds 2
tasks of its own to start at once), interleaved in each round; ``--workers`` and
``--seconds`` restrict the cases.

Several trials per Dask task: ``--chunk 1 2 4`` runs every case with each
:class:`~handle_drake.learning.cluster.DaskExecutor` ``chunk`` (trials per task; the runner
then keeps ``2 x W x chunk`` trials in flight), interleaved in each round on the same cluster.
The central CPU per trial (client loop + dask loop + callbacks) is the figure to compare: it
is less sensitive to the machine's load than the efficiency.

Run: ``python benchmarks/bench_scale.py [--quick] [--workers W ..] [--seconds T ..]
[--saturation S ..] [--chunk C ..]``; prints the tables, writes ``benchmarks/results/scale.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import platform
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas

pin_blas(force=False)

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning import TrialLog, run_experiment  # noqa: E402
from handle_drake.learning.cluster import QUIET_WORKER, DaskExecutor  # noqa: E402
from handle_drake.learning.loop import COMMIT_EVERY, COMMIT_SECONDS  # noqa: E402

BOUNDS = [[-1.0, 1.0], [-1.0, 1.0]]
WORKERS = (8, 32, 128)
SECONDS = (0.05, 0.5, 1.0)
THREADS_PER_WORKER = 8
_TICK = os.sysconf("SC_CLK_TCK")


class SleepTrial:
    """A trial that sleeps ``seconds`` and returns 0 (holds neither a core nor the GIL)."""

    def __init__(self, seconds):
        self.seconds = seconds
        self.name = f"sleep{seconds:g}"

    def __call__(self, x):
        time.sleep(self.seconds)
        return 0.0


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _thread_cpu() -> dict[int, float]:
    """CPU seconds (user + system) of each thread of this process, by native id."""
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        out[int(tid)] = (int(fields[11]) + int(fields[12])) / _TICK
    return out


def _group(name: str, main_id: int, native_id: int) -> str:
    if native_id == main_id:
        return "client loop"
    if name.startswith("Dask-Callback"):
        return "dask callbacks"
    if name.startswith("Dask-Default-Threads") or name.startswith("ThreadPoolExecutor"):
        return "trial threads"
    if "IO loop" in name or "loop" in name.lower():
        return "dask loop"
    return "other"


GROUPS = ("client loop", "dask loop", "dask callbacks", "trial threads", "other")


def _cpu_by_group(before, after, names) -> dict[str, float]:
    main_id = threading.main_thread().native_id
    total = dict.fromkeys(GROUPS, 0.0)
    for tid, seconds in after.items():
        total[_group(names.get(tid, ""), main_id, tid)] += seconds - before.get(tid, 0.0)
    return total


@contextlib.contextmanager
def _cluster(workers: int, saturation: float = 1.0):
    import dask
    from distributed import Client, LocalCluster

    config = {"distributed.scheduler.worker-saturation": saturation, **QUIET_WORKER}
    with dask.config.set(config):
        n = max(1, workers // THREADS_PER_WORKER)
        cluster = LocalCluster(n_workers=n, threads_per_worker=workers // n, processes=False,
                               dashboard_address=None, silence_logs=logging.ERROR,
                               scheduler_kwargs={"dashboard": False})
        client = Client(cluster)
        try:
            yield DaskExecutor(client)
        finally:
            client.close()
            cluster.close()


def _case(executor, folder, workers, seconds, waves) -> dict:
    n = waves * workers
    objective = SleepTrial(seconds)
    db = Path(folder) / f"w{workers}-t{seconds:g}-{time.monotonic_ns()}.sqlite"
    load = _load()
    cpu_before = _thread_cpu()
    start = time.perf_counter()
    result = run_experiment(objective, BOUNDS, "random", n, 0, db, executor=executor,
                            progress=False, objective_name=objective.name)
    elapsed = time.perf_counter() - start
    names = {t.native_id: t.name for t in threading.enumerate()}
    cpu = _cpu_by_group(cpu_before, _thread_cpu(), names)
    assert result.n_done == n, result
    return dict(workers=workers, seconds=seconds, trials=n, elapsed=elapsed,
                efficiency=n * seconds / (elapsed * workers), load=load,
                # the share of a core this process got: its CPU over the case's wall time
                core_share=sum(cpu.values()) / elapsed,
                cpu_per_trial_ms={k: 1e3 * v / n for k, v in cpu.items()})


def _log_only(folder, n=3000) -> float:
    """CPU ms per trial of the log alone (three writes a trial, group commits)."""
    with TrialLog(Path(folder) / f"log-{time.monotonic_ns()}.sqlite") as log:
        log.create_run("r", "random", BOUNDS, 0, "noop")
        cpu = time.process_time()
        with log.grouped(COMMIT_EVERY, COMMIT_SECONDS):
            for i in range(n):
                log.add_pending("r", i, [0.0, 0.0], i, running=True)
                log.mark_done("r", i, 0.0, wall_time=0.0)
        return 1e3 * (time.process_time() - cpu) / n


def _median(values):
    return statistics.median(values) if values else float("nan")


def extrapolate(costs_ms: dict, workers, seconds) -> dict:
    """Predicted efficiency from per-task costs: min(1, cap x T / W) for the tightest cap.

    Caps (trials/s): the scheduler's process (the dask loop per task) and the
    client's (client loop + callbacks per task), each on a core of its own, as
    on a real cluster; ``single process``: all of it on one core (this benchmark)."""
    serial = {"scheduler process": costs_ms["dask loop"],
              "client process": costs_ms["client loop"] + costs_ms["dask callbacks"]}
    serial["single process"] = sum(serial.values()) + costs_ms["other"]
    out = {}
    for w in workers:
        for t in seconds:
            need = w / t
            caps = {k: 1e3 / v for k, v in serial.items() if v > 0}
            split = {k: v for k, v in caps.items() if k != "single process"}
            bound = min(split, key=split.get)
            out[f"{w}|{t:g}"] = dict(
                needed_per_s=need, bound=bound, cap_per_s=split[bound],
                efficiency=min(1.0, split[bound] / need),
                efficiency_one_process=min(1.0, caps["single process"] / need))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one round, two waves")
    parser.add_argument("--rounds", type=int, default=None, help="rounds (default 2, quick 1)")
    parser.add_argument("--waves", type=int, default=None,
                        help="trials per case = waves x workers (default 6, quick 3)")
    parser.add_argument("--workers", type=int, nargs="+", default=list(WORKERS),
                        help=f"worker threads per case (default {' '.join(map(str, WORKERS))})")
    parser.add_argument("--seconds", type=float, nargs="+", default=list(SECONDS),
                        help="trial seconds per case (default "
                             f"{' '.join(f'{t:g}' for t in SECONDS)})")
    parser.add_argument("--saturation", type=float, nargs="+", default=[1.0],
                        help="Dask worker-saturation values, each case with each (default 1.0)")
    parser.add_argument("--chunk", type=int, nargs="+", default=[1],
                        help="trials per Dask task, each case with each (default 1)")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "scale.json")
    add_page_arguments(parser, "scale", published={"quick": False, "rounds": 3, "waves": 16})
    args = parser.parse_args(argv)
    for name in ("workers", "seconds", "saturation", "chunk"):
        if any(not v > 0 for v in getattr(args, name)):
            parser.error(f"--{name}: expected values > 0, got {getattr(args, name)}")
    workers_list, seconds_list, saturations = args.workers, args.seconds, args.saturation
    chunks = args.chunk
    if any(int(c) != c for c in chunks):
        parser.error(f"--chunk: expected integers >= 1, got {chunks}")
    results_run = ResultsRun("Scaling the trial executor: efficiency per workers and trial time",
                             args)
    rounds = args.rounds or (1 if args.quick else 2)
    waves = args.waves or (3 if args.quick else 6)
    print(f"bench_scale: {rounds} round(s), {waves} waves a case, {THREADS_PER_WORKER} "
          f"threads a worker, load average {_load()} ({os.cpu_count()} cpus)", flush=True)
    cases: list[dict] = []
    log_ms = []
    with tempfile.TemporaryDirectory() as folder:
        for r in range(rounds):
            for workers, saturation in ([(w, z) for w in workers_list for z in saturations]
                                        if r % 2 == 0 else
                                        [(w, z) for w in workers_list[::-1]
                                         for z in saturations[::-1]]):
                with _cluster(workers, saturation) as executor:
                    # warm up: the objective reaches every worker, threads start
                    run_experiment(SleepTrial(0.01), BOUNDS, "random", 2 * workers, 1,
                                   Path(folder) / f"warm-{workers}-{r}.sqlite",
                                   executor=executor, progress=False, objective_name="warm")
                    for seconds, chunk in [
                            (t, k) for t in (seconds_list if r % 2 == 0 else seconds_list[::-1])
                            for k in (chunks if r % 2 == 0 else chunks[::-1])]:
                        case = _case(DaskExecutor(executor.client, chunk), folder, workers,
                                     seconds, waves)
                        case["round"] = r + 1
                        case["saturation"] = saturation
                        case["chunk"] = chunk
                        cases.append(case)
                        c = case["cpu_per_trial_ms"]
                        print(f"  round {r + 1}: W={workers:4d} T={seconds:5.2f} s "
                              f"saturation {saturation:g} chunk {chunk}: "
                              f"efficiency {case['efficiency']:.3f} ({case['trials']} trials, "
                              f"{case['elapsed']:.2f} s, load {case['load']}, "
                              f"{case['core_share']:.2f} core); CPU ms/trial "
                              + ", ".join(f"{k} {v:.2f}" for k, v in c.items()), flush=True)
            log_ms.append(_log_only(folder))

    print("\n| workers | trial s | saturation | chunk | efficiency (median) | rounds | load |"
          " core share | client loop ms/trial | dask loop | callbacks | trial threads |"
          " central ms/trial |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    table = {}
    for w, t, z, k in [(w, t, z, k) for w in workers_list for t in seconds_list
                       for z in saturations for k in chunks]:
        mine = [c for c in cases if c["workers"] == w and c["seconds"] == t
                and c["saturation"] == z and c["chunk"] == k]
        eff = [c["efficiency"] for c in mine]
        cost = {g: _median([c["cpu_per_trial_ms"][g] for c in mine]) for g in GROUPS}
        share = _median([c["core_share"] for c in mine])
        # keyed as before for the default saturation (1.0)
        key = f"{w}|{t:g}" + ("" if z == 1.0 else f"|saturation {z:g}") + (
            "" if k == 1 else f"|chunk {k}")
        # central: the serial CPU per trial (all but the sleeping trial threads)
        central = _median([sum(v for g, v in c["cpu_per_trial_ms"].items()
                               if g != "trial threads") for c in mine])
        table[key] = dict(efficiency=_median(eff), rounds=eff,
                          load=[c["load"] for c in mine], core_share=share,
                          cpu_per_trial_ms=cost, central_ms_per_trial=central, saturation=z,
                          chunk=k)
        print(f"| {w} | {t:g} | {z:g} | {k} | {_median(eff):.3f} | "
              + " ".join(f"{e:.3f}" for e in eff)
              + f" | {'/'.join(str(c['load']) for c in mine)} | {share:.2f} | "
                f"{cost['client loop']:.2f} | "
                f"{cost['dask loop']:.2f} | {cost['dask callbacks']:.2f} | "
                f"{cost['trial threads']:.2f} | {central:.2f} |")
    # Per-task costs for the extrapolation: the 128-worker cases (most tasks in flight).
    big = [c for c in cases if c["workers"] == max(workers_list)
           and c["saturation"] == saturations[0] and c["chunk"] == chunks[0]]
    costs = {g: _median([c["cpu_per_trial_ms"][g] for c in big]) for g in GROUPS}
    costs["log (alone)"] = _median(log_ms)
    print(f"\nper-trial CPU ms at {max(workers_list)} workers, saturation {saturations[0]:g}, "
          f"chunk {chunks[0]} (median): "
          + ", ".join(f"{k} {v:.3f}" for k, v in costs.items()))
    paper = extrapolate(costs, (128, 1000), (0.05, 0.2, 0.5, 1.0))
    print("\n| workers | trial s | trials/s needed | bound | its cap /s | predicted efficiency"
          " | all on one core |")
    print("|---|---|---|---|---|---|---|")
    for key, p in paper.items():
        w, t = key.split("|")
        print(f"| {w} | {t} | {p['needed_per_s']:.0f} | {p['bound']} | {p['cap_per_s']:.0f} | "
              f"{p['efficiency']:.2f} | {p['efficiency_one_process']:.2f} |")
    result = dict(benchmark="scale", rounds=rounds, waves=waves, saturations=saturations,
                  chunks=chunks,
                  threads_per_worker=THREADS_PER_WORKER, commit_every=COMMIT_EVERY,
                  commit_seconds=COMMIT_SECONDS, cases=cases, table=table,
                  per_task_cpu_ms=costs, extrapolation=paper,
                  target="efficiency >= 0.9 at 128 workers, 0.5 s trials",
                  machine=dict(cpus=os.cpu_count(), python=sys.version.split()[0],
                               platform=platform.platform()))
    results_run.finish(
        [{"workers": int(k.split("|")[0]), "trial_s": float(k.split("|")[1]),
          "saturation": v["saturation"], "chunk": v["chunk"],
          "efficiency": v["efficiency"], "core_share": v["core_share"],
          "central ms/trial": v["central_ms_per_trial"],
          **{f"{g} ms/trial": c for g, c in v["cpu_per_trial_ms"].items()}}
         for k, v in table.items()], result, args.out)
    print(f"\nwritten to {args.out}")
    for key, row in table.items():
        if key.startswith(f"{max(WORKERS)}|0.5"):
            print(f"efficiency at {max(WORKERS)} workers, 0.5 s trials, saturation "
                  f"{row['saturation']:g}, chunk {row['chunk']}: {row['efficiency']:.3f} "
                  f"(target >= 0.9); central CPU {row['central_ms_per_trial']:.2f} ms/trial")
    return 0


if __name__ == "__main__":
    sys.exit(main())
