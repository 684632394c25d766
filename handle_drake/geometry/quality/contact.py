"""Contact models and the grasp map (report section 4.1.2 and 4.1.4, eqs. 4-14).

Contacts are a point ``p_RC`` (m) and an *inward* normal ``n_R`` (the
direction in which the finger pushes on the object, i.e. into the object),
both expressed in one reference frame R chosen by the caller (usually the
object frame O with its origin at the centre of mass). Each contact becomes a
set of primitive wrenches ``[f; tau]`` in R, with unit normal force (eq. 10):

* ``frictionless`` (eq. 4): one wrench, ``f = n``.
* ``point_friction`` (eqs. 5-7): the Coulomb cone ``|f_t| <= mu f_n``
  linearised into ``num_edges`` edges ``f = n + mu (sin(theta_k) x + cos(theta_k) y)``
  with ``theta_k = 2 pi k / num_edges`` and ``(x, y, n)`` the contact frame.
* ``soft_finger`` (eqs. 8-9, 11): every edge twice, with a torsional moment
  ``+gamma n`` and ``-gamma n`` about the normal (eq. 9 reads ``f_4 >= gamma f_3``;
  eq. 11 and the soft-finger model of Murray, Li & Sastry make it
  ``|f_4| <= gamma f_3``). ``gamma`` is a length (m): the largest torsional
  moment per newton of normal force.

The moment is taken about R's origin, ``tau = p x f (+ torsion)``, and divided
by ``characteristic_length`` (m) when given, so that forces and moments are
comparable (a common choice is the object's radius of gyration or its largest
radius). The grasp map ``G`` (eqs. 13-14) holds the primitive wrenches as columns.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ContactModel",
    "GraspContacts",
    "contact_frames",
    "contact_wrenches",
    "grasp_map",
    "validate_contacts",
    "wrenches_per_contact",
]


class ContactModel(enum.StrEnum):
    """The three contact models of section 4.1.2."""

    FRICTIONLESS = "frictionless"
    POINT_FRICTION = "point_friction"
    SOFT_FINGER = "soft_finger"


def _as_model(model) -> ContactModel:
    try:
        return ContactModel(model)
    except ValueError:
        names = ", ".join(m.value for m in ContactModel)
        raise ValueError(f"contact model: expected one of {names}, got {model!r}") from None


def wrenches_per_contact(model, num_edges: int) -> int:
    """Number of primitive wrenches one contact contributes."""
    model = _as_model(model)
    if model is ContactModel.FRICTIONLESS:
        return 1
    return num_edges if model is ContactModel.POINT_FRICTION else 2 * num_edges


#: Ranges beyond which the metric's arithmetic is no longer exact enough to trust:
#: friction cone edges of length mu (and torsion gamma / L, lever arms |p| / L) beside
#: a unit normal force lose the normal direction in double precision (mu = 1e9 reads a
#: closure grasp as open), and the hull's cost grows with the edges (1000 edges take
#: minutes). Real friction coefficients lie below ~2.
MAX_MU = 1e4
MAX_NUM_EDGES = 256
MAX_RELATIVE_SIZE = 1e6  # |p| / characteristic_length and gamma / characteristic_length


def real_array(name: str, a) -> np.ndarray:
    """``a`` as a float array; TypeError for complex, text or object input (never a cast
    that silently drops an imaginary part)."""
    try:
        raw = np.asarray(a)
    except (TypeError, ValueError, OverflowError) as err:
        raise TypeError(f"{name}: expected an array of numbers, got {type(a).__name__}") from err
    if np.iscomplexobj(raw):
        raise TypeError(f"{name}: expected real numbers, got complex values")
    if raw.dtype.kind not in "biuf":
        if raw.dtype.kind == "O" and any(isinstance(v, complex) for v in raw.ravel()[:10000]):
            raise TypeError(f"{name}: expected real numbers, got complex values")
        if raw.dtype.kind in "USVmM":
            raise TypeError(f"{name}: expected an array of numbers, got {raw.dtype} data")
    try:
        return np.asarray(raw, dtype=float)
    except (TypeError, ValueError, OverflowError) as err:
        raise TypeError(f"{name}: expected an array of numbers, got {type(a).__name__}") from err


def _check_stack(name: str, a, batch: bool) -> np.ndarray:
    arr = real_array(name, a)
    want = 3 if batch else 2
    if arr.ndim != want or arr.shape[-1] != 3:
        shape = "(B, n, 3)" if batch else "(n, 3)"
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite values, got NaN or infinity")
    return arr


def validate_contacts(points, normals, *, batch: bool = False):
    """Check contact arrays and return ``(points, unit_normals)`` as float arrays.

    ``points`` and ``normals`` are ``(n, 3)`` (or ``(B, n, 3)`` with ``batch``),
    finite. Normals are directions and are normalised; a normal shorter than
    1e-9 is an error (it has no direction).
    """
    p = _check_stack("points", points, batch)
    n = _check_stack("normals", normals, batch)
    if p.shape != n.shape:
        raise ValueError(f"normals: expected the shape of points {p.shape}, got {n.shape}")
    if p.shape[-2] == 0:
        raise ValueError("points: expected at least one contact, got 0")
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    if np.any(norm < 1e-9):
        bad = np.argwhere(norm[..., 0] < 1e-9)[0].tolist()
        raise ValueError(f"normals: expected non-zero directions, got a zero normal at {bad}")
    return p, n / norm


def _check_friction(mu, gamma, num_edges, model: ContactModel):
    for name, v in (("mu", mu), ("gamma", gamma)):
        if not isinstance(v, int | float | np.floating | np.integer) or isinstance(v, bool):
            raise TypeError(f"{name}: expected a real number, got {type(v).__name__}")
        if not np.isfinite(v) or v < 0:
            raise ValueError(f"{name}: expected a finite value >= 0, got {v}")
    if mu > MAX_MU:
        raise ValueError(f"mu: expected a value in [0, {MAX_MU:g}] (beyond it the cone edges "
                         f"swamp the normal force in double precision), got {mu:g}")
    if model is not ContactModel.FRICTIONLESS:
        if not isinstance(num_edges, int | np.integer) or isinstance(num_edges, bool):
            raise TypeError(f"num_edges: expected an int, got {type(num_edges).__name__}")
        if not 3 <= num_edges <= MAX_NUM_EDGES:
            raise ValueError(f"num_edges: expected 3..{MAX_NUM_EDGES} cone edges, got "
                             f"{num_edges}")


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` for broadcastable (..., 3) stacks; np.cross costs ~40 us per
    call on small arrays, most of the metric's budget in the non-closure mode."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def contact_frames(normals, tangents=None) -> np.ndarray:
    """Rotation matrices ``R_RC`` (..., 3, 3) whose z axis is the inward normal.

    Without ``tangents`` the tangent axes are a smooth function of the normal
    alone (Duff et al. 2017, "Building an orthonormal basis, revisited"), so they
    are deterministic but not equivariant under a rotation of R; give
    ``tangents`` (any vectors not parallel to the normals; projected onto the
    tangent plane) to fix the contact frames' x axes, e.g. when comparing a
    grasp expressed in two rotated frames.
    """
    n = np.asarray(normals, dtype=float)
    R = np.empty(n.shape + (3,))
    R[..., 2] = n
    if tangents is None:
        nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
        sign = np.where(nz >= 0, 1.0, -1.0)
        a = -1.0 / (sign + nz)
        b = nx * ny * a
        R[..., 0, 0], R[..., 1, 0], R[..., 2, 0] = 1.0 + sign * nx * nx * a, sign * b, -sign * nx
        R[..., 0, 1], R[..., 1, 1], R[..., 2, 1] = b, sign + ny * ny * a, -ny
        return R
    helper = real_array("tangents", tangents)
    if helper.shape != n.shape:
        raise ValueError(f"tangents: expected shape {n.shape}, got {helper.shape}")
    x = helper - np.sum(helper * n, axis=-1, keepdims=True) * n
    xn = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(xn < 1e-9):
        raise ValueError("tangents: expected vectors not parallel to the normals")
    x = x / xn
    R[..., 0], R[..., 1] = x, _cross(n, x)
    return R


def contact_wrenches(
    points,
    normals,
    model="soft_finger",
    *,
    mu: float = 0.5,
    gamma: float = 0.0,
    num_edges: int = 8,
    characteristic_length: float = 1.0,
    tangents=None,
    batch: bool = False,
) -> np.ndarray:
    """Primitive wrenches of each contact, in the reference frame R.

    Args:
        points: ``p_RC`` (n, 3) in m (``(B, n, 3)`` with ``batch=True``).
        normals: inward normals (n, 3) in R; normalised here.
        model: ``"frictionless"``, ``"point_friction"`` or ``"soft_finger"``.
        mu: Coulomb friction coefficient (>= 0).
        gamma: torsional friction coefficient in m (>= 0), soft finger only.
        num_edges: cone edges k (>= 3) for the friction models.
        characteristic_length: moments are divided by it (m, > 0).
        tangents: optional contact-frame x axes, see :func:`contact_frames`.

    Returns:
        ``(n, m_c, 6)`` (or ``(B, n, m_c, 6)``) wrenches ``[f; tau / L]`` with unit
        normal force; ``m_c`` is :func:`wrenches_per_contact`.
    """
    model = _as_model(model)
    p, n = validate_contacts(points, normals, batch=batch)
    _check_friction(mu, gamma, num_edges, model)
    L = characteristic_length
    if not isinstance(L, int | float | np.floating | np.integer) or not np.isfinite(L) or L <= 0:
        raise ValueError(f"characteristic_length: expected a finite value > 0, got {L!r}")
    reach = float(np.max(np.abs(p))) if p.size else 0.0
    if reach > MAX_RELATIVE_SIZE * L:
        raise ValueError(f"points: expected coordinates within {MAX_RELATIVE_SIZE:g} "
                         f"characteristic lengths ({MAX_RELATIVE_SIZE * L:g} m), got "
                         f"{reach:g} m; express them in the object's frame, in m")
    if gamma > MAX_RELATIVE_SIZE * L:
        raise ValueError(f"gamma: expected at most {MAX_RELATIVE_SIZE:g} characteristic "
                         f"lengths ({MAX_RELATIVE_SIZE * L:g} m), got {gamma:g} m")
    if model is ContactModel.FRICTIONLESS:
        f = n[..., None, :]
        w = np.concatenate([f, _cross(p[..., None, :], f) / L], axis=-1)
        return w
    # eq. 13: G_i = [R; [p]x R] maps contact-frame wrenches to R; eq. 11 gives the
    # contact-frame edges c_k = (mu sin(theta_k), mu cos(theta_k), 1).
    R = contact_frames(n, tangents)  # columns x, y, n
    G = np.empty(n.shape[:-1] + (6, 3))
    G[..., :3, :] = R
    G[..., 3:, :] = _cross(p[..., None, :], np.swapaxes(R, -1, -2)).swapaxes(-1, -2) / L
    C = _edge_coefficients(float(mu), int(num_edges))  # (3, k)
    w = np.swapaxes(G @ C, -1, -2)  # (..., k, 6)
    if model is ContactModel.SOFT_FINGER:
        torsion = (gamma / L) * n[..., None, :]
        w = np.concatenate([w, w], axis=-2)
        w[..., :num_edges, 3:] += torsion
        w[..., num_edges:, 3:] -= torsion
    return w


_EDGE_CACHE: dict = {}


def _edge_coefficients(mu: float, k: int) -> np.ndarray:
    key = (mu, k)
    C = _EDGE_CACHE.get(key)
    if C is None:
        theta = 2.0 * np.pi * np.arange(k) / k
        C = np.stack([mu * np.sin(theta), mu * np.cos(theta), np.ones(k)])
        if len(_EDGE_CACHE) < 256:
            _EDGE_CACHE[key] = C
    return C


def grasp_map(points, normals, model="soft_finger", **kwargs) -> np.ndarray:
    """The grasp map ``G`` (6, n * m_c) of eqs. 13-14: primitive wrenches as columns."""
    w = contact_wrenches(points, normals, model, **kwargs)
    return w.reshape(-1, 6).T


@dataclass(frozen=True)
class GraspContacts:
    """Contacts of one grasp in a reference frame R (usually the object frame).

    ``points`` ``p_RC`` (n, 3) m, ``normals`` inward unit normals (n, 3),
    ``forces`` optional measured contact forces on the object (n, 3) N,
    ``names`` optional labels (fingertip names).
    """

    points: np.ndarray
    normals: np.ndarray
    forces: np.ndarray | None = None
    names: tuple[str, ...] = ()

    def __post_init__(self):
        p, n = validate_contacts(self.points, self.normals)
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "normals", n)
        if self.forces is not None:
            f = np.asarray(self.forces, dtype=float)
            if f.shape != p.shape:
                raise ValueError(f"forces: expected shape {p.shape}, got {f.shape}")
            object.__setattr__(self, "forces", f)
        if self.names and len(self.names) != len(p):
            raise ValueError(f"names: expected {len(p)} names, got {len(self.names)}")

    def __len__(self) -> int:
        return len(self.points)
