"""Trial log (SQLite) and runner: resume with no trial lost or repeated, failures, corruption."""

import math
import os
import signal
import sqlite3
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from handle_drake.learning import (
    InlineExecutor,
    RandomSearch,
    TrialLog,
    TrialLogError,
    TrialResult,
    maximize,
    run_experiment,
)
from handle_drake.learning.cluster import WORKER_DEATHS
from handle_drake.learning.test_functions import Branin

OPTIONS = dict(direct_maxfun=200, n_restarts=1)
BRANIN = Branin()


def run(objective, db, n_trials, strategy="bo", executor=None, **kwargs):
    kwargs.setdefault("objective_name", "branin")
    kwargs.setdefault("optimizer_options", OPTIONS if strategy == "bo" else None)
    return run_experiment(
        objective,
        BRANIN.bounds,
        strategy,
        n_trials,
        3,
        db,
        executor=executor or InlineExecutor(),
        progress=False,
        **kwargs,
    )


def parameters(db, run_id="branin-bo-seed3"):
    with TrialLog(db) as log:
        return np.array([r.parameters for r in log.trials(run_id)])


class CountingObjective:
    """Branin that counts its calls, and raises ``interrupt`` at call number ``stop_at``."""

    def __init__(self, stop_at=None, interrupt=KeyboardInterrupt):
        self.calls = []
        self.stop_at, self.interrupt = stop_at, interrupt

    def __call__(self, x):
        self.calls.append(np.array(x))
        if self.stop_at is not None and len(self.calls) == self.stop_at:
            raise self.interrupt("simulated kill")
        return BRANIN(x)


def test_logged_run_equals_in_memory_run(tmp_path):
    db = tmp_path / "trials.sqlite"
    result = run(BRANIN, db, 12)
    reference = maximize(BRANIN, BRANIN.bounds, 12, seed=3, **OPTIONS)
    with TrialLog(db) as log:
        records = log.trials(result.run_id)
        info = log.get_run(result.run_id)
    assert [r.index for r in records] == list(range(12))
    assert all(r.status == "done" for r in records)
    np.testing.assert_array_equal([r.parameters for r in records], reference.X)
    np.testing.assert_array_equal([r.metric for r in records], reference.Y)
    assert result.best_y == reference.y
    assert info.strategy == "bo" and info.seed == 3 and info.objective == "branin"
    assert info.config == OPTIONS
    np.testing.assert_array_equal(info.bounds, BRANIN.bounds)


def test_resume_after_interrupt_loses_and_repeats_nothing(tmp_path):
    n = 14
    run(BRANIN, tmp_path / "ref.sqlite", n)
    parameters_of_uninterrupted = parameters(tmp_path / "ref.sqlite")

    db = tmp_path / "run.sqlite"
    first = CountingObjective(stop_at=8)
    with pytest.raises(KeyboardInterrupt):
        run(first, db, n)
    with TrialLog(db) as log:
        statuses = [r.status for r in log.trials("branin-bo-seed3")]
    assert statuses == ["done"] * 7 + ["running"]

    second = CountingObjective()
    result = run(second, db, n)
    # the interrupted trial ran again with its stored parameters, then the rest
    assert len(second.calls) == n - 7
    np.testing.assert_array_equal(second.calls[0], first.calls[7])
    got = parameters(db)
    np.testing.assert_array_equal(got, parameters_of_uninterrupted)
    assert result.n_done == n and result.n_failed == 0
    # calling again does nothing: the run is complete
    third = CountingObjective()
    run(third, db, n)
    assert third.calls == []


KILL_SCRIPT = """
import sys, time
from handle_drake.learning import run_experiment, InlineExecutor
from handle_drake.learning.test_functions import Branin
branin = Branin()
def slow(x):
    time.sleep(0.15)
    return branin(x)
run_experiment(slow, branin.bounds, "bo", 16, 3, sys.argv[1], executor=InlineExecutor(),
               progress=False, objective_name="branin", optimizer_options=%r)
"""


