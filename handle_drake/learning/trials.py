"""Trial storage (SQLite) and a resumable trial runner.

Every trial of a run is one row of an SQLite database (standard library
``sqlite3``, WAL journal, ``synchronous=FULL``) holding the parameters, the
full scenario text, the metric, the contacts, the wall time, the trial seed,
the status and the error text. A run's settings (strategy, bounds, seed,
objective name, optimiser options) are in a table of their own.

Resume semantics (no trial lost, none repeated):

1. Before a trial is evaluated its row is written as ``pending`` (parameters
   and trial seed), then ``running`` when handed to the executor, then
   ``done`` (metric) or ``failed`` (error) in one transaction each.
2. On resume the optimiser is rebuilt by replaying ``tell``/``tell_failure``
   of the ``done``/``failed`` rows in trial order into a fresh optimiser with
   the run's seed and options (its state is a function of exactly that, see
   :mod:`handle_drake.learning.bayesopt`).
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
resume. A worker process that dies (e.g. a segfault in a simulator) fails the
trials it was running.

Parallelism: trials run through a ``concurrent.futures.Executor``. By default
a ``ProcessPoolExecutor`` (spawn start method, which is safe with Drake's
threads) whose workers pin BLAS to one thread and receive the objective once
(the objective may build its simulation diagram on its first call and reuse
it). Random search runs as many trials at once as there are workers, each
new trial as soon as one finishes. Bayesian optimisation runs in synchronous
batches of its ``batch_size`` (1, sequential, by default): it proposes a batch,
waits for all of it and tells the results in trial order, so a run depends
only on its seed and options (not on which worker finished first) and a
resumed run completes the interrupted batch before asking for the next.
"""

from __future__ import annotations

import inspect
import json
import math
import multiprocessing
import os
import sqlite3
import time
import traceback
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from handle_drake.learning.bayesopt import _derived_seed, check_bounds, make_optimizer

__all__ = [
    "TrialLog",
    "TrialLogError",
    "TrialRecord",
    "RunInfo",
    "TrialResult",
    "TrialRunner",
    "ExperimentResult",
    "InlineExecutor",
    "run_experiment",
]

STATUSES = ("pending", "running", "done", "failed")
_FORMAT = "handle_drake.trial_log"
_VERSION = 1
_SQLITE_HEADER = b"SQLite format 3\x00"

_SCHEMA = """
CREATE TABLE handle_drake_meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE runs (
    run_id TEXT PRIMARY KEY,
    strategy TEXT NOT NULL,
    bounds TEXT NOT NULL,          -- JSON [[lower, upper], ...]
    seed INTEGER NOT NULL,
    objective TEXT NOT NULL,
    config TEXT NOT NULL,          -- JSON optimiser options
    created_at REAL NOT NULL       -- unix time, s
);
CREATE TABLE trials (
    run_id TEXT NOT NULL REFERENCES runs(run_id),
    trial_index INTEGER NOT NULL,
    parameters TEXT NOT NULL,      -- JSON list, units of the run's bounds
    scenario TEXT,                 -- full scenario as given by the objective (YAML/JSON text)
    metric REAL,
    contacts TEXT,                 -- JSON
    wall_time REAL,                -- s spent in the objective
    seed INTEGER NOT NULL,         -- seed handed to the objective
    status TEXT NOT NULL CHECK (status IN ('pending', 'running', 'done', 'failed')),
    error TEXT,
    started_at REAL,
    finished_at REAL,
    PRIMARY KEY (run_id, trial_index)
);
"""


class TrialLogError(RuntimeError):
    """The trial database cannot be used (corrupt, foreign, inconsistent); it was not modified."""


@dataclass(frozen=True)
class RunInfo:
    run_id: str
    strategy: str
    bounds: np.ndarray
    seed: int
    objective: str
    config: dict
    created_at: float


@dataclass(frozen=True)
class TrialRecord:
    run_id: str
    index: int
    parameters: np.ndarray
    status: str
    seed: int
    metric: float | None = None
    scenario: str | None = None
    contacts: Any = None
    wall_time: float | None = None
    error: str | None = None
    started_at: float | None = None
    finished_at: float | None = None


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


