"""Exact geometry of a wrench hull ``P = conv(w_1 .. w_m)`` in R^6, without a full qhull.

Two numbers define the Bimodal Wrench Space metric (report 4.1.6):

* the distance from the origin to ``P`` (eq. 19) when the origin is outside, and
* the radius of the largest origin-centred ball inside ``P`` when it is inside.

**Distance.** The min-norm point of ``P`` is found as a non-negative least
squares problem: with ``E = [W^T; 1^T]`` (7 x m) and ``e = (0, .., 0, 1)``,
``min_{mu >= 0} |E mu - e|^2``. Writing ``mu = t lambda`` with ``lambda`` in the
simplex gives ``t^2 a + (t - 1)^2`` with ``a = |W^T lambda|^2``, minimised by
``t = 1 / (1 + a)`` at value ``a / (1 + a)``, which is increasing in ``a``: so
``lambda = mu / sum(mu)`` is exactly the min-norm point's convex weights
(Lawson & Hanson's least-distance programming, ch. 23). scipy's NNLS is a finite
active-set method, so the answer is exact to rounding, and it costs ~25 us for
64 wrenches. It is checked against Drake's QP (``drake_programs``) in the tests.

**Largest ball.** The radius is ``min_{|u| = 1} h_P(u)``, the smallest facet
offset of ``P``; no convex program gives it (it is the largest-norm vertex of the
polar polytope). We use the expanding-polytope algorithm (EPA, van den Bergen
2001) in R^6: keep a polytope ``Q`` whose vertices are vertices of ``P`` and
which contains the origin; take the facet of ``Q`` nearest the origin, with unit
normal ``u`` and offset ``d``; ask ``P`` for its support point ``s`` in ``u``.
If ``u . s <= d + tol`` then ``P`` lies in ``{u . x <= d}`` and contains
``Q`` ⊇ ball(d), so the radius is ``d`` exactly; otherwise add ``s`` to ``Q``
(beneath-beyond update of a triangulated hull) and repeat. Only the facets
near the origin are ever built, unlike a full hull (thousands of facets in 6-D),
and ``P`` is touched only through its support function, so the same code gives
the L-infinity Ferrari-Canny epsilon of a Minkowski sum without enumerating it.
Written here because neither scipy nor Drake offer a penetration-depth query in
6-D. The result is checked for consistency (closed ridge structure, all
vertices inside every facet) and, should that ever fail, recomputed with qhull.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import ConvexHull, QhullError

from handle_drake.geometry.quality.contact import real_array

try:  # the compiled EPA loop (numba, a dependency); the numpy EPA below if it cannot load
    from handle_drake.geometry.quality.epa_compiled import epa_loop as _compiled_epa_loop
    from handle_drake.geometry.quality.epa_compiled import (
        init_simplex as _compiled_init_simplex,
    )
except (ImportError, AttributeError):  # numba missing, or its private LAPACK binding moved
    _compiled_epa_loop = _compiled_init_simplex = None

__all__ = [
    "min_norm_point",
    "largest_ball_radius",
    "qhull_ball_radius",
    "finite_support",
    "minkowski_support",
    "EPA_STATS",
]

DIM = 6
_BITS = 12  # ridge keys pack 5 vertex indices of 12 bits into one int64
_MAX_VERTICES = 1 << _BITS

# Counters for diagnostics: how often EPA fell back to qhull.
EPA_STATS = {"calls": 0, "fallbacks": 0}
# The compiled EPA loop for wrench sets (set "enabled" False for the numpy loop, e.g. to
# compare the two).
COMPILED_EPA = {"enabled": True}


def _check_wrenches(W) -> np.ndarray:

    W = real_array("wrenches", W)
    if W.ndim != 2 or W.shape[1] != DIM:
        raise ValueError(f"wrenches: expected shape (m, 6), got {W.shape}")
    if W.shape[0] == 0:
        raise ValueError("wrenches: expected at least one wrench, got 0")
    if not np.all(np.isfinite(W)):
        raise ValueError("wrenches: expected finite values, got NaN or infinity")
    scale = float(np.max(np.abs(W)))
    if scale > 1e150 or (0 < scale < 1e-150):
        raise ValueError(f"wrenches: expected magnitudes within 1e-150..1e150 (squares must "
                         f"stay finite), got {scale:g}")
    return W


def min_norm_point(W) -> tuple[np.ndarray, float, np.ndarray]:
    """The point of ``conv(W)`` nearest the origin.

    Args:
        W: wrenches (m, 6).

    Returns:
        ``(x, distance, weights)``: the point (6,), its norm, and convex weights
        (m,) with ``weights @ W == x``.
    """
    return _min_norm_point(_check_wrenches(W))


def _min_norm_point(W: np.ndarray):
    m = W.shape[0]
    E = np.empty((DIM + 1, m))
    E[:DIM] = W.T
    # The sum-to-one row carries weight s: min |W^T mu|^2 + s^2 (sum mu - 1)^2 has the
    # min-norm point's weights (scaled) as its solution for any s > 0; s of the order
    # of the wrenches keeps NNLS from rounding the weights to zero when |W| >> 1.
    scale = float(np.max(np.abs(W)))
    s = scale if scale > 1e3 else 1.0
    E[DIM] = s
    e = np.zeros(DIM + 1)
    e[DIM] = s
    mu, _ = nnls(E, e, maxiter=50 * (m + DIM))
    total = mu.sum()
    if total <= 0:
        raise ValueError(f"wrenches: NNLS found no weights (magnitudes up to {scale:.3g}); "
                         "rescale the wrenches")
    lam = mu / total
    x = lam @ W
    return x, float(np.linalg.norm(x)), lam


# --------------------------------------------------------------------------
# support functions


def finite_support(W) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Support oracle of ``conv(W)``: ``U (d, 6) -> (points (d, 6), values (d,))``."""
    W = np.asarray(W, dtype=float)

    def support(U):
        vals = U @ W.T
        idx = np.argmax(vals, axis=1)
        return W[idx], vals[np.arange(len(idx)), idx]

    return support


