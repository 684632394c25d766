"""Where the taxel grids sit on the hand, and the pressure each cell feels.

A :class:`Pad` is a grid (a :class:`~.profiles.TaxelProfile`) on one body's face, in a
pad frame P: origin at the face's centre, ``+z`` the face's outward normal, ``x`` across
the pad (cell columns, ``u``), ``y`` along it (cell rows, ``v``). On the Shadow hand the
distal pads are the model's ``<f>tip_pad`` boxes (their palmar, ``-y``, face: x across,
the link's z along) and the palm pad lies on the palm's palmar face (``y = -0.012`` of
the ``palm`` link, centred at x 0.011, z 0.06: the union of its palm boxes' faces).

:func:`pad_forces` turns the plant's contact results into each cell's normal force (N):

- hydroelastic contact: every face of a contact surface with a geometry of the pad's
  body whose centroid lies within ``DEPTH_TOLERANCE`` of the face plane and inside the
  grid adds ``pressure(centroid) * area * |n_face . z_P|`` to the cell containing the
  centroid (a midpoint quadrature of the pressure field over each cell's patch);
- point contact (no pressure field): the contact's normal force ``|f . n|`` is spread over
  the cells by a Gaussian of standard deviation ``profile.point_sigma`` centred at the
  contact point projected on the face (each cell gets the Gaussian's integral over its
  patch), when the point is within ``DEPTH_TOLERANCE`` of the face plane.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.geometry import Box
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import BodyIndex
from scipy.special import erf

from handle_drake.devices.taxels.profiles import TaxelProfile

__all__ = ["Pad", "shadow_pads", "pad_forces", "DEPTH_TOLERANCE", "PalmPad"]

#: m: a contact point or surface face further than this from a pad's face plane is not on
#: the pad (the fingertip capsule's sides, the back of the finger).
DEPTH_TOLERANCE = 0.003

#: The pad frame's axes in the Shadow link frame: x across, the link's z along, -y out.
R_LINK_PAD = RotationMatrix(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]))


@dc.dataclass(frozen=True)
class PalmPad:
    """The palm grid's place on the Shadow ``palm`` link (m, link frame)."""

    body: str = "palm"
    centre: tuple[float, float, float] = (0.011, -0.012, 0.06)


@dc.dataclass(frozen=True)
class Pad:
    """One taxel grid: ``name``, the body it is on (``body_name``, and ``body_index`` in
    the plant it was read from), ``X_BP`` (the pad frame in the body frame) and its
    ``profile``."""

    name: str
    body_name: str
    body_index: int
    X_BP: RigidTransform
    profile: TaxelProfile

    @property
    def cells(self) -> int:
        return self.profile.cells


def shadow_pads(plant, hand, scene_graph_inspector, profile: TaxelProfile,
                palm_profile: TaxelProfile | None = None) -> list[Pad]:
    """The Shadow hand's distal pads (first, middle, ring, little, thumb) and, with a
    ``palm_profile``, the palm pad, read from ``plant``'s ``<f>tip_pad`` geometries.

    Raises ValueError when the hand has no such pads or a grid is larger than its pad.
    """
    pads = []
    for finger in ("ff", "mf", "rf", "lf", "th"):
        name = f"{finger}tip_pad"
        found = None
        body = plant.GetBodyByName(f"{finger}distal", hand) if plant.HasBodyNamed(
            f"{finger}distal", hand) else None
        if body is not None:
            for gid in plant.GetCollisionGeometriesForBody(body):
                if scene_graph_inspector.GetName(gid).endswith(name):
                    found = gid
        if found is None:
            raise ValueError(f"taxels: the hand has no {name!r} geometry (only the Shadow hand "
                             "carries tactile pads)")
        box = scene_graph_inspector.GetShape(found)
        if not isinstance(box, Box):
            raise ValueError(f"taxels: {name} is a {type(box).__name__}, expected a Box")
        X_BG = scene_graph_inspector.GetPoseInFrame(found)
        # the palmar face: -y of the box
        X_BP = RigidTransform(R_LINK_PAD, X_BG.multiply([0.0, -box.depth() / 2, 0.0]))
        across, along = box.width(), box.height()
        if profile.cols * profile.pitch_col > across + 1e-9 \
                or profile.rows * profile.pitch_row > along + 1e-9:
            raise ValueError(
                f"taxels: profile {profile.name!r} ({profile.cols * profile.pitch_col * 1e3:.1f}"
                f" x {profile.rows * profile.pitch_row * 1e3:.1f} mm) is larger than the "
                f"{name} ({across * 1e3:.1f} x {along * 1e3:.1f} mm)")
        pads.append(Pad(name, body.name(), int(body.index()), X_BP, profile))
    if palm_profile is not None:
        palm = PalmPad()
        body = plant.GetBodyByName(palm.body, hand)
        pads.append(Pad("palm_pad", palm.body, int(body.index()),
                        RigidTransform(R_LINK_PAD, np.array(palm.centre)), palm_profile))
    return pads


