"""Grasp planning from a grasp class and an object (report section 3.2).

:func:`plan_grasp` turns *(grasp class, object, object pose)* into everything a
floating-wrist station needs to grasp and lift the object:

1. **pre-shape from synergies.** The class's synergy amplitudes for the object
   size (per-class linear regression of the amplitudes on size,
   :class:`~handle_drake.grasp.synergies.SizeRegression`, fitted on the shipped
   grasp data) give a posture that seeds the hand inverse kinematics.
2. **grasp centre and approach (Tables 1-2).** The report's Table 1 centre
   ``c(size)`` in the palm frame P is where the object centre should sit; the
   Table 2 approach vector ``a_P`` is the direction the hand moves in. A Drake
   ``InverseKinematics`` problem (:meth:`GraspKinematics.solve_grasp`) puts the
   class's finger contacts on the object with the object centre held *at* the
   Table 1 centre; the table under the object is part of the problem (the
   hand and forearm stay above it) and ``a_P`` must point within 30 degrees of
   straight down. **IK refinement:** Table 1 comes from the C5 hand and several
   of its centres are out of our model's reach; when the fixed-centre problem
   has no solution, the centre is freed and only pulled towards Table 1 (the
   plan records ``centre_source = "refined"`` and the offset).
3. **hand pose.** The grasp frame G of the solution is placed on the object in
   the world (``x_G`` vertical, the finger row ``y_G`` along the object's long
   horizontal axis), which fixes the palm pose ``X_WP = X_WG X_GP`` and the hand
   base (``forearm``) pose ``X_WB = X_WP X_PB`` through the fixed forearm->palm
   transform at zero wrist angles.
4. **pre-grasp, close, lift.** The pre-grasp base pose backs off ``standoff``
   along the approach; the pre-shape opens each contact finger 25 mm out
   along its contact normal and the closing command pushes it 20 mm in (damped
   least-squares steps on the contact Jacobian, so the position-controlled
   fingers press with a force set by their PD gains). Both are collision
   checked, not only the IK posture: a finger whose opened posture reaches
   into the table, the object or another finger is lifted, then opened less
   (``PRESHAPE_STEPS``); one whose closing command dips into the table closes
   a little upward (``CLOSE_LIFTS``); an idle finger in the way is extended or
   curled (``IDLE_POSTURES``).

The whole hand, not only the fingertips and the forearm, stays above the
table in the IK (every collision shape of the model, ``hand_clearance``):
before, small-sphere pinches were planned with a middle phalanx 18 mm inside
the table top.

:func:`handle_drake.trial.plans.plan_script` / :func:`~handle_drake.trial.plans.plan_scenario`
write keyframes (reach from the stand-off, close, lift) for a ``!FloatingWrist`` scenario.

Object conventions. Kinds ``sphere``, ``cylinder`` and ``cuboid`` of the
catalogue (:mod:`handle_drake.geometry.objects`). The *grasp size* (Table 1's object
size, the distance between the opposing fingers) is the diameter of a sphere
or cylinder and the **depth** (``0.6 * size``, the thin horizontal edge) of a
cuboid. The planner grasps a sphere anywhere, a cylinder lying on its side
(axis horizontal) and a cuboid standing upright (its z axis vertical); use
:func:`resting_pose`.

Mesh objects (``MeshObjectSpec``, :mod:`handle_drake.geometry.objects.mesh`) are planned
like a cuboid standing upright: the IK's proxy is the mesh's bounding box in O
(:func:`~handle_drake.geometry.objects.mesh.grasp_extents`), the fingers close across
its narrower horizontal axis, and the Table 1 grasp size is the mesh's extent
along that axis (the distance between the planes the opposing fingers close
on). The contacts are planned on the proxy; the closing squeeze (20 mm past
it) brings the fingers onto the real surface, which is what the simulation
collides with. A mesh whose opposing faces are not the bounding box's (a
torus, a bowl) is therefore grasped at its outer extent. The instrumented
devices (``joywarrior``, ``wiimote``, ``nunchuk``, ``sixaxis``;
:mod:`handle_drake.geometry.objects.instrumented`) are planned the same way on their
bounding box, lying in their natural resting pose (buttons up).

Frames: W world, O object, G grasp frame of the IK (``x_G`` up, ``y_G`` finger
row, ``z_G`` opposition axis, thumb on ``+z_G``), P palm, B hand base (forearm).
"""

from __future__ import annotations

import dataclasses as dc
import time
from functools import lru_cache

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from handle_drake.base.hands import get_hand_spec
from handle_drake.geometry.objects import ObjectSpec, dimensions, resting_height, surface_mesh
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS
from handle_drake.geometry.objects.mesh import MeshObjectSpec
from handle_drake.grasp.kinematics import GraspKinematics, contact_layout, move_contacts
from handle_drake.grasp.synergies import ClassSynergies, default_synergies
from handle_drake.grasp.synthetic import posture_prior
from handle_drake.grasp.taxonomy import (
    GraspClass,
    approach_palm,
    check_size,
    grasp_centre_palm,
    grasp_info,
)

__all__ = [
    "PLANNABLE_KINDS",
    "ADAPT_MAX_JOINT_CHANGE",
    "GraspPlan",
    "GraspPlanningError",
    "GraspPlanningTimeout",
    "ClassSynergies",
    "ObjectFrameGrasp",
    "PLANNER_HAND",
    "PLANNER_VERSION",
    "adapt_grasp",
    "clear_solution_cache",
    "default_synergies",
    "grasp_dims",
    "grasp_key",
    "object_frame_grasp",
    "place_grasp",
    "plan_grasp",
    "resting_pose",
]

PLANNABLE_KINDS = ("sphere", "cylinder", "cuboid", *DEVICE_OBJECTS)
_IK_SHAPE = {"sphere": "sphere", "cylinder": "cylinder", "cuboid": "box"}
_KIND_ALIASES = {"box": "cuboid"}
MAX_PENETRATION = 0.004  # m, hand-object and hand-hand overlap the plan may keep
MAX_CONTACT_ERROR = 1.5e-3  # m, contact point off the object surface
MAX_APPROACH_ANGLE = np.deg2rad(45.0)  # approach vector from straight down
PRESHAPE_OPENING = 0.025  # m, contacts moved out along their normals for the pre-shape
CLOSING_SQUEEZE = 0.020  # m, and pushed in for the closing command
PRESHAPE_LIFT = 0.010  # m, contacts raised (world up) in the pre-shape
TABLE_TOLERANCE = 0.001  # m, how far any part of the hand may reach into the table in a plan
# (opening, lift) of the pre-shape's contacts (m), tried in turn until no part of the
# hand reaches into the table (see _preshape).
PRESHAPE_STEPS = ((PRESHAPE_OPENING, PRESHAPE_LIFT), (PRESHAPE_OPENING, 0.020),
                  (PRESHAPE_OPENING, 0.030), (0.018, 0.030), (0.012, 0.030), (0.008, 0.030))
