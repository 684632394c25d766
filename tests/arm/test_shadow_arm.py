"""Shadow's 4-DOF arm (the Paris platform): the model against its README's sourced
numbers, read back from the plant; the scenario diagrams/paris_setup.yaml (the C6
hand at 1:1, the Kinect on the arm's trunk); the arm's IK, which moves the hand's
wrist with the arm, checked by forward kinematics on the plant."""

import math
import re
import warnings

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JointActuatorIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.apps.pick.reach import SPHERE_TURN, ArmReach
from handle_drake.base.models import add_package, diagrams_dir, package_url
from handle_drake.devices.arm.model import ARM_SPECS
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import GetPlant, MakeHandStation

SPEC = ARM_SPECS["shadow_arm"]
README = (diagrams_dir().parent / "models" / "shadow_arm" / "README.md").read_text()
PARIS = diagrams_dir() / "paris_setup.yaml"


def _row(label: str, exact: bool = False) -> list[str]:
    """The cells of the README table row whose first cell starts with (is) ``label``."""
    for line in README.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and (cells[0] == label if exact else
                                     cells[0].startswith(label)):
            return cells
    raise AssertionError(f"README.md has no row {label!r}")


def _number(text: str) -> float:
    return float(re.search(r"-?\d+(\.\d+)?", text).group())


def _angle(text: str) -> float:
    text = text.strip()
    return float(eval(text.replace("pi", "math.pi"), {"math": math}))  # e.g. "-pi/4"


def _arm_plant(time_step=0.001):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=time_step, discrete_contact_approximation="sap"), builder)
    parser = Parser(plant)
    add_package(parser)
    (arm,) = parser.AddModelsFromUrl(package_url(SPEC.model_relative_path))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm))
    plant.Finalize()
    return plant, arm, builder.Build()


def test_model_loads_and_simulates_with_finite_state_and_no_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plant, arm, diagram = _arm_plant()
        simulator = Simulator(diagram)
        context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
        plant.SetPositions(context, arm, [0.3, 0.8, 1.0, 0.2])
        plant.get_actuation_input_port(arm).FixValue(context, np.zeros(4))
        simulator.AdvanceTo(0.2)  # falls under gravity onto its joint limits
    x = plant.GetPositionsAndVelocities(context)
    assert np.all(np.isfinite(x))
    q = plant.GetPositions(context, arm)
    assert np.all(q >= np.array(SPEC.lower) - 0.05) and np.all(q <= np.array(SPEC.upper) + 0.05)


def test_kinematics_match_the_readme():
    plant, arm, _ = _arm_plant()
    context = plant.CreateDefaultContext()

    def joint_origin(name):  # the joint's frame on its child, in the world (q = 0)
        return plant.GetJointByName(name, arm).frame_on_child().CalcPoseInWorld(context)

    def in_parent(name):  # the joint's origin in its parent link's frame
        joint = plant.GetJointByName(name, arm)
        return joint.frame_on_child().CalcPose(context, joint.parent_body().body_frame())

    assert joint_origin("ShoulderJRotate").translation()[2] == pytest.approx(
        _number(_row("base plate to ShoulderJRotate")[1]), abs=1e-9)
    swing = in_parent("ShoulderJSwing")
    assert swing.translation()[2] == pytest.approx(
        _number(_row("ShoulderJRotate to ShoulderJSwing")[1]), abs=1e-9)
    assert swing.translation()[1] == pytest.approx(
        _number(_row("ShoulderJSwing beside")[1]), abs=1e-9)
    # The upper arm's frame is turned half a turn about y: its z points down.
    np.testing.assert_allclose(swing.rotation().matrix()[:, 2], [0, 0, -1], atol=1e-9)
    upper = np.linalg.norm(joint_origin("ElbowJSwing").translation()
                           - joint_origin("ShoulderJSwing").translation())
    assert upper == pytest.approx(_number(_row("upper arm, ShoulderJSwing")[1]), abs=1e-9)
    rotate = in_parent("ElbowJRotate").translation()
    assert rotate[0] == pytest.approx(_number(_row("ElbowJRotate axis off")[1]), abs=1e-9)
    assert rotate[2] == pytest.approx(_number(_row("elbow to the hand support")[1]), abs=1e-9)
    # The shoulder's height above the base plate, as the README sums it.
    assert joint_origin("ShoulderJSwing").translation()[2] == pytest.approx(0.5405, abs=1e-9)
    # The spec's closed-form lengths: base to shoulder, upper arm, elbow to flange.
    flange = plant.GetFrameByName("flange", arm).CalcPoseInWorld(context).translation()
    assert np.linalg.norm(flange - joint_origin("ElbowJSwing").translation()) == pytest.approx(
        SPEC.lengths[2], abs=1e-9)
    assert SPEC.lengths[:2] == pytest.approx((0.5405, 0.369), abs=1e-12)
    # At q = 0 the arm hangs straight down: the elbow below the shoulder.
    np.testing.assert_allclose(joint_origin("ElbowJSwing").translation(),
                               [0, -0.134, 0.5405 - 0.369], atol=1e-9)


