"""The scene's further objects and the toy-sorting box in a plant.

The box's lid is cut by shaped holes. Each hole is a polygon star-shaped about
its centre (a circle as a 24-gon, a square, a five-pointed star, a footprint's convex
hull about the object's origin); the lid
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

from handle_drake.geometry.objects import (
    AddObject,
)
from handle_drake.scene.config import (
    box_pose,
    hole_cells,
    hole_polygon,
    initial_pose,
    object_instance_name,
    spec_of,
)
from handle_drake.systems.tactile import BodyPoseSelector

__all__ = ["AddSceneModels", "AddSortingBox", "ExportSceneObjects", "lid_pieces", "SORTING_BOX"]

SORTING_BOX = "sorting_box"
_BOX_COLOR = np.array([0.85, 0.25, 0.20, 1.0])


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
    for i, (hole, (centre, half)) in enumerate(zip(box.holes, hole_cells(box), strict=True)):
        for k, piece in enumerate(lid_pieces(hole_polygon(hole), half)):
            vertices = np.vstack([np.column_stack([piece, np.full(len(piece), z)])
                                  for z in (sz - w, sz)])
            vertices[:, :2] += centre
            add(f"lid_{i}_{k}", Convex(np.ascontiguousarray(vertices.T), f"lid_{i}_{k}"),
                RigidTransform())
    plant.WeldFrames(plant.world_frame(), body.body_frame(), box_pose(scenario))
    return instance


def AddSceneModels(plant, scenario) -> None:
    """Adds ``scenario.objects`` (instances ``object_1``...) and the sorting box."""

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