# m, upward part of a finger's closing move, tried in turn (see _closing)
CLOSE_LIFTS = (0.0, 0.005, 0.010, 0.015, 0.020)
PAD_TILT = np.deg2rad(15.0)  # the second pass's pads on a round object (GraspKinematics)
CANONICAL_APPROACH_ANGLE = np.deg2rad(15.0)  # cone of the first (palm-along-approach) attempts
# Joints the planner sets in every posture prior of a class: the fingers a
# class does not use are kept out of the way (report section 3.3: during the
# reach only the class's fingers may meet the object). Tripod: ring and
# little fingers extended (curled, they pass a few mm from a small sphere and
# hit it in the reach), the thumb abducted to oppose the first and middle finger.
# Adduction grip: ring and little fingers curled into the palm, so the middle
# finger can open away from the first finger (extended beside it, the ring
# finger left it no room: the pre-shape pressed them together at 600 N).
PLANNER_POSTURES: dict[GraspClass, dict[str, float]] = {
    GraspClass.TRIPOD: {"RFJ3": 0.0, "RFJ2": 0.0, "LFJ3": 0.0, "LFJ2": 0.0, "THJ4": 1.1},
    GraspClass.ADDUCTION_GRIP: {"RFJ3": 1.4, "RFJ2": 1.4, "LFJ3": 1.4, "LFJ2": 1.4},
}
WRIST_RANGE = 2.0  # m, travel of the floating wrist's prismatic joints (station.py)
_SPEC = get_hand_spec("shadow")
_NAMES = _SPEC.joint_names
_ACT = _SPEC.actuated_joint_names


class GraspPlanningError(ValueError):
    """No grasp of the requested class was found (unreachable pose or object)."""


class GraspPlanningTimeout(GraspPlanningError):
    """The class's hand-IK search ran past its ``time_budget`` (no answer: not cached)."""


#: Version of the planner's answers: bump it when a change alters the grasp that
#: ``plan_grasp`` returns for the same input (a grasp database built by an older
#: version is then stale: :mod:`handle_drake.grasp.database` recomputes its entries).
PLANNER_VERSION = 1
#: The hand the planner plans for (the key of a stored grasp names it).
PLANNER_HAND = "shadow"

# The planner's pose-invariant answer (an :class:`ObjectFrameGrasp`, or None when the
# search found no grasp) for (class, kind, shape, dims, height above the table,
# coupling ratio) with the default synergies: it does not depend on where the object
# stands or the reach direction (those only place the grasp in the world), so a
# second pick of the same kind and size reuses it (a failed search too). Bounded.
_SOLUTION_CACHE: dict = {}
_SOLUTION_CACHE_SIZE = 256
# adapt_grasp's answers (it is deterministic) per (key, stored key, database): the same
# object planned again (another turn, another pick) is not adapted again.
_ADAPTED_CACHE: dict = {}


def clear_solution_cache() -> None:
    """Forgets the cached hand-IK answers (see ``plan_grasp``'s ``cache``) and
    adaptations."""
    _SOLUTION_CACHE.clear()
    _ADAPTED_CACHE.clear()


# ---------------------------------------------------------------- objects


def _object_spec(obj):

    if isinstance(obj, MeshObjectSpec):
        return obj
    if isinstance(obj, ObjectSpec):
        spec = obj
    elif isinstance(obj, tuple | list) and len(obj) == 2:
        kind, size = obj
        if not isinstance(kind, str):
            raise TypeError(f"object kind must be a str, got {type(kind).__name__}")
        kind = _KIND_ALIASES.get(kind.strip().lower(), kind.strip().lower())
        if kind not in PLANNABLE_KINDS:
            raise ValueError(
                f"cannot plan a grasp on a {kind!r}; expected one of {', '.join(PLANNABLE_KINDS)}"
            )
        spec = ObjectSpec(kind, size)
    else:
        raise TypeError(
            f"object must be an ObjectSpec or a (kind, size) pair, got {type(obj).__name__}"
        )
    if spec.kind not in PLANNABLE_KINDS:
        raise ValueError(
            f"cannot plan a grasp on a {spec.kind!r}; expected one of {', '.join(PLANNABLE_KINDS)}"
        )
    return spec


def _on_bounding_box(kind: str) -> bool:
    """Planned on its bounding box like an upright cuboid: a mesh or an instrumented device."""
    return kind == "mesh" or kind in DEVICE_OBJECTS


def _extents(spec) -> tuple[float, float, float]:
    """Bounding-box edges (x, y, z) in O (m) of a mesh or an instrumented device."""

    return tuple(float(e) for e in surface_mesh(spec).extents)


def grasp_dims(spec) -> tuple[str, tuple[float, ...]]:
    """(IK shape, dims in the grasp frame G) of a catalogue object (see module doc).

    A mesh or an instrumented device is planned as its bounding-box proxy standing
    upright: (opposition, row, height) extents, the fingers closing across the
    narrower horizontal edge (as ``objects.mesh.grasp_extents`` gives a mesh's).
    """

    if _on_bounding_box(spec.kind):
        ex, ey, ez = _extents(spec)
        return "box", (min(ex, ey), max(ex, ey), ez)
    d = dimensions(spec)
    if spec.kind == "sphere":
        return "sphere", (d["diameter"],)
    if spec.kind == "cylinder":
        return "cylinder", (d["diameter"], d["height"])
    # box dims (w along z_G, d along y_G, h along x_G) = (depth, width, height)
    return "box", (d["depth"], d["width"], d["height"])


def resting_pose(kind, size: float | None = None, xy=(0.0, 0.0), yaw: float = 0.0,
                 table_height: float = 0.0) -> RigidTransform:
    """``X_WO`` of a plannable object resting on a table top at ``table_height``.

    sphere and cuboid stand upright; a cylinder lies on its side with its axis
    along the world direction ``(-sin yaw, cos yaw, 0)``. ``kind`` may be a
    ``MeshObjectSpec`` (``size`` unused): it stands as in its file, on its
    lowest point; an instrumented device lies in its resting pose (``size``
    None: its catalogue size).
    """

    if getattr(kind, "kind", None) == "mesh":
        spec, d = kind, None
    else:
        if size is None and kind in DEVICE_OBJECTS:
            size = DEVICE_OBJECTS[kind].default_size
        spec = _object_spec((kind, size))
        d = dimensions(ObjectSpec(spec.kind, spec.size))
    xy = np.asarray(xy, dtype=float)
    if xy.shape != (2,) or not np.isfinite(xy).all():
        raise ValueError(f"xy: expected 2 finite values, got {xy}")
    R = RotationMatrix.MakeZRotation(float(yaw))
    if _on_bounding_box(spec.kind):
        z = resting_height(spec)
    elif spec.kind == "sphere":
        z = 0.5 * d["diameter"]
    elif spec.kind == "cylinder":
        R = R @ RotationMatrix.MakeXRotation(np.pi / 2)
        z = 0.5 * d["diameter"]
    else:
        z = 0.5 * d["height"]
    return RigidTransform(R, [xy[0], xy[1], table_height + z])


# ---------------------------------------------------------------- the plan


