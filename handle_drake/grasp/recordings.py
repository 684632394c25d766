"""Recorded grasps: a documented CSV file format, a loader and a saver.

The format lets a user fit synergies from their own recordings (data-glove
tele-operation or kinesthetic teaching, report section 3.1).

File format ``handle_drake-grasps`` version 1
---------------------------------------------

A UTF-8 CSV file::

    # handle_drake-grasps format=1 angle_unit=rad
    # any further lines starting with '#' are comments
    timestamp,experimenter,grasp_class,object_shape,object_dims_m,WRJ2,WRJ1,FFJ4,...,THJ1
    2012-02-14T10:31:07+00:00,exp1,tripod,sphere,0.04,0.0,0.0,0.1,...

- Line 1 (the magic line) names the format, its version and the angle unit of
  the joint columns: ``rad`` or ``deg`` (degrees are converted to radians when
  loading; files are always saved in radians).
- ``timestamp``: ISO 8601 date-time (``datetime.fromisoformat``); a time zone
  is recommended, naive times are kept as they are.
- ``experimenter``: a non-empty id (no commas).
- ``grasp_class``: one of the eight class names of
  :mod:`handle_drake.grasp.taxonomy` (``palmar_pinch tip_pinch tripod
  writing_tripod lateral lateral_tripod adduction_grip parallel_extension``;
  the report's spellings are accepted).
- ``object_shape``: ``sphere``, ``cylinder`` or ``box``.
- ``object_dims_m``: space-separated sizes in metres; sphere: ``diameter``;
  cylinder: ``diameter length``; box: ``width depth height`` where *width* is
  the extent between the opposing fingers. The first number is the object
  size used by Table 1 and by the synergy-vs-size regressions.
- one column per joint, all 24 Shadow joints (``SHADOW_JOINT_NAMES``), in any
  order; the loader returns them in the canonical order.

The loader checks all of this and raises ValueError naming the line and the
field. It can also check the angles against joint limits.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from handle_drake.grasp.taxonomy import OBJECT_SHAPES, GraspClass, grasp_class

__all__ = [
    "FORMAT_VERSION",
    "SHADOW_JOINT_NAMES",
    "GraspRecords",
    "load_grasps",
    "save_grasps",
]

FORMAT_VERSION = 1
_MAGIC = "# handle_drake-grasps"
_META_COLUMNS = ("timestamp", "experimenter", "grasp_class", "object_shape", "object_dims_m")
_DIMS_PER_SHAPE = {"sphere": 1, "cylinder": 2, "box": 3}

# The file format's joint order: the Shadow E-series convention, the same as
# HandSpec("shadow").joint_names (docs/ARCHITECTURE.md, "Hands").
SHADOW_JOINT_NAMES: tuple[str, ...] = (
    "WRJ2", "WRJ1",
    "FFJ4", "FFJ3", "FFJ2", "FFJ1",
    "MFJ4", "MFJ3", "MFJ2", "MFJ1",
    "RFJ4", "RFJ3", "RFJ2", "RFJ1",
    "LFJ5", "LFJ4", "LFJ3", "LFJ2", "LFJ1",
    "THJ5", "THJ4", "THJ3", "THJ2", "THJ1",
)  # fmt: skip


@dataclass
class GraspRecords:
    """A set of recorded grasps, one row per grasp.

    q: (N, 24) joint angles in rad, columns in ``joint_names`` order.
    grasp_classes: N :class:`GraspClass` values.
    object_shapes: N of ``sphere | cylinder | box``.
    object_dims: N tuples of sizes (m), see the module docstring.
    experimenters: N ids.  timestamps: N ``datetime``.
    """

    q: np.ndarray
    grasp_classes: list[GraspClass]
    object_shapes: list[str]
    object_dims: list[tuple[float, ...]]
    experimenters: list[str]
    timestamps: list[datetime]
    joint_names: tuple[str, ...] = field(default=SHADOW_JOINT_NAMES)

    def __post_init__(self):
        self.q = np.asarray(self.q, dtype=float)
        n_joints = len(self.joint_names)
        if self.q.ndim != 2 or self.q.shape[1] != n_joints:
            raise ValueError(f"q: expected shape (N, {n_joints}), got {self.q.shape}")
        n = self.q.shape[0]
        for name in ("grasp_classes", "object_shapes", "object_dims", "experimenters",
                     "timestamps"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name}: expected {n} entries, got {len(getattr(self, name))}")
        if not np.all(np.isfinite(self.q)):
            row = int(np.argwhere(~np.isfinite(self.q))[0, 0])
            raise ValueError(f"q: non-finite joint angle in grasp {row}")
        self.grasp_classes = [grasp_class(c) for c in self.grasp_classes]
        for i, (shape, dims) in enumerate(zip(self.object_shapes, self.object_dims, strict=True)):
            _check_object(shape, dims, f"grasp {i}")
        self.object_dims = [tuple(float(d) for d in dims) for dims in self.object_dims]
        for i, who in enumerate(self.experimenters):
            _check_experimenter(who, f"grasp {i}")

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def sizes(self) -> np.ndarray:
        """(N,) object size in m: the first entry of each ``object_dims``."""
        return np.array([d[0] for d in self.object_dims])

    def joint_index(self, names: Sequence[str]) -> np.ndarray:
        """Column indices of ``names`` in ``q``."""
        missing = [n for n in names if n not in self.joint_names]
        if missing:
            raise ValueError(
                f"unknown joint names {missing}; expected names from {self.joint_names}"
            )
        return np.array([self.joint_names.index(n) for n in names], dtype=int)

    def select(self, mask) -> GraspRecords:
        """The rows where ``mask`` (bool array or index array) selects."""
        idx = np.arange(len(self))[np.asarray(mask)]
        return GraspRecords(
            q=self.q[idx],
            grasp_classes=[self.grasp_classes[i] for i in idx],
            object_shapes=[self.object_shapes[i] for i in idx],
            object_dims=[self.object_dims[i] for i in idx],
            experimenters=[self.experimenters[i] for i in idx],
            timestamps=[self.timestamps[i] for i in idx],
            joint_names=self.joint_names,
        )

    def of_class(self, name) -> GraspRecords:
        cls = grasp_class(name)
        return self.select(np.array([c == cls for c in self.grasp_classes], dtype=bool))


def _check_experimenter(who: str, where: str) -> None:
    if not isinstance(who, str) or not who.strip() or "," in who or "\n" in who:
        raise ValueError(
            f"{where}: experimenter must be a non-empty id without commas, got {who!r}"
        )


def _check_object(shape: str, dims, where: str) -> None:
    if shape not in OBJECT_SHAPES:
        raise ValueError(f"{where}: object_shape must be one of {OBJECT_SHAPES}, got {shape!r}")
    dims = tuple(dims)
    if len(dims) != _DIMS_PER_SHAPE[shape]:
        raise ValueError(
            f"{where}: a {shape} needs {_DIMS_PER_SHAPE[shape]} object_dims_m values, "
            f"got {len(dims)}"
        )
    for d in dims:
        if not np.isfinite(d) or d <= 0 or d > 2.0:
            raise ValueError(f"{where}: object_dims_m must be in (0, 2] m, got {d}")


def _parse_magic(line: str, path) -> str:
    match = re.fullmatch(r"# handle_drake-grasps format=(\S+)(?: angle_unit=(\S+))?\s*", line)
    if match is None:
        raise ValueError(
            f"{path}: line 1 must be '{_MAGIC} format={FORMAT_VERSION} angle_unit=rad', "
            f"got {line.strip()[:80]!r}"
        )
    version, unit = match.group(1), match.group(2) or "rad"
    if version != str(FORMAT_VERSION):
        raise ValueError(
            f"{path}: unsupported format version {version!r}, expected {FORMAT_VERSION}"
        )
    if unit not in ("rad", "deg"):
        raise ValueError(f"{path}: angle_unit must be 'rad' or 'deg', got {unit!r}")
    return unit


def load_grasps(
    path: str | Path,
    joint_limits: tuple[np.ndarray, np.ndarray] | None = None,
    limit_tolerance: float = 0.05,
) -> GraspRecords:
    """Read and validate a ``handle_drake-grasps`` CSV file.

    joint_limits: optional (lower, upper), each (24,) rad in
      ``SHADOW_JOINT_NAMES`` order; an angle further than ``limit_tolerance``
      (rad) outside them is an error (sensors of a real hand read slightly
      past the nominal limits, hence the tolerance).
    Raises FileNotFoundError, or ValueError naming line and field.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no grasp recording file {path}")
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    if not lines:
        raise ValueError(f"{path}: empty file, expected a '{_MAGIC}' line and a header")
    unit = _parse_magic(lines[0], path)
    # Keep the file's line numbers in error messages.
    body = [(i + 1, ln) for i, ln in enumerate(lines) if i > 0 and not ln.startswith("#")]
    body = [(no, ln) for no, ln in body if ln.strip()]
    if not body:
        raise ValueError(f"{path}: no header line after the magic line")
    header, col = _read_header(path, *body[0])
    rows = [_read_row(f"{path}:{line_no}", line, header, col, unit)
            for line_no, line in body[1:]]
    if not rows:
        raise ValueError(f"{path}: the file holds a header but no grasps")
    stamps, who_all, classes, shapes, dims_all, q_rows = (list(c) for c in zip(*rows,
                                                                                 strict=True))
    q_all = np.array(q_rows)
    if joint_limits is not None:
        _check_limits(q_all, joint_limits, limit_tolerance,
                      [f"{path}:{line_no}" for line_no, _ in body[1:]])
    return GraspRecords(q_all, classes, shapes, dims_all, who_all, stamps)


