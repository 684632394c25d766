"""The scene's further objects and the toy-sorting box in a plant.

The box's lid is cut by shaped holes. Each hole is a polygon star-shaped about
its centre (a circle as a 24-gon, a square, a five-pointed star); the lid
around it is tiled by convex prisms, one per polygon edge: the part of the
hole's cell between the edge and the cell's border inside the wedge the edge
spans from the hole's centre (the intersection of the wedge, the cell and the
half-plane beyond the edge, each convex, so the prism is convex and Drake's
``Convex`` is exact). Walls and floor are boxes.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.geometry import Box, Convex, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import SpatialInertia

__all__ = ["AddSceneModels", "ExportSceneObjects", "spec_of", "initial_pose",
           "footprint_radius", "hole_polygon", "lid_pieces", "box_pose", "hole_centres",
           "in_box", "box_footprint_contains", "SORTING_BOX"]

SORTING_BOX = "sorting_box"
_BOX_COLOR = np.array([0.85, 0.25, 0.20, 1.0])
_CIRCLE_SIDES = 24


def spec_of(o):
    """The object spec of one ``ObjectConfig``."""
    if o.kind == "mesh":
        from handle_drake.scenario import mesh_object_spec

        return mesh_object_spec(o)
    from handle_drake.objects import ObjectSpec

    return ObjectSpec(kind=o.kind, size=o.size, mass=o.mass, mu=o.mu,
                      dimensions=o.dimensions or None, density=o.density)


def initial_pose(o, table) -> RigidTransform:
    """``X_WO`` at the start (``on_table`` puts the object on the table top)."""
    X_WO = o.X_WO.GetDeterministicValue()
    if o.on_table:
        from handle_drake.objects import resting_height

        top = table.top_height if table is not None else 0.0
        p = X_WO.translation().copy()
        p[2] = top + resting_height(spec_of(o))
        X_WO = RigidTransform(X_WO.rotation(), p)
    return X_WO


def footprint_radius(spec) -> float:
    """Radius (m) of the smallest circle about the object's axis holding its footprint."""
    from handle_drake.objects import surface_mesh

    vertices = np.asarray(surface_mesh(spec).vertices)
    return float(np.max(np.linalg.norm(vertices[:, :2], axis=1)))


def hole_polygon(hole) -> np.ndarray:
    """The hole's outline (n, 2), counter-clockwise about its centre (m, lid frame)."""
    from handle_drake.objects import DEFAULT_SIZE, ObjectSpec, dimensions
    from handle_drake.scene.config import HOLE_SHAPES

    size = hole.size or DEFAULT_SIZE[hole.kind]
    d = dimensions(ObjectSpec(kind=hole.kind, size=size))
    c = hole.clearance
    shape = HOLE_SHAPES[hole.kind]
    if shape == "circle":
        # Circumscribed about the circle of the object's diameter plus the clearance.
        r = (d["diameter"] / 2 + c) / math.cos(math.pi / _CIRCLE_SIDES)
        a = 2 * math.pi * (np.arange(_CIRCLE_SIDES) + 0.5) / _CIRCLE_SIDES
        return r * np.column_stack([np.cos(a), np.sin(a)])
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


def _ray_to_rectangle(direction, half) -> np.ndarray:
    """Where the ray from the origin along ``direction`` leaves the rectangle ``|x|<=half``."""
    with np.errstate(divide="ignore"):
        t = np.min(np.where(np.abs(direction) > 1e-12, half / np.abs(direction), np.inf))
    return direction * t


def lid_pieces(polygon: np.ndarray, half: np.ndarray) -> list[np.ndarray]:
    """Convex 2-D pieces tiling the rectangle ``|x| <= half`` minus the hole
    ``polygon`` (star-shaped about the origin): one per polygon edge."""
    corners = np.array([[sx * half[0], sy * half[1]] for sx, sy in
                        ((1, 1), (-1, 1), (-1, -1), (1, -1))])
    corner_angles = np.arctan2(corners[:, 1], corners[:, 0])
    out = []
    n = len(polygon)
    for k in range(n):
        a, b = polygon[k], polygon[(k + 1) % n]
        points = [a, b, _ray_to_rectangle(a, half), _ray_to_rectangle(b, half)]
        start = math.atan2(a[1], a[0])
        span = (math.atan2(b[1], b[0]) - start) % (2 * math.pi)
        for corner, angle in zip(corners, corner_angles, strict=True):
            if 0 < (angle - start) % (2 * math.pi) < span:
                points.append(corner)
        out.append(np.array(points))
    return out


