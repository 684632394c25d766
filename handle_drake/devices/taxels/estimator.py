"""The object's pose in the hand, estimated from what the hand senses (never the plant's
state): the hand's joint positions, its taxels, optionally a camera's detection and the
object's accelerometer (gravity direction).

:class:`InHandPoseEstimator` ports:

- input ``hand_positions`` (nq, rad, ``HandSpec.joint_names`` order: the station's
  ``hand.position_measured``).
- input ``taxels`` (cells, Pa: the station's ``hand.taxels``).
- input ``hand_pose`` (6, ``[x y z roll pitch yaw]`` of the hand base in world: the
  floating wrist's ``wrist.pose_measured``); unconnected, the fixed ``X_WB`` given.
- input ``camera_pose`` (abstract ``RigidTransform``, ``X_WO`` detected), optional.
- input ``roll_pitch`` (2, rad: the object's accelerometer's ``object.roll_pitch``),
  optional; needs ``X_OS``.
- output ``pose`` (abstract ``RigidTransform``): ``X_WO`` estimated.
- output ``covariance`` (36): the 6 x 6 covariance of ``[rotation vector, position]``
  (rad, m) in the hand base frame, row-major.
- output ``quality`` (2): the number of pads in contact and the RMS distance (m) of
  their centres of pressure to the fitted surface.

The method (at ``rate_hz``, state in the context): each connected patch of pressed cells
of a pad (:func:`pad_contacts`) whose cells sum to more than ``contact_threshold`` N
gives a contact: its centre of pressure on the pad's (flat or wrapped) surface and the
outward normal there, placed in the hand base frame B by the forward kinematics of a
plant of the hand alone; a contact within ``self_contact_distance`` of another link of
the hand is pressed by the hand and left out. The object's pose ``X_BO`` is the
least-squares fit (``scipy.optimize.least_squares``) of its primitive's signed distance
(sphere, cylinder, cuboid) at the contacts to ``-pad_compliance * force`` (the pad pressed
into the object; ``sigma_distance``) and of its outward normal to the pads' inward
normals (``sigma_normal``); a contact on the grid's border (the object may touch the body
beyond the grid: a fingertip's tip) gets ``edge_sigma_distance`` and ``edge_sigma_normal``
and its body must touch the object (its least clearance to it 0 within
``edge_sigma_distance``). The object is kept out of every link of the hand and off the
pads that feel nothing, with the previous estimate as a prior, the camera's detection
(``camera_position_std``, ``camera_angle_std``) and the gravity direction; the better of
two starts (the last estimate, and a half-size beyond the contacts along their normals)
is kept. The prior (a filter): in the hand, the last estimate carried by the touching
pads' motion since the last update (:meth:`InHandPoseEstimator.carry`: the object moves
rigidly with the pads that hold it) and widened by ``still_*_std`` plus ``motion_noise``
times that motion and the pads' disagreement, plus ``base_motion_noise`` times the hand
base's step (the lift's load turns the object in the grasp where touch does not see: the
reported covariance grows there); ``motion_model=False``, or no pad touching: a random
walk of ``process_position_std`` / ``process_angle_std`` per update. A roll/pitch reading
counts as gravity only when it agrees with the one before within
``gravity_consistency`` (the device's first sample, a jerk: left out). Before the first
contact the estimate is held in world (the ``X_WO_prior``, refined by the camera and
gravity when they are connected: the object rests where it was seen); from the first
contact it is held in the hand.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, Capsule, Cylinder, Role, Sphere
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, DiscreteContactApproximation
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem
from scipy.ndimage import label
from scipy.optimize import least_squares
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from handle_drake.base.hands import AddHand, get_hand_spec
from handle_drake.devices.taxels.pads import Pad
from handle_drake.geometry.objects.pieces import pieces

__all__ = ["InHandPoseEstimator", "PrimitiveShape", "pad_contacts", "cylinder_signed_distance"]

#: m: a point this far behind a contact, inside the finger, must be outside the object
#: (at least 0.8 of it): the fit's guard against the mirror solution (the object on the
#: far side of the contacts, through the fingers).
INNER_DEPTH = 0.006

#: m: how far a link of the hand may reach into the fitted object (the simulated contact's
#: penetration under grasp forces is up to ~1.5 mm).
HAND_TOLERANCE = 0.002


def _shape_points(shape) -> tuple[np.ndarray, np.ndarray]:
    """Points inside a collision shape (its frame) and the clearance each needs from the
    object (a ball of that radius around each point lies inside the shape)."""
    if isinstance(shape, Sphere):
        return np.zeros((1, 3)), np.array([shape.radius()])
    if isinstance(shape, Capsule | Cylinder):
        z = np.linspace(-shape.length() / 2, shape.length() / 2, 4)
        return np.column_stack([0 * z, 0 * z, z]), np.full(4, shape.radius())
    if isinstance(shape, Box):
        size = np.array([shape.width(), shape.depth(), shape.height()])
        thin = int(np.argmin(size))
        r = size[thin] / 2
        axes = [a for a in range(3) if a != thin]
        grid = [np.linspace(-size[a] / 2 + r, size[a] / 2 - r, 3) if size[a] > 2 * r
                else np.zeros(1) for a in axes]
        g0, g1 = np.meshgrid(*grid, indexing="ij")
        points = np.zeros((g0.size, 3))
        points[:, axes[0]], points[:, axes[1]] = g0.ravel(), g1.ravel()
        return points, np.full(len(points), r)
    return np.zeros((0, 3)), np.zeros(0)


class PrimitiveShape:
    """The signed distance (m) and outward normal of an object, in its frame O: one
    primitive (sphere, cylinder with axis z, box: exact), or the union of an object's
    convex pieces (:func:`~handle_drake.geometry.objects.pieces.pieces`: each convex hull's
    distance is the largest of its face planes' and of its bounding box's distance --
    exact inside and along a face's normal, less than the distance off its edges -- and
    the union's the smallest of its pieces')."""

    def __init__(self, spec):
        parts = pieces(spec)
        if not parts:
            raise ValueError(f"estimator: object kind {spec.kind!r} has no pieces")
        self._parts = []
        for piece in parts:
            frame = (piece.X_OP.rotation().inverse().matrix(), piece.X_OP.translation())
            if piece.shape == "convex":
                bounds = (piece.vertices.min(axis=0), piece.vertices.max(axis=0))
                self._parts.append(("convex", (ConvexHull(piece.vertices).equations, bounds),
                                    *frame))
            else:
                self._parts.append((piece.shape, np.array(piece.params, float), *frame))
        self.shape = parts[0].shape if len(parts) == 1 else "union"
        self.params = self._parts[0][1] if self.shape in ("sphere", "cylinder", "box") \
            else np.zeros(0)
        if self.shape in ("convex", "union"):
            corners = np.vstack([m.vertices for m in (piece.mesh() for piece in parts)])
            self._half = float(np.ptp(corners, axis=0).min() / 2)

    def half_size(self) -> float:
        """The smallest distance from the centre to the surface (m; a union's or hull's:
        half its bounding box's least extent)."""
        if self.shape == "box":
            return float(self.params.min() / 2)
        if self.shape in ("sphere", "cylinder"):
            return float(self.params[0])
        return self._half

    def distance(self, p_O: np.ndarray) -> np.ndarray:
        """Signed distance of each row of ``p_O`` (n, 3)."""
        return np.min([self._piece_distance(part, p_O) for part in self._parts], axis=0)

    @staticmethod
    def _piece_distance(part, p_O):
        shape, params, R_PO, p_OP = part
        p = (np.asarray(p_O, float) - p_OP) @ R_PO.T
        if shape == "sphere":
            return np.linalg.norm(p, axis=1) - params[0]
        if shape == "convex":
            planes, (low, high) = params
            # outside: the larger of two lower bounds, the face planes' and the distance to
            # the piece's bounding box (a thin piece's planes say little off its far end)
            box = np.linalg.norm(np.maximum(np.maximum(low - p, p - high), 0.0), axis=1)
            return np.maximum((p @ planes[:, :3].T + planes[:, 3]).max(axis=1), box)
        if shape == "cylinder":
            return cylinder_signed_distance(p, *params)
        return _box_distance(np.abs(p) - params / 2)

    def normal(self, p_O: np.ndarray, h: float = 1e-5) -> np.ndarray:
        """Unit outward normal (the distance's gradient, central differences) at each row."""
        g = np.column_stack([self.distance(p_O + h * e) - self.distance(p_O - h * e)
                             for e in np.eye(3)]) / (2 * h)
        return g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)


