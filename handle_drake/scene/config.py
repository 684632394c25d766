"""Several objects per scenario, and the toy-sorting box.

``object:`` stays the scenario's first object (model instance ``object``,
ports ``object.*``): every command that takes one object acts on it.
``objects:`` lists further objects, each with the same fields
(:class:`~handle_drake.scenario.ObjectConfig`); they are the model instances
``object_1``, ``object_2``, ... with ports ``object_1.pose``, ... A scenario may
also give ``object: null`` and put every object in ``objects:``.

.. code-block:: yaml

    object: {kind: cylinder, size: 0.05, X_WO: {translation: [0.0, 0.10, 0]}}
    objects:
      - {kind: cuboid, size: 0.06, X_WO: {translation: [0.1, -0.1, 0]}}
      - {kind: star_prism, size: 0.08, X_WO: {translation: [-0.05, -0.15, 0]}}
    sorting_box:
      X_WB: {translation: [0.05, 0.30, 0], rotation: !Rpy {deg: [0, 0, 0]}}
      holes: [{kind: cylinder, size: 0.05}, {kind: cuboid, size: 0.06},
              {kind: star_prism, size: 0.08}, {kind: sphere, size: 0.06}]

This module must not use ``from __future__ import annotations`` (Drake's
``yaml_load_typed`` reads the field types).
"""

import dataclasses as dc
import math

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform
from scipy.spatial import ConvexHull

from handle_drake.geometry.objects import (
    DEFAULT_SIZE,
    ROTATED_CUBOID_YAW,
    ObjectSpec,
    dimensions,
    resting_height,
    surface_mesh,
)
from handle_drake.geometry.objects.mesh import MeshObjectSpec

__all__ = ["Hole", "SortingBoxConfig", "HOLE_SHAPES", "validate_scene", "scene_objects",
           "object_instance_name", "spec_of", "initial_pose", "footprint_radius", "hole_polygon",
           "box_pose", "hole_centres", "in_box", "box_footprint_contains", "hole_cells",
           "hole_spec", "HOLE_CLEARANCE", "release_yaws", "footprint_symmetry"]

_CIRCLE_SIDES = 24

#: The hole each catalogue kind passes through, standing upright as it stood on the table:
#: a circle about its round outline (a sphere's, an upright cylinder's, a wine glass's bowl,
#: the widest part, foot down), a square a cuboid's footprint fits at every quarter turn, the
#: star prism's star, the circle about a mug's cup through its handle's end (it passes at
#: any yaw: a hole of the cup and handle's outline takes it at one yaw only, which the arm
#: often cannot turn it to), and the convex hull of a user's mesh's footprint (as it stands
#: in its file; it passes at the turns that map the hull onto itself).
HOLE_SHAPES = {"sphere": "circle", "cylinder": "circle", "cuboid": "square",
               "rotated_cuboid": "square", "star_prism": "star", "wine_glass": "circle",
               "mug": "round_footprint", "mesh": "footprint"}
#: The default clearance (m) of a hole all round its object's outline (``Hole.clearance``):
#: 12 mm, the toy's, so that an object let go a few mm and degrees off still drops through.
HOLE_CLEARANCE = 0.012


@dc.dataclass
class Hole:
    """One hole of the sorting box's lid, shaped for the catalogue object ``kind``
    of ``size`` (m; 0 takes the kind's default size) with ``clearance`` (m)
    all round its footprint. ``kind: mesh`` is a user's mesh: ``file`` (relative
    paths from the scenario file's folder) and ``scale`` as an object's; its hole is
    its convex footprint."""

    kind: str = "cylinder"
    size: float = 0.0
    clearance: float = HOLE_CLEARANCE
    file: str = ""
    scale: float = 1.0


