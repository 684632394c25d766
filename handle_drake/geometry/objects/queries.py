"""Surface queries on catalogue objects: the pieces' mesh, exact surface sampling, ray casts.

No boolean engine is installed (trimesh's needs ``manifold3d``), so
:func:`surface_mesh` contains the faces the pieces share; :func:`sample_surface`
rejects points on shared faces and :func:`ray_cast` returns the nearest entry
point over all pieces, which is the true surface seen from outside (trimesh's
own ray casting needs ``rtree``, which is not installed).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from handle_drake.geometry.objects.catalogue import ObjectSpec, _mesh_module
from handle_drake.geometry.objects.pieces import pieces


def surface_mesh(spec: ObjectSpec) -> trimesh.Trimesh:
    """The pieces' meshes in the object frame, concatenated (round pieces faceted).

    Not a boolean union: faces shared by two pieces are included. Point
    sampling should use :func:`sample_surface`; ray casting :func:`ray_cast`
    (or the nearest hit from outside on this mesh, which is the true surface).
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.surface_mesh(spec)
    return trimesh.util.concatenate([p.mesh() for p in pieces(spec)])


@lru_cache(maxsize=256)
def _halfspaces(spec: ObjectSpec) -> tuple:
    """For each piece: ("planes", A, b) with the piece = {x: A x <= b} in O, or the
    analytic description ("sphere", centre, r) / ("cylinder", X_OP, r, half_length)."""
    out = []
    for piece in pieces(spec):
        X = piece.X_OP
        if piece.shape == "sphere":
            out.append(("sphere", np.array(X.translation()), piece.params[0]))
        elif piece.shape == "cylinder":
            out.append(("cylinder", X, piece.params[0], piece.params[1] / 2))
        else:
            if piece.shape == "box":
                half = np.array(piece.params) / 2
                verts = (
                    np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
                    * half
                )
            else:
                verts = piece.vertices
            eq = ConvexHull(verts).equations  # n . x + c <= 0 inside
            R, p = X.rotation().matrix(), np.array(X.translation())
            A = eq[:, :3] @ R.T
            b = -eq[:, 3] + A @ p
            out.append(("planes", A, b))
    return tuple(out)


def _inside(desc, points: np.ndarray, tol: float) -> np.ndarray:
    """True where points are inside the piece or within ``tol`` of its surface."""
    if desc[0] == "planes":
        _, A, b = desc
        return np.all(points @ A.T - b <= tol, axis=1)
    if desc[0] == "sphere":
        _, c, r = desc
        return np.linalg.norm(points - c, axis=1) <= r + tol
    _, X, r, half = desc
    q = (points - X.translation()) @ X.rotation().matrix()
    return (np.hypot(q[:, 0], q[:, 1]) <= r + tol) & (np.abs(q[:, 2]) <= half + tol)


def sample_surface(spec: ObjectSpec, n: int, rng=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniformly distributed (by area) on the object's outer surface.

    Returns ``(p_OS, n_O)``: points (n, 3) and outward unit normals (n, 3) in
    the object frame. Points on faces shared by two pieces are rejected, so
    every point lies on the true surface (round pieces are faceted: points on a
    sphere or cylinder lie on its 64-facet mesh, within 0.2 % of the radius).
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.sample_surface(spec, n, rng)
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise TypeError(f"n must be an int, got {type(n).__name__}")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(rng)
    piece_meshes = [p.mesh() for p in pieces(spec)]
    descs = _halfspaces(spec)
    tol = 1e-9 * spec.size
    # Sample on the concatenation by area, then drop points inside another piece;
    # repeat until enough points survive.
    mesh = trimesh.util.concatenate(piece_meshes)
    owner = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(piece_meshes)])
    areas = mesh.area_faces
    cdf = np.cumsum(areas) / areas.sum()
    tri = mesh.triangles
    normals = mesh.face_normals
    points, point_normals = [], []
    have = 0
    while have < n:
        m = max(2 * (n - have), 64)
        faces = np.minimum(np.searchsorted(cdf, rng.random(m)), len(cdf) - 1)
        u, v = rng.random(m), rng.random(m)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        t = tri[faces]
        p = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
        keep = np.ones(m, dtype=bool)
        for i, desc in enumerate(descs):
            others = owner[faces] != i
            keep[others] &= ~_inside(desc, p[others], tol)
        points.append(p[keep])
        point_normals.append(normals[faces[keep]])
        have += int(keep.sum())
    if n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.vstack(points)[:n], np.vstack(point_normals)[:n]


@dataclass(frozen=True)
class RayHits:
    """Result of :func:`ray_cast` for k rays: ``hit`` (k,) bool, ``distance`` (k,)
    along the ray (inf where no hit), ``p_OS`` (k, 3) hit points, ``n_O`` (k, 3)
    outward unit normals (NaN where no hit), ``piece`` (k,) index into
    ``pieces(spec)`` (-1 where no hit)."""

    hit: np.ndarray
    distance: np.ndarray
    p_OS: np.ndarray
    n_O: np.ndarray
    piece: np.ndarray


