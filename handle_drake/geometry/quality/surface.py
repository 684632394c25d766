"""The contact surface model (report section 4.1.3).

A raw contact point cloud (from the physics engine or the tactile sensors) is
reduced to its mean point ``p_m`` and mean inward normal ``n_m`` (eq. 12).
Line segments parallel to ``n_m`` are laid out on a disk of radius ``r`` in the
plane through ``p_m`` orthogonal to ``n_m`` and clipped by the sphere of radius
``r`` about ``p_m``; each is intersected with the object surface (the hit
nearest ``p_m`` is kept), and every hit becomes a point contact with the
surface's inward normal there.

The report bounds the segments by the plane through ``p_m`` (a half ball on
the object's side). A simulated contact point lies inside the object by up to
the penetration depth, where that half ball may miss the surface, so the
segments here span the whole chord of the sphere; on a convex surface through
``p_m`` every hit is on the object's side anyway, so the result is the same.

Surfaces answer ``intersect(origins, directions)`` for rays in the object
frame O and return, per ray, all hits as parameters ``t`` with outward normals;
analytic sphere, box and cylinder are closed-form, and :class:`MeshSurface`
wraps any ``trimesh.Trimesh`` (e.g. ``handle_drake.geometry.objects.surface_mesh``).
"""

from __future__ import annotations

import numpy as np

from handle_drake.geometry import objects

__all__ = [
    "SphereSurface",
    "BoxSurface",
    "CylinderSurface",
    "MeshSurface",
    "ObjectSurface",
    "disk_pattern",
    "contact_surface",
    "mean_contact",
]


def _pose(X_OG):
    """(R_OG, p_OG) from a RigidTransform, a 4x4 matrix or None."""
    if X_OG is None:
        return np.eye(3), np.zeros(3)
    if hasattr(X_OG, "rotation"):
        return np.asarray(X_OG.rotation().matrix()), np.asarray(X_OG.translation())
    X = np.asarray(X_OG, dtype=float)
    if X.shape != (4, 4):
        raise ValueError(f"X_OG: expected a RigidTransform or 4x4 matrix, got {X.shape}")
    return X[:3, :3], X[:3, 3]


def _positive(name, v):
    v = np.asarray(v, dtype=float)
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise ValueError(f"{name}: expected finite values > 0, got {v}")
    return v


class _Analytic:
    """Shared frame handling: rays are moved into the shape frame G."""

    def __init__(self, X_OG=None):
        self.R_OG, self.p_OG = _pose(X_OG)

    def intersect(self, origins, directions):
        """All ray hits: ``(t (R, K), normals_O (R, K, 3))``, ``t = nan`` for no hit."""
        o = (np.asarray(origins, float) - self.p_OG) @ self.R_OG
        d = np.asarray(directions, float) @ self.R_OG
        t, n_G = self._hits(o, d)
        return t, n_G @ self.R_OG.T


class SphereSurface(_Analytic):
    """Sphere of ``radius`` (m) centred at G (pose ``X_OG`` in the object frame)."""

    def __init__(self, radius: float, X_OG=None):
        super().__init__(X_OG)
        self.radius = float(_positive("radius", radius))

    def _hits(self, o, d):
        a = np.sum(d * d, axis=1)
        b = 2 * np.sum(o * d, axis=1)
        c = np.sum(o * o, axis=1) - self.radius**2
        disc = b * b - 4 * a * c
        ok = disc >= 0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        t = np.stack([(-b - sq) / (2 * a), (-b + sq) / (2 * a)], axis=1)
        t[~ok] = np.nan
        pts = o[:, None, :] + t[..., None] * d[:, None, :]
        return t, pts / self.radius


