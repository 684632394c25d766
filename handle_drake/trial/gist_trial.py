"""The in-hand gist trial on the station: settle a grasp once, replay frames, read the plant.

Every in-hand task of :mod:`handle_drake.apps.inhand` whose motion is a sequence of joint
frames (Algorithm 1: the palm-up rotations, the screw cap and the fingertip cylinder) runs
on this one class, over the one :class:`~handle_drake.trial.harness.TrialHarness` on the
scenario's :func:`~handle_drake.station.MakeHandStation`:

- the diagram: the station (its hand driver in Drake primitives: the frames are finite by
  construction), a ``TrajectorySource`` playing the trial's frames into ``hand.position``
  (a zero-order hold whose breaks sit half a control period before each sample of the
  driver: the driver reads the same command as from the motion source itself, without a
  Python call per sample) and, for an object not on a joint, :class:`ReversedGravity` on the
  station's ``applied_spatial_force`` (the held test: the weight reversed). An object on a
  joint (a cap on its thread) is the station's own (``object.joint``).
- :meth:`settle` runs the grasp once with the still frames and keeps that context (time 0);
  :meth:`start` puts a trial there with its frames; :meth:`advance` runs it (``at_each``
  after each sample time), :meth:`each_step` reads the plant at every step (a monitor),
  :meth:`reverse` switches the reversed weight.
- ``hardware=True``: the same frames drive the CAN hand's station in real time (no plant,
  nothing to settle or read: :meth:`play`).

What a trial reads and how it is scored is the task's; the frames are the task's too (they
come from its gist), so this layer knows nothing of gists.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import BasicVector, EventStatus, LeafSystem, NumericParameterIndex
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.scenario import Scenario
from handle_drake.station import hand_initial_command, object_body
from handle_drake.trial.harness import TrialHarness

__all__ = ["GistTrial", "ReversedGravity"]


class ReversedGravity(LeafSystem):
    """While switched on (a numeric parameter; default off), a force ``-2 m g`` on the body
    at its centre of mass: its weight reversed (the hand turned palm down, for it), plus
    ``margin`` N more upwards (the grip's tangential margin beyond the weight).

    The output depends on that parameter alone (its only prerequisite), so Drake computes
    it once per switch and the plant's every step reads the cached forces: no Python call
    per step. Switch it on at the time the reversal starts (the trials do so at the end of
    the hold: the steps from then on feel it)."""

    def __init__(self, plant, body, margin: float = 0.0):
        super().__init__()
        if not (np.isfinite(margin) and margin >= 0):
            raise ValueError(f"reverse_margin: expected a finite value >= 0 N, got {margin!r}")
        self._index = body.index()
        g = plant.gravity_field().gravity_vector()
        # the weight reversed plus ``margin`` (N) more along the same (upward) direction: the
        # grip must hold the object's weight and a tangential margin beyond it (issue 45)
        self._force = -2.0 * body.default_mass() * g - margin * g / np.linalg.norm(g)
        self._on = self.DeclareNumericParameter(BasicVector([0.0]))
        self.DeclareAbstractOutputPort(
            "spatial_forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]),
            self._calc, prerequisites_of_calc={
                self.numeric_parameter_ticket(NumericParameterIndex(self._on))})

    def set_reversed(self, context, on: bool) -> None:
        context.get_mutable_numeric_parameter(self._on).SetAtIndex(0, 1.0 if on else 0.0)

    def _calc(self, context, output):
        forces = []
        if context.get_numeric_parameter(self._on).GetAtIndex(0) > 0.5:
            f = ExternallyAppliedSpatialForce()
            f.body_index = self._index
            f.p_BoBq_B = np.zeros(3)
            f.F_Bq_W = SpatialForce(np.zeros(3), self._force)
            forces.append(f)
        output.set_value(forces)


class GistTrial:
    """The station of ``scenario`` driven by frames, settled once, reset per trial.

    Args:
        scenario: the station's scenario (its hand on a fixed mount; the simulated driver
            samples the frames every ``driver.control_period``).
        meshcat: optional Meshcat (the station draws into it; :meth:`advance` records).
        hardware: the CAN hand's station (the scenario's ``!CanHandDriver``).
        reverse_margin: N beyond the reversed weight (:class:`ReversedGravity`).
        outputs: the station outputs read (see :func:`MakeHandStation`); () the least.
        log: station ports recorded every ``LOG_PERIOD`` (:class:`TrialHarness`).

    Attributes: ``harness``, ``plant`` (None on hardware), ``body`` (the object),
    ``hand_bodies`` (body index -> name), ``geometry`` (collision geometry id -> hand body
    name, ``"object"`` or ``"base"``), ``joint`` (the object's, or None), ``base`` (its
    welded base body, or None), ``weight`` (N), ``reverse_system``, ``settled``.
    """

    def __init__(self, scenario: Scenario, *, meshcat=None, hardware: bool = False,
                 reverse_margin: float = 0.0, outputs=(), log=()):
        self.scenario = scenario
        self.hardware = hardware
        self.reverse_margin = float(reverse_margin)
        self._player = self.reverse_system = None
        self.harness = TrialHarness(scenario, self._add_motion, log=log, meshcat=meshcat,
                                    hardware=hardware, finite_commands=True,
                                    outputs=None if hardware else outputs)
        self.plant = self.harness.plant
        self.settled = None
        self.body = self.joint = self.base = None
        self.hand_bodies, self.geometry, self.weight = {}, {}, 0.0
        if self.plant is not None and scenario.object is not None:
            self._index_plant()

    def _add_motion(self, builder, station):
        q0 = hand_initial_command(self.scenario)
        self._player = builder.AddNamedSystem("motion_frames", TrajectorySource(
            PiecewisePolynomial.ZeroOrderHold([0.0, 1.0], np.column_stack([q0, q0]))))
        builder.Connect(self._player.get_output_port(), station.GetInputPort("hand.position"))
        o = self.scenario.object
        if not self.hardware and o is not None and o.joint is None and not o.fixed:
            plant = station.GetSubsystemByName("plant")
            self.reverse_system = builder.AddNamedSystem("reversed_gravity", ReversedGravity(
                plant, object_body(plant), self.reverse_margin))
            builder.Connect(self.reverse_system.get_output_port(),
                            station.GetInputPort("applied_spatial_force"))
        return self._player

    def _index_plant(self) -> None:
        plant = self.plant
        hand = plant.GetModelInstanceByName("hand")
        self.hand_bodies = {int(plant.get_body(i).index()): plant.get_body(i).name()
                            for i in plant.GetBodyIndices(hand)}
        self.body = object_body(plant)
        others = [plant.get_body(i) for i in plant.GetBodyIndices(self.body.model_instance())]
        self.base = others[1] if len(others) > 1 else None
        if self.scenario.object.joint is not None:
            self.joint = plant.GetJointByName(self.scenario.object.joint.name,
                                              self.body.model_instance())
        self.geometry = {g: name for i, name in self.hand_bodies.items()
                         for g in plant.GetCollisionGeometriesForBody(plant.get_body(
                             BodyIndex(i)))}
        self.geometry.update({g: "object" for g in plant.GetCollisionGeometriesForBody(
            self.body)})
        if self.base is not None:
            self.geometry.update({g: "base" for g in plant.GetCollisionGeometriesForBody(
                self.base)})
        g = float(np.linalg.norm(plant.gravity_field().gravity_vector()))
        self.weight = self.body.default_mass() * g

    # ------------------------------------------------------------------ runs
    @property
    def player(self):
        """The ``TrajectorySource`` playing the frames into ``hand.position``."""
        return self._player

    @property
    def context(self):
        return self.harness.context

    @property
    def simulator(self):
        return self.harness.simulator

    def plant_context(self):
        return self.harness.plant_context()

    def station_context(self):
        return self.harness.station.GetMyContextFromRoot(self.harness.context)

    def settle(self, frames, duration: float) -> None:
        """Runs ``frames`` (the still grasp) from the scenario's initial state for
        ``duration`` s and keeps that state (at time 0) as every trial's start."""
        self.harness.reset()
        self._player.UpdateTrajectory(frames)
        self.harness.initialize()
        self.harness.advance(duration)
        self.settled = self.harness.context.Clone()
        self.settled.SetTime(0.0)

    def start(self, frames, settled=None) -> None:
        """The settled state (time 0; or the context ``settled``) with the trial's
        ``frames``; the weight not reversed. Call :meth:`initialize` before advancing."""
        settled = self.settled if settled is None else settled
        if settled is None:
            raise ValueError("GistTrial.start: settle the grasp first (settle)")
        self.harness.context.SetTimeStateAndParametersFrom(settled)
        self._player.UpdateTrajectory(frames)
        self.reverse(False)

    def initialize(self) -> None:
        self.harness.initialize()

    def reverse(self, on: bool) -> None:
        """Switches the object's reversed weight (a free object only)."""
        if self.reverse_system is None:
            if on:
                raise ValueError("reverse: this scenario's object has no reversed weight "
                                 "(on a joint, fixed or absent)")
            return
        self.reverse_system.set_reversed(
            self.reverse_system.GetMyContextFromRoot(self.harness.context), on)

    def each_step(self, callback: Callable | None) -> None:
        """Calls ``callback(root_context)`` after every step (a simulator monitor); None
        removes it."""
        if callback is None:
            self.harness.simulator.clear_monitor()
            return

        def monitor(root_context):
            callback(root_context)
            return EventStatus.Succeeded()

        self.harness.simulator.set_monitor(monitor)

    def advance(self, t, html=None, at_each=None) -> float:
        """Simulates to ``t`` (or through increasing times, ``at_each()`` after each);
        returns the wall time (s)."""
        return self.harness.advance(t, html, at_each)

    def play(self, frames, duration: float, html=None) -> dict:
        """From the scenario's initial state, ``frames`` for ``duration`` s (on hardware: in
        real time on the CAN hand); the logs of ``log`` as ``{port: (times, values)}``."""
        self.harness.reset()
        self._player.UpdateTrajectory(frames)
        self.harness.initialize()
        wall = self.harness.advance(duration, html)
        out = {name: (log.sample_times().copy(), log.data().T.copy())
               for name, log in self.harness.logs().items()}
        out["wall_time"] = wall
        return out
