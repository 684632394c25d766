"""Run a :class:`~handle_drake.apps.pick.plan.PickPlan` on the simulated station and judge it.

The arm follows the plan's waypoints (and the paths between them) through
``arm.position``: each segment lasts long enough for the slowest joint at half
its speed limit (at least ``MIN_SEGMENT`` s), linear in joint space, and the
driver's own rate limit applies on top. The hand holds each waypoint's command
through ``hand.position``; the release opens to the pre-shape and waits
``SETTLE_TIME`` s for the object to fall.

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
over ``CLOSE_TIME`` s, held ``HOLD_TIME`` s. Success: the object's centre is in
the box (:func:`handle_drake.scene.plant.in_box`). A failure is told by what
the object did: not lifted with the hand, dropped on the way, or stopped on
the lid.

The other objects on the table (bystanders) are free bodies; with
``still_bystanders`` they are welded where they rest (resting on the table,
1 s of the station alone, they halve its speed). Off by default: in the pick
runs the gain was within the machine's noise and one of the seeded scenes
ended differently (docs/results/pick.md, benchmarks/bench_pick_sim.py).
"""

from __future__ import annotations

import dataclasses as dc
import time

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from handle_drake.base.hands import get_hand_spec
from handle_drake.devices.arm.model import get_arm_spec
from handle_drake.scene.config import in_box, object_instance_name
from handle_drake.station import MakeHandStation
from handle_drake.systems.reactive_grasp import (
    ReactiveGrasp,
    ReactiveGraspParams,
    finger_command_groups,
)

__all__ = ["PickOutcome", "execute_pick", "weld_bystanders", "MIN_SEGMENT", "CLOSES",
           "REACTIVE_CLOSE_TIME"]

MIN_SEGMENT = 0.4  # s
CLOSE_TIME = 0.6  # s, the scripted close's ramp
HOLD_TIME = 0.3  # s, and its hold before the lift
SETTLE_TIME = 1.2  # s
CLOSES = ("reactive", "scripted")
#: The reactive close's parameters: the controller's defaults (the lift is the arm's).
REACTIVE_PARAMS = ReactiveGraspParams()
#: Seconds the arm stands at the grasp for the reactive close: every finger closing
#: all the way (``max_closing / close_rate``), the squeeze, the hold, and 0.1 s.
REACTIVE_CLOSE_TIME = (REACTIVE_PARAMS.max_closing / REACTIVE_PARAMS.close_rate
                       + REACTIVE_PARAMS.squeeze_time + REACTIVE_PARAMS.hold_time + 0.1)
_FAR = 10.0  # m, the pose the close trigger reports before the grasp


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

    def __init__(self, nu: int, t_from: float, t_to: float):
        super().__init__()
        self._window = (float(t_from), float(t_to))
        self._scripted = self.DeclareVectorInputPort("scripted", nu)
        self._reactive = self.DeclareVectorInputPort("reactive", nu)
        self.DeclareVectorOutputPort("hand_position", nu, self._output)

    def _output(self, context, output: BasicVector):
        t = context.get_time()
        inside = self._window[0] <= t < self._window[1]
        output.SetFromVector((self._reactive if inside else self._scripted).Eval(context))


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
            hand.append(b.hand if b.label in ("close", "open") else a.hand)
            previous = q
        if b.label == "close" and hold_time > 0:
            t += hold_time
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
    switch = builder.AddNamedSystem("hand_switch", _HandSwitch(
        get_hand_spec(kind).num_actuated, marks["grasp"], marks["release"]))
    builder.Connect(station.GetOutputPort("hand.tactile"), trigger.get_input_port())
    builder.Connect(trigger.GetOutputPort("tactile"), controller.get_tactile_input_port())
    builder.Connect(trigger.GetOutputPort("wrist_pose_measured"),
                    controller.get_wrist_pose_measured_input_port())
    builder.Connect(scripted_port, switch.GetInputPort("scripted"))
    builder.Connect(controller.GetOutputPort("hand_position"), switch.GetInputPort("reactive"))
    builder.Connect(switch.get_output_port(), station.GetInputPort("hand.position"))


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


def execute_pick(scenario, plan, html=None, still_bystanders: bool = False,
                 close: str = "reactive") -> PickOutcome:
    """Simulates ``plan`` on ``scenario``'s station (cameras left out; the other
    objects welded with ``still_bystanders``; ``close``: one of ``CLOSES``, see the
    module doc); writes an HTML replay to ``html`` when given."""
    if close not in CLOSES:
        raise ValueError(f"close: expected one of {CLOSES}, got {close!r}")
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial


    scenario = dc.replace(scenario, cameras=[])
    if still_bystanders:
        scenario = weld_bystanders(scenario, plan.target)
    meshcat = None
    if html is not None:
        from pydrake.geometry import StartMeshcat

        meshcat = StartMeshcat()
    station = MakeHandStation(scenario, meshcat=meshcat)
    spec = get_arm_spec(scenario.hand.mount.kind)
    if close == "reactive":
        times, arm, hand, marks = _timeline(plan, spec.velocity, REACTIVE_CLOSE_TIME, 0.0)
    else:
        times, arm, hand, marks = _timeline(plan, spec.velocity)
    builder = DiagramBuilder()
    builder.AddSystem(station)
    arm_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, arm.T)))
    # The hand's command steps at each knot into a ramp to the next.
    hand_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, hand.T)))
    builder.Connect(arm_source.get_output_port(), station.GetInputPort("arm.position"))
    if close == "reactive":
        _connect_reactive_close(builder, station, scenario, plan, marks,
                                hand_source.get_output_port())
    else:
        builder.Connect(hand_source.get_output_port(), station.GetInputPort("hand.position"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station_context = station.GetMyContextFromRoot(context)
    position = station.GetOutputPort(f"{plan.target}.position")
    p0 = position.Eval(station_context).copy()
    if meshcat is not None:
        meshcat.StartRecording()
    start = time.perf_counter()
    simulator.AdvanceTo(marks["lift"])
    p_lift = position.Eval(station_context).copy()
    close_report = {}
    if close == "reactive":
        controller = diagram.GetSubsystemByName("reactive_close")
        c = controller.GetMyContextFromRoot(context)
        close_report = dict(close_mode=controller.get_mode(c).name,
                            fingers_touched=controller.fingers_touched(c).tolist(),
                            closing_at_squeeze=controller.closing_at_squeeze(c).round(3).tolist())
    simulator.AdvanceTo(marks["release"])
    p_release = position.Eval(station_context).copy()
    end = times[-1] + SETTLE_TIME
    simulator.AdvanceTo(end)
    wall = time.perf_counter() - start
    p = position.Eval(station_context).copy()
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        from pathlib import Path

        Path(html).parent.mkdir(parents=True, exist_ok=True)
        Path(html).write_text(meshcat.StaticHtml())
    inside = in_box(scenario, p)
    reason = _judge(plan, inside, p0, p_lift, p_release, p)
    return PickOutcome(inside, reason, p, end, wall, **close_report)


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
