"""Run a :class:`~handle_drake.apps.pick.plan.PickPlan` on the simulated station and judge it.

The arm follows the plan's waypoints (and the paths between them) through
``arm.position``: each segment lasts long enough for the slowest joint at half
its speed limit (at least ``MIN_SEGMENT`` s), linear in joint space, and the
driver's own rate limit applies on top. The hand holds each waypoint's command
through ``hand.position``; at the release the arm stands ``RELEASE_DWELL`` s (a cuboid; the
object still held) before the hand opens to the pre-shape, and waits
``SETTLE_TIME`` s for the object to fall (longer while it still moves: ``MAX_SETTLE``).

The close (``close="reactive"``, the default) is the project's reactive tactile
grasp (:class:`~handle_drake.systems.reactive_grasp.ReactiveGrasp`, report section
3.3) on the station's ``hand.tactile``: when the arm stands at the grasp pose, each
finger of the class closes from the pre-shape towards the plan's closing command
until its fingertip feels the object, then all squeeze together; its hand command
drives ``hand.position`` from then until the release. The approach is the arm's
(the controller's own wrist command is not used): the controller is told that
the hand has arrived when the arm's timeline reaches the grasp
(:class:`_CloseTrigger`), and feels nothing before. The arm waits
``REACTIVE_CLOSE_TIME`` s there (the longest close, the squeeze and the hold)
before it lifts. ``close="scripted"``: the open-loop ramp to the closing command
over ``CLOSE_TIME`` s, held ``HOLD_TIME`` s.

The release is corrected by what the fingers feel (given the arm's ``reach``):
the close can move the object in the hand (2.4 cm in a replay of a cuboid that
then jammed on its hole's rim), and the release pose assumed the planned grasp.
After the lift the object is located in the hand from what the hand senses
(:func:`handle_drake.apps.pick.touch.locate_by_touch`: a Shadow hand's taxels, its
joints and the hand's pose from the arm's joints; the station gets taxels for it) or,
for a hand without taxels, from its contacts with the hand (:func:`measure_in_hand`:
each contact's point and the object's surface normal there, as the simulator reports
them), and the carry and release are planned again
for the object where it is (:func:`handle_drake.apps.pick.plan.replan_release`);
the arm's trajectory from the lift on is replaced. Without contacts, or when no
release is reachable with the measured grasp, the plan stands. Success: the object's centre is in
the box (:func:`handle_drake.scene.plant.in_box`). A failure is told by what
the object did: not lifted with the hand, dropped on the way, or stopped on
the lid.

The other objects on the table (bystanders) are free bodies; with
``still_bystanders`` they are welded where they rest (resting on the table,
1 s of the station alone, they halve its speed). Off by default: in the pick
runs the gain was within the machine's noise and one of the seeded scenes
ended differently (docs/results/pick.md, benchmarks/bench_pick_sim.py).

``filter_contacts=True`` excludes the collision pairs that no successful pick has
(:func:`filter_idle_contacts`): the arm against the table, the box and the objects,
the bystanders against the box and each other. Off by default: the gain was within
the machine's noise (docs/results/pick.md, fourth pass), and the filter would hide
the very events a pick can fail by (an arm sweeping an object, a dropped object
knocking a bystander against the box: seed 6).
"""

from __future__ import annotations

import dataclasses as dc
import time
import warnings

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem
from scipy.spatial.transform import Rotation

from handle_drake.apps.pick.plan import hole_centres, replan_release, resting_height
from handle_drake.apps.pick.touch import locate_by_touch, senses_touch, with_taxels
from handle_drake.base.hands import get_hand_spec
from handle_drake.devices.arm.model import ARM_INSTANCE, get_arm_spec
from handle_drake.geometry.objects import dimensions
from handle_drake.scene.config import in_box, object_instance_name
from handle_drake.scene.plant import SORTING_BOX
from handle_drake.station import GetPlant, MakeHandStation
from handle_drake.systems.reactive_grasp import (
    ReactiveGrasp,
    ReactiveGraspParams,
    finger_command_groups,
)

