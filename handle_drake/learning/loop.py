"""A resumable trial runner: an optimiser asks, an executor evaluates, a :class:`TrialLog` keeps.

Resume semantics (no trial lost, none repeated):

1. Before a trial is evaluated its row is written as ``running`` when handed
   to the executor (parameters and trial seed; ``pending`` first for a
   re-run one), then
   ``done`` (metric) or ``failed`` (error). The writes are committed in
   groups (:meth:`TrialLog.grouped`: every ``commit_every`` finished trials or
   ``commit_seconds`` after the group's first write, whichever comes first),
   so the file always holds a prefix of the writes: a kill -9 loses at most
   the last group, whose trials rows 2-3 below run again.
2. On resume the optimiser is rebuilt by replaying ``tell``/``tell_failure``
   of the ``done``/``failed`` rows in trial order into a fresh optimiser with
   the run's seed and options (its state is a function of exactly that, see
   :mod:`handle_drake.learning.optim.bo`).
3. ``pending``/``running`` rows (the process died during their evaluation)
   are evaluated again, first, with their stored parameters and seed; the
   optimiser counts them as outstanding asks (``resume_pending``), so new
   proposals continue the original sequence. A proposal that was asked but
   whose row was never written is simply asked again, and the optimiser
   proposes the same point.

Failed trials: an objective that raises an ``Exception`` or returns a
non-finite metric (NaN, inf) gives a ``failed`` row with the error text; the
optimiser is told ``tell_failure`` and the run goes on. ``KeyboardInterrupt``
and ``SystemExit`` are not caught: the row stays ``running`` and is re-run on
resume. A worker process that dies (e.g. a segfault in a simulator) while
running a trial: the trial runs again (the runner re-runs it for a process
pool, Dask's scheduler for a Dask cluster), and after
:data:`~handle_drake.learning.cluster.WORKER_DEATHS` deaths it is ``failed``
with the reason. A trial that saw a pool die runs alone from then on (a pool
breaks for all the trials it runs at once), so its deaths are its own.

Parallelism: trials run through a ``concurrent.futures.Executor``. By default
a ``ProcessPoolExecutor`` (spawn start method, which is safe with Drake's
threads) whose workers pin BLAS to one thread and receive the objective once
(the objective may build its simulation diagram on its first call and reuse
it). Random search keeps twice as many trials in flight as there are
workers (one running and one queued per worker), each new trial submitted as
soon as one finishes. A ``distributed.Client`` (or its
``get_executor()``) is accepted as the executor, see
:mod:`handle_drake.learning.cluster`; an executor with a ``submit_many``
(Dask's) gets each fill of trials as one batch. Bayesian optimisation runs in synchronous
batches of its ``batch_size`` (1, sequential, by default): it proposes a batch,
waits for all of it and tells the results in trial order, so a run depends
only on its seed and options (not on which worker finished first) and a
resumed run completes the interrupted batch before asking for the next.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field

import numpy as np

from handle_drake.learning.cluster import WORKER_DEATHS, LocalPool, as_executor, executor_workers
from handle_drake.learning.executors import (
    InlineExecutor,
    _accepts_seed,
    _default_pool,
    _evaluate,
    _evaluate_in_worker,
)
from handle_drake.learning.log import TrialLog, TrialLogError, TrialRecord, check_group
from handle_drake.learning.optim.base import _derived_seed, check_bounds
from handle_drake.learning.optim.factory import make_optimizer

#: Default group commits of a run's log: a transaction per 256 finished trials, or 0.25 s
#: after its first write (benchmarks/bench_trial_log.py).
COMMIT_EVERY = 256
COMMIT_SECONDS = 0.25


@dataclass
class ExperimentResult:
    run_id: str
    best_x: np.ndarray | None
    best_y: float
    n_done: int
    n_failed: int
    converged: bool
    trials: list[TrialRecord] = field(repr=False, default_factory=list)


def replay(optimizer, records) -> list[TrialRecord]:
    """Rebuilds an optimiser's state from logged trials, in trial order; the one place it
    is done (resuming a run, and any later look at what the optimiser knew).

    ``done`` records are told their metric, ``failed`` ones told as failures,
    ``pending``/``running`` ones declared outstanding asks (``resume_pending``)
    and returned, to be evaluated again.
    """
    unfinished = []
    for record in records:
        if record.status == "done":
            optimizer.tell(record.parameters, record.metric)
        elif record.status == "failed":
            optimizer.tell_failure(record.parameters, record.error or "")
        else:
            optimizer.resume_pending(record.parameters)
            unfinished.append(record)
    return unfinished


class TrialRunner:
    """Evaluates an objective where an optimiser asks, logging each trial to a :class:`TrialLog`.

    Args:
        objective: ``f(x) -> float | TrialResult`` (``f(x, seed=...)`` if it
            has a ``seed`` parameter: each trial gets its own seed derived from
            the run seed and the trial index, so a noisy simulation replays).
            Must be picklable for the default process pool.
        optimizer: a fresh :class:`~handle_drake.learning.optim.base.Optimizer`
            built with the run's seed and options; its ``synchronous`` and
            ``batch_size`` say how trials may run in parallel.
        log, run_id: where the trials go; the run must exist in the log.
        executor: any ``concurrent.futures.Executor``; None for the default
            process pool of ``workers`` processes.
        workers: how many trials the executor runs at once. Default: the
            batch size of a synchronous optimiser, else ``batch_size`` if
            given, else ``os.cpu_count()`` for the default pool and 1 for a
            given executor.
        commit_every, commit_seconds: group commits of the log (see
            :meth:`TrialLog.grouped`): one transaction per ``commit_every``
            finished trials, at most ``commit_seconds`` after its first write.
            ``commit_every=None``: one transaction per write (each state
            change of each trial durable at once, ~3 fsyncs a trial).
        batch_size: trials in flight at once (default ``workers``, twice that
            for an optimiser without a batch size of its own, e.g. random
            search, on an executor other than the inline one: a trial waits
            queued for each worker); a synchronous optimiser fixes it to its
            own ``batch_size`` (give the same or None).
    """

    def __init__(
        self,
        objective,
        optimizer,
        log: TrialLog,
        run_id: str,
        executor=None,
        batch_size=None,
        progress=True,
        workers: int | None = None,
        commit_every: int | None = COMMIT_EVERY,
        commit_seconds: float = COMMIT_SECONDS,
    ):
        if not callable(objective):
            raise TypeError(f"objective must be callable, got {objective!r}")
        info = log.get_run(run_id)
        if info is None:
            raise ValueError(f"run {run_id!r} does not exist in {log.path}")

        executor = as_executor(executor)
        # BO and swarms (an optimiser with ``synchronous = True``) run in batches.
        synchronous = bool(optimizer.synchronous)
        if synchronous:
            q = optimizer.batch_size
            if batch_size is not None and batch_size != q:
                raise ValueError(
                    f"batch_size {batch_size} differs from the optimiser's batch_size {q}; "
                    f"a {type(optimizer).__name__} proposes batches of its own size (make it "
                    f"with batch_size={batch_size})"
                )
            batch_size = q
        for name, value in (("workers", workers), ("batch_size", batch_size)):
            if value is not None and (isinstance(value, bool) or not isinstance(
                    value, int | np.integer) or value < 1):
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if workers is None:
            if batch_size is not None:
                workers = batch_size
            else:
                workers = (max(1, os.cpu_count() or 1) if executor is None
                           else executor_workers(executor))
        if batch_size is None:
            batch_size = workers
            if optimizer.batch_size is None and not isinstance(executor, InlineExecutor):
                # Random search: a second trial queued per worker (in the pool's call
                # queue, on the Dask scheduler), so a worker starts it as soon as it
                # finishes one instead of idling while this process gets the result,
                # logs it and submits the next (measured: ~30 ms a trial on Dask).
                # An executor that runs several trials per task (a chunked
                # DaskExecutor) gets a chunk running and one queued per worker.
                batch_size = 2 * workers * getattr(executor, "chunk", 1)
        if commit_every is not None:
            check_group(commit_every, commit_seconds)
        self.commit_every, self.commit_seconds = commit_every, commit_seconds
        self.objective = objective
        self.optimizer = optimizer
        self.log = log
        self.run_id = run_id
        self.run_seed = info.seed
        self.batch_size = int(batch_size)
        self.synchronous = synchronous
        self.progress = progress
        self._executor = executor
        self._owns_executor = executor is None
        self._workers = workers
        self._pass_seed = _accepts_seed(objective)
        ship = getattr(executor, "ship", None)  # e.g. Dask: the objective once per worker
        self._shipped = objective if ship is None else ship(objective)
        self._deaths: dict[int, int] = {}  # trial index -> worker deaths while running it

    def _submit(self, x, seed) -> Future:
        if self._executor is None:
            self._executor = _default_pool(self.objective, self._workers)
        if self._owns_executor:
            return self._executor.submit(_evaluate_in_worker, x, seed, self._pass_seed)
        return self._executor.submit(_evaluate, self._shipped, x, seed, self._pass_seed)

    def _replay(self) -> tuple[list[TrialRecord], int]:
        records = self.log.trials(self.run_id)
        indices = [r.index for r in records]
        if indices != list(range(len(records))):
            raise TrialLogError(
                f"run {self.run_id!r}: trial indices are not 0..{len(records) - 1}"
                f" (got {indices[:10]}...)"
            )
        return replay(self.optimizer, records), len(records)

    def run(self, n_trials: int) -> ExperimentResult:
        """Run until the run holds ``n_trials`` finished trials (or the optimiser converges)."""
        if isinstance(n_trials, bool) or not isinstance(n_trials, int | np.integer) or n_trials < 0:
            raise ValueError(f"n_trials must be a non-negative integer, got {n_trials!r}")
        queue, next_index = self._replay()
        finished = next_index - len(queue)
        bar = _progress_bar(n_trials, finished, self.run_id, self.progress)
        group = (self.log.grouped(self.commit_every, self.commit_seconds)
                 if self.commit_every is not None else contextlib.nullcontext())
        try:
            with group:  # leaving it (an exception too) commits what was logged
                self._loop(n_trials, queue, next_index, bar)
        finally:
            bar.close()
            if self._owns_executor and self._executor is not None:
                self._executor.shutdown(wait=True, cancel_futures=True)
                self._executor = None
        return self.result()

    def _loop(self, n_trials, queue, next_index, bar) -> None:
        in_flight: dict[Future, TrialRecord] = {}
        untold: list = []  # (trial index, tell) of logged trials the optimiser has yet to see
        stop = False
        while True:
            # A synchronous (BO) batch starts only once the last one is in,
            # and an interrupted batch is finished on its own first.
            room = self.batch_size - len(in_flight)
            if self.synchronous:
                # A generational optimiser (a swarm) resumed in the middle of a
                # generation asks only for that generation's remaining members.
                room = 0 if in_flight else (len(queue) if queue else
                                             self.optimizer.batch_room)
            # An executor that takes a batch (Dask) gets the trials of this fill at once.
            many = None if self._owns_executor else getattr(self._executor, "submit_many", None)
            batch: list[TrialRecord] = []
            # One that runs several trials per task (a chunked DaskExecutor) gets the
            # first chunk at once and then 2, 4, ... chunks at a time, so the workers
            # start while the rest of a large fill (2 x W x chunk trials) is asked and logged.
            chunk = 1 if many is None else getattr(self._executor, "chunk", 1)
            send_at = chunk if chunk > 1 else None
            while room > 0 and (queue or (not stop and next_index < n_trials)):
                if queue and self._deaths.get(queue[0].index):
                    if in_flight or batch:  # it saw its pool die: it runs alone
                        break
                    room = 1
                room -= 1
                if queue:
                    record = queue.pop(0)
                    self.log.mark_running(self.run_id, record.index)
                else:
                    x = self.optimizer.ask()
                    if self.optimizer.converged:
                        stop = True
                        break
                    seed = _derived_seed(self.run_seed, next_index)
                    # written as running at once (pending -> running in one write)
                    self.log.add_pending(self.run_id, next_index, x, seed, running=True)
                    record = TrialRecord(self.run_id, next_index, x, "running", seed)
                    next_index += 1
                if many is None:
                    in_flight[self._submit(record.parameters, record.seed)] = record
                else:
                    batch.append(record)
                    if send_at is not None and len(batch) >= send_at:
                        self._send_many(many, batch, in_flight)
                        batch, send_at = [], 2 * send_at
            if batch:
                self._send_many(many, batch, in_flight)
            if not in_flight:
                break
            # Woken when the log's group is due too, so a finished trial is on
            # disk at most commit_seconds after it came in, however long the rest run.
            completed, _ = wait(list(in_flight), timeout=self.log.due_in(),
                                return_when=FIRST_COMPLETED)
            self.log.commit_if_due()
            for future in sorted(completed, key=lambda f: in_flight[f].index):
                record = in_flight.pop(future)
                # Logged at once (committed with its group: nothing is lost if
                # the batch is killed); a synchronous batch is told in trial
                # order once complete.
                tell = self._finish(record, future)
                if tell is None:  # its worker died: it runs again
                    queue = sorted([*queue, record], key=lambda r: r.index)
                    continue
                untold.append((record.index, tell))
                bar.update(1)
            if not self.synchronous or not (in_flight or queue):
                for _, tell in sorted(untold, key=lambda item: item[0]):
                    tell()
                untold.clear()
                best = None if bar.disable else self.optimizer.best  # O(trials): if shown
                if best is not None:
                    bar.set_postfix(best=f"{best.y:.4g}")

    def _send_many(self, many, batch, in_flight) -> None:
        futures = many(functools.partial(_evaluate, self._shipped),
                       [r.parameters for r in batch], [r.seed for r in batch],
                       [self._pass_seed] * len(batch))
        in_flight.update(zip(futures, batch, strict=True))

    def _finish(self, record: TrialRecord, future: Future):
        """Logs the trial's outcome; returns the call that tells the optimiser, or None
        when the trial is to run again (its worker process died)."""
        try:
            outcome = future.result()
        except BrokenProcessPool as error:
            deaths = self._deaths[record.index] = self._deaths.get(record.index, 0) + 1
            if deaths < WORKER_DEATHS and isinstance(self._executor, LocalPool):
                return None  # the pool replaces itself at the next submit
            outcome = _failure(
                f"worker process died while running the trial, {deaths} times ({error})"
            )
        except Exception as error:
            explain = getattr(self._executor, "trial_failure", None)
            text = None if explain is None else explain(error)  # may raise ExecutorError
            if text is None:
                raise
            outcome = _failure(text)
        x = record.parameters
        if outcome["status"] == "done":
            self.log.mark_done(
                self.run_id,
                record.index,
                outcome["metric"],
                outcome["contacts"],
                outcome["scenario"],
                outcome["wall_time"],
            )
            return lambda: self.optimizer.tell(x, outcome["metric"])
        self.log.mark_failed(
            self.run_id,
            record.index,
            outcome["error"],
            outcome["wall_time"],
            outcome["scenario"],
        )
        return lambda: self.optimizer.tell_failure(x, outcome["error"])

    def result(self) -> ExperimentResult:
        records = self.log.trials(self.run_id)
        done = [r for r in records if r.status == "done"]
        best = max(done, key=lambda r: r.metric) if done else None
        return ExperimentResult(
            run_id=self.run_id,
            best_x=None if best is None else best.parameters,
            best_y=math.nan if best is None else best.metric,
            n_done=len(done),
            n_failed=sum(r.status == "failed" for r in records),
            converged=bool(self.optimizer.converged),
            trials=records,
        )


def _failure(error: str) -> dict:
    return {"status": "failed", "wall_time": None, "scenario": None, "error": error}


def _progress_bar(total, initial, description, enabled):
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=description, disable=not enabled, unit="trial")


def _objective_name(objective) -> str:
    for attribute in ("name", "__name__"):
        name = getattr(objective, attribute, None)
        if isinstance(name, str) and name:
            return name
    return type(objective).__name__


def run_experiment(
    objective: Callable,
    bounds,
    strategy: str = "bo",
    n_trials: int = 50,
    seed: int = 0,
    db_path="trials.sqlite",
    executor: Executor | None = None,
    progress: bool = True,
    *,
    run_id: str | None = None,
    objective_name: str | None = None,
    optimizer_options: dict | None = None,
    batch_size: int | None = None,
    workers: int | None = None,
    commit_every: int | None = COMMIT_EVERY,
    commit_seconds: float = COMMIT_SECONDS,
) -> ExperimentResult:
    """Optimise ``objective`` over ``bounds``, logging every trial to ``db_path``; resumable.

    Calling it again with the same arguments resumes the run (re-running any
    trial that was interrupted) and stops when the run holds ``n_trials``
    finished trials, or earlier if BO's expected improvement falls below its
    threshold. The run is identified by ``run_id`` (default
    ``"<objective name>-<strategy>-seed<seed>"``); resuming with a different
    strategy, bounds, seed, objective name or optimiser options raises
    ``ValueError``. ``commit_every``/``commit_seconds``: the log's group
    commits (:class:`TrialRunner`).
    """
    bounds = check_bounds(bounds)
    options = dict(optimizer_options or {})
    name = objective_name or _objective_name(objective)
    run_id = run_id or f"{name}-{strategy}-seed{seed}"
    optimizer = make_optimizer(strategy, bounds, seed, **options)  # validates everything
    try:
        config = json.loads(json.dumps(options))  # what the database will hold
    except TypeError as error:
        raise TypeError(
            f"optimizer_options must be JSON serialisable to be stored with the run ({error}); "
            "a callable prior mean cannot be logged: use BayesianOptimizer and TrialRunner "
            "directly"
        ) from None
    with TrialLog(db_path) as log:
        log.open_run(run_id, strategy, bounds, seed, name, config)
        runner = TrialRunner(
            objective,
            optimizer,
            log,
            run_id,
            executor=executor,
            batch_size=batch_size,
            progress=progress,
            workers=workers,
            commit_every=commit_every,
            commit_seconds=commit_seconds,
        )
        return runner.run(n_trials)