@dc.dataclass
class SortingBoxConfig:
    """The toy-sorting box: a closed box welded to the world, its lid cut by
    one shaped hole per entry of ``holes`` (in a row along the box's x).

    ``X_WB`` places the centre of the box's bottom (``on_table``: its z is
    the table top); ``rows`` > 1 lays the holes out in that many rows (a
    shape sorter of eight holes); ``size`` is the outer ``[x, y, z]`` (m), ``wall`` the
    thickness of the walls, floor and lid (m). An object is *in the box* when
    its centre lies inside the walls, below the lid.
    """

    X_WB: Transform = dc.field(default_factory=Transform)
    on_table: bool = True
    size: list[float] = dc.field(default_factory=lambda: [0.50, 0.18, 0.14])
    wall: float = 0.012
    #: Rows of holes along the box's y (the holes fill the rows in turn, row 0 at -y).
    rows: int = 1
    holes: list[Hole] = dc.field(default_factory=lambda: [
        Hole("cylinder", 0.05), Hole("cuboid", 0.06), Hole("star_prism", 0.08),
        Hole("sphere", 0.06)])
    mu: float = 0.6


def object_instance_name(index: int) -> str:
    """Model instance of scene object ``index`` (0: ``object``, then ``object_1``...)."""
    return "object" if index == 0 else f"object_{index}"


def scene_objects(scenario) -> list:
    """Every object of ``scenario`` as ``(instance name, ObjectConfig)``, the
    scenario's ``object`` first."""
    out = []
    if scenario.object is not None:
        out.append(("object", scenario.object))
    for i, o in enumerate(scenario.objects):
        out.append((f"object_{i + 1}", o))
    return out


def _check_finite_positive(error, name, value):
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise error(f"{name} must be a finite number > 0, got {value!r}")


def validate_scene(scenario, validate_single, error) -> None:
    """Checks ``objects`` (each as ``object`` is checked, by ``validate_single``
    on a copy of the scenario holding that object alone), that no two objects
    overlap at the start, and the sorting box. Raises ``error(message)``."""
    for i, o in enumerate(scenario.objects):
        single = dc.replace(scenario, object=o, objects=[], sorting_box=None, metric=None,
                            cameras=[])
        try:
            validate_single(single)
        except error as e:
            text = str(e)
            raise error(f"objects[{i}]{text[len('object'):]}" if text.startswith("object")
                        else f"objects[{i}]: {text}") from None
    _check_overlaps(scenario, error)
    if scenario.sorting_box is not None:
        _validate_box(scenario, error)


def _footprints(scenario):
    """(name, centre xy, radius) of the bounding circle of each object standing on the
    table (an object placed in the air, ``on_table: false``, is the user's to place)."""

    out = []
    for name, o in scene_objects(scenario):
        if not o.on_table:
            continue
        X = initial_pose(o, scenario.table)
        out.append((name, X.translation()[:2], footprint_radius(spec_of(o))))
    return out


def _check_overlaps(scenario, error) -> None:
    prints = _footprints(scenario)
    for a in range(len(prints)):
        for b in range(a + 1, len(prints)):
            (na, pa, ra), (nb, pb, rb) = prints[a], prints[b]
            gap = float(math.dist(pa, pb)) - ra - rb
            if gap < -0.25 * min(ra, rb):  # bounding circles overlap deep: shapes do
                raise error(f"{nb}: starts inside {na} (bounding circles {ra:.3f} and "
                            f"{rb:.3f} m, centres {math.dist(pa, pb):.3f} m apart); move it")
    box = scenario.sorting_box
    if box is None:
        return

    for name, p, r in prints:
        if box_footprint_contains(scenario, p, margin=r):
            raise error(f"{name}: starts on or in the sorting box at {p.round(3).tolist()}; "
                        f"move it or the box")