def minkowski_support(wrench_sets, include_origin: bool = True):
    """Support oracle of ``sum_i conv(W_i [+ 0])`` for ``wrench_sets`` (n, m_c, 6).

    With ``include_origin`` every contact may also push with zero force, which is
    the L-infinity grasp wrench space of Ferrari & Canny.
    """
    S = np.asarray(wrench_sets, dtype=float)

    def support(U):
        vals = np.einsum("dk,nmk->dnm", U, S)
        idx = np.argmax(vals, axis=2)
        best = np.take_along_axis(vals, idx[..., None], axis=2)[..., 0]
        pts = S[np.arange(S.shape[0])[None, :], idx]  # (d, n, 6)
        if include_origin:
            keep = best > 0
            best = np.where(keep, best, 0.0)
            pts = pts * keep[..., None]
        return pts.sum(axis=1), best.sum(axis=1)

    return support


# --------------------------------------------------------------------------
# EPA

_RIDGE_COLS = np.array([[c for c in range(DIM) if c != j] for j in range(DIM)])
_SHIFTS = (np.arange(DIM - 1) * _BITS).astype(np.int64)
# Zobrist hashes of the vertices: a facet carries the xor of its 6 vertices' hashes, so the
# key of its ridge opposite vertex v is one xor away (no (facets, 6, 5) index array per step).
# A collision of two different ridges (odds ~1e-14 per call) can only break the ridge
# structure, which consistent() checks with exact keys before a result is returned.
_VERTEX_HASH = np.random.default_rng(20261127).integers(
    0, np.iinfo(np.int64).max, size=_MAX_VERTICES, dtype=np.int64)


def _ridge_keys(ridges: np.ndarray) -> np.ndarray:
    return np.sum(ridges.astype(np.int64) << _SHIFTS, axis=-1)


