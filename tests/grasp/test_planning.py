"""Grasp planning: the plan's frames checked on the station's own plant,
simulated holds through a lift, and clear errors for bad input."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
from handle_drake.grasp.kinematics import CONTACT_POINTS, contact_layout
from handle_drake.grasp.planning import GraspPlanningError, plan_grasp, resting_pose
from handle_drake.grasp.taxonomy import approach_palm
from handle_drake.scenario import LoadScenario
from handle_drake.station import GetPlant, MakeHandStation
from handle_drake.systems.hand_driver import WRIST_JOINTS, pose_to_wrist_joints
from handle_drake.trial.plans import plan_scenario, plan_scenario_yaml, plan_script
from handle_drake.trial.simulate import ScenarioRunner, held_through_lift

SPEC = get_hand_spec("shadow")
DISTAL = {"th": "thdistal", "ff": "ffdistal", "mf": "mfdistal", "rf": "rfdistal", "lf": "lfdistal"}


@pytest.fixture(scope="module")
def lateral_plan():
    # A cuboid of width 28 mm: depth (the grasp width) 16.8 mm, height 42 mm.
    return plan_grasp("lateral", ("cuboid", 0.028), resting_pose("cuboid", 0.028))


def _posed_station(plan, command):
    """(station, plant, its context in the station's context) with the hand base at
    the plan's X_WB and the hand at ``command`` (20 actuated angles)."""
    scenario = plan_scenario(plan)
    station = MakeHandStation(scenario)
    plant = GetPlant(station)
    station_context = station.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(station_context)
    hand = plant.GetModelInstanceByName("hand")
    wrist = plant.GetModelInstanceByName("wrist")
    q = actuated_to_joint_positions(SPEC, command, 1.0)
    for name, value in zip(SPEC.joint_names, q, strict=True):
        plant.GetJointByName(name, hand).set_angle(context, value)
    pose6 = np.array(plan.wrist(plan.X_WB))
    # The wrist joints are (x y z yaw pitch roll) in that order in the wrist instance.
    wrist_q = np.zeros(plant.num_positions(wrist))
    for name, value in zip(WRIST_JOINTS, pose_to_wrist_joints(pose6), strict=True):
        joint = plant.GetJointByName(name, wrist)
        wrist_q[joint.position_start() - plant.GetJointByName(WRIST_JOINTS[0], wrist)
                .position_start()] = value
    plant.SetPositions(context, wrist, wrist_q)
    return station, plant, context


def _station_contacts(plan):
    """Contact points in world, from the *station's* plant posed at X_WB, q_grasp."""
    _, plant, context = _posed_station(plan, plan.grasp_command)
    hand = plant.GetModelInstanceByName("hand")
    out = {}
    for t in contact_layout(plan.grasp_class):
        p_B, _ = CONTACT_POINTS[(t.finger, t.part)]
        frame = plant.GetBodyByName(DISTAL[t.finger], hand).body_frame()
        out[t.finger] = plant.CalcPointsPositions(context, frame, p_B, plant.world_frame()).ravel()
    X_WPalm = plant.GetFrameByName("palm", hand).CalcPoseInWorld(context)
    return out, X_WPalm


def test_planned_contacts_lie_on_the_box_faces_in_the_station(lateral_plan):
    plan = lateral_plan
    contacts, X_WP = _station_contacts(plan)
    X_OW = plan.X_WO.inverse()
    depth = 0.6 * 0.028
    # Thumb pad and first-finger side on the two opposite depth faces (y_O = +-depth/2).
    ys = sorted(X_OW.multiply(p)[1] for p in contacts.values())
    assert ys[0] == pytest.approx(-depth / 2, abs=1.5e-3)
    assert ys[1] == pytest.approx(depth / 2, abs=1.5e-3)
    # The palm pose the plan reports is the station's palm pose (forearm -> palm chain).
    np.testing.assert_allclose(X_WP.GetAsMatrix4(), plan.X_WP.GetAsMatrix4(), atol=1e-9)
    # Table 2 approach in the world, and it points down within the 45 degree cone.
    a_W = X_WP.rotation().multiply(approach_palm("lateral"))
    np.testing.assert_allclose(a_W, plan.approach_W, atol=1e-12)
    assert a_W[2] < -np.cos(np.deg2rad(45.0)) + 1e-6
    # Every fingertip above the table top.
    assert all(p[2] > 0.0 for p in contacts.values())


def test_script_reaches_from_straight_above_then_lifts(lateral_plan):
    script = plan_script(lateral_plan)
    pre, grasp, lift = (np.array(k.wrist) for k in (script[0], script[1], script[-1]))
    np.testing.assert_allclose(pre[:2], grasp[:2], atol=1e-12)
    assert pre[2] - grasp[2] == pytest.approx(0.06)
    assert lift[2] - grasp[2] == pytest.approx(0.13)
    # Scenario text round-trips through the loader.
    scenario = LoadScenario(data=plan_scenario_yaml(lateral_plan))
    assert scenario.script[-1].wrist == pytest.approx(list(lift))


def test_lateral_grasp_on_a_thin_box_holds_through_a_lift(lateral_plan):
    result = ScenarioRunner(plan_scenario(lateral_plan)).run()
    assert held_through_lift(result), result.object_position[::25, 2]


@pytest.fixture(scope="module")
def tripod_sphere_plan():
    return plan_grasp("tripod", ("sphere", 0.04), resting_pose("sphere", 0.04))


def test_tripod_plan_on_a_sphere_opposes_the_thumb_from_above(tripod_sphere_plan):
    plan = tripod_sphere_plan
    contacts, _ = _station_contacts(plan)
    p_WO = plan.X_WO.translation()
    # The thumb is opposed: its pad and the first/middle finger pads lie on the
    # sphere on opposite sides of its centre (their directions from the centre
    # point apart, more than 120 degrees).
    u = {f: (p - p_WO) / np.linalg.norm(p - p_WO) for f, p in contacts.items()}
    for f in ("ff", "mf"):
        assert np.linalg.norm(contacts[f] - p_WO) == pytest.approx(0.02, abs=1.5e-3)
        assert u["th"] @ u[f] < np.cos(np.deg2rad(120.0))
    # The hand comes in from above: approach within 15 degrees of straight down.
    assert plan.approach_W[2] < -np.cos(np.deg2rad(15.0)) + 1e-6


def test_tripod_grasp_on_a_4cm_sphere_holds_through_a_lift(tripod_sphere_plan):
    result = ScenarioRunner(plan_scenario(tripod_sphere_plan)).run()
    assert held_through_lift(result), result.object_position[::25, 2]
    # Held by the class's three fingers: thumb, first and middle finger press on
    # it at the end; ring and little fingers stay off.
    final = result.tactile[-1]  # FF MF RF LF TH (N)
    assert final[[0, 1, 4]].min() > 0.5, final
    assert final[[2, 3]].max() == 0.0, final


def test_bad_input_raises_clear_errors():
    X = resting_pose("sphere", 0.04)
    with pytest.raises(ValueError, match="unknown grasp class 'power'"):
        plan_grasp("power", ("sphere", 0.04), X)
    with pytest.raises(ValueError, match="too large for a tripod"):
        plan_grasp("tripod", ("sphere", 0.12), resting_pose("sphere", 0.12))
    with pytest.raises(ValueError, match="too small for a lateral"):
        plan_grasp("lateral", ("cuboid", 0.004), resting_pose("cuboid", 0.004))
    with pytest.raises(ValueError, match="cannot plan a grasp on a 'mug'"):
        plan_grasp("tripod", ("mug", 0.05), X)
    with pytest.raises(TypeError, match="RigidTransform"):
        plan_grasp("tripod", ("sphere", 0.04), [0, 0, 0.02])
    with pytest.raises(ValueError, match="above the table top"):
        plan_grasp("tripod", ("sphere", 0.04), RigidTransform([0, 0, -0.01]))
    standing = RigidTransform(RotationMatrix(), [0, 0, 0.045])  # cylinder axis vertical
    with pytest.raises(ValueError, match="lying on its side"):
        plan_grasp("tripod", ("cylinder", 0.045), standing)
    far = resting_pose("cylinder", 0.045, xy=(2.5, 0.0))  # beyond the wrist's 2 m travel
    with pytest.raises(ValueError, match="unreachable pose"):
        plan_grasp("tripod", ("cylinder", 0.045), far)
    assert issubclass(GraspPlanningError, ValueError)


@pytest.mark.parametrize("grasp_class, diameter", [("palmar_pinch", 0.028),
                                                   ("lateral_tripod", 0.025)])
def test_the_planned_forearm_stays_above_the_table(grasp_class, diameter):
    """The forearm's collision cylinders (read from the hand model) at the planned
    grasp pose stay above the table top: these grasps of small spheres were once
    planned with the forearm 36 and 179 mm inside the table, so the hand stopped
    short and closed on air."""
    from pydrake.geometry import Cylinder, Role
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.systems.framework import DiagramBuilder

    from handle_drake.base.models import add_package, model_path

    plan = plan_grasp(grasp_class, ("sphere", diameter), resting_pose("sphere", diameter))
    spec = get_hand_spec("shadow")
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    parser = Parser(plant)
    add_package(parser)
    hand = parser.AddModels(model_path(spec.model_relative_path))[0]
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    forearm = plant.GetBodyByName(spec.base_body, hand)
    lowest = []
    for geometry in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(forearm.index()),
                                            Role.kProximity):
        shape = inspector.GetShape(geometry)
        assert isinstance(shape, Cylinder)
        X_WG = plan.X_WB @ inspector.GetPoseInFrame(geometry)
        axis = X_WG.rotation().matrix()[:, 2]
        ends = [X_WG.translation() + s * 0.5 * shape.length() * axis for s in (-1, 1)]
        lowest.append(min(e[2] for e in ends)
                      - shape.radius() * np.sqrt(max(0.0, 1.0 - axis[2] ** 2)))
    assert len(lowest) == 2  # the forearm and its neck
    assert min(lowest) > plan.table_height - 1e-3, lowest