def _validate_box(scenario, error) -> None:
    box = scenario.sorting_box
    if len(box.size) != 3:
        raise error(f"sorting_box.size: expected 3 values [x y z] (m), got {box.size}")
    for i, v in enumerate(box.size):
        _check_finite_positive(error, f"sorting_box.size[{i}]", v)
    _check_finite_positive(error, "sorting_box.wall", box.wall)
    if 3 * box.wall >= min(box.size):
        raise error(f"sorting_box.wall: {box.wall} m leaves no room inside a box of "
                    f"{box.size} m")
    if not (math.isfinite(box.mu) and box.mu >= 0):
        raise error(f"sorting_box.mu must be finite and >= 0, got {box.mu!r}")
    if not box.X_WB.IsDeterministic():
        raise error("sorting_box.X_WB: expected a deterministic pose, got a random one")
    if not box.holes:
        raise error("sorting_box.holes: expected at least one hole")

    if isinstance(box.rows, bool) or not isinstance(box.rows, int) or not \
            1 <= box.rows <= len(box.holes):
        raise error(f"sorting_box.rows: expected an integer from 1 to the number of holes "
                    f"({len(box.holes)}), got {box.rows!r}")
    cells = hole_cells(box)
    for i, hole in enumerate(box.holes):
        if hole.kind not in HOLE_SHAPES:
            raise error(f"sorting_box.holes[{i}].kind: no hole shape for {hole.kind!r}; "
                        f"expected one of {sorted(HOLE_SHAPES)}")
        if hole.size != 0:
            _check_finite_positive(error, f"sorting_box.holes[{i}].size", hole.size)
        if not (math.isfinite(hole.clearance) and hole.clearance >= 0):
            raise error(f"sorting_box.holes[{i}].clearance must be finite and >= 0")
        if hole.kind == "mesh" and not hole.file:
            raise error(f"sorting_box.holes[{i}].file: a mesh hole needs the mesh's file")
        if hole.kind != "mesh" and hole.file:
            raise error(f"sorting_box.holes[{i}].file: only a mesh hole takes a file "
                        f"(kind {hole.kind!r})")
        polygon = hole_polygon(hole)
        reach = np.max(np.abs(polygon), axis=0)  # about the hole's centre
        _, half_cell = cells[i]
        # At least half a wall of lid between the hole and its share's border.
        if reach[0] >= half_cell[0] - box.wall / 2 or reach[1] >= half_cell[1] - box.wall / 2:
            raise error(f"sorting_box.holes[{i}]: the {hole.kind} hole "
                        f"({2 * reach[0]:.3f} x {2 * reach[1]:.3f} m about its centre) does "
                        f"not fit its {2 * half_cell[0]:.3f} x {2 * half_cell[1]:.3f} m share "
                        f"of the lid; make the box larger, give more rows or fewer holes")


def spec_of(o):
    """The object spec of one ``ObjectConfig``."""
    if o.kind == "mesh":
        return MeshObjectSpec(file=o.file, scale=o.scale, mass=o.mass, density=o.density,
                              mu=o.mu)
    return ObjectSpec(kind=o.kind, size=o.size, mass=o.mass, mu=o.mu,
                      dimensions=o.dimensions or None, density=o.density)


def initial_pose(o, table) -> RigidTransform:
    """``X_WO`` at the start (``on_table`` puts the object on the table top)."""
    X_WO = o.X_WO.GetDeterministicValue()
    if o.on_table:

        top = table.top_height if table is not None else 0.0
        p = X_WO.translation().copy()
        p[2] = top + resting_height(spec_of(o))
        X_WO = RigidTransform(X_WO.rotation(), p)
    return X_WO


def footprint_radius(spec) -> float:
    """Radius (m) of the smallest circle about the object's axis holding its footprint."""

    vertices = np.asarray(surface_mesh(spec).vertices)
    return float(np.max(np.linalg.norm(vertices[:, :2], axis=1)))


def hole_spec(hole):
    """The object spec a hole is cut for (its kind at its size, or the default size; a
    mesh hole's mesh)."""
    if hole.kind == "mesh":
        return MeshObjectSpec(file=hole.file, scale=hole.scale)
    return ObjectSpec(kind=hole.kind, size=hole.size or DEFAULT_SIZE[hole.kind])