@dc.dataclass
class GraspPlan:
    """A planned grasp. Joint commands are in the 20-entry command order.

    preshape_command / grasp_command / close_command: (20,) rad: fingers open
      25 mm off the object, on it (the IK solution), and pushed 20 mm in.
    q_grasp: (24,) the IK posture (all joints). amplitudes: (k,) synergy
      amplitudes of the class at this size (the IK seed; None when the class
      has no data), grasp_amplitudes: (k,) of the final grasp posture.
    X_WB / X_WB_pregrasp: hand base (forearm) poses at the grasp and at the
      stand-off. X_WP: palm pose. approach_W: unit approach vector in world.
    p_PC_table1 / p_PC: the Table 1 grasp centre and the planned one, palm
      frame (m); centre_source: "table1" (held there) or "refined".
    """

    grasp_class: GraspClass
    object_spec: object
    grasp_size: float
    X_WO: RigidTransform
    X_WG: RigidTransform
    X_WP: RigidTransform
    X_WB: RigidTransform
    X_WB_pregrasp: RigidTransform
    approach_W: np.ndarray
    q_grasp: np.ndarray
    preshape_command: np.ndarray
    grasp_command: np.ndarray
    close_command: np.ndarray
    amplitudes: np.ndarray | None
    grasp_amplitudes: np.ndarray
    p_PC_table1: np.ndarray
    p_PC: np.ndarray
    centre_source: str
    contact_error: float
    table_height: float
    lift_height: float = 0.13
    coupling_ratio: float = 1.0
    # What perception made of the object, when the plan was made on it
    # (handle_drake.apps.perception.grasping.PerceivedObject), else None.
    perception: object = None
    # The key of the stored grasp this plan's was adapted from (adapt_grasp), else None.
    adapted_from: tuple | None = None

    @property
    def centre_offset(self) -> float:
        """Distance (m) between the planned grasp centre and Table 1's."""
        return float(np.linalg.norm(self.p_PC - self.p_PC_table1))

    def command_dict(self, command) -> dict[str, float]:
        return {n: float(v) for n, v in zip(_ACT, command, strict=True)}

    def wrist(self, X_WB: RigidTransform) -> list[float]:
        """``[x y z roll pitch yaw]`` of a base pose (the ``wrist.pose`` port)."""
        rpy = RollPitchYaw(X_WB.rotation()).vector()
        return [float(v) for v in np.concatenate([X_WB.translation(), rpy])]

    def lifted(self) -> RigidTransform:
        return RigidTransform(self.X_WB.rotation(),
                              self.X_WB.translation() + [0.0, 0.0, self.lift_height])

    def summary(self) -> str:
        p = self.X_WB.translation()
        return (f"{self.grasp_class.value} on a {self.object_spec.kind} "
                f"(size {self.object_spec.size * 100:.1f} cm, grasp width "
                f"{self.grasp_size * 100:.1f} cm): centre {self.centre_source} "
                f"({self.centre_offset * 1000:.1f} mm from Table 1), hand base at "
                f"[{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}] m")


@dc.dataclass(frozen=True)
class ObjectFrameGrasp:
    """The part of a plan that does not depend on where the object stands: what a
    grasp database stores (:mod:`handle_drake.grasp.database`).

    ``key``: :func:`grasp_key` of the request it answers. X_PG: the grasp frame in
    the palm (the IK's object pose); up_G: world up in G; X_BP: the palm in the hand
    base (forearm) at the IK posture; q_grasp / q_pre / q_close: (24,) postures of
    the grasp (idle fingers cleared), pre-shape and closing command; amplitudes /
    grasp_amplitudes: the synergy amplitudes (seed, final posture).
    """

    key: tuple
    X_PG: RigidTransform
    up_G: np.ndarray
    centre_source: str
    X_BP: RigidTransform
    q_grasp: np.ndarray
    q_pre: np.ndarray
    q_close: np.ndarray
    contact_error: float
    amplitudes: np.ndarray | None
    grasp_amplitudes: np.ndarray
    #: The key of the stored grasp this one was adapted from (:func:`adapt_grasp`), or
    #: None: the search's own answer.
    adapted_from: tuple | None = None


def grasp_key(grasp_class, obj, height: float, coupling_ratio: float = 1.0) -> tuple:
    """The request a pose-invariant grasp answers: ``(hand, class, kind, shape,
    dims, height above the table, coupling ratio)`` (the planner version is the
    database's). Lengths are rounded to a micrometre (``KEY_RESOLUTION``): a height
    computed as the object's z minus the table's differs from the resting height in
    the last bits."""
    info = grasp_info(grasp_class)
    spec = _object_spec(obj)
    shape, dims = grasp_dims(spec)
    return (PLANNER_HAND, info.grasp_class.value, spec.kind, shape,
            tuple(_key_length(d) for d in dims), _key_length(height),
            round(float(coupling_ratio), 9))


KEY_RESOLUTION = 1e-6  # m, lengths in a grasp_key


def _key_length(x: float) -> float:
    return round(float(x) / KEY_RESOLUTION) * KEY_RESOLUTION


# ---------------------------------------------------------------- planning


@lru_cache(maxsize=64)
def _kinematics(ratio: float, shape: str, dims: tuple, up, height):
    support = None if up is None else (np.array(up), height)
    return GraspKinematics(ratio, shape=shape, dims=dims, support=support)


def _up_in_grasp_frame(kind: str, natural_up_G) -> np.ndarray:
    """World "up" expressed in G, as close to ``natural_up_G`` as the object allows.

    A sphere can rest in any orientation; a cylinder lies with its axis (y_G)
    horizontal, so up is in the x_G-z_G plane; a cuboid stands with its
    height axis x_G vertical.
    """
    u = np.asarray(natural_up_G, dtype=float)
    if kind == "cylinder":
        u = np.array([u[0], 0.0, u[2]])
        if np.linalg.norm(u) < 1e-6:
            u = np.array([1.0, 0.0, 0.0])
    elif kind == "cuboid" or _on_bounding_box(kind):
        u = np.array([1.0 if u[0] >= 0 else -1.0, 0.0, 0.0])
    return u / np.linalg.norm(u)


def _acceptable(kin: GraspKinematics, sol) -> bool:
    """Our own check of an IK result (SNOPT often reports failure a hair from
    feasibility): contacts on the surface, little penetration, tips and forearm above the
    table."""
    if sol.contact_error > MAX_CONTACT_ERROR:
        return False
    kin.plant.SetPositions(kin.context, kin.plant.GetPositions(kin.context))
    query = kin.plant.get_geometry_query_input_port().Eval(kin.context)
    pairs = query.ComputeSignedDistancePairwiseClosestPoints(0.01)
    if pairs and min(p.distance for p in pairs) < -MAX_PENETRATION - 5e-4:
        return False
    up_height = [kin.plant.CalcRelativeTransform(kin.context, kin.up_frame, f).translation()[2]
                 for f in kin.tip_frames]
    if min(up_height) + kin.support[1] <= 0.002:
        return False
    X_UB = kin.plant.CalcRelativeTransform(kin.context, kin.up_frame, kin.forearm)
    forearm = min((X_UB @ p_B)[2] for p_B in kin.forearm_axis_B) + kin.support[1]
    if forearm <= kin.forearm_radius - 0.002:
        return False
    return kin.table_clearance()[0] > -TABLE_TOLERANCE


