"""Trials on Dask: same runs as the local pool, worker deaths, lost and wrong schedulers.

A ``LocalCluster`` of 2 worker processes on loopback (random ports, no
dashboard) for the module; the objective is the Branin function (closed
form), wrapped where a test needs a worker to die or a trial to take time.
"""

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from handle_drake.learning import (
    InlineExecutor,
    RandomSearch,
    TrialLog,
    TrialResult,
    run_experiment,
)
from handle_drake.learning.cluster import (
    WORKER_DEATHS,
    DaskExecutor,
    ExecutorError,
    ExecutorSpec,
    LocalPool,
    trial_executor,
)
from handle_drake.learning.test_functions import Branin

BRANIN = Branin()
BO = dict(direct_maxfun=200, n_restarts=1, batch_size=2)


@pytest.fixture(scope="module")
def dask_executor():
    with trial_executor("dask", 2) as executor:
        yield executor


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run(db, strategy, n_trials, executor, objective=BRANIN, seed=4, **kwargs):
    return run_experiment(
        objective, BRANIN.bounds, strategy, n_trials, seed, db, executor=executor,
        progress=False, objective_name="branin",
        optimizer_options=BO if strategy == "bo" else None, **kwargs)


def _rows(result):
    return _record_rows(result.trials)


def _record_rows(records):
    return [(r.index, r.status, r.parameters.tolist(), r.metric, r.seed) for r in records]


class DiesOnce:
    """Branin that kills its worker process (SIGKILL, as a crashing simulator would) the
    first time it runs a trial with ``x[0] > threshold``; a marker file remembers the death
    across processes. With ``always`` it kills the worker every time."""

    name = "branin"

    def __init__(self, marker: Path, threshold=5.0, always=False):
        self.marker, self.threshold, self.always = str(marker), threshold, always

    def __call__(self, x):
        if x[0] > self.threshold and (self.always or not os.path.exists(self.marker)):
            with open(self.marker, "a") as f:
                f.write(f"{os.getpid()}\n")
            os.kill(os.getpid(), signal.SIGKILL)
        return BRANIN(x)


def test_executor_choice_is_parsed_or_refused_with_the_field_named():
    assert ExecutorSpec.parse("local") == ExecutorSpec("local")
    assert ExecutorSpec.parse("dask") == ExecutorSpec("dask", None)
    assert ExecutorSpec.parse("dask://10.0.0.7:9000").address == "tcp://10.0.0.7:9000"
    assert ExecutorSpec.parse("dask://head-node").address == "tcp://head-node:8786"
    assert str(ExecutorSpec.parse("dask://h:1234")) == "dask://h:1234"
    for bad in ("ray", "dask://", "dask://h:0", "dask://h:70000", "dask://h:x", "tcp://h:1"):
        with pytest.raises(ValueError, match="executor"):
            ExecutorSpec.parse(bad)
    with pytest.raises(ValueError, match="workers"):
        with trial_executor("dask", 0):
            pass