def _parameters_json(x) -> str:
    # repr-exact floats: json writes the shortest string that reads back equal.
    return json.dumps([float(v) for v in np.asarray(x, dtype=float).reshape(-1)])


class TrialLog:
    """The SQLite trial database. Opening an existing file never overwrites it.

    Raises :class:`TrialLogError` if ``path`` exists and is not a readable
    handle_drake trial log (not SQLite, failed integrity check, an SQLite
    database of something else, or a newer format).
    """

    def __init__(self, path):
        self.path = Path(path)
        existing = self.path.exists() and self.path.stat().st_size > 0
        if existing:
            self._check_existing()
        # Autocommit (isolation_level=None): each write is its own durable transaction.
        self._conn = sqlite3.connect(str(self.path), timeout=30.0, isolation_level=None)
        try:
            self._conn.execute("PRAGMA journal_mode=WAL")
            self._conn.execute("PRAGMA synchronous=FULL")
            self._conn.execute("PRAGMA foreign_keys=ON")
            tables = self._tables(self._conn)
            if not tables:  # a new (or empty) file: create the schema in one transaction
                self._conn.executescript(
                    "BEGIN;"
                    + _SCHEMA
                    + f"INSERT INTO handle_drake_meta VALUES ('format', '{_FORMAT}'), "
                    f"('version', '{_VERSION}');" + "COMMIT;"
                )
        except sqlite3.DatabaseError as error:
            self._conn.close()
            raise TrialLogError(f"{self.path}: cannot use this trial log: {error}") from error

    @staticmethod
    def _tables(conn) -> set[str]:
        rows = conn.execute("SELECT name FROM sqlite_master WHERE type='table'").fetchall()
        return {name for (name,) in rows}

    def _check_existing(self):
        """Validate an existing file read-only, before anything may write to it."""
        with open(self.path, "rb") as f:
            header = f.read(len(_SQLITE_HEADER))
        if header != _SQLITE_HEADER:
            raise TrialLogError(
                f"{self.path} is not an SQLite database (bad header {header[:16]!r}); "
                "refusing to open or overwrite it"
            )
        uri = f"file:{self.path.resolve()}?mode=ro"
        try:
            conn = sqlite3.connect(uri, uri=True)
            try:
                check = conn.execute("PRAGMA quick_check").fetchall()
                if check != [("ok",)]:
                    problems = "; ".join(str(row[0]) for row in check[:3])
                    raise TrialLogError(
                        f"{self.path} failed SQLite's integrity check ({problems}); "
                        "refusing to use it (restore a backup, or start a new file)"
                    )
                tables = self._tables(conn)
                if tables and "handle_drake_meta" not in tables:
                    raise TrialLogError(
                        f"{self.path} is an SQLite database but not a handle_drake trial log "
                        f"(tables: {sorted(tables)}); refusing to modify it"
                    )
                if tables:
                    meta = dict(conn.execute("SELECT key, value FROM handle_drake_meta"))
                    if meta.get("format") != _FORMAT or meta.get("version") != str(_VERSION):
                        raise TrialLogError(
                            f"{self.path}: trial log format {meta.get('format')!r} version "
                            f"{meta.get('version')!r}, expected {_FORMAT!r} version {_VERSION}"
                        )
            finally:
                conn.close()
        except sqlite3.DatabaseError as error:
            raise TrialLogError(
                f"{self.path} is corrupt or not a trial log ({error}); it was not modified"
            ) from error

    def close(self):
        self._conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ runs
    def create_run(self, run_id, strategy, bounds, seed, objective, config=None) -> RunInfo:
        if not isinstance(run_id, str) or not run_id:
            raise ValueError(f"run_id must be a non-empty string, got {run_id!r}")
        bounds = check_bounds(bounds)
        info = RunInfo(
            run_id, strategy, bounds, int(seed), str(objective), dict(config or {}), time.time()
        )
        try:
            self._conn.execute(
                "INSERT INTO runs VALUES (?, ?, ?, ?, ?, ?, ?)",
                (
                    run_id,
                    strategy,
                    json.dumps(bounds.tolist()),
                    info.seed,
                    info.objective,
                    json.dumps(info.config, sort_keys=True),
                    info.created_at,
                ),
            )
        except sqlite3.IntegrityError:
            raise ValueError(f"run {run_id!r} already exists in {self.path}") from None
        return info

    def get_run(self, run_id) -> RunInfo | None:
        row = self._conn.execute("SELECT * FROM runs WHERE run_id = ?", (run_id,)).fetchone()
        if row is None:
            return None
        return RunInfo(
            row[0],
            row[1],
            np.array(json.loads(row[2]), dtype=float),
            int(row[3]),
            row[4],
            json.loads(row[5]),
            float(row[6]),
        )

    def runs(self) -> list[RunInfo]:
        ids = [r for (r,) in self._conn.execute("SELECT run_id FROM runs ORDER BY created_at")]
        return [self.get_run(r) for r in ids]

    # ---------------------------------------------------------------- trials
    def add_pending(self, run_id, index, parameters, seed, scenario=None) -> None:
        """Write the row of a trial about to be evaluated (before evaluating it)."""
        try:
            self._conn.execute(
                "INSERT INTO trials (run_id, trial_index, parameters, scenario, seed, status) "
                "VALUES (?, ?, ?, ?, ?, 'pending')",
                (run_id, int(index), _parameters_json(parameters), scenario, int(seed)),
            )
        except sqlite3.IntegrityError as error:
            raise TrialLogError(
                f"cannot add trial {index} of run {run_id!r}: {error} "
                "(the trial exists already, or the run does not)"
            ) from None

    def _update(self, run_id, index, allowed_from, **values):
        columns = ", ".join(f"{k} = ?" for k in values)
        marks = ", ".join("?" * len(allowed_from))
        cursor = self._conn.execute(
            f"UPDATE trials SET {columns} WHERE run_id = ? AND trial_index = ? "
            f"AND status IN ({marks})",
            (*values.values(), run_id, int(index), *allowed_from),
        )
        if cursor.rowcount != 1:
            raise TrialLogError(
                f"trial {index} of run {run_id!r} is not in state {allowed_from}; cannot set "
                f"{values.get('status')}"
            )

    def mark_running(self, run_id, index) -> None:
        self._update(
            run_id, index, ("pending", "running"), status="running", started_at=time.time()
        )

    def mark_done(self, run_id, index, metric, contacts=None, scenario=None, wall_time=None):
        metric = float(metric)
        if not math.isfinite(metric):
            raise ValueError(
                f"metric must be finite to mark a trial done, got {metric}; use mark_failed"
            )
        values = dict(
            status="done", metric=metric, wall_time=wall_time, finished_at=time.time(), error=None
        )
        if contacts is not None:
            values["contacts"] = contacts if isinstance(contacts, str) else json.dumps(contacts)
        if scenario is not None:
            values["scenario"] = scenario
        self._update(run_id, index, ("pending", "running"), **values)

    def mark_failed(self, run_id, index, error, wall_time=None, scenario=None) -> None:
        values = dict(
            status="failed", error=str(error), wall_time=wall_time, finished_at=time.time()
        )
        if scenario is not None:
            values["scenario"] = scenario
        self._update(run_id, index, ("pending", "running"), **values)

    def trials(self, run_id, status=None) -> list[TrialRecord]:
        """The run's trials in index order (optionally only those with ``status``)."""
        query = (
            "SELECT run_id, trial_index, parameters, status, seed, metric, scenario, contacts, "
            "wall_time, error, started_at, finished_at FROM trials WHERE run_id = ?"
        )
        args = [run_id]
        if status is not None:
            if status not in STATUSES:
                raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
            query += " AND status = ?"
            args.append(status)
        records = []
        for row in self._conn.execute(query + " ORDER BY trial_index", args):
            records.append(
                TrialRecord(
                    run_id=row[0],
                    index=int(row[1]),
                    parameters=np.array(json.loads(row[2])),
                    status=row[3],
                    seed=int(row[4]),
                    metric=row[5],
                    scenario=row[6],
                    contacts=None if row[7] is None else json.loads(row[7]),
                    wall_time=row[8],
                    error=row[9],
                    started_at=row[10],
                    finished_at=row[11],
                )
            )
        return records


