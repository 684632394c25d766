"""Mesh files as grasp objects: the object kind ``mesh``.

A :class:`MeshObjectSpec` names a triangle mesh file (anything ``trimesh``
reads: OBJ, STL, PLY, OFF, GLB, ...), a ``scale`` from file units to metres
and the mass (``mass`` in kg, or ``density`` in kg/m^3). Everywhere the object
catalogue (:mod:`handle_drake.objects`) accepts an ``ObjectSpec`` it accepts
one of these too: ``AddObject``, ``resting_height``, ``mass_properties``,
``pieces``, ``surface_mesh``, ``sample_surface``, ``ray_cast``, scenarios
(``object: {kind: mesh, file: PATH, scale: S, mass: M}``), the grasp trials
of ``babble`` and the planner of ``grasp``.

**Object frame O.** Axes are the file's axes (+z is up when the object stands
on the table, as for the catalogue); the origin is the centre of the mesh's
axis-aligned bounding box (``origin="bbox"``, the default: for a symmetric
solid that is the catalogue's "geometric centre at mid-height") or the file's
own origin (``origin="file"``). ``resting_height`` is then ``-min z`` of the
mesh in O, the object standing on its lowest point as given in the file.

**Size.** ``spec.size`` (the catalogue's characteristic length, used for the
babbling offset box and the metric's torque scale) is the larger horizontal
(x, y) extent of the bounding box in O: the diameter of a sphere or cylinder,
the width of a cuboid, as in the catalogue.

**Collision geometry.** Point contact needs convex pieces (a single
``Convex`` would fill every cavity, a non-convex ``Mesh`` collides as its
hull in Drake), so the mesh is split by an approximate convex decomposition,
CoACD (``coacd``). Chosen by measurement (``benchmarks/bench_mesh_objects.py
--vhacd``): CoACD's pieces covered all of a torus, an L-bracket, a bowl and a
cup (excess volume 0-13 %); V-HACD (``vhacdx`` 0.1.1) returned hulls covering
0-21 % of them, 10-40x faster. CoACD's seconds per mesh are paid once (cache). A mesh that
is already convex (its volume within 0.1 % of its hull's) is one piece and
skips the decomposition. The pieces are cached on disk, keyed by the SHA-256
of the mesh's vertices and faces and the decomposition settings, in
``$HANDLE_DRAKE_CACHE_DIR/convex`` (default ``$XDG_CACHE_HOME/handle_drake``
or ``~/.cache/handle_drake``), so a mesh is decomposed once per machine. The
same pieces carry compliant hydroelastic properties when the scenario asks
for hydroelastic contact (Drake 1.51 supports compliant ``Convex``).

**Mass properties** come from the closed mesh (``trimesh``'s exact volume
integrals; ``mass`` overrides the density). Fallbacks, each with a
:class:`MeshObjectWarning`: a mesh that is not watertight is repaired
(merged vertices, fixed winding, filled holes); if it is still open but made
of closed, disjoint parts, the parts are summed; otherwise the mass
properties are those of its convex hull.

**Surface queries** (the contact surface model, report section 4.1.3) use the
real mesh, not the convex pieces: :func:`ray_cast` returns the first entry
point and the face normal there, :func:`sample_surface` samples it by area.

**Bad input** raises ``FileNotFoundError`` (missing file), ``ValueError``
naming the field (unreadable, empty or non-finite mesh; scale, mass or
density out of range; a mesh larger than ``MAX_EXTENT`` or smaller than
``MIN_EXTENT`` after scaling) or warns (:class:`MeshObjectWarning`) when a
mesh is larger than the hand can enclose (``LARGE_EXTENT``) or not closed.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh
from pydrake.geometry import (
    AddContactMaterial,
    Convex,
    InMemoryMesh,
    Mesh,
    ProximityProperties,
    Sphere,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import SpatialInertia, UnitInertia

__all__ = [
    "MESH_KIND",
    "CACHE_ENV",
    "DEFAULT_DENSITY",
    "MIN_EXTENT",
    "MAX_EXTENT",
    "MAX_TRIANGLES",
    "LARGE_EXTENT",
    "DENSITY_RANGE",
    "MeshObjectSpec",
    "MeshObjectWarning",
    "cache_dir",
    "convex_decomposition",
    "mesh_in_object_frame",
    "pieces",
    "mass_properties",
    "spatial_inertia",
    "total_height",
    "resting_height",
    "contact_feet",
    "surface_mesh",
    "sample_surface",
    "ray_cast",
    "contains",
    "grasp_extents",
    "write_mesh",
    "AddMeshObject",
]

MESH_KIND = "mesh"
#: Environment variable naming the cache folder (decomposed meshes in ``<dir>/convex``).
CACHE_ENV = "HANDLE_DRAKE_CACHE_DIR"
#: kg/m^3 when neither mass nor density is given (wood/plastic, as the catalogue's primitives).
DEFAULT_DENSITY = 500.0
#: m: the largest extent after scaling must lie in [MIN_EXTENT, MAX_EXTENT]; above
#: LARGE_EXTENT a warning says that the hands (a Shadow hand spans ~0.2 m) cannot enclose it.
MIN_EXTENT = 0.005
MAX_EXTENT = 1.0
LARGE_EXTENT = 0.3
#: kg/m^3: the mass must imply a density in this range (expanded foam to osmium).
DENSITY_RANGE = (10.0, 25000.0)
#: Relative volume gap under which a mesh counts as convex (one piece, no decomposition).
_CONVEX_TOLERANCE = 1e-3
_COLOR = (0.60, 0.60, 0.68, 1.0)


class MeshObjectWarning(UserWarning):
    """A mesh object was accepted with a fallback (open mesh, very large object)."""


def _number(name: str, value, low: float | None = None, high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name}: expected a finite number > 0, got {value}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ValueError(f"{name}: expected a value in [{low:g}, {high:g}], got {value:g}")
    return value


@dataclass(frozen=True)
class MeshObjectSpec:
    """A grasp object from a mesh file (see the module doc for frame, size and fallbacks).

    Attributes:
        file: path of the mesh file (OBJ, STL, PLY or any format trimesh reads).
        scale: file units to metres (0.001 for a file in millimetres).
        mass: kg; default ``density * volume``.
        density: kg/m^3 when ``mass`` is None; default :data:`DEFAULT_DENSITY`.
        mu: Coulomb friction coefficient (static = dynamic).
        origin: "bbox" (centre of the bounding box, default) or "file".
        hydroelastic_modulus: Pa, compliant hydroelastic contact.
        resolution_hint: m, hydroelastic tessellation; default: each piece's extent.
        threshold: CoACD concavity threshold (smaller: more, tighter pieces).
        max_pieces: at most this many convex pieces.
        color: RGBA.
        digest: SHA-256 of the file's bytes, filled in on construction (so two
            specs of a file whose content changed are different objects).
    """

    file: str
    scale: float = 1.0
    mass: float | None = None
    density: float | None = None
    mu: float = 0.8
    origin: str = "bbox"
    hydroelastic_modulus: float = 1.0e7
    resolution_hint: float | None = None
    threshold: float = 0.05
    max_pieces: int = 32
    color: tuple[float, float, float, float] | None = None
    digest: str = field(default="", repr=False)

    kind = MESH_KIND  # a class attribute, not a field: every spec is of kind "mesh"

    def __post_init__(self):
        if not isinstance(self.file, str | os.PathLike):
            raise TypeError(f"file: expected a path, got {type(self.file).__name__}")
        from handle_drake.scenario_checks import check_input_file

        if not str(self.file):
            raise ValueError("file: expected a mesh file path, got an empty string")
        path = check_input_file(self.file, "file: mesh file", max_bytes=MAX_MESH_BYTES)
        object.__setattr__(self, "file", str(path.resolve()))
        object.__setattr__(self, "scale", _number("scale", self.scale))
        if self.mass is not None:
            object.__setattr__(self, "mass", _number("mass", self.mass))
        if self.density is not None:
            object.__setattr__(self, "density", _number("density", self.density, *DENSITY_RANGE))
        mu = self.mu
        if isinstance(mu, bool) or not isinstance(mu, int | float | np.floating | np.integer) \
                or not math.isfinite(mu) or mu < 0:
            raise ValueError(f"mu: expected a finite number >= 0, got {mu!r}")
        object.__setattr__(self, "mu", float(mu))
        if self.origin not in ("bbox", "file"):
            raise ValueError(f"origin: expected 'bbox' or 'file', got {self.origin!r}")
        object.__setattr__(self, "hydroelastic_modulus",
                           _number("hydroelastic_modulus", self.hydroelastic_modulus))
        if self.resolution_hint is not None:
            object.__setattr__(self, "resolution_hint",
                               _number("resolution_hint", self.resolution_hint))
        object.__setattr__(self, "threshold", _number("threshold", self.threshold, 0.01, 1.0))
        if isinstance(self.max_pieces, bool) or not isinstance(self.max_pieces, int) \
                or not 1 <= self.max_pieces <= 256:
            raise ValueError(
                f"max_pieces: expected an integer in [1, 256], got {self.max_pieces!r}")
        if self.color is not None:
            rgba = tuple(float(c) for c in self.color)
            if len(rgba) != 4 or not all(0.0 <= c <= 1.0 for c in rgba):
                raise ValueError(f"color: expected 4 numbers in [0, 1] (RGBA), got {self.color}")
            object.__setattr__(self, "color", rgba)
        object.__setattr__(self, "digest", hashlib.sha256(path.read_bytes()).hexdigest())
        _geometry(self)  # reads and checks the mesh now, not when the plant is built

    @property
    def rgba(self) -> tuple[float, float, float, float]:
        return self.color if self.color is not None else _COLOR

    @property
    def size(self) -> float:
        """m: the larger horizontal (x, y) extent of the bounding box in O."""
        return float(max(_geometry(self).extents[:2]))

    @property
    def name(self) -> str:
        return Path(self.file).stem


# --------------------------------------------------------------------------- geometry


@dataclass(frozen=True, eq=False)
class _Geometry:
    mesh: trimesh.Trimesh  # in O, metres
    file_vertices: np.ndarray  # (n, 3) as read (file units and frame), for the decomposition
    file_faces: np.ndarray
    p_FO: np.ndarray  # origin of O in the file frame (file units)
    extents: np.ndarray  # (3,) m
    volume: float  # m^3 of the solid the mass properties describe
    p_OScm: np.ndarray  # centre of mass in O (m)
    I_SScm_unit: np.ndarray  # central inertia for density 1 kg/m^3, expressed in O
    mass_source: str  # "mesh", "parts" or "convex hull"
    watertight: bool
    # The closed solids the collision pieces are cut from, each (vertices in the
    # file frame and units, faces): the mesh as read when it is closed, else the
    # solid its mass properties describe (repaired mesh, each closed part, hull).
    solids: tuple = ()


#: m (or file units): larger coordinates are garbage, and their products overflow.
MAX_COORDINATE = 1e12
#: triangles: a larger mesh is refused (decimate it first, e.g. in MeshLab or Blender).
#: A hand-held object needs a few thousand; scanned ones (YCB's 16k models) ~30k;
#: CoACD took 91 s on a 200k-triangle torus.
MAX_TRIANGLES = 200_000
#: bytes: a mesh file larger than this is refused before it is parsed.
MAX_MESH_BYTES = 256 << 20


def _check_obj_indices(path: str) -> None:
    """OBJ indices count from 1 (negative: from the end); 0 names no vertex, and
    trimesh would read it as the last vertex."""
    if not path.lower().endswith(".obj"):
        return
    with open(path, "rb") as file:
        for number, line in enumerate(file, 1):
            if not line.startswith((b"f ", b"f\t", b"l ", b"l\t")):
                continue
            for token in line.split()[1:]:
                for index in token.split(b"/"):
                    if index and index.lstrip(b"+-").strip(b"0") == b"":
                        raise ValueError(f"file: {path}:{number}: face index 0; OBJ indices "
                                         f"count from 1 (negative ones from the end)")


def _read(path: str) -> trimesh.Trimesh:
    _check_obj_indices(path)
    try:
        with np.errstate(all="ignore"):  # overflow warnings would precede the refusal
            loaded = trimesh.load(path, force="mesh")
    except Exception as error:  # trimesh raises many kinds for bad or unknown files
        text = " ".join(str(error).split())[:200]
        raise ValueError(f"file: cannot read mesh {path}: {type(error).__name__}: {text}") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError(f"file: {path} holds no triangles (empty mesh or a point cloud)")
    if len(loaded.faces) > MAX_TRIANGLES:
        raise ValueError(f"file: {path} has {len(loaded.faces)} triangles, expected at most "
                         f"{MAX_TRIANGLES} (decimate it first)")
    if not np.all(np.isfinite(loaded.vertices)):
        raise ValueError(f"file: {path} has non-finite vertex coordinates")
    if np.abs(loaded.vertices).max() > MAX_COORDINATE:
        raise ValueError(f"file: {path} has vertex coordinates up to "
                         f"{np.abs(loaded.vertices).max():.3g}, expected at most "
                         f"{MAX_COORDINATE:g} (file units)")
    loaded.remove_unreferenced_vertices()
    if loaded.area <= 0.0:
        raise ValueError(f"file: {path} has only degenerate (zero-area) triangles")
    return loaded


def _mass_integrals(mesh: trimesh.Trimesh, name: str):
    """(volume, centre of mass, unit-density central inertia, source, watertight, solids).

    ``solids``: the closed meshes (in the frame of ``mesh``) that the mass
    properties describe, for the convex decomposition: CoACD cuts closed
    solids fast; an open surface it must first remesh into a thin shell, which
    took minutes (a 300-face open hemisphere: > 5 min, 32 slivers).
    """
    if mesh.is_watertight:
        if mesh.volume < 0:
            mesh.invert()
        return mesh.volume, mesh.center_mass, mesh.moment_inertia, "mesh", True, (mesh,)
    repaired = mesh.copy()
    trimesh.repair.fix_winding(repaired)
    trimesh.repair.fill_holes(repaired)
    trimesh.repair.fix_normals(repaired)
    if repaired.is_watertight and repaired.volume > 0:
        warnings.warn(f"mesh {name} was not closed; holes were filled for its mass properties",
                      MeshObjectWarning, stacklevel=3)
        return (repaired.volume, repaired.center_mass, repaired.moment_inertia, "mesh", False,
                (repaired,))
    parts = mesh.split(only_watertight=False)
    if len(parts) > 1 and all(p.is_watertight for p in parts):
        warnings.warn(f"mesh {name} is {len(parts)} closed parts; their mass properties are "
                      "summed (parts taken as disjoint)", MeshObjectWarning, stacklevel=3)
        for p in parts:
            if p.volume < 0:
                p.invert()
        volumes = np.array([p.volume for p in parts])
        com = sum(v * p.center_mass for v, p in zip(volumes, parts, strict=True)) / volumes.sum()
        inertia = np.zeros((3, 3))
        for v, p in zip(volumes, parts, strict=True):
            r = p.center_mass - com
            inertia += p.moment_inertia + v * (r @ r * np.eye(3) - np.outer(r, r))
        return volumes.sum(), com, inertia, "parts", False, tuple(parts)
    from scipy.spatial import QhullError

    try:
        hull = mesh.convex_hull
    except (QhullError, ValueError):
        hull = None
    if hull is None or not hull.volume > 0:
        raise ValueError(f"file: mesh {name} encloses no volume (a flat or degenerate mesh)")
    warnings.warn(f"mesh {name} is not closed (open or non-manifold) and could not be repaired; "
                  "its mass properties and collision geometry are those of its convex hull "
                  "(ray casts still use the real surface)", MeshObjectWarning, stacklevel=3)
    return hull.volume, hull.center_mass, hull.moment_inertia, "convex hull", False, (hull,)


@lru_cache(maxsize=64)
def _geometry(spec: MeshObjectSpec) -> _Geometry:
    raw = _read(spec.file)
    name = Path(spec.file).name
    lo, hi = raw.bounds
    p_FO = (lo + hi) / 2 if spec.origin == "bbox" else np.zeros(3)
    extents = (hi - lo) * spec.scale
    largest = float(extents.max())
    if largest > MAX_EXTENT:
        hint = ""
        for unit, factor in (("millimetres", 1e-3), ("centimetres", 1e-2)):
            if MIN_EXTENT <= largest * factor <= LARGE_EXTENT:
                hint = f" (is the file in {unit}? then scale: {spec.scale * factor:g})"
                break
        raise ValueError(f"scale: mesh {name} would be {largest:.3g} m across, far larger than "
                         f"a hand (at most {MAX_EXTENT:g} m){hint}")
    if largest < MIN_EXTENT:
        hint = (f" (is the file in metres with scale {spec.scale:g}?)" if spec.scale != 1.0
                else "")
        raise ValueError(f"scale: mesh {name} would be {largest * 1000:.3g} mm across, smaller "
                         f"than {MIN_EXTENT * 1000:g} mm{hint}")
    mesh = raw.copy()
    mesh.apply_translation(-p_FO)
    mesh.apply_scale(spec.scale)
    volume, com, inertia, source, watertight, solids = _mass_integrals(mesh, name)
    if watertight:  # the file's own vertices: the cache key does not depend on scale, origin
        # Each closed component apart: a convex one is its own hull, and CoACD
        # segfaulted on two overlapping closed boxes given as one mesh.
        components = raw.split(only_watertight=False)
        solids_F = tuple((np.asarray(m.vertices, dtype=float), np.asarray(m.faces, np.int64))
                         for m in (components if len(components) > 1 else (raw,)))
    else:
        solids_F = tuple((np.asarray(m.vertices, dtype=float) / spec.scale + p_FO,
                          np.asarray(m.faces, dtype=np.int64)) for m in solids)
    if not volume > 0:
        raise ValueError(f"file: mesh {name} encloses no volume (a flat or degenerate mesh)")
    if largest > LARGE_EXTENT:  # warned only for a mesh that is accepted
        warnings.warn(f"mesh {name} is {largest:.2f} m across, larger than the hands can "
                      f"enclose (~{LARGE_EXTENT:g} m); grasps will be partial", MeshObjectWarning,
                      stacklevel=3)
    if spec.mass is not None:
        density = spec.mass / volume
        if not DENSITY_RANGE[0] <= density <= DENSITY_RANGE[1]:
            raise ValueError(
                f"mass: {spec.mass:g} kg in {volume * 1e6:.4g} cm^3 is a density of "
                f"{density:.4g} kg/m^3, outside [{DENSITY_RANGE[0]:g}, {DENSITY_RANGE[1]:g}] "
                "(wrong mass, or wrong scale?)")
    return _Geometry(mesh=mesh, file_vertices=np.asarray(raw.vertices, dtype=float),
                     file_faces=np.asarray(raw.faces, dtype=np.int64), p_FO=p_FO,
                     extents=extents, volume=float(volume), p_OScm=np.asarray(com, dtype=float),
                     I_SScm_unit=np.asarray(inertia, dtype=float), mass_source=source,
                     watertight=watertight, solids=solids_F)


def mesh_in_object_frame(spec: MeshObjectSpec) -> trimesh.Trimesh:
    """The mesh as read, scaled to metres and moved into O (a copy)."""
    return _geometry(spec).mesh.copy()


# --------------------------------------------------------------------------- decomposition


def cache_dir() -> Path:
    """Folder of the decomposition cache (``$HANDLE_DRAKE_CACHE_DIR`` or the user cache)."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "handle_drake"