class BoxSurface(_Analytic):
    """Box with full edge lengths ``size`` (3,) (m), centred at G."""

    def __init__(self, size, X_OG=None):
        super().__init__(X_OG)
        self.size = _positive("size", size).reshape(3)

    def _hits(self, o, d):
        h = self.size / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - o) / d
            t2 = (h - o) / d
        # slab method; a ray parallel to a slab is unbounded inside it, empty outside
        par = d == 0
        inside = np.abs(o) <= h
        lo = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        hi = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        t_in, t_out = np.max(lo, axis=1), np.min(hi, axis=1)
        ok = np.isfinite(t_in) & np.isfinite(t_out) & (t_in <= t_out)
        rows = np.arange(len(o))
        ax_in, ax_out = np.argmax(lo, axis=1), np.argmin(hi, axis=1)
        n_in = np.zeros((len(o), 3))
        n_out = np.zeros((len(o), 3))
        n_in[rows, ax_in] = -np.sign(d[rows, ax_in])
        n_out[rows, ax_out] = np.sign(d[rows, ax_out])
        t = np.stack([t_in, t_out], axis=1)
        t[~ok] = np.nan
        return t, np.stack([n_in, n_out], axis=1)


class CylinderSurface(_Analytic):
    """Solid cylinder of ``radius`` and ``length`` (m) along G's z axis, centred at G."""

    def __init__(self, radius: float, length: float, X_OG=None):
        super().__init__(X_OG)
        self.radius = float(_positive("radius", radius))
        self.length = float(_positive("length", length))

    def _hits(self, o, d):
        R, hz = self.radius, self.length / 2
        n = len(o)
        ts, ns = [], []
        # side: (o_xy + t d_xy)^2 = R^2 with |z| <= hz
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = 2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1])
        c = o[:, 0] ** 2 + o[:, 1] ** 2 - R**2
        disc = b * b - 4 * a * c
        ok = (a > 1e-300) & (disc >= 0)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        safe_a = np.where(ok, a, 1.0)
        for sign in (-1.0, 1.0):
            t = np.where(ok, (-b + sign * sq) / (2 * safe_a), np.nan)
            p = o + t[:, None] * d
            t = np.where(np.abs(p[:, 2]) <= hz + 1e-12, t, np.nan)
            nrm = np.zeros((n, 3))
            nrm[:, :2] = p[:, :2] / R
            ts.append(t)
            ns.append(nrm)
        # caps: z = +-hz with x^2 + y^2 <= R^2
        for zc in (-hz, hz):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (zc - o[:, 2]) / d[:, 2]
            p = o + t[:, None] * d
            t = np.where((d[:, 2] != 0) & (p[:, 0] ** 2 + p[:, 1] ** 2 <= R**2 + 1e-12), t, np.nan)
            nrm = np.zeros((n, 3))
            nrm[:, 2] = np.sign(zc)
            ts.append(t)
            ns.append(nrm)
        return np.stack(ts, axis=1), np.stack(ns, axis=1)


class _BoxTree:
    """The two calls trimesh's ray code makes on an rtree index, answered with numpy.

    trimesh's ``RayMeshIntersector`` (no embree) asks an rtree for the triangles
    whose bounding boxes meet each ray's box; rtree is not a dependency of this
    project, and for the few dozen rays of a contact patch a vectorised box test
    is as fast, so we hand trimesh this stand-in and reuse its intersection code.
    """

    def __init__(self, triangles: np.ndarray):
        self.lo = triangles.min(axis=1)
        self.hi = triangles.max(axis=1)
        self.bounds = np.concatenate([self.lo.min(axis=0), self.hi.max(axis=0)])

    def intersection(self, box):
        box = np.asarray(box, dtype=float)
        overlap = np.all(self.lo <= box[3:], axis=1) & np.all(self.hi >= box[:3], axis=1)
        return np.flatnonzero(overlap)


