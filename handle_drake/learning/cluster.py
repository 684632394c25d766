"""Trials on more than one process or machine: the executor choice, with Dask as the cluster engine.

Every command that runs trials takes the same ``--executor`` option
(:func:`add_executor_arguments`) and opens it with :func:`trial_executor`:

- ``local`` (default): this machine's process pool, ``--workers N`` spawned
  processes with one BLAS thread each (one worker: trials run in the
  command's own process);
- ``dask``: a ``distributed.LocalCluster`` of ``--workers N`` worker
  processes with one thread each (BLAS pinned by Dask's nanny and again by
  the first trial a worker runs), scheduler on loopback, no dashboard, and
  no profiler, fast event-loop tick or fast monitors in the workers (:data:`QUIET_WORKER`);
- ``dask://HOST:PORT``: an existing ``dask scheduler`` and the ``dask worker``
  processes that joined it, on any number of machines.

In Python, :class:`TrialRunner <handle_drake.learning.loop.TrialRunner>` and
``run_experiment`` accept a ``distributed.Client`` or its ``get_executor()``
wherever they accept an executor (:func:`as_executor` wraps it).

What crosses the wire (client -> worker, per trial): a reference to the
trial function (module path), the objective pickled once on the client
(its configuration, e.g. a ``GraspTrialConfig``: some hundred bytes), the
trial's parameters (floats) and seed (int). The worker unpickles each
objective once (:class:`_ShippedOnce`, keyed by a hash of its bytes) and
keeps it, so an objective that builds its Drake diagram on its first call
builds it once per worker. Worker -> client: a dict of plain values (status,
metric, contacts as JSON text, scenario YAML text, wall time, error text).
Plants, diagrams, contexts and the SQLite log never leave their process: the
client writes every row.

Failures:

- A worker that dies while running a trial (segfault, OOM kill, lost
  machine): Dask runs the trial again on another worker; when
  :data:`WORKER_DEATHS` workers died running it (the scheduler's
  ``distributed.scheduler.allowed-failures`` + 1; our ``LocalCluster`` sets
  it), the trial is ``failed`` with the reason. The local pool does the same
  through the runner. Either way the client records the trial once.
- A lost scheduler: :class:`ExecutorError` says so; the trials that were
  running stay ``running`` in the log and run again when the command is
  repeated (the resume of :mod:`handle_drake.learning.loop`).
- An address where no scheduler answers, or a scheduler without workers:
  :class:`ExecutorError` within ``connect_timeout`` seconds.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import logging
import math
import pickle
import re
import threading
from concurrent.futures import CancelledError, Executor, Future
from contextlib import contextmanager
from dataclasses import dataclass

from handle_drake.base.blas import pin_blas
from handle_drake.learning.dask_probe import connect_client, probe_scheduler
from handle_drake.learning.executors import (
    ExecutorError,
    InlineExecutor,
    LocalPool,
    _check_local_workers,
    max_local_workers,
)

__all__ = [
    "WORKER_DEATHS",
    "CONNECT_TIMEOUT",
    "QUIET_WORKER",
    "ExecutorError",
    "ExecutorSpec",
    "DaskExecutor",
    "LocalPool",
    "max_local_workers",
    "add_executor_arguments",
    "add_chunk_argument",
    "check_executor_arguments",
    "as_executor",
    "executor_workers",
    "trial_executor",
]

WORKER_DEATHS = 3  # worker deaths while running one trial before it is `failed`
CONNECT_TIMEOUT = 10.0  # s, to reach a scheduler and to see its first worker
MAX_CONNECT_TIMEOUT = 3600.0  # s: longer is a typo (1e300 would wait for ever)
DEFAULT_PORT = 8786  # the port `dask scheduler` listens on by default
_LOG_LEVEL = logging.ERROR

# A worker runs its trial in a thread and its event loop in another, and the two
# share the GIL: each wake-up of the loop while the trial holds the GIL stops
# the trial until the loop lets go. Dask's defaults wake it for the dashboard
# (which we do not start) 150 times a second: the statistical profiler every
# 10 ms and the event-loop tick every 20 ms. Measured on a 1-thread worker
# running grasp trials: its event-loop thread used 5.8 % of a core (other
# threads' CPU ~28 ms per 0.3 s trial), 2.0 % without them (~8 ms). The
# memory monitor (every 100 ms) and the system monitor (every 500 ms) poll
# psutil on the same loop: at 1 s and 2 s the other threads' CPU fell from 9.0
# to 6.8 ms per trial and the trial's wait for the GIL from 1.5 to 1.2 % (two
# paired runs); memory is still checked every second (a trial's diagram takes
# a few hundred MB once, not per second). Passed on to the workers by the
# nannies; `dask worker`s are told in the README.
QUIET_WORKER = {"distributed.worker.profile.enabled": False,
                "distributed.admin.tick.interval": "1s",
                "distributed.worker.memory.monitor-interval": "1s",
                "distributed.admin.system-monitor.interval": "2s"}

_ADDRESS = re.compile(r"^dask://(?P<host>\[[0-9a-fA-F:.]+\]|[A-Za-z0-9_.-]+)(:(?P<port>[^/]*))?$")


# ----------------------------------------------------------------- choice
@dataclass(frozen=True)
class ExecutorSpec:
    """Which engine runs the trials: ``local``, ``dask`` or ``dask://HOST:PORT``."""

    kind: str  # "local" | "dask"
    address: str | None = None  # "tcp://HOST:PORT" of an existing scheduler, else None

    @classmethod
    def parse(cls, text) -> ExecutorSpec:
        if isinstance(text, ExecutorSpec):
            return text
        expected = "'local', 'dask' or 'dask://HOST:PORT'"
        if not isinstance(text, str):
            raise TypeError(f"executor: expected {expected}, got {text!r:.80}")
        if text in ("local", "dask"):
            return cls(text)
        match = _ADDRESS.match(text)
        if match is None:
            raise ValueError(f"executor: expected {expected}, got {text!r:.80}")
        port = match["port"]
        if port is None:
            port = DEFAULT_PORT
        elif not port.isdigit() or not 1 <= int(port) <= 65535:
            raise ValueError(f"executor: expected a port 1-65535 in {text!r:.80}, got {port!r}")
        return cls("dask", f"tcp://{match['host']}:{int(port)}")

    def __str__(self) -> str:
        if self.address is None:
            return self.kind
        return "dask://" + self.address.removeprefix("tcp://")


