"""``handle-drake simulate LOG`` replays a logged fingertip-cylinder trial's reversed weight
(issue 45, items 6 and 7: "held" means the object survives the reversed weight, and the log's
scenario replays it).

Independent truth: the log's record was written by the trial (ScrewCapTrial on GistTrial, its
frames a TrajectorySource, its reversal ReversedGravity switched by the trial); the replay is
simulate's own build (the logged station scenario's keyframe script on a ScenarioRunner, the
reversal and its travel and touch read by apps/inhand/replay.py). The two must say the same
held verdict and the same largest travel."""

import re

import pytest
from cli_runner import cli_exit

from handle_drake.apps.inhand.experiment import run_inhand
from handle_drake.apps.inhand.replay import logged_reversal
from handle_drake.cli import main as cli_main

#: a short reduced run: one gait, 0.1 s hold, the turn counted only while held (so a trial
#: that misses only the target still runs its reversal); cmaes, 2 trials. Measured: seed 0's
#: best trial (0) is lost on reversal (travel 4.79 m), seed 1's best (1) is held (1.4 mm)
TASK = dict(hold=0.1, held_turn=True, progress=False)
REPLAYED = re.compile(r"reversed weight \(its weight reversed plus (\S+) N, for (\S+) s\): "
                      r"(held|not held); travel (\S+) m")


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    db = tmp_path_factory.mktemp("reversal") / "log.sqlite"
    runs = [run_inhand("fingertip_cylinder", "cmaes", 2, n_particles=2, seed=seed, db=db,
                       **TASK) for seed in (0, 1)]
    return db, runs


def _replay(argv, capsys):
    assert cli_main(argv) == 0
    out = capsys.readouterr().out
    found = REPLAYED.search(out)
    assert found, out
    margin, time, verdict, travel = found.groups()
    return float(margin), float(time), verdict == "held", float(travel), out


def test_the_replayed_reversal_says_what_the_trial_logged(log, capsys):
    db, runs = log
    verdicts = set()
    for run in runs:
        best = max((r for r in run.records if r.status == "done"), key=lambda r: r.metric)
        logged = best.contacts
        assert logged["survived_reversal"] is not None  # the trial ran its reversal
        margin, time, held, travel, out = _replay(["simulate", str(db), "--run-id",
                                                   run.run_id], capsys)
        assert f"trial {best.index} of run {run.run_id!r}" in out
        assert margin == 1.0 and time == 0.5  # the task's reversal, from the log
        assert held == logged["survived_reversal"]
        assert travel == pytest.approx(logged["reversal_travel"], rel=1e-6, abs=1e-9)
        verdicts.add(held)
        if held:  # held: within the trial's 10 mm; lost: it fell far away
            assert travel < 0.01
        else:
            assert travel > 0.01
    assert verdicts == {True, False}  # one run's best is held, the other's is lost


def test_a_palm_up_trial_replays_its_reversal(tmp_path, capsys):
    """The palm-up tasks (InHandTrial) log a reversal verdict too (their weight reversed
    with no margin, the travel read where the reversal leaves the object)."""
    run = run_inhand("cylinder_rotation", "cmaes", 1, n_particles=2, seed=0,
                     db=tmp_path / "palm.sqlite", progress=False)
    logged = run.records[0].contacts
    assert logged["survived_reversal"] is not None
    margin, time, held, travel, _ = _replay(["simulate", str(tmp_path / "palm.sqlite")],
                                            capsys)
    assert margin == 0.0 and time == 0.5
    assert held == logged["survived_reversal"] == logged["held"]
    assert travel == pytest.approx(logged["reversal_travel"], rel=1e-6, abs=1e-9)


def test_a_trial_stopped_before_its_reversal_is_said_so(log, capsys):
    db, runs = log
    stopped = [r for r in runs[0].records if r.contacts["survived_reversal"] is None]
    assert stopped
    *_, out = _replay(["simulate", str(db), "--run-id", runs[0].run_id, "--trial",
                       str(stopped[0].index)], capsys)
    assert "logged: the trial stopped before its reversal" in out


def test_the_cap_has_no_reversal_and_bad_log_flags_are_one_line_errors(log, tmp_path, capsys):
    db, runs = log
    assert logged_reversal(runs[0].records[0].scenario) is not None
    cap = run_inhand("screw_cap", "random", 1, seed=0, db=tmp_path / "cap.sqlite",
                     hold=0.1, progress=False)
    assert logged_reversal(cap.records[0].scenario) is None  # on its thread: nothing to lose
    run = ["simulate", str(db), "--run-id", runs[1].run_id]
    for extra, why in ((["--duration", "0.3"], "--duration"),
                       (["--override", "object: null"], "--override: no free object")):
        assert cli_main(run + extra) == 0  # the motion alone: no reversal to replay
        assert f"reversed weight: not replayed ({why}" in capsys.readouterr().out
    for argv, flag in (([str(db)], "--run-id"),  # two runs: which one
                       ([str(db), "--run-id", "nope"], "--run-id"),
                       ([str(db), "--run-id", runs[0].run_id, "--trial", "7"], "--trial"),
                       ([str(db), "--run-id", runs[0].run_id, "--trial", "-1"], "--trial")):
        code, err = cli_exit(["simulate", *argv], capsys)
        assert code == 2 and flag in err and len(err.strip().splitlines()) == 1, err