def _world_grasp_frame(kind: str, X_WO: RigidTransform, up_G=None, row_O=(1.0, 0.0, 0.0)
                       ) -> np.ndarray:
    """R_WG with ``R_WG up_G = z_W`` and the finger row y_G along the object's row axis.

    Row axis: a cylinder's axis, a cuboid's width edge (x_O); a sphere has
    none (any horizontal direction; the caller then turns the yaw). Raises
    ValueError if the object is not in an orientation the planner supports.
    """
    R_WO = X_WO.rotation().matrix()
    z_W = np.array([0.0, 0.0, 1.0])
    if kind == "sphere":
        row = np.array([0.0, 1.0, 0.0])
    elif kind == "cylinder":
        row = R_WO[:, 2]
        if abs(row @ z_W) > np.sin(np.deg2rad(2.0)):
            raise ValueError(
                "the planner grasps a cylinder lying on its side (axis horizontal); "
                f"its axis is {np.rad2deg(np.arcsin(min(1.0, abs(row @ z_W)))):.1f} deg from "
                "horizontal (use planning.resting_pose)"
            )
    else:
        if abs(abs(R_WO[:, 2] @ z_W) - 1.0) > 1e-3:
            raise ValueError(
                f"the planner grasps a {kind} standing on a face with its z axis vertical "
                "(use planning.resting_pose)"
            )
        row = R_WO @ np.asarray(row_O, dtype=float)
    if up_G is None:
        up_G = np.array([1.0, 0.0, 0.0])
    e1 = np.asarray(up_G, dtype=float) / np.linalg.norm(up_G)
    e2 = np.array([0.0, 1.0, 0.0]) - e1[1] * e1
    if np.linalg.norm(e2) < 1e-6:  # only a sphere can have y_G vertical
        e2 = np.array([0.0, 0.0, 1.0]) - e1[2] * e1
    e2 /= np.linalg.norm(e2)
    f2 = row - (row @ z_W) * z_W
    f2 /= np.linalg.norm(f2)
    E = np.column_stack([e1, e2, np.cross(e1, e2)])
    F = np.column_stack([z_W, f2, np.cross(z_W, f2)])
    return F @ E.T


def _row_axis(spec) -> tuple[float, float, float]:
    """The finger row's axis in O: x_O (a cuboid's width), or the wider horizontal axis of
    a mesh or an instrumented device."""
    if _on_bounding_box(spec.kind):
        ex, ey = _extents(spec)[:2]
        return (1.0, 0.0, 0.0) if ex >= ey else (0.0, 1.0, 0.0)
    return (1.0, 0.0, 0.0)


def _yaw(R: np.ndarray, psi: float) -> np.ndarray:
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R


def _canonical_R_PG(a_P) -> RotationMatrix:
    """Grasp frame G in the palm: ``x_G = -a_P`` (world up when the hand comes
    in along its approach), the opposition axis ``z_G`` the proximal direction
    ``-z_P`` made orthogonal to it, ``y_G = z_G x x_G`` (the finger row)."""
    x = -np.asarray(a_P, dtype=float) / np.linalg.norm(a_P)
    z = np.array([0.0, 0.0, -1.0]) - (x @ [0.0, 0.0, -1.0]) * x
    if np.linalg.norm(z) < 1e-6:
        z = np.array([0.0, 1.0, 0.0]) - x[1] * x
    z /= np.linalg.norm(z)
    return RotationMatrix(np.column_stack([x, np.cross(z, x), z]))


def _with_joints(q, joints: dict, ratio: float) -> np.ndarray:
    """A copy of posture q (24,) with some joints set (J1 follows a set J2)."""
    q = np.array(q, dtype=float)
    for name, value in joints.items():
        q[_NAMES.index(name)] = value
        if name.endswith("J2") and not name.startswith("TH"):
            q[_NAMES.index(name[:-1] + "1")] = ratio * value
    return q


def plan_grasp(
    grasp_class,
    obj,
    X_WO: RigidTransform,
    synergies: ClassSynergies | None = None,
    table_height: float = 0.0,
    standoff: float = 0.06,
    reach_direction=(1.0, 0.0),
    coupling_ratio: float = 1.0,
    lift_height: float = 0.13,
    vertical_standoff: bool = True,
    time_budget: float | None = None,
    cache: bool = True,
    database=None,
    search: bool = True,
) -> GraspPlan:
    """Plan a grasp of class ``grasp_class`` on ``obj`` at ``X_WO`` (see module doc).

    obj: an ``ObjectSpec`` (sphere, cylinder, cuboid), ``(kind, size)`` or a
      ``MeshObjectSpec`` (planned on its bounding box; see the module doc).
    synergies: :class:`ClassSynergies` (default: fitted on the shipped data).
    table_height: world z (m) of the table top under the object.
    reach_direction: preferred horizontal direction (world x, y) the hand
      reaches in (the forearm trails behind it); used to pick the hand's yaw
      among the object's symmetric grasps.
    time_budget: seconds the hand-IK search may take (None: no bound; may overrun one solve).
    cache: reuse an earlier call's exact answer (same class, object kind and
      dimensions, height above the table, coupling ratio; default synergies only).
    database: a :class:`~handle_drake.grasp.database.GraspDatabase` (or any mapping
      with ``get(key, default)`` of :func:`grasp_key` to :class:`ObjectFrameGrasp`
      or None) consulted before searching (default synergies only); its stored
      grasp is the one a fresh search gives. With ``nearest(key)`` (a
      GraspDatabase), a key it lacks gets the nearest stored grasp of the class and
      kind adapted (:func:`adapt_grasp`; bounded by its iterations, not by
      ``time_budget``) before any search.
    search: False: only a cached, stored or adapted grasp; GraspPlanningError
      instead of a search.

    Raises:
        ValueError: unknown class, object kind or size outside the class's
            range ("too large"/"too small"), an object not resting on its
            supported orientation, a target outside the wrist's travel.
        GraspPlanningError (a ValueError): no collision-free posture puts the
            class's contacts on the object from above the table.
            GraspPlanningTimeout (a GraspPlanningError): the search ran out of
            ``time_budget``.
    """
    info = grasp_info(grasp_class)
    deadline = _deadline(time_budget)
    spec = _object_spec(obj)
    if not isinstance(X_WO, RigidTransform):
        raise TypeError(f"X_WO must be a RigidTransform, got {type(X_WO).__name__}")
    shape, dims = grasp_dims(spec)
    size = check_size(info.grasp_class, dims[0])
    height = _height_above_table(X_WO, table_height)
    _check_distances(standoff=standoff, lift_height=lift_height)
    reach = _horizontal_unit(reach_direction)
    row_O = _row_axis(spec)
    _world_grasp_frame(spec.kind, X_WO, row_O=row_O)  # validates the resting orientation early

    key = grasp_key(info.grasp_class, spec, height, coupling_ratio)
    found = _known_grasp(key, synergies, cache, database)
    if found is _MISSING and synergies is None and hasattr(database, "nearest"):
        found = _adapted_grasp(database, key, info, spec, size, height, coupling_ratio,
                               cache, search)
    if found is _MISSING and not search:
        raise GraspPlanningError(
            f"no stored {info.name} grasp of a {spec.kind} to use or adapt (not searched)")
    if found is _MISSING:
        found = _searched_grasp(key, info, spec, shape, dims, size, height, synergies,
                                coupling_ratio, deadline, time_budget, cache)
    if found is None:
        raise GraspPlanningError(
            f"unreachable: no collision-free {info.name} grasp puts the "
            f"{'/'.join(info.fingers)} contacts on this {spec.kind} (grasp width "
            f"{size * 100:.1f} cm) from above the table with the approach of Table 2"
        )
    return place_grasp(found, info.grasp_class, spec, size, X_WO, table_height, reach,
                       standoff, lift_height, vertical_standoff, coupling_ratio, row_O)


_MISSING = object()  # no stored answer for a key


