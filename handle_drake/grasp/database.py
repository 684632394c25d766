"""A grasp database: the planner's answers precomputed, stored in the object's frame.

The grasp planner's hand-IK search (:func:`handle_drake.grasp.planning.plan_grasp`)
takes seconds to a minute per grasp class, but its answer does not depend on where the
object stands: :class:`~handle_drake.grasp.planning.ObjectFrameGrasp` holds the grasp
frame in the palm, the palm in the hand base and the grasp, pre-shape and closing
postures, and :func:`~handle_drake.grasp.planning.place_grasp` puts it on the object
wherever it stands. A :class:`GraspDatabase` stores these answers (a failed search too,
as "no grasp") per request, keyed by :func:`~handle_drake.grasp.planning.grasp_key`:
(hand, grasp class, object kind, shape and dimensions, height above the table, coupling
ratio). The file also records the planner version
(:data:`~handle_drake.grasp.planning.PLANNER_VERSION`).

Validation: an entry is used only for a request with the same key (another object size
or resting height is another key), and only if the file's planner version is the
planner's own; entries of another version are stale (:attr:`GraspDatabase.stale`) and
are never returned, so the planner searches afresh. :func:`build_database` (re)computes
entries; ``handle-drake pick SCENARIO --build-grasp-db`` builds the pick application's
database for a scenario's catalogue objects.

The file is JSON (numbers as Python writes them, so a loaded grasp is the computed one
to the last bit).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform

from handle_drake.base.checks import read_text_file, short, short_path
from handle_drake.grasp.planning import (
    PLANNER_VERSION,
    GraspPlanningTimeout,
    ObjectFrameGrasp,
    grasp_key,
    object_frame_grasp,
)
from handle_drake.grasp.taxonomy import grasp_info

__all__ = ["GraspDatabase", "GraspDatabaseError", "build_database", "check_pose_matrix",
           "FORMAT", "MAX_BYTES"]

FORMAT = "handle_drake.grasp_database/1"
_MISSING = object()


#: The largest grasp database file read (the shipped one is ~100 kB).
MAX_BYTES = 64 << 20


def check_pose_matrix(name: str, value) -> np.ndarray:
    """``value`` as a 4x4 homogeneous transform: finite, last row [0 0 0 1], a proper
    rotation (orthonormal to 1e-6, determinant +1); ValueError naming ``name``."""
    m = np.asarray(value, dtype=float)
    if m.shape != (4, 4):
        raise ValueError(f"{name}: expected a 4x4 matrix, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError(f"{name}: expected finite numbers, got NaN or infinity")
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f"{name}: expected the last row [0, 0, 0, 1], got {m[3].tolist()}")
    R = m[:3, :3]
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    if error > 1e-6 or np.linalg.det(R) < 0:
        raise ValueError(f"{name}: expected a rotation (orthonormal, determinant +1) in the "
                         f"first 3 columns, got one off by {error:.3g} (determinant "
                         f"{np.linalg.det(R):.3g})")
    if np.abs(m[:3, 3]).max() > 10.0:
        raise ValueError(f"{name}: expected a translation within 10 m, got "
                         f"{m[:3, 3].tolist()}")
    return m


class GraspDatabaseError(ValueError):
    """A grasp database file that cannot be read (names the file and the field)."""


def _key_to_json(key: tuple) -> dict:
    hand, cls, kind, shape, dims, height, ratio = key
    return {"hand": hand, "grasp_class": cls, "kind": kind, "shape": shape,
            "dims": list(dims), "height": height, "coupling_ratio": ratio}


def _key_from_json(d: dict) -> tuple:
    return (str(d["hand"]), str(d["grasp_class"]), str(d["kind"]), str(d["shape"]),
            tuple(float(v) for v in d["dims"]), float(d["height"]),
            float(d["coupling_ratio"]))


def _grasp_to_json(g: ObjectFrameGrasp) -> dict:
    return {
        "X_PG": g.X_PG.GetAsMatrix4().tolist(), "up_G": g.up_G.tolist(),
        "centre_source": g.centre_source, "X_BP": g.X_BP.GetAsMatrix4().tolist(),
        "q_grasp": g.q_grasp.tolist(), "q_pre": g.q_pre.tolist(),
        "q_close": g.q_close.tolist(), "contact_error": g.contact_error,
        "amplitudes": None if g.amplitudes is None else g.amplitudes.tolist(),
        "grasp_amplitudes": g.grasp_amplitudes.tolist(),
    }


def _grasp_from_json(key: tuple, d: dict) -> ObjectFrameGrasp:
    def pose(name):
        return RigidTransform(check_pose_matrix(name, d[name]))

    def vector(name, n=None):
        v = np.asarray(d[name], dtype=float)
        if v.ndim != 1 or (n is not None and v.size != n) or not np.isfinite(v).all():
            raise ValueError(f"{name}: expected {n or 'a list of'} finite numbers")
        return v

    return ObjectFrameGrasp(
        key=key, X_PG=pose("X_PG"), up_G=vector("up_G", 3),
        centre_source=str(d["centre_source"]), X_BP=pose("X_BP"),
        q_grasp=vector("q_grasp", 24), q_pre=vector("q_pre", 24),
        q_close=vector("q_close", 24), contact_error=_finite("contact_error", d),
        amplitudes=None if d["amplitudes"] is None else vector("amplitudes"),
        grasp_amplitudes=vector("grasp_amplitudes"))


def _finite(name: str, d: dict) -> float:
    value = d[name]
    if isinstance(value, bool) or not isinstance(value, int | float) \
            or not np.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {short(value)}")
    return float(value)


class GraspDatabase:
    """Stored planner answers (see the module doc); ``get(key, default)`` is what
    ``plan_grasp(database=)`` asks. ``stale``: keys read from the file that belong to
    another planner version (never returned)."""

    def __init__(self, entries: dict | None = None, version: int = PLANNER_VERSION,
                 path: Path | None = None, stale: list | None = None):
        self.entries: dict = dict(entries or {})
        self.version = int(version)
        self.path = path
        self.stale: list = list(stale or [])

    def __len__(self) -> int:
        return len(self.entries)

    def __contains__(self, key) -> bool:
        return self.version == PLANNER_VERSION and key in self.entries

    def get(self, key, default=None):
        """The stored answer for ``key`` (an ObjectFrameGrasp, or None: no grasp
        exists), or ``default`` when there is none of this planner version."""
        if self.version != PLANNER_VERSION:
            return default
        return self.entries.get(key, default)

    def nearest(self, key) -> ObjectFrameGrasp | None:
        """The stored grasp (not a "no grasp" entry) of the same hand, class, object kind
        and shape and coupling ratio as ``key`` whose dimensions and height above the
        table are nearest to ``key``'s (the largest difference of any of them, m), or
        None. What :func:`~handle_drake.grasp.planning.plan_grasp` adapts to a size or
        height the database does not hold (:func:`~handle_drake.grasp.planning.adapt_grasp`)."""
        if self.version != PLANNER_VERSION:
            return None
        hand, cls, kind, shape, dims, height, ratio = key
        best, gap = None, np.inf
        for (h2, c2, k2, s2, d2, z2, r2), grasp in self.entries.items():
            if grasp is None or (h2, c2, k2, s2, r2) != (hand, cls, kind, shape, ratio) or \
                    len(d2) != len(dims):
                continue
            g = max(np.max(np.abs(np.subtract(d2, dims))), abs(z2 - height))
            if g < gap:
                best, gap = grasp, g
        return best

    def put(self, key, grasp: ObjectFrameGrasp | None) -> None:
        if self.version != PLANNER_VERSION:
            raise ValueError(f"cannot add to a database of planner version {self.version} "
                             f"(this planner is version {PLANNER_VERSION})")
        self.entries[key] = grasp

    # ------------------------------------------------------------------ file

    @classmethod
    def load(cls, path) -> GraspDatabase:
        """Reads ``path``; entries of another planner version are kept only in
        :attr:`stale`. Raises :class:`GraspDatabaseError` naming the bad field."""
        path = Path(path)
        try:  # a regular UTF-8 file of at most MAX_BYTES (a FIFO blocks, /dev/zero fills memory)
            text = read_text_file(path, "grasp database", MAX_BYTES)
        except FileNotFoundError:
            raise GraspDatabaseError(f"grasp database {short_path(path)}: no such file") \
                from None
        except (TypeError, ValueError) as error:
            raise GraspDatabaseError(str(error)) from None
        try:
            data = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as error:
            raise GraspDatabaseError(f"grasp database {short_path(path)}: not readable JSON "
                                     f"({str(error)[:200]})") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise GraspDatabaseError(f"grasp database {short_path(path)}: format: expected "
                                     f"{FORMAT!r}")
        version = data.get("planner_version")
        if not isinstance(version, int):
            raise GraspDatabaseError(f"grasp database {short_path(path)}: planner_version: "
                                     f"expected an integer, got {short(version)}")
        items = data.get("entries", [])
        if not isinstance(items, list):
            raise GraspDatabaseError(f"grasp database {short_path(path)}: entries: expected a "
                                     f"list, got {short(items)}")
        entries, stale = {}, []
        for i, item in enumerate(items):
            try:
                if not isinstance(item, dict):
                    raise TypeError(f"expected a mapping with key and grasp, got {short(item)}")
                key = _key_from_json(item["key"])
                grasp = None if item["grasp"] is None else _grasp_from_json(key,
                                                                            item["grasp"])
            except KeyError as error:
                raise GraspDatabaseError(f"grasp database {short_path(path)}: entries[{i}]: "
                                         f"missing {error}") from None
            except (TypeError, ValueError, OverflowError) as error:
                raise GraspDatabaseError(f"grasp database {short_path(path)}: entries[{i}]: "
                                         f"{str(error)[:200]}") from None
            if version == PLANNER_VERSION:
                entries[key] = grasp
            else:
                stale.append(key)
        if version != PLANNER_VERSION:
            return cls({}, PLANNER_VERSION, path, stale)
        return cls(entries, version, path)

    def save(self, path=None, meta: dict | None = None) -> Path:
        path = Path(path or self.path)
        items = [{"key": _key_to_json(k),
                  "grasp": None if g is None else _grasp_to_json(g)}
                 for k, g in sorted(self.entries.items(), key=lambda kv: repr(kv[0]))]
        data = {"format": FORMAT, "planner_version": self.version, "meta": meta or {},
                "entries": items}
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=1) + "\n")
        self.path = path
        return path


def build_database(requests, database: GraspDatabase | None = None,
                   coupling_ratio: float = 1.0, time_budget: float | None = None,
                   rebuild: bool = False, log=print) -> GraspDatabase:
    """Computes the answers for ``requests`` (``(grasp_class, (kind, size), height)``:
    the object's centre ``height`` above the table) into ``database`` (a new one by
    default), skipping keys it holds unless ``rebuild``. A search that runs out of
    ``time_budget`` is reported and not stored (the planner searches again when
    asked)."""
    database = GraspDatabase() if database is None else database
    for grasp_class, obj, height in requests:
        key = grasp_key(grasp_class, obj, height, coupling_ratio)
        if key in database and not rebuild:
            continue
        start = time.perf_counter()
        name = grasp_info(grasp_class).name
        try:
            grasp = object_frame_grasp(grasp_class, obj, height, coupling_ratio,
                                       time_budget=time_budget)
        except GraspPlanningTimeout:
            log(f"{name} on {obj}: no answer within {time_budget} s (not stored)")
            continue
        except ValueError as error:  # the class does not take this size
            log(f"{name} on {obj}: {error} (not stored)")
            continue
        database.put(key, grasp)
        log(f"{name} on {obj} at {height:.4f} m: "
            f"{'no grasp' if grasp is None else 'grasp'} "
            f"({time.perf_counter() - start:.1f} s)")
    return database
