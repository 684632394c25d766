"""The error of a pose located in the hand against the plant's, up to the object's own
symmetry (issue 49 item 5: within 10 mm and 10 deg for every kind). Shared by
tests/pick/test_touch.py and tools/locate_kinds.py (not a conftest: xdist name clash).

The symmetries are the object's, found from its geometry, not from the estimator: a
sphere's every turn; a round kind's (``AXIAL``: cylinder, wine glass) turns about its
axis z, which leave the axis's direction to score; and the discrete turns (about z by
``2 pi k / n``, ``n`` <= 12, each also flipped about x, and a box's signed axis
permutations) that map every vertex of the object's convex pieces onto a vertex within
``MATCH`` (a cuboid's 180 degree turns, a cube's 24, a star prism's fifths...).
"""

from __future__ import annotations

import functools
import itertools

import numpy as np
from scipy.spatial import cKDTree

from handle_drake.geometry.objects import ObjectSpec
from handle_drake.geometry.objects.pieces import pieces

#: Kinds whose every turn about their axis z leaves them as they were.
AXIAL = ("cylinder", "wine_glass")
MATCH = 5e-4  # m


def _vertices(spec) -> np.ndarray:
    return np.vstack([np.asarray(p.mesh().vertices) for p in pieces(spec)])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _candidates():
    flips = (np.eye(3), np.diag([1.0, -1.0, -1.0]))
    out = [_rz(2 * np.pi * k / n) @ f for n in range(1, 13) for k in range(n) for f in flips]
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    return out


@functools.lru_cache(maxsize=32)
def _discrete(kind: str, size: float, key) -> tuple:
    spec = _SPECS[key]
    v = _vertices(spec)
    tree = cKDTree(v)
    found = []
    for S in _candidates():
        if tree.query(v @ S.T)[0].max() < MATCH and not any(np.allclose(S, F) for F in found):
            found.append(S)
    return tuple(found)


_SPECS: dict = {}


def symmetries(spec) -> tuple:
    """The discrete rotations (3x3, object frame) that leave ``spec`` as it was."""
    key = repr(spec)
    _SPECS[key] = spec
    return _discrete(spec.kind, float(spec.size), key)


def pose_errors(spec, R_true, p_true, R_est, p_est) -> tuple[float, float]:
    """``(position error m, angle error deg)`` of the located object pose
    (``R_est``, ``p_est``, any common frame) against the true one, up to symmetry."""
    position = float(np.linalg.norm(np.asarray(p_est) - np.asarray(p_true)))
    R_true, R_est = np.asarray(R_true, float), np.asarray(R_est, float)
    if spec.kind == "sphere":
        return position, 0.0
    if spec.kind in AXIAL:
        flips = [S for S in symmetries(spec) if S[2, 2] < 0]
        cos = float(R_true[:, 2] @ R_est[:, 2])
        cos = abs(cos) if flips else cos
        return position, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    best = min(np.arccos(np.clip((np.trace(R_true.T @ R_est @ S) - 1) / 2, -1.0, 1.0))
               for S in symmetries(spec))
    return position, float(np.degrees(best))


__all__ = ["pose_errors", "symmetries", "AXIAL", "ObjectSpec"]