def _known_grasp(key, synergies, cache, database):
    """The answer for ``key`` already at hand (default synergies only): this process's
    cache first (with ``cache``), else ``database``'s entry; ``_MISSING`` if neither
    has it (an entry may be None: no grasp of the class exists)."""
    if synergies is not None:
        return _MISSING
    if cache and key in _SOLUTION_CACHE:
        return _SOLUTION_CACHE[key]
    if database is not None:
        return database.get(key, _MISSING)
    return _MISSING


def _adapted_grasp(database, key, info, spec, size, height, coupling_ratio, cache, search):
    """The nearest stored grasp of ``key``'s class and kind (``database.nearest``)
    adapted to this object (:func:`adapt_grasp`, memoised with ``cache``), or
    ``_MISSING`` (nothing stored near, or it did not adapt and ``search`` may search
    instead); a GraspPlanningError when it did not adapt and ``search`` is False."""
    # Another size or height of the same class and kind is stored: adapted to this
    # one by one seeded IK solve and checked (adapt_grasp), not searched.
    near = database.nearest(key)
    if near is None:
        return _MISSING
    # Bounded by its solves' iterations (ADAPT_ITERATIONS), not by the clock:
    # the grasp a pick takes does not depend on the machine's load.
    memo = (key, near.key, id(database))
    if not cache or memo not in _ADAPTED_CACHE:
        if len(_ADAPTED_CACHE) >= _SOLUTION_CACHE_SIZE:
            _ADAPTED_CACHE.pop(next(iter(_ADAPTED_CACHE)))
        _ADAPTED_CACHE[memo] = adapt_grasp(near, info.grasp_class, spec, height,
                                           coupling_ratio)
    adapted = _ADAPTED_CACHE[memo]
    if adapted is None and not search:
        raise GraspPlanningError(
            f"the stored {info.name} grasp of a {spec.kind} (grasp width "
            f"{near.key[4][0] * 100:.1f} cm) does not adapt to a grasp width of "
            f"{size * 100:.1f} cm (not searched)")
    return _MISSING if adapted is None else adapted


def _searched_grasp(key, info, spec, shape, dims, size, height, synergies, coupling_ratio,
                    deadline, time_budget, cache):
    """A fresh search's answer (:func:`_object_frame_grasp`), kept in this process's
    cache with ``cache`` and the default synergies."""
    found = _object_frame_grasp(key, info, spec, shape, dims, size, height, synergies,
                                coupling_ratio, deadline, time_budget)
    if cache and synergies is None:
        if len(_SOLUTION_CACHE) >= _SOLUTION_CACHE_SIZE:
            _SOLUTION_CACHE.pop(next(iter(_SOLUTION_CACHE)))
        _SOLUTION_CACHE[key] = found
    return found


def object_frame_grasp(grasp_class, obj, height: float, coupling_ratio: float = 1.0,
                       time_budget: float | None = None) -> ObjectFrameGrasp | None:
    """The planner's pose-invariant answer for ``obj`` resting ``height`` above the
    table (its centre), searched afresh (no cache; default synergies): what a grasp
    database stores. None when no grasp of the class exists; raises
    :class:`GraspPlanningTimeout` past ``time_budget``."""
    info = grasp_info(grasp_class)
    deadline = _deadline(time_budget)
    spec = _object_spec(obj)
    shape, dims = grasp_dims(spec)
    size = check_size(info.grasp_class, dims[0])
    key = grasp_key(info.grasp_class, spec, height, coupling_ratio)
    return _object_frame_grasp(key, info, spec, shape, dims, size, float(height), None,
                               coupling_ratio, deadline, time_budget)


def _object_frame_grasp(key, info, spec, shape, dims, size, height, synergies,
                        coupling_ratio, deadline, time_budget):
    """The hand-IK search and the pre-shape and close of its answer (None: no grasp)."""
    synergies = default_synergies() if synergies is None else synergies
    if not isinstance(synergies, ClassSynergies):
        raise TypeError(f"synergies must be ClassSynergies, got {type(synergies).__name__}")
    amplitudes = synergies.amplitudes(info.grasp_class, size)
    priors, priors_refine = _posture_priors(info.grasp_class, synergies, amplitudes,
                                            coupling_ratio)
    c_table1 = grasp_centre_palm(info.grasp_class, size)
    a_P = approach_palm(info.grasp_class)
    found = _solve_contacts(info, spec.kind, shape, dims, height, priors, priors_refine,
                            c_table1, a_P, coupling_ratio, deadline)
    if found is _TIMED_OUT:
        raise GraspPlanningTimeout(
            f"time budget: the {info.name} search took over {time_budget:.1f} s "
            f"without a grasp")
    if found is None:
        return None
    sol, up, source, kin = found
    # The forearm is welded at the IK plant's world origin, wrist joints at 0.
    kin.fingertip_positions(sol.q)
    X_BP = kin.palm.CalcPoseInWorld(kin.context)
    q_grasp, q_pre, q_close = _preshape_and_close(kin, sol, info.grasp_class, up,
                                                  coupling_ratio)
    return ObjectFrameGrasp(
        key=key, X_PG=sol.X_PO, up_G=np.asarray(up, dtype=float), centre_source=source,
        X_BP=X_BP, q_grasp=q_grasp, q_pre=q_pre, q_close=q_close,
        contact_error=float(sol.contact_error), amplitudes=amplitudes,
        grasp_amplitudes=synergies.synergies.positions_to_amplitudes(q_grasp))


#: How far (rad) any joint of an adapted grasp may move from the stored grasp's posture:
#: beyond it the adapted posture is another grasp than the one the database holds (and
#: the pick runs validated), so the request is searched instead.
ADAPT_MAX_JOINT_CHANGE = 0.35
#: How far (m) the object centre may move in the palm from the stored grasp's.
ADAPT_MAX_CENTRE_SHIFT = 0.015
#: SNOPT's major iterations per stage of an adaptation's solve: seeded next to its
#: answer, the solve is judged by the planner's own acceptance test, not by SNOPT's
#: convergence flag (a full-row parallel extension on a 6.5 cm cuboid took 4.6 s to
#: converge at 400 iterations and was acceptable after 30, in 0.5 s).
ADAPT_ITERATIONS = 30


