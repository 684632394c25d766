"""Forward and inverse kinematics of grasps on simple objects (Shadow hand).

:class:`GraspKinematics` holds a continuous MultibodyPlant of the Shadow hand
(forearm welded to the world, wrist joints held at zero so that the palm
frame P is fixed) plus a free "object" body O. It provides

- forward kinematics of the finger contact points in the palm frame and the
  grasp centre of a posture (report section 3.2.1: the geometric centre of the
  contacts of the class's fingers), and
- :meth:`GraspKinematics.solve_grasp`: a Drake ``InverseKinematics`` problem
  that puts the class's finger contact points on the surface of a sphere,
  cylinder or box *symmetrically about the object centre*, with the finger
  pads facing the object, within joint limits and the J1 = ratio * J2
  coupling, at least cost from a class posture prior.

Grasp frame G (the frame the contact layout is written in): z_G is the
opposition axis (the thumb, or for the adduction grip the first finger, on
+z_G), y_G the direction along which the opposing fingers line up, x_G the
third axis. The IK object body's frame *is* G. A box of dims (w, d, h) spans
z_G: w (the width between the opposing fingers), y_G: d, x_G: h; a cylinder
(diameter, length) has its axis along y_G.

Finger contact points (in the distal link frame, from the model's collision
geometry: capsule radius 8.5 mm, pad boxes 9 mm / 10.5 mm below the axis):
``pad`` faces -y, ``tip`` is the rounded end, ``side`` the radial (thumb-side,
+x) face and ``ulnar_side`` the -x face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Capsule, Cylinder, ProximityProperties, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import JacobianWrtVariable, SpatialInertia
from pydrake.solvers import SnoptSolver, Solve, SolverOptions
from pydrake.systems.framework import DiagramBuilder

from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.base.models import add_package, model_path
from handle_drake.grasp.taxonomy import OBJECT_SHAPES, GraspClass, grasp_centre_palm, grasp_info

__all__ = [
    "CONTACT_POINTS",
    "ContactTarget",
    "GraspKinematics",
    "GraspSolution",
    "contact_layout",
    "move_contacts",
    "object_dims_for",
]

FINGER_SPACING = 0.022  # m, between neighbouring finger knuckles (2 x 11 mm)
_DISTAL = {"th": "thdistal", "ff": "ffdistal", "mf": "mfdistal", "rf": "rfdistal", "lf": "lfdistal"}

# (point in the distal frame, outward surface normal in the distal frame).
CONTACT_POINTS: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
for _f in ("ff", "mf", "rf", "lf"):
    CONTACT_POINTS[(_f, "pad")] = (np.array([0.0, -0.009, 0.019]), np.array([0.0, -1.0, 0.0]))
    CONTACT_POINTS[(_f, "tip")] = (np.array([0.0, -0.006, 0.029]), np.array([0.0, -0.6, 0.8]))
    CONTACT_POINTS[(_f, "side")] = (np.array([0.0085, 0.0, 0.019]), np.array([1.0, 0.0, 0.0]))
    CONTACT_POINTS[(_f, "ulnar_side")] = (np.array([-0.0085, 0.0, 0.019]),
                                          np.array([-1.0, 0.0, 0.0]))
CONTACT_POINTS[("th", "pad")] = (np.array([0.0, -0.0105, 0.020]), np.array([0.0, -1.0, 0.0]))
CONTACT_POINTS[("th", "tip")] = (np.array([0.0, -0.007, 0.031]), np.array([0.0, -0.6, 0.8]))


@dataclass(frozen=True)
class ContactTarget:
    """Where one finger contact goes on the object, in the grasp frame G.

    normal: outward surface normal direction of the face touched (a G axis,
      e.g. +z for the thumb), the finger's contact normal opposes it.
    spread: nominal offset (m) along y_G (fingers side by side).
    """

    finger: str
    part: str
    normal: tuple[float, float, float]
    spread: float = 0.0


def contact_layout(name, shape: str | None = None, dims=None, on_table: bool = False,
                   row_fingers: int | None = None) -> tuple[ContactTarget, ...]:
    """The contact layout of a grasp class in the grasp frame G (symmetric about O).

    on_table: the object rests on a table under it (``x_G`` up). The writing
    tripod's middle finger then supports the object from its ulnar side (the
    ``-y_G`` face, its radial side against it) instead of from below (``-x_G``,
    the face on the table, where no finger fits).

    With the object (``shape``, ``dims``): the parallel extension on a sphere
    keeps only the fingers of its row that fit on the sphere, centred on it (one
    finger per finger spacing of diameter, at least one): four extended fingers
    side by side span 66 mm and cannot all touch a ball, the way a hand holds a
    marble flat between the thumb and one finger. ``row_fingers`` (1-4) sets
    how many of the parallel extension's row fingers touch, centred on the
    object (the planner drops the outer ones when the whole row has no
    solution, e.g. on a cuboid narrower than the row).
    """
    info = grasp_info(name)
    if row_fingers is not None and not (isinstance(row_fingers, int | np.integer)
                                        and 1 <= row_fingers <= 4):
        raise ValueError(f"row_fingers must be an int in 1..4, got {row_fingers!r}")
    if info.grasp_class is GraspClass.PARALLEL_EXTENSION and (
            row_fingers is not None or (shape == "sphere" and dims is not None)):
        k = row_fingers if row_fingers is not None else int(
            np.clip(np.floor(float(np.atleast_1d(dims)[0]) / FINGER_SPACING), 1, 4))
        row = ("mf",) if k == 1 else ("ff", "mf", "rf", "lf")[:k]
        return (ContactTarget("th", "pad", (0.0, 0.0, 1.0)),) + tuple(
            ContactTarget(f, "pad", (0.0, 0.0, -1.0), (0.5 * (k - 1) - i) * FINGER_SPACING)
            for i, f in enumerate(row))
    cls = info.grasp_class
    w = FINGER_SPACING
    up, down, below = (0.0, 0.0, 1.0), (0.0, 0.0, -1.0), (-1.0, 0.0, 0.0)
    c = {(k.finger): k.part for k in info.contacts}
    if cls in (GraspClass.PALMAR_PINCH, GraspClass.TIP_PINCH, GraspClass.LATERAL):
        return (ContactTarget("th", c["th"], up), ContactTarget("ff", c["ff"], down))
    if cls is GraspClass.TRIPOD:
        return (ContactTarget("th", "pad", up), ContactTarget("ff", "pad", down, 0.5 * w),
                ContactTarget("mf", "pad", down, -0.5 * w))
    if cls is GraspClass.WRITING_TRIPOD:
        return (ContactTarget("th", c["th"], up), ContactTarget("ff", c["ff"], down),
                ContactTarget("mf", c["mf"], (0.0, -1.0, 0.0) if on_table else below))
    if cls is GraspClass.LATERAL_TRIPOD:
        # The radial sides of the first and middle fingers side by side against
        # the thumb pad. (The middle-finger pad from below, x_G, is unreachable
        # with the thumb on the first finger's side: no IK solution on any shape.)
        return (ContactTarget("th", "pad", up), ContactTarget("ff", "side", down, 0.5 * w),
                ContactTarget("mf", "side", down, -0.5 * w))
    if cls is GraspClass.ADDUCTION_GRIP:
        return (ContactTarget("ff", "ulnar_side", up), ContactTarget("mf", "side", down))
    if cls is GraspClass.PARALLEL_EXTENSION:
        return (ContactTarget("th", "pad", up),) + tuple(
            ContactTarget(f, "pad", down, s * w)
            for f, s in zip(("ff", "mf", "rf", "lf"), (1.5, 0.5, -0.5, -1.5), strict=True)
        )
    raise AssertionError(cls)  # pragma: no cover - every class is handled above


def object_dims_for(shape: str, size: float, name=None) -> tuple[float, ...]:
    """Default dims (m) of a test object of grasp size ``size`` for a class.

    sphere (diameter,); cylinder (diameter, length); box (width, depth, height).
    The depth (along the finger row) fits the class's fingers.
    """
    if shape not in OBJECT_SHAPES:
        raise ValueError(f"shape must be one of {OBJECT_SHAPES}, got {shape!r}")
    size = float(size)
    if not np.isfinite(size) or size <= 0:
        raise ValueError(f"size must be positive and finite, got {size}")
    n_row = 1
    if name is not None:
        n_row = sum(1 for t in contact_layout(name) if t.normal[2] < 0)
    depth = max(0.05, (n_row + 1) * FINGER_SPACING)
    if shape == "sphere":
        return (size,)
    if shape == "cylinder":
        return (size, max(0.10, depth + 0.02))
    return (size, depth, 0.05)


def _check_dims(shape: str, dims) -> tuple[float, ...]:
    if shape not in OBJECT_SHAPES:
        raise ValueError(f"shape must be one of {OBJECT_SHAPES}, got {shape!r}")
    dims = tuple(float(d) for d in np.atleast_1d(dims))
    expected = {"sphere": 1, "cylinder": 2, "box": 3}[shape]
    if len(dims) != expected or not all(np.isfinite(d) and d > 0 for d in dims):
        raise ValueError(f"dims: a {shape} needs {expected} positive sizes (m), got {dims}")
    return dims


def _object_geometry(shape: str, dims):
    """(X_GS, shape) of the object in the grasp frame G (see the module doc)."""
    if shape == "sphere":
        return RigidTransform(), Sphere(0.5 * dims[0])
    if shape == "cylinder":  # Drake's cylinder axis is its z; G's cylinder axis is y_G
        return RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2)), Cylinder(
            0.5 * dims[0], dims[1])
    w, d, h = dims
    return RigidTransform(), Box(h, d, w)


@dataclass(frozen=True)
class _GraspProblem:
    """The checked arguments of one :meth:`GraspKinematics.solve_grasp`."""

    shape: str
    dims: tuple
    r: float
    q_prior: np.ndarray
    layout: list
    jitters: list
    tolerance: float
    max_pad_angle: float
    max_pad_tilt: float | None
    min_distance: float | None
    check_collisions: bool
    table_clearance: float
    contact_height: float
    hand_clearance: float | None
    approach: np.ndarray | None
    max_approach_angle: float
    centre_prior_weight: float
    p_PO0: np.ndarray
    fix_p_PO: np.ndarray | None


@dataclass
class GraspSolution:
    """A solved grasp: all joints (rad), the object pose in the palm frame, success."""

    q: np.ndarray
    X_PO: RigidTransform
    success: bool
    contact_error: float  # m, worst distance of a contact point from its surface
    layout: tuple = ()  # the ContactTargets solved for (contact_layout)


def _widest_cylinder(plant, inspector, body) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
    """``(radius, (end, end))``: the widest collision cylinder on ``body`` (its
    radius and the two ends of its axis in the body frame)."""
    found = [(inspector.GetShape(g), inspector.GetPoseInFrame(g))
             for g in plant.GetCollisionGeometriesForBody(body)
             if isinstance(inspector.GetShape(g), Cylinder)]
    if not found:
        raise RuntimeError(f"{body.name()}: the model has no collision cylinder on it")
    cylinder, X_BG = max(found, key=lambda f: f[0].radius())
    half = np.array([0.0, 0.0, cylinder.length() / 2])
    return cylinder.radius(), (X_BG @ -half, X_BG @ half)


def _clearance_points(plant, inspector, model, skip=()) -> tuple:
    """``((body frame, points (k, 3), radius), ...)``: the hand's collision shapes as points
    in their body frames, each shape lying within ``radius`` of its points' convex hull
    (exact for a capsule's axis ends and a sphere's centre; a box's corners with radius 0;
    a cylinder's axis ends with its radius, which over-covers its rims)."""
    out = []
    for index in plant.GetBodyIndices(model):
        body = plant.get_body(index)
        if body in skip:
            continue
        for g in plant.GetCollisionGeometriesForBody(body):
            shape, X_BG = inspector.GetShape(g), inspector.GetPoseInFrame(g)
            if isinstance(shape, Capsule | Cylinder):
                half = 0.5 * shape.length()
                p_G, radius = np.array([[0.0, 0.0, -half], [0.0, 0.0, half]]), shape.radius()
            elif isinstance(shape, Sphere):
                p_G, radius = np.zeros((1, 3)), shape.radius()
            elif isinstance(shape, Box):
                h = 0.5 * np.array([shape.width(), shape.depth(), shape.height()])
                p_G = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                for sz in (-1, 1)]) * h
                radius = 0.0
            else:  # pragma: no cover - the shipped hands use only these shapes
                raise NotImplementedError(f"{body.name()}: no clearance points for "
                                          f"{type(shape).__name__}")
            out.append((body.body_frame(), (X_BG @ p_G.T).T, float(radius)))
    return tuple(out)


