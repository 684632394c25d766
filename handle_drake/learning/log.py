"""Trial storage: one SQLite row per trial of a run, and the run's settings.

Every trial of a run is one row of an SQLite database (standard library
``sqlite3``, WAL journal, ``synchronous=FULL``) holding the parameters, the
full scenario text, the metric, the contacts, the wall time, the trial seed,
the status and the error text. A run's settings (strategy, bounds, seed,
objective name, optimiser options) are in a table of their own. A row goes
``pending`` -> ``running`` -> ``done`` | ``failed`` (see
:mod:`handle_drake.learning.loop` for how a run resumes from it).

Group commits. By default every write is its own durable transaction (a
WAL append and an fsync: ~70-100 trials/s here). Inside
:meth:`TrialLog.grouped` the trial writes (``add_pending``, ``mark_*``) are
kept in order in memory and committed together, in one transaction, once
``count`` trials have finished since the last commit or ``seconds`` have
passed since its oldest write (:meth:`TrialLog.commit_if_due`), on any read,
and on leaving the block. What is on disk is therefore always a prefix of
the sequence of writes, one the per-write log could have been killed in
too: after a kill -9 the trials whose rows were not yet committed (at most
``count`` finished ones, or ``seconds`` worth) are simply run again on
resume, and none is repeated or lost.
"""

from __future__ import annotations

import ast
import errno
import functools
import hashlib
import json
import math
import numbers
import os
import socket
import sqlite3
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from handle_drake.base.checks import short as _short
from handle_drake.learning.optim.bo import check_bounds

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


def code_digest(source: str) -> bytes:
    """What of a Python source can change results: its syntax tree without docstrings.

    Comments, blank lines, formatting and docstrings drop out (``ast`` keeps
    neither comments nor positions here), so editing a docstring does not
    start a new run; any change to code does.
    """
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree, annotate_fields=False, include_attributes=False).encode()


def code_fingerprint(root: Path, sources, data_files=()) -> str:
    """A run's simulation fingerprint: Drake's version, the code of ``sources``
    (:func:`code_digest`, paths relative to ``root``) and the bytes of ``data_files``
    (model files, recordings; by name). A run computed by other code or data is
    never resumed as if it were current."""
    digest = hashlib.sha1(f"drake {version('drake')}".encode())
    for path in sources:
        digest.update(Path(path).relative_to(root).as_posix().encode())
        digest.update(code_digest(Path(path).read_text()))
    for path in data_files:
        digest.update(Path(path).name.encode())
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()[:10]


def scenario_fingerprint(text: str) -> str:
    """A short content hash of a scenario's (or settings') text, for run ids."""
    return hashlib.sha256(text.encode()).hexdigest()[:10]


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


def _first_difference(name: str, a, b):
    """``(dotted name, a's value, b's value)`` of the first nested dict entry where ``a``
    and ``b`` differ (``a``, ``b`` themselves when they are not both dicts)."""
    while isinstance(a, dict) and isinstance(b, dict):
        key = next((k for k in sorted(set(a) | set(b), key=str) if a.get(k, _MISSING) !=
                    b.get(k, _MISSING)), None)
        if key is None:
            break
        name, a, b = f"{name}.{key}", a.get(key, _MISSING), b.get(key, _MISSING)
    return name, a, b


class _Missing:
    def __repr__(self):
        return "(missing)"


_MISSING = _Missing()


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


def _parameters_json(x) -> str:
    # repr-exact floats: json writes the shortest string that reads back equal.
    return json.dumps([float(v) for v in np.asarray(x, dtype=float).reshape(-1)])


#: Runs this process holds (:meth:`TrialLog.open_run`): claim name -> [socket, count].
_CLAIMS: dict[str, list] = {}


def _claim_name(path, run_id) -> str | None:
    """The Linux abstract socket name standing for (this log, run id): bound by the one
    process running it, and unbound by the kernel when that process ends however it
    ends (kill -9 too); nothing is written to disk. None off Linux."""
    if not sys.platform.startswith("linux"):
        return None
    digest = hashlib.sha256(f"{os.path.realpath(path)}\0{run_id}".encode()).hexdigest()
    return f"\0handle_drake.trial_log.{digest[:40]}"


def _take_claim(name: str) -> bool:
    entry = _CLAIMS.get(name)
    if entry is None:
        claim = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            claim.bind(name)
        except OSError as error:
            claim.close()
            if error.errno == errno.EADDRINUSE:
                return False
            return True  # no abstract sockets here: run unguarded, as before
        entry = _CLAIMS[name] = [claim, 0]
    entry[1] += 1
    return True