def adapt_grasp(stored: ObjectFrameGrasp, grasp_class, obj, height: float,
                coupling_ratio: float = 1.0, deadline: float | None = None,
                ) -> ObjectFrameGrasp | None:
    """A stored grasp (``stored``: the same class and kind at another size or height
    above the table) moved onto ``obj`` resting ``height`` above the table: the
    search's last IK problem (the contacts of the stored grasp's layout on the new
    surface, pads facing it, no penetration beyond ``MAX_PENETRATION``, the whole
    hand above the table, the approach within ``MAX_APPROACH_ANGLE`` of down, the
    centre pulled to the stored one) solved once, seeded with the stored posture and
    object pose in the palm; then the pre-shape and the close as for a searched
    grasp. The quality test: the planner's own acceptance (:func:`_acceptable`:
    contacts within ``MAX_CONTACT_ERROR`` of the surface, penetration, the tips and
    forearm above the table), each joint within ``ADAPT_MAX_JOINT_CHANGE`` and the
    centre within ``ADAPT_MAX_CENTRE_SHIFT`` of the stored grasp (the same grasp,
    not another one the solver wandered to). Returns the adapted grasp (its
    ``adapted_from`` the stored key) or None. ``deadline``: ``time.perf_counter()``
    after which no further solve starts (a solve itself is bounded by
    ``ADAPT_ITERATIONS``; Drake's SNOPT did not honour its ``Time limit`` option: a
    0.3 s limit let a solve run 10 s)."""
    info = grasp_info(grasp_class)
    spec = _object_spec(obj)
    shape, dims = grasp_dims(spec)
    size = check_size(info.grasp_class, dims[0])
    key = grasp_key(info.grasp_class, spec, height, coupling_ratio)
    if stored.key[1:4] != key[1:4]:
        raise ValueError(f"adapt_grasp: a stored {stored.key[1]} grasp of a {stored.key[2]} "
                         f"cannot serve a {key[1]} grasp of a {key[2]}")
    up = np.asarray(stored.up_G, dtype=float)
    kin = _kinematics(float(coupling_ratio), shape, tuple(dims), tuple(np.round(up, 6)),
                      float(height))
    a_P = approach_palm(info.grasp_class)
    centre = stored.X_PG.translation()
    for row_fingers, pad_tilt in _stored_layouts(kin, info, stored, shape):
        if _out_of_time(deadline):
            return None
        sol = kin.solve_grasp(
            info.grasp_class, shape, dims, stored.q_grasp, approach_P=a_P,
            X_PO_guess=stored.X_PG, min_distance=-MAX_PENETRATION,
            max_approach_angle=MAX_APPROACH_ANGLE, centre_prior_weight=100.0,
            p_PO_guess=centre, row_fingers=row_fingers, max_pad_tilt=pad_tilt,
            max_iterations=ADAPT_ITERATIONS)
        if not _acceptable(kin, sol):
            continue
        if np.max(np.abs(sol.q - stored.q_grasp)) > ADAPT_MAX_JOINT_CHANGE or \
                np.linalg.norm(sol.X_PO.translation() - centre) > ADAPT_MAX_CENTRE_SHIFT:
            continue
        kin.fingertip_positions(sol.q)
        X_BP = kin.palm.CalcPoseInWorld(kin.context)
        q_grasp, q_pre, q_close = _preshape_and_close(kin, sol, info.grasp_class, up,
                                                      coupling_ratio)
        synergies = default_synergies()
        return ObjectFrameGrasp(
            key=key, X_PG=sol.X_PO, up_G=up, centre_source=stored.centre_source, X_BP=X_BP,
            q_grasp=q_grasp, q_pre=q_pre, q_close=q_close,
            contact_error=float(sol.contact_error),
            amplitudes=synergies.amplitudes(info.grasp_class, size),
            grasp_amplitudes=synergies.synergies.positions_to_amplitudes(q_grasp),
            adapted_from=stored.key)
    return None


def _stored_layouts(kin, info, stored: ObjectFrameGrasp, shape):
    """``(row_fingers, pad_tilt)`` the stored grasp was most likely solved with, first:
    the parallel extension's row whose contacts lie nearest the stored object's
    surface (its layout is not stored), then the other pad setting on a round object."""
    dims0 = stored.key[4]
    rows = [None]
    if info.grasp_class is GraspClass.PARALLEL_EXTENSION:
        k = sum(1 for t in contact_layout(info.grasp_class, shape, dims0) if t.normal[2] < 0)
        errors = {n: kin.surface_error(stored.q_grasp, info.grasp_class, shape, dims0,
                                       stored.X_PG, contact_layout(
                                           info.grasp_class, shape, dims0, on_table=True,
                                           row_fingers=n))
                  for n in range(k, 0, -1)}
        best = min(errors.values())
        rows = [n for n in range(k, 0, -1) if errors[n] <= best + 2e-4][:1]
    tilts = (None, PAD_TILT) if shape in ("sphere", "cylinder") else (None,)
    return [(r, t) for t in tilts for r in rows]


def place_grasp(grasp: ObjectFrameGrasp, grasp_class, spec, size, X_WO, table_height,
                reach, standoff, lift_height, vertical_standoff, coupling_ratio, row_O
                ) -> GraspPlan:
    """The :class:`GraspPlan` of a pose-invariant grasp on the object at ``X_WO``."""
    a_P = approach_palm(grasp_class)
    X_WG, X_WP, X_WB, X_WB_pre, approach_W = _hand_poses(
        grasp, spec.kind, X_WO, a_P, reach, standoff, lift_height, vertical_standoff,
        row_O)
    return GraspPlan(
        grasp_class=grasp_class, object_spec=spec, grasp_size=size, X_WO=X_WO,
        X_WG=X_WG, X_WP=X_WP, X_WB=X_WB, X_WB_pregrasp=X_WB_pre, approach_W=approach_W,
        q_grasp=grasp.q_grasp.copy(), preshape_command=_command(grasp.q_pre),
        grasp_command=_command(grasp.q_grasp), close_command=_command(grasp.q_close),
        amplitudes=None if grasp.amplitudes is None else grasp.amplitudes.copy(),
        grasp_amplitudes=grasp.grasp_amplitudes.copy(),
        p_PC_table1=grasp_centre_palm(grasp_class, size),
        p_PC=grasp.X_PG.translation().copy(), centre_source=grasp.centre_source,
        contact_error=grasp.contact_error, table_height=float(table_height),
        lift_height=float(lift_height), coupling_ratio=float(coupling_ratio),
        adapted_from=grasp.adapted_from,
    )


def _check_distances(**distances: float) -> None:
    for name, value in distances.items():
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive distance (m), got {value}")


def _deadline(time_budget: float | None) -> float | None:
    """The ``time.perf_counter()`` by which a search must stop (None: no bound)."""
    if time_budget is not None and not (np.isfinite(time_budget) and time_budget > 0):
        raise ValueError(f"time_budget must be a positive number of seconds, got {time_budget}")
    return None if time_budget is None else time.perf_counter() + float(time_budget)


def _height_above_table(X_WO: RigidTransform, table_height: float) -> float:
    height = float(X_WO.translation()[2] - table_height)
    if not np.isfinite(height) or height <= 0:
        raise ValueError(
            f"the object centre must be above the table top ({table_height} m), "
            f"got z = {X_WO.translation()[2]:.4f} m"
        )
    return height


def _horizontal_unit(reach_direction) -> np.ndarray:
    reach = np.asarray(reach_direction, dtype=float)
    if reach.shape != (2,) or not np.isfinite(reach).all() or np.linalg.norm(reach) == 0:
        raise ValueError(f"reach_direction: expected a non-zero (x, y), got {reach_direction}")
    return np.r_[reach / np.linalg.norm(reach), 0.0]


def _posture_priors(grasp_class, synergies: ClassSynergies, amplitudes, coupling_ratio):
    """IK seeds: the synergy pre-shape (if the class has data) and the class prior; for the
    refined (free-centre) attempts also two perturbed class priors. The planner's own
    joint settings of the class (``PLANNER_POSTURES``) apply to all."""

    class_prior = posture_prior(grasp_class, coupling_ratio)
    priors = []
    if amplitudes is not None:
        priors.append(synergies.synergies.amplitudes_to_positions(amplitudes))
    priors.append(class_prior)
    rng = np.random.default_rng(0)
    priors_refine = priors + [class_prior + rng.normal(scale=0.1, size=class_prior.size)
                              for _ in range(2)]
    override = PLANNER_POSTURES.get(grasp_class, {})
    priors = [_with_joints(p, override, coupling_ratio) for p in priors]
    priors_refine = [_with_joints(p, override, coupling_ratio) for p in priors_refine]
    return priors, priors_refine


