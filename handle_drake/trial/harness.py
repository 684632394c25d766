"""One trial harness: build the station diagram once, reset its context per trial, score.

Every way the project runs a simulated (or real) hand goes through
:class:`TrialHarness`: the scripted scenario run
(:class:`~handle_drake.trial.simulate.ScenarioRunner`, ``handle-drake simulate``), the
reactive plan execution (:class:`~handle_drake.apps.planning.execution.ReactiveGraspRunner`)
and the grasp
babbling trial (:class:`~handle_drake.trial.grasp_trial.GraspTrial`).
A trial is *parameters -> scenario (override) -> simulate -> metric*; the
harness is the "simulate" part and owns what all of them share:

- the diagram: the scenario's station (:func:`~handle_drake.station.MakeHandStation`),
  a controller added by the caller's ``add_controller(builder, station)``,
  ``VectorLogSink`` loggers of named ports (the station's, then the
  controller's) and, on request, :class:`~handle_drake.geometry.quality.ObjectContacts`
  (the hand's contacts on the object, for the grasp metric). It is built once;
  pydrake diagrams do not pickle, so a process pool builds one per worker
  (send parameters, return plain numbers).
- the reset: :meth:`reset` restores the time, state and parameters of the
  default context and empties the logs, so one diagram serves many trials;
  the caller then writes the trial's initial state (:meth:`place_wrist`,
  :meth:`place_hand`, controller parameters) and calls :meth:`initialize`.
- the run: :meth:`advance` (optionally recording a Meshcat replay), with an
  early stop from :meth:`stop_when` (e.g. a grasp that is done, an object
  that fell: the in-hand trial stops early this way).
- the score: :meth:`contacts` and :meth:`grasp_quality` (BW metric of the
  contacts now) and :meth:`run_result` (the logged hand and object signals).

Nothing here depends on which controller drives the station, so an in-hand
trial (start from a stable grasp, replay joint frames, measure rotation) or a
Dask worker uses the same class.
"""

from __future__ import annotations

import dataclasses as dc
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus
from pydrake.systems.primitives import VectorLogSink

from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
from handle_drake.base.viewing import frame_hand_and_object
from handle_drake.geometry.quality import ObjectContacts, score_contacts
from handle_drake.scenario import Scenario
from handle_drake.station import GetPlant, MakeHandStation, object_body
from handle_drake.systems.hand_driver import WRIST_JOINTS, pose_to_wrist_joints

__all__ = ["TrialHarness", "RunResult", "HoldScore", "LOG_PERIOD", "DEFAULT_LOG",
           "advance_recording", "advance_sampling"]

LOG_PERIOD = 0.01  # s, sample period of the harness's loggers

#: The station ports a run records by default (those the station has).
DEFAULT_LOG = ("hand.position_measured", "hand.tactile", "object.position")


@dc.dataclass
class HoldScore:
    """A grasp metric sampled over the end of a run (``Scenario.metric``)."""

    value: float  # mean of ``samples``
    samples: list  # metric at each hold instant
    force_closure: bool  # at the last instant
    contacts: dict  # body name -> contacts in the object frame, at the last instant
    # metric.placements: each placement's value (``value`` is then their mean)
    placement_values: list = dc.field(default_factory=list)


@dc.dataclass
class RunResult:
    """What one run recorded (sampled every ``LOG_PERIOD`` s)."""

    times: np.ndarray  # (T,) s
    object_position: np.ndarray | None  # (T, 3) m, p_WO
    hand_position: np.ndarray  # (T, nq) rad
    tactile: np.ndarray  # (T, fingertips) N
    wall_time: float  # s
    sim_time: float  # s
    score: HoldScore | None = None  # the scenario's metric, if it has one

    @property
    def realtime_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    def object_lift(self) -> float:
        """Height gained by the object between the first and last sample (m)."""
        if self.object_position is None:
            raise ValueError("this scenario has no object")
        return float(self.object_position[-1, 2] - self.object_position[0, 2])


def advance_sampling(simulator, times, each_step, at_sample) -> bool:
    """Simulates to ``times[-1]`` in one ``AdvanceTo``, a monitor calling ``each_step(root
    context)`` after every step and ``at_sample(i, times[i])`` at the first step at or after
    each time (the state ``AdvanceTo(times[i])`` ends in: it applies the discrete update
    due before ``times[i]``, which the next step's monitor sees; tested), in order; stops
    there when ``at_sample`` returns True.
    Returns whether it stopped. One ``AdvanceTo`` per sample cost the trial 0.1 of the bare
    plant's time (issue 45, item 8)."""
    times = [float(t) for t in times]
    if not times:
        return False
    pending, errors, stop = [0], [], [False]
    diagram = simulator.get_system()

    def monitor(root_context):
        try:
            each_step(root_context)
            now = root_context.get_time()  # exactly: AdvanceTo(t) applies updates before t
            while pending[0] < len(times) and times[pending[0]] <= now:
                i = pending[0]
                pending[0] += 1
                if at_sample(i, times[i]):
                    stop[0] = True
                    return EventStatus.ReachedTermination(diagram, "stopped at a sample")
        except Exception as error:  # raised again outside the simulator
            errors.append(error)
            return EventStatus.ReachedTermination(diagram, "raised")
        return EventStatus.Succeeded()

    simulator.set_monitor(monitor)
    try:
        simulator.AdvanceTo(times[-1])
    finally:
        simulator.clear_monitor()
    if errors:
        raise errors[0]
    return stop[0]