@pytest.mark.parametrize("grasp_class, diameter", [("lateral", 0.017),
                                                   ("writing_tripod", 0.024)])
def test_no_part_of_the_planned_hand_reaches_into_the_table(grasp_class, diameter):
    """Every hand collision shape (phalanges, knuckles, palm, not only the
    fingertips) clears the table top at the grasp and in the pre-shape the hand
    reaches with, measured by the station's own SceneGraph. These small-sphere
    grasps were planned with the first finger's middle phalanx 18 mm inside the
    table (the IK bounded only the fingertips): the reach then pressed the
    sphere into the table and the grasp closed on nothing."""
    plan = plan_grasp(grasp_class, ("sphere", diameter), resting_pose("sphere", diameter))
    for command in (plan.grasp_command, plan.preshape_command):
        station, plant, context = _posed_station(plan, command)
        query = plant.get_geometry_query_input_port().Eval(context)
        inspector = query.inspector()
        hand = plant.GetModelInstanceByName("hand")
        table = {g for g in inspector.GetAllGeometryIds()
                 if inspector.GetName(g).endswith("top_collision")}
        assert table
        depths = []
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.05):
            ids = {pair.id_A, pair.id_B}
            if not ids & table:
                continue
            other = (ids - table).pop()
            body = plant.GetBodyFromFrameId(inspector.GetFrameId(other))
            if body.model_instance() == hand:
                depths.append((pair.distance, body.name()))
        assert depths, "no hand geometry within 5 cm of the table: the hand is not there"
        assert min(depths)[0] > -1.5e-3, min(depths)