_TIMED_OUT = object()  # _solve_contacts's answer when the deadline passed


def _out_of_time(deadline) -> bool:
    return deadline is not None and time.perf_counter() > deadline


def _solve_contacts(info, kind, shape, dims, height, priors, priors_refine, c_table1, a_P,
                    coupling_ratio, deadline=None):
    """``(solution, up_G, centre source, kinematics)`` of the first acceptable IK, None,
    or ``_TIMED_OUT`` when ``deadline`` (``time.perf_counter()``) passed before one.

    The parallel extension first with its whole row of fingers on the object
    (on a sphere, the fingers that fit: ``contact_layout``), then, while there
    is no solution, with one outer finger fewer (a cuboid narrower than the
    66 mm row, as a hand holds a thin card between the thumb and two fingers).
    """
    rows = [None]
    if info.grasp_class is GraspClass.PARALLEL_EXTENSION:
        k = sum(1 for t in contact_layout(info.grasp_class, shape, dims) if t.normal[2] < 0)
        rows = list(range(k, 0, -1))
    # On a round object, a second pass with each pad tangent to the surface
    # (``max_pad_tilt``): it finds grasps of small balls the first pass cannot
    # (a pad meeting the ball with its edge), and the first pass keeps the
    # plans it always made.
    tilts = (None, PAD_TILT) if shape in ("sphere", "cylinder") else (None,)
    for pad_tilt in tilts:
        for row_fingers in rows:
            found = _solve_layout(info, kind, shape, dims, height, priors, priors_refine,
                                  c_table1, a_P, coupling_ratio, row_fingers, pad_tilt,
                                  deadline)
            if found is not None:
                return found
    return None


def _solve_layout(info, kind, shape, dims, height, priors, priors_refine, c_table1, a_P,
                  coupling_ratio, row_fingers, pad_tilt=None, deadline=None):
    """:func:`_solve_contacts` for one layout (``row_fingers``: ``contact_layout``).

    Canonical attempts first: the hand comes in along its Table 2 approach
    within a narrow cone, with the grasp frame guessed from the palm
    (x_G = up = -a_P, the thumb on the proximal side, z_G ~ -z_P). Seeded
    from an identity orientation instead, SNOPT settles in a basin with the
    thumb flat in the palm plane (THJ4 = 0) and the hand tilted to the edge of
    the cone; such grasps do not hold (the thumb never meets the object).

    Then, per attempt: (1) a free solve (no table) gives the hand's natural
    orientation about the object; (2) "up" is chosen in G from it (the
    reverse of its approach direction, restricted to what the object's
    resting pose allows) and the problem is solved again with the table and
    the approach cone.
    """
    up_canonical = np.array([1.0, 0.0, 0.0])
    kin_canonical = _kinematics(float(coupling_ratio), shape, tuple(dims),
                                tuple(up_canonical), height)
    X_PG_guess = RigidTransform(_canonical_R_PG(a_P), c_table1)
    for prior in priors:
        if _out_of_time(deadline):
            return _TIMED_OUT
        sol = kin_canonical.solve_grasp(
            info.grasp_class, shape, dims, prior, approach_P=a_P, X_PO_guess=X_PG_guess,
            min_distance=-MAX_PENETRATION, max_approach_angle=CANONICAL_APPROACH_ANGLE,
            centre_prior_weight=100.0, p_PO_guess=c_table1, row_fingers=row_fingers,
            max_pad_tilt=pad_tilt)
        if _acceptable(kin_canonical, sol):
            source = "table1" if np.linalg.norm(sol.X_PO.translation() - c_table1) < 1e-3 \
                else "refined"
            return sol, up_canonical, source, kin_canonical
    attempts = [(p, "table1") for p in priors] + [(p, "refined") for p in priors_refine]
    free_kin = _kinematics(float(coupling_ratio), shape, tuple(dims), None, None)
    for prior, source in attempts:
        if _out_of_time(deadline):
            return _TIMED_OUT
        kw = dict(fix_p_PO=c_table1) if source == "table1" else dict(
            centre_prior_weight=100.0, p_PO_guess=c_table1)
        free = free_kin.solve_grasp(info.grasp_class, shape, dims, prior, min_distance=None,
                                    row_fingers=row_fingers, max_pad_tilt=pad_tilt, **kw)
        if not (free.success and free.contact_error < 1.5e-3):
            continue
        if _out_of_time(deadline):
            return _TIMED_OUT
        up = _up_in_grasp_frame(kind, -(free.X_PO.rotation().inverse().multiply(a_P)))
        kin = _kinematics(float(coupling_ratio), shape, tuple(dims), tuple(np.round(up, 6)),
                          height)
        sol = kin.solve_grasp(info.grasp_class, shape, dims, free.q, approach_P=a_P,
                              X_PO_guess=free.X_PO, min_distance=-MAX_PENETRATION,
                              max_approach_angle=MAX_APPROACH_ANGLE, row_fingers=row_fingers,
                              max_pad_tilt=pad_tilt,
                              **kw)
        if _acceptable(kin, sol):
            return sol, up, source, kin
    return None


def _hand_poses(grasp, kind, X_WO, a_P, reach, standoff, lift_height,
                vertical_standoff, row_O=(1.0, 0.0, 0.0)):
    """``(X_WG, X_WP, X_WB, X_WB_pregrasp, approach_W)`` of an :class:`ObjectFrameGrasp`
    on the object at ``X_WO``.

    Raises ValueError when the base's grasp or stand-off pose (with the lift) is
    outside the floating wrist's travel.
    """
    X_PG, up = grasp.X_PG, grasp.up_G
    R_GP = X_PG.rotation().inverse().matrix()
    R_WG = _world_grasp_frame(kind, X_WO, up, row_O=row_O)
    forearm_W = R_WG @ R_GP @ np.array([0.0, 0.0, -1.0])  # palm -> forearm direction
    if kind == "sphere":
        h = forearm_W[:2]
        if np.linalg.norm(h) > 1e-6:
            R_WG = _yaw(R_WG, np.arctan2(-reach[1], -reach[0]) - np.arctan2(h[1], h[0]))
    elif forearm_W @ -reach < 0:  # the object's symmetric twin: half a turn about vertical
        R_WG = _yaw(R_WG, np.pi)
    X_WG = RigidTransform(RotationMatrix(R_WG), X_WO.translation())
    X_WP = X_WG @ X_PG.inverse()
    X_WB = X_WP @ grasp.X_BP.inverse()
    approach_W = X_WP.rotation().multiply(a_P)
    retreat = -approach_W if not vertical_standoff else np.array([0.0, 0.0, 1.0])
    X_WB_pre = RigidTransform(X_WB.rotation(), X_WB.translation() + standoff * retreat)
    for name, X in (("grasp", X_WB), ("pre-grasp", X_WB_pre)):
        p = X.translation()
        if np.any(np.abs(p) > WRIST_RANGE) or p[2] + lift_height > WRIST_RANGE:
            raise ValueError(
                f"unreachable pose: the hand base {name} target {np.round(p, 3).tolist()} m "
                f"(and the lift) is outside the floating wrist's travel of +-{WRIST_RANGE} m"
            )
    return X_WG, X_WP, X_WB, X_WB_pre, approach_W


