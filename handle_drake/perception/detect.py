"""Tabletop object detection from a point cloud (report section 2.3).

The pipeline, as on the report's platforms (tabletop and object-cluster
detection from a Kinect): the table is the dominant plane (RANSAC), the
points above it are clustered (DBSCAN), and each cluster becomes an object
estimate: the centre of the object's body frame (mid-height on its axis, the
catalogue's convention), its extent, the yaw of its footprint's principal
axes, and a guess of its shape (sphere / cylinder / box) from the primitive
that fits its points best, with the fit's RMS residual as the confidence.

Library pieces: scikit-learn's ``DBSCAN`` (clusters) and scipy's
``ConvexHull`` (footprint). Written here: a vectorised RANSAC for the plane
(see :func:`fit_table_plane` for why), the primitive fits (a few lines of
least squares each) and the minimum-area footprint rectangle, which no
library offers for a 2-D point set.

The camera sees one side of an object. The estimates are built to be
unbiased by that: the top face of a box or cylinder seen from above is seen
whole, so the footprint comes from the points' projection on the table; a
sphere's centre comes from a least-squares sphere fit, not the mean of the
visible cap.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

__all__ = ["TablePlane", "Detection", "DetectorParams", "fit_table_plane", "detect_objects",
           "min_area_rectangle", "KINDS"]

KINDS = ("sphere", "cylinder", "box")


@dc.dataclass(frozen=True)
class DetectorParams:
    """Thresholds of the detector (m unless named otherwise)."""

    voxel: float = 0.003  # points are thinned to one per voxel of this size
    plane_tolerance: float = 0.008  # RANSAC inlier distance to the table plane
    # Points closer to the table belong to it: 5 mm is about 4 sigma of the
    # Kinect's depth noise and one quantisation step at 1 m, seen 45 deg down
    # (no false object on an empty table over the tests' seeds), and lets a
    # 1 cm sphere through (10 mm lost 1-1.5 cm objects).
    min_height: float = 0.005
    cluster_eps: float = 0.015  # DBSCAN neighbourhood radius
    min_points: int = 10  # a cluster with fewer (thinned, 3 mm) points is noise
    ransac_trials: int = 100
    seed: int = 0

    def __post_init__(self):
        for field in ("voxel", "plane_tolerance", "min_height", "cluster_eps"):
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"DetectorParams.{field} must be a finite number > 0, "
                                 f"got {value!r}")
        for field in ("min_points", "ransac_trials"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DetectorParams.{field} must be an integer >= 1, "
                                 f"got {value!r}")


@dc.dataclass
class TablePlane:
    normal: np.ndarray  # (3,) unit, pointing up (world +z side)
    offset: float  # plane: normal . p = offset
    inliers: int

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of N x 3 points above the plane."""
        return points @ self.normal - self.offset


@dc.dataclass
class Detection:
    position: np.ndarray  # (3,) m, world: centre of the object's body frame
    extent: np.ndarray  # (3,) m: footprint length (major), width (minor), height
    yaw: float  # rad in [0, pi): direction of the footprint's major axis
    kind: str  # sphere | cylinder | box
    residual: float  # m, RMS distance of the points to the chosen primitive
    residuals: dict  # m, RMS residual of every primitive tried
    num_points: int

    def as_dict(self) -> dict:
        return {"position": [float(v) for v in self.position],
                "extent": [float(v) for v in self.extent],
                "yaw": float(self.yaw), "kind": self.kind,
                "residual": float(self.residual),
                # A primitive ruled out (inf) is null: JSON has no infinity.
                "residuals": {k: float(v) if math.isfinite(v) else None
                              for k, v in self.residuals.items()},
                "num_points": int(self.num_points)}