def _ray_planes(A, b, o, d):
    # Cyrus-Beck clipping of the rays against the piece's half-spaces.
    num = b[None, :] - o @ A.T  # >= 0 where the origin satisfies the plane
    den = d @ A.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    entering = den < 0
    exiting = den > 0
    t_in = np.where(entering, t, -np.inf).max(axis=1)
    t_out = np.where(exiting, t, np.inf).min(axis=1)
    parallel_out = np.any((den == 0) & (num < 0), axis=1)
    ok = (t_in <= t_out) & ~parallel_out & (t_in >= 0)
    face = np.where(entering, t, -np.inf).argmax(axis=1)
    normal = A[face] / np.linalg.norm(A[face], axis=1, keepdims=True)
    return np.where(ok, t_in, np.inf), normal


def _ray_sphere(c, r, o, d):
    oc = o - c
    bq = np.einsum("ij,ij->i", oc, d)
    disc = bq**2 - (np.einsum("ij,ij->i", oc, oc) - r * r)
    with np.errstate(invalid="ignore"):
        t = -bq - np.sqrt(disc)
    ok = (disc >= 0) & (t >= 0)
    t = np.where(ok, t, np.inf)
    with np.errstate(invalid="ignore"):
        normal = (o + np.where(ok, t, 0)[:, None] * d - c) / r
    return t, normal


def _ray_cylinder(X, r, half, o, d):
    R = X.rotation().matrix()
    q = (o - X.translation()) @ R
    e = d @ R
    best = np.full(len(o), np.inf)
    normal_local = np.zeros_like(q)
    # Side: entry through the round wall within the caps.
    a = e[:, 0] ** 2 + e[:, 1] ** 2
    bq = q[:, 0] * e[:, 0] + q[:, 1] * e[:, 1]
    c = q[:, 0] ** 2 + q[:, 1] ** 2 - r * r
    disc = bq**2 - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-bq - np.sqrt(disc)) / a
    z_side = q[:, 2] + t_side * e[:, 2]
    ok = (a > 0) & (disc >= 0) & (t_side >= 0) & (np.abs(z_side) <= half)
    best = np.where(ok, t_side, best)
    side_point = q + np.where(ok, t_side, 0)[:, None] * e
    normal_local[ok] = np.column_stack(
        [side_point[ok, 0], side_point[ok, 1], 0 * side_point[ok, 0]]
    )
    normal_local[ok] /= r
    # Caps: entry through the top (from above) or the bottom (from below).
    for sign in (1.0, -1.0):
        with np.errstate(divide="ignore", invalid="ignore"):
            t_cap = (sign * half - q[:, 2]) / e[:, 2]
        p = q + np.where(np.isfinite(t_cap), t_cap, 0)[:, None] * e
        ok = (sign * e[:, 2] < 0) & (t_cap >= 0) & (np.hypot(p[:, 0], p[:, 1]) <= r)
        ok &= t_cap < best
        best = np.where(ok, t_cap, best)
        normal_local[ok] = [0.0, 0.0, sign]
    return best, normal_local @ R.T


def _rays(p_OA, d_O) -> tuple[np.ndarray, np.ndarray]:
    """Checked ray origins (k, 3) and unit directions (k, 3) for a ray cast."""
    o = np.atleast_2d(np.asarray(p_OA, dtype=float))
    d = np.atleast_2d(np.asarray(d_O, dtype=float))
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"p_OA must have shape (k, 3), got {np.shape(p_OA)}")
    if d.shape != o.shape:
        raise ValueError(f"d_O must have shape {o.shape}, got {np.shape(d_O)}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("ray origins and directions must be finite")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0):
        raise ValueError("ray directions must be non-zero")
    return o, d / norm[:, None]


def ray_cast(spec: ObjectSpec, p_OA, d_O) -> RayHits:
    """First point where each ray ``p_OA + t d_O`` (t >= 0) enters the object.

    ``p_OA`` (k, 3) or (3,): ray origins in the object frame, outside the solid
    (a ray may start in the cavity of a mug); ``d_O`` same shape: directions
    (normalised here). Exact for the pieces' true shapes (spheres and cylinders
    are not faceted). Raises ValueError for an origin inside the solid.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.ray_cast(spec, p_OA, d_O)
    o, d = _rays(p_OA, d_O)
    descs = _halfspaces(spec)
    inside = np.zeros(len(o), dtype=bool)
    for desc in descs:
        inside |= _inside(desc, o, -1e-12 * spec.size)
    if np.any(inside):
        raise ValueError(
            f"ray origins must lie outside the object; {int(inside.sum())} of {len(o)} are inside"
        )
    best = np.full(len(o), np.inf)
    normals = np.full((len(o), 3), np.nan)
    which = np.full(len(o), -1)
    for i, desc in enumerate(descs):
        if desc[0] == "planes":
            t, nrm = _ray_planes(desc[1], desc[2], o, d)
        elif desc[0] == "sphere":
            t, nrm = _ray_sphere(desc[1], desc[2], o, d)
        else:
            t, nrm = _ray_cylinder(desc[1], desc[2], desc[3], o, d)
        closer = t < best
        best[closer] = t[closer]
        normals[closer] = nrm[closer]
        which[closer] = i
    hit = np.isfinite(best)
    points = np.where(hit[:, None], o + np.where(hit, best, 0)[:, None] * d, np.nan)
    return RayHits(hit, best, points, normals, which)