def advance_recording(simulator, t_final, station, meshcat=None,
                      html: str | Path | None = None, at_each=None) -> float:
    """``simulator.AdvanceTo(t)`` for ``t_final`` (a time or an increasing sequence of
    times, ``at_each()`` called after each); with a Meshcat and ``html``, records
    the run with the station's MeshcatVisualizer and saves it as a self-contained
    page. Returns the wall time (s) of the simulation alone."""
    visualizer = None
    framed = None
    plant = plant_context = None
    if meshcat is not None and station.HasOutputPort("body_poses"):
        # Open the view framed on the hand and object (simulation only: the
        # hardware station has no plant to read poses from).

        plant = GetPlant(station)
        plant_context = plant.GetMyContextFromRoot(simulator.get_context())
        framed = frame_hand_and_object(meshcat, plant, plant_context)
    if html is not None and meshcat is not None:
        from pydrake.geometry import MeshcatVisualizer

        visualizer = next(s for s in station.GetSystems() if isinstance(s, MeshcatVisualizer))
        visualizer.StartRecording(False)
    wall = 0.0
    for t in np.atleast_1d(t_final):
        start = time.perf_counter()
        simulator.AdvanceTo(float(t))
        wall += time.perf_counter() - start
        if at_each is not None:
            at_each()
    if visualizer is not None:
        if framed is not None:
            # The replay frames where the hand and object went as well (a lift).
            frame_hand_and_object(meshcat, plant, plant_context, framed)
        visualizer.StopRecording()
        visualizer.PublishRecording()
        path = Path(html)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(meshcat.StaticHtml())
    return wall