__all__ = ["PickOutcome", "execute_pick", "weld_bystanders", "filter_idle_contacts",
           "MIN_SEGMENT", "CLOSES", "RELEASE_DWELL",
           "REACTIVE_CLOSE_TIME", "measure_in_hand", "locate_object", "PHASES"]

MIN_SEGMENT = 0.4  # s
CLOSE_TIME = 0.6  # s, the scripted close's ramp
HOLD_TIME = 0.3  # s, and its hold before the lift
SETTLE_TIME = 1.2  # s
#: Seconds the arm stands at the release pose, the object still held, before the hand
#: opens: the arm's driver lags its trajectory and the object swings in the grasp after
#: the descent (development seed 6 at 0.5 ms: the cuboid's centre 14 mm from the
#: planned release as the hand opened, the hole's clearance 12 mm; it wedged in the hole).
#: Per kind: measured for the cuboid only; a cylinder and a star prism let go after the
#: same dwell (tests/pick/test_pick_kinds.py) went on rolling in the cavity and stopped on
#: the star's rim, and both went in at rest without it.
RELEASE_DWELL = {"cuboid": 0.5}  # s, by the picked object's kind; others 0
#: After ``SETTLE_TIME``, the run goes on in 0.1 s steps, up to ``MAX_SETTLE`` s more,
#: while the object moves faster than ``SETTLED_SPEED`` (m/s, its centre): the verdict is
#: on the object at rest, not bouncing (a ball let go over its hole was still bouncing
#: at 6 cm/s after 1.2 s).
MAX_SETTLE = 2.0  # s
SETTLED_SPEED = 0.05  # m/s (a ball may roll on the floor at 2 cm/s for long)
CLOSES = ("reactive", "scripted")
#: The reactive close's parameters: the controller's defaults (the lift is the arm's).
REACTIVE_PARAMS = ReactiveGraspParams()
#: Seconds the arm stands at the grasp for the reactive close: every finger closing
#: all the way (``max_closing / close_rate``), the squeeze, the hold, and 0.1 s.
REACTIVE_CLOSE_TIME = (REACTIVE_PARAMS.max_closing / REACTIVE_PARAMS.close_rate
                       + REACTIVE_PARAMS.squeeze_time + REACTIVE_PARAMS.hold_time + 0.1)
_FAR = 10.0  # m, the pose the close trigger reports before the grasp
PRIOR_WEIGHT = 0.01  # the predicted orientation's weight against each contact normal
#: The kinds located in the hand after the lift (from touch: their own geometry's fit,
#: :func:`~handle_drake.apps.pick.touch.locate_by_touch`), their release planned again
#: from it; the others are released as planned. Development sorter scenes 600-615 (true
#: poses, tools/locate_kinds.py): the fit nearer the plant's pose than the plan in
#: position in every scene, within 10 mm and 10 deg in 17 of 22 (docs/results/pick.md).
#: In the box with the located release: mesh 609 and 612, wine glass 605, mug 612,
#: cylinder 610, and tests/pick/test_pick_kinds.py's cylinder, mug, glass and mesh. Not
#: the star prism (the sorter's own scene: in the box as planned, on the rim as located;
#: dev 606 and 610 on the rim either way) nor the rotated cuboid (dev 611 likewise).
LOCATED_KINDS = ("sphere", "cuboid", "cylinder", "mug", "wine_glass", "mesh")


class _CloseTrigger(LeafSystem):
    """Starts a :class:`ReactiveGrasp` whose approach is the arm's: before ``t_start`` it
    passes no touch (``tactile`` reads zero) and reports the hand ``_FAR`` from the
    goal; from ``t_start`` on, the tactile forces as measured and the hand at the
    goal (the arm's driver holds it at the grasp pose), so the controller closes."""

    def __init__(self, n: int, goal6, t_start: float):
        super().__init__()
        self._goal = np.asarray(goal6, dtype=float)
        self._t = float(t_start)
        self._tactile = self.DeclareVectorInputPort("tactile", n)
        self.DeclareVectorOutputPort("tactile", n, self._gated_tactile)
        self.DeclareVectorOutputPort("wrist_pose_measured", 6, self._pose)

    def _gated_tactile(self, context, output: BasicVector):
        started = context.get_time() >= self._t
        output.SetFromVector(self._tactile.Eval(context) if started
                             else np.zeros(output.size()))

    def _pose(self, context, output: BasicVector):
        pose = self._goal.copy()
        if context.get_time() < self._t:
            pose[0] += _FAR
        output.SetFromVector(pose)