def _finger(body_name: str) -> str:
    return body_name[:2]


@pytest.mark.parametrize("grasp_class, kind, width", [("adduction_grip", "cuboid", 0.013),
                                                      ("tip_pinch", "sphere", 0.0155)])
def test_the_pre_shape_keeps_the_fingers_apart(grasp_class, kind, width):
    """In the pre-shape the hand reaches with, no two fingers overlap by more than the
    plan's 4 mm (station SceneGraph). The adduction grip's middle finger once opened
    into the ring finger, and a tip pinch's first finger into the middle finger, at
    600-800 N in simulation: the grasp then closed on nothing."""
    size = width / 0.6 if kind == "cuboid" else width
    plan = plan_grasp(grasp_class, (kind, size), resting_pose(kind, size))
    _, plant, context = _posed_station(plan, plan.preshape_command)
    query = plant.get_geometry_query_input_port().Eval(context)
    inspector = query.inspector()
    hand = plant.GetModelInstanceByName("hand")
    overlaps = []
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.0):
        a, b = (plant.GetBodyFromFrameId(inspector.GetFrameId(g)) for g in (pair.id_A, pair.id_B))
        if a.model_instance() == hand == b.model_instance() and _finger(a.name()) != _finger(
                b.name()):
            overlaps.append((pair.distance, a.name(), b.name()))
    assert not overlaps or min(overlaps)[0] > -4.5e-3, min(overlaps)


