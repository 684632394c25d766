"""A guarded approach-and-close grasp controller (one trial of grasp babbling).

The hand base moves from a start pose along the approach direction until any
hand link touches the object (or a maximum travel is reached), stops there,
then closes the hand to a closing command. This is how the report's OpenRAVE
trials grasp ("approach until contact, close the fingers until contact"), here
with physical contact in the simulation.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.containers import namedview
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import BasicVector, LeafSystem

__all__ = ["GuardedGrasp", "GuardedGraspState", "APPROACH", "CLOSE", "touching_bodies"]

APPROACH, CLOSE = 0, 1

#: The controller's discrete state: mode (APPROACH / CLOSE), travel along the
#: approach (m), contact time (s, NaN until contact), closing start time (s).
GuardedGraspState = namedview("GuardedGraspState",
                              ["mode", "travel", "contact_time", "close_from"])


def touching_bodies(contact_results: ContactResults, bodies_a, bodies_b) -> bool:
    """True if any point or hydroelastic contact joins a body of each set."""
    for i in range(contact_results.num_point_pair_contacts()):
        info = contact_results.point_pair_contact_info(i)
        a, b = info.bodyA_index(), info.bodyB_index()
        if (a in bodies_a and b in bodies_b) or (b in bodies_a and a in bodies_b):
            return True
    return False


class GuardedGrasp(LeafSystem):
    """Approach along a line until contact, back off by a standoff, close the hand.

    Ports:

    - input ``contact_results`` (abstract ``ContactResults``).
    - output ``wrist_pose`` (6): ``[x y z roll pitch yaw]`` command of the hand
      base (see the station's ``wrist.pose``).
    - output ``hand_position`` (nu, rad): the pre-shape until the hand has
      backed off after contact (or reached the end of its travel), then the
      closing command.
    - output ``mode`` (1): 0 approaching, 1 closing; ``contact_time`` (1, s,
      NaN until contact).

    The trial settings (start pose, pre-shape, closing command, standoff) are
    numeric parameters of the context, so one diagram serves many trials:
    reset the context and call :meth:`set_trial`.

    Args:
        start_pose6: default wrist pose at t = 0.
        direction: approach direction in world (normalised here).
        speed: approach speed (m/s); max_travel: stop here without contact (m).
        preshape, closed: default hand commands (nu).
        hand_bodies, object_bodies: ``BodyIndex`` sets for the contact guard.
        standoff: default distance (m) to back off after the first contact.
        period: control period (s).
    """

    def __init__(self, start_pose6, direction, speed, max_travel, preshape, closed,
                 hand_bodies, object_bodies, standoff=0.0, period=0.004):
        super().__init__()
        start = np.asarray(start_pose6, dtype=float)
        direction = np.asarray(direction, dtype=float)
        if start.shape != (6,) or direction.shape != (3,):
            raise ValueError(f"start_pose6 and direction: expected sizes 6 and 3, got "
                             f"{start.shape} and {direction.shape}")
        norm = np.linalg.norm(direction)
        if not np.isfinite(norm) or norm == 0:
            raise ValueError("direction must be a finite non-zero vector")
        if not (speed > 0 and max_travel >= 0):
            raise ValueError(f"expected speed > 0 and max_travel >= 0, got {speed}, {max_travel}")
        preshape = np.asarray(preshape, dtype=float)
        closed = np.asarray(closed, dtype=float)
        if preshape.shape != closed.shape or preshape.ndim != 1:
            raise ValueError(f"preshape and closed: expected equal 1-D sizes, got "
                             f"{preshape.shape} and {closed.shape}")
        self._nu = len(closed)
        self._direction = direction / norm
        self._speed, self._max_travel = float(speed), float(max_travel)
        self._hand_bodies = set(hand_bodies)
        self._object_bodies = set(object_bodies)
        self._period = period
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults()))
        self._p_start = self.DeclareNumericParameter(BasicVector(start))
        self._p_preshape = self.DeclareNumericParameter(BasicVector(preshape))
        self._p_closed = self.DeclareNumericParameter(BasicVector(closed))
        self._p_standoff = self.DeclareNumericParameter(BasicVector([float(standoff)]))
        self._state = self.DeclareDiscreteState(
            GuardedGraspState(np.array([APPROACH, 0.0, np.nan, np.inf]))[:])
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("wrist_pose", 6, self._calc_wrist)
        self.DeclareVectorOutputPort("hand_position", self._nu, self._calc_hand)
        self.DeclareVectorOutputPort(
            "mode", 1, lambda c, out: out.SetAtIndex(0, self.get_state(c).mode))
        self.DeclareVectorOutputPort(
            "contact_time", 1, lambda c, out: out.SetAtIndex(0, self.get_state(c).contact_time))

    def get_contact_results_input_port(self):
        return self._contacts

    def get_state(self, context) -> GuardedGraspState:
        """The discrete state as a :data:`GuardedGraspState` (a copy)."""
        return GuardedGraspState(context.get_discrete_state(self._state).value().copy())

    def set_trial(self, context, start_pose6=None, preshape=None, closed=None,
                  standoff=None) -> None:
        """Sets this trial's settings in ``context`` (None keeps the current one)."""
        for index, value, size in ((self._p_start, start_pose6, 6),
                                   (self._p_preshape, preshape, self._nu),
                                   (self._p_closed, closed, self._nu),
                                   (self._p_standoff, standoff, 1)):
            if value is None:
                continue
            value = np.atleast_1d(np.asarray(value, dtype=float))
            if value.shape != (size,) or not np.all(np.isfinite(value)):
                raise ValueError(f"expected {size} finite values, got {value}")
            context.get_mutable_numeric_parameter(index).SetFromVector(value)

    def _update(self, context, discrete_state):
        s = self.get_state(context)
        now = context.get_time()
        if s.mode == APPROACH:
            touching = touching_bodies(self._contacts.Eval(context), self._hand_bodies,
                                       self._object_bodies)
            if touching or s.travel >= self._max_travel:
                standoff = context.get_numeric_parameter(self._p_standoff).GetAtIndex(0)
                back = min(standoff, s.travel) if touching else 0.0
                s.travel -= back
                s.mode, s.contact_time = CLOSE, (now if touching else np.nan)
                # Close once the wrist has backed off (its PD needs ~0.1 s).
                s.close_from = now + (0.1 if back > 0 else 0.0)
            else:
                s.travel = min(s.travel + self._speed * self._period, self._max_travel)
        discrete_state.set_value(self._state, s[:])

    def _calc_wrist(self, context, out: BasicVector):
        travel = self.get_state(context).travel
        pose = context.get_numeric_parameter(self._p_start).CopyToVector()
        pose[:3] += travel * self._direction
        out.SetFromVector(pose)

    def _calc_hand(self, context, out: BasicVector):
        s = self.get_state(context)
        closing = s.mode == CLOSE and context.get_time() >= s.close_from
        parameter = self._p_closed if closing else self._p_preshape
        out.SetFromVector(context.get_numeric_parameter(parameter).value())
