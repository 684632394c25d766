"""Run a scenario: station + scripted command + loggers, simulate, report.

:class:`ScenarioRunner` builds the diagram once and re-runs it from the
default context (a reset, not a rebuild), which is what trials need.
"""

from __future__ import annotations

import dataclasses as dc
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource, VectorLogSink
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.hands import get_hand_spec
from handle_drake.scenario import FloatingWrist, Scenario
from handle_drake.station import MakeHandStation, hand_initial_command
from handle_drake.systems.hand_driver import rpy_pose6

__all__ = ["ScenarioRunner", "RunResult", "script_trajectories", "advance_recording"]

LOG_PERIOD = 0.01  # s


@dc.dataclass
class RunResult:
    """What one simulated run recorded (sampled every ``LOG_PERIOD`` s)."""

    times: np.ndarray  # (T,) s
    object_position: np.ndarray | None  # (T, 3) m, p_WO
    hand_position: np.ndarray  # (T, nq) rad
    tactile: np.ndarray  # (T, fingertips) N
    wall_time: float  # s
    sim_time: float  # s

    @property
    def realtime_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    def object_lift(self) -> float:
        """Height gained by the object between the first and last sample (m)."""
        if self.object_position is None:
            raise ValueError("this scenario has no object")
        return float(self.object_position[-1, 2] - self.object_position[0, 2])


def advance_recording(simulator, t_final: float, station, meshcat=None,
                      html: str | Path | None = None) -> float:
    """``simulator.AdvanceTo(t_final)``; with a Meshcat and ``html``, records the
    run with the station's MeshcatVisualizer and saves it as a self-contained
    page. Returns the wall time (s) of the simulation alone."""
    visualizer = None
    framed = None
    plant = plant_context = None
    if meshcat is not None and station.HasOutputPort("body_poses"):
        # Open the view framed on the hand and object (simulation only: the
        # hardware station has no plant to read poses from).
        from handle_drake.station import GetPlant
        from handle_drake.viewing import frame_hand_and_object

        plant = GetPlant(station)
        plant_context = plant.GetMyContextFromRoot(simulator.get_context())
        framed = frame_hand_and_object(meshcat, plant, plant_context)
    if html is not None and meshcat is not None:
        from pydrake.geometry import MeshcatVisualizer

        visualizer = next(s for s in station.GetSystems() if isinstance(s, MeshcatVisualizer))
        visualizer.StartRecording(False)
    start = time.perf_counter()
    simulator.AdvanceTo(t_final)
    wall = time.perf_counter() - start
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
    """Builds station + scripted commands + loggers once; runs many times.

    Args:
        scenario: the scenario (its ``script`` drives the hand and wrist).
        meshcat: optional Meshcat for live view and recording.
        hardware: drive the real (CAN) hand instead of the simulation, in
            real time; ``reset`` then only restarts the script and the logs.
    """

    def __init__(self, scenario: Scenario, meshcat=None, hardware: bool = False):
        self.scenario = scenario
        self.meshcat = meshcat
        self.hardware = hardware
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem(
            "station", MakeHandStation(scenario, meshcat, hardware=hardware))
        self.initial_command = hand_initial_command(scenario)
        hand_traj, wrist_traj = script_trajectories(scenario, self.initial_command)
        if hand_traj is not None:
            source = builder.AddNamedSystem("hand_script", TrajectorySource(hand_traj))
        else:
            source = builder.AddNamedSystem(
                "hand_script", ConstantVectorSource(self.initial_command))
        builder.Connect(source.get_output_port(), self.station.GetInputPort("hand.position"))
        if wrist_traj is not None:
            wrist_source = builder.AddNamedSystem("wrist_script", TrajectorySource(wrist_traj))
            builder.Connect(wrist_source.get_output_port(),
                            self.station.GetInputPort("wrist.pose"))
        self._loggers = {}
        for port in ("hand.position_measured", "hand.tactile", "object.position"):
            if self.station.HasOutputPort(port):
                output = self.station.GetOutputPort(port)
                logger = builder.AddSystem(VectorLogSink(output.size(), LOG_PERIOD))
                builder.Connect(output, logger.get_input_port())
                self._loggers[port] = logger
        self._object_contacts = None
        if scenario.object is not None and not hardware:
            from handle_drake.quality import ObjectContacts
            from handle_drake.station import GetPlant, object_body

            plant = GetPlant(self.station)
            hand = plant.GetModelInstanceByName("hand")
            bodies = [plant.get_body(i) for i in plant.GetBodyIndices(hand)]
            self._object_contacts = builder.AddNamedSystem("object_contacts", ObjectContacts(
                plant, object_body(plant), {b.name(): b for b in bodies}))
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

    def reset(self) -> None:
        """Back to the scenario's initial state without rebuilding anything."""
        self.context.SetTimeStateAndParametersFrom(self._default_context)
        for logger in self._loggers.values():
            logger.FindMutableLog(self.context).Clear()
        self.simulator.Initialize()

    def run(self, duration: float | None = None, html: str | Path | None = None) -> RunResult:
        """Resets, simulates ``duration`` (default: the scenario's) and returns the logs."""
        duration = self.scenario.simulation_duration if duration is None else float(duration)
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be finite and > 0, got {duration}")
        self.reset()
        wall = advance_recording(self.simulator, duration, self.station, self.meshcat, html)
        return self._result(duration, wall)

    def grasp_quality(self, surface_radius: float = 0.004, gamma: float = 0.002):
        """BW metric of the hand's contacts on the object now (after :meth:`run`).

        Soft-finger contacts with the object's friction, the contact surface
        model of radius ``surface_radius`` (m), moments scaled by half the
        object size. Returns ``(value, force_closure, contacts by body)``.
        """
        if self._object_contacts is None:
            raise ValueError("grasp_quality needs a simulated scenario with an object")
        from handle_drake.quality import ContactParams, score_contacts
        from handle_drake.quality.surface import ObjectSurface
        from handle_drake.station import object_spec

        spec = object_spec(self.scenario)
        contacts = self._object_contacts.get_output_port().Eval(
            self._object_contacts.GetMyContextFromRoot(self.context))
        params = ContactParams(model="soft_finger", mu=spec.mu, gamma=gamma,
                               characteristic_length=spec.size / 2)
        return score_contacts(contacts, params, ObjectSurface(spec), surface_radius)

    def _result(self, duration, wall) -> RunResult:
        logs = {port: logger.FindLog(self.context) for port, logger in self._loggers.items()}
        hand = logs["hand.position_measured"]
        obj = logs.get("object.position")
        result = RunResult(
            times=hand.sample_times().copy(),
            object_position=None if obj is None else obj.data().T.copy(),
            hand_position=hand.data().T.copy(),
            tactile=logs["hand.tactile"].data().T.copy(),
            wall_time=wall,
            sim_time=duration,
        )
        for name, array in (("hand position", result.hand_position),
                            ("object position", result.object_position)):
            if array is not None and not np.all(np.isfinite(array)):
                raise FloatingPointError(f"simulation diverged: non-finite {name}")
        return result
