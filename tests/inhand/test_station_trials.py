"""The in-hand tasks on the station (issue 45 item 7): an object on a joint is a scenario
object, the trials run on trial.gist_trial.GistTrial over the one harness, the log stores
the station's scenario and ``handle-drake simulate`` replays it.

Independent truths: the module's own diagram (build_screw_cap with its planned commands,
wired by separate code) for the station-built trial; the closed-form Coulomb deceleration
of a cap spun on its thread; the trial's own logged turn for the replay."""

import dataclasses as dc
import math
import re

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from handle_drake.apps.inhand.convergence import stroke_motion
from handle_drake.apps.inhand.experiment import run_inhand
from handle_drake.apps.inhand.screw_cap import (
    CLEAR,
    ScrewCapScenario,
    ScrewCapTask,
    ScrewCapTrial,
    build_screw_cap,
)
from handle_drake.apps.inhand.task import InHandScenario, InHandTask, InHandTrial, trial_text
from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main as cli_main
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import GetPlant, MakeHandStation


def cli_exit(argv, capsys):
    """``handle-drake argv`` in-process: (exit code, stderr)."""
    try:
        code = cli_main(argv)
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, err


@pytest.fixture(scope="module")
def clear():
    return ScrewCapTrial(ScrewCapTask(**CLEAR))


def test_the_station_built_cap_trial_equals_the_modules_own_diagram(clear):
    """The default build (the station) against build_screw_cap's planned commands: the same
    turn to 1e-6 deg, the same score and the same peak forces (here: bit for bit)."""
    x = stroke_motion(clear.gist)
    station = clear.evaluate(x, early_stop=False)
    own = clear.evaluate(x, early_stop=False, build="planned")
    assert "trial" in clear._built and "trial" not in clear._planned_build
    assert station.turn_deg_truth > 90.0  # the hand-written stroke does turn it
    assert station.turn_deg_truth == pytest.approx(own.turn_deg_truth, abs=1e-6)
    assert station.score == own.score and station.checks_passed == own.checks_passed
    assert station.digit_peak_normal == pytest.approx(own.digit_peak_normal, abs=1e-9)
    assert station.welded_force_max == own.welded_force_max


@pytest.mark.parametrize("contact", [{}, {"free_stiffness": 3000.0,
                                      "free_near_rigid_threshold": 0.0}],
                         ids=["rigid", "two-strokes-contact"])
def test_the_free_cylinder_on_the_station_equals_the_modules_own_diagram(contact):
    """The fingertip cylinder (a free bare cylinder, its weight reversed at the end), with
    Drake's rigid default and with TWO_STROKES' compliant contact without SAP's near-rigid
    softening (the station must carry the threshold into its plant)."""
    trial = ScrewCapTrial(ScrewCapTask(free=True, hold=0.1, **contact))
    x = stroke_motion(trial.gist, j3=0.6, j2=0.6)
    station = trial.evaluate(x, early_stop=False)
    own = trial.evaluate(x, early_stop=False, build="planned")
    assert station.turn_deg_truth == pytest.approx(own.turn_deg_truth, abs=1e-6)
    assert station.survived_reversal == own.survived_reversal is not None
    assert station.score == own.score


def test_the_station_scenario_has_the_cap_on_its_thread_joint(clear):
    station = clear.scenario().station()
    assert station.object.joint is not None and station.object.joint.base is not None
    assert station.hand.effort_limits == "menagerie"
    plant = build_screw_cap(clear.scenario())["plant"]
    mine = GetPlant(MakeHandStation(station, finite_commands=True))
    # the same bodies, masses and joint friction in both plants
    assert mine.num_bodies() == plant.num_bodies()
    assert mine.num_positions() == plant.num_positions()
    cap = mine.GetJointByName("cap_thread")  # the screw cap's names
    assert cap.default_damping() == plant.GetJointByName("cap_thread").default_damping()
    assert mine.GetJointActuatorByName("cap_thread_friction").effort_limit() == \
        pytest.approx(ScrewCapTask().coulomb_torque)


def test_a_cap_spun_on_its_thread_slows_at_the_coulomb_deceleration():
    """The shipped in-hand scenario with the hand moved away: a cap spun at 2 rad/s slows at
    Tc / I (I = m r^2 / 2; no viscous part), read from object.joint_position."""
    tc, m, d = 1e-4, 0.012, 0.035
    scenario = LoadScenario(filename=diagrams_dir() / "screw_cap_station.yaml", data=(
        "hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 1.0]}}}\n"
        f"object: {{joint: {{coulomb_torque: {tc}, viscous: 0.0}}}}\nscript: []\n"))
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    plant = GetPlant(station)
    joint = plant.GetJointByName("cap_thread")
    joint.set_angular_rate(plant.GetMyMutableContextFromRoot(context), 2.0)
    simulator.AdvanceTo(0.02)
    rate = joint.get_angular_rate(plant.GetMyContextFromRoot(context))
    expected = 2.0 - tc / (m * (d / 2) ** 2 / 2) * 0.02  # 0.912 rad/s
    assert rate == pytest.approx(expected, rel=0.01)
    q = station.GetOutputPort("object.joint_position").Eval(
        station.GetMyContextFromRoot(context))[0]
    assert q == pytest.approx(joint.get_angle(plant.GetMyContextFromRoot(context)))


