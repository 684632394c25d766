"""Where the taxel grids sit on the hand, and the pressure each cell feels.

A :class:`Pad` is a grid (a :class:`~.profiles.TaxelProfile`) on one body's surface, in a
pad frame P: origin at the grid's centre on the surface, ``+z`` the outward normal there,
``x`` across the pad (cell columns, ``u``), ``y`` along it (cell rows, ``v``). A flat pad
(``radius`` 0) lies in P's ``z = 0`` plane; a skin (``radius`` r > 0) is wrapped around a
cylinder of radius r whose axis is P's ``y`` line through ``(0, 0, -r)``: ``u`` is then
the arc length across it (cell ``u`` at angle ``u / r`` from P's ``z``), so one grid of
cells covers a phalanx's palmar half. On the Shadow hand the distal pads are the
model's ``<f>tip_pad`` boxes (their palmar, ``-y``, face: x across, the link's z
along), wrapped around the fingertip's axis (the link's z line; radius the face's
distance from it, 9 mm, 10.5 mm on the thumb): the flat face at the grid's centre line
and the fingertip capsule's rounded sides towards its edges, so a contact on the side of
the fingertip reads at its own normal (14 mm of arc: +-45 degrees); the palm pad lies
on the palm's palmar face (``y = -0.012`` of the ``palm`` link, centred at x 0.011, z
0.06: the union of its palm boxes' faces) and the skins
(``skin_profile``) wrap the palmar half of the proximal and middle phalanges' capsules
(fingers and thumb; rows along the capsule's straight part, as many as fit).

:func:`pad_forces` turns the plant's contact results into each cell's normal force (N):

- hydroelastic contact: every face of a contact surface with a geometry of the pad's
  body whose centroid lies within ``DEPTH_TOLERANCE`` of the pad's surface and inside the
  grid adds ``pressure(centroid) * area`` to the cell containing the centroid (a
  midpoint quadrature of the pressure field over each cell's patch);
- point contact (no pressure field): the contact's normal force ``|f . n|`` is spread over
  the cells by a Gaussian of standard deviation ``profile.point_sigma`` centred at the
  contact point's surface coordinates (each cell gets the Gaussian's integral over its
  patch), when the point is within ``DEPTH_TOLERANCE`` of the pad's surface.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.geometry import Box, Capsule
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import BodyIndex
from scipy.special import erf

from handle_drake.base.hands import pad_surface_point
from handle_drake.devices.taxels.profiles import TaxelProfile

__all__ = ["Pad", "shadow_pads", "pad_forces", "DEPTH_TOLERANCE", "PalmPad", "SHADOW_SKINS",
           "skin_rows"]

#: m: a contact point or surface face further than this from a pad's surface is not on
#: the pad (the fingertip capsule's sides, the back of the finger).
DEPTH_TOLERANCE = 0.003

#: The pad frame's axes in the Shadow link frame: x across, the link's z along, -y out.
R_LINK_PAD = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))

#: The Shadow links that carry a skin and the straight length (m) of their capsule (the
#: model's; checked when the pads are read from a plant): the rows that fit are
#: ``skin_rows``.
SHADOW_SKINS = {**{f"{f}{link}": length for f in ("ff", "mf", "rf", "lf")
                   for link, length in (("proximal", 0.040), ("middle", 0.025))},
                "thproximal": 0.018, "thmiddle": 0.018}


def skin_rows(profile: TaxelProfile, length: float) -> int:
    """Rows of ``profile`` on a capsule of straight ``length`` (m): as many as fit, at
    most the profile's, at least one."""
    return max(1, min(profile.rows, int(math.floor(length / profile.pitch_row + 1e-9))))


@dc.dataclass(frozen=True)
class PalmPad:
    """The palm grid's place on the Shadow ``palm`` link (m, link frame)."""

    body: str = "palm"
    centre: tuple[float, float, float] = (0.011, -0.012, 0.06)


