"""ReactiveGrasp: the reactive approach and tactile grasp of report section 3.3.

The report's two-level scheme: during the approach, while the fingers are
still in the pre-shape, any fingertip contact is *unexpected*; the hand is
slowed down and shifted sideways to compensate for an error in the estimated
object position or size, and stopped completely when several fingers touch
(an undetected obstacle). Then the fingers close towards the object, each one
stopping at its own first tactile contact, until every finger of the grasp
class touches; finally all of them close a further increment (the squeeze)
and the hand lifts.

Ports (``n`` tactile channels, one per finger; ``nu`` hand commands):

=========================  =====  ===========================  ====================================
port                       dir    size                         units / frame
=========================  =====  ===========================  ====================================
``tactile``                in     n                            N, fingertip normal forces (the
                                                               station's ``hand.tactile``)
``wrist_pose_measured``    in     6                            ``[x y z roll pitch yaw]`` of the
                                                               hand base in world, m and rad
``contact_results``        in     abstract ``ContactResults``  optional (with ``hand_bodies``):
                                                               the side-shift direction; other
                                                               hand bodies' contacts slow down
``taxels``                 in     cells                        optional (with ``taxel_pads``): Pa,
                                                               the station's ``hand.taxels``
``body_poses``             in     abstract ``X_WB`` list        optional (with ``taxel_pads``): the
                                                               pads' bodies (station ``body_poses``)
``wrist_pose``             out    6                            same convention, the commanded base
                                                               pose (station's ``wrist.pose``)
``hand_position``          out    nu                           rad, hand command (``hand.position``)
``mode``                   out    1                            :class:`ReactiveGraspMode` value
``closing``                out    n                            closing fraction of each finger
=========================  =====  ===========================  ====================================

All outputs are read from the discrete/abstract state (no direct feedthrough),
so the measured pose may be fed back from the station without an algebraic loop.

Modes (abstract state, :class:`ReactiveGraspMode`):

- ``APPROACH``: the commanded wrist position moves from ``start_pose6`` to
  ``goal_pose6`` along the straight line at ``approach_speed`` (orientation
  interpolated in roll/pitch/yaw with the travel), fingers in the pre-shape.
- ``SLOW_APPROACH``: entered at the first unexpected contact (one fingertip
  over ``contact_threshold`` or, with ``contact_results``, any other hand
  body touching something other than the hand). The approach speed is multiplied by ``slow_factor``;
  while a contact persists the approach line is shifted sideways (normal to
  the approach) at ``shift_speed`` up to ``max_shift``, in the direction that
  separates the hand from the contact: the contact normal into the hand
  (from ``contact_results``) or, without it, the finger's outward direction
  ``finger_directions_B[i]`` (hand base frame). No direction known: no shift.
- ``STOPPED`` (terminal): ``multiple_contacts`` or more fingertips touch
  during the approach (the report: "multiple unexpected fingertip contacts";
  other hand bodies only slow the approach down); the wrist is
  held at its measured position along the approach, the fingers in the pre-shape.
- ``CLOSE``: the approach has arrived (travel complete and the measured
  position within ``arrival_tolerance`` of the command, or ``arrival_timeout``
  later). Finger ``i``'s command is ``preshape + s_i (closed - preshape)`` on
  its joints; ``s_i`` grows at ``close_rate`` (1/s) until its fingertip force
  exceeds ``contact_threshold`` (it then stays where it was) or it reaches
  ``max_closing``. Optionally (``close_shift_speed`` > 0; off by default,
  see the parameter) while some grasp fingers touch and others do not, the
  wrist shifts sideways at ``close_shift_speed`` (up to ``max_close_shift``)
  along the contact normals into the hand: the hand centres itself on an
  object that is not where the plan put it, bringing the open fingers to it,
  instead of the first finger shoving it towards the others (which is what
  the open-loop close does). With ``taxel_pads`` and ``cop_shift_gain`` > 0
  (off by default) the close centres the hand on the pads' centres of pressure
  instead: while some grasp fingers touch and others do not, the wrist moves at
  ``cop_shift_gain`` times the mean offset (world) of the touching grasp
  fingers' pad centres of pressure from their pad centres (:meth:`ReactiveGrasp.
  cop_offset`), horizontal and across the approach, at most ``shift_speed``,
  up to ``max_cop_shift``: an object met off the pads' centre lines (which no
  fingertip force tells) is brought between the pads before the others close;
  with ``cop_hold_above`` > 0 those wait while the offset is larger than it.
- ``RECENTRE`` (with ``planned_object`` and ``max_recentres`` > 0; off by
  default, see the parameter): the first grasp finger to touch the object in
  the close locates it from its contact point and normal
  (:meth:`ObjectEstimate.displacement`: a sphere's centre lies one radius
  behind the contact along the normal, a cylinder's axis likewise, a box's
  face only along the normal). If the object is more than
  ``recentre_threshold`` from where the plan put it (horizontally: it rests
  on the table), the fingers undo ``recentre_reopen`` of their closing (at
  twice ``close_rate``), the wrist shifts by that displacement (up to
  ``max_recentre``) at ``shift_speed``, and the close goes on, now about the
  object. The closing fingers alone cannot correct an error across their
  closing direction: on a round object they meet it off its centre line and
  the squeeze pushes it out sideways.
- ``SQUEEZE``: every grasp finger touches (or is at ``max_closing``): each
  grasp finger's ``s_i`` ramps by ``squeeze`` over ``squeeze_time``.
- ``LIFT``: ``hold_time`` after the squeeze, the wrist rises ``lift_height``
  at ``lift_speed`` and holds there.

The closing fraction is the position-control analogue of a grip force: with
PD-controlled joints, the squeeze past the contact sets how hard a finger presses.
"""

from __future__ import annotations