def test_joint_limits_speeds_and_efforts_match_the_readme():
    plant, arm, _ = _arm_plant()
    actuators = {plant.get_joint_actuator(JointActuatorIndex(i)).joint().name():
                 plant.get_joint_actuator(JointActuatorIndex(i))
                 for i in range(plant.num_actuators())}
    for i, name in enumerate(SPEC.joint_names):
        cells = _row(name, exact=True)
        lo, hi = (_angle(v) for v in cells[1].split(".."))
        joint = plant.GetJointByName(name, arm)
        assert joint.position_lower_limits()[0] == pytest.approx(lo, abs=1e-5)
        assert joint.position_upper_limits()[0] == pytest.approx(hi, abs=1e-5)
        assert joint.velocity_upper_limits()[0] == pytest.approx(float(cells[2]), abs=1e-6)
        assert actuators[name].effort_limit() == pytest.approx(float(cells[3]))
        # The driver's limits are the model's.
        assert SPEC.lower[i] == pytest.approx(lo, abs=1e-5)
        assert SPEC.upper[i] == pytest.approx(hi, abs=1e-5)
        assert SPEC.velocity[i] == pytest.approx(float(cells[2]))


def test_masses_and_centres_of_mass_match_the_readme():
    plant, arm, _ = _arm_plant()
    context = plant.CreateDefaultContext()
    for link in ("base", "trunk", "upperarm", "lowerarm", "handsupport"):
        cells = _row(link, exact=True)
        body = plant.GetBodyByName(link, arm)
        assert body.default_mass() == pytest.approx(float(cells[1]))
        com = [float(v) for v in cells[2].split(",")]
        np.testing.assert_allclose(body.CalcCenterOfMassInBodyFrame(context), com, atol=1e-9)
        # The inertia is a real solid's (triangle inequality of the principal moments).
        moments = np.linalg.eigvalsh(body.default_rotational_inertia().CopyToFullMatrix3())
        assert np.all(moments > 0) and moments[0] + moments[1] >= moments[2] - 1e-12


def test_paris_scenario_builds_the_c6_hand_on_the_arm_with_the_kinect_on_the_trunk():
    scenario = LoadScenario(filename=PARIS)
    assert scenario.hand.coupling_ratio == 1.0
    assert scenario.hand.mount.kind == "shadow_arm"
    station = MakeHandStation(scenario)
    plant = GetPlant(station)
    context = station.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    arm = plant.GetModelInstanceByName("arm")
    X_WT = plant.GetBodyByName("trunk", arm).EvalPoseInWorld(plant_context)
    X_TC = scenario.cameras[0].config.X_PB.GetDeterministicValue()
    pose = RigidTransform(station.GetOutputPort("kinect.pose").Eval(context))  # a copy
    np.testing.assert_allclose(pose.GetAsMatrix4(), (X_WT @ X_TC).GetAsMatrix4(), atol=1e-9)
    # The Kinect looks forwards (+x) and down, 45 deg below the horizontal.
    axis = pose.rotation().matrix()[:, 2]
    assert axis[0] > 0.6 and axis[2] == pytest.approx(-math.sqrt(0.5), abs=1e-3)
    # It turns with the shoulder: ShoulderJRotate by 0.3 rad turns the camera about the
    # base's vertical axis.
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.GetJointByName("ShoulderJRotate", arm).set_angle(plant_context, 0.3)
    turned = station.GetOutputPort("kinect.pose").Eval(context)
    base = scenario.hand.mount.X_WB.GetDeterministicValue()
    yaw = RigidTransform(base.rotation().MakeZRotation(0.3), [0, 0, 0])
    expected = base @ yaw @ base.inverse() @ pose
    np.testing.assert_allclose(turned.GetAsMatrix4(), expected.GetAsMatrix4(), atol=1e-9)