def _read_header(path: Path, header_no: int, header_line: str) -> tuple[list[str], dict]:
    """The header's column names and each name's index; a bad header is an error."""
    header = next(csv.reader([header_line]))
    header = [h.strip() for h in header]
    expected = set(_META_COLUMNS) | set(SHADOW_JOINT_NAMES)
    missing = [c for c in (*_META_COLUMNS, *SHADOW_JOINT_NAMES) if c not in header]
    unknown = [c for c in header if c not in expected]
    duplicate = sorted({c for c in header if header.count(c) > 1})
    if missing or unknown or duplicate:
        raise ValueError(
            f"{path}:{header_no}: bad header: missing columns {missing}, unknown columns "
            f"{unknown}, duplicated columns {duplicate}; expected {len(expected)} columns: "
            f"{', '.join(_META_COLUMNS)} and the 24 Shadow joint names"
        )
    return header, {name: header.index(name) for name in header}


def _read_row(where: str, line: str, header: list[str], col: dict, unit: str):
    """One grasp line: (timestamp, experimenter, class, shape, dims, q in rad)."""
    row = next(csv.reader([line]))
    if len(row) != len(header):
        raise ValueError(f"{where}: expected {len(header)} fields, got {len(row)}")
    try:
        stamp = datetime.fromisoformat(row[col["timestamp"]].strip())
    except ValueError as err:
        raise ValueError(f"{where}: timestamp is not ISO 8601: {err}") from None
    who = row[col["experimenter"]].strip()
    _check_experimenter(who, where)
    try:
        cls = grasp_class(row[col["grasp_class"]])
    except ValueError as err:
        raise ValueError(f"{where}: grasp_class: {err}") from None
    shape = row[col["object_shape"]].strip().lower()
    try:
        dims = tuple(float(v) for v in row[col["object_dims_m"]].split())
    except ValueError:
        raise ValueError(
            f"{where}: object_dims_m must be space-separated numbers, "
            f"got {row[col['object_dims_m']]!r}"
        ) from None
    _check_object(shape, dims, where)
    q = np.empty(len(SHADOW_JOINT_NAMES))
    for j, name in enumerate(SHADOW_JOINT_NAMES):
        c = col[name]
        try:
            q[j] = float(row[c])
        except ValueError:
            raise ValueError(f"{where}: {name} is not a number: {row[c]!r}") from None
        if not np.isfinite(q[j]):
            raise ValueError(f"{where}: {name} must be finite, got {row[c]!r}")
    if unit == "deg":
        q = np.deg2rad(q)
    return stamp, who, cls, shape, dims, q