import dataclasses as dc
import enum

import numpy as np
from pydrake.common.containers import namedview
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import LeafSystem

from handle_drake.base.hands import get_hand_spec, pad_surface_point

__all__ = ["ObjectEstimate", "ReactiveGrasp", "ReactiveGraspMode", "ReactiveGraspParams",
           "ReactiveGraspProgress", "TaxelPadLayout", "finger_command_groups"]


#: The controller's progress (discrete state): travel along the approach (m),
#: sideways shift x y z (m), lift (m), when the mode was entered and when the
#: approach reached its full travel (s; inf before); the re-centring's target
#: shift x y z (m), how many re-centrings ran, and when the last one's shift
#: was complete (s; inf before).
ReactiveGraspProgress = namedview("ReactiveGraspProgress", [
    "travel", "shift_x", "shift_y", "shift_z", "lift", "mode_entry_time", "arrival_time",
    "target_x", "target_y", "target_z", "recentres", "recentred_time"])


class ReactiveGraspMode(enum.IntEnum):
    APPROACH = 0
    SLOW_APPROACH = 1
    STOPPED = 2
    CLOSE = 3
    SQUEEZE = 4
    LIFT = 5
    RECENTRE = 6


class ObjectEstimate:
    """Where the plan thinks the object is, in world, and its shape: what one touch
    tells about where it really is (:meth:`displacement`).

    Args:
        kind: ``"sphere"``, ``"cylinder"`` or ``"box"``.
        X_WO: the planned pose (a ``RigidTransform``): the centre, and for a
            cylinder its axis (``z_O``), for a box its faces (``O``'s axes).
        radius: sphere or cylinder radius (m).
        half_extents: box half edges along ``x_O y_O z_O`` (m).
    """

    KINDS = ("sphere", "cylinder", "box")

    def __init__(self, kind: str, X_WO, radius: float | None = None, half_extents=None):
        if kind not in self.KINDS:
            raise ValueError(f"ObjectEstimate kind must be one of {self.KINDS}, got {kind!r}")
        self.kind = kind
        self.centre_W = np.asarray(X_WO.translation(), dtype=float).copy()
        self.R_WO = np.asarray(X_WO.rotation().matrix(), dtype=float).copy()
        if kind in ("sphere", "cylinder"):
            if radius is None or not (np.isfinite(radius) and radius > 0):
                raise ValueError(f"ObjectEstimate: a {kind} needs a radius > 0 (m), got {radius}")
            self.radius = float(radius)
        else:
            h = None if half_extents is None else np.asarray(half_extents, dtype=float)
            if h is None or h.shape != (3,) or not (np.isfinite(h).all() and (h > 0).all()):
                raise ValueError("ObjectEstimate: a box needs 3 half extents > 0 (m), got "
                                 f"{half_extents}")
            self.half_extents = h

    def displacement(self, p_W, n_W) -> np.ndarray:
        """(3,) how far (m, world) the object is from its planned pose, from one contact:
        ``p_W`` the contact point, ``n_W`` the object's outward surface normal there.

        Sphere: the centre is ``p - r n``; cylinder: the axis is ``r`` behind
        the contact across it (nothing known along it; a touch on or near an
        end face says nothing); box: the touched face
        (the one whose normal is nearest ``n``) is this far along its normal
        from where it was planned (nothing known along the face)."""
        p = np.asarray(p_W, dtype=float)
        n = np.asarray(n_W, dtype=float)
        n = n / np.linalg.norm(n)
        if self.kind == "sphere":
            return p - self.radius * n - self.centre_W
        if self.kind == "cylinder":
            a = self.R_WO[:, 2]
            across = n - (n @ a) * a
            norm = np.linalg.norm(across)
            if norm < 0.5:  # on or near an end face: nothing said across the axis
                return np.zeros(3)
            d = p - self.radius * across / norm - self.centre_W
            return d - (d @ a) * a
        p_O = self.R_WO.T @ (p - self.centre_W)
        n_O = self.R_WO.T @ n
        k = int(np.argmax(np.abs(n_O)))
        sign = float(np.sign(n_O[k]))
        return (sign * p_O[k] - self.half_extents[k]) * sign * self.R_WO[:, k]


