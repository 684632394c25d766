"""Run a scenario: station + scripted command + loggers, simulate, report.

:class:`ScenarioRunner` is the scenario's keyframe script on a
:class:`~handle_drake.trial.harness.TrialHarness`: the diagram is built once and
re-run from the default context (a reset, not a rebuild). ``RunResult``,
``LOG_PERIOD`` and ``advance_recording`` live in :mod:`handle_drake.trial.harness`
and are re-exported here.
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

import numpy as np
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.base.hands import get_hand_spec
from handle_drake.geometry.quality import ContactParams
from handle_drake.geometry.quality.surface import ObjectSurface
from handle_drake.scenario import DumpScenario, FloatingWrist, Scenario
from handle_drake.station import GetPlant, hand_initial_command, object_body, object_spec
from handle_drake.systems.guarded_grasp import GuardedGrasp
from handle_drake.systems.hand_driver import rpy_pose6
from handle_drake.trial.harness import (
    DEFAULT_LOG,
    LOG_PERIOD,
    HoldScore,
    RunResult,
    TrialHarness,
    advance_recording,
)

__all__ = [
    "placed",
    "ScenarioRunner",
    "RunResult",
    "script_trajectories",
    "advance_recording",
    "LOG_PERIOD",
    "REQUIRED_LIFT",
    "held_through_lift",
]

REQUIRED_LIFT = 0.10  # m: how far a held object rises with the hand in the lift scenarios


def held_through_lift(result: RunResult, required_lift: float = REQUIRED_LIFT,
                      settle: float = 0.3) -> bool:
    """True if the object ends at least ``required_lift`` higher and did not
    fall during the last ``settle`` seconds (it moved by less than 1 cm)."""
    z = result.object_position[:, 2]
    late = result.times >= result.times[-1] - settle
    return bool(z[-1] - z[0] >= required_lift and np.ptp(z[late]) < 0.01)


def placed(scenario: Scenario, placement) -> Scenario:
    """``scenario`` with its guarded grasp's ``start_pose`` moved sideways by ``placement``
    (``[dx, dy]``, m) and no ``metric.placements`` (one run of the robust objective)."""
    c = scenario.controller
    start = np.array(c.start_pose, dtype=float)
    start[:2] += np.asarray(placement, dtype=float)
    return dc.replace(scenario, controller=dc.replace(c, start_pose=start.tolist()),
                      metric=dc.replace(scenario.metric, placements=[]))


def script_trajectories(scenario: Scenario, initial_command: np.ndarray):
    """The scenario's keyframes as (hand, wrist) ``PiecewisePolynomial`` or None."""
    if not scenario.script:
        return None, None
    spec = get_hand_spec(scenario.hand.kind)
    names = list(spec.actuated_joint_names)
    hand = np.array(initial_command, dtype=float)
    floating = isinstance(scenario.hand.mount, FloatingWrist)
    wrist = rpy_pose6(scenario.hand.mount.X_WB.GetDeterministicValue()) if floating else None
    times, hand_values, wrist_values = [], [], []
    if scenario.script[0].time > 0:
        times.append(0.0)
        hand_values.append(hand.copy())
        wrist_values.append(None if wrist is None else wrist.copy())
    for keyframe in scenario.script:
        for name, value in keyframe.hand.items():
            hand[names.index(name)] = value
        if keyframe.wrist:
            wrist = np.array(keyframe.wrist, dtype=float)
        times.append(keyframe.time)
        hand_values.append(hand.copy())
        wrist_values.append(None if wrist is None else wrist.copy())
    if len(times) == 1:
        times.append(times[0] + 1.0)
        hand_values.append(hand_values[0])
        wrist_values.append(wrist_values[0])
    hand_traj = PiecewisePolynomial.FirstOrderHold(times, np.array(hand_values).T)
    wrist_traj = (PiecewisePolynomial.FirstOrderHold(times, np.array(wrist_values).T)
                  if floating else None)
    return hand_traj, wrist_traj


