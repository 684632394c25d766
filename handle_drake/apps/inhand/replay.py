"""Replays a parameter vector (Algorithm 1) on a hand station: simulated or the CAN hand.

The same :class:`GistMotionSource` that drives the trials drives ``hand.position``
of any station the :class:`~handle_drake.trial.harness.TrialHarness` builds; with
``hardware=True`` (a ``!CanHandDriver`` scenario) the diagram runs in real
time against the CAN hand, exactly as ``handle-drake simulate --hardware``.

:class:`ReversalRunner` and :func:`replay_reversal`: ``handle-drake simulate`` of a logged
fingertip-cylinder trial (a free object whose trial ends with its weight reversed) builds
the logged station scenario with :class:`~handle_drake.trial.gist_trial.ReversedGravity`
on ``applied_spatial_force``, plays the logged script, then reverses the weight for the
trial's ``reverse_time`` and says whether the object is held (issue 45, items 6 and 7),
read from the plant by this module's own code.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from handle_drake.apps.inhand.gist import ActionGist, GistMotionSource
from handle_drake.apps.inhand.screw_cap import ScrewCapScenario
from handle_drake.apps.inhand.task import TRIAL_MARKER, InHandScenario, touching_hand_bodies
from handle_drake.scenario import Scenario
from handle_drake.station import object_body
from handle_drake.trial.gist_trial import ReversedGravity
from handle_drake.trial.harness import TrialHarness
from handle_drake.trial.simulate import ScenarioRunner

__all__ = ["replay_motion", "Replay", "ReversalRunner", "Reversal", "logged_reversal",
           "replay_reversal"]


@dc.dataclass
class Replay:
    times: np.ndarray  # (T,) s
    commanded: np.ndarray  # (T, nu) rad, hand.position_commanded
    measured: np.ndarray  # (T, nq) rad, hand.position_measured
    wall_time: float


def replay_motion(scenario: Scenario, gist: ActionGist, c, q0, duration: float,
                  n_frames: int = 50, hold: float = 0.5, hardware: bool = False,
                  meshcat=None, html=None) -> Replay:
    """Sends the frames of ``c`` to the scenario's hand for ``duration + hold`` seconds."""
    if scenario.hand.kind != "shadow":
        raise ValueError(f"hand.kind: the action gist drives the shadow hand, got "
                         f"{scenario.hand.kind!r}")

    def add_motion(builder, station):
        source = builder.AddNamedSystem("motion", GistMotionSource(gist, q0, duration, n_frames,
                                                                   parameters=c))
        builder.Connect(source.get_output_port(), station.GetInputPort("hand.position"))
        return source

    harness = TrialHarness(scenario, add_motion, meshcat=meshcat, hardware=hardware,
                           log=("hand.position_commanded", "hand.position_measured"))
    harness.reset()
    harness.initialize()
    wall = harness.advance(duration + hold, html=html)
    logs = harness.logs()
    commanded, measured = logs["hand.position_commanded"], logs["hand.position_measured"]
    return Replay(commanded.sample_times().copy(), commanded.data().T.copy(),
                  measured.data().T.copy(), wall)


@dc.dataclass
class Reversal:
    """A logged trial's reversal settings (from its trial scenario)."""

    time: float  # s, the weight reversed after the scenario's duration
    travel: float  # m, held only if the object moves less
    margin: float  # N beyond the reversed weight
    # the travel as the trial reads it: the largest over every step (the fingertip
    # cylinder), or where the reversal leaves it (the palm-up tasks, InHandTrial)
    every_step: bool = True


def logged_reversal(text: str) -> Reversal | None:
    """The reversal of a logged in-hand trial's text (its trial scenario after the station's,
    :func:`~handle_drake.apps.inhand.task.logged_scenario`): the fingertip cylinder's or a
    palm-up task's; None for a text without one (the screw cap on its thread, a scenario
    file)."""
    marker = next((line for line in text.splitlines() if line.startswith(TRIAL_MARKER)), "")
    if marker.endswith(", palm up"):
        palm_up = InHandScenario.load(text)
        return _checked_reversal(palm_up.reverse_time, palm_up.reverse_travel, 0.0, False)
    if not marker.endswith(": fingertip cylinder"):
        return None
    trial = ScrewCapScenario.load(text)
    return _checked_reversal(trial.reverse_time, trial.reverse_travel, trial.reverse_margin,
                             True)


def _checked_reversal(time, travel, margin, every_step: bool) -> Reversal:
    trial = Reversal(time, travel, margin, every_step)
    for name, value in (("reverse_time", trial.time), ("reverse_travel", trial.travel)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a finite value > 0 in the logged trial, got "
                             f"{value!r}")
    return Reversal(float(time), float(travel), float(margin), every_step)


class ReversalRunner(ScenarioRunner):
    """The scenario's runner with the object's weight reversible (:class:`ReversedGravity`
    on the station's ``applied_spatial_force``, off until :func:`replay_reversal`)."""

    def __init__(self, scenario: Scenario, margin: float, meshcat=None, log=()):
        self._margin = float(margin)
        self.reverse_system = None
        super().__init__(scenario, meshcat, log=log)

    def add_driver(self, builder, station):
        controller = super().add_driver(builder, station)
        plant = station.GetSubsystemByName("plant")
        self.reverse_system = builder.AddNamedSystem(
            "reversed_gravity", ReversedGravity(plant, object_body(plant), self._margin))
        builder.Connect(self.reverse_system.get_output_port(),
                        station.GetInputPort("applied_spatial_force"))
        return controller


def replay_reversal(runner: ReversalRunner, reversal: Reversal, html=None) -> dict:
    """After :meth:`ReversalRunner.run` (the scenario's whole duration): the weight reversed
    for ``reversal.time``; returns ``held`` (moved less than ``reversal.travel`` from where
    the run left it, and a hand body other than the palm touches it at the end),
    ``travel`` (m: the largest over every step, or at the end, as ``reversal.every_step``)
    and ``touching`` (hand bodies, at the end)."""
    plant, context = runner.harness.plant, runner.context
    plant_context = plant.GetMyContextFromRoot(context)
    body = object_body(plant)
    p_end = plant.EvalBodyPoseInWorld(plant_context, body).translation().copy()
    worst = [0.0]

    def each_step(root_context):
        p = plant.EvalBodyPoseInWorld(plant.GetMyContextFromRoot(root_context),
                                      body).translation()
        worst[0] = max(worst[0], float(np.linalg.norm(p - p_end)))
        return ""  # never stops

    runner.reverse_system.set_reversed(runner.reverse_system.GetMyContextFromRoot(context),
                                       True)
    runner.harness.stop_when(each_step)
    try:
        runner.harness.advance(context.get_time() + reversal.time, html)
    finally:
        runner.harness.stop_when(None)
    hand = {int(i): plant.get_body(i).name()
            for i in plant.GetBodyIndices(plant.GetModelInstanceByName("hand"))}
    touching = touching_hand_bodies(
        plant.get_contact_results_output_port().Eval(plant_context), body, hand)
    travel = worst[0] if reversal.every_step else float(np.linalg.norm(
        plant.EvalBodyPoseInWorld(plant_context, body).translation() - p_end))
    held = travel < reversal.travel and any(name != "palm" for name in touching)
    return dict(held=bool(held), travel=travel, touching=touching)
