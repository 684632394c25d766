"""What the CAN side needs to know about a hand: sizes, limits, couplings, fingers.

:class:`HandLayout` is a plain, picklable summary of a
:class:`handle_drake.base.hands.HandSpec` (joint order of ``hand.position_measured``,
command order of ``hand.position``, coupled joints, limits). The codec, the
bus server, the simulated firmware and the proxy driver all take a layout, so
none of them parses a model file on the hot path, and tests can build a layout
from literal numbers.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np

from handle_drake.base.hands import HandSpec, actuated_position_limits, get_hand_spec

__all__ = ["HAND_KIND_CODES", "HandLayout", "hand_layout"]

# The STATUS frame's KIND nibble (declared in hand.dbc).
HAND_KIND_CODES = {"shadow": 1, "barrett": 2}

def _vector(name: str, value, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name}: expected {size} values, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, got {array.tolist()}")
    array = array.copy()
    array.setflags(write=False)
    return array


@dc.dataclass(frozen=True, eq=False)
class HandLayout:
    """Sizes, order, limits and couplings of one hand, as the CAN interface sees it.

    Attributes:
        kind: "shadow" or "barrett".
        joint_names: all joints (nq), order of ``hand.position_measured``.
        actuated_joint_names: command vector (nu), order of ``hand.position``.
        couplings: ``(follower, leader, ratio)``: ``q_follower = ratio * q_leader``.
        command_lower, command_upper: limits (rad) of each command entry such
            that leader and follower stay within their joint limits.
        joint_lower, joint_upper: limits (rad) of every joint.
        closing_joints: per tactile pad (fingertip order), the actuated joints
            that press that fingertip onto an object.
    """

    kind: str
    joint_names: tuple[str, ...]
    actuated_joint_names: tuple[str, ...]
    couplings: tuple[tuple[str, str, float], ...]
    command_lower: np.ndarray
    command_upper: np.ndarray
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    closing_joints: tuple[tuple[str, ...], ...]

    def __post_init__(self):
        if self.kind not in HAND_KIND_CODES:
            raise ValueError(f"kind: expected one of {sorted(HAND_KIND_CODES)}, got {self.kind!r}")
        nq, nu = len(self.joint_names), len(self.actuated_joint_names)
        missing = [n for n in self.actuated_joint_names if n not in self.joint_names]
        if missing:
            raise ValueError(f"actuated_joint_names: {missing} are not in joint_names")
        object.__setattr__(self, "command_lower", _vector("command_lower", self.command_lower, nu))
        object.__setattr__(self, "command_upper", _vector("command_upper", self.command_upper, nu))
        object.__setattr__(self, "joint_lower", _vector("joint_lower", self.joint_lower, nq))
        object.__setattr__(self, "joint_upper", _vector("joint_upper", self.joint_upper, nq))
        if np.any(self.command_lower > self.command_upper):
            raise ValueError("command_lower must not exceed command_upper")
        for follower, leader, _ in self.couplings:
            if follower not in self.joint_names or leader not in self.actuated_joint_names:
                raise ValueError(f"coupling ({follower}, {leader}): unknown or unactuated joint")
        for pad in self.closing_joints:
            for name in pad:
                if name not in self.actuated_joint_names:
                    raise ValueError(f"closing joint {name!r} is not an actuated joint")

    @property
    def nq(self) -> int:
        return len(self.joint_names)

    @property
    def nu(self) -> int:
        return len(self.actuated_joint_names)

    @property
    def num_tactile(self) -> int:
        return len(self.closing_joints)

    @property
    def kind_code(self) -> int:
        return HAND_KIND_CODES[self.kind]

    def actuated_indices(self) -> np.ndarray:
        """Index into the joint vector of each command entry."""
        return np.array([self.joint_names.index(n) for n in self.actuated_joint_names], dtype=int)

    def joint_positions(self, q_actuated) -> np.ndarray:
        """All joints (nq) from a command-ordered vector (nu), followers coupled."""
        q_actuated = np.asarray(q_actuated, dtype=float)
        if q_actuated.shape != (self.nu,):
            raise ValueError(f"q_actuated: expected {self.nu} values, got shape {q_actuated.shape}")
        value = dict(zip(self.actuated_joint_names, q_actuated, strict=True))
        for follower, leader, ratio in self.couplings:
            value[follower] = ratio * value[leader]
        return np.array([value.get(name, 0.0) for name in self.joint_names])

    def actuated_positions(self, q) -> np.ndarray:
        """The command entries (nu) of a joint vector (nq)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise ValueError(f"q: expected {self.nq} values, got shape {q.shape}")
        return q[self.actuated_indices()]


def hand_layout(kind_or_spec, coupling_ratio: float | None = None) -> HandLayout:
    """The :class:`HandLayout` of a hand kind ("shadow", "barrett") or a ``HandSpec``.

    ``coupling_ratio`` replaces the adjustable couplings (Shadow ``xFJ1 =
    ratio * xFJ2``: 1.0 for the C6 hand, 1.1 for the C5 hand). Limits are
    read from the hand's model file through :mod:`handle_drake.base.hands`.
    """

    if isinstance(kind_or_spec, str):
        spec = get_hand_spec(kind_or_spec)
    elif isinstance(kind_or_spec, HandSpec):
        spec = kind_or_spec
    else:
        raise TypeError(
            f"expected a hand kind (str) or a HandSpec, got {type(kind_or_spec).__name__}"
        )
    lower, upper = actuated_position_limits(spec, coupling_ratio)
    return HandLayout(
        kind=spec.name,
        joint_names=tuple(spec.joint_names),
        actuated_joint_names=tuple(spec.actuated_joint_names),
        couplings=tuple(spec.coupling_ratios(coupling_ratio)),
        command_lower=lower,
        command_upper=upper,
        joint_lower=spec.joint_lower_limits,
        joint_upper=spec.joint_upper_limits,
        closing_joints=spec.closing_joints,
    )