def _release_claim(name: str) -> None:
    entry = _CLAIMS.get(name)
    if entry is not None:
        entry[1] -= 1
        if entry[1] <= 0:
            entry[0].close()
            del _CLAIMS[name]


def _one_line(error) -> str:
    """SQLite's message without the raw column it may quote ("Could not decode to UTF-8
    column 'scenario' with text '...'": kilobytes over many lines)."""
    text = str(error)
    if text.startswith("Could not decode to UTF-8 column"):
        return text.split(" with text ", 1)[0] + " (not UTF-8 text)"
    return _short(text.replace("\n", " "), 200)


def _guarded(method):
    """SQLite failures inside a method become TrialLogError with the real reason:
    a write to a read-only log says so, a record damaged after opening says that."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.IntegrityError:
            raise
        except sqlite3.OperationalError as error:
            if self.read_only or "readonly" in str(error):
                raise TrialLogError(f"{self.path} is read-only: cannot record trials in it "
                                    f"({error}); copy it somewhere writable to resume") from None
            raise TrialLogError(f"{self.path}: {_one_line(error)}") from None
        except sqlite3.DatabaseError as error:
            raise TrialLogError(f"{self.path} is damaged: {_one_line(error)}; it was not "
                                f"modified") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise TrialLogError(f"{self.path} is damaged: a field does not decode "
                                f"({str(error)[:200]})") from None

    return wrapper


def check_group(count, seconds) -> None:
    """Validates group-commit bounds (:meth:`TrialLog.grouped`)."""
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"commit_every: expected an integer >= 1, got {count!r}")
    if (isinstance(seconds, bool) or not isinstance(seconds, int | float)
            or not math.isfinite(seconds) or seconds < 0):
        raise ValueError(f"commit_seconds: expected a finite number >= 0, got {seconds!r}")


class TrialLog:
    """The SQLite trial database. Opening an existing file never overwrites it.

    Raises :class:`TrialLogError` if ``path`` exists and is not a readable
    handle_drake trial log (not SQLite, failed integrity check, an SQLite
    database of something else, or a newer format).
    """

    def __init__(self, path):
        self.path = Path(path)
        self._claims: set[str] = set()  # runs this log opened for writing (open_run)
        #: Trial writes not yet committed, in order: (sql, args, message if not one row).
        self._buffer: list[tuple[str, tuple, str | None]] = []
        self._group: tuple[int, float] | None = None  # (count, seconds) inside grouped()
        self._finished = 0  # trials finished (done/failed) in the buffer
        self._oldest = 0.0  # monotonic time of the buffer's first write
        existing = self.path.exists() and self.path.stat().st_size > 0
        #: A valid log on a file (or in a folder) this process cannot write opens read-only:
        #: every read works, every write raises TrialLogError saying so.
        self.read_only = existing and not (
            os.access(self.path, os.W_OK) and os.access(self.path.parent, os.W_OK))
        wal = Path(f"{self.path}-wal")
        if self.read_only and wal.exists() and wal.stat().st_size > 0:
            raise TrialLogError(f"{self.path} is read-only and its journal {wal.name} holds "
                                "trials not yet merged into it; open it once where it is "
                                "writable (it was not modified)")
        if existing:
            self._check_existing()
        if self.read_only:
            self._conn = sqlite3.connect(self._read_only_uri(), uri=True)
            return
        # Autocommit (isolation_level=None): each write is its own durable transaction.
        try:
            self._conn = sqlite3.connect(str(self.path), timeout=30.0, isolation_level=None)
        except sqlite3.DatabaseError as error:
            raise TrialLogError(f"{self.path}: cannot create a trial log there ({error})") from None
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
        uri = self._read_only_uri()
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
                    self._decode_every_row(conn)
            finally:
                conn.close()
        except sqlite3.DatabaseError as error:
            raise TrialLogError(
                f"{self.path} is damaged: SQLite cannot read it ({_one_line(error)}); it was not "
                f"modified"
            ) from error

    def _read_only_uri(self) -> str:
        # immutable: a read-only folder cannot hold the WAL's -shm file, and nobody can be
        # writing a file this process may not write either.
        immutable = "&immutable=1" if self.read_only else ""
        return f"file:{quote(str(self.path.resolve()))}?mode=ro{immutable}"

    def _decode_every_row(self, conn) -> None:
        """Reads and decodes every record, so a damaged one is found now, not mid-run.

        SQLite's quick check verifies the b-trees, not the bytes inside a record: a few
        scribbled bytes there pass it and fail later (a malformed-record error, a JSON
        field that no longer parses, a status outside the four).
        """
        where = "runs"
        try:
            for n, row in enumerate(conn.execute("SELECT * FROM runs")):
                where = f"runs row {n + 1}"
                check_bounds(np.array(json.loads(row[2]), dtype=float))
                int(row[3]), float(row[6])
                if not isinstance(json.loads(row[5]), dict):
                    raise ValueError("config is not a JSON object")
            for n, row in enumerate(conn.execute(
                    "SELECT run_id, trial_index, parameters, status, seed, contacts, "
                    "CAST(scenario AS BLOB) FROM trials")):
                where = f"trials row {n + 1}"
                if row[6] is not None:
                    try:
                        row[6].decode("utf-8")
                    except UnicodeDecodeError as error:
                        raise ValueError(f"scenario: not UTF-8 text (byte "
                                         f"0x{error.object[error.start]:02x} at offset "
                                         f"{error.start})") from None
                np.array(json.loads(row[2]), dtype=float)
                if row[3] not in STATUSES:
                    raise ValueError(f"status {row[3]!r}")
                int(row[1]), int(row[4])
                if row[5] is not None:
                    json.loads(row[5])
        except sqlite3.DatabaseError as error:
            raise TrialLogError(f"{self.path} is damaged at {where}: SQLite cannot read it "
                                f"({_one_line(error)}); it was not modified") from None
        except (ValueError, TypeError, UnicodeDecodeError) as error:
            raise TrialLogError(f"{self.path} is damaged at {where}: a field does not decode "
                                f"({str(error)[:200]}); it was not modified") from None

    def close(self):
        try:
            self.commit()
        finally:
            self._conn.close()
            for name in self._claims:
                _release_claim(name)
            self._claims.clear()

    # --------------------------------------------------------- group commits
    @contextmanager
    def grouped(self, count: int = 256, seconds: float = 0.25):
        """Within the block, trial writes are committed in groups (see the module doc).

        A group is committed when it holds ``count`` finished trials or its
        oldest write is ``seconds`` old (checked at every write and by
        :meth:`commit_if_due`, which a caller waiting for trials calls after
        at most :meth:`due_in` s), before any read, and on leaving the block
        (an exception too: what was done is kept). A kill -9 loses only the
        uncommitted group, whose trials a resumed run evaluates again.
        """
        check_group(count, seconds)
        if self._group is not None:
            raise RuntimeError(f"{self.path}: grouped() blocks do not nest")
        self._group = (count, float(seconds))
        try:
            yield self
        finally:
            self._group = None
            self.commit()

    def due_in(self) -> float | None:
        """Seconds until the uncommitted group is due (0: now), None when nothing waits."""
        if not self._buffer or self._group is None:
            return None
        return max(0.0, self._oldest + self._group[1] - time.monotonic())

    def commit_if_due(self) -> bool:
        """Commits the group when it holds ``count`` finished trials or is ``seconds`` old."""
        if not self._buffer:
            return False
        if (self._group is None or self._finished >= self._group[0]
                or time.monotonic() - self._oldest >= self._group[1]):
            self.commit()
            return True
        return False

    @_guarded
    def commit(self) -> None:
        """Writes the uncommitted trial writes in one transaction (nothing if none)."""
        if not self._buffer:
            return
        writes, self._buffer, self._finished = self._buffer, [], 0
        # IMMEDIATE: the write lock first, so another writer of the file (another run's
        # log) waits for it instead of failing on a stale snapshot; held for the write only.
        self._conn.execute("BEGIN IMMEDIATE")
        try:
            for sql, args, message in writes:
                self._execute(sql, args, message)
            self._conn.execute("COMMIT")
        except BaseException:
            self._conn.execute("ROLLBACK")
            raise

    def _execute(self, sql, args, message):
        """Runs one trial write. ``message``: for an UPDATE the error text when it does not
        change exactly one row; for an INSERT a function of the IntegrityError giving it."""
        try:
            cursor = self._conn.execute(sql, args)
        except sqlite3.IntegrityError as error:
            if not callable(message):
                raise
            raise TrialLogError(message(error)) from None
        if isinstance(message, str) and cursor.rowcount != 1:
            raise TrialLogError(message)

    def _write(self, sql, args, message, finishes=False):
        """One trial write: now, or into the group (committed when due)."""
        if self._group is None:
            self._execute(sql, args, message)
            return
        if not self._buffer:
            self._oldest = time.monotonic()
        self._buffer.append((sql, args, message))
        self._finished += finishes
        self.commit_if_due()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ runs
    @_guarded
    def create_run(self, run_id, strategy, bounds, seed, objective, config=None) -> RunInfo:
        if not isinstance(run_id, str) or not run_id:
            raise ValueError(f"run_id must be a non-empty string, got {run_id!r}")
        bounds = check_bounds(bounds)
        if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) \
                or not -(2**63) <= int(seed) < 2**63:
            raise ValueError(f"seed: expected an integer in -2**63..2**63-1 (SQLite's "
                             f"INTEGER), got {str(seed)[:40]}")
        info = RunInfo(
            run_id, strategy, bounds, int(seed), str(objective), dict(config or {}), time.time()
        )
        self.commit()
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

    def _claim(self, run_id) -> None:
        """Refuses a run another process is running on this log right now (its trials
        would be taken twice); see :func:`_claim_name`."""
        name = _claim_name(self.path, run_id)
        if name is None or name in self._claims:
            return
        if not _take_claim(name):
            raise TrialLogError(f"{self.path}: run {run_id!r} is being run by another process "
                                f"right now (its trials are in this log); wait for it to "
                                f"end, or give another log")
        self._claims.add(name)

    def open_run(self, run_id, strategy, bounds, seed, objective, config=None) -> RunInfo:
        """Creates the run, or checks that the logged run of that id has these settings.

        The one place a run is opened for writing (``run_experiment``, the
        in-hand runs): calling it again with the same settings resumes the run;
        another strategy, seed, objective name, config (compared as JSON) or
        bounds raises ``ValueError`` naming the field, its logged and its given
        value.
        """
        bounds = check_bounds(bounds)
        self._claim(run_id)
        info = self.get_run(run_id)
        if info is None:
            return self.create_run(run_id, strategy, bounds, seed, objective, config)
        given = dict(strategy=strategy, seed=int(seed), objective=str(objective),
                     config=json.loads(json.dumps(dict(config or {}), sort_keys=True)))
        for key, value in given.items():
            stored = getattr(info, key)
            if stored != value:
                field, stored, value = _first_difference(key, stored, value)
                raise ValueError(f"run {run_id!r} exists in {self.path} with {field}="
                                 f"{_short(stored)}, got {_short(value)}; use another run id "
                                 "or trial log")
        if info.bounds.shape != bounds.shape or not np.array_equal(info.bounds, bounds):
            raise ValueError(f"run {run_id!r} exists in {self.path} with bounds "
                             f"{_short(info.bounds.tolist())}, got {_short(bounds.tolist())}")
        return info

    @_guarded
    def get_run(self, run_id) -> RunInfo | None:
        self.commit()  # a read sees every write made before it
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

    @_guarded
    def runs(self) -> list[RunInfo]:
        self.commit()
        ids = [r for (r,) in self._conn.execute("SELECT run_id FROM runs ORDER BY created_at")]
        return [self.get_run(r) for r in ids]

    # ---------------------------------------------------------------- trials
    @_guarded
    def add_pending(self, run_id, index, parameters, seed, scenario=None,
                    running=False) -> None:
        """Write the row of a trial about to be evaluated (before evaluating it);
        ``running``: as handed to the executor already (``mark_running`` in the same write)."""
        status, started_at = ("running", time.time()) if running else ("pending", None)
        self._write(
            "INSERT INTO trials (run_id, trial_index, parameters, scenario, seed, status, "
            "started_at) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (run_id, int(index), _parameters_json(parameters), scenario, int(seed), status,
             started_at),
            lambda error: (f"cannot add trial {index} of run {run_id!r}: {error} "
                           "(the trial exists already, or the run does not)"),
        )

    @_guarded
    def _update(self, run_id, index, allowed_from, **values):
        columns = ", ".join(f"{k} = ?" for k in values)
        marks = ", ".join("?" * len(allowed_from))
        self._write(
            f"UPDATE trials SET {columns} WHERE run_id = ? AND trial_index = ? "
            f"AND status IN ({marks})",
            (*values.values(), run_id, int(index), *allowed_from),
            f"trial {index} of run {run_id!r} is not in state {allowed_from}; cannot set "
            f"{values.get('status')}",
            finishes=values.get("status") in ("done", "failed"),
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

    @_guarded
    def trials(self, run_id, status=None) -> list[TrialRecord]:
        """The run's trials in index order (optionally only those with ``status``)."""
        self.commit()
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
