"""The PA10-6C model, the !Arm mount and its simulated driver."""

import math
import warnings

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.base.models import add_package, package_url
from handle_drake.devices.arm.model import ARM_SPECS
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import GetPlant, MakeHandStation

SPEC = ARM_SPECS["pa10"]
# Published lengths (models/pa10/README.md): base to shoulder, upper arm, forearm, flange.
L0, L1, L2, L3 = 0.317, 0.450, 0.480, 0.070
# The hand above the table, fingers along +x, palm down.
HOME = [0.0, 0.37, 2.13, 0.0, -0.93, math.pi / 2]


def _arm_plant():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    parser = Parser(plant)
    add_package(parser)
    (arm,) = parser.AddModelsFromUrl(package_url(SPEC.model_relative_path))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm))
    plant.Finalize()
    return plant, arm, builder.Build()


def _flange_closed_form(q):
    """Flange pose from the link lengths: Rz(S1) Tz(L0) Ry(S2) Tz(L1) Ry(E1) Rz(E2) Tz(L2)
    Ry(W1) Rz(W2) Tz(L3)."""
    def T(R=None, p=(0, 0, 0)):
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = np.eye(3) if R is None else R, p
        return out

    def rz(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    def ry(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    chain = [T(rz(q[0])), T(p=(0, 0, L0)), T(ry(q[1])), T(p=(0, 0, L1)), T(ry(q[2])),
             T(rz(q[3])), T(p=(0, 0, L2)), T(ry(q[4])), T(rz(q[5])), T(p=(0, 0, L3))]
    X = np.eye(4)
    for step in chain:
        X = X @ step
    return X


def test_flange_position_matches_the_published_link_lengths():
    plant, arm, _ = _arm_plant()
    context = plant.CreateDefaultContext()
    flange = plant.GetFrameByName("flange", arm)
    # Straight up: the four lengths add up.
    np.testing.assert_allclose(flange.CalcPoseInWorld(context).translation(),
                               [0, 0, L0 + L1 + L2 + L3], atol=1e-12)
    # Planar configurations (E2 = W2 = 0): the arm is a 3-link chain in the S1 plane.
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(SPEC.lower, SPEC.upper)
        q[3] = q[5] = 0.0
        plant.SetPositions(context, arm, q)
        a, b, c = q[1], q[1] + q[2], q[1] + q[2] + q[4]
        reach = L1 * math.sin(a) + L2 * math.sin(b) + L3 * math.sin(c)
        height = L0 + L1 * math.cos(a) + L2 * math.cos(b) + L3 * math.cos(c)
        expected = [reach * math.cos(q[0]), reach * math.sin(q[0]), height]
        np.testing.assert_allclose(flange.CalcPoseInWorld(context).translation(), expected,
                                   atol=1e-12)
    # Any configuration: the pose is the product of the elementary motions.
    for _ in range(10):
        q = rng.uniform(SPEC.lower, SPEC.upper)
        plant.SetPositions(context, arm, q)
        np.testing.assert_allclose(flange.CalcPoseInWorld(context).GetAsMatrix4(),
                                   _flange_closed_form(q), atol=1e-12)


def test_joint_limits_are_the_manufacturers():
    plant, arm, _ = _arm_plant()
    degrees = [177, 90, 137, 255, 165, 255]
    for name, limit in zip(SPEC.joint_names, degrees, strict=True):
        joint = plant.GetJointByName(name, arm)
        np.testing.assert_allclose(joint.position_lower_limits(), [-math.radians(limit)],
                                   atol=1e-6)
        np.testing.assert_allclose(joint.position_upper_limits(), [math.radians(limit)],
                                   atol=1e-6)
    # The PA-10's m2..m7 per joint, S2's link its S2 and S3 links together; S1's link
    # has no source (models/pa10/README.md, "Masses and collision shapes").
    masses = [plant.GetBodyByName(f"link{i}", arm).default_mass() for i in range(1, 7)]
    np.testing.assert_allclose(masses, [9.78, 8.41 + 3.51, 4.31, 3.45, 1.46, 0.24],
                               atol=1e-9)


def test_no_two_links_touch_when_straight():
    plant, _, diagram = _arm_plant()
    context = diagram.CreateDefaultContext()
    query = plant.get_geometry_query_input_port().Eval(plant.GetMyContextFromRoot(context))
    assert query.ComputePointPairPenetration() == []
    # W1 bent back to its limit, the flange meets the forearm: self-collisions are modelled.
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context),
                       [0, -math.radians(90), 0, 0, math.radians(165), 0])
    query = plant.get_geometry_query_input_port().Eval(plant.GetMyContextFromRoot(context))
    inspector = query.inspector()
    pairs = {tuple(sorted((inspector.GetName(p.id_A), inspector.GetName(p.id_B))))
             for p in query.ComputePointPairPenetration()}
    assert pairs == {("pa10_6c::link4_collision_0", "pa10_6c::link6_collision_0")}


