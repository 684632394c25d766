"""Run a :class:`~handle_drake.apps.pick.plan.PickPlan` on the simulated station and judge it.

The arm follows the plan's waypoints (and the paths between them) through
``arm.position``: each segment lasts long enough for the slowest joint at half
its speed limit (at least ``MIN_SEGMENT`` s), linear in joint space, and the
driver's own rate limit applies on top. The hand holds each waypoint's command
through ``hand.position``; the close ramps over ``CLOSE_TIME`` s and holds
``HOLD_TIME`` s before the lift; the release opens to the pre-shape and waits
``SETTLE_TIME`` s for the object to fall. Success: the object's centre is in
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

from handle_drake.devices.arm.model import get_arm_spec
from handle_drake.scene.config import in_box, object_instance_name
from handle_drake.station import MakeHandStation

__all__ = ["PickOutcome", "execute_pick", "weld_bystanders", "MIN_SEGMENT"]

MIN_SEGMENT = 0.4  # s
CLOSE_TIME = 0.6  # s
HOLD_TIME = 0.3  # s
SETTLE_TIME = 1.2  # s


@dc.dataclass
class PickOutcome:
    in_box: bool
    reason: str  # "in the box" or why not
    p_WO_final: np.ndarray
    sim_seconds: float
    wall_seconds: float

    @property
    def real_time_rate(self) -> float:
        return self.sim_seconds / self.wall_seconds


def _timeline(plan, velocity):
    """(times, arm knots, hand knots, labels->time)."""
    times, arm, hand, marks = [0.0], [plan.waypoints[0].q], [plan.waypoints[0].hand], {}
    t = 0.0
    for a, b in zip(plan.waypoints, plan.waypoints[1:], strict=False):
        points = [*(b.path or []), b.q]
        previous = a.q
        for q in points:
            dt = max(MIN_SEGMENT if q is b.q else 0.05,
                     float(np.max(np.abs(q - previous) / (0.5 * np.asarray(velocity)))))
            if b.label in ("close", "open"):
                dt = CLOSE_TIME
            t += dt
            times.append(t)
            arm.append(q)
            hand.append(b.hand if b.label in ("close", "open") else a.hand)
            previous = q
        if b.label == "close":
            t += HOLD_TIME
            times.append(t)
            arm.append(b.q)
            hand.append(b.hand)
        marks[b.label] = t
    return np.array(times), np.array(arm), np.array(hand), marks


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


def execute_pick(scenario, plan, html=None, still_bystanders: bool = False) -> PickOutcome:
    """Simulates ``plan`` on ``scenario``'s station (cameras left out; the other
    objects welded with ``still_bystanders``); writes an HTML replay to
    ``html`` when given."""
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
    times, arm, hand, marks = _timeline(plan, spec.velocity)
    builder = DiagramBuilder()
    builder.AddSystem(station)
    arm_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, arm.T)))
    # The hand's command steps at each knot into a ramp to the next.
    hand_source = builder.AddSystem(TrajectorySource(
        PiecewisePolynomial.FirstOrderHold(times, hand.T)))
    builder.Connect(arm_source.get_output_port(), station.GetInputPort("arm.position"))
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
    lifted = p_lift[2] - p0[2]
    if inside:
        reason = "in the box"
    elif lifted < 0.5 * plan.grasp.lift_height:
        reason = (f"not in the box: the grasp did not lift the object (it rose "
                  f"{lifted * 100:.1f} cm of {plan.grasp.lift_height * 100:.0f})")
    elif np.linalg.norm(p_release[:2] - plan.X_WO_release.translation()[:2]) > 0.03:
        reason = (f"not in the box: dropped on the way (at the release it was "
                  f"{np.linalg.norm(p_release[:2] - plan.X_WO_release.translation()[:2]) * 100:.1f}"
                  f" cm off the hole)")
    else:
        reason = (f"not in the box: let go over the hole but stopped at "
                  f"{np.round(p, 3).tolist()} (on the lid or the rim)")
    return PickOutcome(inside, reason, p, end, wall)