@pytest.mark.parametrize("parent, message", [
    ("arm::elbow", "the shadow_arm arm has no link 'elbow'"),
    ("table", "expected one of ['world', 'wrist'] or arm::<link>"),
])
def test_bad_camera_parents_are_refused_with_the_field_named(parent, message):
    text = PARIS.read_text().replace("base_frame: arm::trunk", f"base_frame: {parent}")
    with pytest.raises(ScenarioError, match=re.escape(message)) as error:
        LoadScenario(data=text)
    assert "cameras[0].config.X_PB.base_frame" in str(error.value)


def test_an_arm_camera_needs_an_arm():
    text = PARIS.read_text()
    text = text[:text.index("  mount: !Arm")] + text[text.index("table:"):]
    with pytest.raises(ScenarioError, match=r"cameras\[0\]\.config\.X_PB\.base_frame: "
                                            r"'arm::trunk' needs the hand on an !Arm"):
        LoadScenario(data=text)


@pytest.fixture(scope="module")
def reach():
    scenario = LoadScenario(filename=PARIS)
    scenario.cameras = []
    return scenario, ArmReach(scenario)


def _fk_palm(reach, q_arm, q_hand):
    """The palm's pose, by a plant context of its own (not the IK's)."""
    plant = reach.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, reach.positions(q_arm, q_hand))
    return plant.GetBodyByName("palm", reach.hand).EvalPoseInWorld(context)


def test_four_joint_ik_moves_the_wrist_and_reaches_a_pose_the_arm_can_take(reach):
    scenario, ik = reach
    assert ik.free_hand_joints == ("WRJ2", "WRJ1")
    names = ik.hand_spec.joint_names
    rng = np.random.default_rng(1)
    solved = 0
    for _ in range(4):
        # A pose the arm and wrist can take (truth by construction), 0.1 m over the table.
        q_true = rng.uniform(SPEC.lower, SPEC.upper)
        hand_true = np.zeros(len(names))
        hand_true[names.index("WRJ2")] = rng.uniform(-0.4, 0.1)
        hand_true[names.index("WRJ1")] = rng.uniform(-0.5, 0.4)
        X_palm = _fk_palm(ik, q_true, hand_true)
        if X_palm.translation()[2] < 0.1:
            continue
        X_WB = ik.hand_pose(q_true, np.zeros(len(names)))  # the base as if the wrist were 0
        ready = np.array(scenario.hand.mount.initial_position)
        result = ik.solve_from_seeds(X_WB, [ready], np.zeros(len(names)), tries=6,
                                     collision=False)
        if not result.ok:
            continue
        solved += 1
        # The plan's posture has the wrist at 0; the IK moved it to put the palm there.
        X = _fk_palm(ik, result.q, result.q_hand)
        X_want = _palm_of_base(ik, X_WB)
        assert np.linalg.norm(X.translation() - X_want.translation()) <= 0.002 * math.sqrt(3) + 1e-6
        assert X.rotation().InvertAndCompose(X_want.rotation()).ToAngleAxis().angle() <= 0.021
        fixed = [i for i, n in enumerate(names) if n not in ("WRJ2", "WRJ1")]
        np.testing.assert_array_equal(result.q_hand[fixed], 0.0)
    assert solved >= 2


def _palm_of_base(ik, X_WB):
    """Where the palm is when the hand's base is at ``X_WB`` and the wrist at 0."""
    plant = ik.plant
    context = plant.CreateDefaultContext()
    forearm = plant.GetBodyByName(ik.hand_spec.base_body, ik.hand).body_frame()
    palm = plant.GetBodyByName("palm", ik.hand).body_frame()
    return X_WB @ palm.CalcPose(context, forearm)