# ------------------------------------------------------------------ executors
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
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"  # for anything the worker starts later
    # numpy is already imported (this module imports it), so the environment
    # variables come too late for its BLAS; threadpoolctl changes it live.
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
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
    return ProcessPoolExecutor(
        max_workers=max_workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_worker,
        initargs=(objective,),
    )


# --------------------------------------------------------------------- runner
@dataclass
class ExperimentResult:
    run_id: str
    best_x: np.ndarray | None
    best_y: float
    n_done: int
    n_failed: int
    converged: bool
    trials: list[TrialRecord] = field(repr=False, default_factory=list)


class TrialRunner:
    """Evaluates an objective where an optimiser asks, logging each trial to a :class:`TrialLog`.

    Args:
        objective: ``f(x) -> float | TrialResult`` (``f(x, seed=...)`` if it
            has a ``seed`` parameter: each trial gets its own seed derived from
            the run seed and the trial index, so a noisy simulation replays).
            Must be picklable for the default process pool.
        optimizer: a fresh :class:`BayesianOptimizer` / :class:`RandomSearch`
            built with the run's seed and options.
        log, run_id: where the trials go; the run must exist in the log.
        executor: any ``concurrent.futures.Executor``; None for the default
            process pool (the optimiser's ``batch_size`` workers for BO,
            ``os.cpu_count()`` for random search).
        batch_size: trials in flight at once; for BO it is the optimiser's
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
    ):
        if not callable(objective):
            raise TypeError(f"objective must be callable, got {objective!r}")
        info = log.get_run(run_id)
        if info is None:
            raise ValueError(f"run {run_id!r} does not exist in {log.path}")
        # BO and swarms (an optimiser with ``synchronous = True``) run in batches.
        synchronous = getattr(optimizer, "synchronous", optimizer.strategy == "bo")
        if synchronous:
            q = getattr(optimizer, "batch_size", 1)
            if batch_size is not None and batch_size != q:
                raise ValueError(
                    f"batch_size {batch_size} differs from the optimiser's batch_size {q}; "
                    f"Bayesian optimisation proposes batches of its own size (make it with "
                    f"batch_size={batch_size})"
                )
            batch_size = q
        if executor is None:
            workers = batch_size if synchronous else max(1, os.cpu_count() or 1)
        else:
            workers = getattr(executor, "_max_workers", 1)
        if batch_size is None:
            batch_size = workers
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
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

    def _submit(self, x, seed) -> Future:
        if self._executor is None:
            self._executor = _default_pool(self.objective, self._workers)
        if self._owns_executor:
            return self._executor.submit(_evaluate_in_worker, x, seed, self._pass_seed)
        return self._executor.submit(_evaluate, self.objective, x, seed, self._pass_seed)

    def _replay(self) -> tuple[list[TrialRecord], int]:
        records = self.log.trials(self.run_id)
        indices = [r.index for r in records]
        if indices != list(range(len(records))):
            raise TrialLogError(
                f"run {self.run_id!r}: trial indices are not 0..{len(records) - 1}"
                f" (got {indices[:10]}...)"
            )
        unfinished = []
        for record in records:
            if record.status == "done":
                self.optimizer.tell(record.parameters, record.metric)
            elif record.status == "failed":
                self.optimizer.tell_failure(record.parameters, record.error or "")
            else:
                self.optimizer.resume_pending(record.parameters)
                unfinished.append(record)
        return unfinished, len(records)

    def run(self, n_trials: int) -> ExperimentResult:
        """Run until the run holds ``n_trials`` finished trials (or the optimiser converges)."""
        if isinstance(n_trials, bool) or not isinstance(n_trials, int | np.integer) or n_trials < 0:
            raise ValueError(f"n_trials must be a non-negative integer, got {n_trials!r}")
        queue, next_index = self._replay()
        finished = next_index - len(queue)
        in_flight: dict[Future, TrialRecord] = {}
        untold: list = []  # (trial index, tell) of logged trials the optimiser has yet to see
        stop = False
        bar = _progress_bar(n_trials, finished, self.run_id, self.progress)
        try:
            while True:
                # A synchronous (BO) batch starts only once the last one is in,
                # and an interrupted batch is finished on its own first.
                room = self.batch_size - len(in_flight)
                if self.synchronous:
                    # A generational optimiser (a swarm) resumed in the middle of a
                    # generation asks only for that generation's remaining members.
                    room = 0 if in_flight else (len(queue) if queue else getattr(
                        self.optimizer, "batch_room", self.batch_size))
                while room > 0 and (queue or (not stop and next_index < n_trials)):
                    room -= 1
                    if queue:
                        record = queue.pop(0)
                    else:
                        x = self.optimizer.ask()
                        if self.optimizer.converged:
                            stop = True
                            break
                        seed = _derived_seed(self.run_seed, next_index)
                        self.log.add_pending(self.run_id, next_index, x, seed)
                        record = TrialRecord(self.run_id, next_index, x, "pending", seed)
                        next_index += 1
                    self.log.mark_running(self.run_id, record.index)
                    in_flight[self._submit(record.parameters, record.seed)] = record
                if not in_flight:
                    break
                completed, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
                for future in sorted(completed, key=lambda f: in_flight[f].index):
                    record = in_flight.pop(future)
                    # Logged at once (nothing is lost if the batch is killed);
                    # a synchronous batch is told in trial order once complete.
                    untold.append((record.index, self._finish(record, future)))
                    bar.update(1)
                if not self.synchronous or not in_flight:
                    for _, tell in sorted(untold, key=lambda item: item[0]):
                        tell()
                    untold.clear()
                    best = self.optimizer.best
                    if best is not None:
                        bar.set_postfix(best=f"{best.y:.4g}")
        finally:
            bar.close()
            if self._owns_executor and self._executor is not None:
                self._executor.shutdown(wait=True, cancel_futures=True)
                self._executor = None
        return self.result()

    def _finish(self, record: TrialRecord, future: Future):
        """Logs the trial's outcome; returns the call that tells the optimiser."""
        try:
            outcome = future.result()
        except BrokenProcessPool as error:
            outcome = {
                "status": "failed",
                "wall_time": None,
                "scenario": None,
                "error": f"worker process died while running the trial ({error})",
            }
            if self._owns_executor:
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = None  # a new pool is made at the next submit
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
) -> ExperimentResult:
    """Optimise ``objective`` over ``bounds``, logging every trial to ``db_path``; resumable.

    Calling it again with the same arguments resumes the run (re-running any
    trial that was interrupted) and stops when the run holds ``n_trials``
    finished trials, or earlier if BO's expected improvement falls below its
    threshold. The run is identified by ``run_id`` (default
    ``"<objective name>-<strategy>-seed<seed>"``); resuming with a different
    strategy, bounds, seed, objective name or optimiser options raises
    ``ValueError``.
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
        info = log.get_run(run_id)
        if info is None:
            log.create_run(run_id, strategy, bounds, seed, name, config)
        else:
            stored = dict(
                strategy=info.strategy, seed=info.seed, objective=info.objective, config=info.config
            )
            given = dict(strategy=strategy, seed=int(seed), objective=name, config=config)
            for key in stored:
                if stored[key] != given[key]:
                    raise ValueError(
                        f"run {run_id!r} exists in {db_path} with {key}="
                        f"{stored[key]!r}, got {given[key]!r}; use another run_id"
                    )
            if info.bounds.shape != bounds.shape or not np.array_equal(info.bounds, bounds):
                raise ValueError(
                    f"run {run_id!r} exists in {db_path} with bounds "
                    f"{info.bounds.tolist()}, got {bounds.tolist()}"
                )
        runner = TrialRunner(
            objective,
            optimizer,
            log,
            run_id,
            executor=executor,
            batch_size=batch_size,
            progress=progress,
        )
        return runner.run(n_trials)