class GraspKinematics:
    """Kinematics of the Shadow hand for grasp synthesis and analysis (see module doc)."""

    def __init__(self, coupling_ratio: float = 1.0, shape: str | None = None, dims=None,
                 support=None):
        """shape, dims: register the object's collision geometry (frame G), so
        that :meth:`solve_grasp` can keep the hand out of the object and out of
        itself (``min_distance``); without them only kinematics is available.

        support: optional ``(up_G, height)``: the object rests on a table whose
          top lies ``height`` (m) below the object centre along ``-up_G`` (a
          vector in G). A frame ``up_frame`` (z = up) is fixed to the object,
          so :meth:`solve_grasp` can keep the fingertips above the table with
          smooth position bounds, whatever the hand's pose relative to it.
        """
        self.spec = get_hand_spec("shadow")
        self.coupling_ratio = float(coupling_ratio)
        if not np.isfinite(self.coupling_ratio) or self.coupling_ratio <= 0:
            raise ValueError(f"coupling_ratio must be > 0, got {coupling_ratio}")
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        parser = Parser(plant)
        add_package(parser)
        self.hand = parser.AddModels(model_path(self.spec.model_relative_path))[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(self.spec.base_body, self.hand))
        self.object_body = plant.AddRigidBody(
            "grasp_object", plant.AddModelInstance("grasp_object"),
            SpatialInertia.SolidSphereWithMass(0.05, 0.02),
        )
        self.object_frame = self.object_body.body_frame()
        self.shape, self.dims = shape, None
        if shape is not None:
            self.dims = _check_dims(shape, dims)
            X, geometry = _object_geometry(shape, self.dims)
            plant.RegisterCollisionGeometry(
                self.object_body, X, geometry, "grasp_object", ProximityProperties()
            )
        self._add_support(plant, shape, support)
        plant.Finalize()
        self.plant = plant
        self.diagram = builder.Build()
        self.diagram_context = self.diagram.CreateDefaultContext()
        self.context = plant.GetMyMutableContextFromRoot(self.diagram_context)
        self.palm = plant.GetFrameByName("palm", self.hand)
        self.forearm = plant.GetFrameByName(self.spec.base_body, self.hand)
        # The forearm's collision cylinder, as the model declares it: with a
        # support its axis ends stay a radius above the table, so the forearm
        # never reaches into it (a small object grasped with the hand turned
        # flat drove it 40 mm into the table top).
        self.forearm_radius, self.forearm_axis_B = _widest_cylinder(
            plant, scene_graph.model_inspector(), self.forearm.body())
        # Every other collision shape of the hand, as points with a radius: a
        # posture clears the table when each point is its radius above it.
        self.clearance_points = _clearance_points(
            plant, scene_graph.model_inspector(), self.hand, skip=(self.forearm.body(),))
        self.object_frame = self.object_body.body_frame()
        self.q_index = np.array(
            [plant.GetJointByName(n, self.hand).position_start() for n in self.spec.joint_names]
        )
        self.lower = self.spec.joint_lower_limits
        self.upper = self.spec.joint_upper_limits
        self.distal = {
            f: plant.GetBodyByName(b, self.hand).body_frame() for f, b in _DISTAL.items()
        }
        self.tip_frames = [plant.GetFrameByName(n, self.hand) for n in self.spec.fingertip_frames]
        self._wrist = [self.spec.joint_names.index(n) for n in ("WRJ2", "WRJ1")]

    # ---- forward kinematics --------------------------------------------------
    def _check_q(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.spec.num_joints,):
            raise ValueError(f"q: expected shape ({self.spec.num_joints},), got {q.shape}")
        return q

    def _set(self, q) -> None:
        full = self.plant.GetPositions(self.context)
        full[self.q_index] = q
        full[self._wrist_indices()] = 0.0  # the palm frame is the reference: wrist at rest
        self.plant.SetPositions(self.context, full)

    def _wrist_indices(self):
        return self.q_index[self._wrist]

    def contact_points(self, q, name) -> dict[str, np.ndarray]:
        """Contact points ``p_PC`` (m, palm frame) of the class's fingers at posture q."""
        q = self._check_q(q)
        self._set(q)
        out = {}
        for spec in grasp_info(name).contacts:
            p_B, _ = CONTACT_POINTS[(spec.finger, spec.part)]
            out[spec.finger] = self.plant.CalcPointsPositions(
                self.context, self.distal[spec.finger], p_B, self.palm
            ).ravel()
        return out

    def grasp_centre(self, q, name) -> np.ndarray:
        """Report section 3.2.1: geometric centre of the class's finger contacts, palm frame (m).

        For a thumb-vs-fingers grasp the centre lies between the thumb and the
        mean of the opposing fingers (so a four-finger row does not outweigh the
        thumb); supporting side contacts (writing / lateral tripod) do not move it.
        """
        pts = self.contact_points(q, name)
        layout = contact_layout(name)
        plus = [pts[t.finger] for t in layout if t.normal[2] > 0]
        minus = [pts[t.finger] for t in layout if t.normal[2] < 0]
        return 0.5 * (np.mean(plus, axis=0) + np.mean(minus, axis=0))

    def fingertip_positions(self, q) -> dict[str, np.ndarray]:
        """Fingertip frames (spec.fingertip_frames) in the palm frame, m."""
        q = self._check_q(q)
        self._set(q)
        return {
            n: self.plant.GetFrameByName(n, self.hand)
            .CalcPose(self.context, self.palm)
            .translation()
            for n in self.spec.fingertip_frames
        }

    # ---- inverse kinematics --------------------------------------------------
    def _add_support(self, plant, shape, support) -> None:
        """With a support: the table's ``(up_G, height)`` and a frame ``up_frame`` on the
        object with z = up (see the constructor)."""
        self.support = None
        if support is None:
            return
        if shape is None:
            raise ValueError("support needs the object shape and dims")
        up, height = support
        up = np.asarray(up, dtype=float)
        if up.shape != (3,) or not np.isfinite(up).all() or np.linalg.norm(up) < 1e-9:
            raise ValueError(f"support up_G: expected a non-zero 3-vector, got {up}")
        height = float(height)
        if not np.isfinite(height) or height <= 0:
            raise ValueError(f"support height must be > 0 (m), got {height}")
        up = up / np.linalg.norm(up)
        self.support = (up, height)
        # A frame on the object with z = up: "above the table" becomes a
        # smooth bound on a point's z in it (a table geometry under the
        # signed-distance constraint made SNOPT fail on most grasps).
        from pydrake.multibody.tree import FixedOffsetFrame

        self.up_frame = plant.AddFrame(FixedOffsetFrame(
            "grasp_object_up", self.object_frame,
            RigidTransform(RotationMatrix.MakeFromOneVector(up, 2))))

    def solve_grasp(
        self,
        name,
        shape: str,
        dims,
        q_prior,
        rng: np.random.Generator | None = None,
        target_jitter: float = 0.0,
        tolerance: float = 0.004,
        max_pad_angle: float = np.deg2rad(40.0),
        p_PO_guess=None,
        fix_p_PO=None,
        centre_prior_weight: float = 0.0,
        min_distance: float | None = -0.002,
        approach_P=None,
        max_approach_angle: float = np.deg2rad(30.0),
        table_clearance: float = 0.004,
        hand_clearance: float | None = 0.0,
        contact_height: float = 0.0,
        X_PO_guess: RigidTransform | None = None,
        row_fingers: int | None = None,
        max_pad_tilt: float | None = None,
        max_iterations: int = 400,
    ) -> GraspSolution:
        """Postures of class ``name`` holding a (shape, dims) object (see module doc).

        q_prior: (24,) posture prior (cost ``|q - q_prior|^2`` on the finger joints).
        target_jitter: std (m) of a random offset of the contact targets along
          the surface (experimenter variation). tolerance: half-width (m) of the
          region around each target the contact may use.
        fix_p_PO: if given, the object centre is held at this palm-frame point
          (used by the planner to grasp at a Table-1 grasp centre).
        centre_prior_weight: weight (1/m^2) of a cost pulling the object centre
          towards ``p_PO_guess`` (default: the Table 1 grasp centre).
        min_distance: lower bound (m) on the signed distance between any two
          geometries (hand-object and hand-hand); needs the object geometry
          (``shape``/``dims`` in the constructor, the same as here). None: off.
        approach_P: with a ``support`` (constructor), the hand's approach
          direction in the palm frame (Table 2); it is kept within
          ``max_approach_angle`` of "down" (``-up_G``), so that the hand comes
          in from above the table.
        table_clearance: with a support, every fingertip stays this far (m)
          above the table; contact_height: the class's contacts at least this
          much (m) higher still. hand_clearance: with a support, every other
          collision shape of the hand (phalanges, knuckles, palm) stays this far
          (m) above the table (None: unchecked; before, a pinch on a small sphere
          put the middle phalanx 18 mm into the table top).
        X_PO_guess: initial guess of the object pose in the palm frame (e.g. a
          solution without the table), instead of the centre guess.
        row_fingers: see :func:`contact_layout`.
        max_pad_tilt: on a sphere or a cylinder, each contact's pad lies
          tangent to the surface within this angle (rad): the point one radius
          out along the pad's normal stays within ``r sin(max_pad_tilt)`` of the
          centre (sphere) or the axis (cylinder). Without it only the angle to
          the layout's direction was bounded (``max_pad_angle``), and a pad
          touching a small ball away from that direction met it with its edge
          (a 25 mm ball: a pad 6 mm in it and no collision-free IK). None: off.
        max_iterations: SNOPT's major iterations limit of each stage (a seeded
          solve near its answer needs a few dozen).
        """
        g = self._grasp_problem(
            name, shape, dims, q_prior, rng, target_jitter, tolerance, max_pad_angle,
            p_PO_guess, fix_p_PO, centre_prior_weight, min_distance, approach_P,
            max_approach_angle, table_clearance, hand_clearance, contact_height, row_fingers,
            max_pad_tilt)
        return self._solve(name, g, X_PO_guess, int(max_iterations))

    def _solve(self, name, g: _GraspProblem, X_PO_guess,
               max_iterations: int = 400) -> GraspSolution:
        """Two-stage IK of a checked grasp problem from the prior posture."""
        plant = self.plant
        # Initial guess: the prior posture, the object at its expected centre.
        q0 = plant.GetPositions(self.context).copy()
        q0[self.q_index] = np.clip(g.q_prior, self.lower, self.upper)
        self._set(q0[self.q_index])
        X_WP = self.palm.CalcPoseInWorld(self.context)
        if X_PO_guess is not None:
            X_PO0 = X_PO_guess
        else:
            X_PO0 = RigidTransform(g.fix_p_PO if g.fix_p_PO is not None else g.p_PO0)
        plant.SetFreeBodyPose(self.context, self.object_body, X_WP @ X_PO0)
        q0 = plant.GetPositions(self.context).copy()
        # Stage 1 without collision constraints (smooth, fast); stage 2 adds
        # them, starting from stage 1 (the distance constraint is hard to
        # satisfy from a guess where the object overlaps the hand).
        options = SolverOptions()
        # Fail fast: a grasp that needs more iterations is almost always infeasible.
        options.SetOption(SnoptSolver.id(), "Major iterations limit", max_iterations)
        prog, qv = self._build_ik(g, False)
        result = Solve(prog, q0, options)
        if g.check_collisions and result.is_success():
            q1 = result.GetSolution(qv)
            prog, qv = self._build_ik(g, True)
            result = Solve(prog, q1, options)
        q_sol = result.GetSolution(qv)
        plant.SetPositions(self.context, q_sol)
        q = q_sol[self.q_index]
        X_PO = plant.CalcRelativeTransform(self.context, self.palm, self.object_frame)
        err = self.surface_error(q, name, g.shape, g.dims, X_PO, g.layout)
        return GraspSolution(q, X_PO, bool(result.is_success()), err, g.layout)

    def _grasp_problem(self, name, shape, dims, q_prior, rng, target_jitter, tolerance,
                       max_pad_angle, p_PO_guess, fix_p_PO, centre_prior_weight, min_distance,
                       approach_P, max_approach_angle, table_clearance, hand_clearance,
                       contact_height, row_fingers, max_pad_tilt) -> _GraspProblem:
        """:meth:`solve_grasp`'s arguments checked, with the contact layout and jitters."""
        info = grasp_info(name)
        dims = _check_dims(shape, dims)
        q_prior = self._check_q(q_prior)
        rng = rng or np.random.default_rng(0)
        layout = contact_layout(info.grasp_class, shape, dims,
                                on_table=self.support is not None, row_fingers=row_fingers)
        jitters = [target_jitter * rng.normal(size=3) if target_jitter > 0 else np.zeros(3)
                   for _ in layout]
        if p_PO_guess is None:
            p_PO_guess = grasp_centre_palm(info.grasp_class, dims[0])
        p_PO0 = np.asarray(p_PO_guess, dtype=float)
        if p_PO0.shape != (3,):
            raise ValueError(f"p_PO_guess: expected shape (3,), got {p_PO0.shape}")
        if fix_p_PO is not None:
            fix_p_PO = np.asarray(fix_p_PO, dtype=float)
            if fix_p_PO.shape != (3,):
                raise ValueError(f"fix_p_PO: expected shape (3,), got {fix_p_PO.shape}")
        approach = None
        if approach_P is not None:
            approach = np.asarray(approach_P, dtype=float)
            if approach.shape != (3,) or not np.isfinite(approach).all():
                raise ValueError(f"approach_P: expected a finite 3-vector, got {approach}")
            if self.support is None:
                raise ValueError("approach_P needs a support (table) in the constructor")
        check_collisions = min_distance is not None and self.shape is not None
        if check_collisions and (self.shape, self.dims) != (shape, dims):
            raise ValueError(
                f"this GraspKinematics holds a {self.shape} {self.dims}, asked for a "
                f"{shape} {dims}; build one per object to check collisions"
            )
        return _GraspProblem(
            shape=shape, dims=dims, r=0.5 * dims[0], q_prior=q_prior, layout=layout,
            jitters=jitters, tolerance=tolerance, max_pad_angle=max_pad_angle,
            max_pad_tilt=max_pad_tilt, min_distance=min_distance,
            check_collisions=check_collisions, table_clearance=table_clearance,
            contact_height=contact_height, hand_clearance=hand_clearance, approach=approach,
            max_approach_angle=max_approach_angle, centre_prior_weight=centre_prior_weight,
            p_PO0=p_PO0, fix_p_PO=fix_p_PO)

    def _build_ik(self, g: _GraspProblem, with_collisions: bool):
        """The grasp's InverseKinematics program (``with_collisions``: stage 2)."""
        ik = InverseKinematics(self.plant, self.context, with_joint_limits=True)
        prog = ik.get_mutable_prog()
        qv = ik.q()
        for i in self._wrist_indices():
            prog.AddBoundingBoxConstraint(0.0, 0.0, qv[i])
        for follower, leader, _ in self.spec.couplings:
            i = self.q_index[self.spec.joint_names.index(follower)]
            j = self.q_index[self.spec.joint_names.index(leader)]
            prog.AddLinearEqualityConstraint(
                np.array([[1.0, -self.coupling_ratio]]), np.zeros(1), [qv[i], qv[j]]
            )
        fingers = [k for k in range(len(self.q_index)) if k not in self._wrist]
        prog.AddQuadraticErrorCost(
            np.eye(len(fingers)), g.q_prior[fingers], qv[self.q_index[fingers]]
        )
        self._add_contacts(ik, g)
        if with_collisions:
            ik.AddMinimumDistanceLowerBoundConstraint(g.min_distance, 0.01)
        if self.support is not None:
            self._add_table_clearances(ik, g)
        if g.approach is not None:
            ik.AddAngleBetweenVectorsConstraint(
                self.palm, g.approach, self.object_frame, -self.support[0], 0.0,
                float(g.max_approach_angle))
        if g.centre_prior_weight > 0:
            ik.AddPositionCost(self.palm, g.p_PO0, self.object_frame, np.zeros(3),
                               g.centre_prior_weight * np.eye(3))
        if g.fix_p_PO is not None:
            ik.AddPositionConstraint(self.object_frame, np.zeros(3), self.palm,
                                     g.fix_p_PO - 1e-4, g.fix_p_PO + 1e-4)
        return prog, qv

    def _add_contacts(self, ik, g: _GraspProblem) -> None:
        """Each contact of the layout on the surface, its pad facing the object."""
        shape, r = g.shape, g.r
        for t, jitter in zip(g.layout, g.jitters, strict=True):
            p_B, n_B = CONTACT_POINTS[(t.finger, t.part)]
            normal = np.asarray(t.normal, dtype=float)
            self._add_surface_constraint(ik, t, p_B, normal, shape, g.dims, r, g.tolerance,
                                         jitter)
            if g.max_pad_tilt is not None and shape in ("sphere", "cylinder"):
                # The centre of curvature the pad sees, one radius out along its normal.
                p_BC = p_B + r * np.asarray(n_B, dtype=float)
                slack = r * np.sin(float(g.max_pad_tilt))
                if shape == "sphere":
                    ik.AddPointToPointDistanceConstraint(
                        self.distal[t.finger], p_BC, self.object_frame, np.zeros(3), 0.0,
                        slack)
                else:
                    ik.AddPointToLineDistanceConstraint(
                        self.distal[t.finger], p_BC, self.object_frame, np.zeros(3),
                        np.array([0.0, 1.0, 0.0]), 0.0, slack)
            ik.AddAngleBetweenVectorsConstraint(
                self.distal[t.finger], n_B, self.object_frame, -normal, 0.0, g.max_pad_angle
            )

    def _add_table_clearances(self, ik, g: _GraspProblem) -> None:
        """Fingertips, contacts, the rest of the hand and the forearm above the table."""
        big = 10.0
        # Fingertips (tip frame and the end of the distal capsule) and
        # the finger contacts at least table_clearance above the table.
        floor = -self.support[1] + g.table_clearance
        for frame in self.tip_frames:
            for p_B in (np.zeros(3), np.array([0.0, 0.0, 0.006])):
                ik.AddPositionConstraint(frame, p_B, self.up_frame,
                                         [-big, -big, floor], [big, big, big])
        for t in g.layout:
            p_B, _ = CONTACT_POINTS[(t.finger, t.part)]
            ik.AddPositionConstraint(self.distal[t.finger], p_B, self.up_frame,
                                     [-big, -big, floor + g.contact_height],
                                     [big, big, big])
        if g.hand_clearance is not None:
            hand_floor = -self.support[1] + float(g.hand_clearance)
            for frame, points, radius in self.clearance_points:
                for p_B in points:
                    ik.AddPositionConstraint(frame, p_B, self.up_frame,
                                             [-big, -big, hand_floor + radius],
                                             [big, big, big])
        # The forearm too: both ends of its axis a radius above the table
        # (exact for a level forearm, a radius to spare for an upright one).
        for p_B in self.forearm_axis_B:
            ik.AddPositionConstraint(self.forearm, p_B, self.up_frame,
                                     [-big, -big, floor + self.forearm_radius],
                                     [big, big, big])

    def _add_surface_constraint(self, ik, t, p_B, normal, shape, dims, r, tol, jitter):
        frame = self.distal[t.finger]
        O = self.object_frame
        axis = int(np.argmax(np.abs(normal)))
        sign = float(np.sign(normal[axis]))
        centre = np.zeros(3)
        centre[1] = t.spread
        centre += jitter * (np.arange(3) != axis)  # jitter along the surface only
        lo, hi = centre - tol, centre + tol
        big = 1.0
        if shape == "sphere":
            # On the sphere, on the normal's side, near the nominal spread.
            ik.AddPointToPointDistanceConstraint(frame, p_B, O, np.zeros(3), r, r)
            lo[axis], hi[axis] = (0.2 * r, r) if sign > 0 else (-r, -0.2 * r)
            ik.AddPositionConstraint(frame, p_B, O, lo, hi)
        elif shape == "cylinder":
            length = dims[1]
            ik.AddPointToLineDistanceConstraint(frame, p_B, O, np.zeros(3), np.array([0, 1.0, 0]),
                                                r, r)
            half = 0.5 * length - 0.008
            lo[1], hi[1] = max(lo[1], -half), min(hi[1], half)
            lo[axis], hi[axis] = (0.2 * r, r) if sign > 0 else (-r, -0.2 * r)
            ik.AddPositionConstraint(frame, p_B, O, lo, hi)
        else:
            w, d, h = dims
            half = np.array([0.5 * h, 0.5 * d, 0.5 * w]) - 0.006
            lo = np.maximum(lo, -half - 0.006)
            hi = np.minimum(hi, half + 0.006)
            lo, hi = np.maximum(lo, -big), np.minimum(hi, big)
            face = 0.5 * np.array([h, d, w])[axis]
            lo[axis] = hi[axis] = sign * face
            ik.AddPositionConstraint(frame, p_B, O, lo, hi)

    def _heights_above_table(self) -> dict[str, float]:
        """Body name -> height (m) of its lowest collision shape above the table, at the
        posture and object pose now in :attr:`context` (the forearm's is
        ``forearm_axis_B`` / ``forearm_radius``). Needs a support."""
        if self.support is None:
            raise ValueError("the table clearance needs a support (table) in the constructor")
        heights: dict[str, float] = {}
        for frame, points, radius in self.clearance_points:
            X_UB = self.plant.CalcRelativeTransform(self.context, self.up_frame, frame)
            z = float(min((X_UB @ points.T)[2]) - radius + self.support[1])
            name = frame.body().name()
            heights[name] = min(z, heights.get(name, np.inf))
        return heights

    def table_clearance(self) -> tuple[float, str]:
        """``(height, body name)`` of the hand's lowest collision shape above the table
        (m; negative: into it) at the posture and object pose now in :attr:`context`
        (after :meth:`solve_grasp`, or :meth:`set_posture`). Needs a support."""
        heights = self._heights_above_table()
        name = min(heights, key=heights.get)
        return heights[name], name

    def bodies_in_table(self, tolerance: float) -> set[str]:
        """Names of the hand bodies reaching more than ``tolerance`` (m) into the table
        (see :meth:`table_clearance`)."""
        return {name for name, z in self._heights_above_table().items() if z < -tolerance}

    def bodies_in_contact(self, max_penetration: float) -> set[str]:
        """Names of the hand bodies reaching more than ``max_penetration`` (m) into the
        object or another hand body, at the posture and object pose now in
        :attr:`context`. Needs the object's shape."""
        if self.shape is None:
            raise ValueError("bodies_in_contact needs the object shape in the constructor")
        query = self.plant.get_geometry_query_input_port().Eval(self.context)
        inspector = query.inspector()
        names = set()
        for pair in query.ComputeSignedDistancePairwiseClosestPoints(0.0):
            if pair.distance < -max_penetration:
                for g in (pair.id_A, pair.id_B):
                    body = self.plant.GetBodyFromFrameId(inspector.GetFrameId(g))
                    if body.model_instance() == self.hand:
                        names.add(body.name())
        return names

    def collisions(self, max_penetration: float, table_tolerance: float
                   ) -> tuple[set[str], set[str]]:
        """``(into the table, into the object or the hand)``:
        :meth:`bodies_in_table` and :meth:`bodies_in_contact`."""
        return self.bodies_in_table(table_tolerance), self.bodies_in_contact(max_penetration)

    def set_posture(self, q, X_PO: RigidTransform) -> None:
        """Puts the hand at posture q (24,) and the object at ``X_PO`` (palm frame)."""
        self._set(self._check_q(q))
        X_WP = self.palm.CalcPoseInWorld(self.context)
        self.plant.SetFreeBodyPose(self.context, self.object_body, X_WP @ X_PO)

    def contact_jacobian(self, q, finger: str, part: str = "pad") -> tuple[np.ndarray, np.ndarray]:
        """Position ``p_PC`` (3,) of a finger contact point and its Jacobian (3, 24).

        The Jacobian is with respect to the 24 hand joints (``spec.joint_names``
        order); the wrist columns are zero (the palm frame is the reference).
        """
        q = self._check_q(q)
        if (finger, part) not in CONTACT_POINTS:
            raise ValueError(f"unknown contact {(finger, part)}; expected one of "
                             f"{sorted(CONTACT_POINTS)}")
        self._set(q)
        p_B, _ = CONTACT_POINTS[(finger, part)]
        frame = self.distal[finger]
        p = self.plant.CalcPointsPositions(self.context, frame, p_B, self.palm).ravel()
        J = self.plant.CalcJacobianTranslationalVelocity(
            self.context, JacobianWrtVariable.kQDot, frame, p_B, self.palm, self.palm)
        J = J[:, self.q_index]
        J[:, self._wrist] = 0.0
        return p, J

    def surface_error(self, q, name, shape, dims, X_PO: RigidTransform, layout=None) -> float:
        """Largest distance (m) of a class contact point (of ``layout``, default its
        layout on this object, :func:`contact_layout`) from the object surface."""
        if layout is None:
            layout = contact_layout(name, shape, dims, on_table=self.support is not None)
        used = {t.finger for t in layout}
        pts = {f: p for f, p in self.contact_points(q, name).items() if f in used}
        X_OP = X_PO.inverse()
        errs = []
        r = 0.5 * dims[0]
        for p in pts.values():
            p_O = X_OP.multiply(p)
            if shape == "sphere":
                errs.append(abs(np.linalg.norm(p_O) - r))
            elif shape == "cylinder":
                errs.append(abs(np.hypot(p_O[0], p_O[2]) - r))
            else:
                half = 0.5 * np.array([dims[2], dims[1], dims[0]])
                outside = np.maximum(np.abs(p_O) - half, 0.0)
                inside = np.min(half - np.abs(p_O))
                errs.append(np.linalg.norm(outside) if np.any(outside > 0) else inside)
        return float(max(errs))