def _check_points(points) -> np.ndarray:
    points = np.asarray(points)
    if np.iscomplexobj(points):
        raise TypeError("points must be real, got a complex array")
    points = points.astype(float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be an N x 3 array (m), got shape {points.shape}")
    return points[np.all(np.isfinite(points), axis=1)]


def _voxel_thin(points: np.ndarray, voxel: float) -> np.ndarray:
    if len(points) == 0:
        return points
    keys = np.floor(points / voxel).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, first = np.unique(flat, return_index=True)
    return points[np.sort(first)]


def fit_table_plane(points: np.ndarray, params: DetectorParams | None = None
                    ) -> TablePlane | None:
    """The dominant plane of ``points`` (N x 3, world) by RANSAC, refined by a
    least-squares (SVD) fit to all its inliers; ``None`` with fewer than 3
    points or no plane. The normal is returned pointing to world +z's side.

    RANSAC is written out (vectorised numpy: every trial's plane scored in one
    matrix product on a random subset) rather than scikit-learn's
    ``RANSACRegressor``: that fits z = f(x, y), one estimator call per trial,
    and took 0.12 s a frame, twice the frame's rendering time."""
    return _fit_plane(_check_points(points), DetectorParams() if params is None else params)


def _fit_plane(points: np.ndarray, params: DetectorParams) -> TablePlane | None:
    if len(points) < 3:
        return None
    rng = np.random.default_rng(params.seed)
    subset = points if len(points) <= 1500 else points[rng.choice(len(points), 1500, False)]
    triples = subset[rng.integers(0, len(subset), size=(params.ransac_trials, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    good = norms > 1e-12
    if not np.any(good):
        return None
    normals = normals[good] / norms[good, None]
    offsets = np.einsum("ij,ij->i", normals, triples[good, 0])
    counts = (np.abs(subset @ normals.T - offsets) <= params.plane_tolerance).sum(axis=0)
    best = int(np.argmax(counts))
    inliers = points[np.abs(points @ normals[best] - offsets[best]) <= params.plane_tolerance]
    if len(inliers) < 3:
        return None
    count = len(inliers)
    if count > 20000:  # plenty for a plane's least squares
        inliers = inliers[rng.choice(count, 20000, False)]
    centroid = inliers.mean(axis=0)
    centred = inliers - centroid
    _, vectors = np.linalg.eigh(centred.T @ centred)
    normal = vectors[:, 0]  # least spread: the plane's normal
    if normal[2] < 0:
        normal = -normal
    return TablePlane(normal=normal, offset=float(normal @ centroid), inliers=count)


def min_area_rectangle(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The minimum-area rectangle around 2-D points (rotating calipers over the
    convex hull's edges): ``(centre (2,), (length, width), angle)`` with the
    angle (rad, in [0, pi)) of the longer side."""
    from scipy.spatial import ConvexHull, QhullError

    xy = np.asarray(xy, dtype=float)
    try:
        hull = xy[ConvexHull(xy).vertices]
    except (QhullError, ValueError):
        hull = xy  # degenerate (collinear or too few points)
    best = None
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    for angle in angles if len(angles) else [0.0]:
        c, s = math.cos(angle), math.sin(angle)
        R = np.array([[c, s], [-s, c]])  # world -> rectangle axes
        local = hull @ R.T
        low, high = local.min(axis=0), local.max(axis=0)
        area = float(np.prod(high - low))
        if best is None or area < best[0]:
            best = (area, angle, low, high, R)
    _, angle, low, high, R = best
    centre = R.T @ ((low + high) / 2)
    size = high - low
    if size[1] > size[0]:
        size = size[::-1]
        angle += np.pi / 2
    return centre, size, float(np.mod(angle, np.pi))


def _fit_sphere(points):
    # |p|^2 = 2 c.p + (r^2 - |c|^2): linear least squares in (c, k).
    A = np.column_stack([2 * points, np.ones(len(points))])
    b = (points ** 2).sum(axis=1)
    solution, *_ = np.linalg.lstsq(A, b, rcond=None)
    centre = solution[:3]
    radius = math.sqrt(max(solution[3] + centre @ centre, 0.0))
    residual = np.sqrt(np.mean((np.linalg.norm(points - centre, axis=1) - radius) ** 2))
    return centre, radius, float(residual)


def _fit_circle(xy):
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    solution, *_ = np.linalg.lstsq(A, b, rcond=None)
    centre = solution[:2]
    radius = math.sqrt(max(solution[2] + centre @ centre, 0.0))
    return centre, radius


def _cylinder_residual(local, centre, radius, height):
    # Distance to the closed cylinder (side and top; the bottom is on the table).
    r = np.linalg.norm(local[:, :2] - centre, axis=1)
    side = np.abs(r - radius)
    top = np.where(r <= radius, np.abs(local[:, 2] - height),
                   np.hypot(r - radius, local[:, 2] - height))
    return float(np.sqrt(np.mean(np.minimum(side, top) ** 2)))


def _box_residual(local_xy, z, half, height):
    # Distance of points to the surface of an axis-aligned box (local frame).
    q = np.column_stack([np.abs(local_xy) - half, np.abs(z - height / 2) - height / 2])
    outside = np.linalg.norm(np.maximum(q, 0), axis=1)
    inside = np.minimum(q.max(axis=1), 0)
    return float(np.sqrt(np.mean((outside + inside) ** 2)))


def _describe(cluster: np.ndarray, plane: TablePlane) -> Detection:
    # Table frame: origin on the plane under the world origin, z = normal.
    n = plane.normal
    x_axis = np.cross([0.0, 1.0, 0.0], n)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(n, x_axis)
    origin = plane.offset * n
    R_WT = np.column_stack([x_axis, y_axis, n])
    local = (cluster - origin) @ R_WT
    height = float(np.percentile(local[:, 2], 99.5))
    centre_xy, (length, width), angle = min_area_rectangle(local[:, :2])

    # Sphere: fit all points.
    s_centre, s_radius, s_res = _fit_sphere(local)
    # Cylinder about the table normal: a circle through the side's points
    # (the top is a filled disc: fitting it too would shrink the circle).
    side = local[local[:, 2] < height - 0.004]
    c_centre, c_radius = _fit_circle((side if len(side) >= 10 else local)[:, :2])
    c_res = _cylinder_residual(local, c_centre, c_radius, height)
    # Box: the minimum-area footprint rectangle extruded to the height.
    c, s = math.cos(angle), math.sin(angle)
    R = np.array([[c, s], [-s, c]])
    # The rectangle's axes come from the hull; its size and centre from the
    # 0.5-99.5 % range along them, so a few noisy edge pixels (a Kinect's
    # flying pixels) do not widen it.
    along = (local[:, :2] - centre_xy) @ R.T
    low, high = np.percentile(along, [0.5, 99.5], axis=0)
    centre_xy = centre_xy + R.T @ ((low + high) / 2)
    length, width = high - low
    b_res = _box_residual((local[:, :2] - centre_xy) @ R.T, local[:, 2],
                          np.array([length, width]) / 2, height)
    residuals = {"sphere": s_res, "cylinder": c_res, "box": b_res}
    # A sphere must also look like one: resting on the table, as tall as wide.
    if not (abs(s_centre[2] - s_radius) < 0.25 * s_radius + 0.003
            and abs(2 * s_radius - height) < 0.25 * height + 0.003):
        residuals["sphere"] = math.inf
    kind = min(residuals, key=residuals.get)
    if kind == "sphere":
        centre_local = s_centre
        extent = np.array([2 * s_radius, 2 * s_radius, height])
    elif kind == "cylinder":
        centre_local = np.array([*c_centre, height / 2])
        extent = np.array([2 * c_radius, 2 * c_radius, height])
    else:
        centre_local = np.array([*centre_xy, height / 2])
        extent = np.array([length, width, height])
    # Yaw of the major axis, measured in world about the table normal.
    major_W = R_WT @ np.array([math.cos(angle), math.sin(angle), 0.0])
    yaw = float(np.mod(math.atan2(major_W[1], major_W[0]), np.pi))
    return Detection(position=origin + R_WT @ centre_local, extent=extent, yaw=yaw, kind=kind,
                     residual=residuals[kind], residuals=residuals,
                     num_points=len(cluster))


def _merge_stacked(clusters: list[np.ndarray], plane: TablePlane) -> list[np.ndarray]:
    """Clusters whose footprints overlap are one object: a thin part seen
    apart from the rest (a wine glass's stem between bowl and foot) stands on
    the same spot of the table. Objects on a table do not stack here."""
    def footprint(cluster):
        flat = cluster - np.outer(plane.height(cluster), plane.normal)
        low, high = flat.min(axis=0), flat.max(axis=0)
        return (low + high) / 2, float(np.linalg.norm(high - low)) / 2

    merged = True
    while merged and len(clusters) > 1:
        merged = False
        prints = [footprint(c) for c in clusters]
        for i in range(len(clusters)):
            for j in range(i + 1, len(clusters)):
                (ci, ri), (cj, rj) = prints[i], prints[j]
                if np.linalg.norm(ci - cj) < max(ri, rj):
                    clusters[i] = np.vstack([clusters[i], clusters.pop(j)])
                    merged = True
                    break
            if merged:
                break
    return clusters


def detect_objects(points, params: DetectorParams | None = None
                   ) -> tuple[TablePlane | None, list[Detection]]:
    """Table plane and object detections from world-frame points (N x 3, m;
    non-finite rows, i.e. invalid pixels, are dropped). An empty or object-free
    view gives an empty list, not an error. Detections are sorted by their
    distance from the world origin."""
    from sklearn.cluster import DBSCAN

    params = DetectorParams() if params is None else params
    points = _check_points(points)
    plane = _fit_plane(points, params)
    if plane is None:
        return None, []
    above = _voxel_thin(points[plane.height(points) > params.min_height], params.voxel)
    if len(above) < params.min_points:
        return plane, []
    labels = DBSCAN(eps=params.cluster_eps, min_samples=5).fit_predict(above)
    clusters = [above[labels == label] for label in sorted(set(labels) - {-1})]
    detections = []
    for cluster in _merge_stacked(clusters, plane):
        if len(cluster) >= params.min_points:
            detections.append(_describe(cluster, plane))
    detections.sort(key=lambda d: float(np.linalg.norm(d.position[:2])))
    return plane, detections