class ScenarioRunner:
    """The scenario on its station (a :class:`TrialHarness`), built once, run many times.

    What drives the station is the scenario's: its keyframe ``script``, or its
    ``controller`` (a :class:`~handle_drake.scenario.GuardedGraspController`).
    With a ``metric`` the run ends by scoring the grasp (``RunResult.score``).

    A trial is a scenario too: :meth:`run` accepts another scenario that
    differs from the built one only in what a trial sets per run (the
    controller's start pose, pre-shape, closing command and standoff, the
    duration), so one diagram serves a whole experiment and a logged trial's
    scenario replays it alone (``handle-drake simulate``).

    Args:
        scenario: the scenario.
        meshcat: optional Meshcat for live view and recording.
        hardware: drive the real (CAN) hand instead of the simulation, in
            real time; ``reset`` then only restarts the script and the logs.
        log: port names to record (see :class:`TrialHarness`).
        finite_commands: the station's drivers as Drake primitives (no Python call per
            control period; see :func:`~handle_drake.station.MakeHandStation`). Default:
            when the scenario's validated keyframe script drives every command input
            (no controller; a floating wrist has a script), where the Python drivers'
            hold on a non-finite command cannot act; False keeps the Python drivers.
        outputs: the station outputs read besides ``log`` (see :class:`TrialHarness`);
            None: all of them.
    """

    def __init__(self, scenario: Scenario, meshcat=None, hardware: bool = False,
                 log=DEFAULT_LOG, finite_commands: bool | None = None, outputs=None):
        if hardware and scenario.controller is not None:
            raise ValueError("a scenario controller (the guarded grasp) reads simulated contact "
                             "results: it cannot drive the hardware; use a script")
        self.scenario = scenario
        self.meshcat = meshcat
        self.hardware = hardware
        self.initial_command = hand_initial_command(scenario)
        if finite_commands is None:
            finite_commands = scenario.controller is None and (
                bool(scenario.script) or not isinstance(scenario.hand.mount, FloatingWrist))
        self.harness = TrialHarness(
            scenario, self.add_driver, log=log, meshcat=meshcat, hardware=hardware,
            object_contacts=scenario.object is not None and not hardware,
            finite_commands=finite_commands, outputs=outputs)
        self.station = self.harness.station
        self.controller = self.harness.controller
        self.diagram = self.harness.diagram
        self.simulator = self.harness.simulator
        self.context = self.harness.context
        self._structure = None  # the scenario's text without its trial settings, when needed

    def add_driver(self, builder, station):
        """Adds what drives ``station`` (the scenario's controller, else its script) to
        ``builder``; returns the controller, or None for a script.

        The extension point of an experiment that needs more systems in the one
        diagram (a recorder, a MIDI receiver): override it, call ``super()`` and
        return the system whose ports :attr:`harness` may log.
        """
        if self.scenario.controller is not None:
            return _add_guarded_grasp(builder, station, self.scenario)
        hand_traj, wrist_traj = script_trajectories(self.scenario, self.initial_command)
        if hand_traj is not None:
            source = builder.AddNamedSystem("hand_script", TrajectorySource(hand_traj))
        else:
            source = builder.AddNamedSystem(
                "hand_script", ConstantVectorSource(self.initial_command))
        builder.Connect(source.get_output_port(), station.GetInputPort("hand.position"))
        if wrist_traj is not None:
            wrist_source = builder.AddNamedSystem("wrist_script", TrajectorySource(wrist_traj))
            builder.Connect(wrist_source.get_output_port(), station.GetInputPort("wrist.pose"))
        return None

    def _trial_scenario(self, scenario: Scenario | None) -> Scenario:
        if scenario is None:
            return self.scenario
        if not isinstance(scenario, Scenario):
            raise TypeError(f"scenario: expected a Scenario, got {type(scenario).__name__}")
        if scenario is self.scenario or _same_structure(scenario, self.scenario):
            return scenario
        if self._structure is None:
            self._structure = _structure(self.scenario)
        if _structure(scenario) != self._structure:
            raise ValueError(
                "scenario: this runner's diagram was built for another scenario; a run may "
                "change only the controller's start_pose, preshape, closed and standoff, the "
                "metric and simulation_duration (build a ScenarioRunner for this one)")
        return scenario

    def reset(self, scenario: Scenario | None = None) -> None:
        """Back to the initial state of ``scenario`` (default: the runner's) without rebuilding
        anything: the context's defaults, then the controller's trial settings."""
        scenario = self._trial_scenario(scenario)
        self.harness.reset()
        c = scenario.controller
        if c is not None:
            names = get_hand_spec(scenario.hand.kind).actuated_joint_names
            preshape = np.array([c.preshape.get(n, 0.0) for n in names])
            closed = np.array([c.closed.get(n, 0.0) for n in names])
            self.controller.set_trial(self.harness.controller_context(), start_pose6=c.start_pose,
                                      preshape=preshape, closed=closed, standoff=c.standoff)
            self.harness.place_wrist(c.start_pose)
            self.harness.place_hand(preshape)
        self.harness.initialize()

    def run(self, duration: float | None = None, html: str | Path | None = None,
            scenario: Scenario | None = None) -> RunResult:
        """Resets to ``scenario`` (default: the runner's; see the class doc), simulates
        ``duration`` (default: the scenario's) and returns the logs, and the score of
        the scenario's ``metric``."""
        scenario = self._trial_scenario(scenario)
        duration = scenario.simulation_duration if duration is None else float(duration)
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be finite and > 0, got {duration}")
        if scenario.metric is not None and scenario.metric.placements:
            return self._run_placements(scenario, duration, html)
        self.reset(scenario)
        metric = scenario.metric
        if metric is None:
            wall = self.harness.advance(duration, html)
            return self.harness.run_result(duration, wall)
        if metric.hold_window >= duration:
            raise ValueError(f"duration must exceed the metric's hold_window "
                             f"({metric.hold_window} s), got {duration}")
        hold_times = (duration - metric.hold_window * np.linspace(1.0, 0.0, metric.hold_samples)
                      if metric.hold_samples > 1 else [duration])
        params, surface = self._metric_model(scenario)
        samples, last = [], []

        def score():
            value, closure, contacts = self.harness.grasp_quality(params, surface,
                                                                  metric.surface_radius)
            samples.append(float(value))
            last[:] = [closure, contacts]

        wall = self.harness.advance(hold_times, html, at_each=score)
        hold = HoldScore(value=float(np.mean(samples)), samples=samples,
                         force_closure=bool(last[0]), contacts=last[1])
        return self.harness.run_result(duration, wall, hold)

    def _run_placements(self, scenario: Scenario, duration: float, html) -> RunResult:
        """One run per ``metric.placements`` entry (:func:`placed`); the result is the
        first placement's run (its logs, replay and contacts) with the metric's value
        the mean over the placements and ``placement_values`` each one's."""
        values, first = [], None
        for k, placement in enumerate(scenario.metric.placements):
            result = self.run(duration, html if k == 0 else None,
                              scenario=placed(scenario, placement))
            values.append(result.score.value)
            first = first or result
        first.score = dc.replace(first.score, value=float(np.mean(values)),
                                 placement_values=values)
        return first

    def _metric_model(self, scenario: Scenario):

        m = scenario.metric
        spec = object_spec(scenario)
        params = ContactParams(model="soft_finger", mu=spec.mu, gamma=m.gamma,
                               num_edges=m.num_edges, characteristic_length=spec.size / 2)
        return params, ObjectSurface(spec)

    def grasp_quality(self, surface_radius: float = 0.004, gamma: float = 0.002):
        """BW metric of the hand's contacts on the object now (after :meth:`run`).

        Soft-finger contacts with the object's friction, the contact surface
        model of radius ``surface_radius`` (m), moments scaled by half the
        object size. Returns ``(value, force_closure, contacts by body)``.
        """
        if self.hardware or self.scenario.object is None:
            raise ValueError("grasp_quality needs a simulated scenario with an object")

        spec = object_spec(self.scenario)
        params = ContactParams(model="soft_finger", mu=spec.mu, gamma=gamma,
                               characteristic_length=spec.size / 2)
        return self.harness.grasp_quality(params, ObjectSurface(spec), surface_radius)


