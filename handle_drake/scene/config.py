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

from pydrake.common.schema import Transform

__all__ = ["Hole", "SortingBoxConfig", "HOLE_SHAPES", "validate_scene", "scene_objects",
           "object_instance_name"]

#: The hole each catalogue kind passes through.
HOLE_SHAPES = {"sphere": "circle", "cylinder": "circle", "cuboid": "square",
               "rotated_cuboid": "square", "star_prism": "star"}


@dc.dataclass
class Hole:
    """One hole of the sorting box's lid, shaped for the catalogue object ``kind``
    of ``size`` (m; 0 takes the kind's default size) with ``clearance`` (m)
    all round its footprint."""

    kind: str = "cylinder"
    size: float = 0.0
    clearance: float = 0.012


@dc.dataclass
class SortingBoxConfig:
    """The toy-sorting box: a closed box welded to the world, its lid cut by
    one shaped hole per entry of ``holes`` (in a row along the box's x).

    ``X_WB`` places the centre of the box's bottom (``on_table``: its z is
    the table top); ``size`` is the outer ``[x, y, z]`` (m), ``wall`` the
    thickness of the walls, floor and lid (m). An object is *in the box* when
    its centre lies inside the walls, below the lid.
    """

    X_WB: Transform = dc.field(default_factory=Transform)
    on_table: bool = True
    size: list[float] = dc.field(default_factory=lambda: [0.50, 0.18, 0.14])
    wall: float = 0.012
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
    from handle_drake.scene.plant import footprint_radius, initial_pose, spec_of

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
    from handle_drake.scene.plant import box_footprint_contains

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
    from handle_drake.scene.plant import hole_polygon

    cell = box.size[0] / len(box.holes)
    for i, hole in enumerate(box.holes):
        if hole.kind not in HOLE_SHAPES:
            raise error(f"sorting_box.holes[{i}].kind: no hole shape for {hole.kind!r}; "
                        f"expected one of {sorted(HOLE_SHAPES)}")
        if hole.size != 0:
            _check_finite_positive(error, f"sorting_box.holes[{i}].size", hole.size)
        if not (math.isfinite(hole.clearance) and hole.clearance >= 0):
            raise error(f"sorting_box.holes[{i}].clearance must be finite and >= 0")
        polygon = hole_polygon(hole)
        half = (polygon.max(axis=0) - polygon.min(axis=0)) / 2
        if half[0] >= cell / 2 - box.wall or half[1] >= box.size[1] / 2 - box.wall:
            raise error(f"sorting_box.holes[{i}]: the {hole.kind} hole "
                        f"({2 * half[0]:.3f} x {2 * half[1]:.3f} m) does not fit its "
                        f"{cell:.3f} x {box.size[1]:.3f} m share of the lid; make the box "
                        f"larger or give fewer holes")