def test_the_replayed_log_reproduces_the_logged_turn(tmp_path, capsys):
    """One logged screw-cap trial; ``handle-drake simulate LOG`` replays its station
    scenario (the motion as a keyframe script) and prints the joint's turn: the logged
    one."""
    task = dict(CLEAR, hold=0.1, progress=False)
    run = run_inhand("screw_cap", "random", 1, seed=3, db=tmp_path / "log.sqlite", **task)
    record = run.records[0]
    assert ScrewCapScenario.load(record.scenario).parameters == pytest.approx(
        record.parameters.tolist(), abs=0)
    assert cli_main(["simulate", str(tmp_path / "log.sqlite")]) == 0
    out = capsys.readouterr().out
    turn = float(re.search(r"turned (\S+) deg", out).group(1))
    assert turn == pytest.approx(record.contacts["turn_deg_truth"], abs=1e-6)


def test_the_palm_up_log_is_a_station_scenario_with_its_trial(tmp_path):
    trial = InHandTrial(InHandTask())
    text = trial(trial.gist.initial_parameters()).scenario
    scenario = LoadScenario(text=text)  # what handle-drake simulate reads
    assert scenario.script and scenario.script[0].time == pytest.approx(1.0 - 0.005)
    assert InHandScenario.load(text).parameters == trial.scenario().parameters
    assert trial_text(trial.scenario().dump()) == trial.scenario().dump()


def test_bad_jointed_objects_and_log_flags_are_one_line_errors(tmp_path, capsys):
    for override, field in (("object: {kind: cuboid}", "object.joint"),
                            ("object: {joint: {coulomb_torque: -1}}", "coulomb_torque"),
                            ("object: {mass: null}", "object.mass"),
                            ("object: {on_table: true}", "on_table"),
                            ("hand: {effort_limits: soft}", "hand.effort_limits"),
                            ("object: {joint: {base: {neck_length: 5}}}", "neck_length"),
                            ("object: {joint: {name: 'a b'}}", "object.joint.name")):
        with pytest.raises(ScenarioError, match=re.escape(field)):
            LoadScenario(filename=diagrams_dir() / "screw_cap_station.yaml", data=override)
    code, err = cli_exit(["simulate", "screw_cap_station", "--trial", "3"], capsys)
    assert code == 2 and "--trial" in err and len(err.strip().splitlines()) == 1
    run_inhand("screw_cap", "random", 1, seed=0, db=tmp_path / "a.sqlite",
               **dict(CLEAR, hold=0.1, progress=False))
    code, err = cli_exit(["simulate", str(tmp_path / "a.sqlite"), "--run-id", "nope"], capsys)
    assert code == 2 and "--run-id" in err and len(err.strip().splitlines()) == 1
    code, err = cli_exit(["simulate", str(tmp_path / "a.sqlite"), "--trial", "7"], capsys)
    assert code == 2 and "--trial" in err
    scribbled = tmp_path / "scribbled.sqlite"
    scribbled.write_bytes(b"SQLite format 3\x00" + bytes(range(256)) * 8)
    code, err = cli_exit(["simulate", str(scribbled)], capsys)
    assert code == 2 and "SCENARIO" in err and len(err.strip().splitlines()) == 1, err


def test_the_shipped_in_hand_scenario_replays_the_hand_written_stroke(clear, capsys):
    """diagrams/screw_cap_station.yaml is the clear cap's station with the hand-written
    stroke as its script: simulate turns the cap as the trial does."""
    outcome = clear.evaluate(stroke_motion(clear.gist), early_stop=False)
    assert cli_main(["simulate", "screw_cap_station"]) == 0
    turn = float(re.search(r"turned (\S+) deg", capsys.readouterr().out).group(1))
    assert turn == pytest.approx(outcome.turn_deg_truth, abs=1e-6)
    assert math.isfinite(turn) and dc.is_dataclass(clear.scenario())
    assert np.isfinite(outcome.score)


def test_inhand_hardware_is_checked_before_any_trial(tmp_path, capsys):
    db = tmp_path / "never.sqlite"
    for value, words in (("nohost", "HOST:PORT"), ("127.0.0.1:1", "CAN bus server")):
        code, err = cli_exit(["inhand", "--task", "screw_cap", "--trials", "1", "--db", str(db),
                              "--hardware", value], capsys)
        assert code == 2 and words in err.strip().splitlines()[-1], err
    code, err = cli_exit(["inhand", "--task", "jog_wheel", "--db", str(db), "--hardware",
                          "127.0.0.1:1"], capsys)
    assert code == 2 and "floating wrist" in err
    assert not db.exists()