def _check_limits(q_all: np.ndarray, joint_limits, limit_tolerance: float,
                  where: list[str]) -> None:
    """Every angle within the limits (+- the tolerance); ``where[r]``: row r's file:line."""
    lower, upper = (np.asarray(v, dtype=float) for v in joint_limits)
    if lower.shape != (24,) or upper.shape != (24,):
        raise ValueError(
            f"joint_limits: expected two arrays of shape (24,), got "
            f"{lower.shape}, {upper.shape}"
        )
    bad = (q_all < lower - limit_tolerance) | (q_all > upper + limit_tolerance)
    if np.any(bad):
        r, j = np.argwhere(bad)[0]
        raise ValueError(
            f"{where[r]}: {SHADOW_JOINT_NAMES[j]} = {q_all[r, j]:.4f} rad is "
            f"outside its limits [{lower[j]:.4f}, {upper[j]:.4f}] (tolerance "
            f"{limit_tolerance} rad)"
        )


def save_grasps(path: str | Path, records: GraspRecords) -> Path:
    """Write ``records`` as a ``handle_drake-grasps`` file (angles in rad).

    Refuses records whose joints are not the 24 Shadow joints. Writes to a
    temporary file and renames it, so a failure never leaves half a file.
    """
    if not isinstance(records, GraspRecords):
        raise TypeError(f"records must be GraspRecords, got {type(records).__name__}")
    if tuple(records.joint_names) != SHADOW_JOINT_NAMES:
        raise ValueError(
            f"records.joint_names: expected the 24 Shadow joints in order, "
            f"got {records.joint_names}"
        )
    path = Path(path)
    out = io.StringIO()
    out.write(f"{_MAGIC} format={FORMAT_VERSION} angle_unit=rad\n")
    out.write(
        "# object_dims_m: sphere 'diameter', cylinder 'diameter length', "
        "box 'width depth height' (width between the opposing fingers)\n"
    )
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow([*_META_COLUMNS, *SHADOW_JOINT_NAMES])
    for i in range(len(records)):
        writer.writerow([
            records.timestamps[i].isoformat(),
            records.experimenters[i],
            records.grasp_classes[i].value,
            records.object_shapes[i],
            " ".join(f"{d:.6g}" for d in records.object_dims[i]),
            *(f"{v:.6f}" for v in records.q[i]),
        ])  # fmt: skip
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(out.getvalue(), encoding="utf-8")
    tmp.replace(path)
    return path