def _executor_type(text: str) -> ExecutorSpec:
    try:
        return ExecutorSpec.parse(text)
    except (TypeError, ValueError) as error:
        raise argparse.ArgumentTypeError(str(error).removeprefix("executor: ")) from None


def _timeout_type(text: str) -> float:
    expected = f"expected seconds in (0, {MAX_CONNECT_TIMEOUT:g}]"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{expected}, got {text!r}") from None
    if not (math.isfinite(value) and 0 < value <= MAX_CONNECT_TIMEOUT):
        raise argparse.ArgumentTypeError(f"{expected}, got {text}")
    return value


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    """Adds ``--executor`` and ``--connect-timeout`` to a command that runs trials.

    Open the choice with ``trial_executor(args.executor, workers,
    connect_timeout=args.connect_timeout)``; the command keeps its own
    ``--workers``.
    """
    parser.add_argument(
        "--executor", type=_executor_type, default=ExecutorSpec("local"),
        metavar="{local,dask,dask://HOST:PORT}",
        help="where trials run: 'local' (this machine's process pool, default), 'dask' (a "
             "Dask LocalCluster of --workers processes) or 'dask://HOST:PORT' (the workers of "
             "a running `dask scheduler`, on any machines)")
    parser.add_argument(
        "--connect-timeout", type=_timeout_type, default=None, metavar="SECONDS",
        help=f"dask://: give up when no scheduler answers, or it has no worker, within SECONDS "
             f"(default {CONNECT_TIMEOUT:g})")


def _chunk_type(text: str) -> int:
    if not (text.isascii() and text.isdigit()) or not 1 <= int(text) <= 10_000:
        raise argparse.ArgumentTypeError(f"expected an integer in 1..10000 (trials per Dask "
                                         f"task), got {text!r}")
    return int(text)


def add_chunk_argument(parser: argparse.ArgumentParser) -> None:
    """Adds ``--chunk N`` (trials per Dask task, :meth:`DaskExecutor.submit_many`) to a
    command that runs trials with ``--executor``; open with ``trial_executor(...,
    chunk=args.chunk or 1)``. :func:`check_executor_arguments` refuses it without Dask."""
    parser.add_argument(
        "--chunk", type=_chunk_type, default=None, metavar="N",
        help="dask: run N trials one after another in each Dask task (default 1): fewer "
             "tasks for the scheduler when trials are short or workers many; N x 2 trials "
             "per worker are then in flight")


