"""Grasp quality: force closure, the Bimodal Wrench Space metric and classic references.

The **Bimodal Wrench Space** metric ``BW`` (report 4.1.6, eqs. 15-21) of a
grasp with primitive wrenches ``W`` (the columns of the grasp map ``G``) and
grasp wrench space ``W_G = conv(W)`` (eq. 17):

* in force closure (origin inside ``W_G``, eq. 18): the radius of the largest
  origin-centred ball inside ``W_G`` (> 0);
* otherwise: minus the distance from the origin to ``W_G`` (eq. 19, <= 0).

Both branches tend to 0 at the closure boundary, so ``BW`` is continuous in
the contacts. ``method="fast"`` computes the distance by NNLS and the radius by
EPA (``hull.py``, both exact); ``method="drake"`` uses Drake's min-distance QP
and closure LP (``drake_programs.py``) and EPA for the radius (no convex
program gives it). The two agree to 1e-6 on the test set.

The torque part of a wrench depends on where moments are taken and on the
unit of length: ``ContactParams.characteristic_length`` divides moments by a
length (e.g. the object's largest radius) to make them comparable with forces.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .contact import ContactModel, _as_model, _check_friction, contact_wrenches
from .drake_programs import DIM, ClosurePrograms, wrench_rank
from .hull import (
    _check_wrenches,
    _min_norm_point,
    largest_ball_radius,
    minkowski_support,
    qhull_ball_radius,
)

__all__ = [
    "ContactParams",
    "GraspQuality",
    "quality_from_wrenches",
    "grasp_quality",
    "bw_metric",
    "bw_metric_batch",
    "is_force_closure",
    "ferrari_canny",
    "ferrari_canny_linf_qhull",
    "hull_volume",
]

INSIDE_TOL = 1e-9  # origin counted inside W_G when its distance is below this
CLOSURE_TOL = 1e-9  # force closure when the ball radius exceeds this


@dataclass(frozen=True)
class ContactParams:
    """How contacts become wrenches (see :mod:`handle_drake.geometry.quality.contact`).

    Attributes:
        model: ``"frictionless"``, ``"point_friction"`` or ``"soft_finger"`` (the report's choice).
        mu: Coulomb friction coefficient, >= 0.
        gamma: torsional friction coefficient (m), >= 0. The default 0.002 m is
            about ``2/3 mu a`` for a fingertip patch of radius a = 6 mm, mu = 0.5.
        num_edges: friction-cone edges k, >= 3.
        characteristic_length: moments are divided by it (m, > 0); 1.0 keeps N*m.
    """

    model: str = "soft_finger"
    mu: float = 0.5
    gamma: float = 0.002
    num_edges: int = 8
    characteristic_length: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "model", _as_model(self.model))
        _check_friction(self.mu, self.gamma, self.num_edges, ContactModel.POINT_FRICTION)
        L = self.characteristic_length
        real = isinstance(L, int | float | np.floating | np.integer)
        if not real or not np.isfinite(L) or L <= 0:
            raise ValueError(f"characteristic_length: expected a finite value > 0, got {L!r}")

    def wrenches(self, points, normals, *, tangents=None, batch: bool = False) -> np.ndarray:
        """Primitive wrenches ``(n, m_c, 6)`` (``(B, n, m_c, 6)`` with ``batch``)."""
        return contact_wrenches(
            points,
            normals,
            self.model,
            mu=self.mu,
            gamma=self.gamma,
            num_edges=self.num_edges,
            characteristic_length=self.characteristic_length,
            tangents=tangents,
            batch=batch,
        )


@dataclass(frozen=True)
class GraspQuality:
    """Result of the BW analysis of one grasp.

    ``value`` is the BW metric; ``distance`` the distance from the origin to
    ``W_G`` (0 when inside); ``radius`` the largest ball radius (0 when not in
    closure); ``force_closure`` is ``value > 1e-9``.
    """

    value: float
    force_closure: bool
    distance: float
    radius: float


_PROGRAMS: ClosurePrograms | None = None


def _programs() -> ClosurePrograms:
    global _PROGRAMS
    if _PROGRAMS is None:
        _PROGRAMS = ClosurePrograms()
    return _PROGRAMS


def quality_from_wrenches(W, *, method: str = "fast") -> GraspQuality:
    """BW analysis of primitive wrenches ``W`` (m, 6) (the transposed grasp map).

    ``method``: ``"fast"`` (NNLS + EPA) or ``"drake"`` (Drake QP and LP + EPA).
    """
    return _quality(_check_wrenches(W), method)


def _quality(W: np.ndarray, method: str) -> GraspQuality:
    # Tolerances are relative to the wrenches' size beyond 1 (the NNLS distance of an
    # inside origin is ~1e-16 |W|): W scaled by 1e8 must score 1e8 times the radius.
    scale = max(1.0, float(np.max(np.abs(W))))
    if method == "fast":
        _, distance, _ = _min_norm_point(W)
        inside = distance <= INSIDE_TOL * scale
    elif method == "drake":
        _, distance, _ = _programs().min_distance(W)
        inside = distance <= 1e3 * INSIDE_TOL * scale  # Clarabel solves to ~1e-10
        if inside:
            inside = wrench_rank(W) == DIM and _programs().closure_lp(W) > CLOSURE_TOL
            if not inside:
                return GraspQuality(-distance, False, distance, 0.0)
    else:
        raise ValueError(f"method: expected 'fast' or 'drake', got {method!r}")
    if not inside:
        return GraspQuality(-distance, False, distance, 0.0)
    radius, _ = largest_ball_radius(W)
    if radius <= CLOSURE_TOL * scale:  # origin on the boundary (or W_G flat): not closure
        value = radius if radius > 0 else -distance
        return GraspQuality(value, False, distance, 0.0)
    return GraspQuality(radius, True, 0.0, radius)


def grasp_quality(
    points, normals, params: ContactParams | None = None, *, tangents=None, method="fast"
) -> GraspQuality:
    """BW analysis of contacts (points ``p_RC`` (n, 3) m, inward normals (n, 3))."""
    params = ContactParams() if params is None else params
    W = params.wrenches(points, normals, tangents=tangents).reshape(-1, DIM)
    return _quality(W, method)


def bw_metric(points, normals, params: ContactParams | None = None, **kwargs) -> float:
    """The Bimodal Wrench Space metric of one grasp (see :func:`grasp_quality`)."""
    return grasp_quality(points, normals, params, **kwargs).value


def bw_metric_batch(
    points, normals, params: ContactParams | None = None, *, method="fast", details=False
):
    """BW metric of many grasps.

    Args:
        points, normals: ``(B, n, 3)`` arrays (all grasps with n contacts; the
            wrenches are then built in one vectorised call) or sequences of B
            ``(n_b, 3)`` arrays (ragged).
        params: contact parameters shared by all grasps.
        details: also return the list of :class:`GraspQuality`.

    Returns:
        ``(B,)`` metric values (and the details when asked).
    """
    params = ContactParams() if params is None else params
    regular = isinstance(points, np.ndarray) and isinstance(normals, np.ndarray)
    if regular:
        if points.ndim != 3:
            raise ValueError(f"points: expected shape (B, n, 3), got {points.shape}")
        if len(points) == 0:
            return (np.zeros(0), []) if details else np.zeros(0)
        Ws = params.wrenches(points, normals, batch=True).reshape(len(points), -1, DIM)
    else:
        if not isinstance(points, Sequence) or not isinstance(normals, Sequence):
            raise TypeError("points, normals: expected (B, n, 3) arrays or sequences of (n, 3)")
        if len(points) != len(normals):
            raise ValueError(f"normals: expected {len(points)} grasps, got {len(normals)}")
        Ws = []
        for b, (p, n) in enumerate(zip(points, normals, strict=True)):
            try:
                Ws.append(params.wrenches(p, n).reshape(-1, DIM))
            except ValueError as err:
                raise ValueError(f"grasp {b}: {err}") from None
    if method not in ("fast", "drake"):
        raise ValueError(f"method: expected 'fast' or 'drake', got {method!r}")
    out = [_quality(W, method) for W in Ws]
    values = np.array([q.value for q in out])
    return (values, out) if details else values


def is_force_closure(points, normals, params: ContactParams | None = None, *, tangents=None):
    """Force closure by Drake's closure LP and a rank test (eq. 18)."""
    params = ContactParams() if params is None else params
    W = params.wrenches(points, normals, tangents=tangents).reshape(-1, DIM)
    return _programs().is_force_closure(W, tol=CLOSURE_TOL)


def ferrari_canny(
    points, normals, params: ContactParams | None = None, *, norm: str = "L1", tangents=None
) -> float:
    """Ferrari-Canny epsilon: largest origin-centred ball in the grasp wrench space.

    ``norm="L1"``: ``conv(0, all wrenches)`` (total normal force <= 1); in closure
    it equals the BW metric. ``norm="Linf"``: the Minkowski sum of each contact's
    ``conv(0, its wrenches)`` (each normal force <= 1), evaluated by EPA through
    its support function. 0.0 when the grasp is not in force closure.
    """
    params = ContactParams() if params is None else params
    Wc = params.wrenches(points, normals, tangents=tangents)
    W = Wc.reshape(-1, DIM)
    if norm not in ("L1", "Linf"):
        raise ValueError(f"norm: expected 'L1' or 'Linf', got {norm!r}")
    q = quality_from_wrenches(W)
    if not q.force_closure:
        return 0.0
    if norm == "L1":
        return q.radius
    radius, _ = largest_ball_radius(support=minkowski_support(Wc), initial_points=W)
    return max(radius, 0.0)


def _minkowski_points(Wc: np.ndarray, limit: int = 200_000) -> np.ndarray:
    """All sums of one point of each ``conv(0, W_i)`` vertex set (small grasps only)."""
    sets = [np.vstack([np.zeros((1, DIM)), w]) for w in Wc]
    count = int(np.prod([len(s) for s in sets]))
    if count > limit:
        raise ValueError(f"Minkowski sum too large to enumerate: {count} > {limit} points")
    return np.array([np.sum(c, axis=0) for c in itertools.product(*sets)])


def ferrari_canny_linf_qhull(points, normals, params: ContactParams | None = None) -> float:
    """Reference L-infinity epsilon by enumerating the Minkowski sum and a full qhull."""
    params = ContactParams() if params is None else params
    Wc = params.wrenches(points, normals)
    return max(qhull_ball_radius(_minkowski_points(Wc)), 0.0)


def hull_volume(points, normals, params: ContactParams | None = None) -> float:
    """6-D volume of ``W_G = conv(W)`` (qhull); 0.0 when ``W_G`` is flat (rank < 6)."""
    params = ContactParams() if params is None else params
    W = params.wrenches(points, normals).reshape(-1, DIM)
    if len(W) <= DIM or wrench_rank(W - W.mean(axis=0)) < DIM:
        return 0.0
    try:
        return float(ConvexHull(W).volume)
    except QhullError:
        return 0.0
