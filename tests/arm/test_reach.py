"""Arm IK on the Hamburg table: the solution reaches the pose, within limits, clear of
the scene, and the simulated arm driven to it puts the hand there."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator

from handle_drake.arm.model import ARM_SPECS
from handle_drake.arm.reach import ArmReach
from handle_drake.demo import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.station import GetPlant, MakeHandStation

SPEC = ARM_SPECS["pa10"]


@pytest.fixture(scope="module")
def setup():
    scenario = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    scenario.cameras = []
    return scenario, ArmReach(scenario)


def test_ik_reaches_a_palm_down_pose_over_the_table_and_the_arm_gets_there(setup):
    scenario, reach = setup
    hand_open = np.zeros(len(reach.hand_spec.joint_names))
    # Hand base 0.25 m up over the table's near half, fingers along +x, palm down.
    target = RigidTransform(RollPitchYaw(np.pi / 2, 0, np.pi / 2), [-0.35, -0.05, 0.25])
    ready = np.array(scenario.hand.mount.initial_position)
    result = reach.solve_from_seeds(target, [ready], hand_open)
    assert result.ok, result.message
    assert np.all(result.q >= np.array(SPEC.lower) - 1e-9)
    assert np.all(result.q <= np.array(SPEC.upper) + 1e-9)
    assert result.position_error <= 0.002 * np.sqrt(3) + 1e-6
    assert result.angle_error <= 0.02 + 1e-6
    assert reach.min_distance(result.q, hand_open) >= 0.003 - 1e-4
    # Closed loop: the simulated station, commanded to q, holds the hand at the target.
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    station.GetInputPort("arm.position").FixValue(context, result.q)
    simulator.AdvanceTo(2.5)
    plant = GetPlant(station)
    X = plant.GetFrameByName(reach.hand_spec.base_body).CalcPoseInWorld(
        plant.GetMyContextFromRoot(context))
    np.testing.assert_allclose(X.translation(), target.translation(), atol=0.006)
    assert X.rotation().InvertAndCompose(target.rotation()).ToAngleAxis().angle() < 0.03


def test_ik_reports_an_unreachable_pose(setup):
    scenario, reach = setup
    far = RigidTransform(RollPitchYaw(np.pi / 2, 0, np.pi / 2), [1.5, 0.0, 0.3])
    result = reach.solve(far, np.array(scenario.hand.mount.initial_position),
                         np.zeros(len(reach.hand_spec.joint_names)))
    assert not result.ok and "IK failed" in result.message


def test_ik_keeps_the_hand_out_of_the_table(setup):
    """A pose that puts the forearm 2 cm into the table top is refused with collision
    avoidance and found without it."""
    scenario, reach = setup
    hand_open = np.zeros(len(reach.hand_spec.joint_names))
    # Forearm axis horizontal at z = 0.025: its 4.5 cm radius reaches 2 cm below the top.
    low = RigidTransform(RollPitchYaw(np.pi / 2, 0, np.pi / 2), [-0.35, -0.05, 0.025])
    ready = np.array(scenario.hand.mount.initial_position)
    assert reach.solve_from_seeds(low, [ready], hand_open, collision=False).ok
    assert not reach.solve_from_seeds(low, [ready], hand_open, tries=1).ok
