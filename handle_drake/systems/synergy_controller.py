"""SynergyController: a hand position command from synergy amplitudes, joint
targets or fingertip targets, switchable at run time.

Ports (Shadow hand, ``k`` synergies):

=======================  =====  =========  ===========================================
port                     dir    size       units / frame
=======================  =====  =========  ===========================================
``amplitudes``           in     k          synergy amplitudes (rad-scaled PCA scores)
``joint_command``        in     20         rad, command order (docs/ARCHITECTURE.md)
``fingertip_targets``    in     15         m, positions of the fingertip frames
                                           ``fftip mftip rftip lftip thtip`` in the
                                           palm frame P, stacked ``[x y z] * 5``
``mode``                 in     abstract   optional :class:`ControlMode`; when
                                           connected it overrides the mode state
``position``             out    20         rad, rate-limited command (connect to the
                                           station's ``hand.position``)
``active_mode``          out    abstract   the :class:`ControlMode` in use
=======================  =====  =========  ===========================================

Modes (abstract state, :class:`ControlMode`):

- ``SYNERGY``: target = ``synergies.amplitudes_to_command(amplitudes)``
  (``mean + amplitudes @ components[:k]``, clipped to the joint limits).
- ``JOINT``: target = ``joint_command``.
- ``CARTESIAN``: each update takes one damped least-squares step of the
  fingertips towards ``fingertip_targets`` from the current command (the
  fingertip Jacobians of the Shadow model, J1 folded into J2):
  ``dq = J^T (J J^T + lambda^2 I)^-1 (p_target - p(q))`` per finger, with
  ``|dq|`` capped by the velocity limit. This is the cheap differential-IK
  step the brief asks for, not a full IK solve.

Switching. Call :meth:`SynergyController.set_mode` on a context (between
simulator steps), or connect the ``mode`` input port (a ``Value(ControlMode)``
source, e.g. from a state machine) to switch at run time. The output is the
discrete command state and every update moves it by at most
``max_joint_velocity * period`` per joint, so a mode switch never jumps: the
command ramps from where it is to the new mode's target.

Every output command lies within the command limits of
:func:`handle_drake.base.hands.actuated_position_limits` (which keep each coupled
distal joint ``J1 = ratio * J2`` inside its own limits).
"""

from __future__ import annotations

import enum
import functools

import numpy as np
from pydrake.common.value import AbstractValue, Value
from pydrake.systems.framework import LeafSystem, ValueProducer

from handle_drake.base.hands import (
    actuated_position_limits,
    actuated_to_joint_positions,
    get_hand_spec,
)
from handle_drake.grasp.kinematics import GraspKinematics
from handle_drake.grasp.synergies import Synergies

__all__ = ["ControlMode", "SynergyController"]



class ControlMode(enum.IntEnum):
    JOINT = 0
    CARTESIAN = 1
    SYNERGY = 2


def _mode(value) -> ControlMode:
    if isinstance(value, ControlMode):
        return value
    if isinstance(value, str):
        try:
            return ControlMode[value.strip().upper()]
        except KeyError:
            pass
    elif isinstance(value, int | np.integer) and int(value) in {m.value for m in ControlMode}:
        return ControlMode(int(value))
    raise ValueError(
        f"unknown control mode {value!r}; expected one of "
        f"{', '.join(m.name.lower() for m in ControlMode)}"
    )


class _Scratch:
    """Per-context scratch of the Cartesian mode (lives in the context's cache)."""

    def __init__(self):
        self.plant_context = None


@functools.cache
def _fingertip_kinematics(coupling_ratio: float):
    """The Shadow model's fingertip kinematics (an immutable, finalized plant), built once
    per process and ratio, on the first Cartesian use."""

    return GraspKinematics(coupling_ratio)


