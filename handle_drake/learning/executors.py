"""Where trials run: the objective contract, an inline executor and the default process pool.

An objective is ``f(x[, seed]) -> float | TrialResult``. :func:`_evaluate`
runs one trial and never raises an ``Exception`` (a failed trial is data).
The default pool is a ``ProcessPoolExecutor`` (spawn start method, which is
safe with Drake's threads) whose workers pin BLAS to one thread and receive
the objective once (the objective may build its simulation diagram on its
first call and reuse it). ``KeyboardInterrupt`` and ``SystemExit`` are not
caught; a worker process that dies breaks the pool: :class:`LocalPool`
replaces itself and the runner re-runs the trials (``WORKER_DEATHS``).
The executor chosen by name, and Dask for more machines: :mod:`.cluster`.
"""

from __future__ import annotations

import inspect
import json
import math
import multiprocessing
import os
import time
import traceback
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any

from handle_drake.base.blas import pin_blas
from handle_drake.base.orphans import init_worker


@dataclass
class TrialResult:
    """What an objective may return instead of a bare float.

    ``metric``: the value to maximise. ``contacts``: anything JSON
    serialisable (e.g. a list of contact points/normals/forces).
    ``scenario``: the full scenario text the trial ran, so it can be replayed.
    """

    metric: float
    contacts: Any = None
    scenario: str | None = None


class InlineExecutor(Executor):
    """Runs each submitted call at once in the calling thread (debugging, tests, real hands)."""

    def submit(self, fn, /, *args, **kwargs):
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as error:  # noqa: BLE001 - handed to the caller through the future
            future.set_exception(error)
        return future


_WORKER_OBJECTIVE = None


def _init_worker(objective):
    """Process-pool initializer: one BLAS thread per worker, objective received once."""
    global _WORKER_OBJECTIVE
    pin_blas()
    _WORKER_OBJECTIVE = objective


def _accepts_seed(objective) -> bool:
    try:
        return "seed" in inspect.signature(objective).parameters
    except (TypeError, ValueError):
        return False


def _evaluate(objective, x, seed, pass_seed):
    """Run one trial; never raises an ``Exception`` (returns it as a failure)."""
    start = time.perf_counter()
    outcome = {"status": "failed", "metric": None, "contacts": None, "scenario": None}
    try:
        value = objective(x, seed=seed) if pass_seed else objective(x)
        result = value if isinstance(value, TrialResult) else TrialResult(value)
        outcome["scenario"] = result.scenario
        try:
            metric = float(result.metric)
        except (TypeError, ValueError):
            raise TypeError(
                f"objective must return a number or a TrialResult, got {result.metric!r}"
            ) from None
        if result.contacts is not None:
            outcome["contacts"] = json.dumps(result.contacts)
        if math.isfinite(metric):
            outcome.update(status="done", metric=metric)
        else:
            outcome["error"] = f"objective returned a non-finite metric: {metric}"
    except Exception:  # noqa: BLE001 - a failed trial is data, not a crash of the run
        outcome["error"] = traceback.format_exc(limit=-8)
    outcome["wall_time"] = time.perf_counter() - start
    return outcome


def _evaluate_in_worker(x, seed, pass_seed):
    return _evaluate(_WORKER_OBJECTIVE, x, seed, pass_seed)


def _default_pool(objective, max_workers):
    return LocalPool(max_workers, initializer=_init_worker, initargs=(objective,))


# ------------------------------------------------------------------- pools
class ExecutorError(RuntimeError):
    """The executor cannot run trials (no scheduler, no workers, lost scheduler).

    The trial log is intact: the command resumes the run when repeated.
    """


def max_local_workers() -> int:
    """Most worker processes one machine runs: 4 per CPU core (at least 8).

    Trials are CPU-bound simulations: more processes than that only add
    memory (each imports Drake, ~250 MB), and ``--workers 100000`` would
    start processes until the machine runs out of memory.
    """
    return max(8, 4 * (os.cpu_count() or 1))


def _check_local_workers(workers) -> None:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if workers > max_local_workers():
        raise ValueError(f"workers: expected at most {max_local_workers()} worker processes "
                         f"on this machine (4 per CPU core), got {workers}")


class LocalPool(Executor):
    """A spawn process pool (one BLAS thread per worker) that replaces itself once broken.

    A worker that dies breaks a ``ProcessPoolExecutor`` for good; the runner
    re-runs the trials it lost (:data:`WORKER_DEATHS`), so the next
    :meth:`submit` starts a fresh pool.
    """

    def __init__(self, max_workers: int, initializer=pin_blas, initargs=()):
        _check_local_workers(max_workers)
        self.max_workers = max_workers
        self._initializer, self._initargs = initializer, initargs
        self._pool = None

    def submit(self, fn, /, *args, **kwargs):
        if self._pool is None:
            # Workers die with this process, even when it is killed with kill -9.
            self._pool = ProcessPoolExecutor(
                max_workers=self.max_workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=init_worker,
                initargs=(os.getpid(), self._initializer, self._initargs))
        try:
            return self._pool.submit(fn, *args, **kwargs)
        except BrokenProcessPool:  # a worker died: this pool takes no more work
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
            return self.submit(fn, *args, **kwargs)

    def shutdown(self, wait=True, *, cancel_futures=False):
        if self._pool is not None:
            self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)
            self._pool = None