class MeshSurface:
    """A closed triangle mesh (``trimesh.Trimesh``) in the object frame.

    Ray hits come from trimesh's pure-numpy ray-triangle code
    (``trimesh.ray.ray_triangle.ray_triangle_id``, no embree) with a numpy
    broad phase (:class:`_BoxTree`). For a concatenation of convex pieces (as
    ``objects.surface_mesh`` builds) internal faces are hit too; use
    ``contact_surface(..., pick="first")`` to keep the outer surface.
    """

    def __init__(self, mesh):
        import trimesh  # local: only needed for meshes

        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh: expected a trimesh.Trimesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0:
            raise ValueError("mesh: expected a mesh with faces, got 0 faces")
        from trimesh.ray.ray_triangle import ray_triangle_id

        self.mesh = mesh
        self._triangles = np.asarray(mesh.triangles)
        self._normals = np.asarray(mesh.face_normals)
        self._tree = _BoxTree(self._triangles)
        self._ray_triangle_id = ray_triangle_id

    def intersect(self, origins, directions):
        o = np.asarray(origins, float)
        d = np.asarray(directions, float)
        tri_idx, ray_idx, locs = self._ray_triangle_id(
            self._triangles, o, d, triangles_normal=self._normals, tree=self._tree,
            multiple_hits=True,
        )
        counts = np.bincount(ray_idx, minlength=len(o))
        K = max(1, int(counts.max()) if len(counts) else 1)
        t = np.full((len(o), K), np.nan)
        nrm = np.zeros((len(o), K, 3))
        order = np.argsort(ray_idx, kind="stable")
        ray_sorted = ray_idx[order]
        starts = np.searchsorted(ray_sorted, ray_sorted)
        slot = np.arange(len(order)) - starts
        dd = np.sum(d * d, axis=1)
        t[ray_sorted, slot] = np.einsum("ij,ij->i", locs[order] - o[ray_sorted],
                                        d[ray_sorted]) / dd[ray_sorted]
        nrm[ray_sorted, slot] = self._normals[tri_idx[order]]
        return t, nrm


class ObjectSurface:
    """A catalogue object (``handle_drake.geometry.objects.ObjectSpec``), ray cast exactly.

    Wraps ``objects.ray_cast`` (analytic spheres and cylinders, exact convex
    pieces; a ``MeshObjectSpec``'s real mesh): one hit per ray, the point where
    the ray first enters the solid.
    Rays that start inside the solid report no hit.
    """

    def __init__(self, spec):

        if not isinstance(spec, objects.ObjectSpec) and getattr(spec, "kind", None) != "mesh":
            raise TypeError(f"spec: expected an ObjectSpec or a MeshObjectSpec, got "
                            f"{type(spec).__name__}")
        self.spec = spec
        self._ray_cast = objects.ray_cast

    def intersect(self, origins, directions):
        o = np.asarray(origins, float)
        d = np.asarray(directions, float)
        try:
            hits = [self._ray_cast(self.spec, o, d)]
            rows = [np.arange(len(o))]
        except ValueError:  # some origin inside the solid: cast one by one
            hits, rows = [], []
            for i in range(len(o)):
                try:
                    hits.append(self._ray_cast(self.spec, o[i : i + 1], d[i : i + 1]))
                    rows.append(np.array([i]))
                except ValueError:
                    continue
        t = np.full((len(o), 1), np.nan)
        nrm = np.zeros((len(o), 1, 3))
        for h, r in zip(hits, rows, strict=True):
            ok = h.hit
            t[r[ok], 0] = h.distance[ok] / np.linalg.norm(d[r[ok]], axis=1)
            nrm[r[ok], 0] = h.n_O[ok]
        return t, nrm


def disk_pattern(radius: float, num_rings: int = 2, points_per_ring: int = 6) -> np.ndarray:
    """Offsets (2-D) of the segments on the disk: the centre plus rings.

    Ring ``j`` (1..num_rings) has radius ``j r / (num_rings + 0.5)`` and
    ``j * points_per_ring`` points, so the pattern covers the disk evenly.
    """
    radius = float(_positive("radius", radius))
    if num_rings < 0 or points_per_ring < 1:
        raise ValueError(
            f"num_rings >= 0 and points_per_ring >= 1 expected, got {num_rings}, {points_per_ring}"
        )
    pts = [np.zeros((1, 2))]
    for j in range(1, num_rings + 1):
        k = j * points_per_ring
        a = 2 * np.pi * (np.arange(k) + 0.5 * (j % 2)) / k
        rho = j * radius / (num_rings + 0.5)
        pts.append(rho * np.stack([np.cos(a), np.sin(a)], axis=1))
    return np.vstack(pts)