def box_pose(scenario) -> RigidTransform:
    """``X_WB`` of the box's bottom centre (``on_table``: on the table top)."""
    box = scenario.sorting_box
    X = box.X_WB.GetDeterministicValue()
    if box.on_table:
        p = X.translation().copy()
        p[2] = scenario.table.top_height if scenario.table is not None else 0.0
        X = RigidTransform(X.rotation(), p)
    return X


def hole_centres(scenario) -> dict[str, np.ndarray]:
    """World position of each hole's centre on top of the lid, by hole kind."""
    box = scenario.sorting_box
    X_WB = box_pose(scenario)
    cell = box.size[0] / len(box.holes)
    out = {}
    for i, hole in enumerate(box.holes):
        x = -box.size[0] / 2 + cell * (i + 0.5)
        out.setdefault(hole.kind, X_WB @ np.array([x, 0.0, box.size[2]]))
    return out


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


def _proximity(mu: float) -> ProximityProperties:
    from pydrake.geometry import AddContactMaterial

    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    return props


def AddSortingBox(plant, scenario):
    """The sorting box, welded to the world (before Finalize); returns its instance."""
    box = scenario.sorting_box
    sx, sy, sz = box.size
    w = box.wall
    instance = plant.AddModelInstance(SORTING_BOX)
    body = plant.AddRigidBody("box", instance, SpatialInertia.SolidBoxWithMass(1.0, sx, sy, sz))
    props = _proximity(box.mu)

    def add(name, shape, X):
        plant.RegisterCollisionGeometry(body, X, shape, f"{name}_collision", props)
        plant.RegisterVisualGeometry(body, X, shape, f"{name}_visual", _BOX_COLOR)

    add("floor", Box(sx, sy, w), RigidTransform([0, 0, w / 2]))
    inner_h = sz - 2 * w
    for sign in (-1, 1):
        add(f"wall_x{sign:+d}", Box(w, sy, inner_h), RigidTransform([sign * (sx - w) / 2, 0,
                                                                      w + inner_h / 2]))
        add(f"wall_y{sign:+d}", Box(sx - 2 * w, w, inner_h),
            RigidTransform([0, sign * (sy - w) / 2, w + inner_h / 2]))
    cell = sx / len(box.holes)
    half = np.array([cell / 2, sy / 2])
    for i, hole in enumerate(box.holes):
        x = -sx / 2 + cell * (i + 0.5)
        for k, piece in enumerate(lid_pieces(hole_polygon(hole), half)):
            vertices = np.vstack([np.column_stack([piece, np.full(len(piece), z)])
                                  for z in (sz - w, sz)])
            vertices[:, 0] += x
            add(f"lid_{i}_{k}", Convex(np.ascontiguousarray(vertices.T), f"lid_{i}_{k}"),
                RigidTransform())
    plant.WeldFrames(plant.world_frame(), body.body_frame(), box_pose(scenario))
    return instance


def AddSceneModels(plant, scenario) -> None:
    """Adds ``scenario.objects`` (instances ``object_1``...) and the sorting box."""
    from handle_drake.objects import AddObject
    from handle_drake.scene.config import object_instance_name

    hydroelastic = scenario.plant_config.contact_model != "point"
    for i, o in enumerate(scenario.objects):
        name = object_instance_name(i + 1)
        instance = AddObject(plant, spec_of(o), name=name, hydroelastic=hydroelastic)
        body = plant.get_body(plant.GetBodyIndices(instance)[0])
        if o.fixed:
            plant.WeldFrames(plant.world_frame(), body.body_frame(),
                             initial_pose(o, scenario.table))
        else:
            plant.SetDefaultFloatingBaseBodyPose(body, initial_pose(o, scenario.table))
    if scenario.sorting_box is not None:
        AddSortingBox(plant, scenario)


def ExportSceneObjects(builder, plant, scenario) -> None:
    """Exports ``object_<i>.pose`` / ``.spatial_velocity`` / ``.position`` of the
    further objects (as ``object.*`` for the first)."""
    from handle_drake.scene.config import object_instance_name
    from handle_drake.systems.sensors import BodyPoseSelector

    for i in range(len(scenario.objects)):
        name = object_instance_name(i + 1)
        instance = plant.GetModelInstanceByName(name)
        body = plant.get_body(plant.GetBodyIndices(instance)[0])
        selector = builder.AddNamedSystem(f"{name}_pose", BodyPoseSelector(body))
        builder.Connect(plant.get_body_poses_output_port(), selector.GetInputPort("body_poses"))
        builder.Connect(plant.get_body_spatial_velocities_output_port(),
                        selector.GetInputPort("body_spatial_velocities"))
        for signal in ("pose", "spatial_velocity", "position"):
            builder.ExportOutput(selector.GetOutputPort(signal), f"{name}.{signal}")
