"""The pick's outcome judged from the plant's final state, by code separate from the
application's verdict (``execute._judge`` and ``scene.config.in_box``, which look at the
object's centre only): every collision point of the object inside the box's cavity, and
the object at rest on the box's floor (issue 49, item 8).

Collision points: the corners of each box-shaped collision geometry, the six
extreme points of each sphere (the cuboid's corner feet and the ball), 32 points on each
rim of a cylinder and the hull vertices of a convex piece (a mug's, a wine glass's, a
star prism's, a mesh's), in the world,
from the plant's body pose and SceneGraph's geometry poses. The cavity: the sorting
box body's frame as the plant has it, inside the walls, above the floor and below the
lid, by the box's specification (outer size, wall thickness). At rest: not falling
(vertical speed below ``REST_SPEED``), its lowest point on the floor (within
``FLOOR_GAP``), and not thrown about (speed below ``MAX_ROLL``): a ball may still roll
on the floor (the point contact has no rolling resistance: a ball let go over its hole
rolled on at 2 cm/s, 1 rad/s, after the run's 1.2 s settle).
"""

from __future__ import annotations

import dataclasses as dc
import itertools
import math

import numpy as np
from pydrake.geometry import Box, Convex, Cylinder, Role, Sphere

from handle_drake.station import GetPlant, MakeHandStation

#: At rest: vertical speed (m/s), the lowest point's height above the floor (m), speed.
REST_SPEED = 0.01
FLOOR_GAP = 0.003
MAX_ROLL = 0.1
#: How far (m) a point may be inside the floor or a wall: the contact's compliance (a ball
#: resting on the floor sinks 0.08 mm into it; a cylinder lying on it and a mesh prism on a
#: face, at rest, 1.1-1.7 mm: point contact at Drake's default penetration allowance).
PENETRATION = 0.002


class FinalState:
    """An ``execute_pick`` monitor that keeps the plant's last state (positions and
    velocities) and time."""

    def __init__(self):
        self.x = None
        self.t = None

    def __call__(self, station, station_context):
        plant = GetPlant(station)
        context = station.GetSubsystemContext(plant, station_context)
        self.x = plant.GetPositionsAndVelocities(context).copy()
        self.t = station_context.get_time()


class TiltAtTheLid(FinalState):
    """:class:`FinalState` and the object's tilt from upright (deg, the body axis nearest the
    vertical) as its centre first comes down through ``z`` (m) after having been above
    ``z`` + 1 cm (a cube wedges across its hole from a tilt; issue 49, item 3)."""

    def __init__(self, instance: str, z: float):
        super().__init__()
        self.instance, self.z, self.above, self.tilt = instance, z, False, None

    def __call__(self, station, station_context):
        super().__call__(station, station_context)
        plant = GetPlant(station)
        context = station.GetSubsystemContext(plant, station_context)
        (index,) = plant.GetBodyIndices(plant.GetModelInstanceByName(self.instance))
        X_WO = plant.get_body(index).EvalPoseInWorld(context)
        z = X_WO.translation()[2]
        if z > self.z + 0.01:
            self.above = True
        elif self.above and self.tilt is None and z < self.z:
            up = float(np.max(np.abs(X_WO.rotation().matrix()[2, :])))
            self.tilt = math.degrees(math.acos(min(1.0, up)))


def _points(shape, X_WG, R_WB) -> np.ndarray:
    """World points of a collision shape: a box's corners; a sphere's extreme points
    along the sorting box's axes ``R_WB`` (its centre +- radius: what decides whether
    it fits in the box-aligned cavity and how high its lowest point is)."""
    if isinstance(shape, Box):
        half = np.array([shape.width(), shape.depth(), shape.height()]) / 2
        local = np.array([s * half for s in itertools.product((-1, 1), repeat=3)])
        return np.array([X_WG @ p for p in local])
    if isinstance(shape, Sphere):
        r = shape.radius()
        axes = R_WB.matrix().T  # rows: the box's axes in the world
        return X_WG.translation() + np.vstack([r * axes, -r * axes])
    if isinstance(shape, Cylinder):  # its two rims, 32 points each
        a = 2 * np.pi * np.arange(32) / 32
        r, half = shape.radius(), shape.length() / 2
        local = np.vstack([np.column_stack([r * np.cos(a), r * np.sin(a), np.full(32, z)])
                           for z in (-half, half)])
        return np.array([X_WG @ p for p in local])
    if isinstance(shape, Convex):  # its hull's vertices
        hull = shape.GetConvexHull()
        local = np.array([hull.vertex(i) for i in range(hull.num_vertices())])
        return np.array([X_WG @ p for p in local])
    raise NotImplementedError(f"collision points of a {type(shape).__name__}")


def judge_in_box(scenario, instance: str, x) -> dict:
    """``{"in_cavity", "at_rest", "points", "outside", "speed", "spin"}``: the object
    ``instance`` of ``scenario``'s station at state ``x`` (the plant's positions and
    velocities)."""
    station = MakeHandStation(dc.replace(scenario, cameras=[]))
    plant = GetPlant(station)
    context = station.CreateDefaultContext()
    plant_context = station.GetSubsystemContext(plant, context)
    plant.SetPositionsAndVelocities(plant_context, np.asarray(x))
    inspector = station.GetOutputPort("query_object").Eval(context).inspector()
    (index,) = plant.GetBodyIndices(plant.GetModelInstanceByName(instance))
    body = plant.get_body(index)
    X_WO = plant.EvalBodyPoseInWorld(plant_context, body)
    box = scenario.sorting_box
    box_body = plant.GetBodyByName("box", plant.GetModelInstanceByName("sorting_box"))
    X_WB = plant.EvalBodyPoseInWorld(plant_context, box_body)
    points = []
    for g in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(index), Role.kProximity):
        points.append(_points(inspector.GetShape(g), X_WO @ inspector.GetPoseInFrame(g),
                              X_WB.rotation()))
    points = np.vstack(points)
    p_B = np.array([X_WB.inverse() @ p for p in points])
    inner = np.array(box.size[:2]) / 2 - box.wall + PENETRATION
    inside = (np.all(np.abs(p_B[:, :2]) < inner, axis=1)
              & (p_B[:, 2] > box.wall - PENETRATION)
              & (p_B[:, 2] < box.size[2] - box.wall + PENETRATION))
    V = plant.EvalBodySpatialVelocityInWorld(plant_context, body)
    speed, spin = float(np.linalg.norm(V.translational())), float(np.linalg.norm(
        V.rotational()))
    lowest = float(p_B[:, 2].min() - box.wall)
    at_rest = (abs(V.translational()[2]) < REST_SPEED and lowest < FLOOR_GAP
               and speed < MAX_ROLL)
    return {"in_cavity": bool(inside.all()), "at_rest": bool(at_rest), "points": len(points),
            "outside": int((~inside).sum()), "speed": speed, "spin": spin,
            "above_floor": lowest}