def test_resume_after_sigkill_of_the_process(tmp_path):
    n = 16
    run(BRANIN, tmp_path / "ref.sqlite", n)
    expected = parameters(tmp_path / "ref.sqlite")

    db = tmp_path / "killed.sqlite"
    process = subprocess.Popen([sys.executable, "-c", KILL_SCRIPT % (OPTIONS,), str(db)])
    deadline = time.monotonic() + 120
    done = 0
    try:
        while time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.1)
            if db.exists():
                try:
                    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
                        done = conn.execute(
                            "SELECT COUNT(*) FROM trials WHERE status = 'done'"
                        ).fetchone()[0]
                except sqlite3.OperationalError:
                    continue  # schema not created yet
                if done >= 6:
                    break
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert process.returncode == -signal.SIGKILL, "the run finished before it was killed"
    assert 6 <= done < n

    with TrialLog(db) as log:
        before = log.trials("branin-bo-seed3")
    resumed = CountingObjective()
    run(resumed, db, n)
    after = parameters(db)
    np.testing.assert_array_equal(after, expected)  # none lost, none repeated, same sequence
    finished_before = sum(r.status == "done" for r in before)
    assert len(resumed.calls) == n - finished_before
    for record in before:  # what was stored before the kill is unchanged
        np.testing.assert_array_equal(after[record.index], record.parameters)


def test_failures_are_stored_and_the_run_goes_on(tmp_path):
    def flaky(x):
        if x[0] < -2.5:
            raise RuntimeError(f"simulator diverged at {x[0]:.3f}")
        if x[1] > 12.0:
            return math.nan
        return BRANIN(x)

    db = tmp_path / "flaky.sqlite"
    result = run(flaky, db, 16, strategy="random", objective_name="flaky")
    with TrialLog(db) as log:
        records = log.trials(result.run_id)
    assert len(records) == 16
    for r in records:
        if r.parameters[0] < -2.5:
            assert r.status == "failed" and "simulator diverged" in r.error and r.metric is None
        elif r.parameters[1] > 12.0:
            assert r.status == "failed" and "non-finite metric: nan" in r.error
        else:
            assert r.status == "done" and r.metric == BRANIN(r.parameters)
    assert result.n_failed == sum(r.status == "failed" for r in records) > 0
    assert result.n_done + result.n_failed == 16


def test_trial_result_contacts_scenario_and_seed_are_stored(tmp_path):
    seen_seeds = []

    def objective(x, seed):
        seen_seeds.append(seed)
        return TrialResult(
            metric=float(-np.sum(x**2)),
            contacts=[{"p_WC": [0.0, 0.01, 0.02], "force": 1.5}],
            scenario=f"object: sphere\noffset: {x.tolist()}\n",
        )

    db = tmp_path / "contacts.sqlite"
    result = run_experiment(
        objective,
        [(-1, 1), (-1, 1)],
        "random",
        5,
        11,
        db,
        executor=ThreadPoolExecutor(2),
        progress=False,
    )
    with TrialLog(db) as log:
        records = log.trials(result.run_id)
    assert sorted(seen_seeds) == sorted(r.seed for r in records)
    assert len(set(seen_seeds)) == 5
    for r in records:
        assert r.contacts == [{"p_WC": [0.0, 0.01, 0.02], "force": 1.5}]
        assert r.scenario == f"object: sphere\noffset: {r.parameters.tolist()}\n"
        assert r.metric == pytest.approx(-np.sum(r.parameters**2))
        assert r.wall_time >= 0 and r.finished_at >= r.started_at


def test_parallel_random_search_in_process_pool(tmp_path):
    """Default executor: spawned worker processes; same points as the in-memory sequence."""
    db = tmp_path / "parallel.sqlite"
    result = run_experiment(BRANIN, BRANIN.bounds, "random", 10, 5, db, progress=False)
    searcher = RandomSearch(BRANIN.bounds, seed=5)
    expected = np.array([searcher.ask() for _ in range(10)])
    with TrialLog(db) as log:
        records = log.trials(result.run_id)
    np.testing.assert_array_equal([r.parameters for r in records], expected)
    np.testing.assert_array_equal([r.metric for r in records], BRANIN(expected))


class DiesAtTrial:
    """Kills its worker process (as a segfaulting simulator would) for x[0] > 8."""

    name = "dies"

    def __call__(self, x):
        if x[0] > 8.0:
            os._exit(3)
        return BRANIN(x)


def test_a_dying_worker_fails_its_trial_only(tmp_path):
    db = tmp_path / "dying.sqlite"
    result = run_experiment(
        DiesAtTrial(), BRANIN.bounds, "random", 4, 2, db, progress=False, batch_size=1
    )
    with TrialLog(db) as log:
        records = log.trials(result.run_id)
    assert len(records) == 4
    dead = [r for r in records if r.parameters[0] > 8.0]
    assert len(dead) == 1, "seed 2 should propose one point with x[0] > 8 in 4 trials"
    for r in records:
        if r.parameters[0] > 8.0:  # run again by a fresh pool, WORKER_DEATHS times
            assert r.status == "failed"
            assert f"worker process died while running the trial, {WORKER_DEATHS} times" in r.error
        else:
            assert r.status == "done"