class _HandSwitch(LeafSystem):
    """``hand.position``: the scripted command, but the reactive controller's between
    ``t_from`` and ``t_to`` (the close, the lift and the carry)."""

    def __init__(self, nu: int, t_from: float, t_to: float, scripted_only=()):
        super().__init__()
        self._window = (float(t_from), float(t_to))
        # Command entries always from the script (the wrist an arm's IK moves).
        self._scripted_only = np.asarray(scripted_only, dtype=int)
        self._scripted = self.DeclareVectorInputPort("scripted", nu)
        self._reactive = self.DeclareVectorInputPort("reactive", nu)
        self.DeclareVectorOutputPort("hand_position", nu, self._output)

    def set_window(self, t_from: float, t_to: float) -> None:
        """Moves the reactive window (the release was planned again)."""
        self._window = (float(t_from), float(t_to))

    def _output(self, context, output: BasicVector):
        t = context.get_time()
        inside = self._window[0] <= t < self._window[1]
        if not inside:
            output.SetFromVector(self._scripted.Eval(context))
            return
        value = np.array(self._reactive.Eval(context))
        value[self._scripted_only] = self._scripted.Eval(context)[self._scripted_only]
        output.SetFromVector(value)


@dc.dataclass
class PickOutcome:
    in_box: bool
    reason: str  # "in the box" or why not
    p_WO_final: np.ndarray
    sim_seconds: float
    wall_seconds: float
    # The reactive close at the lift (None when scripted): its mode's name, the fingers
    # that stopped on a touch and each finger's closing fraction when the squeeze began.
    close_mode: str | None = None
    fingers_touched: list | None = None
    closing_at_squeeze: list | None = None
    # The object in the hand after the lift (with a reach): how far (mm) and how much
    # turned (deg) from the planned grasp it was measured, from how many contacts, and
    # whether the release was planned again for it.
    in_hand_offset_mm: float | None = None
    in_hand_turn_deg: float | None = None
    in_hand_contacts: int = 0
    release_corrected: bool = False
    # The measured pose against the plant's (mm, deg): how far the located object was
    # from where it truly was in the hand after the lift.
    in_hand_error_mm: float | None = None
    in_hand_error_deg: float | None = None
    # Where the object's centre was when the hand began to open, from the release pose
    # planned for it (mm, horizontal), and its tilt from upright there (deg).
    release_offset_mm: float | None = None
    release_tilt_deg: float | None = None
    release_height_mm: float | None = None

    @property
    def real_time_rate(self) -> float:
        return self.sim_seconds / self.wall_seconds


def _timeline(plan, velocity, close_time=CLOSE_TIME, hold_time=HOLD_TIME):
    """(times, arm knots, hand knots, labels->time); the close lasts ``close_time`` s
    and is held ``hold_time`` s."""
    times, arm, hand, marks = [0.0], [plan.waypoints[0].q], [plan.waypoints[0].hand], {}
    t = 0.0
    for a, b in zip(plan.waypoints, plan.waypoints[1:], strict=False):
        points = [*(b.path or []), b.q]
        previous = a.q
        for q in points:
            dt = max(MIN_SEGMENT if q is b.q else 0.05,
                     float(np.max(np.abs(q - previous) / (0.5 * np.asarray(velocity)))))
            if b.label == "close":
                dt = close_time
            elif b.label == "open":
                dt = CLOSE_TIME
            t += dt
            times.append(t)
            arm.append(q)
            # b's command: a's but at the close and the open, and for an arm with fewer
            # than six joints the wrist joints the IK set for b (plan.wrist_from_ik).
            hand.append(b.hand)
            previous = q
        dwell = hold_time if b.label == "close" else RELEASE_DWELL.get(plan.kind, 0.0) \
            if b.label == "release" else 0.0
        if dwell > 0:
            t += dwell
            times.append(t)
            arm.append(b.q)
            hand.append(b.hand)
        marks[b.label] = t
    return np.array(times), np.array(arm), np.array(hand), marks