def _gaussian_cell_weights(profile: TaxelProfile, u: float, v: float) -> np.ndarray:
    """Integral over each cell of a unit 2-D Gaussian centred at ``(u, v)`` (row-major)."""
    s = profile.point_sigma * math.sqrt(2.0)
    edges_u = (np.arange(profile.cols + 1) - profile.cols / 2) * profile.pitch_col
    edges_v = (np.arange(profile.rows + 1) - profile.rows / 2) * profile.pitch_row
    wu = np.diff(0.5 * erf((edges_u - u) / s))
    wv = np.diff(0.5 * erf((edges_v - v) / s))
    return np.outer(wv, wu).ravel()


def _cell_of(profile: TaxelProfile, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-major cell index of each ``(u, v)``, -1 outside the grid."""
    col = np.floor(u / profile.pitch_col + profile.cols / 2).astype(int)
    row = np.floor(v / profile.pitch_row + profile.rows / 2).astype(int)
    inside = (col >= 0) & (col < profile.cols) & (row >= 0) & (row < profile.rows)
    return np.where(inside, row * profile.cols + col, -1)


class PadForces:
    """:func:`pad_forces` with its lookups built once (the sensor calls it every sample)."""

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

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def __call__(self, contact_results, body_poses) -> np.ndarray:
        out = np.zeros(self.size)
        X_WP = {}

        def pose(i):
            if i not in X_WP:
                pad = self.pads[i]
                X_WP[i] = (body_poses[pad.body_index] @ pad.X_BP).inverse()
            return X_WP[i]

        for k in range(contact_results.num_point_pair_contacts()):
            info = contact_results.point_pair_contact_info(k)
            bodies = (int(info.bodyA_index()), int(info.bodyB_index()))
            if bodies[0] not in self._by_body and bodies[1] not in self._by_body:
                continue
            fn = abs(float(np.dot(info.contact_force(), info.point_pair().nhat_BA_W)))
            p_WC = info.contact_point()
            for body in bodies:
                for i in self._by_body.get(body, ()):
                    p = pose(i).multiply(p_WC)
                    if abs(p[2]) > DEPTH_TOLERANCE:
                        continue
                    profile = self.pads[i].profile
                    out[self.offsets[i]:self.offsets[i + 1]] += fn * _gaussian_cell_weights(
                        profile, p[0], p[1])
        for k in range(contact_results.num_hydroelastic_contacts()):
            info = contact_results.hydroelastic_contact_info(k)
            surface = info.contact_surface()
            bodies = [self._geometry_body.get(g) for g in (surface.id_M(), surface.id_N())]
            if bodies[0] is None and bodies[1] is None:
                continue
            n = surface.num_faces()
            centroids = np.empty((n, 3))
            normals = np.empty((n, 3))
            force = np.empty(n)
            field = surface.tri_e_MN() if surface.is_triangle() else surface.poly_e_MN()
            for f in range(n):
                c = surface.centroid(f)
                centroids[f] = c
                normals[f] = surface.face_normal(f)
                force[f] = field.EvaluateCartesian(f, c) * surface.area(f)
            for body in bodies:
                for i in self._by_body.get(body, ()) if body is not None else ():
                    X = pose(i)
                    p = centroids @ X.rotation().matrix().T + X.translation()
                    z_P = X.rotation().matrix()[2].copy()  # pad normal in world (row 2 of R_PW)
                    profile = self.pads[i].profile
                    cell = _cell_of(profile, p[:, 0], p[:, 1])
                    keep = (cell >= 0) & (np.abs(p[:, 2]) <= DEPTH_TOLERANCE)
                    if np.any(keep):
                        w = force[keep] * np.abs(normals[keep] @ z_P)
                        out[self.offsets[i]:self.offsets[i + 1]] += np.bincount(
                            cell[keep], weights=w, minlength=profile.cells)
        return out


def _body_index(i: int) -> BodyIndex:
    return BodyIndex(i)


def pad_forces(plant, pads: list[Pad], contact_results, body_poses) -> np.ndarray:
    """Each cell's normal force (N), pads in order, cells row-major (see the module doc)."""
    return PadForces(plant, pads)(contact_results, body_poses)