@dc.dataclass
class ReactiveGraspParams:
    """Numeric parameters of :class:`ReactiveGrasp` (SI units)."""

    approach_speed: float = 0.12  # m/s, wrist speed along the approach
    slow_factor: float = 0.25  # approach speed multiplier after an unexpected contact
    shift_speed: float = 0.05  # m/s, sideways shift while an unexpected contact persists
    max_shift: float = 0.015  # m, largest sideways shift
    multiple_contacts: int = 2  # this many touching fingertips in the approach: stop
    contact_threshold: float = 0.2  # N, fingertip force that counts as contact
    close_rate: float = 1.0  # 1/s, closing fraction per second
    max_closing: float = 1.0  # closing fraction at which a finger without contact stops
    squeeze: float = 0.45  # closing fraction added after all grasp fingers touch
    squeeze_time: float = 0.2  # s
    hold_time: float = 0.2  # s, after the squeeze, before the lift
    lift_height: float = 0.13  # m
    lift_speed: float = 0.2  # m/s
    arrival_tolerance: float = 0.004  # m, measured vs commanded wrist position on arrival
    arrival_timeout: float = 0.3  # s, close anyway this long after the travel is complete
    # m/s, sideways wrist shift while only some grasp fingers touch (0: off). Off by
    # default: at a 20 mm position error it held 39/96 grasps with or without it
    # (bench_grasp_classes --reactive close_shift_speed=0.03), and it let the
    # object of the 20 mm compensation test drift 5.0 mm instead of 2.8.
    close_shift_speed: float = 0.0
    max_close_shift: float = 0.015  # m, largest shift in the close (on top of the approach's)
    # Re-centring on the object located by the first touch of the close (needs a
    # planned_object): this many times at most (0: off), when the object is more
    # than recentre_threshold from the plan, by at most max_recentre. Off by
    # default: at a 10 mm position error it held 68/96 grasps reopening the
    # fingers first (recentre_reopen=1) and 67/96 without (0), against 68/96 off
    # (bench_grasp_classes --offset 10 --sizes 3 --reactive max_recentres=1): it
    # saves the pinches of a sphere met off its centre line (a tip pinch on a
    # 22.5 mm ball, both directions), and loses as many balls that the first
    # touch set rolling, which no contact model here slows down.
    max_recentres: int = 0
    recentre_threshold: float = 0.003  # m
    max_recentre: float = 0.025  # m
    recentre_reopen: float = 0.0  # share of each finger's closing undone before the shift
    # 1/s, the close's centring on the pads' centres of pressure (needs taxel_pads; 0: off,
    # the default, so results without taxels are unchanged); at most max_cop_shift (m) on
    # top of the approach's shift
    cop_shift_gain: float = 0.0
    max_cop_shift: float = 0.015
    # N, a pad's force (cells over their noise floor) from which its centre of pressure
    # counts: less than contact_threshold, as a fingertip pressed at its tip, beyond
    # the grid, leaves only a fraction of its force on the border cells
    cop_min_force: float = 0.05
    # m: while the centring's offset is above this (and its shift under its cap), the
    # grasp fingers that do not touch yet wait (0: they close on meanwhile)
    cop_hold_above: float = 0.0

    def validate(self) -> None:
        for f in dc.fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value):
                raise ValueError(f"ReactiveGraspParams.{f.name} must be finite, got {value}")
        positive = ("approach_speed", "slow_factor", "close_rate", "max_closing",
                    "squeeze_time", "lift_speed", "arrival_tolerance")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"ReactiveGraspParams.{name} must be > 0, "
                                 f"got {getattr(self, name)}")
        for name in ("shift_speed", "max_shift", "contact_threshold", "squeeze", "hold_time",
                     "lift_height", "arrival_timeout", "close_shift_speed", "max_close_shift",
                     "recentre_threshold", "max_recentre", "recentre_reopen", "cop_shift_gain",
                     "max_cop_shift", "cop_min_force", "cop_hold_above"):
            if getattr(self, name) < 0:
                raise ValueError(f"ReactiveGraspParams.{name} must be >= 0, "
                                 f"got {getattr(self, name)}")
        if self.recentre_reopen > 1:
            raise ValueError("ReactiveGraspParams.recentre_reopen must be in [0, 1], "
                             f"got {self.recentre_reopen}")
        if self.slow_factor > 1:
            raise ValueError("ReactiveGraspParams.slow_factor must be in (0, 1], "
                             f"got {self.slow_factor}")
        if int(self.multiple_contacts) != self.multiple_contacts or self.multiple_contacts < 1:
            raise ValueError("ReactiveGraspParams.multiple_contacts must be an integer >= 1, "
                             f"got {self.multiple_contacts}")
        if int(self.max_recentres) != self.max_recentres or self.max_recentres < 0:
            raise ValueError("ReactiveGraspParams.max_recentres must be an integer >= 0, "
                             f"got {self.max_recentres}")


def _capped(shift: np.ndarray, cap: float) -> np.ndarray:
    """``shift`` scaled down to length ``cap`` if it is longer."""
    norm = np.linalg.norm(shift)
    return shift * (cap / norm) if norm > cap else shift


@dc.dataclass(frozen=True)
class TaxelPadLayout:
    """One finger's taxel pad as the centring on the centre of pressure reads it (the
    taxel device's ``Pad`` in plain numbers; ``systems`` does not import ``devices``).

    Attributes:
        start: index of the pad's first cell in the ``taxels`` vector.
        cell_centres: (cells, 2) ``(u, v)`` of each cell in the pad frame P (m): ``u``
            across the pad (P's x), ``v`` along it (P's y).
        cell_area: m^2 of one cell.
        body_index: the pad's body (an index into ``body_poses``).
        X_BP: the pad frame in that body's frame (origin at the grid's centre, +z out).
        radius: 0 for a flat pad; r > 0: wrapped around a cylinder of radius r whose
            axis is P's y line through ``(0, 0, -r)`` (``u`` is the arc length).
        noise_floor: Pa; cells at or below it read as empty.
    """

    start: int
    cell_centres: np.ndarray
    cell_area: float
    body_index: int
    X_BP: RigidTransform
    radius: float = 0.0
    noise_floor: float = 0.0

    @property
    def cells(self) -> int:
        return len(self.cell_centres)

    def centre_of_pressure(self, taxels, along: bool = True) -> tuple[np.ndarray, float]:
        """``(p_P, force)``: the centre of pressure on the pad's surface, in P (m; the
        zero vector without force), and the pad's total normal force (N). ``along``
        False: its ``u`` only (the point on the pad's centre line across from it)."""
        p = np.asarray(taxels, float)[self.start:self.start + self.cells]
        f = np.where(p > self.noise_floor, p, 0.0) * self.cell_area
        total = float(f.sum())
        if total <= 0.0:
            return np.zeros(3), 0.0
        u, v = f @ self.cell_centres / total
        return pad_surface_point(u, v if along else 0.0, self.radius)[0][0], total


def finger_command_groups(hand_kind: str) -> list[list[int]]:
    """Indices into the hand command of the joints each tactile channel's finger closes:
    ``HandSpec.finger_joints`` (shadow: the J4..J2, LFJ5, THJ5..THJ1 of each finger;
    barrett: each finger's proximal flexion, the shared spread stays at the pre-shape)."""

    return get_hand_spec(hand_kind).finger_command_indices()