@pytest.mark.parametrize("grasp_class, kind, width", [("writing_tripod", "cuboid", 0.024),
                                                      ("parallel_extension", "cuboid", 0.025)])
def test_classes_that_had_no_plan_on_a_table_now_hold(grasp_class, kind, width):
    """The writing tripod's middle finger once had to reach under a cuboid standing
    on the table, and the parallel extension's four-finger row (66 mm) had to fit on
    a 42 mm cuboid face: neither had a plan. Now the middle finger supports the
    ulnar face and the row drops its outer fingers; the grasps hold through the lift."""
    size = width / 0.6
    plan = plan_grasp(grasp_class, (kind, size), resting_pose(kind, size))
    result = ScenarioRunner(plan_scenario(plan)).run()
    assert held_through_lift(result), result.object_lift()


def test_a_16mm_ball_is_pinched_with_the_pads_tangent_to_it():
    """The palmar pinch of a 16 mm ball on a table had no plan: every posture the
    first pass found met the ball with the edge of a pad (6 mm into it). The
    second pass on round objects keeps each pad tangent to the surface within
    15 deg: the ray out along the pad's normal passes through the ball's centre
    (geometry of the planned posture in the station), and the grasp holds."""
    from handle_drake.apps.planning.execution import ReactiveGraspRunner

    size = 0.016
    plan = plan_grasp("palmar_pinch", ("sphere", size), resting_pose("sphere", size))
    _, plant, context = _posed_station(plan, plan.grasp_command)
    hand = plant.GetModelInstanceByName("hand")
    centre = plan.X_WO.translation()
    for finger in ("th", "ff"):
        X_WB = plant.GetBodyByName(f"{finger}distal", hand).EvalPoseInWorld(context)
        p_B, n_B = CONTACT_POINTS[(finger, "pad")]
        ray = X_WB.rotation().matrix() @ n_B
        to_centre = centre - X_WB @ p_B
        angle = np.degrees(np.arccos(ray @ to_centre / np.linalg.norm(to_centre)))
        assert angle < 16.0, (finger, angle)
        # ...and the pad is on the ball's surface (within the plan's contact error).
        assert abs(np.linalg.norm(to_centre) - size / 2) < 2.5e-3, (finger, to_centre)
    assert held_through_lift(ReactiveGraspRunner(plan).run())