def check_executor_arguments(args) -> None:
    """Before any work: ``--connect-timeout`` is refused without ``--executor
    dask://HOST:PORT`` (it would be silently ignored), and a ``dask://`` address
    must greet as a Dask server within the timeout (:mod:`.dask_probe`; nothing
    is written before). For any parsed namespace (does nothing without them)."""
    spec = getattr(args, "executor", None)
    timeout = getattr(args, "connect_timeout", None)
    if not isinstance(spec, ExecutorSpec):
        return
    if timeout is not None and spec.address is None:
        raise ValueError(f"--connect-timeout: only for --executor dask://HOST:PORT (a running "
                         f"scheduler), got --executor {spec}")
    chunk = getattr(args, "chunk", None)
    if chunk is not None and chunk != 1 and spec.kind != "dask":
        raise ValueError(f"--chunk: only for --executor dask or dask://HOST:PORT, got "
                         f"--executor {spec}")
    if spec.address is not None:

        probe_scheduler(spec.address, CONNECT_TIMEOUT if timeout is None else timeout)


# -------------------------------------------------------------- worker side
_SHIPPED: dict[str, object] = {}  # hash of the pickled objective -> the objective, per process


def _shipped(token: str, payload: bytes) -> _ShippedOnce:
    return _ShippedOnce(None, token, payload)


class _ShippedOnce:
    """An objective pickled once on the client and unpickled once per worker process.

    Pickles as ``(hash, bytes)`` and unpickles as the same light handle: the
    scheduler, which deserialises and re-serialises every task it receives
    (distributed >= 2024; in the client's process for a ``LocalCluster``),
    passes it on untouched. Only a call resolves it, in the worker: the
    objective unpickled for the same hash before in this process, so the
    objective's own caches (a Drake diagram built on its first call) live for
    the worker's lifetime instead of one trial. Dask has no per-worker object
    cache that survives a worker restart without the client's help; this
    needs none.
    """

    def __init__(self, objective, token: str | None = None, payload: bytes | None = None):
        if token is None:
            from distributed.protocol.pickle import dumps

            payload = dumps(objective)  # cloudpickle for what plain pickle cannot
            token = hashlib.sha1(payload).hexdigest()
        self.objective, self.token, self.payload = objective, token, payload

    def __reduce__(self):
        return _shipped, (self.token, self.payload)

    def resolve(self):
        """The objective: this process's one copy of it (unpickled on the first call)."""
        if self.objective is None:
            objective = _SHIPPED.get(self.token)
            if objective is None:
                if not _SHIPPED:
                    pin_blas()  # the first trial in this worker (a `dask worker --no-nanny` too)
                objective = _SHIPPED[self.token] = pickle.loads(self.payload)
            self.objective = objective
        return self.objective

    def __call__(self, *args, **kwargs):
        return self.resolve()(*args, **kwargs)


