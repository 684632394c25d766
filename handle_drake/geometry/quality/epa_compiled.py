"""The EPA of :mod:`.hull` for a finite wrench set, compiled with numba: the initial
simplex (``init_simplex``, when the axes' support points span R^6; else the numpy one,
which asks the oracle for more) and the loop (``epa_loop``).

The same steps as ``hull._Epa`` (nearest facet, support point, visible facets, the
horizon by the facets' Zobrist ridge keys, new facets' normals by one 6x6 LAPACK
``gesv`` each, the exact ridge-structure check at the end), on plain arrays in one
compiled call instead of ~50 numpy calls per added vertex. The arithmetic is numpy's,
bit for bit: the support values and the visibility test by the same BLAS calls (gemm
``u W^T``, gemv ``N s``; numba calls the OpenBLAS scipy ships), the normal by the same
LAPACK ``gesv``, its norm summed in order as ``np.add.reduce`` does for 6 terms, and
the offset summed as ``np.einsum("ij,ij->i")`` does (two SSE2 lanes:
``(p0 + p2 + p4) + (p1 + p3 + p5)``); ``tests/quality`` compares the radii with the
numpy EPA bit for bit. (With plain loops for the support values, 36 of 364 random
grasps took another path on near-ties and ended 1e-14 away.) The summation orders are
numpy's x86-64 ones; on another architecture (e.g. NEON's fused multiply-add in einsum) or
with another BLAS build the last bits may differ, which that test would show.

``epa_loop`` returns a status: 0 converged (radius and normal valid), 1 the EPA gave
up (no visible facet, iteration limit, broken ridge structure): the caller falls back
to qhull as the numpy EPA does; 2 too many vertices (the numpy EPA's OverflowError).
The first call compiles (cached on disk by numba: ``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba.np.linalg import _LAPACK, F_INT_nptype

# numba's own binding of LAPACK ?gesv (the one its np.linalg.solve calls: scipy's
# OpenBLAS); a private numba name, hence numba pinned below 0.70 in pyproject.toml.
_XGESV = _LAPACK().numba_xgesv(numba.float64)
_KIND = ord("d")

__all__ = ["epa_loop"]


def _njit(function):
    """``numba.njit(cache=True)``, or without the disk cache (with a warning) when numba
    finds no place to write one: a user who can write neither the package's
    ``__pycache__`` nor a home cache gets numba's ``RuntimeError: cannot cache function
    ...: no locator available`` at import otherwise (set ``NUMBA_CACHE_DIR`` to keep it)."""
    try:
        return numba.njit(cache=True)(function)
    except RuntimeError as error:
        if "cannot cache" not in str(error):
            raise
        global _WARNED
        if not _WARNED:
            import warnings

            warnings.warn(f"numba cannot cache the compiled EPA ({error}); compiling it in "
                          f"each process (set NUMBA_CACHE_DIR to a writable folder)",
                          RuntimeWarning, stacklevel=2)
            _WARNED = True
        return numba.njit(function)


_WARNED = False

DIM = 6


@_njit
def _oriented(V, center, ridge, vi, n_out, A, x, ipiv):
    """Unit outward normal and offset of the facet ``ridge + [vi]`` (as hull._Epa._oriented);
    NaN when the facet is degenerate (numpy's LinAlgError). ``A`` (6, 6), ``x`` (6,) and
    ``ipiv`` (6,) are work buffers: ``A`` holds the matrix column-major (``A[c, k]`` is
    row k, column c), as numpy and numba's solve hand it to LAPACK."""
    for c in range(DIM):
        p0 = V[ridge[0], c]
        for k in range(1, DIM - 1):
            A[c, k - 1] = V[ridge[k], c] - p0
        A[c, DIM - 2] = V[vi, c] - p0
        A[c, DIM - 1] = p0 - center[c]
    x[:] = 0.0
    x[DIM - 1] = 1.0
    # LAPACK dgesv as np.linalg.solve calls it, without its copies and checks.
    if _XGESV(_KIND, DIM, 1, A.ctypes, DIM, ipiv.ctypes, x.ctypes, DIM) != 0:
        n_out[:] = np.nan
        return np.nan
    sq = 0.0  # np.add.reduce of 6 terms: in order from 0
    for c in range(DIM):
        sq += x[c] * x[c]
    norm = np.sqrt(sq)
    for c in range(DIM):
        n_out[c] = x[c] / norm
    # np.einsum("ij,ij->i") of 6 terms (SSE2, two lanes): (p0 + p2 + p4) + (p1 + p3 + p5)
    even = n_out[0] * V[ridge[0], 0]
    odd = n_out[1] * V[ridge[0], 1]
    even += n_out[2] * V[ridge[0], 2]
    odd += n_out[3] * V[ridge[0], 3]
    even += n_out[4] * V[ridge[0], 4]
    odd += n_out[5] * V[ridge[0], 5]
    return even + odd


_SIMPLEX_FACETS = np.array([[c for c in range(DIM + 1) if c != j] for j in range(DIM + 1)],
                           dtype=np.int64)


@_njit
def init_simplex(pts, tol, vertex_hash):
    """``hull._Epa.init_simplex`` while the given points suffice: 7 affinely independent
    points of ``pts`` chosen greedily (farthest from the flat of those chosen), and the 7
    facets of their simplex. Returns ``(ok, V0, F0, N0, b0, H0, center)``; ``ok`` False when
    the points span less than R^6 (the numpy code then asks the support oracle for more)
    or a facet is degenerate."""
    n = pts.shape[0]
    V0 = np.empty((DIM + 1, DIM))
    F0 = _SIMPLEX_FACETS.copy()
    N0 = np.empty((DIM + 1, DIM))
    b0 = np.empty(DIM + 1)
    H0 = np.zeros(DIM + 1, dtype=np.int64)
    center = np.empty(DIM)
    V0[0] = pts[0]
    basis = np.empty((DIM, DIM))
    rel = np.empty((n, DIM))
    for k in range(1, DIM + 1):
        for r in range(n):
            for c in range(DIM):
                rel[r, c] = pts[r, c] - V0[0, c]
        if k > 1:  # rel - (rel @ basis.T) @ basis, by BLAS as numpy does
            B = basis[:k - 1]
            resid = rel - np.dot(np.dot(rel, B.T), B)
        else:
            resid = rel.copy()
        j, best = -1, -np.inf
        for r in range(n):
            sq = 0.0  # np.linalg.norm(axis=1): sqrt of add.reduce, in order
            for c in range(DIM):
                sq += resid[r, c] * resid[r, c]
            dist = np.sqrt(sq)
            if dist > best:
                j, best = r, dist
        if not best > tol:
            return False, V0, F0, N0, b0, H0, center
        V0[k] = pts[j]
        for c in range(DIM):
            basis[k - 1, c] = resid[j, c] / best
    center[:] = V0[0]  # np.mean(axis=0): rows added in order, then / 7
    for r in range(1, DIM + 1):
        for c in range(DIM):
            center[c] += V0[r, c]
    for c in range(DIM):
        center[c] /= DIM + 1
    A, x, ipiv = np.empty((DIM, DIM)), np.empty(DIM), np.empty(DIM, dtype=F_INT_nptype)
    for f in range(DIM + 1):
        b0[f] = _oriented(V0, center, F0[f, :DIM - 1], F0[f, DIM - 1], N0[f], A, x, ipiv)
        if np.isnan(b0[f]):
            return False, V0, F0, N0, b0, H0, center
        for k in range(DIM):
            H0[f] ^= vertex_hash[F0[f, k]]
    return True, V0, F0, N0, b0, H0, center


@_njit
def epa_loop(W, V0, F0, N0, b0, H0, center, vertex_hash, eps, gap_tol, max_iterations):
    """Runs the EPA from the initial simplex (``V0`` 7 vertices, facets ``F0/N0/b0/H0``).

    Returns ``(status, radius, u)``.
    """
    m = W.shape[0]
    max_vertices = vertex_hash.shape[0]
    V = np.empty((64, DIM))
    nv = V0.shape[0]
    V[:nv] = V0
    cap_f = 256
    F = np.zeros((cap_f, DIM), dtype=np.int64)
    N = np.zeros((cap_f, DIM))
    b = np.full(cap_f, np.inf)
    H = np.zeros(cap_f, dtype=np.int64)
    nf = F0.shape[0]
    F[:nf], N[:nf], b[:nf], H[:nf] = F0, N0, b0, H0
    u = np.zeros(DIM)
    ridge = np.empty(DIM - 1, dtype=np.int64)
    A, x, ipiv = np.empty((DIM, DIM)), np.empty(DIM), np.empty(DIM, dtype=F_INT_nptype)
    WT = W.T  # F-contiguous view, as numpy's W.T
    for _ in range(max_iterations):
        j = 0
        for i in range(1, nf):
            if b[i] < b[j]:
                j = i
        # support point of conv(W) in N[j] (hull.finite_support)
        vals = np.dot(N[j:j + 1], WT)  # BLAS gemm, as numpy's u[None, :] @ W.T
        best, arg = -np.inf, 0
        for r in range(m):
            if vals[0, r] > best:
                best, arg = vals[0, r], r
        if best - b[j] <= gap_tol:
            u[:] = N[j]
            if _consistent(V, nv, F, N, b, nf):
                return 0, b[j], u
            return 1, 0.0, u
        s = W[arg]
        # visible facets
        d = np.dot(N[:nf], s) - b[:nf]  # BLAS gemv, as numpy's N @ s - b
        vis = np.empty(nf, dtype=np.int64)
        nvis = 0
        for i in range(nf):
            if d[i] > eps:
                vis[nvis] = i
                nvis += 1
        if nvis == 0:
            return 1, 0.0, u
        if nv >= max_vertices:
            return 2, 0.0, u
        if nv == V.shape[0]:
            V = np.concatenate((V, np.empty_like(V)))
        V[nv] = s
        vi = nv
        nv += 1
        new, nnew = _horizon(F, H, vis, nvis, vertex_hash)
        if nf + nnew > cap_f:
            cap_f = 2 * (nf + nnew)
            F, N, b, H = _grown(F, N, b, H, nf, cap_f)
        for q in range(nnew):
            f = vis[new[q] // DIM]
            jj = new[q] % DIM
            w = 0
            for k in range(DIM):
                if k != jj:
                    ridge[w] = F[f, k]
                    w += 1
            row = nf + q
            for k in range(DIM - 1):
                F[row, k] = ridge[k]
            F[row, DIM - 1] = vi
            b[row] = _oriented(V, center, ridge, vi, N[row], A, x, ipiv)
            if np.isnan(b[row]):
                return 1, 0.0, u
            H[row] = H[f] ^ vertex_hash[F[f, jj]] ^ vertex_hash[vi]
        for a in range(nvis):
            b[vis[a]] = np.inf
            N[vis[a]] = 0.0
        nf += nnew
    return 1, 0.0, u


@_njit
def _horizon(F, H, vis, nvis, vertex_hash):
    """Ridges of exactly one visible facet, as ``facet slot * 6 + opposite vertex``, in the
    order of their keys (as numpy's argsort of the keys, then the keys seen once)."""
    keys = np.empty(nvis * DIM, dtype=np.int64)
    for a in range(nvis):
        f = vis[a]
        for k in range(DIM):
            keys[a * DIM + k] = H[f] ^ vertex_hash[F[f, k]]
    order = np.argsort(keys)
    nk = keys.shape[0]
    new = np.empty(nk, dtype=np.int64)
    nnew = 0
    for q in range(nk):
        key = keys[order[q]]
        if q > 0 and keys[order[q - 1]] == key:
            continue
        if q + 1 < nk and keys[order[q + 1]] == key:
            continue
        new[nnew] = order[q]
        nnew += 1
    return new, nnew


@_njit
def _grown(F, N, b, H, nf, cap):
    F2 = np.zeros((cap, DIM), dtype=np.int64)
    N2 = np.zeros((cap, DIM))
    b2 = np.full(cap, np.inf)
    H2 = np.zeros(cap, dtype=np.int64)
    F2[:nf], N2[:nf], b2[:nf], H2[:nf] = F[:nf], N[:nf], b[:nf], H[:nf]
    return F2, N2, b2, H2


@_njit
def _consistent(V, nv, F, N, b, nf):
    """Every ridge in exactly two live facets (exact keys), every vertex inside every facet."""
    live = np.empty(nf, dtype=np.int64)
    nl = 0
    for i in range(nf):
        if np.isfinite(b[i]):
            live[nl] = i
            nl += 1
    if nl == 0:
        return False
    keys = np.empty(nl * DIM, dtype=np.int64)
    ridge = np.empty(DIM - 1, dtype=np.int64)
    for a in range(nl):
        f = live[a]
        for jj in range(DIM):
            w = 0
            for k in range(DIM):
                if k != jj:
                    ridge[w] = F[f, k]
                    w += 1
            ridge.sort()
            key = 0
            for k in range(DIM - 1):
                key += ridge[k] << (12 * k)
            keys[a * DIM + jj] = key
    keys.sort()
    if keys.shape[0] % 2:
        return False
    for q in range(0, keys.shape[0], 2):
        if keys[q] != keys[q + 1]:
            return False
        if q + 2 < keys.shape[0] and keys[q + 2] == keys[q + 1]:
            return False
    worst = 0.0
    for a in range(nl):
        worst = max(worst, abs(b[live[a]]))
    limit = 1e-8 * max(1.0, worst)
    for a in range(nl):
        f = live[a]
        for r in range(nv):
            dot = 0.0
            for c in range(DIM):
                dot += V[r, c] * N[f, c]
            if dot - b[f] > limit:
                return False
    return True