def _decomposition_key(vertices: np.ndarray, faces: np.ndarray, settings: dict) -> str:
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(faces, dtype="<i8").tobytes())
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


def convex_decomposition(vertices, faces, threshold: float = 0.05, max_pieces: int = 32,
                         directory=None, name: str = "mesh") -> list[np.ndarray]:
    """Convex pieces (a list of (k, 3) hull vertex arrays) of a closed triangle mesh.

    CoACD (Wei et al. 2022, ``coacd`` on PyPI) with ``threshold`` (its
    concavity bound, relative to the mesh's size) and at most ``max_pieces``
    hulls, seed 0 (deterministic); with ``HANDLE_DRAKE_REDUCED`` set, a
    shallower plane search (a few times faster, a few more pieces). A
    convex mesh (volume within 0.1 % of its hull) is returned as its hull
    without running CoACD. Results are cached
    as ``<directory>/convex/<sha256>.npz`` (default :func:`cache_dir`) keyed
    by the vertices, faces and settings; a damaged cache file is recomputed.
    A CoACD run (seconds to minutes for dense meshes) says so on stderr, with
    ``name``, before it starts and when it ends.
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"vertices, faces: expected (n, 3) arrays, got {vertices.shape}, "
                         f"{faces.shape}")
    import coacd

    from handle_drake.testing import reduced

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    # CoACD's manifold remeshing (its "preprocess") is for open or non-manifold
    # input only; on a closed mesh it just costs time. Reduced mode (the test
    # suite) searches its cutting planes with fewer tree-search iterations.
    settings = {"method": "coacd", "version": getattr(coacd, "__version__", "1"),
                "threshold": float(threshold), "max_pieces": int(max_pieces), "seed": 0,
                "preprocess_mode": "off" if mesh.is_watertight else "on",
                "mcts_iterations": 40 if reduced() else 150,
                "mcts_max_depth": 2 if reduced() else 3}
    key = _decomposition_key(vertices, faces, settings)
    folder = Path(directory) if directory is not None else cache_dir()
    path = folder / "convex" / f"{key}.npz"
    if path.is_file():
        try:
            with np.load(path) as data:
                counts = data["counts"]
                return np.split(data["points"], np.cumsum(counts)[:-1])
        except (OSError, KeyError, ValueError):
            pass  # unreadable: decompose again and overwrite
    hull = mesh.convex_hull
    if mesh.is_watertight and abs(hull.volume - abs(mesh.volume)) <= _CONVEX_TOLERANCE * \
            hull.volume:
        result = [np.asarray(hull.vertices, dtype=float)]
    else:
        print(f"decomposing {name} ({len(faces)} triangles) into convex pieces with CoACD, "
              f"once (cached in {folder / 'convex'}) ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        run = {k: settings[k] for k in ("threshold", "preprocess_mode", "mcts_iterations",
                                        "mcts_max_depth")}
        run["max_convex_hull"] = settings["max_pieces"]
        result = _isolated(_run_coacd, vertices, faces, run)
        if result is None and run["preprocess_mode"] == "off":
            # CoACD crashes on some closed but self-intersecting meshes (two
            # overlapping boxes in one file); its manifold remeshing repairs them.
            result = _isolated(_run_coacd, vertices, faces, {**run, "preprocess_mode": "on"})
        if result is None:
            warnings.warn(f"CoACD failed on mesh {name}; its collision geometry is its convex "
                          "hull", MeshObjectWarning, stacklevel=2)
            return [np.asarray(hull.vertices, dtype=float)]  # not cached: the next run retries
        result = [np.asarray(v, dtype=float) for v in result if len(v) >= 4]
        print(f"decomposed {name}: {len(result)} pieces in {time.perf_counter() - start:.1f} s",
              file=sys.stderr, flush=True)
        if not result:
            result = [np.asarray(hull.vertices, dtype=float)]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    np.savez(tmp, points=np.vstack(result), counts=np.array([len(r) for r in result]))
    os.replace(tmp, path)  # concurrent writers never leave half a file
    return result


def _run_coacd(vertices, faces, run: dict) -> list[np.ndarray]:
    import coacd

    coacd.set_log_level("error")
    return [np.asarray(v, dtype=float)
            for v, _ in coacd.run_coacd(coacd.Mesh(vertices, faces), seed=0, **run)]


def _isolated(function, *args):
    """``function(*args)`` in a child process: its result, or None when the child died
    or the function raised RuntimeError or ValueError.

    CoACD is C++ that segfaults on some inputs (measured: a closed,
    self-intersecting mesh with its remeshing off); in a child process that
    costs the child, not the user's session. Spawning costs ~1 s, against
    seconds to minutes of decomposition. CoACD does not look at signals while
    it runs, so the child ignores Ctrl-C and this process, which waits in
    short polls, kills it on KeyboardInterrupt (or any other exception): a
    decomposition stops within a second of Ctrl-C. The child dies with this
    process too (:mod:`handle_drake.orphans`).
    """
    import multiprocessing

    if multiprocessing.current_process().daemon:  # a Dask or pool worker may not have children
        return function(*args)
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_isolated_child, args=(send, os.getpid(), function, args),
                            name="handle_drake-isolated", daemon=True)
    child.start()
    send.close()  # only the child writes: its death reads as EOF here
    try:
        while not receive.poll(0.1):
            if not child.is_alive() and not receive.poll(0):
                return None
        try:
            ok, value = receive.recv()
        except (EOFError, OSError):  # died without an answer (a segfault)
            return None
        return value if ok else None
    finally:
        receive.close()
        if child.is_alive():
            child.kill()
        child.join(5)


def _isolated_child(send, parent_pid, function, args):
    import signal

    from handle_drake.orphans import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides (see _isolated)
    die_with_parent(parent_pid)
    try:
        result = (True, function(*args))
    except (RuntimeError, ValueError):
        result = (False, None)
    send.send(result)
    send.close()


@lru_cache(maxsize=64)
def pieces(spec: MeshObjectSpec) -> tuple:
    """The convex pieces (``objects.Piece``, shape "convex", vertices in O) of the mesh."""
    from handle_drake.objects import Piece

    g = _geometry(spec)
    parts = [p for v, f in g.solids
             for p in convex_decomposition(v, f, spec.threshold, spec.max_pieces, name=spec.name)]
    identity = RigidTransform()
    return tuple(Piece(f"piece_{i:02d}", "convex", (), identity, (v - g.p_FO) * spec.scale)
                 for i, v in enumerate(parts))


# --------------------------------------------------------------------------- mass


def _density(spec: MeshObjectSpec) -> float:
    g = _geometry(spec)
    if spec.mass is not None:
        return spec.mass / g.volume
    return spec.density if spec.density is not None else DEFAULT_DENSITY


def spatial_inertia(spec: MeshObjectSpec) -> SpatialInertia:
    """``M_OOo_O``: the object's spatial inertia about its origin, expressed in O."""
    g = _geometry(spec)
    mass = _density(spec) * g.volume
    I = g.I_SScm_unit / g.volume  # per unit mass, about the centre of mass
    G_SScm = UnitInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    M_SScm = SpatialInertia(mass, np.zeros(3), G_SScm, skip_validity_check=False)
    return M_SScm.Shift(-g.p_OScm)