def _connect_reactive_close(builder, station, scenario, plan, marks, scripted_port):
    """The reactive close between the grasp and the release (see the module doc)."""
    grasp = plan.grasp
    kind = scenario.hand.kind
    groups = finger_command_groups(kind)
    goal = np.asarray(grasp.wrist(grasp.X_WB))
    controller = builder.AddNamedSystem("reactive_close", ReactiveGrasp(
        goal, goal, grasp.preshape_command, grasp.close_command, groups,
        params=dc.replace(REACTIVE_PARAMS, arrival_timeout=1e3)))
    trigger = builder.AddNamedSystem("close_trigger", _CloseTrigger(
        len(groups), goal, marks["grasp"]))
    names = get_hand_spec(kind).actuated_joint_names
    switch = builder.AddNamedSystem("hand_switch", _HandSwitch(
        len(names), marks["grasp"], marks["release"],
        [names.index(n) for n in getattr(plan, "wrist_from_ik", ())]))
    builder.Connect(station.GetOutputPort("hand.tactile"), trigger.get_input_port())
    builder.Connect(trigger.GetOutputPort("tactile"), controller.get_tactile_input_port())
    builder.Connect(trigger.GetOutputPort("wrist_pose_measured"),
                    controller.get_wrist_pose_measured_input_port())
    builder.Connect(scripted_port, switch.GetInputPort("scripted"))
    builder.Connect(controller.GetOutputPort("hand_position"), switch.GetInputPort("reactive"))
    builder.Connect(switch.get_output_port(), station.GetInputPort("hand.position"))
    return switch


def measure_in_hand(plant, plant_context, contacts, target_instance, hand_instance,
                    base_body: str, spec, X_OB_planned: RigidTransform):
    """``(X_OB, contacts used)``: the object's pose in the hand base frame B from its
    contacts with the hand (``contacts``: the plant's ContactResults), or None with
    fewer than two. The prediction is the planned grasp (``X_OB_planned``) on the hand
    where it is now. A sphere's centre lies one radius inside each contact point along
    the surface normal (their mean; orientation as predicted). A cuboid's faces: each
    contact's normal is matched to the predicted face it is nearest to, the rotation
    that best turns the predicted faces' normals onto the measured ones (Wahba's
    problem, :meth:`scipy.spatial.transform.Rotation.align_vectors`, the predicted
    axes added with weight ``PRIOR_WEIGHT``) corrects the orientation, and the centre
    is the least-squares point whose faces pass through the contact points (held at
    the prediction along directions no contact constrains)."""
    object_bodies = {int(i) for i in plant.GetBodyIndices(target_instance)}
    hand_bodies = {int(i) for i in plant.GetBodyIndices(hand_instance)}
    points, normals = [], []
    for k in range(contacts.num_point_pair_contacts()):
        info = contacts.point_pair_contact_info(k)
        a, b = int(info.bodyA_index()), int(info.bodyB_index())
        nhat = np.asarray(info.point_pair().nhat_BA_W)  # from B into A
        if a in object_bodies and b in hand_bodies:
            normal = -nhat
        elif b in object_bodies and a in hand_bodies:
            normal = nhat
        else:
            continue
        points.append(np.asarray(info.contact_point()))
        normals.append(normal / np.linalg.norm(normal))
    if len(points) < 2:
        return None
    X_WB = plant.GetBodyByName(base_body, hand_instance).EvalPoseInWorld(plant_context)
    X_WO = locate_object(spec, X_WB @ X_OB_planned.inverse(), points, normals)
    return X_WO.inverse() @ X_WB, len(points)