def _footprint_polygon(spec, clearance: float) -> np.ndarray:
    """The convex hull of the object's footprint (its surface's vertices seen from above,
    in O), grown by ``clearance`` (m): each hull vertex moved out along the bisector of its
    edges' normals by ``clearance / cos(half the turn)``, so every edge moves out by
    ``clearance``. Counter-clockwise (scipy's ``ConvexHull`` order in 2-D)."""
    xy = np.asarray(surface_mesh(spec).vertices)[:, :2]
    corners = xy[ConvexHull(xy).vertices]
    prev, nxt = np.roll(corners, 1, axis=0), np.roll(corners, -1, axis=0)

    def outward(a, b):  # the right-hand normal of a counter-clockwise edge a -> b
        e = b - a
        n = np.column_stack([e[:, 1], -e[:, 0]])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    n1, n2 = outward(prev, corners), outward(corners, nxt)
    bisector = n1 + n2
    bisector /= np.linalg.norm(bisector, axis=1, keepdims=True)
    cos_half = np.einsum("ij,ij->i", bisector, n1)
    return corners + bisector * (clearance / cos_half)[:, None]


def _circle(radius: float) -> np.ndarray:
    """A polygon circumscribed about the circle of ``radius`` (m)."""
    r = radius / math.cos(math.pi / _CIRCLE_SIDES)
    a = 2 * math.pi * (np.arange(_CIRCLE_SIDES) + 0.5) / _CIRCLE_SIDES
    return r * np.column_stack([np.cos(a), np.sin(a)])


def hole_polygon(hole) -> np.ndarray:
    """The hole's outline (n, 2), counter-clockwise about its centre (m, lid frame; an
    object passes it standing upright at the yaws :func:`release_yaws` gives)."""

    spec = hole_spec(hole)
    c = hole.clearance
    shape = HOLE_SHAPES[hole.kind]
    if shape == "footprint":
        return _footprint_polygon(spec, c)
    if shape == "round_footprint":
        reach = float(np.max(np.linalg.norm(np.asarray(surface_mesh(spec).vertices)[:, :2],
                                            axis=1)))
        return _circle(reach + c)
    d = dimensions(spec)
    if shape == "circle":
        return _circle(d["diameter"] / 2 + c)
    if shape == "square":
        # The toy's square hole: the cuboid's footprint (width x depth) fits at every
        # quarter turn.
        h = max(d["width"], d["depth"]) / 2 + c
        return np.array([[h, -h], [h, h], [-h, h], [-h, -h]])
    # A star: the prism's outline grown by the clearance along each vertex's ray.
    r_out, r_in = d["diameter"] / 2 + c, d["inner_diameter"] / 2 + c
    angles = math.pi * np.arange(10) / 5
    radii = np.where(np.arange(10) % 2 == 0, r_out, r_in)
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


def box_pose(scenario) -> RigidTransform:
    """``X_WB`` of the box's bottom centre (``on_table``: on the table top)."""
    box = scenario.sorting_box
    X = box.X_WB.GetDeterministicValue()
    if box.on_table:
        p = X.translation().copy()
        p[2] = scenario.table.top_height if scenario.table is not None else 0.0
        X = RigidTransform(X.rotation(), p)
    return X