def _scenario(hand="shadow", initial=HOME, extra=""):
    return LoadScenario(data=f"""
hand:
  kind: {hand}
  mount: !Arm {{kind: pa10, X_WB: {{translation: [-0.55, 0, 0]}},
                initial_position: {list(initial)}}}
object: {{kind: cylinder, size: 0.05}}
simulation_duration: 0.4
{extra}""")


@pytest.mark.parametrize("hand", ["shadow", "barrett"])
def test_arm_station_simulates_without_warnings_and_holds_its_pose(hand):
    scenario = _scenario(hand)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        station = MakeHandStation(scenario)
        simulator = Simulator(station)
        simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    state = GetPlant(station).GetPositionsAndVelocities(
        GetPlant(station).GetMyContextFromRoot(context))
    assert np.all(np.isfinite(state))
    q = station.GetOutputPort("arm.position_measured").Eval(context)
    np.testing.assert_allclose(q, HOME, atol=1e-3)
    x = station.GetOutputPort("arm.state_estimated").Eval(context)
    np.testing.assert_allclose(x[:6], q)
    assert np.max(np.abs(x[6:])) < 1e-2
    # The hand is bolted to the flange: its base is the flange frame.
    plant = GetPlant(station)
    plant_context = plant.GetMyContextFromRoot(context)
    from handle_drake.base.hands import get_hand_spec

    X_WF = plant.GetFrameByName("flange").CalcPoseInWorld(plant_context)
    X_WH = plant.GetFrameByName(get_hand_spec(hand).base_body).CalcPoseInWorld(plant_context)
    assert X_WF.IsNearlyEqualTo(X_WH, 1e-9)


def test_arm_driver_rate_limits_and_reaches_a_commanded_configuration():
    station = MakeHandStation(_scenario())
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    target = np.array(HOME) + np.array([0.3, -0.1, 0.2, 0.5, 0.3, -0.4])
    station.GetInputPort("arm.position").FixValue(context, target)
    simulator.AdvanceTo(0.1)
    commanded = station.GetOutputPort("arm.position_commanded").Eval(context)
    # S1 moves at most 1 rad/s: about 0.1 rad in 0.1 s (one control period of slack).
    moved = np.abs(commanded - HOME)
    assert np.all(moved <= np.array(SPEC.velocity) * 0.105 + 1e-9)
    assert moved[0] == pytest.approx(0.1, abs=0.006)
    simulator.AdvanceTo(0.6)
    np.testing.assert_allclose(station.GetOutputPort("arm.position_measured").Eval(context),
                               target, atol=2e-3)


@pytest.mark.parametrize("mount, message", [
    ("!Arm {kind: ur5}", "hand.mount.kind: unknown arm 'ur5'"),
    ("!Arm {initial_position: [0, 0, 0]}", "hand.mount.initial_position: expected 6"),
    ("!Arm {initial_position: [0, 2.0, 0, 0, 0, 0]}", "initial_position[1] (S2)"),
    ("!Arm {kp: [1, 1, 1, 1, 1, -1]}", "hand.mount.kp: expected values > 0"),
    ("!Arm {control_period: 0}", "hand.mount.control_period"),
])
def test_bad_arm_mounts_are_refused_with_the_field_named(mount, message):
    with pytest.raises(ScenarioError) as error:
        LoadScenario(data=f"hand: {{kind: shadow, mount: {mount}}}")
    assert message in str(error.value)


def test_hardware_station_refuses_an_arm():
    scenario = _scenario()
    with pytest.raises(ValueError, match="FixedMount"):
        from handle_drake.station import MakeHardwareStation

        MakeHardwareStation(scenario)