def _finger(body_name: str) -> str:
    """The finger (``ff``, ``mf``, ``rf``, ``lf``, ``th``) a hand body belongs to, from its
    name (``ffmiddle``, ``lfmetacarpal``, ``thbase``...; ``palm`` gives ``pa``)."""
    return body_name[:2]


def _contact_moves(sol, grasp_class, up) -> tuple[dict, np.ndarray]:
    """``({finger: (part, outward direction in P)}, up in P)``: the directions along which
    the pre-shape opens and the close squeezes each of the class's fingers.

    Opening and squeezing act in the horizontal plane (the outward contact
    normal with its vertical part removed). The class's fingers left out of the
    layout on this object (a parallel extension's row beyond a small sphere)
    open and close with their row.
    """
    R_PG = sol.X_PO.rotation().matrix()
    up_P = R_PG @ up
    normals = {}
    for t in sol.layout:
        n = R_PG @ np.asarray(t.normal, dtype=float)
        n_h = n - (n @ up_P) * up_P
        normals[t.finger] = (t.part, n_h / np.linalg.norm(n_h) if np.linalg.norm(n_h) > 0.2
                             else n)
    row = next((normals[t.finger] for t in sol.layout if t.normal[2] < 0), None)
    for spec in grasp_info(grasp_class).contacts:
        if spec.finger not in normals and row is not None:
            normals[spec.finger] = (spec.part, row[1])
    return normals, up_P


def _opened(kin, sol, normals, up_P, coupling_ratio, step: dict):
    """``(posture, fingers in the table, fingers into the object or the hand)`` of the
    pre-shape with each finger at its ``PRESHAPE_STEPS[step[finger]]``."""
    moves = {}
    for f, (part, n) in normals.items():
        opening, lift = PRESHAPE_STEPS[step[f]]
        moves[f] = (part, opening * n + lift * up_P)
    q = move_contacts(kin, sol.q, moves, coupling_ratio)
    kin.set_posture(q, sol.X_PO)
    table, others = kin.collisions(MAX_PENETRATION, TABLE_TOLERANCE)
    return q, {_finger(n) for n in table}, {_finger(n) for n in others}


def _preshape(kin, sol, normals, up_P, coupling_ratio) -> np.ndarray:
    """The pre-shape: each contact finger at the first of ``PRESHAPE_STEPS`` (lifted
    higher, then opened less) that touches nothing, else the first that clears the
    table (pressed against a neighbour whichever way it opens), else the first;
    each finger chooses on its own (a collision is charged to the fingers whose
    bodies it involves)."""
    tried = {}  # step -> (posture, table fingers, other fingers), every finger at it
    for i in range(len(PRESHAPE_STEPS)):
        tried[i] = _opened(kin, sol, normals, up_P, coupling_ratio, dict.fromkeys(normals, i))
    final = {}
    for f in normals:
        clean = [i for i, (_, table, others) in tried.items() if f not in table | others]
        clear = [i for i, (_, table, _) in tried.items() if f not in table]
        final[f] = (clean or clear or [0])[0]
    steps = set(final.values())
    if len(steps) == 1:
        return tried[steps.pop()][0]
    return _opened(kin, sol, normals, up_P, coupling_ratio, final)[0]


def _closing(kin, sol, normals, up_P, coupling_ratio) -> np.ndarray:
    """The closing command, ``CLOSING_SQUEEZE`` in along each finger's direction; a
    finger whose squeeze past the object swings it down into the table (a lateral
    tripod's middle finger on a small sphere pressed the table at 20 N before it
    reached the sphere) closes a little upward, ``CLOSE_LIFTS`` in turn."""
    lifts = dict.fromkeys(normals, CLOSE_LIFTS[0])
    for k in range(len(CLOSE_LIFTS)):
        moves = {f: (part, -CLOSING_SQUEEZE * n + lifts[f] * up_P)
                 for f, (part, n) in normals.items()}
        q_close = move_contacts(kin, sol.q, moves, coupling_ratio)
        kin.set_posture(q_close, sol.X_PO)
        low = {_finger(n) for n in kin.bodies_in_table(TABLE_TOLERANCE)} & set(normals)
        if not low or k + 1 == len(CLOSE_LIFTS):
            break
        for f in low:
            lifts[f] = CLOSE_LIFTS[k + 1]
    return q_close


# Postures an idle finger (not one of the class's) may take to keep out of the
# working fingers' way: (J3, J2) of its flexion joints, J1 following J2.
IDLE_POSTURES = ((0.0, 0.0), (1.4, 1.4), (0.8, 0.4))


def _clear_idle_fingers(kin, sol, normals, up_P, coupling_ratio) -> np.ndarray:
    """The IK posture with each idle finger (one the class does not use) moved out of
    the way when, in the grasp, the first pre-shape or the closing command, it
    touches a working finger, the object or the table.

    The IK keeps the fingers apart only in the grasp posture (and allows a few
    mm): the pre-shape and the close then drove a tip pinch's first finger
    into the middle finger at several hundred newtons. An idle finger that
    collides keeps the first of its own posture, extended, curled
    (``IDLE_POSTURES``) that collides with nothing in all three postures.
    """
    idle = [f for f in kin.spec.fingers if f not in normals and f != "th"]
    if not idle:
        return sol.q

    def hits(qs, finger):
        for q in qs:
            kin.set_posture(q, sol.X_PO)
            if finger in {_finger(n) for n in set().union(
                    *kin.collisions(MAX_PENETRATION, TABLE_TOLERANCE))}:
                return True
        return False

    first = dict.fromkeys(normals, 0)
    base = (sol.q, _opened(kin, sol, normals, up_P, coupling_ratio, first)[0],
            _closing(kin, sol, normals, up_P, coupling_ratio))
    for finger in idle:
        if not hits(base, finger):
            continue
        for j3, j2 in IDLE_POSTURES:
            joints = {f"{finger.upper()}J3": j3, f"{finger.upper()}J2": j2}
            moved = tuple(_with_joints(q, joints, coupling_ratio) for q in base)
            if not hits(moved, finger):
                base = moved
                break
    kin.set_posture(sol.q, sol.X_PO)
    return base[0]


def _preshape_and_close(kin, sol, grasp_class, up, coupling_ratio):
    """Postures (24,) of the pre-shape (open) and the closing command, along the contact
    normals (:func:`_contact_moves`), and the IK posture with the idle fingers out of
    the way (:func:`_clear_idle_fingers`): ``(q_grasp, q_pre, q_close)``.

    The opening also lifts the contacts a little: a pre-shape that swings a
    fingertip down would hit the table the plan keeps it clear of. Both
    postures are collision checked (:func:`_preshape`, :func:`_closing`).
    """
    normals, up_P = _contact_moves(sol, grasp_class, up)
    q_grasp = _clear_idle_fingers(kin, sol, normals, up_P, coupling_ratio)
    sol = dc.replace(sol, q=q_grasp)
    q_pre = _preshape(kin, sol, normals, up_P, coupling_ratio)
    q_close = _closing(kin, sol, normals, up_P, coupling_ratio)
    kin.set_posture(sol.q, sol.X_PO)
    return q_grasp, q_pre, q_close


def _command(q) -> np.ndarray:
    """The 20-entry command of a 24-joint posture."""
    return np.array([q[_NAMES.index(n)] for n in _ACT])