def locate_object(spec, X_WO_predicted: RigidTransform, points, normals) -> RigidTransform:
    """The pose of a sphere or cuboid ``spec`` touched at ``points`` (k, 3) where its
    outward surface normals are ``normals`` (k, 3), near ``X_WO_predicted`` (see
    :func:`measure_in_hand`)."""
    points, normals = np.asarray(points, dtype=float), np.asarray(normals, dtype=float)
    R, c = X_WO_predicted.rotation().matrix(), X_WO_predicted.translation()
    d = dimensions(spec)
    if spec.kind == "sphere":
        c = np.mean(points - 0.5 * d["diameter"] * normals, axis=0)
    else:
        half = 0.5 * np.array([d["width"], d["depth"], d["height"]])
        axis = np.argmax(np.abs(normals @ R), axis=1)
        sign = np.sign(np.einsum("ij,ij->i", normals, R[:, axis].T))
        faces = (R[:, axis] * sign).T
        # The predicted axes as weak observations of themselves: a rotation about a
        # direction no contact normal constrains (two opposite faces only) stays as
        # predicted instead of being arbitrary.
        weights = np.r_[np.ones(len(normals)), np.full(3, PRIOR_WEIGHT)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            turn = Rotation.align_vectors(np.vstack([normals, R.T]), np.vstack([faces, R.T]),
                                          weights=weights)[0].as_matrix()
        R, faces = turn @ R, faces @ turn.T
        A, rhs, weight = faces, np.einsum("ij,ij->i", faces, points) - half[axis], 1e-3
        c = np.linalg.solve(A.T @ A + weight * np.eye(3), A.T @ rhs + weight * c)
    return RigidTransform(RotationMatrix.ProjectToRotationMatrix(R), c)


def _correct_release(simulator, diagram, station, scenario, plan, reach, close, sources):
    """Measures the object in the hand (now, after the lift) and, if a release is
    reachable with it, replaces the arm's and the hand's trajectories from the lift on.
    Returns ``(plan, times, marks, report)``."""
    from pydrake.trajectories import PiecewisePolynomial

    if plan.kind not in LOCATED_KINDS:  # measure_in_hand locates these only
        return plan, None, None, {}
    plant = GetPlant(station)
    context = plant.GetMyContextFromRoot(simulator.get_context())
    hand = plant.GetModelInstanceByName("hand")
    X_OB_planned = plan.X_WO.inverse() @ plan.grasp.X_WB
    if senses_touch(station):  # the hand's taxels, joints and the arm's joints
        measured = locate_by_touch(station, simulator.get_mutable_context(), scenario,
                                   plan.grasp.object_spec, X_OB_planned)
    else:  # the simulator's contact points
        measured = measure_in_hand(plant, context,
                                   station.GetOutputPort("contact_results").Eval(
                                       station.GetMyContextFromRoot(simulator.get_context())),
                                   plant.GetModelInstanceByName(plan.target), hand,
                                   get_hand_spec(scenario.hand.kind).base_body,
                                   plan.grasp.object_spec, X_OB_planned)
    if measured is None:
        return plan, None, None, {}
    X_OB, count = measured
    error = X_OB_planned.inverse() @ X_OB
    X_WB = plant.GetBodyByName(get_hand_spec(scenario.hand.kind).base_body,
                               hand).EvalPoseInWorld(context)
    X_WO_true = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(
        plan.target))[0]).EvalPoseInWorld(context)
    truth = (X_WB @ X_OB.inverse()).inverse() @ X_WO_true
    report = dict(in_hand_offset_mm=round(float(np.linalg.norm(
        X_OB.translation() - X_OB_planned.translation())) * 1000, 1),
        in_hand_turn_deg=round(float(np.degrees(error.rotation().ToAngleAxis().angle())), 1),
        in_hand_contacts=count,
        in_hand_error_mm=round(float(np.linalg.norm(truth.translation())) * 1000, 1),
        in_hand_error_deg=round(float(np.degrees(truth.rotation().ToAngleAxis().angle())), 1))
    again = replan_release(scenario, reach, plan, X_OB)
    if again is None:
        return plan, None, None, report
    plan = dc.replace(plan, waypoints=again[0], X_WO_release=again[1])
    times, arm, hand_knots, marks = _plan_timeline(plan, scenario, close)
    arm_source, hand_source, switch = sources
    arm_source.UpdateTrajectory(PiecewisePolynomial.FirstOrderHold(times, arm.T))
    hand_source.UpdateTrajectory(PiecewisePolynomial.FirstOrderHold(times, hand_knots.T))
    if switch is not None:
        switch.set_window(marks["grasp"], marks["release"])
    return plan, times, marks, dict(report, release_corrected=True)