def test_a_dask_executor_leaves_dasks_settings_whole_for_the_next_one():
    """The first Dask executor of a fresh process (distributed not yet imported) once
    deleted distributed's whole config subtree on closing: every later Client failed
    with KeyError 'distributed'. Two in a row in a new process, then the config."""
    code = (
        "from handle_drake.learning.cluster import trial_executor\n"
        "for _ in range(2):\n"
        "    with trial_executor('dask', 1) as pool:\n"
        "        assert pool.submit(pow, 2, 10).result() == 1024\n"
        "import dask\n"
        "print(dask.config.get('distributed.client.direct-to-workers', 'missing'))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] != "missing"


def test_bo_and_random_runs_on_dask_equal_the_local_pool(tmp_path, dask_executor):
    """Same seed, same trials and metrics: the run does not depend on the executor. The
    Dask runs get a bare ``distributed.Client`` and its ``get_executor()``."""
    client = dask_executor.client
    with LocalPool(2) as pool:
        local_bo = _run(tmp_path / "local.sqlite", "bo", 20, pool)
        local_random = _run(tmp_path / "local.sqlite", "random", 20, pool)
    dask_bo = _run(tmp_path / "dask.sqlite", "bo", 20, client.get_executor())
    dask_random = _run(tmp_path / "dask.sqlite", "random", 20, client)
    assert _rows(dask_bo) == _rows(local_bo)
    assert _rows(dask_random) == _rows(local_random)
    assert len(dask_bo.trials) == 20 and dask_bo.n_done == 20
    X = np.array([r.parameters for r in dask_random.trials])
    searcher = RandomSearch(BRANIN.bounds, seed=4)
    np.testing.assert_array_equal(X, [searcher.ask() for _ in range(20)])
    np.testing.assert_array_equal([r.metric for r in dask_random.trials], BRANIN(X))


@pytest.mark.parametrize("strategy", ["bo", "random"])
def test_a_worker_killed_mid_trial_loses_and_repeats_nothing(tmp_path, dask_executor, strategy):
    """One worker process dies in the middle of a trial; Dask runs the trial again on
    another; the log holds each trial once, equal to an undisturbed local run."""
    marker = tmp_path / "deaths"
    killed = _run(tmp_path / "dask.sqlite", strategy, 6, dask_executor, DiesOnce(marker))
    assert marker.exists(), "no trial had x[0] > 5: the worker was never killed"
    reference = _run(tmp_path / "ref.sqlite", strategy, 6, InlineExecutor())
    assert _rows(killed) == _rows(reference)
    assert [r.status for r in killed.trials] == ["done"] * 6
    with TrialLog(tmp_path / "dask.sqlite") as log:
        count = log._conn.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    assert count == 6


def test_a_trial_that_always_kills_its_worker_fails_after_the_stated_deaths(
        tmp_path, dask_executor):
    marker = tmp_path / "deaths"
    result = _run(tmp_path / "dask.sqlite", "random", 4, dask_executor,
                  DiesOnce(marker, threshold=8.0, always=True), seed=2)
    dead = [r for r in result.trials if r.parameters[0] > 8.0]
    assert len(dead) == 1, "seed 2 proposes one point with x[0] > 8 in 4 trials"
    assert dead[0].status == "failed"
    assert f"died while running the trial, {WORKER_DEATHS} times" in dead[0].error
    assert len(marker.read_text().split()) == WORKER_DEATHS
    assert all(r.status == "done" for r in result.trials if r.parameters[0] <= 8.0)
    assert len(result.trials) == 4


class Counting:
    """Branin that counts its own calls and reports its process and its BLAS threads."""

    name = "branin"

    def __init__(self):
        self.calls = 0

    def __call__(self, x):
        from threadpoolctl import threadpool_info

        self.calls += 1
        blas = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
        return TrialResult(BRANIN(x), {"pid": os.getpid(), "calls": self.calls, "blas": blas})


def test_each_worker_keeps_the_objective_it_received_once_and_runs_one_blas_thread(
        tmp_path, dask_executor):
    """The objective is unpickled once per worker process and kept (so is a Drake diagram
    it builds on its first call): a worker's trials see its call count go 1, 2, 3, ...;
    an objective unpickled per trial would count 1 every time."""
    result = _run(tmp_path / "count.sqlite", "random", 8, dask_executor, Counting())
    calls: dict[int, list] = {}
    for r in result.trials:
        calls.setdefault(r.contacts["pid"], []).append(r.contacts["calls"])
        assert r.contacts["blas"] and set(r.contacts["blas"]) == {1}
        assert r.metric == BRANIN(r.parameters)
    assert os.getpid() not in calls and sum(map(len, calls.values())) == 8
    for counts in calls.values():
        assert sorted(counts) == list(range(1, len(counts) + 1))
    assert max(map(len, calls.values())) > 1


def test_our_cluster_workers_run_without_the_profiler_and_the_fast_tick(dask_executor):
    """A worker's event loop shares the GIL with its trial: our LocalCluster's workers run
    neither Dask's statistical profiler (every 10 ms) nor the 20 ms event-loop tick, and
    poll memory every 1 s and the system every 2 s (not 100 and 500 ms), nor do the
    workers the nannies restart after the deaths of earlier tests."""

    def settings(dask_worker):
        import dask

        return ("profile" in dask_worker.periodic_callbacks,
                dask.config.get("distributed.admin.tick.interval"),
                dask.config.get("distributed.worker.memory.monitor-interval"),
                dask.config.get("distributed.admin.system-monitor.interval"))

    dask_executor.client.wait_for_workers(2, timeout=120)  # one may be restarting
    seen = dask_executor.client.run(settings)
    assert len(seen) == 2 and set(seen.values()) == {(False, "1s", "1s", "2s")}


class InFlight(ThreadPoolExecutor):
    """A 2-thread pool that records the most trials submitted and not yet finished."""

    def __init__(self):
        super().__init__(2)
        self.now = self.most = 0
        self.lock = threading.Lock()

    def submit(self, fn, /, *args, **kwargs):
        with self.lock:
            self.now += 1
            self.most = max(self.most, self.now)
        future = super().submit(fn, *args, **kwargs)
        future.add_done_callback(self._done)
        return future

    def _done(self, _):
        with self.lock:
            self.now -= 1


def _slow_branin(x):
    time.sleep(0.05)
    return BRANIN(x)


def test_random_search_queues_a_trial_per_worker_and_bo_keeps_its_batch(tmp_path):
    """Random search keeps 2 x workers trials in flight (a worker finds its next trial
    queued instead of waiting for the client to log one and submit another); BO's
    synchronous batches stay at its batch size; the inline executor runs one at a time.
    The trials are the seeded sequence whatever the count."""
    with InFlight() as pool:
        queued = _run(tmp_path / "a.sqlite", "random", 12, pool, _slow_branin)
    assert pool.most == 4
    with InFlight() as pool:
        bo = _run(tmp_path / "b.sqlite", "bo", 12, pool, _slow_branin)
    assert pool.most == 2
    assert bo.n_done == 12
    reference = _run(tmp_path / "c.sqlite", "random", 12, InlineExecutor(), _slow_branin)
    assert _rows(queued) == _rows(reference)


class MapSizes:
    """A Dask client that records, per ``map``, how many calls each task carries."""

    def __init__(self, client):
        self._client, self.tasks, self.calls = client, [], []

    def map(self, fn, *iterables, **kwargs):
        iterables = [list(i) for i in iterables]
        chunked = getattr(fn, "func", None) is not None and fn.func.__name__ == "_run_chunk"
        sizes = [len(g) for g in iterables[0]] if chunked else [1] * len(iterables[0])
        self.tasks += sizes
        self.calls.append(sizes)
        return self._client.map(fn, *iterables, **kwargs)

    def __getattr__(self, name):
        return getattr(self._client, name)


def _chunked(dask_executor, chunk):
    return DaskExecutor(MapSizes(dask_executor.client), chunk=chunk)


def test_a_chunked_run_equals_the_inline_reference_with_fewer_tasks(tmp_path, dask_executor):
    """Trials in chunks of 3 per Dask task: the same trials, results and log as one trial at
    a time in this process, each trial logged once, in tasks of at most 3 trials; the
    runner keeps a chunk running and one queued per worker (2 x 2 x 3 = 12 at first)."""
    executor = _chunked(dask_executor, 3)
    chunked = _run(tmp_path / "dask.sqlite", "random", 20, executor)
    reference = _run(tmp_path / "ref.sqlite", "random", 20, InlineExecutor())
    assert _rows(chunked) == _rows(reference)
    assert chunked.n_done == 20
    sizes = executor.client.tasks
    assert sum(sizes) == 20 and max(sizes) == 3 and sizes[:4] == [3, 3, 3, 3]
    assert len(sizes) < 10
    # the first chunk is sent alone, before the rest of the first fill (12) is asked
    assert executor.client.calls[:2] == [[3], [3, 3]]
    bo = _run(tmp_path / "dask.sqlite", "bo", 8, _chunked(dask_executor, 2))
    assert _rows(bo) == _rows(_run(tmp_path / "ref.sqlite", "bo", 8, InlineExecutor()))
    with pytest.raises(ValueError, match="chunk"):
        DaskExecutor(dask_executor.client, chunk=0)
    with pytest.raises(ValueError, match="chunk: only for a Dask executor"):
        with trial_executor("local", 1, chunk=2):
            pass


def test_chunk_flag_is_checked_with_the_flag_named(tmp_path, capsys):
    """``--chunk``: an integer >= 1 (exit 2 naming the flag), and only with Dask."""
    from handle_drake.apps.babbling.cli import main

    base = ["babble", "--object", "sphere", "--trials", "2", "--db", str(tmp_path / "b.sqlite"),
            "--no-progress", "--no-plot"]
    for bad in ("0", "two", "-1"):
        with pytest.raises(SystemExit) as stop:
            main([*base, "--executor", "dask", "--chunk", bad])
        assert stop.value.code == 2
        assert "--chunk" in capsys.readouterr().err
    assert main([*base, "--chunk", "2"]) == 2
    err = capsys.readouterr().err
    assert "--chunk: only for --executor dask" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b.sqlite").exists()


def _raises_above_five(x):
    if x[0] > 5.0:
        raise ValueError(f"no trial at x[0] = {x[0]:.3f}")
    return BRANIN(x)


def test_a_failure_inside_a_chunk_fails_that_trial_only(tmp_path, dask_executor):
    """A call that raises inside a chunk fails its own future; the others of the chunk
    return. Through the runner: the trials that raise are failed with their error, the
    rest done, the log equal to the inline run's."""
    executor = DaskExecutor(dask_executor.client, chunk=4)
    futures = executor.submit_many(divmod, [7, 1, 9, 8], [2, 0, 4, 3])
    assert futures[0].result(timeout=60) == (3, 1)
    with pytest.raises(ZeroDivisionError):
        futures[1].result(timeout=60)
    assert [f.result(timeout=60) for f in futures[2:]] == [(2, 1), (2, 2)]
    chunked = _run(tmp_path / "dask.sqlite", "random", 12, _chunked(dask_executor, 4),
                   _raises_above_five)
    reference = _run(tmp_path / "ref.sqlite", "random", 12, InlineExecutor(),
                     _raises_above_five)
    assert _rows(chunked) == _rows(reference)
    failed = [r for r in chunked.trials if r.status == "failed"]
    assert failed and len(failed) < 12
    assert all("no trial at x[0]" in r.error for r in failed)
    assert all((r.status == "failed") == (r.parameters[0] > 5.0) for r in chunked.trials)


def test_a_worker_killed_mid_chunk_reruns_its_trials_and_repeats_nothing(
        tmp_path, dask_executor):
    """A worker dies in the middle of a chunk: Dask runs the chunk again on another worker;
    the log holds each trial once, equal to an undisturbed run here."""
    marker = tmp_path / "deaths"
    killed = _run(tmp_path / "dask.sqlite", "random", 9, _chunked(dask_executor, 3),
                  DiesOnce(marker))
    assert len(marker.read_text().split()) == 1
    reference = _run(tmp_path / "ref.sqlite", "random", 9, InlineExecutor())
    assert _rows(killed) == _rows(reference)
    with TrialLog(tmp_path / "dask.sqlite") as log:
        count = log._conn.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    assert count == 9


def test_a_trial_that_always_kills_its_worker_fails_alone_out_of_its_chunk(
        tmp_path, dask_executor):
    """The chunk dies WORKER_DEATHS times, then its trials run one per task: the killer
    is failed after its own WORKER_DEATHS deaths, its chunk mates are done."""
    marker = tmp_path / "deaths"
    result = _run(tmp_path / "dask.sqlite", "random", 4, _chunked(dask_executor, 2),
                  DiesOnce(marker, threshold=8.0, always=True), seed=2)
    dead = [r for r in result.trials if r.parameters[0] > 8.0]
    assert len(dead) == 1, "seed 2 proposes one point with x[0] > 8 in 4 trials"
    assert dead[0].status == "failed"
    assert f"died while running the trial, {WORKER_DEATHS} times" in dead[0].error
    assert len(marker.read_text().split()) == 2 * WORKER_DEATHS  # as a chunk, then alone
    assert all(r.status == "done" for r in result.trials if r.parameters[0] <= 8.0)
    assert len(result.trials) == 4


def test_a_worker_killed_in_the_local_pool_reruns_its_trial_once(tmp_path):
    marker = tmp_path / "deaths"
    with LocalPool(2) as pool:
        killed = _run(tmp_path / "local.sqlite", "random", 4, pool, DiesOnce(marker))
    assert len(marker.read_text().split()) == 1  # one death, then the trial ran alone
    reference = _run(tmp_path / "ref.sqlite", "random", 4, InlineExecutor())
    assert _rows(killed) == _rows(reference)


def test_a_wrong_scheduler_address_fails_fast_with_a_clear_message(tmp_path, capsys):
    from handle_drake.apps.babbling.cli import main

    address = f"127.0.0.1:{_free_port()}"  # nothing listens there
    outcome = {}

    def connect():
        try:
            with trial_executor(f"dask://{address}", connect_timeout=1.0):
                outcome["error"] = None
        except ExecutorError as error:
            outcome["error"] = error

    thread = threading.Thread(target=connect, daemon=True)
    thread.start()
    thread.join(60)  # a guard against a hang, not a timing assertion
    assert not thread.is_alive(), "connecting to a wrong address hangs"
    assert "no Dask scheduler answered at tcp://" + address in str(outcome["error"])
    db = tmp_path / "never.sqlite"
    code = main(["babble", "--executor", f"dask://{address}", "--connect-timeout", "1",
                 "--db", str(db), "--no-progress", "--no-plot"])
    assert code == 2
    assert "no Dask scheduler answered" in capsys.readouterr().err
    from handle_drake.cli import main as cli_main

    code = cli_main(["inhand", "--executor", f"dask://{address}", "--connect-timeout", "1",
                     "--db", str(tmp_path / "inhand.sqlite"), "--no-progress", "--no-plot",
                     "--no-html"])
    assert code == 2
    assert "no Dask scheduler answered" in capsys.readouterr().err
    with TrialLog(tmp_path / "inhand.sqlite") as log:
        assert log.runs() == []  # refused before any trial
    assert main(["report", "--executor", f"dask://{address}", "--connect-timeout", "1",
                 "--out", str(tmp_path / "report"), "--reduced", "--no-progress"]) == 2
    assert "no Dask scheduler answered" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main(["babble", "--executor", "dask://h:99999", "--db", str(db)])
    assert exit_.value.code == 2
    assert "--executor: expected a port 1-65535" in capsys.readouterr().err


class Slow:
    name = "branin"

    def __call__(self, x):
        time.sleep(0.4)
        return BRANIN(x)


def _start(args):
    # The same code as this process (a deployment installs the same checkout everywhere).
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    return subprocess.Popen([sys.executable, "-m", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)


def test_a_lost_scheduler_is_a_clear_error_and_the_log_resumes(tmp_path):
    """A real ``dask scheduler`` and ``dask worker`` on loopback; the scheduler is killed
    mid-run: ExecutorError, and the run resumes later (here on the local executor) into
    the same trials as an undisturbed run."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = _start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port",
                        str(port), "--no-dashboard"])
    worker = _start(["distributed.cli.dask_worker", address, "--nthreads", "1",
                     "--no-dashboard", "--host", "127.0.0.1"])
    db = tmp_path / "lost.sqlite"
    TrialLog(db).close()  # the schema exists before two connections look at the file
    try:
        with trial_executor(f"dask://127.0.0.1:{port}", connect_timeout=60) as executor:
            assert isinstance(executor, DaskExecutor)

            def kill_when_a_trial_is_done():
                while True:
                    time.sleep(0.1)
                    with TrialLog(db) as log:
                        runs = log.runs()
                        if runs and log.trials(runs[0].run_id, "done"):
                            break
                scheduler.kill()

            killer = threading.Thread(target=kill_when_a_trial_is_done, daemon=True)
            killer.start()
            with pytest.raises(ExecutorError, match="lost the Dask scheduler"):
                _run(db, "random", 12, executor, Slow())
            killer.join(30)
    finally:
        for process in (scheduler, worker):
            process.kill()
            process.wait(30)
    with TrialLog(db) as log:
        statuses = [r.status for r in log.trials("branin-random-seed4")]
    assert "done" in statuses and len(statuses) < 12
    resumed = _run(db, "random", 12, InlineExecutor())
    reference = _run(tmp_path / "ref.sqlite", "random", 12, InlineExecutor())
    assert _rows(resumed) == _rows(reference)


@pytest.mark.parametrize("chunk", [[], ["--chunk", "2"]], ids=["one-per-task", "chunk-2"])
def test_babble_on_a_dask_cluster_logs_real_grasp_trials_as_simulated_here(tmp_path, chunk):
    """The real grasp trial: ``babble --executor dask`` (2 worker processes) logs each
    trial once, and each metric is what the same simulation gives in this process; the
    same with 2 trials per Dask task (``--chunk 2``)."""
    from handle_drake.apps.babbling.cli import main
    from handle_drake.trial.grasp_trial import GraspTrial

    db = tmp_path / "babble.sqlite"
    assert main(["babble", "--object", "sphere", "--dims", "2", "--strategy", "random",
                 "--trials", "4", "--seed", "2", "--noise", "0.01", "--executor", "dask",
                 "--workers", "2", "--db", str(db), "--no-progress", "--no-plot",
                 *chunk]) == 0
    with TrialLog(db) as log:
        (run,) = log.runs()
        rows = log.trials(run.run_id)
    assert [r.index for r in rows] == [0, 1, 2, 3]
    assert all(r.status == "done" for r in rows)
    trial = GraspTrial(hand="barrett", object="sphere", space="offset", noise=0.01)
    for row in rows[:2]:
        assert row.metric == trial(row.parameters, seed=row.seed).metric


def test_inhand_pso_on_a_dask_cluster_equals_the_run_in_process(tmp_path, capsys,
                                                                dask_executor):
    """``handle-drake inhand --executor dask://HOST:PORT`` (the module's 2-process
    LocalCluster): two iterations of Algorithm 2 (4 particles) log the same particles and
    scores, trial for trial, as the same run simulated in this process."""
    from handle_drake.apps.inhand.experiment import run_inhand
    from handle_drake.cli import main as cli_main

    db = tmp_path / "inhand.sqlite"
    address = "dask://" + dask_executor.address.removeprefix("tcp://")
    assert cli_main(["inhand", "--optimizer", "ipso", "--particles", "4", "--trials", "8",
                     "--seed", "1", "--executor", address, "--db", str(db),
                     "--no-progress", "--no-plot", "--no-html"]) == 0
    assert f"({address} executor)" in capsys.readouterr().out
    with TrialLog(db) as log:
        (run,) = log.runs()
        rows = log.trials(run.run_id)
    reference = run_inhand("cylinder_rotation", "ipso", 8, 1, 1, tmp_path / "ref.sqlite", 4,
                           progress=False)
    assert run.run_id == reference.run_id
    assert _record_rows(rows) == _record_rows(reference.records)
    assert [r.status for r in rows] == ["done"] * 8
    # the swarm moved: the second iteration's particles are not the first's
    X = np.array([r.parameters for r in rows])
    assert not np.allclose(X[:4], X[4:])
    # in Python, run_inhand takes a bare distributed.Client as its executor
    first = run_inhand("cylinder_rotation", "ipso", 4, None, 1, tmp_path / "client.sqlite", 4,
                       progress=False, executor=dask_executor.client)
    assert _record_rows(first.records) == _record_rows(reference.records[:4])


def test_the_reports_grids_and_runs_on_dask_equal_those_simulated_here(tmp_path, dask_executor):
    """``report --executor dask``'s two parts: a ground-truth grid evaluated in chunks on
    the workers (the client writes the cache) and a batch of runs driven by client threads
    give the values and trials of the same grid and runs in this process. The grid gets a
    bare ``distributed.Client``."""
    from handle_drake.apps.babbling.babbling import RunSpec, grid_values, run_batch
    from handle_drake.trial.grasp_trial import GraspTrialConfig

    config = GraspTrialConfig(hand="barrett", object="sphere", space="offset")
    _, on_dask = grid_values(config, 2, tmp_path / "grids", executor=dask_executor.client)
    _, here = grid_values(config, 2)
    np.testing.assert_array_equal(on_dask, here)
    assert on_dask.shape == (2, 2) and len(list((tmp_path / "grids").glob("*.npz"))) == 1
    specs = [RunSpec(config, "random", seed, n_trials=1) for seed in (0, 1)]
    run_batch(specs, tmp_path / "dask.sqlite", progress=False, executor=dask_executor)
    run_batch(specs, tmp_path / "here.sqlite", progress=False)
    for spec in specs:
        with TrialLog(tmp_path / "dask.sqlite") as a, TrialLog(tmp_path / "here.sqlite") as b:
            rows = _record_rows(a.trials(spec.run_id))
            assert len(rows) == 1 and rows == _record_rows(b.trials(spec.run_id))


def test_babble_bo_on_a_running_cluster_proposes_batches_of_its_worker_count(
        tmp_path, capsys, dask_executor):
    """``babble --strategy bo --executor dask://HOST:PORT`` without --workers (the README's
    cluster command): BO proposes batches of the cluster's workers (2 here), not one trial
    at a time; --workers 1 still asks for the sequential BO."""
    from handle_drake.apps.babbling.cli import main

    address = "dask://" + dask_executor.address.removeprefix("tcp://")
    db = tmp_path / "babble.sqlite"
    common = ["babble", "--object", "sphere", "--dims", "2", "--strategy", "bo", "--trials",
              "4", "--seed", "3", "--executor", address, "--db", str(db), "--no-progress",
              "--no-plot"]
    assert main(common) == 0
    assert "BO batches of 2 trial(s)" in capsys.readouterr().out
    assert main(common + ["--workers", "1"]) == 0
    with TrialLog(db) as log:
        runs = log.runs()
        print({r.run_id: r.config for r in runs})
        assert sorted(r.config.get("batch_size", 1) for r in runs) == [1, 2]
        for run in runs:
            assert [t.status for t in log.trials(run.run_id)] == ["done"] * 4