def test_ik_reaches_the_pregrasp_of_a_reachable_sphere(reach):
    """The grasp planner's pre-grasp for a sphere 0.5 m in front of the arm: the IK's
    answer, by forward kinematics, puts the sphere's centre where the grasp has it in
    the palm, the hand turned at most SPHERE_TURN from the plan, clear of the table."""
    from handle_drake.apps.pick.plan import default_grasp_database
    from handle_drake.base.hands import actuated_to_joint_positions
    from handle_drake.geometry.objects import ObjectSpec, resting_height
    from handle_drake.grasp.planning import plan_grasp

    scenario, ik = reach
    spec = ObjectSpec(kind="sphere", size=0.06)
    X_WO = RigidTransform([-0.1, 0.0, resting_height(spec)])
    base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
    grasp = plan_grasp("tripod", spec, X_WO, table_height=0.0,
                       reach_direction=X_WO.translation()[:2] - base[:2], coupling_ratio=1.0,
                       database=default_grasp_database(), time_budget=10)
    q_open = actuated_to_joint_positions(ik.hand_spec, grasp.preshape_command, 1.0)
    p_BO = (X_WO.inverse() @ grasp.X_WB).inverse().translation()
    ready = np.array(scenario.hand.mount.initial_position)
    result = ik.solve_from_seeds(grasp.X_WB_pregrasp, [ready], q_open, tries=2,
                                 symmetry=("sphere", p_BO))
    assert result.ok, result.message
    assert np.all(result.q >= np.array(SPEC.lower) - 1e-6)
    assert np.all(result.q <= np.array(SPEC.upper) + 1e-6)
    # Forward kinematics on a fresh context: the palm where the IK left it.
    X_palm = _fk_palm(ik, result.q, result.q_hand)
    # Where the plan's palm holds the sphere's centre at the pre-grasp.
    plant = ik.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, ik.positions(ready, q_open))
    forearm = plant.GetBodyByName(ik.hand_spec.base_body, ik.hand).body_frame()
    palm = plant.GetBodyByName("palm", ik.hand).body_frame()
    X_plan = grasp.X_WB_pregrasp @ palm.CalcPose(context, forearm)
    p_PO = X_plan.inverse() @ (grasp.X_WB_pregrasp @ p_BO)
    np.testing.assert_allclose(X_palm @ p_PO, grasp.X_WB_pregrasp @ p_BO, atol=0.0036)
    turn = X_palm.rotation().InvertAndCompose(X_plan.rotation()).ToAngleAxis().angle()
    assert turn <= SPHERE_TURN + 1e-3
    # Only the wrist moved among the hand's joints; clear of the table and the box.
    names = ik.hand_spec.joint_names
    fixed = [i for i, n in enumerate(names) if n not in ("WRJ2", "WRJ1")]
    np.testing.assert_allclose(result.q_hand[fixed], q_open[fixed])
    assert ik.min_distance(result.q, result.q_hand) >= 0.003 - 1e-4


def test_the_pick_plan_carries_the_wrist_the_ik_chose_in_the_hand_commands():
    """plan_pick on the Paris scene's sphere (true pose): every waypoint's hand command
    holds the wrist its IK chose (the close and the open keep the one before), and by
    forward kinematics with those commands the sphere's centre sits in the palm where
    the planned grasp has it, at the grasp and the lift."""
    from handle_drake.apps.pick.plan import plan_pick
    from handle_drake.base.hands import actuated_to_joint_positions
    from handle_drake.scene.config import initial_pose, scene_objects

    scenario = LoadScenario(filename=PARIS)
    scenario.cameras = []
    (name, target), *_ = scene_objects(scenario)
    X_WO = initial_pose(target, scenario.table)
    ik = ArmReach(scenario, ignore=(name,))
    plan = plan_pick(scenario, ik, name, target.kind, target.size, X_WO,
                     scenario.hand.mount.initial_position)
    assert plan.wrist_from_ik == ("WRJ2", "WRJ1")
    actuated = list(ik.hand_spec.actuated_joint_names)
    wrist = [actuated.index("WRJ2"), actuated.index("WRJ1")]
    by_label = {w.label: w for w in plan.waypoints}
    np.testing.assert_array_equal(by_label["close"].hand[wrist], by_label["grasp"].hand[wrist])
    np.testing.assert_array_equal(by_label["open"].hand[wrist], by_label["release"].hand[wrist])
    # The planned grasp's sphere centre in the palm (the plan's own wrist).
    ratio = scenario.hand.coupling_ratio
    q_planned = actuated_to_joint_positions(ik.hand_spec, plan.grasp.preshape_command, ratio)
    X_BP = _palm_of_base_at(ik, q_planned)
    p_PO = X_BP.inverse() @ (plan.grasp.X_WB.inverse() @ X_WO.translation())
    for label, lifted in (("grasp", 0.0), ("lift", None)):
        w = by_label[label]
        q_hand = actuated_to_joint_positions(ik.hand_spec, w.hand, ratio)
        X_palm = _fk_palm(ik, w.q, q_hand)
        want = X_WO.translation() if lifted is not None else (
            plan.grasp.lifted() @ plan.grasp.X_WB.inverse() @ X_WO.translation())
        np.testing.assert_allclose(X_palm @ p_PO, want, atol=0.0036)


def _palm_of_base_at(ik, q_hand):
    plant = ik.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, ik.positions(np.zeros(4), q_hand))
    forearm = plant.GetBodyByName(ik.hand_spec.base_body, ik.hand).body_frame()
    return plant.GetBodyByName("palm", ik.hand).body_frame().CalcPose(context, forearm)