def mass_properties(spec: MeshObjectSpec):
    """``objects.MassProperties`` of the mesh (see the module doc for fallbacks)."""
    from handle_drake.objects import MassProperties

    g = _geometry(spec)
    density = _density(spec)
    return MassProperties(float(density * g.volume), g.volume, g.p_OScm.copy(),
                          density * g.I_SScm_unit)


def total_height(spec: MeshObjectSpec) -> float:
    """Vertical extent (m) of the mesh standing on its lowest point."""
    return float(_geometry(spec).extents[2])


def resting_height(spec: MeshObjectSpec) -> float:
    """Height (m) of O above a table the mesh stands on (``-min z`` in O)."""
    return float(-_geometry(spec).mesh.bounds[0, 2])


def _foot_radius(spec: MeshObjectSpec) -> float:
    return 0.01 * spec.size


def contact_feet(spec: MeshObjectSpec) -> np.ndarray:
    """Centres (k, 3) in O of collision-only spheres under a flat bottom (point contact).

    As for the catalogue (``objects.contact_feet``): one contact point per
    geometry pair makes a flat-bottomed piece rock on the table. The bottom is
    the faces lying in the lowest plane (normal within 2.5 degrees of -z);
    feet sit at up to 8 corners of their 2-D convex hull, moved in by one
    radius and a half towards its centre. Meshes without such a face get none.
    """
    from scipy.spatial import ConvexHull, QhullError

    mesh = _geometry(spec).mesh
    r = _foot_radius(spec)
    z_min = mesh.bounds[0, 2]
    tol = 1e-6 * spec.size
    on_floor = np.all(mesh.triangles[:, :, 2] <= z_min + tol, axis=1)
    flat = on_floor & (mesh.face_normals[:, 2] < -math.cos(math.radians(2.5)))
    if mesh.area_faces[flat].sum() < (4 * r) ** 2:
        return np.zeros((0, 3))
    xy = mesh.triangles[flat][:, :, :2].reshape(-1, 2)
    try:
        corners = xy[ConvexHull(xy).vertices]
    except QhullError:
        return np.zeros((0, 3))
    if len(corners) > 8:
        corners = corners[np.linspace(0, len(corners), 8, endpoint=False).astype(int)]
    centre = corners.mean(axis=0)
    inward = centre - corners
    inward /= np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-12)
    feet = corners + 1.5 * r * inward
    return np.column_stack([feet, np.full(len(feet), z_min + r)])