def cylinder_signed_distance(p: np.ndarray, radius: float, length: float) -> np.ndarray:
    """Signed distance of each row of ``p`` (n, 3, in the cylinder's frame: axis z, centred)
    from a solid cylinder's surface (negative inside)."""
    p = np.asarray(p, float).reshape(-1, 3)
    return _box_distance(np.column_stack([np.hypot(p[:, 0], p[:, 1]) - radius,
                                          np.abs(p[:, 2]) - length / 2]))


def _box_distance(q: np.ndarray) -> np.ndarray:
    """Signed distance from the excess ``q`` (n, k) of each point over a box's half-sizes."""
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def interior(pad: Pad, uv) -> bool:
    """Whether a centre of pressure ``uv`` lies three quarters of a cell or more inside the
    grid's border: pressure on the pad (the object's face on it, its normal the pad's).
    One nearer the border is where an object touching the body beyond the grid (a
    fingertip's tip, a capsule's end) also reads: its normal, and its place to a few mm,
    are uncertain."""
    prof = pad.profile
    return bool(abs(uv[0]) <= (prof.cols / 2 - 0.75) * prof.pitch_col
                and abs(uv[1]) <= (prof.rows / 2 - 0.75) * prof.pitch_row)


def pad_contacts(pads: list[Pad], taxels: np.ndarray, X_BPads: list[RigidTransform],
                 threshold: float, with_interior: bool = False):
    """Per contact patch of each pad (cells above three noise deviations, connected
    through sides or corners, together above ``threshold`` N): its centre of pressure
    ``c_B`` (on the pad's surface), the pad's outward normal ``n_B`` there and its force
    (N) from ``taxels`` (Pa). Arrays (k, 3), (k, 3), (k,); ``with_interior``: and (k,)
    bools, :func:`interior` of each. Two patches on one pad (a fingertip touching with
    its tip and its side) are two contacts: one centre of pressure between them would
    lie on neither."""
    points, normals, forces, inside = [], [], [], []
    start = 0
    for pad, X_BP in zip(pads, X_BPads, strict=True):
        profile = pad.profile
        f = np.asarray(taxels[start:start + pad.cells], float) * profile.cell_area
        start += pad.cells
        # cells under three noise deviations are taken as empty
        f = np.where(f > 3.0 * profile.noise_std_pa * profile.cell_area, f, 0.0)
        if f.sum() <= threshold:
            continue
        labels, count = label(f.reshape(profile.rows, profile.cols) > 0,
                              structure=np.ones((3, 3)))
        labels = labels.ravel()
        centres = profile.cell_centres()
        for patch in range(1, count + 1):
            w = np.where(labels == patch, f, 0.0)
            total = w.sum()
            if total <= threshold:
                continue
            uv = w @ centres / total
            # the centre of pressure on the pad's surface (a skin's curves) and its normal
            p_P, n_P = pad.surface_point(uv[0], uv[1])
            points.append(X_BP.multiply(p_P[0]))
            normals.append(X_BP.rotation().multiply(n_P[0]))
            forces.append(total)
            inside.append(interior(pad, uv))
    out = (np.array(points).reshape(-1, 3), np.array(normals).reshape(-1, 3),
           np.array(forces, float))
    return (*out, np.array(inside, bool)) if with_interior else out