def _plan_timeline(plan, scenario, close):
    spec = get_arm_spec(scenario.hand.mount.kind)
    if close == "reactive":
        return _timeline(plan, spec.velocity, REACTIVE_CLOSE_TIME, 0.0)
    return _timeline(plan, spec.velocity)


def weld_bystanders(scenario, target: str):
    """``scenario`` with every object but ``target`` (an instance name: ``object``,
    ``object_1``...) welded where it rests."""
    names = [object_instance_name(i + 1) for i in range(len(scenario.objects))]
    if scenario.object is not None:
        names.append("object")
    if target not in names:
        raise ValueError(f"target {target!r} is not an object of the scenario")
    first = scenario.object
    if first is not None and target != "object":
        first = dc.replace(first, fixed=True)
    others = [o if object_instance_name(i + 1) == target else dc.replace(o, fixed=True)
              for i, o in enumerate(scenario.objects)]
    return dc.replace(scenario, object=first, objects=others)


def filter_idle_contacts(station, root_context, target: str) -> list[tuple[str, str]]:
    """Excludes, in ``root_context``'s geometry state (the station's ``scene_graph``),
    the collision pairs no successful pick of ``target`` (an instance name) has:
    the arm's links against the table, the sorting box and every object (the
    plan keeps the arm clear of them; the hand is not the arm), and each object
    that is not picked (a bystander, resting where the scene put it, clear of the
    box and of the others) against the box and the other bystanders. The hand
    against everything, the target against everything and the bystanders
    against the table stay. Returns the excluded (group, group) pairs by name."""
    plant = GetPlant(station)
    scene_graph = station.GetSubsystemByName("scene_graph")

    def geometries(instance_name):
        instance = plant.GetModelInstanceByName(instance_name)
        return plant.CollectRegisteredGeometries(
            [plant.get_body(i) for i in plant.GetBodyIndices(instance)])

    names = ["object"] if plant.HasModelInstanceNamed("object") else []
    k = 1
    while plant.HasModelInstanceNamed(object_instance_name(k)):
        names.append(object_instance_name(k))
        k += 1
    if target not in names:
        raise ValueError(f"target {target!r} is not an object of the station")
    fixed = [n for n in ("table", SORTING_BOX) if plant.HasModelInstanceNamed(n)]
    bystanders = [n for n in names if n != target]
    pairs = [(ARM_INSTANCE, n) for n in (*fixed, *names)] if plant.HasModelInstanceNamed(
        ARM_INSTANCE) else []
    if SORTING_BOX in fixed:
        pairs += [(n, SORTING_BOX) for n in bystanders]
    pairs += [(a, b) for i, a in enumerate(bystanders) for b in bystanders[i + 1:]]
    declaration = CollisionFilterDeclaration()
    for a, b in pairs:
        declaration.ExcludeBetween(geometries(a), geometries(b))
    scene_graph.collision_filter_manager(
        scene_graph.GetMyMutableContextFromRoot(root_context)).Apply(declaration)
    return pairs


#: The phases of an executed pick, in order, and the timeline mark each ends at (the
#: release ends after the settle).
PHASES = (("approach", "grasp"), ("close", "close"), ("lift", "lift"), ("carry", "release"),
          ("release", None))


