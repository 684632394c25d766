"""Group commits of the trial log: what is on disk when, and kill -9 in the middle of a group."""

import itertools
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from handle_drake.learning import InlineExecutor, TrialLog, run_experiment
from handle_drake.learning.test_functions import Branin

BRANIN = Branin()


def on_disk(db, status="done") -> int:
    """Trials of ``status`` another connection sees (what survives a kill -9)."""
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
        return conn.execute("SELECT COUNT(*) FROM trials WHERE status = ?",
                            (status,)).fetchone()[0]


def finish(log, index):
    log.add_pending("r", index, [0.0, 0.0], index, running=True)
    log.mark_done("r", index, float(index))


def test_a_group_is_committed_at_its_count_its_age_a_read_and_its_end(tmp_path):
    db = tmp_path / "groups.sqlite"
    with TrialLog(db) as log:
        log.create_run("r", "random", BRANIN.bounds, 0, "branin")
        with log.grouped(count=3, seconds=3600):
            finish(log, 0)
            finish(log, 1)
            assert on_disk(db) == 0 and on_disk(db, "running") == 0  # in memory only
            assert 3590 < log.due_in() <= 3600
            finish(log, 2)  # the third finished trial: the group is due
            assert on_disk(db) == 3 and log.due_in() is None
            finish(log, 3)
            assert on_disk(db) == 3
            assert [r.index for r in log.trials("r")] == [0, 1, 2, 3]  # a read commits first
            assert on_disk(db) == 4
            log.add_pending("r", 4, [0.0, 0.0], 4)
            assert on_disk(db, "pending") == 0
        assert on_disk(db, "pending") == 1  # leaving the block commits
        with log.grouped(count=1000, seconds=0.2):
            finish(log, 5)
            assert not log.commit_if_due() and on_disk(db) == 4
            time.sleep(0.25)
            assert log.due_in() == 0.0
            assert log.commit_if_due() and on_disk(db) == 5
        # outside a group every write is durable at once, as before
        finish(log, 6)
        assert on_disk(db) == 6


def test_a_bad_write_in_a_group_fails_the_commit_and_commits_none_of_it(tmp_path):
    db = tmp_path / "bad.sqlite"
    with TrialLog(db) as log:
        log.create_run("r", "random", BRANIN.bounds, 0, "branin")
        finish(log, 0)
        with pytest.raises(Exception, match="trial 0 of run 'r' exists already|is not in state"):
            with log.grouped(count=10, seconds=3600):
                finish(log, 1)
                log.mark_done("r", 0, 1.0)  # done already: refused at the commit
        assert [(r.index, r.metric) for r in log.trials("r")] == [(0, 0.0)]


@pytest.mark.parametrize("every, seconds, message", [
    (0, 1.0, "commit_every: expected an integer >= 1, got 0"),
    (True, 1.0, "commit_every"),
    (10, -1.0, "commit_seconds: expected a finite number >= 0, got -1.0"),
    (10, float("nan"), "commit_seconds"),
])
def test_bad_group_bounds_are_refused_naming_the_argument(tmp_path, every, seconds, message):
    with pytest.raises(ValueError, match=message):
        run_experiment(BRANIN, BRANIN.bounds, "random", 2, 0, tmp_path / "x.sqlite",
                       executor=InlineExecutor(), progress=False, commit_every=every,
                       commit_seconds=seconds)


GROUP_KILL_SCRIPT = """
import os, signal, sys
from handle_drake.learning import run_experiment, InlineExecutor
from handle_drake.learning.test_functions import Branin
branin = Branin()
calls = []
def dies(x):
    calls.append(1)
    if len(calls) == 37:  # trial 36: kill -9, no goodbye
        os.kill(os.getpid(), signal.SIGKILL)
    return branin(x)
run_experiment(dies, branin.bounds, "random", 60, 3, sys.argv[1], executor=InlineExecutor(),
               progress=False, objective_name="branin", commit_every=10, commit_seconds=3600)
"""


def test_sigkill_inside_a_group_loses_only_that_group_and_repeats_nothing(tmp_path):
    """Groups of 10 finished trials; killed while trial 36 runs. On disk: trials 0-29
    (three groups), nothing of 30-36. The resumed run evaluates 30-59 once each and
    the log equals the uninterrupted run's."""
    n = 60
    reference = run_experiment(BRANIN, BRANIN.bounds, "random", n, 3, tmp_path / "ref.sqlite",
                               executor=InlineExecutor(), progress=False,
                               objective_name="branin")
    db = tmp_path / "killed.sqlite"
    process = subprocess.run([sys.executable, "-c", GROUP_KILL_SCRIPT, str(db)], timeout=300)
    assert process.returncode == -signal.SIGKILL
    with TrialLog(db) as log:
        before = log.trials("branin-random-seed3")
    assert [r.index for r in before] == list(range(30))  # a commit per trial would hold 37
    assert all(r.status == "done" for r in before)
    calls = []

    def counting(x):
        calls.append(np.array(x))
        return BRANIN(x)

    result = run_experiment(counting, BRANIN.bounds, "random", n, 3, db,
                            executor=InlineExecutor(), progress=False, objective_name="branin",
                            commit_every=10, commit_seconds=3600)
    expected = [r.parameters for r in reference.trials]
    assert len(calls) == n - 30
    np.testing.assert_array_equal(calls, expected[30:])  # 30-36 again, then the rest
    np.testing.assert_array_equal([r.parameters for r in result.trials], expected)
    assert [r.metric for r in result.trials] == [r.metric for r in reference.trials]
    assert result.n_done == n


def test_the_runner_commits_a_finished_trial_while_the_others_still_run(tmp_path):
    """Two workers: trial 0 returns at once, the others run 1.5 s. Nothing else is
    written meanwhile, yet trial 0 is on disk within commit_seconds (the runner's
    wait wakes up for the group), not when the slow ones end."""
    db = tmp_path / "slow.sqlite"
    order, lock, seen = itertools.count(), threading.Lock(), []

    def objective(x):
        with lock:
            k = next(order)
        if k == 0:
            return 0.0
        time.sleep(0.7)
        seen.append(on_disk(db))
        time.sleep(0.8)
        return 1.0

    with ThreadPoolExecutor(2) as pool:
        run_experiment(objective, BRANIN.bounds, "random", 3, 0, db, executor=pool,
                       progress=False, objective_name="slow", commit_every=100,
                       commit_seconds=0.2)
    assert seen and seen[0] == 1
    assert on_disk(db) == 3
