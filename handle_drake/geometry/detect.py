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
from scipy.spatial import ConvexHull, QhullError, cKDTree

__all__ = ["TablePlane", "Detection", "DetectorParams", "fit_table_plane", "detect_objects",
           "min_area_rectangle", "KINDS", "TabletopDetector", "detect"]

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
    cluster_eps: float = 0.008  # DBSCAN neighbourhood radius
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
    # The catalogue kind told from the round (cylinder) detections' outline
    # (:func:`round_shape`): cylinder | mug | wine_glass | star_prism | other; for a
    # sphere and a box their own kind; its characteristic size (m: the cylinder's, mug's
    # and glass bowl's diameter, the star's tip-to-tip diameter) and yaw (rad: the mug's
    # handle, a star tip's direction, within its turn of symmetry; else ``yaw``).
    shape: str = ""
    shape_size: float = 0.0
    shape_yaw: float = 0.0

    @property
    def pose(self):
        """``X_WO`` (pydrake ``RigidTransform``): the detected centre, turned
        by ``yaw`` about world z (the footprint's major axis along x)."""
        from pydrake.math import RigidTransform, RotationMatrix

        return RigidTransform(RotationMatrix.MakeZRotation(float(self.yaw)),
                              np.asarray(self.position, dtype=float))

    def as_dict(self) -> dict:
        return {"position": [float(v) for v in self.position],
                "extent": [float(v) for v in self.extent],
                "yaw": float(self.yaw), "kind": self.kind,
                "residual": float(self.residual),
                # A primitive ruled out (inf) is null: JSON has no infinity.
                "residuals": {k: float(v) if math.isfinite(v) else None
                              for k, v in self.residuals.items()},
                "num_points": int(self.num_points), "shape": self.shape,
                "shape_size": float(self.shape_size), "shape_yaw": float(self.shape_yaw)}


def _check_points(points) -> np.ndarray:
    points = _check_rows(points)
    # One pass: a row with an inf or nan sums to a non-finite value (inf - inf
    # is nan). float32 input (Drake's clouds) stays float32 here; the few
    # points above the table are made float64 for the fits.
    return points[np.isfinite(points[:, 0] + points[:, 1] + points[:, 2])]