def execute_pick(scenario, plan, html=None, still_bystanders: bool = False,
                 close: str = "reactive", reach=None,
                 filter_contacts: bool = False, monitor=None, progress=None) -> PickOutcome:
    """Simulates ``plan`` on ``scenario``'s station (cameras left out; the other
    objects welded with ``still_bystanders``; ``close``: one of ``CLOSES``; with
    ``reach``, the ArmReach the plan was made with, the release is corrected by the
    object measured in the hand: see the module doc; ``filter_contacts``: the pairs
    of :func:`filter_idle_contacts` excluded (default: every pair simulated);
    ``monitor(station, station_context)``, if given, is called after every step);
    writes an HTML replay to ``html`` when given. ``progress(phase, sim_seconds,
    wall_seconds, note)``, if given, is called as each of :data:`PHASES` ends (the
    simulated and wall-clock seconds it took; ``note``: the object's height gained,
    or where it ended)."""
    if close not in CLOSES:
        raise ValueError(f"close: expected one of {CLOSES}, got {close!r}")
    scenario = dc.replace(scenario, cameras=[])
    if still_bystanders:
        scenario = weld_bystanders(scenario, plan.target)
    if reach is not None:  # the release is corrected from the hand's taxels
        scenario = with_taxels(scenario)
    meshcat = None
    if html is not None:
        from pydrake.geometry import StartMeshcat

        meshcat = StartMeshcat()
    station = MakeHandStation(scenario, meshcat=meshcat)
    times, marks, diagram, sources = _build_diagram(station, scenario, plan, close)
    simulator = _simulator(diagram, station, plan.target, filter_contacts, monitor)
    context = simulator.get_mutable_context()
    station_context = station.GetMyContextFromRoot(context)
    position = station.GetOutputPort(f"{plan.target}.position")
    p0 = position.Eval(station_context).copy()
    if meshcat is not None:
        meshcat.StartRecording()
    start = time.perf_counter()
    clock = [0.0, start]  # the last phase's end: simulated, wall

    def advance(phase, t):
        simulator.AdvanceTo(t)
        if progress is not None:
            now = time.perf_counter()
            p_now = position.Eval(station_context)
            note = (f"object {100 * (p_now[2] - p0[2]):+.1f} cm from where it stood"
                    if phase != "release" else
                    f"object at {np.round(p_now, 3).tolist()}")
            progress(phase, t - clock[0], now - clock[1], note)
            clock[:] = [t, now]

    advance("approach", marks["grasp"])
    advance("close", marks["close"])
    advance("lift", marks["lift"])
    p_lift = position.Eval(station_context).copy()
    close_report = _close_report(diagram, context) if close == "reactive" else {}
    if reach is not None:
        plan, new_times, new_marks, measured = _correct_release(
            simulator, diagram, station, scenario, plan, reach, close, sources)
        close_report.update(measured)
        if new_times is not None:
            times, marks = new_times, new_marks
    advance("carry", marks["release"])
    p_release = position.Eval(station_context).copy()
    close_report.update(_release_report(station, station_context, scenario, plan, p_release))
    end = _settle(simulator, station, station_context, plan.target, times[-1])
    advance("release", end)
    wall = time.perf_counter() - start
    p = position.Eval(station_context).copy()
    if meshcat is not None:
        _write_replay(meshcat, html)
    inside = in_box(scenario, p)
    reason = _judge(plan, inside, p0, p_lift, p_release, p)
    return PickOutcome(inside, reason, p, end, wall, **close_report)


def _release_report(station, station_context, scenario, plan, p_release) -> dict:
    """The object's horizontal offset (mm) from the planned release and its tilt from
    upright (deg) as the hand begins to open, and the planned height (mm) of its bottom
    above the lid's top there."""
    bottom = (plan.X_WO_release.translation()[2] - hole_centres(scenario)[plan.kind][2]
              - resting_height(plan.grasp.object_spec))
    plant = GetPlant(station)
    context = station.GetSubsystemContext(plant, station_context)
    body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(plan.target))[0])
    # The object's axis nearest the vertical (a cuboid may rest on any face).
    up = np.max(np.abs(body.EvalPoseInWorld(context).rotation().matrix()[2, :]))
    return dict(release_offset_mm=round(float(np.linalg.norm(
        p_release[:2] - plan.X_WO_release.translation()[:2])) * 1000, 1),
        release_tilt_deg=round(float(np.degrees(np.arccos(np.clip(up, 0, 1)))), 1),
        release_height_mm=round(float(bottom) * 1000, 1))