class _Epa:
    """The polytope Q: facets in growing buffers; a removed facet stays with offset +inf.

    Live facets keep the order a compacting list would give them (survivors in order, new
    ones appended), so ``argmin(b)`` picks the same facet; rows of ``F`` are sorted vertex
    indices (a new facet is a sorted ridge plus the newest vertex).
    """

    def __init__(self, support, scale: float):
        self.support = support
        self.eps = 1e-11 * scale  # visibility tolerance
        self.V = np.empty((64, DIM))
        self.nv = 0
        self.nf = 0
        self._grow_facets(256)
        self.center = np.zeros(DIM)

    def _grow_facets(self, capacity: int) -> None:
        F = np.zeros((capacity, DIM), dtype=np.int64)
        N = np.zeros((capacity, DIM))
        b = np.full(capacity, np.inf)
        H = np.zeros(capacity, dtype=np.int64)
        if self.nf:
            F[: self.nf], N[: self.nf] = self.F[: self.nf], self.N[: self.nf]
            b[: self.nf], H[: self.nf] = self.b[: self.nf], self.H[: self.nf]
        self.F, self.N, self.b, self.H = F, N, b, H

    def _append_facets(self, F_new, N_new, b_new, H_new) -> None:
        n = len(F_new)
        if self.nf + n > len(self.b):
            self._grow_facets(2 * (self.nf + n))
        sl = slice(self.nf, self.nf + n)
        self.F[sl], self.N[sl], self.b[sl], self.H[sl] = F_new, N_new, b_new, H_new
        self.nf += n

    def _push_vertex(self, s) -> int:
        if self.nv == len(self.V):
            self.V = np.concatenate([self.V, np.empty_like(self.V)])
        self.V[self.nv] = s
        self.nv += 1
        return self.nv - 1

    def _oriented(self, F_new: np.ndarray):
        """Unit outward normals and offsets of simplices ``F_new`` (H, 6).

        The normal solves ``N . (v_k - v_0) = 0`` (k = 1..5) and
        ``N . (v_0 - center) = 1``: one 6x6 solve per facet, and the sign is
        outward by construction because ``center`` is strictly inside ``Q``.
        """
        P = self.V[F_new]  # (H, 6, 6)
        A = np.empty_like(P)
        A[:, :DIM - 1] = P[:, 1:] - P[:, :1]
        A[:, DIM - 1] = P[:, 0] - self.center
        rhs = np.zeros((len(P), DIM, 1))
        rhs[:, DIM - 1] = 1.0
        N = np.linalg.solve(A, rhs)[..., 0]
        N /= np.sqrt(np.add.reduce(N * N, axis=1, keepdims=True))  # np.linalg.norm's sum
        return N, np.einsum("ij,ij->i", N, P[:, 0])

    def init_simplex(self, pts: np.ndarray, scale: float) -> bool:
        """Pick 7 affinely independent points; query more directions if needed."""
        chosen = [pts[0]]
        basis = np.empty((0, DIM))
        pool = pts
        tol = 1e-9 * scale
        while len(chosen) < DIM + 1:
            rel = pool - chosen[0]
            resid = rel - (rel @ basis.T) @ basis
            dist = np.linalg.norm(resid, axis=1)
            j = int(np.argmax(dist)) if len(pool) else -1
            if j >= 0 and dist[j] > tol:
                chosen.append(pool[j])
                basis = np.vstack([basis, resid[j] / dist[j]])
                continue
            # no candidate off the current flat: ask P in the orthogonal directions
            _, _, Vt = np.linalg.svd(np.vstack([basis, np.zeros((1, DIM))]))
            comp = Vt[len(basis) :]
            sp, _ = self.support(np.vstack([comp, -comp]))
            rel = sp - chosen[0]
            resid = rel - (rel @ basis.T) @ basis
            if np.max(np.linalg.norm(resid, axis=1)) <= tol:
                return False  # P lies in a lower-dimensional flat
            pool = sp
        for p in chosen:
            self._push_vertex(p)
        self.center = np.mean(self.V[: DIM + 1], axis=0)
        F = np.array([[c for c in range(DIM + 1) if c != j] for j in range(DIM + 1)])
        N, b = self._oriented(F)
        self._append_facets(F, N, b, np.bitwise_xor.reduce(_VERTEX_HASH[F], axis=1))
        return self.nf == DIM + 1

    def add(self, s: np.ndarray) -> bool:
        nf = self.nf
        d = self.N[:nf] @ s - self.b[:nf]  # removed facets: 0 - inf, never visible
        vis = np.flatnonzero(d > self.eps)
        if not len(vis):
            return False
        if self.nv >= _MAX_VERTICES:
            raise OverflowError("EPA: too many vertices")
        vi = self._push_vertex(s)
        Fv = self.F[vis]  # (nvis, 6)
        Hv = self.H[vis]
        # The horizon: ridges of exactly one visible facet (a ridge shared by two visible
        # facets is interior): keys sorted once, a key equal to neither neighbour is single.
        Vh = _VERTEX_HASH[Fv]
        keys = (Hv[:, None] ^ Vh).ravel()  # key of the ridge opposite each vertex
        order = np.argsort(keys)
        sorted_keys = keys[order]
        single = np.ones(len(keys), dtype=bool)
        same = sorted_keys[1:] == sorted_keys[:-1]
        single[1:] &= ~same
        single[:-1] &= ~same
        f, j = np.divmod(order[single], DIM)
        F_new = np.empty((len(f), DIM), dtype=np.int64)
        F_new[:, :DIM - 1] = Fv[f[:, None], _RIDGE_COLS[j]]
        F_new[:, DIM - 1] = vi
        N_new, b_new = self._oriented(F_new)
        self.b[vis] = np.inf
        self.N[vis] = 0.0
        self._append_facets(F_new, N_new, b_new, Hv[f] ^ Vh[f, j] ^ _VERTEX_HASH[vi])
        return True

    def consistent(self) -> bool:
        live = np.isfinite(self.b[: self.nf])
        if not np.any(live):
            return False
        F, N, b = self.F[: self.nf][live], self.N[: self.nf][live], self.b[: self.nf][live]
        ridges = F[:, _RIDGE_COLS].reshape(-1, DIM - 1)
        keys = np.sort(_ridge_keys(np.sort(ridges, axis=1)))
        # every ridge in exactly two facets: sorted keys pair up, and pairs differ
        if len(keys) % 2 or not (np.all(keys[0::2] == keys[1::2])
                                 and np.all(keys[2::2] != keys[1:-1:2])):
            return False
        slack = self.V[: self.nv] @ N.T - b
        return bool(np.max(slack) <= 1e-8 * max(1.0, float(np.max(np.abs(b)))))


