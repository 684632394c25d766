"""Where trials run: the objective contract, an inline executor and the default process pool.

An objective is ``f(x[, seed]) -> float | TrialResult``. :func:`_evaluate`
runs one trial and never raises an ``Exception`` (a failed trial is data).
The default pool is a ``ProcessPoolExecutor`` (spawn start method, which is
safe with Drake's threads) whose workers pin BLAS to one thread and receive
the objective once (the objective may build its simulation diagram on its
first call and reuse it). ``KeyboardInterrupt`` and ``SystemExit`` are not
caught; a worker process that dies breaks the pool: :class:`LocalPool`
replaces itself and the runner re-runs the trials (``WORKER_DEATHS``).
Executors for more processes and machines (Dask): :mod:`.cluster`.
"""

from __future__ import annotations

import inspect
import json
import math
import time
import traceback
from concurrent.futures import Executor, Future
from dataclasses import dataclass
from typing import Any

from handle_drake.base.blas import pin_blas
from handle_drake.learning.cluster import LocalPool


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