def _build_diagram(station, scenario, plan, close):
    """``(times, marks, diagram, sources)``: the plan's timeline and the diagram that
    plays it to ``station`` (the arm's and the hand's trajectory sources, the hand's
    through the reactive close with ``close`` "reactive"); ``sources``: ``(arm_source,
    hand_source, switch)`` as ``_correct_release`` takes them (switch None: scripted)."""
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    times, arm, hand, marks = _plan_timeline(plan, scenario, close)
    builder = DiagramBuilder()
    builder.AddSystem(station)
    arm_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, arm.T)))
    # The hand's command steps at each knot into a ramp to the next.
    hand_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, hand.T)))
    builder.Connect(arm_source.get_output_port(), station.GetInputPort("arm.position"))
    switch = None
    if close == "reactive":
        switch = _connect_reactive_close(builder, station, scenario, plan, marks,
                                         hand_source.get_output_port())
    else:
        builder.Connect(hand_source.get_output_port(), station.GetInputPort("hand.position"))
    return times, marks, builder.Build(), (arm_source, hand_source, switch)


def _settle(simulator, station, station_context, target: str, t_last: float) -> float:
    """Advances ``SETTLE_TIME`` past the timeline's last knot ``t_last``, then in 0.1 s
    steps while ``target`` moves faster than ``SETTLED_SPEED`` (at most ``MAX_SETTLE``
    more); returns the time it stopped at."""
    end = t_last + SETTLE_TIME
    plant = GetPlant(station)
    plant_context = station.GetSubsystemContext(plant, station_context)
    body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(target))[0])
    simulator.AdvanceTo(end)
    while (np.linalg.norm(plant.EvalBodySpatialVelocityInWorld(plant_context, body)
                          .translational()) > SETTLED_SPEED
           and end < t_last + SETTLE_TIME + MAX_SETTLE - 1e-9):
        end += 0.1
        simulator.AdvanceTo(end)
    return end


def _write_replay(meshcat, html) -> None:
    """Ends ``meshcat``'s recording and writes it to ``html`` as a static page."""
    from pathlib import Path

    meshcat.StopRecording()
    meshcat.PublishRecording()
    Path(html).parent.mkdir(parents=True, exist_ok=True)
    Path(html).write_text(meshcat.StaticHtml())


def _simulator(diagram, station, target, filter_contacts, monitor):
    """The run's Simulator: the idle pairs filtered, the monitor set (execute_pick)."""
    from pydrake.systems.analysis import Simulator

    simulator = Simulator(diagram)
    if filter_contacts:
        filter_idle_contacts(station, simulator.get_mutable_context(), target)
    if monitor is not None:
        def _monitor(root_context):
            monitor(station, station.GetMyContextFromRoot(root_context))
            return EventStatus.Succeeded()

        simulator.set_monitor(_monitor)
    return simulator


def _close_report(diagram, context) -> dict:
    controller = diagram.GetSubsystemByName("reactive_close")
    c = controller.GetMyContextFromRoot(context)
    return dict(close_mode=controller.get_mode(c).name,
                fingers_touched=controller.fingers_touched(c).tolist(),
                closing_at_squeeze=controller.closing_at_squeeze(c).round(3).tolist())


def _judge(plan, inside, p0, p_lift, p_release, p) -> str:
    """"in the box", or what the object did instead."""
    lifted = p_lift[2] - p0[2]
    off = np.linalg.norm(p_release[:2] - plan.X_WO_release.translation()[:2])
    if inside:
        return "in the box"
    if lifted < 0.5 * plan.grasp.lift_height:
        return (f"not in the box: the grasp did not lift the object (it rose "
                f"{lifted * 100:.1f} cm of {plan.grasp.lift_height * 100:.0f})")
    if off > 0.03:
        return (f"not in the box: dropped on the way (at the release it was "
                f"{off * 100:.1f} cm off the hole)")
    return (f"not in the box: let go over the hole but stopped at "
            f"{np.round(p, 3).tolist()} (on the lid or the rim)")
