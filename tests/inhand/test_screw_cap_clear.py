"""Issue 45, the screw cap: the clear placement is the default everywhere, its target lies
above what the demonstration and the hand-written stroke reach, and a turn past the target
is reached once the fingers leave the cap after their stroke (a cap on its thread cannot be
lost)."""

import argparse

import numpy as np
import pytest

from handle_drake.apps.inhand.convergence import stroke_motion
from handle_drake.apps.inhand.screw_cap import (
    CLEAR,
    DEFAULT_PLACEMENT,
    ONE_GAIT,
    PLACEMENTS,
    ScrewCapTask,
    ScrewCapTrial,
    build_screw_cap,
    simulate_scenario,
)


def test_the_default_task_is_the_clear_placement_and_the_old_ones_are_named():
    assert DEFAULT_PLACEMENT == "clear" and PLACEMENTS["clear"] is CLEAR
    task = ScrewCapTask()
    for name, value in CLEAR.items():
        assert getattr(task, name) == value, name
    # read from the built plant (not from the settings): the step, the 100 mm cap, the
    # bottle with its neck (two geometries), Menagerie's 1 N m on a finger joint
    built = build_screw_cap(ScrewCapTrial(task).scenario(), driver=False)
    plant = built["plant"]
    assert plant.time_step() == pytest.approx(0.001)
    diagram = built["diagram"]
    context = diagram.CreateDefaultContext()
    inspector = plant.EvalSceneGraphInspector(plant.GetMyContextFromRoot(context))
    (cap,) = plant.GetCollisionGeometriesForBody(built["cap"])
    assert inspector.GetShape(cap).length() == pytest.approx(0.1)
    assert len(plant.GetCollisionGeometriesForBody(built["bottle"])) == 2
    limits = {plant.get_joint_actuator(i).joint().name(): plant.get_joint_actuator(i)
              .effort_limit() for i in plant.GetJointActuatorIndices()}
    assert limits["FFJ3"] == pytest.approx(1.0) and limits["RFJ2"] == pytest.approx(1.0)
    # the wedged placement is a named preset with its own (2 ms, the sheet's 2 N m, 60 mm)
    old = build_screw_cap(ScrewCapTrial(ScrewCapTask(**ONE_GAIT)).scenario(), driver=False)
    assert old["plant"].time_step() == pytest.approx(0.002)
    assert len(old["plant"].GetCollisionGeometriesForBody(old["bottle"])) == 1
    # the free cylinder keeps its own defaults (it has no bottle or placement)
    free = ScrewCapTask(free=True)
    assert (free.time_step, free.effort_limits, free.target_deg) == (0.002, "sheet", 90.0)


def test_the_command_lines_default_to_the_clear_placement():
    from handle_drake.apps.inhand.cli import _task_options, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    options = _task_options(parser.parse_args(["inhand", "--task", "screw_cap"]))
    assert {k: options[k] for k in CLEAR} == CLEAR and options["target_deg"] == 270.0
    # the free cylinder gets no placement; an old placement is asked for by name
    free = _task_options(parser.parse_args(["inhand", "--task", "fingertip_cylinder"]))
    assert "cap_position" not in free and "time_step" not in free
    old = _task_options(parser.parse_args(["inhand", "--task", "screw_cap", "--placement",
                                           "one-gait"]))
    assert old["time_step"] == 0.002 and old["target_deg"] == 90.0


def test_the_target_lies_above_what_the_demonstration_and_the_stroke_reach():
    # issue 45 item 4: the demonstration's own parameters turn the cap -1.8 deg and the
    # hand-written stroke 113.6 deg (the plant's joint, and a separate re-simulation of the
    # logged scenario); the default target is 270 deg
    trial = ScrewCapTrial(ScrewCapTask())
    assert trial.config.target_deg == 270.0
    for x, low, high in ((trial.gist.initial_parameters(), -10.0, 10.0),
                         (stroke_motion(trial.gist), 100.0, 130.0)):
        outcome = trial.evaluate(x, early_stop=False)
        assert low < outcome.turn_deg_truth < high
        assert not outcome.reached_target and outcome.score < trial.target_score
        again = simulate_scenario(trial.scenario(x).dump())["turn_deg"]
        assert again == pytest.approx(outcome.turn_deg_truth, abs=2.0)


# One of the fresh perturbations under which the stroke over-turns the cap (friction x 0.76,
# mass x 1.14, effort limits x 0.79, the thread 0.0115 N m, the cap moved < 2 mm): its
# fingers drag it 188 deg by 0.55 s, flex past it and never touch it again
_OVER_TURN = dict(target_deg=90.0, mu_scale=0.7585, mass_scale=1.1357, effort_scale=0.7904,
                  coulomb_torque=0.0115, cap_position=(0.40411, -0.00529, 0.07187))


def test_a_turn_past_the_target_is_reached_after_the_fingers_leave_the_cap():
    trial = ScrewCapTrial(ScrewCapTask(**_OVER_TURN))
    x = stroke_motion(trial.gist)
    outcome = trial.evaluate(x, early_stop=False)
    t = np.array(outcome.times)
    touched = [bool(c) for c in outcome.contacts]
    last_touch = float(t[np.flatnonzero(touched)[-1]])
    end = trial.last_stroke_end(x)
    # the fingers left the cap before their stroke ended and did not come back: no finger
    # on it during the last 0.6 s (0.3 s is the contact window)
    assert last_touch < end and last_touch < t[-1] - 0.6
    # the plant's joint (and a separate re-simulation): far past the target, kept by the
    # thread's friction with nothing touching the cap at the end
    assert outcome.turn_deg_truth > 150.0
    again = simulate_scenario(trial.scenario(x).dump())
    assert again["turn_deg"] == pytest.approx(outcome.turn_deg_truth, abs=3.0)
    assert not again["touching"]
    assert outcome.reached_target and outcome.checks_passed == 4
    assert outcome.score >= trial.target_score
    # the rule can fail: a contact window shorter than the gap between the last touch and
    # the stroke's end leaves the cap lost at the stroke's end (the checks from then fail)
    short = ScrewCapTrial(ScrewCapTask(**_OVER_TURN, contact_window=0.5 * (end - last_touch)))
    lost = short.evaluate(x, early_stop=False)
    assert lost.turn_deg_truth == pytest.approx(outcome.turn_deg_truth, abs=1e-9)
    assert not lost.reached_target and lost.checks_passed < 4