@dc.dataclass
class _Step:
    """The working copy of :class:`ReactiveGrasp`'s state during one update (plain
    numbers and arrays, written back to the context's state at the end)."""

    travel: float
    lift: float
    t_mode: float
    t_arrived: float
    shift: np.ndarray
    target: np.ndarray
    recentres: float
    t_recentred: float
    s: np.ndarray
    touched: np.ndarray
    squeeze_from: np.ndarray
    recentre_from: np.ndarray


def _checked_arguments(start_pose6, goal_pose6, preshape, closed, finger_groups, grasp_fingers,
                       params, finger_directions_B, hand_bodies, fingertip_bodies,
                       planned_object, object_bodies, period):
    """:class:`ReactiveGrasp`'s arguments checked (in this order), as arrays."""
    start = np.asarray(start_pose6, dtype=float)
    goal = np.asarray(goal_pose6, dtype=float)
    for name, v in (("start_pose6", start), ("goal_pose6", goal)):
        if v.shape != (6,) or not np.isfinite(v).all():
            raise ValueError(f"{name}: expected 6 finite values, got shape {v.shape}")
    preshape = np.asarray(preshape, dtype=float)
    closed = np.asarray(closed, dtype=float)
    if preshape.ndim != 1 or preshape.shape != closed.shape:
        raise ValueError(f"preshape and closed: expected equal 1-D sizes, got "
                         f"{preshape.shape} and {closed.shape}")
    if not (np.isfinite(preshape).all() and np.isfinite(closed).all()):
        raise ValueError("preshape and closed must be finite")
    nu = preshape.size
    groups = [np.asarray(g, dtype=int) for g in finger_groups]
    if not groups:
        raise ValueError("finger_groups: expected at least one finger")
    seen = np.concatenate(groups)
    if np.any(seen < 0) or np.any(seen >= nu) or len(set(seen.tolist())) != seen.size:
        raise ValueError(f"finger_groups: expected disjoint indices in [0, {nu}), got "
                         f"{[g.tolist() for g in groups]}")
    n = len(groups)
    if grasp_fingers is None:
        grasp = np.array([np.any(closed[g] != preshape[g]) for g in groups])
    else:
        grasp = np.asarray(grasp_fingers, dtype=bool)
        if grasp.shape != (n,):
            raise ValueError(f"grasp_fingers: expected {n} flags, got shape {grasp.shape}")
    if not grasp.any():
        raise ValueError("no grasp finger: closed equals preshape on every finger")
    params = params if params is not None else ReactiveGraspParams()
    if not isinstance(params, ReactiveGraspParams):
        raise TypeError(f"params must be ReactiveGraspParams, got {type(params).__name__}")
    params.validate()
    if finger_directions_B is not None:
        finger_directions_B = np.asarray(finger_directions_B, dtype=float)
        if finger_directions_B.shape != (n, 3) or not np.isfinite(finger_directions_B).all():
            raise ValueError(f"finger_directions_B: expected ({n}, 3) finite values, got "
                             f"shape {finger_directions_B.shape}")
    if (hand_bodies is None) != (fingertip_bodies is None):
        raise ValueError("hand_bodies and fingertip_bodies go together (both or neither)")
    if fingertip_bodies is not None and len(fingertip_bodies) != n:
        raise ValueError(f"fingertip_bodies: expected {n} (one per tactile channel), "
                         f"got {len(fingertip_bodies)}")
    if not (np.isfinite(period) and period > 0):
        raise ValueError(f"period must be > 0 (s), got {period}")
    if planned_object is not None:
        if not isinstance(planned_object, ObjectEstimate):
            raise TypeError("planned_object must be an ObjectEstimate, got "
                            f"{type(planned_object).__name__}")
        if hand_bodies is None:
            raise ValueError("planned_object needs hand_bodies and fingertip_bodies: the "
                             "re-centring reads where the fingertips touch")
        if object_bodies is None or len(object_bodies) == 0:
            raise ValueError("planned_object needs object_bodies: the re-centring reads "
                             "where the fingertips touch the object")
    return start, goal, preshape, closed, groups, grasp, params, finger_directions_B


def _checked_taxel_pads(taxel_pads, taxel_cells, n: int) -> list | None:
    """``taxel_pads`` checked against ``n`` fingers and ``taxel_cells`` cells."""
    if taxel_pads is None:
        if taxel_cells is not None:
            raise ValueError("taxel_cells needs taxel_pads (the pads the cells belong to)")
        return None
    pads = list(taxel_pads)
    if len(pads) != n:
        raise ValueError(f"taxel_pads: expected {n} entries (one per tactile channel, None "
                         f"for a finger without a pad), got {len(pads)}")
    if isinstance(taxel_cells, bool) or not isinstance(taxel_cells, int | np.integer) \
            or taxel_cells < 1:
        raise ValueError(f"taxel_cells: expected the taxels port's size (an integer >= 1), "
                         f"got {taxel_cells!r}")
    for i, pad in enumerate(pads):
        if pad is None:
            continue
        if not isinstance(pad, TaxelPadLayout):
            raise TypeError(f"taxel_pads[{i}]: expected a TaxelPadLayout or None, got "
                            f"{type(pad).__name__}")
        centres = np.asarray(pad.cell_centres)
        if centres.ndim != 2 or centres.shape[1] != 2 or not np.isfinite(centres).all():
            raise ValueError(f"taxel_pads[{i}].cell_centres: expected (cells, 2) finite "
                             f"values, got shape {centres.shape}")
        if not 0 <= pad.start <= taxel_cells - len(centres):
            raise ValueError(f"taxel_pads[{i}]: cells {pad.start}..{pad.start + len(centres)}"
                             f" do not fit the {taxel_cells} taxels")
        if not (np.isfinite(pad.cell_area) and pad.cell_area > 0):
            raise ValueError(f"taxel_pads[{i}].cell_area: expected > 0 (m^2), got "
                             f"{pad.cell_area}")
    if all(pad is None for pad in pads):
        raise ValueError("taxel_pads: every entry is None (no finger has a pad)")
    return pads