@dc.dataclass(frozen=True)
class Pad:
    """One taxel grid: ``name``, the body it is on (``body_name``, and ``body_index`` in
    the plant it was read from), ``X_BP`` (the pad frame in the body frame), its
    ``profile`` and ``radius`` (0: flat; > 0: a skin around a cylinder, see the module
    doc)."""

    name: str
    body_name: str
    body_index: int
    X_BP: RigidTransform
    profile: TaxelProfile
    radius: float = 0.0

    @property
    def cells(self) -> int:
        return self.profile.cells

    def surface_coordinates(self, p_P: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                             np.ndarray]:
        """``(u, v, depth)`` of points ``p_P`` (n, 3) in the pad frame: the surface
        coordinates of their projection and their height above the surface (m)."""
        p = np.asarray(p_P, float).reshape(-1, 3)
        if self.radius <= 0.0:
            return p[:, 0], p[:, 1], p[:, 2]
        z = p[:, 2] + self.radius
        return (self.radius * np.arctan2(p[:, 0], z), p[:, 1],
                np.hypot(p[:, 0], z) - self.radius)

    def surface_point(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (n, 3) on the pad's surface at ``(u, v)`` and the outward normals there,
        in the pad frame (:func:`~handle_drake.base.hands.pad_surface_point`)."""
        return pad_surface_point(u, v, self.radius)


def shadow_pads(plant, hand, scene_graph_inspector, profile: TaxelProfile,
                palm_profile: TaxelProfile | None = None,
                skin_profile: TaxelProfile | None = None) -> list[Pad]:
    """The Shadow hand's distal pads (first, middle, ring, little, thumb), with a
    ``palm_profile`` the palm pad, and with a ``skin_profile`` the skins of
    :data:`SHADOW_SKINS` (in that order), read from ``plant``'s geometries.

    Raises ValueError when the hand has no such pads or a grid is larger than its pad.
    """
    pads = []
    for finger in ("ff", "mf", "rf", "lf", "th"):
        name = f"{finger}tip_pad"
        body, found = _geometry(plant, hand, scene_graph_inspector, f"{finger}distal", name)
        if found is None:
            raise ValueError(f"taxels: the hand has no {name!r} geometry (only the Shadow hand "
                             "carries tactile pads)")
        box = scene_graph_inspector.GetShape(found)
        if not isinstance(box, Box):
            raise ValueError(f"taxels: {name} is a {type(box).__name__}, expected a Box")
        X_BG = scene_graph_inspector.GetPoseInFrame(found)
        # the palmar face: -y of the box; the grid wraps around the fingertip's axis (the
        # link's z line) through the face's centre: a skin over the pad's face and its
        # rounded sides (what touches the capsule's side reads there, at its own normal)
        centre = X_BG.multiply([0.0, -box.depth() / 2, 0.0])
        X_BP = RigidTransform(R_LINK_PAD, centre)
        across, along = box.width(), box.height()
        if profile.cols * profile.pitch_col > across + 1e-9 \
                or profile.rows * profile.pitch_row > along + 1e-9:
            raise ValueError(
                f"taxels: profile {profile.name!r} ({profile.cols * profile.pitch_col * 1e3:.1f}"
                f" x {profile.rows * profile.pitch_row * 1e3:.1f} mm) is larger than the "
                f"{name} ({across * 1e3:.1f} x {along * 1e3:.1f} mm)")
        pads.append(Pad(name, body.name(), int(body.index()), X_BP, profile,
                        radius=float(np.hypot(centre[0], centre[1]))))
    if palm_profile is not None:
        palm = PalmPad()
        body = plant.GetBodyByName(palm.body, hand)
        pads.append(Pad("palm_pad", palm.body, int(body.index()),
                        RigidTransform(R_LINK_PAD, np.array(palm.centre)), palm_profile))
    if skin_profile is not None:
        pads += [_skin(plant, hand, scene_graph_inspector, link, length, skin_profile)
                 for link, length in SHADOW_SKINS.items()]
    return pads


def _geometry(plant, hand, inspector, body_name: str, suffix: str):
    """``(body, geometry id)`` of ``body_name``'s collision geometry named ``*suffix``
    (None, None when there is none)."""
    if not plant.HasBodyNamed(body_name, hand):
        return None, None
    body = plant.GetBodyByName(body_name, hand)
    for gid in plant.GetCollisionGeometriesForBody(body):
        if inspector.GetName(gid).endswith(suffix):
            return body, gid
    return body, None


def _skin(plant, hand, inspector, link: str, length: float, profile: TaxelProfile) -> Pad:
    """The skin on ``link``'s capsule: the palmar half (around the link's -y), rows along
    the capsule's axis centred on it."""
    body, gid = _geometry(plant, hand, inspector, link, "_collision_0")
    shape = inspector.GetShape(gid) if gid is not None else None
    if not isinstance(shape, Capsule):
        raise ValueError(f"taxels: the hand's {link} has no capsule to carry a skin")
    if abs(shape.length() - length) > 1e-4:
        raise ValueError(f"taxels: {link}'s capsule is {shape.length() * 1e3:.1f} mm long, "
                         f"the skin layout expects {length * 1e3:.1f} mm")
    if profile.cols * profile.pitch_col > math.pi * shape.radius() + 1e-9:
        raise ValueError(f"taxels: skin profile {profile.name!r} is wider "
                         f"({profile.cols * profile.pitch_col * 1e3:.1f} mm) than half of "
                         f"{link}'s capsule ({math.pi * shape.radius() * 1e3:.1f} mm)")
    X_BG = inspector.GetPoseInFrame(gid)
    axis = X_BG.rotation().matrix()[:, 2]
    out = np.array([0.0, -1.0, 0.0]) - axis * -axis[1]
    out /= np.linalg.norm(out)
    R = RotationMatrix(np.column_stack([np.cross(axis, out), axis, out]))
    X_BP = RigidTransform(R, X_BG.translation() + shape.radius() * out)
    rows = skin_rows(profile, length)
    return Pad(f"{link}_skin", body.name(), int(body.index()), X_BP,
               profile.replace(rows=rows), radius=shape.radius())