def mean_contact(cloud_points, cloud_normals):
    """``(p_m, n_m)``: mean point and normalised mean inward normal of a cloud (eq. 12)."""
    p = np.asarray(cloud_points, dtype=float).reshape(-1, 3)
    n = np.asarray(cloud_normals, dtype=float).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError("cloud_points: expected at least one point, got 0")
    if n.shape != p.shape:
        raise ValueError(f"cloud_normals: expected shape {p.shape}, got {n.shape}")
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(n))):
        raise ValueError("contact cloud: expected finite values, got NaN or infinity")
    n_m = n.mean(axis=0)
    norm = np.linalg.norm(n_m)
    if norm < 1e-9:
        raise ValueError("cloud_normals: the mean normal is zero (normals cancel out)")
    return p.mean(axis=0), n_m / norm


def contact_surface(
    cloud_points,
    cloud_normals,
    surface,
    radius: float,
    *,
    num_rings: int = 2,
    points_per_ring: int = 6,
    pick: str = "nearest",
):
    """Contact surface model of one contact: ``(points (k, 3), inward_normals (k, 3))``.

    Args:
        cloud_points: raw contact points (N, 3) in the object frame O (m).
        cloud_normals: their inward normals (N, 3) in O.
        surface: object surface in O (:class:`SphereSurface`, :class:`BoxSurface`,
            :class:`CylinderSurface`, :class:`MeshSurface` or anything with the same
            ``intersect`` method).
        radius: sphere radius r bounding the segments (m).
        num_rings, points_per_ring: the segment pattern (:func:`disk_pattern`).
        pick: which hit of a segment to keep: ``"nearest"`` to ``p_m`` (the
            report) or ``"first"`` along the segment from outside (use it for a
            mesh that is a union of pieces with internal faces).

    Returns:
        Surface points and inward surface normals for every segment that hits
        the surface (segments that miss are dropped; none hit -> empty arrays).
    """
    if pick not in ("nearest", "first"):
        raise ValueError(f"pick: expected 'nearest' or 'first', got {pick!r}")
    p_m, n_m = mean_contact(cloud_points, cloud_normals)
    offsets = disk_pattern(radius, num_rings, points_per_ring)
    helper = np.eye(3)[np.argmin(np.abs(n_m))]
    x = helper - helper.dot(n_m) * n_m
    x /= np.linalg.norm(x)
    y = np.cross(n_m, x)
    base = p_m + offsets[:, :1] * x + offsets[:, 1:] * y
    half = np.sqrt(np.maximum(radius**2 - np.sum(offsets**2, axis=1), 0.0))
    origins = base - half[:, None] * n_m  # from outside the object, pushing inward
    dirs = np.tile(n_m, (len(base), 1))
    t, n_out = surface.intersect(origins, dirs)
    # keep hits inside the segment [0, 2 half]; pick the one nearest p_m
    valid = np.isfinite(t) & (t >= -1e-12) & (t <= 2 * half[:, None] + 1e-12)
    hit_pts = origins[:, None, :] + np.where(valid, t, 0.0)[..., None] * dirs[:, None, :]
    if pick == "nearest":
        dist = np.where(valid, np.linalg.norm(hit_pts - p_m, axis=2), np.inf)
    else:
        dist = np.where(valid, t, np.inf)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(origins))
    hit = np.isfinite(dist[rows, best])
    pts = hit_pts[rows, best][hit]
    normals = -n_out[rows, best][hit]
    return pts, normals
