"""Adding catalogue objects and the table to a ``MultibodyPlant`` (built in code, no files)."""

from __future__ import annotations

import math

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    ProximityProperties,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia

from handle_drake.geometry.objects.catalogue import (
    _TABLE_COLOR,
    BODY_NAME,
    ROTATED_CUBOID_YAW,
    ObjectSpec,
    _check_positive,
    _mesh_module,
    dimensions,
    resting_height,
)
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS
from handle_drake.geometry.objects.pieces import Piece, pieces, spatial_inertia


def _object_proximity(spec: ObjectSpec, piece: Piece, hydroelastic: bool) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(spec.mu, spec.mu), properties=props)
    if hydroelastic:
        hint = spec.resolution_hint or piece.round_resolution_hint()
        AddCompliantHydroelasticProperties(hint, spec.hydroelastic_modulus, props)
    return props


def AddObject(plant, spec: ObjectSpec, name: str = "object", hydroelastic: bool = False):
    """Adds ``spec`` as a free rigid body to ``plant`` (before Finalize).

    The model instance is called ``name``; its body ``BODY_NAME`` has the
    object frame O as body frame. Every piece gets collision geometry
    (Coulomb friction ``mu``; compliant hydroelastic properties when
    ``hydroelastic`` is True, else point contact only) and visual geometry.
    Returns the ``ModelInstanceIndex``.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.AddMeshObject(plant, spec, name, hydroelastic)
    if not isinstance(spec, ObjectSpec):
        raise TypeError(f"spec must be an ObjectSpec, got {type(spec).__name__}")
    if plant.is_finalized():
        raise ValueError("AddObject must be called before plant.Finalize()")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty str, got {name!r}")
    instance: ModelInstanceIndex = plant.AddModelInstance(name)
    rgba = np.array(spec.rgba)
    body = plant.AddRigidBody(BODY_NAME, instance, spatial_inertia(spec))
    for piece in pieces(spec):
        shape = piece.drake_shape()
        plant.RegisterCollisionGeometry(
            body,
            piece.X_OP,
            shape,
            f"{piece.name}_collision",
            _object_proximity(spec, piece, hydroelastic),
        )
        plant.RegisterVisualGeometry(body, piece.X_OP, shape, f"{piece.name}_visual", rgba)
    if not hydroelastic:
        props = ProximityProperties()
        AddContactMaterial(friction=CoulombFriction(spec.mu, spec.mu), properties=props)
        for i, p_OF in enumerate(contact_feet(spec)):
            plant.RegisterCollisionGeometry(
                body, RigidTransform(p_OF), Sphere(_foot_radius(spec)), f"foot_{i}", props
            )
    return instance


def _foot_radius(spec: ObjectSpec) -> float:
    return 0.01 * spec.size


def contact_feet(spec: ObjectSpec) -> np.ndarray:
    """Centres (k, 3) in O of the small collision spheres added under flat bottoms.

    Drake's point contact yields one contact point per pair of geometries, so a
    box or a cylinder standing on the table box rocks on a single point forever.
    Under point contact, :func:`AddObject` therefore adds collision-only spheres
    of radius ``0.01 * size`` inside the bottom rim (4 corners of a cuboid, 8
    points on the rim of a cylinder or a wine-glass foot) whose lowest points lie
    on the bottom face; a star prism gets one near each tip. They have no mass
    and do not change the shape. The mug (16 wall pieces on the table) and the
    sphere get none.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.contact_feet(spec)
    r = _foot_radius(spec)
    d = dimensions(spec)
    z = -resting_height(spec) + r
    if spec.kind in ("cuboid", "rotated_cuboid"):
        hx, hy = d["width"] / 2 - r, d["depth"] / 2 - r
        local = np.array([[sx * hx, sy * hy, z] for sx in (-1, 1) for sy in (-1, 1)])
        yaw = ROTATED_CUBOID_YAW if spec.kind == "rotated_cuboid" else 0.0
        return local @ RotationMatrix.MakeZRotation(yaw).matrix().T
    if spec.kind in ("cylinder", "wine_glass"):
        radius = (d["diameter"] if spec.kind == "cylinder" else d["foot_diameter"]) / 2 - r
        angles = 2 * math.pi * np.arange(8) / 8
        return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(8, z)])
    if spec.kind == "star_prism":
        # Near the five tips (4 radii in from the tip, where the arm is wider than a foot).
        radius = d["diameter"] / 2 - 4 * r
        angles = 2 * math.pi * np.arange(5) / 5
        return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(5, z)])
    if spec.kind in DEVICE_OBJECTS:
        return np.array(DEVICE_OBJECTS[spec.kind].feet(spec.size, r)).reshape(-1, 3)
    return np.zeros((0, 3))


def _table_proximity(mu: float, hydroelastic: str, resolution_hint: float, modulus: float):
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    if hydroelastic == "rigid":
        AddRigidHydroelasticProperties(resolution_hint, props)
    elif hydroelastic == "compliant":
        AddCompliantHydroelasticProperties(resolution_hint, modulus, props)
    return props


def AddTable(
    plant,
    top_height: float = 0.0,
    size: tuple[float, float] = (0.8, 0.8),
    name: str = "table",
    *,
    thickness: float = 0.05,
    mu: float = 0.8,
    hydroelastic: str = "rigid",
    hydroelastic_modulus: float = 1.0e7,
):
    """Adds a table top (a box welded to the world) whose top surface is at ``top_height``.

    The body ``top`` has its frame at the centre of the top surface, z up.
    ``hydroelastic`` is "rigid" (default), "compliant" or "none" (point contact
    only); with "rigid" the table meets compliant objects hydroelastically and
    point-contact objects through the fallback. Returns the ``ModelInstanceIndex``.
    """
    if plant.is_finalized():
        raise ValueError("AddTable must be called before plant.Finalize()")
    top_height = float(top_height)
    if not math.isfinite(top_height):
        raise ValueError(f"top_height must be finite, got {top_height}")
    size = tuple(size)
    if len(size) != 2:
        raise ValueError(f"table size must be (x, y), expected 2 numbers, got {len(size)}")
    sx, sy = (_check_positive("table size", s) for s in size)
    thickness = _check_positive("thickness", thickness)
    if hydroelastic not in ("rigid", "compliant", "none"):
        raise ValueError(
            f"hydroelastic must be 'rigid', 'compliant' or 'none', got {hydroelastic!r}"
        )
    mu = float(mu)
    if not math.isfinite(mu) or mu < 0:
        raise ValueError(f"mu must be a finite number >= 0, got {mu}")
    instance = plant.AddModelInstance(name)
    body = plant.AddRigidBody("top", instance, SpatialInertia.SolidBoxWithMass(10.0, sx, sy, 0.05))
    X_TG = RigidTransform([0, 0, -thickness / 2])
    shape = Box(sx, sy, thickness)
    props = _table_proximity(mu, hydroelastic, 0.1, hydroelastic_modulus)
    plant.RegisterCollisionGeometry(body, X_TG, shape, "top_collision", props)
    plant.RegisterVisualGeometry(body, X_TG, shape, "top_visual", np.array(_TABLE_COLOR))
    plant.WeldFrames(plant.world_frame(), body.body_frame(), RigidTransform([0, 0, top_height]))
    return instance