class TrialHarness:
    """The scenario's station + a controller + loggers (+ object contacts), built once.

    Args:
        scenario: the scenario whose station is built (validated by the station).
        add_controller: ``f(builder, station) -> system or None``: adds and
            connects whatever drives the station's inputs (a script, a
            controller); its return value is :attr:`controller`.
        log: port names to record every ``LOG_PERIOD``: the station's output
            ports first, then the controller's; names neither has are skipped
            (a scenario without an object has no ``object.position``).
        object_contacts: add :class:`~handle_drake.geometry.quality.ObjectContacts` (the
            hand bodies' contacts on the object; simulation with an object only).
        meshcat: optional Meshcat for live view and :meth:`advance` recordings.
        hardware: drive the real (CAN) hand; the simulator then keeps real time.
        finite_commands: ``add_controller`` feeds the station's command inputs with
            commands finite by construction (see :func:`MakeHandStation`: the simulated
            drivers are then Drake primitives).
        outputs: the station outputs read (:func:`MakeHandStation`'s ``outputs``: the
            systems feeding only others are left out); None: all. The ``log`` ports
            are added to it.

    Attributes: ``scenario``, ``station``, ``plant`` (None on hardware),
    ``controller``, ``diagram``, ``simulator``, ``context`` (the root context).
    """

    def __init__(self, scenario: Scenario, add_controller: Callable | None = None, *,
                 log=DEFAULT_LOG, object_contacts: bool = False, meshcat=None,
                 hardware: bool = False, finite_commands: bool = False, outputs=None):
        if object_contacts and (hardware or scenario.object is None):
            raise ValueError("object_contacts needs a simulated scenario with an object")
        self.scenario = scenario
        self.meshcat = meshcat
        self.hardware = hardware
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem(
            "station", MakeHandStation(
                scenario, meshcat, hardware=hardware, finite_commands=finite_commands,
                outputs=outputs if outputs is None or isinstance(outputs, str)
                else tuple(outputs) + tuple(log)))
        self.plant = None if hardware else GetPlant(self.station)
        self.controller = None if add_controller is None else add_controller(builder, self.station)
        self._loggers = {}
        for name in log:
            for system in (self.station, self.controller):
                if system is not None and system.HasOutputPort(name):
                    output = system.GetOutputPort(name)
                    logger = builder.AddSystem(VectorLogSink(output.size(), LOG_PERIOD))
                    builder.Connect(output, logger.get_input_port())
                    self._loggers[name] = logger
                    break
        self._object_contacts = None
        if object_contacts:
            hand = self.plant.GetModelInstanceByName("hand")
            bodies = [self.plant.get_body(i) for i in self.plant.GetBodyIndices(hand)]
            self._object_contacts = builder.AddNamedSystem("object_contacts", ObjectContacts(
                self.plant, object_body(self.plant), {b.name(): b for b in bodies}))
            builder.Connect(self.station.GetOutputPort("contact_results"),
                            self._object_contacts.GetInputPort("contact_results"))
            builder.Connect(self.station.GetOutputPort("body_poses"),
                            self._object_contacts.GetInputPort("body_poses"))
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        if hardware:
            # A real hand runs in real time; the diagram must keep pace with it.
            self.simulator.set_target_realtime_rate(1.0)
        self.context = self.simulator.get_mutable_context()
        self._default_context = self.diagram.CreateDefaultContext()
        self._stop = None

    # ------------------------------------------------------------------ trial
    def reset(self) -> None:
        """Back to the scenario's initial time, state and parameters, logs emptied.

        Nothing is rebuilt. Write the trial's own initial state after this,
        then call :meth:`initialize`.
        """
        self.context.SetTimeStateAndParametersFrom(self._default_context)
        for logger in self._loggers.values():
            logger.FindMutableLog(self.context).Clear()

    def initialize(self) -> None:
        self.simulator.Initialize()

    def stop_when(self, condition: Callable | None) -> None:
        """Ends :meth:`advance` early once ``condition(root_context)`` returns a reason
        (a non-empty string); None removes the condition."""
        self._stop = condition
        if condition is None:
            self.simulator.clear_monitor()
        else:
            self.simulator.set_monitor(self._monitor)

    def _monitor(self, root_context):
        reason = self._stop(root_context)
        if reason:
            return EventStatus.ReachedTermination(self.diagram, str(reason))
        return EventStatus.DidNothing()

    def advance(self, t, html: str | Path | None = None, at_each=None) -> float:
        """Simulates to time ``t`` (or through an increasing sequence of times,
        calling ``at_each()`` at each; an early stop ends it); with ``html`` saves a
        Meshcat replay. Returns the wall time (s)."""
        return advance_recording(self.simulator, t, self.station, self.meshcat, html, at_each)

    def controller_context(self):
        return self.controller.GetMyMutableContextFromRoot(self.context)

    def plant_context(self):
        return self.plant.GetMyMutableContextFromRoot(self.context)

    def place_wrist(self, pose6) -> None:
        """Sets the floating wrist's joints to ``[x y z roll pitch yaw]`` in the context."""

        self._set_joint_positions("wrist", WRIST_JOINTS, pose_to_wrist_joints(pose6))

    def place_hand(self, command) -> None:
        """Sets the hand's joints to the posture of an actuated ``command`` (nu) in the context,
        and the simulated driver's initial command to it (so the hand holds there)."""

        spec = get_hand_spec(self.scenario.hand.kind)
        self._set_joint_positions("hand", spec.joint_names,
                                  actuated_to_joint_positions(spec, command))
        driver = self.station.GetSubsystemByName("hand_driver")
        driver.set_initial_command(driver.GetMyMutableContextFromRoot(self.context), command)

    def _set_joint_positions(self, instance_name, names, values) -> None:
        plant, plant_context = self.plant, self.plant_context()
        instance = plant.GetModelInstanceByName(instance_name)
        q = plant.GetPositions(plant_context)
        for name, value in zip(names, values, strict=True):
            q[plant.GetJointByName(name, instance).position_start()] = value
        plant.SetPositions(plant_context, q)

    # ------------------------------------------------------------------ score
    def contacts(self) -> dict:
        """The hand's contacts on the object now (body name -> contacts in the object frame)."""
        if self._object_contacts is None:
            raise ValueError("this harness was built without object_contacts")
        return self._object_contacts.get_output_port().Eval(
            self._object_contacts.GetMyContextFromRoot(self.context))

    def grasp_quality(self, params, surface, surface_radius: float):
        """``score_contacts`` of :meth:`contacts`: ``(BW value, force closure, contacts)``."""

        return score_contacts(self.contacts(), params, surface, surface_radius)

    def logs(self) -> dict:
        """Name -> Drake ``VectorLog`` of every recorded port (this run so far)."""
        return {name: logger.FindLog(self.context) for name, logger in self._loggers.items()}

    def run_result(self, sim_time: float, wall_time: float,
                   score: HoldScore | None = None) -> RunResult:
        """The logged hand and object signals as a :class:`RunResult`.

        Raises FloatingPointError if the hand or object positions are not finite.
        """
        logs = self.logs()
        hand = logs["hand.position_measured"]
        obj = logs.get("object.position")
        result = RunResult(
            times=hand.sample_times().copy(),
            object_position=None if obj is None else obj.data().T.copy(),
            hand_position=hand.data().T.copy(),
            tactile=logs["hand.tactile"].data().T.copy(),
            wall_time=wall_time,
            sim_time=sim_time,
            score=score,
        )
        for name, array in (("hand position", result.hand_position),
                            ("object position", result.object_position)):
            if array is not None and not np.all(np.isfinite(array)):
                raise FloatingPointError(f"simulation diverged: non-finite {name}")
        return result
