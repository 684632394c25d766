"""Wrenches and their change of frame (report section 4.1.1, eqs. 1-3).

A wrench is ``w = [f; tau]`` (eq. 1): force (N) first, then moment (N*m),
both expressed in one frame and the moment taken about that frame's origin.
"""

from __future__ import annotations

import numpy as np

__all__ = ["skew", "wrench_transform", "transform_wrenches"]


def skew(p) -> np.ndarray:
    """The cross-product matrix ``[p]x`` of eq. 3, so that ``skew(p) @ v == cross(p, v)``.

    ``p`` may be a 3-vector or a stack ``(..., 3)``; the result is ``(..., 3, 3)``.
    """
    p = np.asarray(p, dtype=float)
    if p.shape[-1:] != (3,):
        raise ValueError(f"skew: expected a (..., 3) array, got shape {p.shape}")
    S = np.zeros(p.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -p[..., 2], p[..., 1]
    S[..., 1, 0], S[..., 1, 2] = p[..., 2], -p[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -p[..., 1], p[..., 0]
    return S


def _rotation_and_translation(X_CB=None, R_CB=None, p_CB=None):
    if X_CB is not None:
        if R_CB is not None or p_CB is not None:
            raise TypeError("give either X_CB or (R_CB, p_CB), not both")
        if hasattr(X_CB, "rotation") and hasattr(X_CB, "translation"):
            return np.asarray(X_CB.rotation().matrix()), np.asarray(X_CB.translation())
        X = np.asarray(X_CB, dtype=float)
        if X.shape != (4, 4):
            raise ValueError(f"X_CB: expected a RigidTransform or a 4x4 matrix, got {X.shape}")
        return X[:3, :3], X[:3, 3]
    R = np.eye(3) if R_CB is None else np.asarray(R_CB, dtype=float)
    p = np.zeros(3) if p_CB is None else np.asarray(p_CB, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"R_CB: expected shape (3, 3), got {R.shape}")
    if p.shape != (3,):
        raise ValueError(f"p_CB: expected shape (3,), got {p.shape}")
    return R, p


def wrench_transform(X_CB=None, *, R_CB=None, p_CB=None) -> np.ndarray:
    """The 6x6 matrix of eq. 2 that maps a wrench at B's origin, in B, to C.

    ``X_CB`` is the pose of frame B in frame C (a ``RigidTransform`` or 4x4
    matrix), or give its parts ``R_CB`` and ``p_CB`` (position of B's origin in
    C; the report's ``p_bc``). Then ``F_C = wrench_transform(X_CB) @ F_B``::

        f_C   = R_CB f_B
        tau_C = p_CB x (R_CB f_B) + R_CB tau_B
    """
    R, p = _rotation_and_translation(X_CB, R_CB, p_CB)
    T = np.zeros((6, 6))
    T[:3, :3] = R
    T[3:, 3:] = R
    T[3:, :3] = skew(p) @ R
    return T


def transform_wrenches(wrenches_B, X_CB=None, *, R_CB=None, p_CB=None) -> np.ndarray:
    """Apply eq. 2 to a stack of wrenches ``(..., 6)`` given in B; returns them in C."""
    w = np.asarray(wrenches_B, dtype=float)
    if w.shape[-1:] != (6,):
        raise ValueError(f"wrenches_B: expected shape (..., 6), got {w.shape}")
    return w @ wrench_transform(X_CB, R_CB=R_CB, p_CB=p_CB).T