class InHandPoseEstimator(LeafSystem):
    """See the module doc.

    Args:
        hand_kind, coupling_ratio: the hand (a plant of it alone gives the pads' poses).
        pads: the taxel pads (:func:`~.pads.shadow_pads`), their ``body_name`` and ``X_BP``.
        spec: the object's ``ObjectSpec`` (any catalogue kind: :class:`PrimitiveShape`).
        X_WO_prior: the object's pose believed before the grasp (a detection, a plan).
        X_WB: the hand base's pose for a fixed mount (used when ``hand_pose`` is unconnected).
        X_OS: the accelerometer's frame on the object (for ``roll_pitch``).
    """

    def __init__(self, hand_kind: str, coupling_ratio, pads: list[Pad], spec,
                 X_WO_prior: RigidTransform, X_WB: RigidTransform | None = None,
                 X_OS: RigidTransform | None = None, rate_hz: float = 20.0,
                 prior_position_std: float = 0.01, prior_angle_std: float = 0.2,
                 contact_threshold: float = 0.2, sigma_distance: float = 0.0015,
                 sigma_normal: float = 0.3, edge_sigma_distance: float = 0.004,
                 edge_sigma_normal: float = 5.0, pad_compliance: float = 2e-4,
                 process_position_std: float = 0.002,
                 process_angle_std: float = 0.05, camera_position_std: float = 0.005,
                 camera_angle_std: float = 0.1, gravity_std: float = 0.05,
                 self_contact_distance: float = 0.004, motion_model: bool = True,
                 still_position_std: float = 0.0005, still_angle_std: float = 0.01,
                 motion_noise: float = 0.5, gravity_consistency: float = 0.1,
                 base_motion_noise: float = 0.1):
        super().__init__()
        self._shape = PrimitiveShape(spec)
        self._half_size = self._shape.half_size()
        self._pads = list(pads)
        spec_h = get_hand_spec(hand_kind)
        hand = self._build_kinematics(hand_kind, coupling_ratio, spec_h)
        self._self_contact_distance = self_contact_distance
        inspector = self._scene_graph.model_inspector()
        self._links, self._others = self._hand_geometry(inspector, hand)
        self._clearance = np.concatenate([c for _, _, c in self._links])
        # per pad: the rows of hand_points() inside its body (an edge contact's body
        # touches the object: the least clearance-reduced distance of them is 0)
        sizes = np.cumsum([0] + [len(c) for _, _, c in self._links])
        self._pad_rows = [np.concatenate([np.arange(sizes[k], sizes[k + 1])
                                          for k, (body, _, _) in enumerate(self._links)
                                          if body.name() == pad.body_name] or [np.zeros(0, int)])
                          for pad in self._pads]
        self._q_index = np.array([self._plant.GetJointByName(n, hand).position_start()
                                  for n in spec_h.joint_names], dtype=int)
        self._q0 = self._plant.GetPositions(self._plant_context)
        self._bodies = [self._plant.GetBodyByName(p.body_name, hand) for p in self._pads]
        self._X_WO_prior = RigidTransform(X_WO_prior)
        self._X_WB = None if X_WB is None else RigidTransform(X_WB)
        self._X_OS = None if X_OS is None else RigidTransform(X_OS)
        self._period = 1.0 / rate_hz
        self._sig = dict(
            prior_p=prior_position_std, prior_a=prior_angle_std, d=sigma_distance,
            n=sigma_normal, proc_p=process_position_std, proc_a=process_angle_std,
            cam_p=camera_position_std, cam_a=camera_angle_std, g=gravity_std,
            edge_d=edge_sigma_distance, edge_n=edge_sigma_normal, compliance=pad_compliance,
            still_p=still_position_std, still_a=still_angle_std, motion=motion_noise,
            g_consistency=gravity_consistency, base_motion=base_motion_noise)
        self._motion_model = bool(motion_model)
        self._threshold = contact_threshold
        self._offsets = np.cumsum([0] + [p.cells for p in self._pads])
        nq, cells = len(spec_h.joint_names), sum(p.cells for p in self._pads)
        self._q_port = self.DeclareVectorInputPort("hand_positions", nq)
        self._taxel_port = self.DeclareVectorInputPort("taxels", cells)
        self._hand_pose = self.DeclareVectorInputPort("hand_pose", 6)
        self._camera = self.DeclareAbstractInputPort("camera_pose",
                                                     AbstractValue.Make(RigidTransform()))
        self._roll_pitch = self.DeclareVectorInputPort("roll_pitch", 2)
        # state: quaternion wxyz and p of X_BO (or X_WO before contact), 36 covariance,
        # contacts, rms, in_hand, then whether the last update saw the joints, its joints
        # (the pads' motion), its roll and pitch and whether it read them
        self._nq = nq
        self._state = self.DeclareDiscreteState(self._initial_state())
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareAbstractOutputPort("pose", lambda: AbstractValue.Make(RigidTransform()),
                                       self._calc_pose, {self.all_input_ports_ticket(),
                                                         self.xd_ticket()})
        self.DeclareVectorOutputPort("covariance", 36, lambda c, o: o.SetFromVector(
            c.get_discrete_state(self._state).value()[7:43]), {self.xd_ticket()})
        self.DeclareVectorOutputPort("quality", 2, lambda c, o: o.SetFromVector(
            c.get_discrete_state(self._state).value()[43:45]), {self.xd_ticket()})

    def _build_kinematics(self, hand_kind, coupling_ratio, spec_h):
        """A plant of the hand alone, its base welded to the world: kinematics and the
        hand's own geometry only (never stepped; AddHand asks for a SAP plant: its
        couplers), and a scratch context, overwritten whole at each use (no result depends
        on its past). Returns the hand's model instance."""
        builder = DiagramBuilder()
        self._plant, self._scene_graph = AddMultibodyPlantSceneGraph(builder, 0.001)
        self._plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
        hand = AddHand(self._plant, hand_kind, coupling_ratio=coupling_ratio)
        self._plant.WeldFrames(self._plant.world_frame(),
                               self._plant.GetBodyByName(spec_h.base_body, hand).body_frame())
        self._plant.Finalize()
        self._kinematics = builder.Build()
        self._kin_context = self._kinematics.CreateDefaultContext()
        self._plant_context = self._plant.GetMyContextFromRoot(self._kin_context)
        self._sg_context = self._scene_graph.GetMyContextFromRoot(self._kin_context)
        return hand

    @property
    def half_size(self) -> float:
        """The object's smallest distance from its centre to its surface (m)."""
        return self._half_size

    @property
    def shape_kind(self) -> str:
        """The object's primitive: "sphere", "cylinder", "box", "convex" or "union"."""
        return self._shape.shape

    @property
    def hand_clearance(self) -> np.ndarray:
        """The clearance each of :meth:`hand_points` needs from the object (m)."""
        return self._clearance

    def _hand_geometry(self, inspector, hand):
        """Points inside every link of the hand with their clearance (the object is not
        inside the hand), and per pad the hand geometries that can touch it (not on its
        body, not filtered against it)."""
        links = []
        for g in inspector.GetAllGeometryIds(Role.kProximity):
            points, clearance = _shape_points(inspector.GetShape(g))
            if len(points):
                X_LG = inspector.GetPoseInFrame(g)
                body = self._plant.GetBodyFromFrameId(inspector.GetFrameId(g))
                links.append((body, points @ X_LG.rotation().matrix().T
                              + X_LG.translation(), clearance))
        others = []
        for pad in self._pads:
            own = self._plant.GetCollisionGeometriesForBody(
                self._plant.GetBodyByName(pad.body_name, hand))
            others.append({
                g for g in inspector.GetAllGeometryIds(Role.kProximity)
                if g not in own and not any(inspector.CollisionFiltered(g, o) for o in own)})
        return links, others

    def _initial_state(self) -> np.ndarray:
        x = np.zeros(58 + len(self._q_index))
        x[:4] = self._X_WO_prior.rotation().ToQuaternion().wxyz()
        x[4:7] = self._X_WO_prior.translation()
        s = self._sig
        x[7:43] = np.diag([s["prior_a"] ** 2] * 3 + [s["prior_p"] ** 2] * 3).ravel()
        return x

    # -- helpers -------------------------------------------------------------------------
    def _X_WB_of(self, context) -> RigidTransform:
        if self._hand_pose.HasValue(context):
            x = self._hand_pose.Eval(context)
            return RigidTransform(RollPitchYaw(x[3:6]), x[:3])
        if self._X_WB is None:
            raise RuntimeError("estimator: hand_pose is unconnected and no fixed X_WB was given")
        return self._X_WB

    def pad_poses(self, q: np.ndarray) -> list[RigidTransform]:
        """``X_BP`` of each pad for hand joint positions ``q`` (forward kinematics).
        Uses the estimator's own plant context: call from one thread."""
        full = self._q0.copy()
        full[self._q_index] = q
        self._plant.SetPositions(self._plant_context, full)
        return [self._plant.EvalBodyPoseInWorld(self._plant_context, b) @ p.X_BP
                for b, p in zip(self._bodies, self._pads, strict=True)]

    def hand_points(self) -> np.ndarray:
        """The link points of the hand in B at the joints last set (:meth:`pad_poses`)."""
        return np.concatenate([
            points @ X.rotation().matrix().T + X.translation()
            for X, points in ((self._plant.EvalBodyPoseInWorld(self._plant_context, body), p)
                              for body, p, _ in self._links)])

    def contacts(self, q: np.ndarray, taxels: np.ndarray):
        """:meth:`contact_pads`' contacts without the pads (``(points, normals, free, terms,
        touching)``)."""
        return self.contact_pads(q, taxels)[0]

    def contact_pads(self, q: np.ndarray, taxels: np.ndarray):
        """``(contacts, pads)``, ``pads`` per contact kept its pad's index and force (N): the
        pads' contacts with the object (centres of pressure and outward normals in B), the
        face centres of the pads that feel nothing and each contact's terms for
        :meth:`fit` (``(points, normals, free, terms, touching)``; ``terms`` (k, 3): the distance's
        and the normal's standard deviations and the expected signed distance, the pad
        pressed ``pad_compliance`` m per N into the object): a pad whose centre of
        pressure lies within ``self_contact_distance`` of another link of the hand (one it
        can collide with) is pressed by the hand, not the object, and is left out. A
        centre of pressure on the grid's border (:func:`pad_contacts`' interior false)
        gets ``edge_sigma_distance`` and ``edge_sigma_normal``; ``touching``: per such
        border contact the rows of :meth:`hand_points` of its link (:meth:`fit`'s)."""
        X_BPads = self.pad_poses(q)
        query = self._scene_graph.get_query_output_port().Eval(self._sg_context)
        keep, free = [], []
        pads = []  # per contact kept: its pad's index and force (N), for the motion model
        for i, (pad, X_BP) in enumerate(zip(self._pads, X_BPads, strict=True)):
            points, normals, force, inside = pad_contacts(
                [pad], taxels[self._offsets[i]:self._offsets[i + 1]], [X_BP], self._threshold,
                with_interior=True)
            if not len(points):
                free.append(X_BP.translation())
                continue
            s = self._sig
            for point, normal, f, ok in zip(points, normals, force, inside, strict=True):
                near = query.ComputeSignedDistanceToPoint(point, self._self_contact_distance)
                if any(d.id_G in self._others[i] for d in near):
                    continue
                pads.append((i, float(f)))
                terms = (s["d"], s["n"]) if ok else (s["edge_d"], s["edge_n"])
                keep.append((point, normal, (*terms, -s["compliance"] * f),
                             None if ok else self._pad_rows[i]))
        free = np.array(free).reshape(-1, 3)
        touching = [k[3] for k in keep if k[3] is not None]
        if not keep:
            return (np.zeros((0, 3)), np.zeros((0, 3)), free, np.zeros((0, 3)), touching), pads
        return (np.array([k[0] for k in keep]), np.array([k[1] for k in keep]), free,
                np.array([k[2] for k in keep]), touching), pads

    @staticmethod
    def _unpack(x) -> RigidTransform:
        q = np.asarray(x[:4], float)
        return RigidTransform(Quaternion(q / np.linalg.norm(q)), np.asarray(x[4:7], float))

    def _calc_pose(self, context, out):
        x = context.get_discrete_state(self._state).value()
        X = self._unpack(x)
        if x[45] > 0.5:
            X = self._X_WB_of(context) @ X
        out.set_value(X)

    # -- the update ------------------------------------------------------------------------
    def _steady_roll_pitch(self, context, x):
        """The accelerometer's roll and pitch when connected and it agrees with the
        reading of the last update (kept in ``x``) within ``gravity_consistency`` (not a
        transient: a first sample, a jerk), else None."""
        if not self._roll_pitch.HasValue(context) or self._X_OS is None:
            return None
        n = 47 + self._nq
        rp = np.asarray(self._roll_pitch.Eval(context), float)
        steady = x[n + 2] > 0.5 and np.all(np.isfinite(rp)) and np.linalg.norm(
            rp - x[n:n + 2]) <= self._sig["g_consistency"]
        x[n:n + 2], x[n + 2] = rp, 1.0
        return rp if steady else None

    def _base_step(self, x, X_WB: RigidTransform) -> np.ndarray:
        """The hand base's motion since the last update (m, rad; 0 at the first), its
        pose of now kept in ``x``."""
        m = 50 + self._nq  # the hand base's pose at the last update: p, quaternion, flag
        step = np.zeros(2)
        if x[m + 7] > 0.5:
            X_prev = RigidTransform(Quaternion(x[m + 3:m + 7] / np.linalg.norm(x[m + 3:m + 7])),
                                    x[m:m + 3])
            step = np.array([np.linalg.norm(X_WB.translation() - X_prev.translation()),
                             (X_prev.rotation().inverse() @ X_WB.rotation())
                             .ToAngleAxis().angle()])
        x[m:m + 3], x[m + 3:m + 7], x[m + 7] = (X_WB.translation(),
                                                X_WB.rotation().ToQuaternion().wxyz(), 1.0)
        return step

    def _update(self, context, state):
        x = context.get_discrete_state(self._state).value().copy()
        X_WB = self._X_WB_of(context)
        X_BW = X_WB.inverse()
        q = np.asarray(self._q_port.Eval(context), float)
        (points, normals, free, terms, touching), pads = self.contact_pads(
            q, self._taxel_port.Eval(context))
        in_hand = x[45] > 0.5
        X_BO_prev = self._unpack(x) if in_hand else X_BW @ self._unpack(x)
        cov_prev = x[7:43].reshape(6, 6)
        camera = self._camera.HasValue(context)
        q_prev, had_q = x[47:47 + self._nq].copy(), x[46] > 0.5
        x[46], x[47:47 + self._nq] = 1.0, q
        rp = self._steady_roll_pitch(context, x)
        gravity_in = rp is not None
        if not in_hand and len(points) == 0 and not camera and not gravity_in:
            state.get_mutable_vector(self._state).SetFromVector(x)
            return EventStatus.Succeeded()
        s = self._sig
        # the prior: the last estimate (in the hand: carried by the touching pads' motion),
        # widened by the process noise
        process = np.array([s["proc_a"]] * 3 + [s["proc_p"]] * 3)
        base_step = self._base_step(x, X_WB)
        if self._motion_model and in_hand and had_q and pads:
            X_BO_prev, process = self.carry(X_BO_prev, q_prev, q, pads)
            self.pad_poses(q)  # the joints of now again, for hand_points()
            # the hand base's motion loads the grasp (inertia): the object may slip or turn
            # in it, most where the touch does not see
            k = s["base_motion"]
            process = np.hypot(process, k * np.array(
                [base_step[0] / self._half_size + base_step[1]] * 3
                + [base_step[0] + self._half_size * base_step[1]] * 3))
        prior_std = np.sqrt(np.maximum(np.diag(cov_prev), 0.0) + process ** 2)
        priors = [(X_BO_prev, prior_std)]
        if camera:
            priors.append((X_BW @ self._camera.Eval(context),
                           np.array([s["cam_a"]] * 3 + [s["cam_p"]] * 3)))
        gravity = None
        if gravity_in:
            r, p = rp
            down_S = RollPitchYaw(r, p, 0.0).ToRotationMatrix().inverse().multiply([0, 0, -1.0])
            gravity = (X_BW.rotation().multiply([0, 0, -1.0]), down_S)
        hand = (self.hand_points(), self._clearance)
        starts = [X_BO_prev]
        if len(points):
            # a start from the touch alone: the object's centre a half-size beyond the
            # contacts, along the pads' normals
            guess = np.mean(points + self._half_size * normals, axis=0)
            starts.append(RigidTransform(X_BO_prev.rotation(), guess))
        best = None
        for start in starts:
            result = self.fit(points, normals, priors, gravity, free, hand, start=start,
                              terms=terms, touching=touching)
            if best is None or result[3] < best[3]:
                best = result
        X_BO, cov, rms, _ = best
        # held in the hand from the first touch; before it, in world (a camera or the
        # accelerometer alone refine where the object rests)
        in_hand = in_hand or len(points) > 0
        X = X_BO if in_hand else X_WB @ X_BO
        x[:4] = X.rotation().ToQuaternion().wxyz()
        x[4:7] = X.translation()
        x[7:43] = cov.ravel()
        x[43:45] = (len(points), rms)
        x[45] = float(in_hand)
        state.get_mutable_vector(self._state).SetFromVector(x)
        return EventStatus.Succeeded()

    def carry(self, X_BO: RigidTransform, q_prev, q, contact_pads):
        """The object carried by the pads that touch it from joints ``q_prev`` to ``q``
        (it moves rigidly with them: each touching pad's motion moves it; the
        force-weighted mean of those poses) and the process noise of the step (std of
        ``[rotation vector, position]``): ``still_*_std`` plus ``motion_noise`` times the
        pads' mean motion and their disagreement. ``contact_pads``: ``[(pad index,
        force)]``. Returns ``(X_BO, std6)``."""
        pads = sorted({i for i, _ in contact_pads})
        force = np.array([sum(f for j, f in contact_pads if j == i) for i in pads])
        w = force / force.sum() if force.sum() > 0 else np.full(len(pads), 1 / len(pads))
        before = self.pad_poses(q_prev)
        after = self.pad_poses(q)
        moved = [after[i] @ before[i].inverse() @ X_BO for i in pads]
        p = np.array([X.translation() for X in moved])
        R = Rotation.from_matrix(np.array([X.rotation().matrix() for X in moved]))
        p_mean, R_mean = w @ p, R.mean(weights=w)
        spread_p = float(np.sqrt(w @ np.sum((p - p_mean) ** 2, axis=1)))
        spread_a = float(np.sqrt(w @ np.sum((R * R_mean.inv()).as_rotvec() ** 2, axis=1)))
        R_prev = Rotation.from_matrix(X_BO.rotation().matrix())
        step_p = float(np.linalg.norm(p_mean - X_BO.translation()))
        step_a = float(np.linalg.norm((R_mean * R_prev.inv()).as_rotvec()))
        s = self._sig
        std = np.array([np.hypot(s["still_a"], s["motion"] * (step_a + spread_a))] * 3
                       + [np.hypot(s["still_p"], s["motion"] * (step_p + spread_p))] * 3)
        return RigidTransform(RotationMatrix(R_mean.as_matrix()), p_mean), std

    def fit(self, points, normals, priors, gravity=None, free=(), hand=None, start=None,
            terms=None, touching=()):
        """``(X_BO, covariance, rms)``: the least-squares pose (see the module doc).

        ``points``, ``normals``: (k, 3) contacts and the pads' outward normals in B;
        ``priors``: ``[(X_BO, std6)]`` with ``std6`` of ``[rotation vector, position]``;
        ``gravity``: ``(down_B, down_S)`` or None; ``free``: (m, 3) centres of the pads
        that feel nothing (not inside the object); ``hand``: ``(points, clearance)`` inside
        the hand's links (not inside the object); ``start``: where the search starts (default:
        the first prior); ``terms``: (k, 3) per contact, the distance's and the normal's
        standard deviations and the expected signed distance (default: ``sigma_distance``,
        ``sigma_normal``, 0); ``touching``: per edge contact the rows of ``hand`` inside
        its pad's body, which touches the object (within ``edge_sigma_distance``).
        Returns ``(X_BO, covariance, rms, cost)``.
        """
        free = np.asarray(free, float).reshape(-1, 3)
        points = np.asarray(points, float).reshape(-1, 3)
        normals = np.asarray(normals, float).reshape(-1, 3)
        X0 = priors[0][0] if start is None else start
        R0 = X0.rotation().matrix()
        p0 = X0.translation()
        s = self._sig
        prior_terms = [(Rotation.from_matrix(X.rotation().matrix()), X.translation(),
                        np.asarray(std, float)) for X, std in priors]
        R_OS = None if self._X_OS is None else self._X_OS.rotation().matrix()
        if terms is None:
            terms = np.tile([s["d"], s["n"], 0.0], (len(points), 1))
        terms = np.asarray(terms, float).reshape(-1, 3)
        if len(terms) != len(points):
            raise ValueError(f"estimator.fit: terms: expected {len(points)} rows (one per "
                             f"contact), got {len(terms)}")
        sigma_d, sigma_n, expected = terms.T

        def pose(v):
            R = Rotation.from_rotvec(v[:3]).as_matrix() @ R0
            return R, p0 + v[3:]

        def residuals(v):
            R, p = pose(v)
            res = []
            if len(points):
                p_O = (points - p) @ R  # R^T (c - p) per row
                res.append((self._shape.distance(p_O) - expected) / sigma_d)
                n_B = self._shape.normal(p_O) @ R.T
                res.append(((n_B + normals) / sigma_n[:, None]).ravel())
                # the finger behind each contact is outside the object
                inner = (points - INNER_DEPTH * normals - p) @ R
                res.append(np.minimum(self._shape.distance(inner) - 0.8 * INNER_DEPTH, 0.0)
                           / s["d"])
            if hand is not None:
                gap = self._shape.distance((hand[0] - p) @ R) - hand[1]
                res.append(np.minimum(gap + HAND_TOLERANCE, 0.0) / s["d"])
                res.extend([np.atleast_1d(gap[rows].min()) / s["edge_d"]
                            for rows in touching if len(rows)])
            if len(free):
                # pads that feel nothing are not inside the object
                res.append(np.minimum(self._shape.distance((free - p) @ R), 0.0) / s["d"])
            rot = Rotation.from_matrix(R)
            for R_prior, p_prior, std in prior_terms:
                res.append((rot * R_prior.inv()).as_rotvec() / std[:3])
                res.append((p - p_prior) / std[3:])
            if gravity is not None and R_OS is not None:
                down_B, down_S = gravity
                res.append(((R @ R_OS).T @ down_B - down_S) / s["g"])
            return np.concatenate(res)

        result = least_squares(residuals, np.zeros(6), method="lm" if len(
            residuals(np.zeros(6))) >= 6 else "trf", x_scale=[0.1] * 3 + [0.01] * 3,
            ftol=1e-6, xtol=1e-6)
        R, p = pose(result.x)
        J = result.jac
        cov = np.linalg.pinv(J.T @ J)
        # the covariance of the rotation about R0 is that of the rotation vector of R R0^T
        if len(points):
            rms = float(np.sqrt(np.mean(self._shape.distance((points - p) @ R) ** 2)))
        else:
            rms = 0.0
        return RigidTransform(RotationMatrix(R), p), cov, rms, float(result.cost)