def _check_rows(points) -> np.ndarray:
    """``points`` as an N x 3 float array, non-finite rows kept (the hot path
    drops them after the height test, on the few points above the table)."""
    points = np.asarray(points)
    if np.iscomplexobj(points):
        raise TypeError("points must be real, got a complex array")
    if points.dtype not in (np.float32, np.float64):
        points = points.astype(float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be an N x 3 array (m), got shape {points.shape}")
    return points


def _sample_finite(points: np.ndarray, params: DetectorParams, size: int = 20000) -> np.ndarray:
    """At most ``size`` of the finite rows, evenly strided through the cloud
    (an image's rows): what the table plane is fitted to."""
    points = points[::max(1, len(points) // (2 * size))]  # evenly over the image
    points = points[np.isfinite(points[:, 0] + points[:, 1] + points[:, 2])]
    return np.asarray(points[::max(1, -(-len(points) // size))], dtype=float)


def _above(points: np.ndarray, plane: TablePlane, min_height: float) -> np.ndarray:
    """The finite points more than ``min_height`` above ``plane`` (float64).
    One pass over the columns (a Drake cloud's N x 3 view is column-major:
    each column is contiguous); non-finite rows fail the test or are dropped
    after it."""
    n = plane.normal.astype(points.dtype)
    with np.errstate(invalid="ignore", over="ignore"):  # inf rows: nan or inf, dropped
        height = points[:, 0] * n[0]
        height += points[:, 1] * n[1]
        height += points[:, 2] * n[2]
        index = np.flatnonzero(height > plane.offset + min_height)
    above = np.column_stack([points[index, 0], points[index, 1], points[index, 2]]).astype(float)
    return above[np.isfinite(above).all(axis=1)]


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
    # Everything below works on a random sample of at most 20000 points (with
    # replacement: choosing without it permutes the whole cloud): plenty for a
    # plane, and the cost no longer grows with the image.
    sample = points if len(points) <= 20000 else points[rng.integers(0, len(points), 20000)]
    sample = np.asarray(sample, dtype=float)
    subset = sample if len(sample) <= 1500 else sample[rng.integers(0, len(sample), 1500)]
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
    inliers = sample[np.abs(sample @ normals[best] - offsets[best]) <= params.plane_tolerance]
    if len(inliers) < 3:
        return None
    centroid = inliers.mean(axis=0)
    centred = inliers - centroid
    _, vectors = np.linalg.eigh(centred.T @ centred)
    normal = vectors[:, 0]  # least spread: the plane's normal
    if normal[2] < 0:
        normal = -normal
    # ``inliers`` counts the whole cloud's points (the sample's share scaled).
    count = int(round(len(inliers) * len(points) / len(sample)))
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
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    if not len(angles):
        angles = np.zeros(1)
    # Every candidate angle at once: the hull in each rectangle's axes.
    c, s = np.cos(angles), np.sin(angles)
    u = hull[:, 0, None] * c + hull[:, 1, None] * s  # (points, angles)
    v = -hull[:, 0, None] * s + hull[:, 1, None] * c
    lows = np.stack([u.min(axis=0), v.min(axis=0)], axis=1)
    highs = np.stack([u.max(axis=0), v.max(axis=0)], axis=1)
    k = int(np.argmin(np.prod(highs - lows, axis=1)))
    angle, low, high = float(angles[k]), lows[k], highs[k]
    R = np.array([[c[k], s[k]], [-s[k], c[k]]])  # world -> rectangle axes
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


def _fit_circle_robust(xy, tolerance: float = 0.003, rounds: int = 3):
    """A circle through ``xy`` that ignores what is off it (a mug's handle,
    the inside of its cup, a glass's stem): least squares, then refits on the
    points within ``tolerance`` (m, or 2.5 median deviations if larger) of
    the last circle."""
    centre, radius = _fit_circle(xy)
    for _ in range(rounds):
        deviation = np.abs(np.linalg.norm(xy - centre, axis=1) - radius)
        keep = deviation <= max(tolerance, 2.5 * float(np.median(deviation)))
        if keep.sum() < 10 or keep.all():
            break
        centre, radius = _fit_circle(xy[keep])
    return centre, radius


def _hull_fill(xy: np.ndarray) -> float:
    """Area of the convex hull of ``xy`` over that of its minimum-area
    rectangle: 1 for a rectangle, pi/4 for a disc (nan if degenerate)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(xy) < 5:
        return math.nan
    try:
        hull_area = ConvexHull(xy).volume
    except (QhullError, ValueError):
        return math.nan
    _, (length, width), _ = min_area_rectangle(xy)
    return float(hull_area / (length * width)) if length * width > 0 else math.nan


#: A top face whose hull fills more than this share of its minimum-area
#: rectangle is a box's (a rectangle: 1; a disc: pi/4 = 0.785). Measured over
#: seeded scenes (seeds 100-139): upright cuboids' top slices 0.88-0.97 (10th
#: percentile to max), cylinders, glasses, mugs and star prisms 0.78-0.84.
BOX_FILL = 0.85
#: ... and whose box fit's RMS residual is at most this times the cylinder's
#: (box over cylinder residual, development seeds: upright cuboids 0.12-1.13,
#: round objects 0.44-4.75, median 1.41).
BOX_RESIDUAL_RATIO = 1.3
#: A box fitting better than this times the cylinder's residual is a box
#: whatever its top's outline (round objects on the development seeds: at
#: least 0.44, star prisms; two whole cuboids near the camera with their
#: tops cut by the sensor's range, from the fresh block: 0.25).
BOX_CLEAR_RATIO = 0.3


def _table_frame(plane: TablePlane):
    """``(origin, R_WT)``: the table frame (origin on the plane under the world
    origin, z = the normal), computed once per plane."""
    cached = plane.__dict__.get("_frame")
    if cached is None:
        n = plane.normal
        x_axis = np.cross([0.0, 1.0, 0.0], n)
        x_axis /= np.linalg.norm(x_axis)
        y_axis = np.cross(n, x_axis)
        cached = plane.__dict__["_frame"] = (plane.offset * n,
                                             np.column_stack([x_axis, y_axis, n]))
    return cached


#: The most points of a cluster the primitive fits use.
DESCRIBE_POINTS = 800


def _describe(cluster: np.ndarray, plane: TablePlane) -> Detection:
    # Table frame: origin on the plane under the world origin, z = normal.
    origin, R_WT = _table_frame(plane)
    # At most DESCRIBE_POINTS points (evenly through the cluster, already
    # thinned to a 3 mm grid): the fits' cost stays bounded per object.
    step = -(-len(cluster) // DESCRIBE_POINTS)
    local = (np.asarray(cluster[::step], dtype=float) - origin) @ R_WT
    height = float(np.percentile(local[:, 2], 99.5))
    centre_xy, (length, width), angle = min_area_rectangle(local[:, :2])

    # Sphere: fit all points.
    s_centre, s_radius, s_res = _fit_sphere(local)
    # Cylinder about the table normal: a circle through the side's points
    # (the top is a filled disc: fitting it too would shrink the circle),
    # robust to what is no part of the cylinder (a mug's handle).
    side = local[local[:, 2] < height - 0.004]
    c_centre, c_radius = _fit_circle_robust((side if len(side) >= 10 else local)[:, :2])
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
    # A sphere must also look like one: resting on the table, as tall as its
    # fitted diameter, and as long (a low star prism's top fits a sphere's cap).
    if not (abs(s_centre[2] - s_radius) < 0.25 * s_radius + 0.003
            and abs(2 * s_radius - height) < 0.25 * height + 0.003
            and abs(2 * s_radius - length) < 0.15 * length + 0.003):
        residuals["sphere"] = math.inf
    kind = min(residuals, key=residuals.get)
    if kind != "sphere":
        # Box or cylinder: the top face's outline decides, not the residuals
        # (a box seen face-on shows a top strip and one face, which a circle
        # through the face's points fits as well as the box does): does its
        # hull fill its rectangle? The top slice: the points within 6 mm (or
        # a tenth of the height) of the top.
        # A box must also fit about as well as the cylinder: a mug partly
        # hidden, its rim's arc and handle in the top slice, fills 0.86 but
        # fits a box 1.5x worse (upright cuboids: at most 1.13x, measured on
        # the development seeds).
        top = local[local[:, 2] > height - max(0.006, 0.1 * height), :2]
        fill = _hull_fill(top)
        if math.isfinite(fill):
            box_like = fill > BOX_FILL and b_res <= BOX_RESIDUAL_RATIO * c_res
            # ... or the box fits far better, whatever the top's outline (a box
            # near the camera, its top's near part beyond the sensor's range:
            # the outline is cut and fills less).
            kind = "box" if box_like or b_res < BOX_CLEAR_RATIO * c_res else "cylinder"
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
    shape, size, shape_yaw = _shape(kind, extent, yaw, local, c_centre, c_radius, height,
                                    R_WT, centre_local)
    return Detection(position=origin + R_WT @ centre_local, extent=extent, yaw=yaw, kind=kind,
                     residual=residuals[kind], residuals=residuals,
                     num_points=len(cluster), shape=shape, shape_size=float(size),
                     shape_yaw=float(shape_yaw))


def _shape(kind, extent, yaw, local, c_centre, c_radius, height, R_WT, centre_local):
    """``(shape, size, yaw)`` of a detection (:class:`Detection`'s fields): a sphere's and
    a box's their own; a round one's by :func:`round_shape`, its size corrected by
    ``SHAPE_SIZE_BIAS`` and its yaw turned into the world (a star's centre moved to its
    top face's, in ``centre_local``)."""
    if kind == "sphere":
        return "sphere", extent[0], yaw
    if kind == "box":
        return "cuboid", extent[0], yaw
    shape, size, turn = round_shape(local, c_centre, c_radius, height)
    x_W = R_WT @ np.array([math.cos(turn), math.sin(turn), 0.0])
    if shape == "star_prism":  # the top face's centre, not the side's circle
        centre_local[:2] = _top_centre(local, height)
    return shape, size + SHAPE_SIZE_BIAS.get(shape, 0.0), math.atan2(x_W[1], x_W[0])


def _top_centre(local: np.ndarray, height: float) -> np.ndarray:
    """The centroid of the top face's points (seen whole from above)."""
    top = local[local[:, 2] > height - max(0.006, 0.1 * height), :2]
    return top.mean(axis=0) if len(top) else local[:, :2].mean(axis=0)


#: A star prism: the top face's outline (its furthest point per 10 deg about the
#: centre) varies with five-fold symmetry by more than this share of its mean radius
#: (a star of the catalogue's proportions, tips 1 and notches 0.45: ~0.3; a disc: ~0).
STAR_HARMONIC = 0.12
#: A mug: points this far (m) outside the cup's circle, between 15 % and 85 % of its
#: height, make a handle when there are at least ``HANDLE_POINTS`` of them.
HANDLE_GAP = 0.004
HANDLE_POINTS = 6
#: A wine glass: of the points up to 35 % of its height (above the foot), at most this
#: share lie beyond 60 % of the bowl's radius (a cylinder's or a mug's side: most).
GLASS_LOW_WIDE = 0.15
#: Added to the measured size (m) of each round shape: the median error of the
#: measurement on the development scenes (perception's random_scene seeds 100-119,
#: Kinect v1 profile): a star's tips are thin slivers of the top slice (-4.0 mm), a
#: glass's upper points include its narrower rim (-5.6 mm), a mug's cup circle is fitted
#: on the outer wall seen from one side (-4.1 mm), a cylinder's (-0.7 mm).
SHAPE_SIZE_BIAS = {"star_prism": 0.0040, "wine_glass": 0.0056, "mug": 0.0041,
                   "cylinder": 0.0007}


def round_shape(local: np.ndarray, centre, radius: float, height: float):
    """``(kind, size, yaw)`` of a round (cylinder) detection from its points in the
    table frame (``local``, z up from the table), the side's fitted circle (``centre``,
    ``radius``) and height: a star prism (a five-fold outline of its top), a mug (points
    beyond its cup's circle: the handle), a wine glass (nothing wide low down: the stem),
    else a cylinder. ``yaw`` (rad, table frame): a star tip's direction, the mug's
    handle's, else 0."""
    centre = np.asarray(centre, dtype=float)
    top = local[local[:, 2] > height - max(0.006, 0.1 * height)]
    if len(top) >= 20:
        c = _top_centre(local, height)
        d = top[:, :2] - c
        r, theta = np.linalg.norm(d, axis=1), np.arctan2(d[:, 1], d[:, 0])
        bins = np.floor((theta + np.pi) / np.radians(10)).astype(int)
        outline = np.zeros(36)
        np.maximum.at(outline, np.clip(bins, 0, 35), r)
        seen = outline > 0
        angles = -np.pi + np.radians(10) * (np.arange(36) + 0.5)
        if seen.sum() >= 24:
            mean = outline[seen].mean()
            harmonics = np.abs([np.sum((outline[seen] - mean) * np.exp(-k * 1j * angles[seen]))
                                for k in range(1, 7)]) * 2 / seen.sum()
            five = np.sum((outline[seen] - mean) * np.exp(-5j * angles[seen])) * 2 / seen.sum()
            # A star's outline is five-fold above all; a top seen in part (its near edge
            # out of the camera's range, a glass's rim over its far wall) is lopsided:
            # its first or second harmonic leads.
            if abs(five) > STAR_HARMONIC * mean and np.argmax(harmonics) == 4:
                return ("star_prism", 2 * float(np.percentile(r, 98)),
                        -float(np.angle(five)) / 5)
    r_side = np.linalg.norm(local[:, :2] - centre, axis=1)
    middle = (local[:, 2] > 0.15 * height) & (local[:, 2] < 0.85 * height)
    handle = middle & (r_side > radius + HANDLE_GAP)
    if handle.sum() >= HANDLE_POINTS:
        d = np.mean(local[handle, :2] - centre, axis=0)
        return "mug", 2 * radius, float(math.atan2(d[1], d[0]))
    low = local[:, 2] < 0.35 * height
    low = low & (local[:, 2] > 0.08 * height)
    if low.sum() == 0 or np.mean(r_side[low] > 0.6 * radius) <= GLASS_LOW_WIDE:
        upper = local[:, 2] > 0.6 * height
        bowl = 2 * float(_fit_circle_robust(local[upper, :2])[1]) if upper.sum() >= 10 \
            else 2 * radius
        return "wine_glass", bowl, 0.0
    return "cylinder", 2 * radius, 0.0


def _grid_clusters(points: np.ndarray, cell: float) -> np.ndarray:
    """Cluster labels (0, 1, ...) of ``points``: the connected components of
    the occupied cells of a grid of ``cell`` (m), cells touching by a face,
    an edge or a corner (points up to about two cells apart join).
    Vectorised on the occupied cells only (sorted cell keys, a binary search
    for each of the 13 forward neighbours, scipy's connected components): the
    cost follows the number of points, not the volume they span, and stays a
    millisecond or two where DBSCAN's neighbour pairs took tens."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    keys = np.floor(points / cell).astype(np.int64)
    keys -= keys.min(axis=0) - 1  # a margin of one cell: neighbours stay >= 0
    span = keys.max(axis=0) + 2
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    cells, inverse = np.unique(flat, return_inverse=True)
    offsets = np.array([(dx * span[1] + dy) * span[2] + dz
                        for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                        if (dx, dy, dz) > (0, 0, 0)])
    neighbours = cells[:, None] + offsets  # (cells, 13)
    where = np.searchsorted(cells, neighbours).clip(max=len(cells) - 1)
    hit = cells[where] == neighbours
    rows = np.broadcast_to(np.arange(len(cells))[:, None], hit.shape)[hit]
    graph = coo_matrix((np.ones(len(rows)), (rows, where[hit])), shape=(len(cells),) * 2)
    _, labels = connected_components(graph, directed=False)
    return labels[inverse.ravel()]


#: A footprint filling at least this share of its convex hull is one object
#: (no split is searched for).
SOLID = 0.92


def _split_touching(cluster: np.ndarray, plane: TablePlane, cell: float) -> list[np.ndarray]:
    """Objects that touch (or stand closer than the clustering reach) make one
    cluster; their footprints (points projected on the table) make a shape
    with a waist. The distance transform of the footprint (distance to its
    outline) is low at a waist and high inside each object: cut at a level
    ``c`` (3 mm upwards), the footprint falls apart into cores; a core counts
    if its peak is at least 6 mm and ``c / 0.6`` (the waist is narrow against
    the objects on either side). With two cores or more, every footprint cell
    goes to its nearest core. An elongated box's footprint has no waist, and
    a mug's handle (7 mm thick) no core of its own."""
    from scipy import ndimage
    from scipy.spatial import ConvexHull, QhullError

    if len(cluster) < 20:
        return [cluster]
    origin, R_WT = _table_frame(plane)
    xy = (np.asarray(cluster, dtype=float) - origin) @ R_WT[:, :2]
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(int) + 2
    grid = np.zeros(ij.max(axis=0) + 3, dtype=bool)
    grid[ij[:, 0], ij[:, 1]] = True
    grid = ndimage.binary_fill_holes(ndimage.binary_closing(grid, iterations=1))
    # A footprint that fills its convex hull has no waist: one object (most
    # clusters; a box, a ball, a can). The cut search below is for the rest.
    occupied = np.argwhere(grid)
    try:
        hull = ConvexHull(occupied)
    except (QhullError, ValueError):
        return [cluster]
    # Cells inside a convex polygon through cell centres: area + perimeter / 2.
    if len(occupied) >= SOLID * (hull.volume + 0.5 * hull.area):
        return [cluster]
    dist = ndimage.distance_transform_edt(grid) * cell
    if dist.max() < 2 * 0.006:
        return [cluster]  # too small to hold two objects of 12 mm
    for cut in np.arange(0.003, 0.6 * dist.max(), cell):
        cores, count = ndimage.label(dist > cut)
        if count < 2:
            continue
        peaks = ndimage.maximum(dist, cores, index=np.arange(1, count + 1))
        keep = np.flatnonzero(peaks >= max(0.006, cut / 0.6)) + 1
        if len(keep) < 2:
            continue
        seeds = np.where(np.isin(cores, keep), cores, 0)
        _, (ni, nj) = ndimage.distance_transform_edt(seeds == 0, return_indices=True)
        owner = seeds[ni, nj][ij[:, 0], ij[:, 1]]
        return [cluster[owner == k] for k in keep if np.any(owner == k)]
    return [cluster]


#: Two clusters whose footprint hulls overlap by at least this share of the
#: smaller one's area are one object (upright objects on a table do not
#: overlap in footprint: a wine glass's bowl seen as its near wall and the
#: inside of its far wall, apart from its foot).
HULL_OVERLAP = 0.2
#: A fragment (a few points, or a thin strip: a box's face seen edge-on)
#: whose footprint lies within this distance (m) of a larger cluster's hull
#: is part of it.
FRAGMENT_REACH = 0.004


#: Pieces of one object seen apart around a nearer object (a box behind a
#: wine glass, seen beside its stem and under its bowl) join when each has
#: fewer points than this (thinned), what lies between them is hidden from
#: the camera by a nearer surface, and together they are no longer than
#: :data:`PIECES_LENGTH` (m; the catalogue's largest footprint, a 90 mm mug
#: with its handle, is 117 mm).
PIECE_POINTS = 100
PIECES_LENGTH = 0.12


def _hidden_between(a: np.ndarray, b: np.ndarray, camera: np.ndarray,
                    rays: tuple) -> bool:
    """Whether the camera (at ``camera``, world) cannot see the space between
    the 3-D point sets ``a`` and ``b``: on the segment between their nearest
    points, each of 5 samples has a point of the cloud (``rays``: the unit
    directions' ``cKDTree`` and the ranges of the points above the table)
    within 4 mm of its line of sight and at least 1 cm nearer."""
    distance, nearest = cKDTree(b).query(a)
    k = int(np.argmin(distance))
    p, q = a[k], b[nearest[k]]
    tree, ranges = rays
    for t in (0.1, 0.3, 0.5, 0.7, 0.9):
        sample = p + t * (q - p) - camera
        length = float(np.linalg.norm(sample))
        near = tree.query_ball_point(sample / length, 0.004 / length)
        if not near or not np.any(ranges[near] < length - 0.01):
            return False
    return True


def _unseen_between(a: np.ndarray, b: np.ndarray, view) -> bool:
    """Whether the camera got no return at all between the 3-D point sets
    ``a`` and ``b``: on the middle of the segment between their nearest
    points, each of 3 samples (at 0.3, 0.5, 0.7) projects (``view``: a depth
    frame's ``depth``, ``K``, ``X_WC``) to a 3 x 3 patch of mostly (>= 5)
    invalid pixels (the segment's ends lie on the cut's edge, where the
    table behind shows). That is a surface nearer than the
    sensor's range (a tall object near the camera: its near top is cut off
    and the rest is seen as its far top and its side, apart), never empty
    space between two objects (the table behind it is in range)."""
    distance, nearest = cKDTree(b).query(a)
    k = int(np.argmin(distance))
    p, q = a[k], b[nearest[k]]
    depth, K, X_WC = view.depth, np.asarray(view.K, dtype=float), np.asarray(view.X_WC, float)
    rows, cols = depth.shape
    for t in (0.3, 0.5, 0.7):
        p_C = X_WC[:3, :3].T @ (p + t * (q - p) - X_WC[:3, 3])
        if p_C[2] <= 0:
            return False
        u, v = (K[:2, :2] @ (p_C[:2] / p_C[2]) + K[:2, 2]).round().astype(int)
        if not (1 <= u < cols - 1 and 1 <= v < rows - 1):
            return False
        patch = depth[v - 1:v + 2, u - 1:u + 2]
        if np.count_nonzero(np.isfinite(patch) & (patch > 0)) > 4:
            return False
    return True


def _hull_equations(xy: np.ndarray):
    try:
        return ConvexHull(xy).equations
    except (QhullError, ValueError):
        return None


def _hull_overlap(a: np.ndarray, b: np.ndarray, cell: float = 0.0015) -> float:
    """Area shared by the convex hulls of the 2-D point sets ``a`` and ``b``
    over the smaller hull's area, counted on a grid of ``cell`` (m) over the
    hulls' common bounding box (0 if they do not meet or one is degenerate).
    (scipy has no polygon intersection and shapely is no dependency: a grid
    of a few hundred cells is exact enough for a share.)"""
    lo = np.maximum(a.min(axis=0), b.min(axis=0))
    hi = np.minimum(a.max(axis=0), b.max(axis=0))
    if np.any(hi <= lo):
        return 0.0
    ea, eb = _hull_equations(a), _hull_equations(b)
    if ea is None or eb is None:
        return 0.0

    def area(eq, low, high):  # grid cells inside the hull within [low, high]
        xs = np.arange(low[0], high[0] + cell, cell)
        ys = np.arange(low[1], high[1] + cell, cell)
        grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        return grid, (grid @ eq[:, :2].T + eq[:, 2]).max(axis=1) <= 0

    grid, in_a = area(ea, lo, hi)
    both = np.count_nonzero(in_a & ((grid @ eb[:, :2].T + eb[:, 2]).max(axis=1) <= 0))
    if both == 0:
        return 0.0
    smaller = min(np.count_nonzero(area(e, p.min(axis=0), p.max(axis=0))[1])
                  for e, p in ((ea, a), (eb, b)))
    return both / max(smaller, 1)


def _join_across(flats: list[np.ndarray], components: list[int], clusters=None,
                 camera=None, view=None) -> list[int]:
    """Owner (union-find parent) of each cluster after joining the parts of
    one object that the camera sees apart (different connected components):
    footprint hulls that overlap (:data:`HULL_OVERLAP`), or a fragment
    (fewer than a quarter of the other's points, and fewer than 30 or a strip
    under 6 mm wide) within :data:`FRAGMENT_REACH` of the other's hull. Parts
    of one component (split at a waist by :func:`_split_touching`) are never
    joined here. Objects 15-20 mm apart stay apart: their hulls neither
    overlap nor come within 4 mm. With the ``camera``'s position (world) and
    the ``clusters`` (world points), also small pieces of one object seen
    apart around a nearer one (:data:`PIECE_POINTS`, :func:`_hidden_between`);
    with the depth ``view`` too, parts of any size with no return between
    them (:func:`_unseen_between`: a near top out of the sensor's range),
    together at most :data:`PIECES_LENGTH` long."""
    owner = list(range(len(flats)))
    rays = []  # the lines of sight's tree, built when a pair of pieces needs it

    def lines_of_sight():
        if not rays:
            cloud = np.vstack(clusters) - camera
            ranges = np.linalg.norm(cloud, axis=1)
            rays.extend([cKDTree(cloud / ranges[:, None]), ranges])
        return tuple(rays)

    def find(a):
        while owner[a] != a:
            a = owner[a]
        return a

    xy = [f[:, :2] for f in flats]
    boxes = np.array([[*p.min(axis=0), *p.max(axis=0)] for p in xy])
    order = np.argsort([-len(f) for f in flats], kind="stable")  # larger first
    for a, i in enumerate(order):
        for j in order[a + 1:]:
            if components[i] == components[j] or find(i) == find(j):
                continue
            lo, hi = boxes[i], boxes[j]
            reach = FRAGMENT_REACH
            near = not (lo[0] > hi[2] + reach or hi[0] > lo[2] + reach
                        or lo[1] > hi[3] + reach or hi[1] > lo[3] + reach)
            # j is the smaller (order: larger first).
            joined = near and _hull_overlap(xy[i], xy[j]) >= HULL_OVERLAP
            if not joined and near and 4 * len(xy[j]) <= len(xy[i]) and (
                    len(xy[j]) < 30 or min_area_rectangle(xy[j])[1][1] < 0.006):
                eq = _hull_equations(xy[i])
                if eq is not None:
                    outside = (xy[j] @ eq[:, :2].T + eq[:, 2]).max(axis=1)
                    joined = float(np.percentile(outside, 90)) <= reach
            if (not joined and view is not None and clusters is not None
                    and np.max(np.maximum(hi[2:], lo[2:]) - np.minimum(hi[:2], lo[:2]))
                    <= math.sqrt(2) * PIECES_LENGTH
                    and min_area_rectangle(np.vstack([xy[i], xy[j]]))[1][0] <= PIECES_LENGTH):
                joined = _unseen_between(clusters[i], clusters[j], view)
            if joined:
                owner[find(j)] = find(i)
    if camera is None or clusters is None:
        return [find(i) for i in range(len(flats))]
    # Then the small pieces still alone, pairwise (a group's points together).
    groups: dict[int, list[int]] = {}
    for i in range(len(flats)):
        groups.setdefault(find(i), []).append(i)
    pieces = [m for m in groups.values() if sum(len(xy[i]) for i in m) < PIECE_POINTS]
    for a, ma in enumerate(pieces):
        for mb in pieces[a + 1:]:
            if find(ma[0]) == find(mb[0]):
                continue
            union = np.vstack([xy[i] for i in ma + mb])
            if (np.ptp(union, axis=0).max() > math.sqrt(2) * PIECES_LENGTH
                    or min_area_rectangle(union)[1][0] > PIECES_LENGTH):
                continue
            if _hidden_between(np.vstack([clusters[i] for i in ma]),
                               np.vstack([clusters[i] for i in mb]), camera,
                               lines_of_sight()):
                owner[find(mb[0])] = find(ma[0])
    return [find(i) for i in range(len(flats))]


def _join_seen_apart(clusters: list[np.ndarray], components: list[int], plane: TablePlane,
                     camera=None, view=None) -> list[np.ndarray]:
    """``clusters`` with the parts of one object that the camera sees apart
    stacked into one (:func:`_join_across`)."""
    if len(clusters) < 2:
        return clusters
    origin, R_WT = _table_frame(plane)
    flats = [(np.asarray(c, dtype=float) - origin) @ R_WT for c in clusters]
    groups: dict[int, list[int]] = {}
    for i, root in enumerate(_join_across(flats, components, clusters, camera, view)):
        groups.setdefault(root, []).append(i)
    return [np.vstack([clusters[i] for i in m]) for m in groups.values()]


def _merge_parts(clusters: list[np.ndarray], plane: TablePlane,
                 params: DetectorParams) -> list[np.ndarray]:
    """Clusters that are parts of one object become one cluster:

    - a part standing within another's footprint (a wine glass's stem seen
      apart from its bowl and foot): most of its points, projected on the
      table, fall inside the other's footprint hull;
    - a part that does not reach down to the table (a mug's handle, seen
      apart from the cup): its lowest point is more than 4 mm above the
      points cut off as table (9 mm above the table; a 60 mm mug's handle
      starts 12 mm up), its footprint is thin (at most 15 mm wide: a
      handle is 7-11 mm) and it has less than a third of the points of a
      cluster within 2 cm (horizontally), the nearest of which it joins. (A
      ball whose bottom is hidden behind a can looks off the table too, but
      is neither thin nor a small part of its neighbour.) The first rule is
      applied first: a glass's bowl, larger than its foot, takes the foot and
      so reaches the table.

    Objects that merely stand close (a ball 2 cm from a box) stay apart; none stack here."""
    if len(clusters) < 2:
        return clusters
    origin, R_WT = _table_frame(plane)
    flats = [(np.asarray(c, dtype=float) - origin) @ R_WT for c in clusters]
    owner = list(range(len(clusters)))

    def find(a):
        while owner[a] != a:
            a = owner[a]
        return a

    boxes = np.array([[*f[:, :2].min(axis=0), *f[:, :2].max(axis=0)] for f in flats])
    hulls: dict[int, object] = {}

    def inside(i, j):  # most of i's footprint within j's hull
        lo, hi = boxes[i], boxes[j]
        if lo[0] > hi[2] or lo[2] < hi[0] or lo[1] > hi[3] or lo[3] < hi[1]:
            return False  # the footprints' bounding boxes do not even overlap
        if j not in hulls:
            try:
                hulls[j] = ConvexHull(flats[j][:, :2]).equations
            except (QhullError, ValueError):
                hulls[j] = None
        if hulls[j] is None:
            return False
        distance = flats[i][:, :2] @ hulls[j][:, :2].T + hulls[j][:, 2]  # <= 0 inside
        return np.mean(distance.max(axis=1) <= 0) > 0.5

    # First the parts within another's footprint (a glass's foot and stem
    # under its bowl), so that a bowl with its foot reaches the table.
    for i, fi in enumerate(flats):
        for j, fj in enumerate(flats):
            if i != j and len(fi) <= len(fj) and inside(i, j):
                owner[find(i)] = find(j)
                break
    groups: dict[int, list[int]] = {}
    for i in range(len(clusters)):
        groups.setdefault(find(i), []).append(i)
    members = list(groups.values())
    flats = [np.vstack([flats[i] for i in m]) for m in members]
    clusters = [np.vstack([clusters[i] for i in m]) for m in members]
    boxes = np.array([[*f[:, :2].min(axis=0), *f[:, :2].max(axis=0)] for f in flats])
    owner = list(range(len(clusters)))
    # Then the small parts off the table (a mug's handle), to the nearest large one.
    for i, fi in enumerate(flats):
        if np.min(fi[:, 2]) <= params.min_height + 0.004:
            continue  # it reaches the table: an object of its own
        if min_area_rectangle(fi[:, :2])[1][1] > 0.015:
            continue  # no thin part: an object whose foot is hidden (behind another)
        near = [j for j in range(len(flats)) if j != i and len(flats[j]) > 3 * len(fi)
                and boxes[j][0] - 0.02 < boxes[i][2] and boxes[i][0] < boxes[j][2] + 0.02
                and boxes[j][1] - 0.02 < boxes[i][3] and boxes[i][1] < boxes[j][3] + 0.02]
        gaps = [cKDTree(flats[j][:, :2]).query(fi[:, :2], distance_upper_bound=0.02)[0].min()
                for j in near]
        if gaps and min(gaps) < 0.02:
            owner[find(i)] = find(near[int(np.argmin(gaps))])
    merged: dict[int, list[np.ndarray]] = {}
    for i, c in enumerate(clusters):
        merged.setdefault(find(i), []).append(c)
    return [np.vstack(g) for g in merged.values()]


def detect_objects(points, params: DetectorParams | None = None,
                   plane: TablePlane | None = None, camera=None, view=None
                   ) -> tuple[TablePlane | None, list[Detection]]:
    """Table plane and object detections from world-frame points (N x 3, m;
    non-finite rows, i.e. invalid pixels, are dropped). An empty or object-free
    view gives an empty list, not an error. Detections are sorted by their
    distance from the world origin. ``plane``: the table plane already known
    (a fixed camera's earlier frame, see :class:`TabletopDetector`); without
    it the plane is fitted to ``points``. ``camera``: the camera's position
    (world, m; a frame's ``X_WC`` translation): with it, pieces of one object
    seen apart around a nearer object are joined (:func:`_join_across`).
    ``view``: the depth frame the points come from (``depth``, ``K``,
    ``X_WC``; its camera is ``camera``): with it, also the parts of an object
    seen apart around its surface nearer than the sensor's range."""
    params = DetectorParams() if params is None else params
    points = _check_rows(points)
    if view is not None:
        if not all(hasattr(view, k) for k in ("depth", "K", "X_WC")):
            raise TypeError(f"view must be a depth frame (depth, K, X_WC), "
                            f"got {type(view).__name__}")
        if camera is None:
            camera = np.asarray(view.X_WC, dtype=float)[:3, 3]
    if camera is not None:
        camera = np.asarray(camera, dtype=float)
        if camera.shape != (3,) or not np.all(np.isfinite(camera)):
            raise ValueError(f"camera must be a finite position (3,) in m, got {camera!r}")
    if plane is None:
        plane = _fit_plane(_sample_finite(points, params), params)
    if plane is None or len(points) == 0:
        return plane, []
    above = _above(points, plane, params.min_height)
    above = _voxel_thin(above, params.voxel)
    if len(above) < params.min_points:
        return plane, []
    labels = _grid_clusters(above, params.cluster_eps / 2)
    order = np.argsort(labels, kind="stable")
    bounds = np.flatnonzero(np.diff(labels[order])) + 1
    clusters, components = [], []  # each part's connected component
    for component, members in enumerate(np.split(order, bounds)):
        if len(members) >= 5:  # fewer: noise (DBSCAN's min_samples)
            parts = _split_touching(above[members], plane, params.voxel)
            components.extend([component] * len(parts))
            clusters.extend(parts)
    detections = []
    clusters = _join_seen_apart(clusters, components, plane, camera, view)
    for cluster in _merge_parts(clusters, plane, params):
        if len(cluster) >= params.min_points:
            detections.append(_describe(cluster, plane))
    detections.sort(key=lambda d: float(np.linalg.norm(d.position[:2])))
    return plane, detections


class TabletopDetector:
    """Detection frame after frame from a fixed camera: the table plane is
    fitted once (the first frame) and kept while it still holds the table
    (at least half as many of a frame's sampled points on it as when it was
    fitted; otherwise it is fitted again, e.g. after the camera moved).

    ``detector.detect(frame_or_points)`` -> list of :class:`Detection`."""

    def __init__(self, params: DetectorParams | None = None):
        self.params = DetectorParams() if params is None else params
        self.plane: TablePlane | None = None
        self._share = 0.0  # share of a frame's points on the plane when fitted
        self.refits = 0

    def _on_plane(self, sample: np.ndarray) -> float:
        if len(sample) == 0:
            return 0.0
        return float(np.mean(np.abs(self.plane.height(sample)) <= self.params.plane_tolerance))

    def detect(self, frame, camera=None, view=None) -> list[Detection]:
        """``frame``: a depth frame or world points (N x 3); ``camera``,
        ``view``: the camera's position (world, m) and depth frame when
        ``frame`` is points (a frame is its own view), see
        :func:`detect_objects`."""
        points = _check_rows(frame.points() if hasattr(frame, "points") else frame)
        view = _view(frame) if view is None else view
        sample = _sample_finite(points, self.params, 2000)
        if self.plane is not None and self._on_plane(sample) < 0.5 * self._share:
            self.plane = None
        if self.plane is None:
            self.plane = _fit_plane(_sample_finite(points, self.params), self.params)
            if self.plane is None:
                return []
            self._share = self._on_plane(sample)
            self.refits += 1
        return detect_objects(points, self.params, plane=self.plane, camera=camera,
                              view=view)[1]


def detect(frame, params: DetectorParams | None = None) -> list[Detection]:
    """The objects on the table in one depth frame (a
    :class:`~handle_drake.devices.camera.frames.DepthFrame`, or world points
    N x 3): each a :class:`Detection` with ``kind``, ``pose`` (``X_WO``) and
    ``extent``. For a stream from a fixed camera use
    :class:`TabletopDetector` (the table plane is fitted once)."""
    points = frame.points() if hasattr(frame, "points") else frame
    return detect_objects(points, params, view=_view(frame))[1]


def _view(frame):
    """``frame`` if it is a depth frame (``depth``, ``K``, ``X_WC``), else None."""
    return frame if all(hasattr(frame, k) for k in ("depth", "K", "X_WC")) else None
