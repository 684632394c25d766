"""Where the Dask event loop's CPU goes in the scale benchmark's case (issue 34, item 2).

Runs one case of ``bench_scale.py`` (default W = 128 worker threads, T = 0.5 s sleep trials,
10 waves) on the same in-process ``LocalCluster`` (``worker-saturation`` 1.0, the quiet
worker settings) with ``cProfile`` enabled in the event-loop thread only (the thread that
runs the scheduler, the in-process workers and every comm), and prints the loop's own time
(self time of its functions) grouped by where the code lives: the scheduler, the workers'
state machines, comms, asyncio/tornado, idle (waiting in ``epoll``); a built-in's or the
standard library's time goes to its callers' groups. cProfile slows the
loop (its CPU per trial reads ~1.7x the unprofiled benchmark's): read shares, not times.

Run: ``python benchmarks/bench_scale_loop_profile.py [--workers W] [--seconds T] [--waves N]``;
writes ``benchmarks/results/scale_loop_profile.json``.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import cProfile
import logging
import pstats
import sys
import tempfile
import threading
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_scale as bs  # noqa: E402 - pins BLAS, as every benchmark

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402

GROUPS = (
    ("idle (epoll wait)", lambda f, name: name == "<method 'poll' of 'select.epoll' objects>"),
    ("scheduler (distributed/scheduler.py)", lambda f, name: f.startswith("distributed/scheduler")),
    ("in-process workers (distributed/worker*.py)",
     lambda f, name: f.startswith("distributed/worker")),
    ("comms (distributed comm, core, protocol, batched)",
     lambda f, name: f.startswith(("distributed/comm", "distributed/core", "distributed/batched",
                                   "distributed/protocol"))),
    ("client and utils (distributed/client.py, utils.py)",
     lambda f, name: f.startswith(("distributed/client", "distributed/utils"))),
    ("other distributed", lambda f, name: f.startswith("distributed/")),
    ("asyncio, tornado, selectors",
     lambda f, name: any(k in f for k in ("tornado", "asyncio", "selectors"))),
    ("handle_drake (the bridge)", lambda f, name: "handle_drake" in f),
)


def _group(filename: str, name: str) -> str:
    f = filename.split("site-packages/")[-1]
    for group, match in GROUPS:
        if match(f, name):
            return group
    return OTHER


OTHER = "other (Python built-ins and stdlib)"


def _grouped(stats, depth: int = 4) -> collections.Counter:
    """Self time per group; the time of a built-in or stdlib function goes to the groups of
    its callers (in the shares cProfile records per caller), up to ``depth`` levels."""
    groups = collections.Counter()

    def assign(func, seconds, level):
        group = _group(func[0], func[2])
        callers = stats[func][4] if func in stats else {}
        if group != OTHER or level >= depth or not callers:
            groups[group] += seconds
            return
        total = sum(v[2] for v in callers.values())
        for caller, (_, _, tt, _) in callers.items():
            if total > 0:
                assign(caller, seconds * tt / total, level + 1)

    for func, (_, _, self_time, _, _) in stats.items():
        assign(func, self_time, 0)
    return groups


@contextlib.contextmanager
def _cluster(workers: int):
    import dask
    from distributed import Client, LocalCluster

    from handle_drake.learning.cluster import QUIET_WORKER, DaskExecutor

    config = {"distributed.scheduler.worker-saturation": 1.0, **QUIET_WORKER}
    with dask.config.set(config):
        n = max(1, workers // bs.THREADS_PER_WORKER)
        cluster = LocalCluster(n_workers=n, threads_per_worker=workers // n, processes=False,
                               dashboard_address=None, silence_logs=logging.ERROR,
                               scheduler_kwargs={"dashboard": False})
        client = Client(cluster)
        try:
            yield cluster, DaskExecutor(client)
        finally:
            client.close()
            cluster.close()


def _on_loop(cluster, fn) -> None:
    """Runs ``fn`` in the event-loop thread and waits for it."""
    done = threading.Event()
    cluster.loop.add_callback(lambda: (fn(), done.set()))
    if not done.wait(10):
        raise RuntimeError("the event loop did not run the callback within 10 s")


def main(argv=None) -> int:
    from handle_drake.learning import run_experiment

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=128)
    parser.add_argument("--seconds", type=float, default=0.5)
    parser.add_argument("--waves", type=int, default=10)
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "scale_loop_profile.json")
    add_page_arguments(parser, "scale", published={"workers": 128, "waves": 10})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Scale: where the Dask event loop's time goes", args)
    for name in ("workers", "seconds", "waves"):
        if not getattr(args, name) > 0:
            parser.error(f"--{name}: expected a value > 0, got {getattr(args, name)}")
    profile = cProfile.Profile()
    with tempfile.TemporaryDirectory() as folder, _cluster(args.workers) as (cluster, executor):
        run_experiment(bs.SleepTrial(0.01), bs.BOUNDS, "random", 2 * args.workers, 1,
                       Path(folder) / "warm.sqlite", executor=executor, progress=False,
                       objective_name="warm")
        _on_loop(cluster, profile.enable)
        case = bs._case(executor, folder, args.workers, args.seconds, args.waves)
        _on_loop(cluster, profile.disable)
    groups = _grouped(pstats.Stats(profile).stats)
    total = sum(groups.values())
    busy = total - groups["idle (epoll wait)"]
    print(f"W={args.workers} T={args.seconds:g} s, {case['trials']} trials: efficiency "
          f"{case['efficiency']:.3f} under the profiler, load {case['load']}; CPU ms/trial "
          + ", ".join(f"{k} {v:.2f}" for k, v in case["cpu_per_trial_ms"].items()))
    print("\n| the event loop's own time | s | share of the loop | share of its busy time |")
    print("|---|---|---|---|")
    for group, seconds in groups.most_common():
        busy_share = "" if group.startswith("idle") else f"{100 * seconds / busy:.0f} %"
        print(f"| {group} | {seconds:.2f} | {100 * seconds / total:.0f} % | {busy_share} |")
    rows = [{"group": group, "seconds": round(seconds, 3),
             "share_of_busy": "" if group.startswith("idle") else round(seconds / busy, 3)}
            for group, seconds in groups.most_common()]
    results_run.finish(rows, {"case": case, "loop_self_seconds": dict(groups),
                              "busy_seconds": busy}, args.out)
    print(f"\nwritten to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