_TRIAL_FIELDS = ("controller", "metric", "simulation_duration")


def _fixed_controller(controller):
    if controller is None:
        return None
    return dc.replace(controller, start_pose=[], preshape={}, closed={}, standoff=0.0)


def _same_structure(a: Scenario, b: Scenario) -> bool:
    """A quick, sufficient check that ``a`` differs from ``b`` only in trial settings: the
    same (or equal) objects in every other field, as a trial made by ``dc.replace`` of a
    base scenario has. False means "compare the texts" (:func:`_structure`)."""
    for field in dc.fields(Scenario):
        if field.name in _TRIAL_FIELDS:
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if x is not y and x != y:
            return False
    return _fixed_controller(a.controller) == _fixed_controller(b.controller)


def _structure(scenario: Scenario) -> str:
    """The scenario as text without what a run may change (see :class:`ScenarioRunner`)."""
    fixed = dc.replace(scenario, simulation_duration=1.0, metric=None,
                       controller=_fixed_controller(scenario.controller))
    return DumpScenario(fixed)


def _add_guarded_grasp(builder, station, scenario: Scenario):
    """The scenario's :class:`~handle_drake.systems.guarded_grasp.GuardedGrasp`, connected."""

    c = scenario.controller
    names = get_hand_spec(scenario.hand.kind).actuated_joint_names
    plant = GetPlant(station)
    hand = plant.GetModelInstanceByName("hand")
    hand_bodies = [plant.get_body(i) for i in plant.GetBodyIndices(hand)]
    known = {b.name() for b in hand_bodies}
    unknown = sorted(set(c.guard_bodies) - known)
    if unknown:
        raise ValueError(f"controller.guard_bodies: {unknown} are not bodies of the "
                         f"{scenario.hand.kind} hand; expected some of {sorted(known)}")
    guard = [b for b in hand_bodies if not c.guard_bodies or b.name() in c.guard_bodies]
    controller = builder.AddNamedSystem("controller", GuardedGrasp(
        c.start_pose, c.direction, speed=c.speed, max_travel=c.max_travel,
        preshape=[c.preshape.get(n, 0.0) for n in names],
        closed=[c.closed.get(n, 0.0) for n in names],
        hand_bodies=[b.index() for b in guard], object_bodies=[object_body(plant).index()],
        standoff=c.standoff, period=c.period))
    builder.Connect(station.GetOutputPort("contact_results"),
                    controller.get_contact_results_input_port())
    builder.Connect(controller.GetOutputPort("wrist_pose"), station.GetInputPort("wrist.pose"))
    builder.Connect(controller.GetOutputPort("hand_position"),
                    station.GetInputPort("hand.position"))
    return controller