# ------------------------------------------------------- moving contacts


def _collapse(J: np.ndarray, joints: tuple[str, ...], ratio: float, names) -> np.ndarray:
    """Columns of the command joints of one finger, the coupled J1 folded into J2."""
    cols = []
    for name in joints:
        col = J[:, names.index(name)].copy()
        if name.endswith("J2") and not name.startswith("TH"):
            col += ratio * J[:, names.index(name[:-1] + "1")]
        cols.append(col)
    return np.column_stack(cols)


def move_contacts(kin: GraspKinematics, q: np.ndarray, moves: dict, ratio: float = 1.0,
                  steps: int = 5, damping: float = 0.01) -> np.ndarray:
    """Move finger contact points by given palm-frame displacements.

    moves: ``{finger: (part, dx_P (3,))}``. Each finger's joints take
    ``steps`` damped least-squares steps ``dq = J^T (J J^T + damping^2 I)^-1 dx``
    (Jacobian re-evaluated each step), clipped to the command limits; the
    coupled J1 follows J2. Returns the new (24,) posture.
    """
    names, act = kin.spec.joint_names, kin.spec.actuated_joint_names
    lower, upper = actuated_position_limits(kin.spec, ratio)
    q = np.array(q, dtype=float)
    for finger, (part, dx) in moves.items():
        joints = kin.spec.finger_joints[kin.spec.fingers.index(finger)]
        idx = [names.index(j) for j in joints]
        lo = np.array([lower[act.index(j)] for j in joints])
        hi = np.array([upper[act.index(j)] for j in joints])
        step = np.asarray(dx, dtype=float) / steps
        for _ in range(steps):
            _, J = kin.contact_jacobian(q, finger, part)
            Jf = _collapse(J, joints, ratio, names)
            dq = Jf.T @ np.linalg.solve(Jf @ Jf.T + damping**2 * np.eye(3), step)
            q[idx] = np.clip(q[idx] + dq, lo, hi)
            for j in joints:
                if j.endswith("J2") and finger != "th":
                    q[names.index(j[:-1] + "1")] = ratio * q[names.index(j)]
    return q