def hole_cells(box) -> list:
    """``(centre (2,), half size (2,))`` in the box frame (m) of each hole's share of the
    lid: ``rows`` rows along y, the holes filling them in turn (as many per row as the
    first row takes)."""
    rows = box.rows if isinstance(box.rows, int) and box.rows >= 1 else 1
    per_row = -(-len(box.holes) // rows)
    sx, sy = box.size[0], box.size[1]
    half = np.array([sx / per_row / 2, sy / rows / 2])
    out = []
    for i in range(len(box.holes)):
        row, col = divmod(i, per_row)
        out.append((np.array([-sx / 2 + (2 * col + 1) * half[0],
                              -sy / 2 + (2 * row + 1) * half[1]]), half))
    return out


def hole_centres(scenario) -> dict[str, np.ndarray]:
    """World position of each hole's centre on top of the lid, by hole kind."""
    box = scenario.sorting_box
    X_WB = box_pose(scenario)
    out = {}
    for hole, (centre, _) in zip(box.holes, hole_cells(box), strict=True):
        out.setdefault(hole.kind, X_WB @ np.array([centre[0], centre[1], box.size[2]]))
    return out


#: Turns (rad) about the vertical that map a kind's hole onto itself: its object passes
#: at any of them from the yaw its hole is cut at. None: at any yaw (round). A mesh's:
#: those of its footprint's hull (:func:`footprint_symmetry`).
_HOLE_SYMMETRY = {"cuboid": 4, "rotated_cuboid": 4, "star_prism": 5}


def footprint_symmetry(spec, tolerance: float = 0.001, most: int = 12) -> int:
    """The largest n <= ``most`` such that the convex hull of ``spec``'s footprint
    (:func:`hole_polygon`'s, no clearance) turned by 2 pi / n about O's vertical lies
    within ``tolerance`` (m) of itself (each turned vertex that near the hull's
    outline); 1 if none."""
    polygon = _footprint_polygon(spec, 0.0)
    edges = np.roll(polygon, -1, axis=0) - polygon
    normal = np.column_stack([edges[:, 1], -edges[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = np.einsum("ij,ij->i", normal, polygon)
    for n in range(most, 1, -1):
        a = 2 * math.pi / n
        turned = polygon @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        # Each turned vertex on the hull's outline: inside every edge's line, on one.
        signed = turned @ normal.T - offset
        if np.all(signed.max(axis=1) < tolerance) and np.all(
                np.abs(signed).min(axis=1) < tolerance):
            return n
    return 1


def release_yaws(scenario, kind: str) -> list[float] | None:
    """The object yaws (rad, world, about the vertical) at which a ``kind`` standing
    upright passes its hole: the box's yaw (the hole is cut in the box frame as the
    object's footprint in its own frame; a rotated cuboid's box is turned by
    ``ROTATED_CUBOID_YAW`` in O) plus each turn of the hole's symmetry; None for a
    round object (any yaw)."""
    if kind == "mesh":
        hole = next(h for h in scenario.sorting_box.holes if h.kind == "mesh")
        n = footprint_symmetry(hole_spec(hole))
    elif kind in _HOLE_SYMMETRY:
        n = _HOLE_SYMMETRY[kind]
    else:
        return None

    m = box_pose(scenario).rotation().matrix()
    yaw = math.atan2(m[1, 0], m[0, 0]) - (ROTATED_CUBOID_YAW if kind == "rotated_cuboid"
                                          else 0.0)
    return [yaw + 2 * math.pi * k / n for k in range(n)]


def in_box(scenario, p_WO) -> bool:
    """Whether the point ``p_WO`` (an object's centre) lies inside the box:
    within the walls, above the floor, below the lid."""
    box = scenario.sorting_box
    p_B = box_pose(scenario).inverse() @ np.asarray(p_WO, dtype=float)
    inner = np.array(box.size[:2]) / 2 - box.wall
    return bool(np.all(np.abs(p_B[:2]) < inner) and box.wall < p_B[2] < box.size[2] - box.wall)


def box_footprint_contains(scenario, p_xy, margin: float = 0.0) -> bool:
    """Whether the point ``p_xy`` (world) is within ``margin`` of the box's footprint."""
    box = scenario.sorting_box
    p = box_pose(scenario).inverse() @ np.array([p_xy[0], p_xy[1], 0.0])
    return bool(np.all(np.abs(p[:2]) < np.array(box.size[:2]) / 2 + margin))