def test_mismatched_resume_is_refused(tmp_path):
    db = tmp_path / "t.sqlite"
    run(BRANIN, db, 3)
    with pytest.raises(ValueError, match="config"):
        run(BRANIN, db, 5, optimizer_options=dict(OPTIONS, direct_maxfun=100))
    with pytest.raises(ValueError, match="bounds"):
        run_experiment(
            BRANIN,
            [(-5, 10), (0, 14)],
            "bo",
            5,
            3,
            db,
            progress=False,
            objective_name="branin",
            optimizer_options=OPTIONS,
            executor=InlineExecutor(),
        )


def test_open_run_creates_resumes_and_names_what_differs(tmp_path):
    """The one create-or-check of a run (run_experiment, the in-hand runs)."""
    with TrialLog(tmp_path / "t.sqlite") as log:
        created = log.open_run("r", "ipso", [(0, 1), (0, 2)], 4, "task", {"shape": (1, 2)})
        # a resume with the same settings (a tuple is logged as a JSON list) gets the run
        again = log.open_run("r", "ipso", [(0, 1), (0, 2)], 4, "task", {"shape": [1, 2]})
        assert again.created_at == created.created_at and again.config == {"shape": [1, 2]}
        for change, field in ((dict(strategy="pso"), "strategy='ipso', got 'pso'"),
                              (dict(seed=5), "seed=4, got 5"),
                              (dict(objective="other"), "objective='task', got 'other'"),
                              (dict(config={"shape": [1, 3]}),
                               r"config.shape=\[1, 2\], got \[1, 3\]"),
                              (dict(config={}), r"config.shape=\[1, 2\], got \(missing\)")):
            settings = dict(strategy="ipso", seed=4, objective="task", config={"shape": (1, 2)})
            settings.update(change)
            with pytest.raises(ValueError, match=f"run 'r' exists in .* with {field}"):
                log.open_run("r", settings["strategy"], [(0, 1), (0, 2)], settings["seed"],
                             settings["objective"], settings["config"])
        with pytest.raises(ValueError, match=r"with bounds \[\[0.0, 1.0\], \[0.0, 2.0\]\]"):
            log.open_run("r", "ipso", [(0, 1), (0, 3)], 4, "task", {"shape": (1, 2)})
        assert [r.run_id for r in log.runs()] == ["r"]


def test_garbage_file_is_refused_and_left_untouched(tmp_path):
    path = tmp_path / "garbage.sqlite"
    content = os.urandom(4096)
    path.write_bytes(content)
    with pytest.raises(TrialLogError, match="not an SQLite database"):
        TrialLog(path)
    with pytest.raises(TrialLogError):
        run(BRANIN, path, 3)
    assert path.read_bytes() == content
    assert not (tmp_path / "garbage.sqlite-wal").exists()


def test_foreign_sqlite_database_is_refused(tmp_path):
    path = tmp_path / "other.sqlite"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE customers (name TEXT)")
        conn.execute("INSERT INTO customers VALUES ('ada')")
    content = path.read_bytes()
    with pytest.raises(TrialLogError, match="not a handle_drake trial log"):
        TrialLog(path)
    assert path.read_bytes() == content


def test_damaged_trial_log_is_refused(tmp_path):
    path = tmp_path / "damaged.sqlite"
    with TrialLog(path) as log:
        log.create_run("r", "random", [(0, 1)], 0, "f")
        for i in range(400):  # several pages of rows
            log.add_pending("r", i, [i / 400], i, scenario="x" * 200)
    size = path.stat().st_size
    assert size > 8 * 4096
    data = bytearray(path.read_bytes())
    data[3 * 4096 : 5 * 4096] = os.urandom(2 * 4096)  # scribble over two b-tree pages
    path.write_bytes(bytes(data))
    with pytest.raises(TrialLogError):
        TrialLog(path)
    assert path.read_bytes() == bytes(data)