# --------------------------------------------------------------------------- surface


def surface_mesh(spec: MeshObjectSpec) -> trimesh.Trimesh:
    """The real mesh in O (a copy): the surface of the object, no internal faces."""
    return mesh_in_object_frame(spec)


def sample_surface(spec: MeshObjectSpec, n: int, rng=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniform by area on the mesh and their face normals, in O."""
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise TypeError(f"n: expected an int, got {type(n).__name__}")
    if n < 0:
        raise ValueError(f"n: expected >= 0, got {n}")
    mesh = _geometry(spec).mesh
    rng = np.random.default_rng(rng)
    areas = mesh.area_faces
    faces = np.minimum(np.searchsorted(np.cumsum(areas) / areas.sum(), rng.random(n)),
                       len(areas) - 1)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = mesh.triangles[faces]
    p = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    return p, np.asarray(mesh.face_normals[faces])


@lru_cache(maxsize=64)
def _surface(spec: MeshObjectSpec):
    from handle_drake.quality.surface import MeshSurface

    return MeshSurface(_geometry(spec).mesh)


def contains(spec: MeshObjectSpec, points) -> np.ndarray:
    """True where points (k, 3) in O are inside the closed mesh (generalised winding number).

    The winding number (sum of signed solid angles of the faces, Van Oosterom
    and Strackee's formula, over 4 pi) is 1 inside a closed outward-wound mesh
    and 0 outside; > 0.5 is inside. Hand-written: trimesh's ``contains`` needs
    ``rtree``, which this project does not depend on.
    """
    p = np.atleast_2d(np.asarray(points, dtype=float))
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points: expected shape (k, 3), got {np.shape(points)}")
    tri = _geometry(spec).mesh.triangles
    out = np.empty(len(p), dtype=bool)
    step = max(1, 2_000_000 // max(1, len(tri)))
    for start in range(0, len(p), step):
        q = p[start:start + step]
        a, b, c = (tri[None, :, k, :] - q[:, None, :] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc
               + np.einsum("pfi,pfi->pf", b, c) * la + np.einsum("pfi,pfi->pf", c, a) * lb)
        winding = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
        out[start:start + step] = winding > 0.5
    return out


def ray_cast(spec: MeshObjectSpec, p_OA, d_O):
    """First point where each ray ``p_OA + t d_O`` (t >= 0) meets the mesh surface.

    Returns ``objects.RayHits`` (``piece`` is 0 for a hit, -1 for none); the
    normal is the hit face's normal, turned against the ray (for a closed mesh
    hit from outside that is the outward normal). Exact on the mesh: against
    the true shape the error is the mesh's facet error. Raises ValueError for
    an origin inside a closed mesh.
    """
    from handle_drake.objects.queries import RayHits, _rays

    o, d = _rays(p_OA, d_O)
    if _geometry(spec).watertight:
        inside = contains(spec, o)
        if np.any(inside):
            raise ValueError(f"ray origins must lie outside the object; {int(inside.sum())} of "
                             f"{len(o)} are inside")
    t, normals = _surface(spec).intersect(o, d)
    t = np.where(np.isfinite(t) & (t >= 0), t, np.inf)
    best = np.argmin(t, axis=1)
    rows = np.arange(len(o))
    distance = t[rows, best]
    hit = np.isfinite(distance)
    n = normals[rows, best]
    n = np.where((np.einsum("ij,ij->i", n, d) > 0)[:, None], -n, n)
    points = np.where(hit[:, None], o + np.where(hit, distance, 0)[:, None] * d, np.nan)
    n = np.where(hit[:, None], n, np.nan)
    return RayHits(hit, distance, points, n, np.where(hit, 0, -1))


def grasp_extents(spec: MeshObjectSpec) -> tuple[float, float, float]:
    """(opposition, row, height) extents (m) of the mesh for the grasp planner.

    The planner grasps a mesh like an upright cuboid: its proxy is the
    bounding box in O, the fingers close across the *narrower* horizontal
    axis and the finger row runs along the wider one. The Table 1 size of the
    grasp is the opposition extent: the distance between the two planes the
    opposing fingers close on.
    """
    ex, ey, ez = (float(v) for v in _geometry(spec).extents)
    return (min(ex, ey), max(ex, ey), ez)


def write_mesh(spec, path) -> Path:
    """Writes an object's surface as a mesh file, in metres in O; the format follows the
    extension (``.obj``, ``.stl``, ``.ply``, ... as trimesh writes them).

    For a catalogue ``ObjectSpec`` the surface is ``objects.surface_mesh``: a
    closed mesh for the one-piece kinds (sphere as a 1280-face icosphere,
    cylinder as a 64-gon prism, cuboids exact); the multi-piece kinds (mug,
    wine glass, star prism) keep the faces their pieces share, so read back
    they are not one closed surface (the parts fallback of the mass properties).
    """
    from handle_drake.objects import surface_mesh as catalogue_surface

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    catalogue_surface(spec).export(path)
    return path


# --------------------------------------------------------------------------- plant


def _visual_shape(spec: MeshObjectSpec):
    # With normals: Drake's renderers (RgbdSensor, RenderEngineVtk) refuse an OBJ
    # without them. Smooth-shaded: vertices split at sharp edges, so a box is flat.
    text = trimesh.exchange.obj.export_obj(_geometry(spec).mesh.smooth_shaded,
                                           include_normals=True, include_texture=False)
    from pydrake.common import MemoryFile

    return Mesh(InMemoryMesh(mesh_file=MemoryFile(text, ".obj", spec.name)), 1.0)


def AddMeshObject(plant, spec: MeshObjectSpec, name: str = "object", hydroelastic: bool = False):
    """Adds the mesh object as a free body (``objects.BODY_NAME``) to an unfinalized plant.

    Collision: one ``Convex`` per piece (:func:`pieces`), Coulomb friction
    ``mu``, compliant hydroelastic when ``hydroelastic``; under point contact
    also :func:`contact_feet`. Visual: the real mesh. Returns the model instance.
    """
    from handle_drake.objects.catalogue import BODY_NAME
    from handle_drake.objects.plant import _object_proximity

    if not isinstance(spec, MeshObjectSpec):
        raise TypeError(f"spec: expected a MeshObjectSpec, got {type(spec).__name__}")
    if plant.is_finalized():
        raise ValueError("AddObject must be called before plant.Finalize()")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name: expected a non-empty str, got {name!r}")
    instance = plant.AddModelInstance(name)
    body = plant.AddRigidBody(BODY_NAME, instance, spatial_inertia(spec))
    identity = RigidTransform()
    for piece in pieces(spec):
        shape = Convex(np.ascontiguousarray(piece.vertices.T), piece.name)
        plant.RegisterCollisionGeometry(body, identity, shape, f"{piece.name}_collision",
                                        _object_proximity(spec, piece, hydroelastic))
    plant.RegisterVisualGeometry(body, identity, _visual_shape(spec), "mesh_visual",
                                 np.array(spec.rgba))
    if not hydroelastic:
        props = ProximityProperties()
        AddContactMaterial(friction=CoulombFriction(spec.mu, spec.mu), properties=props)
        for i, p_OF in enumerate(contact_feet(spec)):
            plant.RegisterCollisionGeometry(body, RigidTransform(p_OF), Sphere(_foot_radius(spec)),
                                            f"foot_{i}", props)
    return instance