class ReactiveGrasp(LeafSystem):
    """Reactive approach, per-finger tactile closing, squeeze and lift (see module doc).

    Args:
        start_pose6, goal_pose6: wrist poses ``[x y z roll pitch yaw]`` at the
            start and at the end of the approach (the planned grasp pose).
        preshape, closed: (nu,) hand commands: open, and fully closed (the
            closing fraction 1).
        finger_groups: per tactile channel, the command indices its finger
            closes (:func:`finger_command_groups`). Commands in no group stay
            at the pre-shape.
        grasp_fingers: (n,) bool, the fingers that must touch before the
            squeeze (default: those whose ``closed`` differs from ``preshape``).
            The other fingers keep the pre-shape.
        params: :class:`ReactiveGraspParams`.
        finger_directions_B: optional (n, 3) outward direction of each finger
            in the hand base frame (used for the shift without contact results).
        hand_bodies, fingertip_bodies: optional ``BodyIndex`` collections; with
            them the system has a ``contact_results`` input (fingertip_bodies in
            tactile order).
        planned_object: optional :class:`ObjectEstimate`, the object as the plan
            saw it: with it (and the contact results) the close re-centres the
            hand on an object that is not where planned (mode ``RECENTRE``).
        object_bodies: the ``BodyIndex`` (or several) of the object in the
            contact results: only a fingertip's touch of these locates it (a
            fingertip on the table says nothing about the object). Needed with
            ``planned_object``.
        period: control period (s).
        taxel_pads, taxel_cells: optional, per tactile channel its distal pad
            (:class:`TaxelPadLayout`, None for a finger without one) and the size
            of the taxel vector: with them the system has ``taxels`` and
            ``body_poses`` inputs, and ``cop_shift_gain`` > 0 centres the close
            on the pads' centres of pressure.
    """

    def __init__(self, start_pose6, goal_pose6, preshape, closed, finger_groups,
                 grasp_fingers=None, params: ReactiveGraspParams | None = None,
                 finger_directions_B=None, hand_bodies=None, fingertip_bodies=None,
                 planned_object: ObjectEstimate | None = None, object_bodies=None,
                 period: float = 0.004, taxel_pads=None, taxel_cells: int | None = None):
        super().__init__()
        (start, goal, preshape, closed, groups, grasp, self.params,
         finger_directions_B) = _checked_arguments(
            start_pose6, goal_pose6, preshape, closed, finger_groups, grasp_fingers, params,
            finger_directions_B, hand_bodies, fingertip_bodies, planned_object, object_bodies,
            period)
        n = len(groups)
        self._taxel_pads = _checked_taxel_pads(taxel_pads, taxel_cells, n)
        self._taxel_cells = taxel_cells
        self._object = planned_object
        self._object_bodies = (set() if object_bodies is None
                               else {int(b) for b in object_bodies})

        self._start, self._goal = start, goal
        path = goal[:3] - start[:3]
        self._length = float(np.linalg.norm(path))
        self._direction = path / self._length if self._length > 0 else np.zeros(3)
        self._preshape, self._closed = preshape, closed
        self._groups, self._grasp, self._n = groups, grasp, n
        self._finger_directions_B = finger_directions_B
        self._period = float(period)
        self._hand_bodies = None if hand_bodies is None else {int(b) for b in hand_bodies}
        self._tip_channel = (None if fingertip_bodies is None
                             else {int(b): i for i, b in enumerate(fingertip_bodies)})

        self._declare_ports_and_state(n, start, preshape, hand_bodies)

    def _declare_ports_and_state(self, n: int, start, preshape, hand_bodies) -> None:
        """Inputs, the discrete state (read through names), the update and the outputs."""
        self._tactile = self.DeclareVectorInputPort("tactile", n)
        self._pose_measured = self.DeclareVectorInputPort("wrist_pose_measured", 6)
        self._contacts = None
        if hand_bodies is not None:
            self._contacts = self.DeclareAbstractInputPort(
                "contact_results", AbstractValue.Make(ContactResults()))
        self._taxels = self._body_poses = None
        if self._taxel_pads is not None:
            self._taxels = self.DeclareVectorInputPort("taxels", int(self._taxel_cells))
            self._body_poses = self.DeclareAbstractInputPort(
                "body_poses", AbstractValue.Make([RigidTransform()]))

        self._wrist = self.DeclareDiscreteState(start)
        self._hand = self.DeclareDiscreteState(preshape)
        self._s = self.DeclareDiscreteState(np.zeros(n))
        self._touched = self.DeclareDiscreteState(np.zeros(n))  # 1 once a finger stopped on contact
        self._squeeze_from = self.DeclareDiscreteState(np.zeros(n))
        self._recentre_from = self.DeclareDiscreteState(np.zeros(n))
        self._internal = self.DeclareDiscreteState(
            ReactiveGraspProgress(np.array([0.0, 0, 0, 0, 0, 0, np.inf, 0, 0, 0, 0, np.inf]))[:])
        # The mode, once: as its number (the ``mode`` output reads it).
        self._mode_value = self.DeclareDiscreteState(np.array([float(ReactiveGraspMode.APPROACH)]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, 0.0, self._update)

        self.DeclareStateOutputPort("wrist_pose", self._wrist)
        self.DeclareStateOutputPort("hand_position", self._hand)
        self.DeclareStateOutputPort("mode", self._mode_value)
        self.DeclareStateOutputPort("closing", self._s)

    # ---- accessors -------------------------------------------------------------
    def get_tactile_input_port(self):
        return self._tactile

    def get_wrist_pose_measured_input_port(self):
        return self._pose_measured

    def get_contact_results_input_port(self):
        if self._contacts is None:
            raise RuntimeError("this ReactiveGrasp was built without hand_bodies: "
                               "it has no contact_results input")
        return self._contacts

    def get_taxels_input_port(self):
        if self._taxels is None:
            raise RuntimeError("this ReactiveGrasp was built without taxel_pads: "
                               "it has no taxels input")
        return self._taxels

    def get_body_poses_input_port(self):
        if self._body_poses is None:
            raise RuntimeError("this ReactiveGrasp was built without taxel_pads: "
                               "it has no body_poses input")
        return self._body_poses

    def cop_offset(self, context, fingers) -> np.ndarray:
        """(3,) m, world: the mean, over the ``fingers`` ((n,) bool) whose pad feels more
        than ``cop_min_force``, of the pad's centre of pressure across the pad (``u``:
        :meth:`TaxelPadLayout.centre_of_pressure` with ``along`` False) minus its
        centre (zeros when none does, or without ``taxel_pads``). Moving the hand by
        it brings the pads' centre lines onto the centres of pressure. Along the
        finger (``v``) is left out: a closing finger meets an object with its tip
        first wherever the object is (a pinched cuboid moved towards the thumb was
        met 6.7 mm towards the thumb's tip, beyond its grid)."""
        if self._taxel_pads is None:
            return np.zeros(3)
        taxels = self._taxels.Eval(context)
        poses = None
        offsets = []
        for i in np.flatnonzero(fingers):
            pad = self._taxel_pads[i]
            if pad is None:
                continue
            p_P, force = pad.centre_of_pressure(taxels, along=False)
            if force <= self.params.cop_min_force:
                continue
            poses = self._body_poses.Eval(context) if poses is None else poses
            R_WP = poses[pad.body_index].rotation() @ pad.X_BP.rotation()
            offsets.append(R_WP.multiply(p_P))
        return np.mean(offsets, axis=0) if offsets else np.zeros(3)

    def _cop_shift(self, context, touching) -> np.ndarray:
        """The wrist's step (m, world) centring the close on the pads' centres of pressure:
        ``cop_shift_gain`` h times :meth:`cop_offset` of the touching grasp fingers,
        horizontal and across the approach, at most ``shift_speed`` h long."""
        p, h = self.params, self._period
        d = self.cop_offset(context, touching & self._grasp)
        d[2] = 0.0  # the object rests on the table: never push the hand into it
        a = np.array([self._direction[0], self._direction[1], 0.0])
        if np.linalg.norm(a) > 1e-9:
            a /= np.linalg.norm(a)
            d -= (d @ a) * a
        return _capped(p.cop_shift_gain * h * d, p.shift_speed * h)

    def get_mode(self, context) -> ReactiveGraspMode:
        return ReactiveGraspMode(int(context.get_discrete_state(self._mode_value).GetAtIndex(0)))

    def get_progress(self, context) -> ReactiveGraspProgress:
        """Travel, sideways shift, lift and the mode's times, as a (copied) named view."""
        return ReactiveGraspProgress(context.get_discrete_state(self._internal).value().copy())

    def fingers_touched(self, context) -> np.ndarray:
        """(n,) bool: the fingers that stopped closing on a tactile contact."""
        return context.get_discrete_state(self._touched).value() > 0

    def closing_at_squeeze(self, context) -> np.ndarray:
        """(n,) closing fractions when the squeeze began (zeros before it)."""
        return context.get_discrete_state(self._squeeze_from).value().copy()

    def lift_complete(self, context) -> bool:
        """True once the lift has reached ``lift_height``."""
        return (self.get_mode(context) is ReactiveGraspMode.LIFT
                and self.get_progress(context).lift >= self.params.lift_height - 1e-12)

    def nominal_duration(self) -> float:
        """Time (s) of an undisturbed run: approach, close to max, squeeze, hold, lift."""
        p = self.params
        return (self._length / p.approach_speed + p.max_closing / p.close_rate + p.squeeze_time
                + p.hold_time + p.lift_height / p.lift_speed + 4 * self._period)

    def recentre_duration(self) -> float:
        """Longest time (s) the re-centrings add to a run: reopen, shift, settle and
        close again, ``max_recentres`` times (0 without a ``planned_object``)."""
        p = self.params
        if self._object is None or p.shift_speed == 0:
            return 0.0
        return p.max_recentres * (1.5 * p.max_closing / p.close_rate
                                  + p.max_recentre / p.shift_speed + p.arrival_timeout
                                  + 4 * self._period)

    def cop_hold_duration(self) -> float:
        """Longest time (s) the open fingers wait for the centring on the centres of
        pressure (``cop_hold_above``): the whole capped shift at the slowest rate a
        waiting step moves (0 when off)."""
        p = self.params
        if self._taxel_pads is None or p.cop_shift_gain <= 0 or p.cop_hold_above <= 0 \
                or p.shift_speed == 0:
            return 0.0
        rate = min(p.shift_speed, p.cop_shift_gain * p.cop_hold_above)
        return (p.max_shift + p.max_cop_shift) / rate + 4 * self._period

    # ---- helpers ---------------------------------------------------------------
    def _hand_command(self, s) -> np.ndarray:
        command = self._preshape.copy()
        for i, g in enumerate(self._groups):
            if self._grasp[i]:
                command[g] = self._preshape[g] + s[i] * (self._closed[g] - self._preshape[g])
        return command

    def _wrist_command(self, travel, shift, lift) -> np.ndarray:
        pose = np.empty(6)
        fraction = travel / self._length if self._length > 0 else 1.0
        pose[:3] = self._start[:3] + travel * self._direction + shift
        pose[2] += lift
        pose[3:] = self._start[3:] + fraction * (self._goal[3:] - self._start[3:])
        return pose

    def _touching(self, context) -> tuple[np.ndarray, int, np.ndarray, dict]:
        """(fingertip contact flags (n,), number of other hand bodies touching,
        separating direction in world (zeros if unknown), and per fingertip
        channel touching the object (``object_bodies``) its strongest contact with
        it: ``(point, the object's outward normal, force)`` in world).

        With ``contact_results`` a fingertip counts only if it touches
        something other than the hand (the simulated pad also feels a finger
        pressed against it).
        """
        forces = self._tactile.Eval(context)
        touching = np.asarray(forces) > self.params.contact_threshold
        direction = np.zeros(3)
        tip_contacts: dict[int, tuple] = {}
        if self._contacts is None or not self._contacts.HasValue(context):
            return touching, 0, direction, tip_contacts
        results = self._contacts.Eval(context)
        external = np.zeros(self._n, dtype=bool)
        others = set()
        for k in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(k)
            a, b = int(info.bodyA_index()), int(info.bodyB_index())
            a_hand, b_hand = a in self._hand_bodies, b in self._hand_bodies
            if a_hand == b_hand:
                continue  # self contact, or no hand body
            nhat = info.point_pair().nhat_BA_W  # from B into A
            magnitude = abs(float(info.contact_force() @ nhat))
            into_hand = nhat if a_hand else -nhat
            direction += magnitude * into_hand
            body = a if a_hand else b
            channel = self._tip_channel.get(body)
            if channel is not None:
                external[channel] = True
                other = b if a_hand else a
                if (other in self._object_bodies
                        and magnitude > tip_contacts.get(channel, (None, None, -1.0))[2]):
                    tip_contacts[channel] = (np.array(info.contact_point()), into_hand.copy(),
                                             magnitude)
            elif magnitude > self.params.contact_threshold:
                others.add(body)
        touching &= external
        return touching, len(others), direction, tip_contacts

    def _shift_direction(self, context, touching, direction_W) -> np.ndarray:
        d = direction_W
        if np.linalg.norm(d) == 0 and self._finger_directions_B is not None:
            rpy = context.get_discrete_state(self._wrist).value()[3:]
            R_WB = RollPitchYaw(rpy).ToRotationMatrix().matrix()
            d = R_WB @ self._finger_directions_B[touching].sum(axis=0)
        d = d - (d @ self._direction) * self._direction  # sideways only
        norm = np.linalg.norm(d)
        return d / norm if norm > 1e-9 else np.zeros(3)

    def _settled(self, context, travel, shift, waited) -> bool:
        """The wrist has reached its command at ``travel``/``shift`` (within
        ``arrival_tolerance``), or ``waited`` (s) has reached ``arrival_timeout``."""
        p = self.params
        measured = self._pose_measured.Eval(context)[:3]
        command = self._wrist_command(travel, shift, 0.0)[:3]
        return (np.linalg.norm(measured - command) <= p.arrival_tolerance
                or waited >= p.arrival_timeout)

    def _recentring(self, new_touches, tip_contacts, recentres) -> np.ndarray | None:
        """The wrist shift (m, world, horizontal) that re-centres the hand on the object
        located by the strongest of this step's first touches (``new_touches``),
        or None: no planned object, no re-centring left, or the object where planned."""
        p = self.params
        if self._object is None or recentres >= p.max_recentres or p.shift_speed == 0:
            return None
        located = [tip_contacts[i] for i in np.flatnonzero(new_touches) if i in tip_contacts]
        if not located:
            return None
        point, normal, _ = max(located, key=lambda c: c[2])
        d = self._object.displacement(point, normal)
        d[2] = 0.0  # it rests on the table: only a horizontal error
        if np.linalg.norm(d) <= p.recentre_threshold:
            return None
        return _capped(d, p.max_recentre)

    # ---- update ----------------------------------------------------------------
    def _update(self, context, state):
        now = context.get_time()
        mode = self.get_mode(context)
        progress = self.get_progress(context)
        w = _Step(
            travel=progress.travel, lift=progress.lift, t_mode=progress.mode_entry_time,
            t_arrived=progress.arrival_time,
            shift=np.array([progress.shift_x, progress.shift_y, progress.shift_z]),
            target=np.array([progress.target_x, progress.target_y, progress.target_z]),
            recentres=progress.recentres, t_recentred=progress.recentred_time,
            s=context.get_discrete_state(self._s).value().copy(),
            touched=context.get_discrete_state(self._touched).value().copy(),
            squeeze_from=context.get_discrete_state(self._squeeze_from).value().copy(),
            recentre_from=context.get_discrete_state(self._recentre_from).value().copy())
        new_mode = mode
        if mode in (ReactiveGraspMode.APPROACH, ReactiveGraspMode.SLOW_APPROACH):
            new_mode = self._step_approach(context, w, now)
        elif mode is ReactiveGraspMode.CLOSE:
            new_mode = self._step_close(context, w)
        elif mode is ReactiveGraspMode.RECENTRE:
            new_mode = self._step_recentre(context, w, now)
        elif mode is ReactiveGraspMode.SQUEEZE:
            elapsed = now - w.t_mode
            ramp = min(1.0, elapsed / self.params.squeeze_time)
            w.s = np.where(self._grasp, w.squeeze_from + ramp * self.params.squeeze, w.s)
            if elapsed >= self.params.squeeze_time + self.params.hold_time - 1e-9:
                new_mode = ReactiveGraspMode.LIFT
        elif mode is ReactiveGraspMode.LIFT:
            w.lift = min(w.lift + self.params.lift_speed * self._period, self.params.lift_height)
        if new_mode is not mode:
            w.t_mode = now
        state.get_mutable_discrete_state(self._mode_value).set_value([float(new_mode)])
        state.get_mutable_discrete_state(self._internal).set_value(
            np.r_[w.travel, w.shift, w.lift, w.t_mode, w.t_arrived, w.target, w.recentres,
                  w.t_recentred])
        state.get_mutable_discrete_state(self._s).set_value(w.s)
        state.get_mutable_discrete_state(self._touched).set_value(w.touched)
        state.get_mutable_discrete_state(self._squeeze_from).set_value(w.squeeze_from)
        state.get_mutable_discrete_state(self._recentre_from).set_value(w.recentre_from)
        state.get_mutable_discrete_state(self._wrist).set_value(
            self._wrist_command(w.travel, w.shift, w.lift))
        state.get_mutable_discrete_state(self._hand).set_value(self._hand_command(w.s))

    def _step_approach(self, context, w: _Step, now: float) -> ReactiveGraspMode:
        """APPROACH / SLOW_APPROACH: advance (slower, shifting away, on an early touch);
        stop on multiple contacts; close once arrived and settled."""
        p, h = self.params, self._period
        new_mode = self.get_mode(context)
        touching, others, direction_W, _ = self._touching(context)
        if touching.sum() >= p.multiple_contacts:
            # Hold where the hand is, not where the command had run ahead to.
            measured = self._pose_measured.Eval(context)[:3]
            along = float((measured - self._start[:3] - w.shift) @ self._direction)
            w.travel = float(np.clip(along, 0.0, w.travel))
            return ReactiveGraspMode.STOPPED
        if touching.any() or others:
            new_mode = ReactiveGraspMode.SLOW_APPROACH
            d = self._shift_direction(context, touching, direction_W)
            w.shift = _capped(w.shift + p.shift_speed * h * d, p.max_shift)
        slow = new_mode is ReactiveGraspMode.SLOW_APPROACH
        speed = p.approach_speed * (p.slow_factor if slow else 1.0)
        w.travel = min(w.travel + speed * h, self._length)
        if w.travel >= self._length:
            w.t_arrived = min(w.t_arrived, now)
            if self._settled(context, w.travel, w.shift, now - w.t_arrived):
                new_mode = ReactiveGraspMode.CLOSE
        return new_mode

    def _step_close(self, context, w: _Step) -> ReactiveGraspMode:
        """CLOSE: each grasp finger closes until its fingertip touches; re-centre on an
        object found elsewhere; squeeze once every grasp finger is done."""
        p, h = self.params, self._period
        tips, _, direction_W, tip_contacts = self._touching(context)
        d = self._recentring(tips & self._grasp & (w.touched == 0), tip_contacts, w.recentres)
        if d is not None:
            w.target, w.recentres, w.t_recentred = w.shift + d, w.recentres + 1, np.inf
            w.recentre_from = w.s.copy()
            return ReactiveGraspMode.RECENTRE
        step, hold = self._cop_step(context, tips, w.shift)
        for i in np.flatnonzero(self._grasp):
            if w.touched[i]:
                continue
            if tips[i]:
                w.touched[i] = 1.0  # this finger stops where it is
            elif not hold:
                w.s[i] = min(w.s[i] + p.close_rate * h, p.max_closing)
        done = (w.touched > 0) | (w.s >= p.max_closing)
        if p.close_shift_speed > 0 and tips[self._grasp].any() and not np.all(
                done[self._grasp]):
            d = self._shift_direction(context, tips & self._grasp, direction_W)
            w.shift = _capped(w.shift + p.close_shift_speed * h * d,
                              p.max_shift + p.max_close_shift)
        if not np.all(done[self._grasp]):
            w.shift = _capped(w.shift + step, p.max_shift + p.max_cop_shift)
        if np.all(done[self._grasp]):
            w.squeeze_from = w.s.copy()
            return ReactiveGraspMode.SQUEEZE
        return ReactiveGraspMode.CLOSE

    def _cop_step(self, context, tips, shift) -> tuple[np.ndarray, bool]:
        """The close's step on the centres of pressure (zeros when off or no grasp finger
        touches) and whether the open grasp fingers wait for it: the offset is above
        ``cop_hold_above`` and the step still moves the wrist (under the cap)."""
        p = self.params
        if p.cop_shift_gain <= 0 or self._taxel_pads is None or not tips[self._grasp].any():
            return np.zeros(3), False
        step = self._cop_shift(context, tips)
        moved = _capped(shift + step, p.max_shift + p.max_cop_shift) - shift
        hold = (p.cop_hold_above > 0 and np.linalg.norm(moved) > 1e-9
                and np.linalg.norm(step) > p.cop_shift_gain * self._period * p.cop_hold_above)
        return step, hold

    def _step_recentre(self, context, w: _Step, now: float) -> ReactiveGraspMode:
        """RECENTRE: undo recentre_reopen of the closing, then shift, then settle, then
        close on."""
        p, h = self.params, self._period
        floor = (1.0 - p.recentre_reopen) * w.recentre_from
        w.s = np.where(self._grasp, np.maximum(w.s - 2 * p.close_rate * h, floor), w.s)
        if not np.any(w.s[self._grasp] > floor[self._grasp]):
            w.shift = w.shift + _capped(w.target - w.shift, p.shift_speed * h)
            if np.linalg.norm(w.target - w.shift) < 1e-9:
                w.t_recentred = min(w.t_recentred, now)
                if self._settled(context, w.travel, w.shift, now - w.t_recentred):
                    w.touched[:] = 0.0
                    return ReactiveGraspMode.CLOSE
        return ReactiveGraspMode.RECENTRE