def test_log_state_machine_and_bad_values(tmp_path):
    with TrialLog(tmp_path / "s.sqlite") as log:
        log.create_run("r", "bo", [(0, 1)], 0, "f")
        with pytest.raises(ValueError, match="already exists"):
            log.create_run("r", "bo", [(0, 1)], 0, "f")
        with pytest.raises(TrialLogError, match="run does not"):
            log.add_pending("missing", 0, [0.5], 0)
        log.add_pending("r", 0, [0.5], 0)
        with pytest.raises(TrialLogError, match="exists already"):
            log.add_pending("r", 0, [0.5], 0)
        with pytest.raises(ValueError, match="finite"):
            log.mark_done("r", 0, math.nan)
        log.mark_done("r", 0, 1.25)
        with pytest.raises(TrialLogError, match="not in state"):
            log.mark_failed("r", 0, "late failure")  # a done trial is never overwritten
        assert log.trials("r")[0].metric == 1.25
        with pytest.raises(ValueError, match="lower must be < upper"):
            log.create_run("bad", "bo", [(1, 0)], 0, "f")
    with pytest.raises(ValueError, match="n_trials"):
        run(BRANIN, tmp_path / "n.sqlite", -1)


def test_parallel_random_search_resumes_the_original_sequence(tmp_path):
    """Several trials in flight when interrupted: none lost, none repeated, same points."""
    n = 12
    db = tmp_path / "parallel_resume.sqlite"
    first = CountingObjective(stop_at=6)
    with pytest.raises(KeyboardInterrupt):
        run(first, db, n, strategy="random", executor=ThreadPoolExecutor(2), batch_size=3)
    with TrialLog(db) as log:
        before = log.trials("branin-random-seed3")
    unfinished = [r for r in before if r.status == "running"]
    assert unfinished, "the interruption should leave trials in flight"
    second = CountingObjective()
    run(second, db, n, strategy="random", executor=ThreadPoolExecutor(2), batch_size=3)
    searcher = RandomSearch(BRANIN.bounds, seed=3)
    expected = np.array([searcher.ask() for _ in range(n)])
    with TrialLog(db) as log:
        records = log.trials("branin-random-seed3")
    assert [r.index for r in records] == list(range(n))
    assert all(r.status == "done" for r in records)
    np.testing.assert_array_equal([r.parameters for r in records], expected)
    done_before = sum(r.status == "done" for r in before)
    assert len(second.calls) == n - done_before  # each unfinished or new trial ran once
    rerun = {tuple(r.parameters) for r in unfinished}
    assert rerun <= {tuple(c) for c in second.calls}


def test_unloggable_options_are_refused(tmp_path):
    with pytest.raises(TypeError, match="JSON serialisable"):
        run(BRANIN, tmp_path / "m.sqlite", 3, optimizer_options=dict(mean=lambda X: X[:, 0]))


class ShuffledBranin(CountingObjective):
    """Branin whose calls finish in a scrambled order (sleeps keyed on the point)."""

    def __call__(self, x):
        time.sleep(0.002 * (int(abs(x[0]) * 1e6) % 7))
        return super().__call__(x)


def test_parallel_bo_batches_are_reproducible_and_resume_exactly(tmp_path):
    """BO with batches of 2 on 2 threads: completions arrive in any order, yet
    the run is a function of its seed; a run killed inside a batch resumes
    into the very same trials, running each unfinished one once."""
    n, options = 16, dict(OPTIONS, batch_size=2)
    run_id = "branin-bo-seed3"
    reference = []
    for attempt in range(2):
        db = tmp_path / f"ref{attempt}.sqlite"
        run(ShuffledBranin(), db, n, executor=ThreadPoolExecutor(2), optimizer_options=options)
        reference.append(parameters(db, run_id))
    np.testing.assert_array_equal(reference[0], reference[1])
    assert len(reference[0]) == n and len({tuple(p) for p in reference[0]}) == n
    # The same options sequentially (batch 1) give another run.
    sequential = tmp_path / "seq.sqlite"
    run(BRANIN, sequential, n)
    assert not np.array_equal(parameters(sequential), reference[0])

    db = tmp_path / "killed.sqlite"
    first = ShuffledBranin(stop_at=13)  # inside the batch of trials 12 and 13
    with pytest.raises(KeyboardInterrupt):
        run(first, db, n, executor=ThreadPoolExecutor(2), optimizer_options=options)
    with TrialLog(db) as log:
        before = log.trials(run_id)
    assert any(r.status == "running" for r in before)
    second = ShuffledBranin()
    run(second, db, n, executor=ThreadPoolExecutor(2), optimizer_options=options)
    np.testing.assert_array_equal(parameters(db, run_id), reference[0])
    done_before = sum(r.status == "done" for r in before)
    assert len(second.calls) == n - done_before
    # A mismatched batch size for a BO runner is refused with the reason.
    with pytest.raises(ValueError, match="differs from the optimiser's batch_size 2"):
        run(BRANIN, tmp_path / "x.sqlite", 4, optimizer_options=options, batch_size=3)
