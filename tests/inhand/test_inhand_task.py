"""The in-hand trial on the simulated hand: physics of the task, replay, runs, CLI."""

import re

import numpy as np
import pytest

from handle_drake.apps.inhand.experiment import learning_curve, replay_best, run_inhand
from handle_drake.apps.inhand.task import (
    InHandScenario,
    InHandTask,
    InHandTrial,
    inhand_fingerprint,
)
from handle_drake.cli import main as cli_main
from handle_drake.learning.log import TrialLog
from handle_drake.scenario import DumpScenario


def _stroke(trial):
    """The hand-written motion: the three fingers' flex strokes at J3 +1.0, J2 +0.9 rad,
    no release, thumb still."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        x[sl][1:] = [1.0, 0.9] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    return x


@pytest.mark.parametrize("task, step, reached", [("cylinder_rotation", 0.0005, True),
                                                  ("star_rotation", 0.002, False)])
def test_each_palm_up_task_defaults_to_a_step_at_which_its_stroke_has_converged(task, step,
                                                                              reached):
    # issue 45, item 1: the hand-written stroke at the task's default step and at half of it
    # (reduced: the published table adds a quarter) rolls the object the same within 10 %
    # and reaches the target at both or at neither (the cylinder: 42.6, 41.8 deg at 0.5,
    # 0.25 ms, where 2 ms gave 50.6; the star: 8.4, 7.9 at 2, 1 ms)
    default = InHandTask(task=task)
    assert default.time_step == step
    assert InHandTask(task=task, time_step=0.001).time_step == 0.001  # still settable
    runs = []
    for h in (step, step / 2):
        trial = InHandTrial(InHandTask(task=task, time_step=h))
        runs.append(trial.evaluate(_stroke(trial), early_stop=False))
    turns = [o.rotation_deg for o in runs]
    assert abs(turns[0] - turns[1]) <= 0.1 * abs(turns[1]), turns
    assert [o.reached_target for o in runs] == [reached, reached], turns


def test_hand_written_stroke_rolls_the_cylinder_30_deg_and_holds_it():
    # the cylinder is an instrumented object: a JoyWarrior accelerometer at its origin
    # constructed at 2 ms (the task's default before issue 45; at its converged 0.5 ms the
    # stroke rolls it 42.6 deg, tested above, and the device's first sample reads 3.1 deg):
    # what is tested here is the device against the plant and the checks, at that step
    trial = InHandTrial(InHandTask(accelerometer="joywarrior24f14", time_step=0.002))
    outcome = trial.evaluate(_stroke(trial))
    assert outcome.completed and outcome.held
    assert outcome.rotation_deg >= 30.0
    assert outcome.reached_target and outcome.checks_passed == 4
    assert outcome.score >= trial.target_score == trial.dimension + 2
    assert "palm" in outcome.contacts[-1]  # lies in the palm against the curled fingers
    # the instrumented object's accelerometer (noisy, quantised device model) sees the
    # same rotation as the plant's pose once the cylinder is at rest
    assert len(outcome.accelerometer_rotation_deg_series) == len(outcome.rotation_deg_series)
    hold = np.array(outcome.times) > 1.0  # at rest after the motion
    np.testing.assert_allclose(np.array(outcome.accelerometer_rotation_deg_series)[hold],
                               np.array(outcome.rotation_deg_series)[hold], atol=2.0)
    assert abs(outcome.accelerometer_rotation_deg_series[0]) < 1.0  # from the settled grasp
    # without any variation the cylinder stays in its cradle: no rotation, fails check 2
    still = _stroke(trial)
    for sl in trial.gist.slices():
        still[sl][1:] = 0.0
    rest = trial.evaluate(still)
    assert abs(rest.rotation_deg) < 2.0 and rest.held_time > 0.4
    assert rest.checks_passed == 1 and not rest.completed  # early stop at check 2
    # eqs. 47-49: passing check 1 activated part 2; the samples up to ~0.3 s matched
    assert rest.s_b == trial.dims_per_part[:2].sum()
    assert 0.1 < rest.s_a < 0.3 and rest.score == rest.s_b + rest.s_a
    # run to the end anyway: same score, the cylinder still lies in the hand, unrotated,
    # through the hold; but the cradle does not grip it: reversed weight lifts it out
    full = trial.evaluate(still, early_stop=False)
    assert full.completed and full.held_time == pytest.approx(trial.config.total_time)
    assert abs(full.rotation_deg) < 2.0
    assert full.survived_reversal is False and not full.held
    assert full.score == rest.score and full.checks_passed == 1


def test_samples_read_the_touching_hand_bodies_from_the_geometry_query_as_from_the_results():
    # Each sample reads which hand bodies touch the cylinder from the geometry query's point
    # pairs (no contact solve); the point-contact results hold the same pairs. The whole
    # outcome (every sample's contact set, rotation, score) equals the contact-results read
    # for the hand-written stroke and random draws that end in different ways.
    trial = InHandTrial()
    built = trial._build()
    query = built["touching_query"]
    assert query is not None
    bounds = trial.bounds
    draws = [_stroke(trial)] + list(np.random.default_rng(3).uniform(
        bounds[:, 0], bounds[:, 1], size=(3, trial.dimension)))
    scores = set()
    try:
        for x in draws:
            built["touching_query"] = query
            fast = trial.evaluate(x, early_stop=False).as_dict()
            built["touching_query"] = None
            reference = trial.evaluate(x, early_stop=False).as_dict()
            fast.pop("wall_time"), reference.pop("wall_time")
            assert fast == reference
            assert any(fast["contacts"])
            scores.add(fast["score"])
    finally:
        built["touching_query"] = query
    assert len(scores) >= 2  # the draws end differently


def test_a_palm_carried_cylinder_that_falls_under_reversed_weight_is_not_held():
    # the stroke, then a release back along its path: the fingers leave the cylinder lying
    # on the palm, rolled past the target. Before the held test at the end this trial was
    # held and reached the target (score 29.0 >= 28); the palm carries all its weight.
    # Constructed at 2 ms (at the converged 0.5 ms this release rolls it back to -15.6 deg
    # instead; the held test's logic is what is tested, on this physical case)
    trial = InHandTrial(InHandTask(time_step=0.002))
    x = _stroke(trial)
    for m, sl in zip(trial.gist.motions, trial.gist.slices(), strict=True):
        if m.finger != "TH" and m.variation[0] < 0:
            x[sl][1:] = [1.0, 0.9]
    outcome = trial.evaluate(x)
    assert outcome.completed and outcome.checks_passed == 4 and outcome.rotation_deg >= 30.0
    assert outcome.contacts[-1] == ["palm"]
    assert outcome.palm_weight_share == pytest.approx(1.0, abs=0.05)
    # with its weight reversed (the hand palm down) it leaves the hand: not held, not reached
    assert outcome.survived_reversal is False
    assert not outcome.held and not outcome.held_truth and not outcome.reached_target
    assert outcome.score < trial.target_score
    # the hand-written stroke alone keeps the fingers on it: it survives, held, reached
    kept = trial.evaluate(_stroke(trial))
    assert kept.survived_reversal and kept.held and kept.reached_target


def test_old_evaluation_scores_held_time_and_rotation():
    trial = InHandTrial(InHandTask(evaluation="old"))
    outcome = trial.evaluate(_stroke(trial))
    assert outcome.score == pytest.approx(2.0)  # held throughout, rotated past the target


def test_a_replayed_best_trial_reproduces_its_score(tmp_path):
    run = run_inhand("cylinder_rotation", "random", trials=2, workers=1, seed=4,
                     db=tmp_path / "r.sqlite", progress=False)
    assert len(run.records) == 2
    logged, outcome = replay_best(run)
    assert outcome.score == pytest.approx(logged, abs=1e-9)
    assert outcome.accelerometer_rotation_deg_series == []  # a plain cylinder
    it, best = learning_curve(run.records, 1)
    assert list(it) == [1, 2] and best[1] == max(r.metric for r in run.records)
    # every trial is logged whole as its scenario (parameters as data), the run id carries
    # the code's fingerprint
    assert run.run_id.endswith("-" + inhand_fingerprint())
    for record in run.records:
        logged = InHandScenario.load(record.scenario)
        assert logged.parameters == [float(v) for v in record.parameters]
        assert DumpScenario(logged.station) == DumpScenario(run.trial.scenario().station)
        assert logged.station.table is None and logged.station.object.kind == "cylinder"
        assert logged.action_gist() == run.trial.gist
    # the same settings resume the run; other settings are another run, and refused
    # under this run's id when it is given
    again = run_inhand("cylinder_rotation", "random", trials=2, workers=1, seed=4,
                       db=tmp_path / "r.sqlite", progress=False)
    assert [r.metric for r in again.records] == [r.metric for r in run.records]
    assert again.run_id == run.run_id
    with pytest.raises(ValueError, match=r"exists in .* with config.task.mu=0.8, got 0.9"):
        run_inhand("cylinder_rotation", "random", trials=2, workers=1, seed=4,
                   db=tmp_path / "r.sqlite", progress=False, mu=0.9, run_id=run.run_id)


def test_each_trial_object_builds_its_own_diagram_and_pickles_without_it():
    import pickle

    trial = InHandTrial(InHandTask(settle_time=0.1, hold=0.0, motion_duration=0.2))
    x = trial.gist.initial_parameters()
    first = trial.evaluate(x)
    built = trial._built
    assert built is not None and trial.evaluate(x).score == first.score
    assert trial._built is built  # built once per trial object
    copy = pickle.loads(pickle.dumps(trial))
    assert copy._built is None and copy.config == trial.config  # a worker builds its own
    other = InHandTrial(trial.config)
    assert other.evaluate(x).score == first.score and other._built is not built


def test_bad_input():
    trial = InHandTrial()
    with pytest.raises(ValueError, match=r"expected 26 values \(eq. 45\), got 3"):
        trial.evaluate(np.zeros(3))
    with pytest.raises(ValueError, match="task: expected one of"):
        InHandTask(task="juggling")
    with pytest.raises(ValueError, match="accelerometer: device: unknown accelerometer 'adxl'"):
        InHandTask(accelerometer="adxl")
    with pytest.raises(ValueError, match="benchmark: expected 4 values"):
        InHandTask(benchmark=(0.0, 1.0))
    with pytest.raises(ValueError, match="n_particles: expected an integer >= 1, got 0"):
        run_inhand(trials=1, n_particles=0, db="/nonexistent/x.sqlite")


def test_cli_bad_arguments_exit_2(tmp_path, capsys):
    assert cli_main(["inhand", "--plot", "curve.jpg", "--db", str(tmp_path / "a.sqlite")]) == 2
    assert "--plot: expected a .png file name" in capsys.readouterr().err
    (tmp_path / "foreign.sqlite").write_text("not a database")
    assert cli_main(["inhand", "--db", str(tmp_path / "foreign.sqlite")]) == 2
    for bad in (["--optimizer", "bo"], ["--accelerometer", "adxl"], ["--executor", "mpi"]):
        with pytest.raises(SystemExit) as error:
            cli_main(["inhand", *bad])
        assert error.value.code == 2


def _rows(db):
    from handle_drake.learning import TrialLog

    with TrialLog(db) as log:
        (run,) = log.runs()
        return [(r.index, r.status, r.parameters.tolist(), r.metric)
                for r in log.trials(run.run_id)]


def test_cli_run_in_parallel_equals_the_sequential_run(tmp_path, capsys):
    """``handle-drake inhand`` as a user runs it: the sequential run (with an instrumented
    cylinder) writes its learning curve and replay (the replayed best trial scores what
    was logged); the same run with the particles of each iteration on a local pool of 2
    worker processes logs the same trials (the instrumented cylinder too: its score is the
    sensor's, issue 35). (The same run on Dask, through ``--executor dask://``:
    ``tests/learning/test_cluster.py``.)"""
    common = ["inhand", "--optimizer", "ipso", "--particles", "2", "--trials", "4", "--seed",
              "1", "--no-progress"]
    png, html = tmp_path / "curve.png", tmp_path / "best.html"
    assert cli_main([*common, "--db", str(tmp_path / "seq.sqlite"), "--plot", str(png),
                     "--html", str(html), "--accelerometer", "joywarrior24f14"]) == 0
    out = capsys.readouterr().out
    assert "(local executor)" in out and "trials: 4 done, 0 failed" in out
    assert png.stat().st_size > 10_000 and "<html" in html.read_text()[:2000].lower()
    logged, replayed = (float(v) for v in re.search(
        r"score ([-\d.e+]+), logged ([-\d.e+]+)\)", out).groups())
    assert replayed == pytest.approx(logged, abs=1e-3)
    assert "deg (joywarrior24f14 accelerometer)" in out
    assert cli_main([*common, "--db", str(tmp_path / "pool.sqlite"), "--workers", "2",
                     "--no-plot", "--no-html", "--accelerometer", "joywarrior24f14"]) == 0
    assert "trials: 4 done, 0 failed" in capsys.readouterr().out
    sequential = _rows(tmp_path / "seq.sqlite")
    assert [r[0] for r in sequential] == [0, 1, 2, 3]
    assert _rows(tmp_path / "pool.sqlite") == sequential


def test_cli_runs_that_differ_in_any_trial_setting_are_two_runs_of_one_log(tmp_path, capsys):
    """The README's sequence: a plain run, then the instrumented object, in one log; a given
    --run-id resumes that run and refuses other settings under it, naming the field."""
    db = tmp_path / "inhand.sqlite"
    common = ["inhand", "--trials", "1", "--seed", "0", "--db", str(db), "--no-plot",
              "--no-html", "--no-progress", "--optimizer", "random"]
    assert cli_main(common) == 0
    assert cli_main([*common, "--accelerometer", "joywarrior24f14"]) == 0
    with TrialLog(db) as log:
        runs = log.runs()
    assert len(runs) == 2 and runs[0].run_id != runs[1].run_id
    assert [bool(r.config["task"].get("accelerometer")) for r in runs] == [False, True]
    capsys.readouterr()
    assert cli_main([*common, "--accelerometer", "joywarrior24f14",
                     "--run-id", runs[0].run_id]) == 2
    err = capsys.readouterr().err
    assert "config.task.accelerometer=(missing), got 'joywarrior24f14'" in err
    assert cli_main([*common, "--run-id", "mine"]) == 0
    with TrialLog(db) as log:
        assert [r.run_id for r in log.runs()][-1] == "mine"
