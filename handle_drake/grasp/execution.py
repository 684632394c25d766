"""Executing a :class:`~handle_drake.grasp.planning.GraspPlan` with tactile feedback.

``plan -> ReactiveGrasp -> station``: :class:`ReactiveGraspRunner` builds the
plan's floating-wrist station and a :class:`~handle_drake.systems.reactive_grasp.
ReactiveGrasp` controller (report section 3.3) in one diagram:

- the approach runs from the plan's stand-off pose ``X_WB_pregrasp`` to its
  grasp pose ``X_WB`` with the fingers in the pre-shape; a fingertip (or other
  hand) contact slows it and shifts it sideways, several stop it;
- each finger of the class then closes from the pre-shape towards the plan's
  closing command and stops at its own tactile contact; once all of them
  touch, all close a further ``squeeze`` (by default the plan's own squeeze:
  ``CLOSING_SQUEEZE`` out of the ``PRESHAPE_OPENING + CLOSING_SQUEEZE`` stroke);
- the hand lifts the plan's ``lift_height``.

The open-loop alternative is the plan's keyframe script (``plan.to_scenario()``
run by :class:`~handle_drake.run.ScenarioRunner`). Both return a
:class:`~handle_drake.run.RunResult`, so :func:`handle_drake.demo.held_through_lift`
judges either.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus
from pydrake.systems.primitives import VectorLogSink

from handle_drake.grasp.planning import CLOSING_SQUEEZE, PRESHAPE_OPENING, GraspPlan
from handle_drake.hands import get_hand_spec
from handle_drake.run import LOG_PERIOD, RunResult, advance_recording
from handle_drake.station import GetPlant, MakeHandStation
from handle_drake.systems.reactive_grasp import (
    ReactiveGrasp,
    ReactiveGraspMode,
    ReactiveGraspParams,
    finger_command_groups,
)

__all__ = ["ReactiveGraspRunner", "plan_params", "run_plan"]

SETTLE = 0.5  # s simulated after the lift completes (held_through_lift looks at 0.3 s)


def plan_params(plan: GraspPlan, **overrides) -> ReactiveGraspParams:
    """Controller parameters for a plan: its squeeze fraction and lift height."""
    base = dict(squeeze=CLOSING_SQUEEZE / (PRESHAPE_OPENING + CLOSING_SQUEEZE),
                lift_height=plan.lift_height)
    base.update(overrides)
    return ReactiveGraspParams(**base)


class ReactiveGraspRunner:
    """Station + ReactiveGrasp + loggers for one plan; built once, run many times.

    Args:
        plan: a :class:`GraspPlan`.
        meshcat: optional Meshcat (live view; ``run(html=...)`` saves a replay).
        params: :class:`ReactiveGraspParams` (default :func:`plan_params`).
    """

    def __init__(self, plan: GraspPlan, meshcat=None, params: ReactiveGraspParams | None = None,
                 world_object=None):
        if not isinstance(plan, GraspPlan):
            raise TypeError(f"plan must be a GraspPlan, got {type(plan).__name__}")
        self.plan = plan
        self.meshcat = meshcat
        self.scenario = plan.to_scenario(world_object=world_object)
        self.scenario.script = []  # the controller drives the station, not keyframes
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem("station", MakeHandStation(self.scenario, meshcat))
        plant = GetPlant(self.station)
        hand = plant.GetModelInstanceByName("hand")
        spec = get_hand_spec(self.scenario.hand.kind)
        tips = [plant.GetFrameByName(n, hand).body().index() for n in spec.fingertip_frames]
        self.controller = builder.AddNamedSystem("reactive_grasp", ReactiveGrasp(
            plan.wrist(plan.X_WB_pregrasp), plan.wrist(plan.X_WB), plan.preshape_command,
            plan.close_command, finger_command_groups(spec.name),
            params=params if params is not None else plan_params(plan),
            hand_bodies=plant.GetBodyIndices(hand), fingertip_bodies=tips))
        c, s = self.controller, self.station
        builder.Connect(s.GetOutputPort("hand.tactile"), c.get_tactile_input_port())
        builder.Connect(s.GetOutputPort("wrist.pose_measured"),
                        c.get_wrist_pose_measured_input_port())
        builder.Connect(s.GetOutputPort("contact_results"), c.get_contact_results_input_port())
        builder.Connect(c.GetOutputPort("wrist_pose"), s.GetInputPort("wrist.pose"))
        builder.Connect(c.GetOutputPort("hand_position"), s.GetInputPort("hand.position"))
        self._loggers = {}
        for port in ("hand.position_measured", "hand.tactile", "object.position"):
            output = s.GetOutputPort(port)
            logger = builder.AddSystem(VectorLogSink(output.size(), LOG_PERIOD))
            builder.Connect(output, logger.get_input_port())
            self._loggers[port] = logger
        mode_log = builder.AddSystem(VectorLogSink(1, LOG_PERIOD))
        builder.Connect(c.GetOutputPort("mode"), mode_log.get_input_port())
        self._loggers["mode"] = mode_log
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self._controller_context = c.GetMyContextFromRoot(self.context)
        self._default_context = self.diagram.CreateDefaultContext()
        self._done_at = None
        self.simulator.set_monitor(self._monitor)

    @property
    def max_duration(self) -> float:
        """Upper bound (s) on a run: a slowed approach of the whole stand-off and the rest."""
        p = self.controller.params
        length = float(np.linalg.norm(self.plan.X_WB.translation()
                                      - self.plan.X_WB_pregrasp.translation()))
        slowed = length / (p.approach_speed * p.slow_factor) - length / p.approach_speed
        return self.controller.nominal_duration() + slowed + p.arrival_timeout + SETTLE

    def _monitor(self, root_context):
        mode = self.controller.get_mode(self._controller_context)
        finished = (mode is ReactiveGraspMode.STOPPED
                    or self.controller.lift_complete(self._controller_context))
        t = root_context.get_time()
        if finished and self._done_at is None:
            self._done_at = t
        if self._done_at is not None and t >= self._done_at + SETTLE:
            return EventStatus.ReachedTermination(self.controller, "grasp finished")
        return EventStatus.DidNothing()

    def run(self, duration: float | None = None, html=None) -> RunResult:
        """Simulates until the lift is done (plus ``SETTLE``), the approach
        stopped, or ``duration`` (default :attr:`max_duration`)."""
        duration = self.max_duration if duration is None else float(duration)
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be finite and > 0, got {duration}")
        self.context.SetTimeStateAndParametersFrom(self._default_context)
        for logger in self._loggers.values():
            logger.FindMutableLog(self.context).Clear()
        self._done_at = None
        self.simulator.Initialize()
        wall = advance_recording(self.simulator, duration, self.station, self.meshcat, html)
        logs = {k: v.FindLog(self.context) for k, v in self._loggers.items()}
        result = RunResult(
            times=logs["hand.position_measured"].sample_times().copy(),
            object_position=logs["object.position"].data().T.copy(),
            hand_position=logs["hand.position_measured"].data().T.copy(),
            tactile=logs["hand.tactile"].data().T.copy(),
            wall_time=wall, sim_time=self.context.get_time(),
        )
        self.modes = [ReactiveGraspMode(int(m)) for m in logs["mode"].data()[0]]
        if not np.all(np.isfinite(result.object_position)):
            raise FloatingPointError("simulation diverged: non-finite object position")
        return result

    def final_mode(self) -> ReactiveGraspMode:
        return self.controller.get_mode(self._controller_context)

    def fingers_touched(self) -> np.ndarray:
        """(fingers,) bool: which fingers stopped closing on their own contact (last run)."""
        return self.controller.fingers_touched(self._controller_context)

    def closing_at_squeeze(self) -> np.ndarray:
        """(fingers,) closing fraction of each finger when the squeeze began (last run)."""
        return self.controller.closing_at_squeeze(self._controller_context)


def run_plan(plan: GraspPlan, reactive: bool = True, meshcat=None, html=None,
             params: ReactiveGraspParams | None = None, world_object=None) -> RunResult:
    """Executes a plan reactively (:class:`ReactiveGraspRunner`) or open loop
    (its keyframe script on :class:`~handle_drake.run.ScenarioRunner`).

    world_object: the object that is really there (an ``ObjectConfig``), when
    the plan was made on an estimate of it (perception, pose error); None:
    the plan's own object."""
    if reactive:
        return ReactiveGraspRunner(plan, meshcat, params, world_object).run(html=html)
    if params is not None:
        raise ValueError("params apply to the reactive execution only (reactive=True)")
    from handle_drake.run import ScenarioRunner

    return ScenarioRunner(plan.to_scenario(world_object=world_object), meshcat).run(html=html)
