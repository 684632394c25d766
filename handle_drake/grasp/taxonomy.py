"""The eight dexterous grasp classes of the seed report and its Tables 1 and 2.

The report (section 3.2.1) recorded human-like grasps of eight fingertip
grasp classes and fitted, per class, the grasp centre point as a linear
function of object size (Table 1) and chose a fixed approach vector (Table 2).
Both tables are shipped here verbatim as defaults.

Table 1 frame ("report frame" R), quoted from section 3.2.1:

- the origin (0, 0, 0) is at the WRJ1 joint of the Shadow hand,
- x runs to the left (along the stretched thumb),
- y is up (from the palm),
- z runs along the palm from the wrist to the tip of the middle finger,

with every length in millimetres. Table 1 gives, per class, ``c = c0 + Δ·s``
per axis, where ``s`` is the object size in millimetres (the diameter, or the
width between the opposing fingers for a box) and ``Δ`` is dimensionless
(mm per mm).

Which way "up from the palm" points. We read y as *dorsal* (out of the back of
the hand), i.e. "up" when the hand lies palm down, for four independent reasons:

1. every y0 in Table 1 is negative (-26 to -82 mm); a grasped object sits in
   front of the palm, so negative y must be the palmar side;
2. Table 2 gives (0, -1, 0) for the tripod and the text says "y is the
   suitable approach direction": the hand moves towards the object, i.e. along
   -y = palmar, in agreement with 1;
3. for the lateral grasp Table 2 gives (0.71, 0, 0.71) and the text says "the
   hand mostly moving forward but also a bit to the left": +z forward and +x
   left, in agreement with "x runs to the left";
4. the frame is right-handed: with y dorsal and z distal, x = y × z points to
   the left of a right hand lying palm down, which is the thumb side, as the
   caption says ("along the stretched thumb").

The model's palm frame P (``docs`` hand_kinematics.md, section 1) is the child
frame of WRJ1 with its origin on the WRJ1 axis, z distal, +x towards the
first finger / thumb side and -y palmar. So R and P have the *same axes* and
the same origin; the conversion is a change of units only, and
:data:`X_PR` is the identity. It is still written out as a transform so that a
model whose palm frame differs (another hand, a left hand) changes one line.

Grasp-class IDs are the report's (they are the zero-based indices of the same
grasps in Feix et al.'s GRASP taxonomy). The report spells adduction grip
"ADDICTION_GRIP" in its tables and "addition grip" in its text; both are
accepted as aliases.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

__all__ = [
    "GraspClass",
    "GraspClassInfo",
    "ContactSpec",
    "GRASP_CLASSES",
    "OBJECT_SHAPES",
    "X_PR",
    "grasp_class",
    "grasp_info",
    "grasp_centre_report_mm",
    "grasp_centre_palm",
    "approach_report",
    "approach_palm",
    "report_mm_to_palm",
    "palm_to_report_mm",
    "check_size",
]

OBJECT_SHAPES = ("sphere", "cylinder", "box")


class GraspClass(enum.Enum):
    """The eight grasp classes recorded in the report (value: the canonical name)."""

    PALMAR_PINCH = "palmar_pinch"
    TIP_PINCH = "tip_pinch"
    TRIPOD = "tripod"
    WRITING_TRIPOD = "writing_tripod"
    LATERAL = "lateral"
    LATERAL_TRIPOD = "lateral_tripod"
    ADDUCTION_GRIP = "adduction_grip"
    PARALLEL_EXTENSION = "parallel_extension"


@dataclass(frozen=True)
class ContactSpec:
    """Which part of which finger touches the object.

    finger: one of ``th ff mf rf lf``; part: ``pad`` (the palmar face of the
    distal phalanx, near the tip), ``tip`` (the very end of the fingertip) or
    ``side`` (the radial, i.e. thumb-facing, side of the distal phalanx, or
    the ulnar side when ``part == "ulnar_side"``).
    """

    finger: str
    part: str


@dataclass(frozen=True)
class GraspClassInfo:
    """Everything the library knows about one grasp class.

    table1: (x0, dx, y0, dy, z0, dz) from the report's Table 1, millimetres and
      mm per mm, in the report frame R.
    approach_table2: (ax, ay, az) as printed in Table 2 (report frame, not
      normalised: the report rounds 1/sqrt(2) to 0.71).
    contacts: the fingers (and finger parts) that touch the object; the grasp
      centre is their geometric centre (report section 3.2.1).
    size_range_m: object sizes (m) our Shadow model grasps with this class.
      Not from the report: chosen from the model's reach (the synthetic data
      set and planner succeed in it); outside it the planner raises.
    default_shape: the object shape used for this class by the CLI scenarios.
    """

    grasp_class: GraspClass
    report_id: int
    report_label: str
    table1: tuple[float, float, float, float, float, float]
    approach_table2: tuple[float, float, float]
    contacts: tuple[ContactSpec, ...]
    size_range_m: tuple[float, float]
    default_shape: str

    @property
    def name(self) -> str:
        return self.grasp_class.value

    @property
    def fingers(self) -> tuple[str, ...]:
        return tuple(c.finger for c in self.contacts)


def _c(*pairs: str) -> tuple[ContactSpec, ...]:
    return tuple(ContactSpec(*p.split(":")) for p in pairs)


# Table 1 and Table 2 of the report, row by row (IDs and labels as printed).
GRASP_CLASSES: dict[GraspClass, GraspClassInfo] = {
    info.grasp_class: info
    for info in (
        GraspClassInfo(
            GraspClass.PALMAR_PINCH, 8, "PALMAR_PINCH",
            (56.32, 0.11, -81.42, 0.36, 105.38, 0.36), (0.0, -1.0, 0.0),
            _c("th:pad", "ff:pad"), (0.01, 0.07), "sphere",
        ),
        GraspClassInfo(
            GraspClass.TRIPOD, 13, "TRIPOD",
            (39.27, 0.10, -69.97, 0.28, 108.26, 0.38), (0.0, -1.0, 0.0),
            _c("th:pad", "ff:pad", "mf:pad"), (0.02, 0.07), "sphere",
        ),
        GraspClassInfo(
            GraspClass.LATERAL, 15, "LATERAL",
            (52.14, 0.09, -26.60, 0.14, 102.82, 0.12), (0.71, 0.0, 0.71),
            _c("th:pad", "ff:side"), (0.004, 0.03), "box",
        ),
        GraspClassInfo(
            GraspClass.WRITING_TRIPOD, 19, "WRITING_TRIPOD",
            (38.49, 0.10, -78.52, 0.47, 102.54, 0.48), (0.0, -1.0, 0.0),
            _c("th:pad", "ff:pad", "mf:side"), (0.008, 0.04), "cylinder",
        ),
        GraspClassInfo(
            GraspClass.PARALLEL_EXTENSION, 21, "PARALLEL_EXT.",
            (43.71, 0.10, -82.29, 0.32, 102.17, 0.40), (0.0, -0.71, 0.71),
            _c("th:pad", "ff:pad", "mf:pad", "rf:pad", "lf:pad"), (0.01, 0.06), "box",
        ),
        GraspClassInfo(
            GraspClass.ADDUCTION_GRIP, 22, "ADDICTION_GRIP",
            (21.64, 0.45, -33.99, -0.43, 184.01, -0.52), (0.0, -0.71, 0.71),
            _c("ff:ulnar_side", "mf:side"), (0.006, 0.02), "cylinder",
        ),
        GraspClassInfo(
            GraspClass.TIP_PINCH, 23, "TIP_PINCH",
            (53.70, 0.06, -59.12, 0.33, 108.95, 0.33), (0.0, -1.0, 0.0),
            _c("th:tip", "ff:tip"), (0.005, 0.04), "sphere",
        ),
        GraspClassInfo(
            GraspClass.LATERAL_TRIPOD, 24, "LATERAL_TRIPOD",
            (37.54, 0.14, -55.24, 0.40, 117.61, 0.03), (0.0, -1.0, 0.0),
            _c("th:pad", "ff:side", "mf:side"), (0.01, 0.04), "cylinder",
        ),
    )
}

_ALIASES = {
    "addiction_grip": GraspClass.ADDUCTION_GRIP,
    "addition_grip": GraspClass.ADDUCTION_GRIP,
    "parallel_ext": GraspClass.PARALLEL_EXTENSION,
    "parallel_ext.": GraspClass.PARALLEL_EXTENSION,
}

# Pose of the report frame R in the palm frame P (see the module docstring):
# same origin (WRJ1 axis), same axes. Lengths in R are millimetres.
X_PR = RigidTransform()
_MM = 1e-3


def grasp_class(name: str | GraspClass) -> GraspClass:
    """The :class:`GraspClass` named ``name`` (case-insensitive; '-', ' ' = '_').

    Raises ValueError naming the known classes for an unknown name.
    """
    if isinstance(name, GraspClass):
        return name
    if not isinstance(name, str):
        raise TypeError(f"grasp class must be a str or GraspClass, got {type(name).__name__}")
    key = name.strip().lower().replace("-", "_").replace(" ", "_")
    if key in _ALIASES:
        return _ALIASES[key]
    for member in GraspClass:
        if member.value == key:
            return member
    known = ", ".join(m.value for m in GraspClass)
    raise ValueError(f"unknown grasp class {name!r}; expected one of: {known}")


def grasp_info(name: str | GraspClass) -> GraspClassInfo:
    """The :class:`GraspClassInfo` of a class name (see :func:`grasp_class`)."""
    return GRASP_CLASSES[grasp_class(name)]


def _finite_size(size: float, unit: str) -> float:
    size = float(size)
    if not np.isfinite(size) or size <= 0:
        raise ValueError(f"object size must be a positive finite number ({unit}), got {size}")
    return size


def grasp_centre_report_mm(name: str | GraspClass, size_mm: float) -> np.ndarray:
    """Table 1: the grasp centre ``c0 + Δ·size`` in the report frame, mm."""
    x0, dx, y0, dy, z0, dz = grasp_info(name).table1
    s = _finite_size(size_mm, "mm")
    return np.array([x0 + dx * s, y0 + dy * s, z0 + dz * s])


def report_mm_to_palm(p_R_mm) -> np.ndarray:
    """A point (3,) or points (N, 3) given in the report frame (mm) -> palm frame (m)."""
    p = np.asarray(p_R_mm, dtype=float)
    if p.shape[-1:] != (3,) or p.ndim > 2:
        raise ValueError(f"expected a point of shape (3,) or (N, 3), got {p.shape}")
    return (X_PR.multiply((p * _MM).reshape(-1, 3).T)).T.reshape(p.shape)


def palm_to_report_mm(p_P) -> np.ndarray:
    """Inverse of :func:`report_mm_to_palm`: palm frame (m) -> report frame (mm)."""
    p = np.asarray(p_P, dtype=float)
    if p.shape[-1:] != (3,) or p.ndim > 2:
        raise ValueError(f"expected a point of shape (3,) or (N, 3), got {p.shape}")
    return (X_PR.inverse().multiply(p.reshape(-1, 3).T)).T.reshape(p.shape) / _MM


def grasp_centre_palm(name: str | GraspClass, size_m: float) -> np.ndarray:
    """Table 1 in SI: grasp centre ``p_PC`` (m) in the palm frame for size (m)."""
    size_m = _finite_size(size_m, "m")
    return report_mm_to_palm(grasp_centre_report_mm(name, size_m / _MM))


def approach_report(name: str | GraspClass) -> np.ndarray:
    """Table 2 approach vector (direction the hand moves), unit length, report frame."""
    a = np.asarray(grasp_info(name).approach_table2, dtype=float)
    return a / np.linalg.norm(a)


def approach_palm(name: str | GraspClass) -> np.ndarray:
    """Table 2 approach vector as a unit vector in the palm frame."""
    return X_PR.rotation().multiply(approach_report(name))


def check_size(name: str | GraspClass, size_m: float) -> float:
    """Raise ValueError if ``size_m`` is outside the class's graspable range."""
    info = grasp_info(name)
    size_m = _finite_size(size_m, "m")
    lo, hi = info.size_range_m
    if size_m > hi:
        raise ValueError(
            f"object size {size_m:.4f} m is too large for a {info.name} grasp with this hand "
            f"(expected at most {hi:.4f} m)"
        )
    if size_m < lo:
        raise ValueError(
            f"object size {size_m:.4f} m is too small for a {info.name} grasp with this hand "
            f"(expected at least {lo:.4f} m)"
        )
    return size_m