def _gaussian_cell_weights(profile: TaxelProfile, u, v) -> np.ndarray:
    """Integral over each cell of a unit 2-D Gaussian centred at each ``(u, v)``:
    (n, cells) row-major (``u``, ``v`` arrays of n; scalars give (cells,))."""
    scalar = np.ndim(u) == 0
    u, v = np.atleast_1d(u), np.atleast_1d(v)
    s = profile.point_sigma * math.sqrt(2.0)
    edges_u = (np.arange(profile.cols + 1) - profile.cols / 2) * profile.pitch_col
    edges_v = (np.arange(profile.rows + 1) - profile.rows / 2) * profile.pitch_row
    wu = np.diff(0.5 * erf((edges_u[None, :] - u[:, None]) / s), axis=1)
    wv = np.diff(0.5 * erf((edges_v[None, :] - v[:, None]) / s), axis=1)
    w = (wv[:, :, None] * wu[:, None, :]).reshape(len(u), -1)
    return w[0] if scalar else w


def _cell_of(profile: TaxelProfile, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-major cell index of each ``(u, v)``, -1 outside the grid."""
    col = np.floor(u / profile.pitch_col + profile.cols / 2).astype(int)
    row = np.floor(v / profile.pitch_row + profile.rows / 2).astype(int)
    inside = (col >= 0) & (col < profile.cols) & (row >= 0) & (row < profile.rows)
    return np.where(inside, row * profile.cols + col, -1)


class PadForces:
    """:func:`pad_forces` with its lookups built once (the sensor calls it every sample).

    ``body_poses`` may be a callable returning them: it is called only when a contact
    touches a body that carries a pad (most samples of a free hand evaluate nothing).
    """

    def __init__(self, plant, pads: list[Pad]):
        self.pads = list(pads)
        self.offsets = np.cumsum([0] + [p.cells for p in self.pads])
        self._by_body: dict[int, list[int]] = {}
        for i, pad in enumerate(self.pads):
            self._by_body.setdefault(pad.body_index, []).append(i)
        self._geometry_body = {
            gid: pad.body_index for pad in self.pads
            for gid in plant.GetCollisionGeometriesForBody(plant.get_body(
                _body_index(pad.body_index)))}
        # per pad, as arrays for all pads at once: R_BP, p_BP, the radius, the Gaussian's
        # cell edges over its width (padded to the largest grid with +inf: empty cells)
        # and each padded cell's index in the output (the last slot, size, for padding)
        self._R_BP = np.array([p.X_BP.rotation().matrix() for p in self.pads])
        self._p_BP = np.array([p.X_BP.translation() for p in self.pads])
        self._radius = np.array([p.radius for p in self.pads])
        self._width = np.array([p.profile.point_sigma * math.sqrt(2.0) for p in self.pads])
        rows = max(p.profile.rows for p in self.pads)
        cols = max(p.profile.cols for p in self.pads)
        self._edges_u = np.full((len(self.pads), cols + 1), np.inf)
        self._edges_v = np.full((len(self.pads), rows + 1), np.inf)
        self._cell_index = np.full((len(self.pads), rows, cols), self.size)
        for i, pad in enumerate(self.pads):
            prof = pad.profile
            self._edges_u[i, :prof.cols + 1] = (np.arange(prof.cols + 1) - prof.cols / 2) \
                * prof.pitch_col / self._width[i]
            self._edges_v[i, :prof.rows + 1] = (np.arange(prof.rows + 1) - prof.rows / 2) \
                * prof.pitch_row / self._width[i]
            self._cell_index[i, :prof.rows, :prof.cols] = self.offsets[i] + np.arange(
                prof.cells).reshape(prof.rows, prof.cols)
        self._cell_index = self._cell_index.reshape(len(self.pads), -1)

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def __call__(self, contact_results, body_poses) -> np.ndarray:
        out = np.zeros(self.size)
        cache = {}

        def frame(body):
            """(R_WB, p_WB) of a body as arrays."""
            if body not in cache:
                if "poses" not in cache:
                    cache["poses"] = body_poses() if callable(body_poses) else body_poses
                M = cache["poses"][body].GetAsMatrix34()
                cache[body] = (M[:, :3], M[:, 3])
            return cache[body]

        self._point_contacts(contact_results, out, frame)
        self._hydroelastic_contacts(contact_results, out, frame)
        return out

    def _point_contacts(self, contact_results, out, frame) -> None:
        """Each point contact with a pad body spread over that body's pads' cells (all
        contacts and pads in one vectorised pass)."""
        by_body = self._by_body
        rows = []  # (pad, body, fn, p_WC) per contact and pad of a body it touches
        for k in range(contact_results.num_point_pair_contacts()):
            info = contact_results.point_pair_contact_info(k)
            a, b = int(info.bodyA_index()), int(info.bodyB_index())
            if a not in by_body and b not in by_body:
                continue
            fn = abs(float(info.contact_force() @ info.point_pair().nhat_BA_W))
            p_WC = info.contact_point()
            rows += [(i, body, fn, p_WC) for body in (a, b) for i in by_body.get(body, ())]
        if not rows:
            return
        pad = np.array([r[0] for r in rows])
        fn = np.array([r[2] for r in rows])
        frames = [frame(r[1]) for r in rows]
        R_WB = np.array([f[0] for f in frames])
        p_B = np.einsum("kji,kj->ki", R_WB, np.array([r[3] for r in rows])
                        - np.array([f[1] for f in frames]))
        p_P = np.einsum("kji,kj->ki", self._R_BP[pad], p_B - self._p_BP[pad])
        # surface coordinates (Pad.surface_coordinates, for flat and wrapped pads at once)
        radius = self._radius[pad]
        z = p_P[:, 2] + radius
        wrapped = radius > 0
        u = np.where(wrapped, radius * np.arctan2(p_P[:, 0], z), p_P[:, 0])
        depth = np.where(wrapped, np.hypot(p_P[:, 0], z) - radius, p_P[:, 2])
        keep = np.abs(depth) <= DEPTH_TOLERANCE
        if not keep.any():
            return
        pad, fn, u, v = pad[keep], fn[keep], u[keep], p_P[keep, 1]
        width = self._width[pad][:, None]
        wu = np.diff(erf(self._edges_u[pad] - u[:, None] / width), axis=1)
        wv = np.diff(erf(self._edges_v[pad] - v[:, None] / width), axis=1)
        # 0.25: each axis's cell integral is half the difference of the erf at its edges
        w = (0.25 * fn)[:, None, None] * wv[:, :, None] * wu[:, None, :]
        out += np.bincount(self._cell_index[pad].ravel(), weights=w.ravel(),
                           minlength=self.size + 1)[:self.size]

    def _hydroelastic_contacts(self, contact_results, out, frame) -> None:
        """Each hydroelastic surface with a pad body binned into that body's pads' cells."""
        for k in range(contact_results.num_hydroelastic_contacts()):
            info = contact_results.hydroelastic_contact_info(k)
            surface = info.contact_surface()
            bodies = [self._geometry_body.get(g) for g in (surface.id_M(), surface.id_N())]
            bodies = [body for body in bodies if body is not None]
            if not bodies:
                continue
            n = surface.num_faces()
            centroids = np.empty((n, 3))
            force = np.empty(n)
            field = surface.tri_e_MN() if surface.is_triangle() else surface.poly_e_MN()
            for f in range(n):
                c = surface.centroid(f)
                centroids[f] = c
                force[f] = field.EvaluateCartesian(f, c) * surface.area(f)
            for body in bodies:
                R_WB, p_WB = frame(body)
                c_B = (centroids - p_WB) @ R_WB
                for i in self._by_body[body]:
                    pad = self.pads[i]
                    u, v, depth = pad.surface_coordinates((c_B - self._p_BP[i]) @ self._R_BP[i])
                    cell = _cell_of(pad.profile, u, v)
                    keep = (cell >= 0) & (np.abs(depth) <= DEPTH_TOLERANCE)
                    if np.any(keep):
                        out[self.offsets[i]:self.offsets[i + 1]] += np.bincount(
                            cell[keep], weights=force[keep], minlength=pad.profile.cells)


def _body_index(i: int) -> BodyIndex:
    return BodyIndex(i)


def pad_forces(plant, pads: list[Pad], contact_results, body_poses) -> np.ndarray:
    """Each cell's normal force (N), pads in order, cells row-major (see the module doc)."""
    return PadForces(plant, pads)(contact_results, body_poses)