def qhull_ball_radius(W) -> float:
    """Largest origin-centred ball in ``conv(W)`` from a full qhull (the reference).

    Returns the smallest facet offset: positive when the origin is inside,
    ``<= 0`` when it is on or outside the hull, and 0.0 when qhull finds the
    points degenerate (lower-dimensional hull, no interior).
    """
    W = _check_wrenches(W)
    try:
        hull = ConvexHull(W)
    except (QhullError, ValueError):
        return 0.0
    return float(np.min(-hull.equations[:, -1]))


def largest_ball_radius(
    W=None,
    *,
    support=None,
    initial_points=None,
    scale: float | None = None,
    tol: float = 1e-12,
    max_iterations: int = 2000,
) -> tuple[float, np.ndarray]:
    """Radius of the largest origin-centred ball inside a convex set, by EPA.

    Give either wrenches ``W`` (m, 6) or a ``support`` oracle (see
    :func:`finite_support`, :func:`minkowski_support`) with a few
    ``initial_points`` of the set. Requires the origin inside the set for a
    positive answer; returns ``(radius, u)`` where ``u`` is the unit normal of
    the nearest facet. The radius is ``<= 0`` if the origin is on or outside the
    set, and exactly 0.0 when the set has no interior (lower-dimensional).
    """
    EPA_STATS["calls"] += 1
    if W is not None:
        W = _check_wrenches(W)
        support = finite_support(W)
    elif support is None:
        raise TypeError("largest_ball_radius: give wrenches W or a support oracle")
    axes = np.vstack([np.eye(DIM), -np.eye(DIM)])
    pts, h = support(axes)
    if initial_points is not None:
        pts = np.vstack([pts, np.asarray(initial_points, dtype=float)])
    if scale is None:
        scale = max(1.0, float(np.max(np.abs(h))))
    epa = _Epa(support, scale)
    gap_tol = max(tol * scale, 4 * epa.eps)
    if W is not None and _compiled_epa_loop is not None and COMPILED_EPA["enabled"]:
        # The same steps compiled (epa_compiled.py); the numpy initial simplex when the
        # axes' support points do not span R^6 (it asks the oracle for more).
        ok, *simplex = _compiled_init_simplex(pts, 1e-9 * scale, _VERTEX_HASH)
        if not ok:
            if not epa.init_simplex(pts, scale):
                return 0.0, np.zeros(DIM)
            k = DIM + 1
            simplex = [epa.V[:k], epa.F[:k], epa.N[:k], epa.b[:k], epa.H[:k], epa.center]
        try:
            status, radius, u = _compiled_epa_loop(np.ascontiguousarray(W), *simplex,
                                                   _VERTEX_HASH, epa.eps, gap_tol,
                                                   max_iterations)
        except np.linalg.LinAlgError:
            status = 1
        if status == 0:
            return float(radius), u
        EPA_STATS["fallbacks"] += 1
        return qhull_ball_radius(W), np.zeros(DIM)
    if not epa.init_simplex(pts, scale):
        return 0.0, np.zeros(DIM)
    try:
        for _ in range(max_iterations):
            j = int(np.argmin(epa.b[: epa.nf]))
            u = epa.N[j]
            s, hs = support(u[None, :])
            if hs[0] - epa.b[j] <= gap_tol:
                if epa.consistent():
                    return float(epa.b[j]), u.copy()
                break
            if not epa.add(s[0]):
                break
    except (OverflowError, np.linalg.LinAlgError):
        pass
    # Degenerate numerics: fall back to the exact full hull.
    EPA_STATS["fallbacks"] += 1
    if W is None:
        raise RuntimeError("largest_ball_radius: EPA failed on a support oracle")
    return qhull_ball_radius(W), np.zeros(DIM)
