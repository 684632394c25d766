"""An object's turn about its own axis, from what the hand senses (never the plant's state).

The pose estimator (:mod:`.estimator`) fits the object's signed distance to the contacts: a
cylinder's turn about its own axis leaves that distance unchanged, so the turn of a cap or
a cylinder is not in it. Two sensed sources give it instead:

- :class:`ContactTurn` (touch and joints): the hand's joint positions (forward kinematics of
  the pads on a plant of the hand alone) and the taxels' contact patches
  (:func:`~.estimator.pad_contacts`). Between two readings, the pad's material point under
  each contact moves with the pad; a contact that sticks (rolling without slip) moves the
  object's surface with it, so that point's angular displacement about the object's axis is
  the object's turn. A pad counts when it touches at both readings and its centre of
  pressure lies on the object's surface (within ``surface_tolerance`` of the radius, within
  the length); the turn's increment is the force-weighted mean over those pads
  (``combine="mean"``), or their median. The axis: given (the cap's, on its thread: the
  task's setup), or for a free object refitted at every reading to the contacts on a
  circle of the known radius (a prior the last centre within ``centre_std``).
- :class:`GravityTurn` (the object's accelerometer): about a horizontal axis the gravity
  direction in the sensor frame turns by minus the object's turn, so the angle of the
  specific force in the plane across the axis, unwrapped, is the turn (exact at rest; the
  sensor on the axis feels no centripetal part).

Both are plain Python (a trial reads the station's ports and calls ``update``).
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, DiscreteContactApproximation
from pydrake.systems.framework import DiagramBuilder
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from handle_drake.base.hands import AddHand, get_hand_spec
from handle_drake.devices.taxels.estimator import pad_contacts
from handle_drake.devices.taxels.pads import Pad

__all__ = ["ContactTurn", "GravityTurn", "COMBINES"]

COMBINES = ("mean", "median")


class ContactTurn:
    """The turn (rad, about ``axis_B``) of a cylinder of ``radius`` touched by ``pads``.

    Args:
        hand_kind, coupling_ratio: the hand (a plant of it alone gives the pads' poses).
        pads: the taxel pads of the station's ``hand.taxels`` (their order).
        centre_B, axis_B: a point on the object's axis and its direction in the hand base
            frame B (the turn counts positive about ``axis_B``).
        radius, length: the object's (m).
        free: the axis moves with the object (refitted at every reading).
    """

    def __init__(self, hand_kind: str, coupling_ratio, pads: list[Pad], centre_B, axis_B,
                 radius: float, length: float, free: bool = False,
                 contact_threshold: float = 0.2, surface_tolerance: float = 0.004,
                 centre_std: float = 0.002, combine: str = "mean", min_lever: float = 0.3,
                 R_BO=None, ridge: float = 0.05, up_B=None, gravity_weight: float = 1.0,
                 rest_tolerance: float = 0.1):
        if combine not in COMBINES:
            raise ValueError(f"combine: expected one of {COMBINES}, got {combine!r}")
        axis = np.asarray(axis_B, float)
        if axis.shape != (3,) or not np.linalg.norm(axis) > 0:
            raise ValueError(f"axis_B: expected a non-zero 3-vector, got {axis_B!r}")
        if not (radius > 0 and length > 0):
            raise ValueError(f"radius, length: expected values > 0 m, got {radius!r}, "
                             f"{length!r}")
        self._axis = axis / np.linalg.norm(axis)
        self._centre0 = np.asarray(centre_B, float).reshape(3)
        self._radius, self._length, self._free = float(radius), float(length), bool(free)
        self._threshold, self._tol = float(contact_threshold), float(surface_tolerance)
        self._centre_std, self._combine = float(centre_std), combine
        self._min_lever, self._ridge = float(min_lever), float(ridge)
        self._axis0 = self._axis.copy()
        self._up_B = None if up_B is None else np.asarray(up_B, float).reshape(3)
        self._gravity_weight, self._rest = float(gravity_weight), float(rest_tolerance)
        self._R_BO = np.eye(3) if R_BO is None else np.asarray(
            R_BO.matrix() if hasattr(R_BO, "matrix") else R_BO, float).reshape(3, 3)
        # the turn counts about +z of the object's frame, or -z
        self._sign = 1.0 if self._axis @ self._R_BO[:, 2] >= 0 else -1.0
        if free and R_BO is None:
            raise ValueError("R_BO: a free object's initial orientation in B is needed")
        self._pads = list(pads)
        self._offsets = np.cumsum([0] + [p.cells for p in self._pads])
        spec = get_hand_spec(hand_kind)
        builder = DiagramBuilder()
        self._plant, _ = AddMultibodyPlantSceneGraph(builder, 0.001)
        self._plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
        hand = AddHand(self._plant, hand_kind, coupling_ratio=coupling_ratio)
        self._plant.WeldFrames(self._plant.world_frame(),
                               self._plant.GetBodyByName(spec.base_body, hand).body_frame())
        self._plant.Finalize()
        self._diagram = builder.Build()
        self._context = self._plant.GetMyContextFromRoot(self._diagram.CreateDefaultContext())
        self._q_index = np.array([self._plant.GetJointByName(n, hand).position_start()
                                  for n in spec.joint_names], dtype=int)
        self._q0 = self._plant.GetPositions(self._context)
        self._bodies = [self._plant.GetBodyByName(p.body_name, hand) for p in self._pads]
        self.reset()

    def reset(self) -> None:
        """Turn 0, the axis at its given place, no previous reading."""
        self.turn = 0.0
        self.centre = self._centre0.copy()
        self._axis = self._axis0.copy()
        self._R, self._raw = np.eye(3), 0.0
        self._previous = None  # per pad: (X_BP, contact points (k, 3), forces (k,))
        self.touching: list[str] = []
        self.on_object: dict[str, float] = {}
        self.forces: dict[str, float] = {}
        self.contacts: list = []  # per pad: (X_BP, contact points (k, 3) in B, forces (k,))

    @property
    def pads(self) -> list[Pad]:
        return list(self._pads)

    def pad_poses(self, q) -> list[RigidTransform]:
        """``X_BP`` of every pad at hand joint positions ``q`` (forward kinematics)."""
        full = self._q0.copy()
        full[self._q_index] = np.asarray(q, float)
        self._plant.SetPositions(self._context, full)
        return [self._plant.EvalBodyPoseInWorld(self._context, b) @ p.X_BP
                for b, p in zip(self._bodies, self._pads, strict=True)]

    def _on_object(self, points: np.ndarray, side: bool = False) -> np.ndarray:
        """Which contact points lie on the object: within its radius (``side``: on its
        side, within ``surface_tolerance`` of the radius), at least ``min_lever`` of it
        from the axis, and (on a thread: a bottle is near) within its length."""
        rel = points - self.centre
        along = rel @ self._axis
        across = np.linalg.norm(rel - np.outer(along, self._axis), axis=1)
        if self._free and not side:  # a free object turns about any axis: within its bounds
            return np.linalg.norm(rel, axis=1) <= np.hypot(self._radius, self._length / 2) \
                + self._tol
        ok = (across <= self._radius + self._tol) & (across >= self._min_lever * self._radius)
        if side:
            ok &= np.abs(across - self._radius) <= self._tol
        return ok if self._free else ok & (np.abs(along) <= self._length / 2 + self._tol)

    def _refit_centre(self, points: np.ndarray) -> None:
        """A free object's axis: through the contacts' circle of the known radius."""
        a = self._axis

        e1 = np.cross(np.eye(3)[int(np.argmin(np.abs(a)))], a)
        e1 /= np.linalg.norm(e1)
        plane = np.column_stack([e1, np.cross(a, e1)])  # the axis moves across itself

        def residuals(m):
            rel = points - (self.centre + plane @ m)
            rel -= np.outer(rel @ a, a)
            # the radius within 1 mm, the centre's move within centre_std
            return np.r_[(np.linalg.norm(rel, axis=1) - self._radius) / 1e-3,
                         m / self._centre_std]

        if len(points) >= 2:
            self.centre = self.centre + plane @ least_squares(residuals, np.zeros(2)).x

    def update(self, q, taxels, f_S=None) -> float:
        """One reading (joint positions ``q``, taxels in Pa; a free object's accelerometer
        ``f_S``, m/s^2, the sensor's axes the object's, or None): the turn so far (rad)."""
        X_BPads = self.pad_poses(q)
        taxels = np.asarray(taxels, float)
        current = []
        for i, (pad, X_BP) in enumerate(zip(self._pads, X_BPads, strict=True)):
            points, _, forces = pad_contacts([pad], taxels[self._offsets[i]:self._offsets[
                i + 1]], [X_BP], self._threshold)
            current.append((X_BP, points, forces))
        self.contacts = current
        self.touching = [p.name for p, (_, pts, _) in zip(self._pads, current, strict=True)
                         if len(pts)]
        self.forces = {p.name: float(f.sum()) for p, (_, _, f) in zip(
            self._pads, current, strict=True) if len(f)}
        # per pad its force (N) on the object: its contacts within the object's bounds
        self.on_object = {p.name: float(f[self._on_object(pts, side=True)].sum())
                          for p, (_, pts, f) in zip(self._pads, current, strict=True)
                          if len(pts) and self._on_object(pts, side=True).any()}
        pairs = self._pairs(current) if self._previous is not None else []
        if self._free:
            self._rigid_step(pairs, self._up_measured(f_S))
            allpoints = np.concatenate([pts for _, pts, _ in current])
            side = self._on_object(allpoints, side=True)
            if side.sum() >= 2:
                self._refit_centre(allpoints[side])
        elif pairs:
            self._axis_step(pairs)
        self._previous = current
        return self.turn

    def _pairs(self, current) -> list:
        """Per pad touching at both readings: its contacts on the object at the last
        reading ``c`` (k, 3), where the pad's material points there are now, and weights
        (the force)."""
        pairs = []
        for (X_prev, p_prev, f_prev), (X_now, p_now, f_now) in zip(
                self._previous, current, strict=True):
            if not len(p_prev) or not len(p_now):
                continue
            ok = self._on_object(p_prev)
            if ok.any():
                c = p_prev[ok]
                pairs.append((c, (X_now @ X_prev.inverse()).multiply(c.T).T,
                              np.minimum(f_prev[ok], f_now.sum())))
        return pairs

    def _axis_step(self, pairs) -> None:
        """The object on a fixed axis: each sticking contact's angular displacement about
        it, combined (``combine``)."""
        c = np.concatenate([p[0] for p in pairs])
        moved = np.concatenate([p[1] for p in pairs])
        weights = np.concatenate([p[2] for p in pairs])
        lever = c - self.centre
        lever -= np.outer(lever @ self._axis, self._axis)
        steps = np.cross(lever, moved - c) @ self._axis / np.maximum(
            np.sum(lever ** 2, axis=1), 1e-12)
        self.turn += float(np.average(steps, weights=weights)
                           if self._combine == "mean" else np.median(steps))

    def _up_measured(self, f_S):
        """The up direction in the object frame from a reading near 1 g (else None)."""
        if f_S is None or self._up_B is None:
            return None
        f = np.asarray(f_S, float).reshape(3)
        g = np.linalg.norm(f)
        return f / g if abs(g / 9.81 - 1.0) <= self._rest else None

    def _rigid_step(self, pairs, up_O=None) -> None:
        """A free object: the rigid motion (twist about the centre) that moves the
        sticking contacts as the pads moved them (robust least squares: a sliding pad
        is an outlier; a small penalty on the rotation fixes the turn about the line of
        two contacts), integrated; the turn is its rotation about the object's initial
        axis read as the task reads the plant's (``R_BO``)."""
        if sum(len(p[0]) for p in pairs) >= 2 or up_O is not None:
            c = np.concatenate([p[0] for p in pairs] or [np.zeros((0, 3))])
            d = np.concatenate([p[1] for p in pairs] or [np.zeros((0, 3))]) - c
            w = np.sqrt(np.concatenate([p[2] for p in pairs] or [np.zeros(0)]))
            r = c - self.centre
            scale = self._radius * max(float(np.sqrt(np.sum(w ** 2))), 1.0)
            R_O = self._R @ self._R_BO

            def residuals(x):
                res = [((x[:3] + np.cross(x[3:], r) - d) * w[:, None]).ravel(),
                       self._ridge * scale * x[3:]]
                if up_O is not None:  # the accelerometer: up in the object frame
                    R = Rotation.from_rotvec(x[3:]).as_matrix() @ R_O
                    res.append(self._gravity_weight * scale * (R.T @ self._up_B - up_O))
                return np.concatenate(res)

            x = least_squares(residuals, np.zeros(6), loss="soft_l1",
                              f_scale=5e-4 * float(np.mean(w)) if len(w) else 1e-3).x
            self._R = Rotation.from_rotvec(x[3:]).as_matrix() @ self._R
            self.centre = self.centre + x[:3]
            self._axis = self._R @ self._axis0
        M = self._R_BO.T @ self._R @ self._R_BO
        raw = self._sign * float(np.arctan2(M[1, 0], M[0, 0]))
        self.turn += (raw - self._raw + np.pi) % (2 * np.pi) - np.pi
        self._raw = raw


class GravityTurn:
    """The turn (rad) about ``axis_S`` (the sensor frame; horizontal in world) from the
    accelerometer's specific force: minus the unwrapped angle of the force across the
    axis. Readings under ``min_across`` of g across the axis (the axis near vertical) are
    skipped, and so are readings off 1 g by more than ``rest_tolerance`` (g): the object
    accelerating (a pinched cylinder shaken by the fingers) is not at rest."""

    def __init__(self, axis_S=(0.0, 0.0, 1.0), min_across: float = 0.3,
                 rest_tolerance: float = 0.1, window: int = 1):
        a = np.asarray(axis_S, float)
        if a.shape != (3,) or not np.linalg.norm(a) > 0:
            raise ValueError(f"axis_S: expected a non-zero 3-vector, got {axis_S!r}")
        self._a = a / np.linalg.norm(a)
        helper = np.eye(3)[int(np.argmin(np.abs(self._a)))]
        self._e1 = np.cross(helper, self._a)
        self._e1 /= np.linalg.norm(self._e1)
        self._e2 = np.cross(self._a, self._e1)
        self._min, self._rest = float(min_across), float(rest_tolerance)
        self._window = int(window)
        self.reset()

    def reset(self) -> None:
        self.turn = 0.0
        self._phi = None
        self._recent = []

    def update(self, f_S) -> float:
        # the mean of the last ``window`` readings (a contact's vibration averages out)
        self._recent = [*self._recent, np.asarray(f_S, float).reshape(3)][-self._window:]
        f = np.mean(self._recent, axis=0)
        x, y = f @ self._e1, f @ self._e2
        if np.hypot(x, y) < self._min * 9.81 \
                or abs(np.linalg.norm(f) / 9.81 - 1.0) > self._rest:
            return self.turn
        phi = float(np.arctan2(y, x))
        if self._phi is not None:
            self.turn -= (phi - self._phi + np.pi) % (2 * np.pi) - np.pi
        self._phi = phi
        return self.turn