# ------------------------------------------------------------------- pools
class DaskExecutor(Executor):
    """A ``distributed.Client`` as the trial runner's executor.

    ``submit`` returns ``concurrent.futures`` futures (``pure=False``: two
    trials with equal arguments are two tasks). Trials are best run on a
    scheduler with ``distributed.scheduler.worker-saturation: 1.0`` (our
    LocalCluster sets it; see the README for ``dask scheduler``).
    :meth:`ship` pickles an objective once, to be unpickled once per worker;
    :meth:`trial_failure` turns Dask's errors into a failed trial (worker
    deaths) or :class:`ExecutorError` (lost scheduler).
    """

    def __init__(self, client, chunk: int = 1):
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise ValueError(f"chunk: expected an integer >= 1 (trials per Dask task), "
                             f"got {chunk!r}")
        self.client = client
        self.chunk = chunk  # trials per Dask task in submit_many (1: one task per trial)
        self._tasks: dict = {}  # Dask future not yet settled -> its bridge, or the
        # _Chunk of its trials' bridges (a dropped one is cancelled)
        self._lock = threading.Lock()

    @property
    def address(self) -> str:
        return str(self.client.scheduler.address)

    @property
    def max_workers(self) -> int:
        """Worker threads in the cluster now (at least 1)."""
        try:
            return max(1, sum(self.client.nthreads().values()))
        except Exception as error:  # noqa: BLE001 - a closed client or lost scheduler
            raise ExecutorError(f"cannot reach the Dask scheduler at {self.address}: "
                                f"{error}") from None

    def submit(self, fn, /, *args, **kwargs):
        """``fn(*args, **kwargs)`` on a worker, as a ``concurrent.futures.Future``.

        Bridged by hand rather than through ``client.get_executor()``: its
        bridge never settles when a result is lost with a dying worker and
        the gather fails (distributed 2026.8), which hangs the run.
        """
        task = self.client.submit(fn, *args, pure=False, **kwargs)
        bridge = Future()
        bridge.set_running_or_notify_cancel()
        with self._lock:
            self._tasks[task] = bridge
        task.add_done_callback(self._settle)  # in Dask's one callback thread
        return bridge

    def submit_many(self, fn, *iterables) -> list:
        """``fn(*args)`` for every ``args`` of ``zip(*iterables)``, sent to the scheduler
        as one batch (``client.map``: one graph update for all, ~1 ms of the loop per
        task instead of ~2.7 ms for one ``submit`` each here); their futures in order.

        With ``chunk`` > 1 the calls go in tasks of at most ``chunk`` calls each (sizes
        as even as can be), run one after another in one worker thread: the scheduler,
        the comms and the workers' state machines handle one task per chunk instead of
        one per trial. Each call still has its own future, settled when its chunk
        returns; a call that raises fails its own future only. A chunk whose worker
        died :data:`WORKER_DEATHS` times (Dask re-runs a lost chunk whole before that)
        has its calls sent again one per task, so only the call that kills its worker
        fails, after its own deaths."""
        if self.chunk > 1:
            return self._submit_chunks(fn, list(zip(*iterables, strict=True)))
        tasks = self.client.map(fn, *iterables, pure=False)
        bridges = []
        for task in tasks:
            bridge = Future()
            bridge.set_running_or_notify_cancel()
            with self._lock:
                self._tasks[task] = bridge
            task.add_done_callback(self._settle)
            bridges.append(bridge)
        return bridges

    def _submit_chunks(self, fn, calls: list) -> list:
        parts = math.ceil(len(calls) / self.chunk)
        edges = [round(i * len(calls) / parts) for i in range(parts + 1)]
        groups = [calls[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]
        bridges = []
        for _ in calls:
            bridge = Future()
            bridge.set_running_or_notify_cancel()
            bridges.append(bridge)
        if not groups:
            return bridges
        tasks = self.client.map(functools.partial(_run_chunk, fn), groups, pure=False)
        for task, a, b, group in zip(tasks, edges[:-1], edges[1:], groups, strict=True):
            with self._lock:
                self._tasks[task] = _Chunk(fn, group, bridges[a:b])
            task.add_done_callback(self._settle)
        return bridges

    def _settle(self, task):
        """Hands finished results to their bridges: every task finished by now in one
        gather (one round trip for all, not one each: ~1 ms of the client's and the
        scheduler's loop per task here, bench_scale), the rest one by one."""
        with self._lock:
            if task not in self._tasks:  # settled with an earlier batch
                return
            ready = [t for t in self._tasks if t.status == "finished"]
            if task not in ready:
                ready.append(task)
        finished = [t for t in ready if t.status == "finished"]
        alone = [t for t in ready if t.status != "finished"]
        if len(finished) > 1:
            try:
                results = self.client.gather(finished)
            except BaseException:  # noqa: BLE001 - e.g. a result lost with its worker
                alone += finished
            else:
                for done, result in zip(finished, results, strict=True):
                    self._resolve(done, result)
        else:
            alone += finished
        for done in alone:
            try:
                # Blocks while Dask recomputes a result lost with its worker.
                result = done.result()
            except BaseException as error:  # noqa: BLE001 - handed to the runner
                self._resolve(done, error=error)
            else:
                self._resolve(done, result)

    def _resolve(self, task, result=None, error=None):
        with self._lock:
            bridge = self._tasks.pop(task, None)
        if bridge is None:
            return
        if isinstance(bridge, _Chunk):
            self._resolve_chunk(bridge, result, error)
            return
        if error is None:
            bridge.set_result(result)
        else:
            bridge.set_exception(error)

    def _resolve_chunk(self, chunk: _Chunk, results, error):
        from distributed.scheduler import KilledWorker

        if error is None:
            for bridge, (ok, value) in zip(chunk.bridges, results, strict=True):
                if ok:
                    bridge.set_result(value)
                else:
                    bridge.set_exception(value)
        elif isinstance(error, KilledWorker) and len(chunk.calls) > 1:
            # The chunk's worker died WORKER_DEATHS times: its calls again, one per task,
            # so each has deaths of its own (the chunk=1 path from here on).
            try:
                tasks = self.client.map(chunk.fn, *zip(*chunk.calls, strict=True), pure=False)
            except BaseException as lost:  # noqa: BLE001 - e.g. the scheduler is gone
                for bridge in chunk.bridges:
                    bridge.set_exception(lost)
                return
            for task, bridge in zip(tasks, chunk.bridges, strict=True):
                with self._lock:
                    self._tasks[task] = bridge
                task.add_done_callback(self._settle)
        else:
            for bridge in chunk.bridges:
                bridge.set_exception(error)

    def ship(self, objective):
        return _ShippedOnce(objective)

    def trial_failure(self, error: BaseException) -> str | None:
        """The failure text of a trial whose future raised ``error``, or raise.

        Worker deaths (Dask's ``KilledWorker``, after its own re-runs) fail
        the trial; a cancelled task means the scheduler is gone.
        """
        from distributed.scheduler import KilledWorker

        if isinstance(error, KilledWorker):
            return (f"worker process died while running the trial, "
                    f"{error.allowed_failures + 1} times (on {error.last_worker.address} last; "
                    f"Dask re-ran it {error.allowed_failures} times, the scheduler's "
                    "distributed.scheduler.allowed-failures)")
        if isinstance(error, CancelledError | OSError):
            raise ExecutorError(
                f"lost the Dask scheduler at {self.address} ({type(error).__name__}: "
                f"{error or 'task cancelled'}); the trial log is intact: the trials that were "
                "running stay 'running' and run again when the command is repeated") from error
        return None

    def shutdown(self, wait=True, *, cancel_futures=False):
        with self._lock:
            tasks = list(self._tasks)
        if cancel_futures and tasks:
            self.client.cancel(tasks)
        elif wait and tasks:
            from distributed import wait as wait_for

            wait_for(tasks)


@dataclass(frozen=True)
class _Chunk:
    """The calls of one chunked Dask task and their futures, in order."""

    fn: object
    calls: list
    bridges: list


def _run_chunk(fn, calls) -> list:
    """Runs ``fn(*args)`` for each ``args`` of ``calls`` in turn (in a worker):
    ``(True, result)`` or ``(False, exception)`` per call, in order."""
    results = []
    for args in calls:
        try:
            results.append((True, fn(*args)))
        except Exception as error:  # noqa: BLE001 - that call's failure, not the chunk's
            results.append((False, error))
    return results


def as_executor(executor):
    """``executor``; a ``distributed.Client`` or its ``get_executor()`` made a DaskExecutor."""
    module = type(executor).__module__ or ""
    if not module.startswith("distributed"):
        return executor
    from distributed import Client
    from distributed.cfexecutor import ClientExecutor

    if isinstance(executor, Client):
        return DaskExecutor(executor)
    if isinstance(executor, ClientExecutor):
        # distributed has no public accessor for an executor's client.
        return DaskExecutor(executor._client)
    return executor


def executor_workers(executor) -> int:
    """How many trials ``executor`` runs at once (1 if it does not say)."""
    for name in ("max_workers", "_max_workers"):
        value = getattr(executor, name, None)
        if isinstance(value, int) and value >= 1:
            return value
    return 1


# ---------------------------------------------------------------- factory
@contextmanager
def trial_executor(executor="local", workers: int = 1, *, connect_timeout: float = CONNECT_TIMEOUT,
                   worker_deaths: int = WORKER_DEATHS, chunk: int = 1):
    """Opens the executor ``executor`` names (see :class:`ExecutorSpec`) and closes it after.

    Yields an ``InlineExecutor`` (``local``, one worker), a :class:`LocalPool`
    (``local``, more) or a :class:`DaskExecutor` (``dask``: a LocalCluster
    of ``workers`` processes, ``dask://HOST:PORT``: the scheduler's workers,
    ``workers`` is then not used here). Raises :class:`ExecutorError` when no
    scheduler answers at the address, or it has no worker, within
    ``connect_timeout`` s. ``chunk``: trials per Dask task (:meth:`DaskExecutor.submit_many`;
    Dask only). A ``dask`` executor holds its Dask settings while
    open: close several in the reverse order of opening (nested ``with``
    blocks or a ``contextlib.ExitStack`` do).
    """
    spec = ExecutorSpec.parse(executor)
    if spec.address is None:  # processes on this machine
        _check_local_workers(workers)
    elif isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if connect_timeout is None:
        connect_timeout = CONNECT_TIMEOUT
    if not (isinstance(connect_timeout, int | float)
            and 0 < connect_timeout <= MAX_CONNECT_TIMEOUT):
        raise ValueError(f"connect_timeout: expected seconds in (0, {MAX_CONNECT_TIMEOUT:g}], "
                         f"got {connect_timeout!r}")
    if not (isinstance(worker_deaths, int) and worker_deaths >= 1):
        raise ValueError(f"worker_deaths: expected an integer >= 1, got {worker_deaths!r}")
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: expected an integer >= 1 (trials per Dask task), got {chunk!r}")
    if chunk != 1 and spec.kind == "local":
        raise ValueError(f"chunk: only for a Dask executor, got chunk {chunk} with {spec}")
    if spec.kind == "local":
        pool = InlineExecutor() if workers == 1 else LocalPool(workers)
        try:
            yield pool
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        return
    if spec.address is not None:  # a bounded look first: Client trusts whatever answers

        probe_scheduler(spec.address, connect_timeout)
    try:
        # distributed loads its defaults into dask.config on import: *before* the
        # settings below, since set() on a missing "distributed" subtree records it as
        # new and deletes the whole subtree on exit (every later Client: KeyError).
        import dask
        import distributed  # noqa: F401
    except ImportError as error:
        raise ExecutorError(f"executor {spec}: Dask is not installed ({error}); "
                            "pip install 'handle_drake[dask]'") from None
    # For our LocalCluster (read while it runs, so set for its lifetime):
    # worker-saturation 1: a worker holds only the trial it runs, so a dying
    # worker makes no other trial "suspicious" (Dask counts a death against
    # every task assigned to the worker). lost-worker-timeout: LocalCluster
    # closes for good a worker away for longer (15 s by default), and a
    # worker that imports Drake on a loaded machine can take that long to
    # restart: the cluster would shrink to nothing and the run would wait.
    local_config = {"distributed.scheduler.allowed-failures": worker_deaths - 1,
                    "distributed.scheduler.worker-saturation": 1.0,
                    "distributed.deploy.lost-worker-timeout": "1 day",
                    **QUIET_WORKER}
    with dask.config.set(local_config if spec.address is None else {}):
        client, cluster = _connect(spec, workers, connect_timeout)
        try:
            yield DaskExecutor(client, chunk)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def _connect(spec: ExecutorSpec, workers, connect_timeout):
    from distributed import Client, LocalCluster

    if spec.address is None:
        # No dashboard; the scheduler's plain HTTP routes (health, metrics) still
        # start, on port 8787 unless told otherwise: a random port instead.
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
            scheduler_port=0, dashboard_address=None, silence_logs=_LOG_LEVEL,
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"})
        try:
            return Client(cluster), cluster
        except BaseException:
            cluster.close()
            raise

    try:  # a bounded look at the peer first: Client trusts whatever answers
        client = connect_client(spec.address, connect_timeout)
    except (OSError, TimeoutError) as error:
        raise ExecutorError(
            f"executor {spec}: no Dask scheduler answered at {spec.address} within "
            f"{connect_timeout:g} s ({error}); start one with `dask scheduler` and point "
            "workers at it with `dask worker " + spec.address + "`") from None
    try:
        client.wait_for_workers(1, timeout=connect_timeout)
    except (OSError, TimeoutError) as error:
        client.close()
        raise ExecutorError(
            f"executor {spec}: the scheduler at {spec.address} has no worker after "
            f"{connect_timeout:g} s ({error}); start some with `dask worker {spec.address}`"
        ) from None
    return client, None
