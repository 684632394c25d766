"""The seven grasp objects grasped where the camera sees them (the babbling trial
aimed at the perceived pose)."""

import math

import numpy as np
import pytest

from handle_drake.apps.perception.grasping import aimed_trial_scenario, perceived_grasp_trial
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig


def test_aimed_scenario_turns_the_hand_about_its_aim_point():
    # The Shadow's wrist starts off the object's axis (its palm site is not on
    # the wrist frame's vertical), so a turn about the aim point moves it in a circle.
    trial = GraspTrial(GraspTrialConfig(hand="shadow", object="cuboid", space="offset"))
    start0 = np.array(trial.scenario([0.0, 0.0]).controller.start_pose)
    assert abs(start0[0]) > 0.05
    offset, psi = np.array([0.01, -0.005]), 0.3
    start = np.array(aimed_trial_scenario(trial, offset, psi).controller.start_pose)
    c, s = math.cos(psi), math.sin(psi)
    expected_xy = offset + np.array([[c, -s], [s, c]]) @ start0[:2]
    np.testing.assert_allclose(start[:2], expected_xy, atol=1e-12)
    assert start[2] == start0[2] and start[3:5].tolist() == start0[3:5].tolist()
    assert start[5] == pytest.approx(start0[5] + psi)
    # No error: exactly the trial's own scenario at that offset.
    same = aimed_trial_scenario(trial, offset, 0.0).controller.start_pose
    assert same == trial.scenario(offset).controller.start_pose


def test_perceived_cuboid_is_grasped_like_the_truth():
    trial = GraspTrial(GraspTrialConfig(hand="barrett", object="cuboid", space="offset"))
    truth = trial.evaluate([0.0, 0.0])
    p = perceived_grasp_trial("cuboid", xy=(0.08, -0.05), yaw=0.6, trial=trial)
    assert p.error is not None and p.error["kind_ok"]
    # The Kinect at 1 m: the centre within 5 mm, the box's yaw within 3 deg.
    assert p.error["xy_mm"] < 5.0 and abs(p.error["yaw_deg"]) < 3.0
    assert np.hypot(*p.offset_O) * 1000 == pytest.approx(p.error["xy_mm"], abs=0.01)
    assert p.yaw_error == pytest.approx(math.radians(p.error["yaw_deg"]))
    # A millimetre off barely changes the grasp: still force closure, metric within 20 %.
    assert truth.force_closure and p.force_closure
    assert p.metric == pytest.approx(truth.metric_noiseless, rel=0.2)


def test_bad_input():
    trial = GraspTrial(GraspTrialConfig(hand="barrett", object="sphere", space="offset"))
    with pytest.raises(ValueError, match="kind"):
        perceived_grasp_trial("teapot")
    with pytest.raises(ValueError, match="trial"):
        perceived_grasp_trial("mug", trial=trial)
    with pytest.raises(ValueError, match="offset_O"):
        aimed_trial_scenario(trial, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="yaw_error"):
        aimed_trial_scenario(trial, [0.0, 0.0], math.nan)
    standoff = GraspTrial(GraspTrialConfig(hand="barrett", object="sphere", space="standoff"))
    with pytest.raises(ValueError, match="offset"):
        aimed_trial_scenario(standoff, [0.0, 0.0])