class SynergyController(LeafSystem):
    """Synergy / joint / fingertip command with a velocity limit (see module doc).

    Args:
        synergies: a :class:`Synergies` over the 20 Shadow command joints.
        initial_command: (20,) rad; default the synergy mean.
        max_joint_velocity: rad/s (> 0).
        period: s, update period (> 0).
        mode: the initial :class:`ControlMode` (or its name).
        coupling_ratio: J1/J2 ratio of the hand (limits and fingertip kinematics).
        damping: m, the damped least-squares lambda of the Cartesian mode.
    """

    def __init__(self, synergies: Synergies, initial_command=None,
                 max_joint_velocity: float = 2.0, period: float = 0.01,
                 mode=ControlMode.SYNERGY, coupling_ratio: float = 1.0,
                 damping: float = 0.01):
        super().__init__()
        if not isinstance(synergies, Synergies):
            raise TypeError(f"synergies must be a Synergies, got {type(synergies).__name__}")
        spec = get_hand_spec("shadow")
        if tuple(synergies.synergy_joint_names) != tuple(spec.actuated_joint_names):
            raise ValueError(
                "synergies must be fitted over the 20 Shadow command joints in command order "
                f"{spec.actuated_joint_names}, got {synergies.synergy_joint_names}"
            )
        for name, value in (("max_joint_velocity", max_joint_velocity), ("period", period),
                            ("damping", damping)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        self._spec = spec
        self._synergies = synergies
        self._ratio = float(coupling_ratio)
        self._lower, self._upper = actuated_position_limits(spec, self._ratio)
        self._max_step = float(max_joint_velocity) * float(period)
        self._damping = float(damping)
        nu = spec.num_actuated
        if initial_command is None:
            initial_command = synergies.mean
        initial = np.asarray(initial_command, dtype=float)
        if initial.shape != (nu,):
            raise ValueError(f"initial_command: expected shape ({nu},), got {initial.shape}")
        if not np.isfinite(initial).all():
            raise ValueError("initial_command must be finite")
        initial = np.clip(initial, self._lower, self._upper)
        # Scratch of the Cartesian mode, per context (Drake's cache, not the
        # system): a context of the fingertip kinematics' plant, made on first use.
        self._scratch = self.DeclareCacheEntry(
            description="fingertip kinematics scratch",
            value_producer=ValueProducer(allocate=lambda: AbstractValue.Make(_Scratch()),
                                         calc=lambda context, value: None),
            prerequisites_of_calc={self.nothing_ticket()})

        self._amplitudes = self.DeclareVectorInputPort("amplitudes", synergies.k)
        self._joint_command = self.DeclareVectorInputPort("joint_command", nu)
        self._fingertips = self.DeclareVectorInputPort("fingertip_targets", 15)
        self._mode_port = self.DeclareAbstractInputPort("mode", Value(ControlMode.JOINT))
        self._command = self.DeclareDiscreteState(initial)
        self._mode_state = self.DeclareAbstractState(Value(_mode(mode)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self._position = self.DeclareVectorOutputPort(
            "position", nu,
            lambda context, out: out.SetFromVector(context.get_discrete_state(0).value()),
            prerequisites_of_calc={self.discrete_state_ticket(self._command)},
        )
        self.DeclareAbstractOutputPort(
            "active_mode", lambda: Value(ControlMode.JOINT),
            lambda context, out: out.set_value(self.get_mode(context)),
            prerequisites_of_calc={self.abstract_state_ticket(self._mode_state)},
        )

    # ---- accessors -----------------------------------------------------------
    def get_amplitudes_input_port(self):
        return self._amplitudes

    def get_joint_command_input_port(self):
        return self._joint_command

    def get_fingertip_targets_input_port(self):
        return self._fingertips

    def get_mode_input_port(self):
        return self._mode_port

    def get_position_output_port(self):
        return self._position

    @property
    def synergies(self) -> Synergies:
        return self._synergies

    def get_mode(self, context) -> ControlMode:
        return context.get_abstract_state(int(self._mode_state)).get_value()

    def set_mode(self, context, mode) -> None:
        """Switch the mode (``ControlMode`` or "joint" / "cartesian" / "synergy")."""
        context.get_mutable_abstract_state(int(self._mode_state)).set_value(_mode(mode))

    def set_command(self, context, command) -> None:
        """Set the held command (e.g. to the measured position at start-up)."""
        command = np.asarray(command, dtype=float)
        if command.shape != (self._spec.num_actuated,) or not np.isfinite(command).all():
            raise ValueError(
                f"command: expected {self._spec.num_actuated} finite values, got {command.shape}"
            )
        context.get_mutable_discrete_state(0).SetFromVector(
            np.clip(command, self._lower, self._upper))

    # ---- kinematics ----------------------------------------------------------
    def fingertip_positions(self, command) -> np.ndarray:
        """(5, 3) positions (m) of the fingertip frames in the palm frame for a command."""
        kin = _fingertip_kinematics(self._ratio)
        p, _ = self._fingertip_jacobians(kin, kin.plant.CreateDefaultContext(),
                                         np.asarray(command, dtype=float))
        return p

    def _fingertip_jacobians(self, kin, plant_context, command):
        from pydrake.multibody.tree import JacobianWrtVariable

        q = actuated_to_joint_positions(self._spec, command, self._ratio)
        full = kin.plant.GetPositions(plant_context)
        full[kin.q_index] = q
        full[kin._wrist_indices()] = 0.0  # the palm frame is the reference: wrist at rest
        kin.plant.SetPositions(plant_context, full)
        names = self._spec.joint_names
        positions, jacobians = [], []
        for name in kin.spec.fingertip_frames:
            frame = kin.plant.GetFrameByName(name, kin.hand)
            positions.append(frame.CalcPose(plant_context, kin.palm).translation())
            J = kin.plant.CalcJacobianTranslationalVelocity(
                plant_context, JacobianWrtVariable.kQDot, frame, np.zeros(3), kin.palm,
                kin.palm)
            J = J[:, kin.q_index]
            # Chain rule through the coupling q_J1 = ratio * q_J2: d/dJ2 += ratio * d/dJ1.
            Ja = np.zeros((3, self._spec.num_actuated))
            for i, name in enumerate(self._spec.actuated_joint_names):
                Ja[:, i] = J[:, names.index(name)]
                if name[:2] in ("FF", "MF", "RF", "LF") and name.endswith("J2"):
                    Ja[:, i] += self._ratio * J[:, names.index(name[:-1] + "1")]
            jacobians.append(Ja)
        return np.array(positions), jacobians

    def _cartesian_target(self, context, current):
        targets = self._fingertips.Eval(context).reshape(5, 3)
        if not np.isfinite(targets).all():
            return current
        kin = _fingertip_kinematics(self._ratio)
        scratch = self._scratch.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()
        if scratch.plant_context is None:
            scratch.plant_context = kin.plant.CreateDefaultContext()
        positions, jacobians = self._fingertip_jacobians(kin, scratch.plant_context, current)
        dq = np.zeros_like(current)
        lam2 = self._damping**2
        for p, J, target in zip(positions, jacobians, targets, strict=True):
            cols = np.nonzero(np.any(J != 0.0, axis=0))[0]  # this finger's joints
            Jf = J[:, cols]
            dq[cols] += Jf.T @ np.linalg.solve(Jf @ Jf.T + lam2 * np.eye(3), target - p)
        return current + dq

    # ---- update ----------------------------------------------------------------
    def _update(self, context, state):
        current = context.get_discrete_state(0).value().copy()
        mode = self.get_mode(context)
        if self._mode_port.HasValue(context):
            mode = _mode(self._mode_port.Eval(context))
            state.get_mutable_abstract_state(int(self._mode_state)).set_value(mode)
        target = current
        if mode is ControlMode.SYNERGY and self._amplitudes.HasValue(context):
            a = self._amplitudes.Eval(context)
            if np.isfinite(a).all():
                target = self._synergies.amplitudes_to_command(a)
        elif mode is ControlMode.JOINT and self._joint_command.HasValue(context):
            q = self._joint_command.Eval(context)
            if np.isfinite(q).all():
                target = q
        elif mode is ControlMode.CARTESIAN and self._fingertips.HasValue(context):
            target = self._cartesian_target(context, current)
        target = np.clip(target, self._lower, self._upper)
        step = np.clip(target - current, -self._max_step, self._max_step)
        state.get_mutable_discrete_state().set_value(0, current + step)
