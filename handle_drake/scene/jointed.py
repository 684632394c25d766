"""An object on a joint, and bare in-hand objects: a cap on its thread, a free cylinder.

The in-hand tasks hold objects the catalogue does not model: a cap on a revolute joint at
the mouth of a bottle welded to the world (report Fig. 32), turned against the thread's
friction, and a plain cylinder held by the fingertips alone. A scenario's ``object`` says
so with its ``joint`` (:class:`ThreadJoint`) and ``contact_feet: false``; the station
builds it with :func:`AddBareObject` (the one builder, used by the screw cap's own model
too, so both give the same plant bit for bit).

- The object is one Drake ``Cylinder`` (``size`` across, ``dimensions.height`` along its
  body z), with the analytic solid-cylinder inertia of its ``mass`` and Coulomb friction
  ``mu`` (``point_stiffness`` > 0: that point-contact stiffness); no contact feet.
- :class:`ThreadJoint`: a revolute joint about the object's own z axis at ``X_WO`` (the
  frame ``<instance>_mouth`` on the world), with Coulomb friction ``coulomb_torque`` and
  viscous ``viscous``. Drake's discrete SAP plant has no Coulomb joint friction, so the
  Coulomb part is a PD actuator with ``kp = 0``, ``kd = coulomb_torque / stiction_speed``
  and the effort limit ``coulomb_torque``: SAP solves it implicitly as ``tau = -clamp(kd v,
  -Tc, Tc)``, Coulomb friction regularised below ``stiction_speed``. Its reference is 0
  (the station connects it). ``base``: a body welded to the world beside it (the bottle,
  :class:`ObjectBase`) that does not collide with the object (the thread is the joint).

Configs here are plain dataclasses below :mod:`handle_drake.scenario` (which holds them
in ``ObjectConfig``); this module must not use ``from __future__ import annotations``
(Drake's YAML reader needs real types).
"""

import dataclasses as dc
import math

import numpy as np
from pydrake.common.schema import Transform
from pydrake.geometry import (
    AddContactMaterial,
    CollisionFilterDeclaration,
    Cylinder,
    GeometrySet,
    ProximityProperties,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PdControllerGains,
    RevoluteJoint,
    SpatialInertia,
    UnitInertia,
)

__all__ = ["ObjectBase", "ThreadJoint", "BareObject", "AddBareObject", "FilterObjectBase",
           "validate_thread_joint", "JOINT_NAME", "BASE_NAME"]

JOINT_NAME = "object_joint"
BASE_NAME = "base"


@dc.dataclass
class ObjectBase:
    """A cylinder welded to the world at ``X_WB`` (its axis its body z; the bottle under a
    cap), ``diameter`` across and ``length`` long, with an optional neck: a narrower
    cylinder (``neck_diameter`` across, ``neck_length`` long; 0: none) on its axis, centred
    ``neck_offset`` along its z."""

    X_WB: Transform = dc.field(default_factory=Transform)
    name: str = BASE_NAME  # the body's name in the plant
    diameter: float = 0.06
    length: float = 0.08
    mass: float = 0.3
    neck_length: float = 0.0
    neck_diameter: float = 0.025
    neck_offset: float = 0.0


@dc.dataclass
class ThreadJoint:
    """The object on a revolute joint about its own z axis at ``X_WO`` (a cap on its
    thread): Coulomb friction ``coulomb_torque`` (N m, regularised below
    ``stiction_speed`` rad/s) plus viscous ``viscous`` (N m s/rad); ``base``: the welded
    body it sits on (None: none)."""

    coulomb_torque: float = 0.01
    viscous: float = 1.0e-3
    stiction_speed: float = 0.01
    base: ObjectBase | None = None
    name: str = JOINT_NAME  # the joint's name in the plant (its actuator: <name>_friction)


@dc.dataclass(frozen=True)
class BareObject:
    """What :func:`AddBareObject` builds (plain numbers, from a scenario's object)."""

    diameter: float
    length: float
    mass: float
    mu: float
    X_WO: RigidTransform
    point_stiffness: float = 0.0
    joint: ThreadJoint | None = None
    X_WB: RigidTransform | None = None  # the joint's base (None: the base's own X_WB)
    # the plant's names: model instance, body, base body, joint and its frame on the world
    names: tuple = ("object", "object", BASE_NAME, JOINT_NAME, "object_mouth")


def validate_thread_joint(joint: ThreadJoint, error=ValueError, where: str = "object.joint"):
    """Raises ``error`` naming the first bad field of ``joint``."""
    for name in ("coulomb_torque", "stiction_speed"):
        value = getattr(joint, name)
        if isinstance(value, bool) or not (isinstance(value, int | float)
                                           and math.isfinite(value) and 0 < value <= 1e3):
            raise error(f"{where}.{name}: expected a value in (0, 1000], got {value!r}")
    if isinstance(joint.viscous, bool) or not (isinstance(joint.viscous, int | float)
                                               and math.isfinite(joint.viscous)
                                               and 0 <= joint.viscous <= 1e3):
        raise error(f"{where}.viscous: expected a value in [0, 1000], got {joint.viscous!r}")
    names = [("name", joint.name)] + ([("base.name", joint.base.name)] if joint.base else [])
    for field, name in names:
        if not isinstance(name, str) or not name or any(c in name for c in " /:\t\n"):
            raise error(f"{where}.{field}: expected a name without spaces, '/' or ':', got "
                        f"{name!r}")
    base = joint.base
    if base is None:
        return
    for name in ("diameter", "length", "mass"):
        value = getattr(base, name)
        if isinstance(value, bool) or not (isinstance(value, int | float)
                                           and math.isfinite(value) and 0 < value <= 1e3):
            raise error(f"{where}.base.{name}: expected a finite value > 0, got {value!r}")
    if not (math.isfinite(base.neck_length) and 0 <= base.neck_length <= 1.0):
        raise error(f"{where}.base.neck_length: expected a value in [0, 1] m, got "
                    f"{base.neck_length!r}")
    if not (math.isfinite(base.neck_diameter) and 0 < base.neck_diameter <= 1.0):
        raise error(f"{where}.base.neck_diameter: expected a value in (0, 1] m, got "
                    f"{base.neck_diameter!r}")
    if not (math.isfinite(base.neck_offset) and abs(base.neck_offset) <= 1.0):
        raise error(f"{where}.base.neck_offset: expected a value in [-1, 1] m, got "
                    f"{base.neck_offset!r}")


def _proximity(mu: float, stiffness: float = 0.0) -> ProximityProperties:
    """Friction ``mu``; ``stiffness`` (N/m) > 0: the point contact's stiffness (the pair's
    stiffness is at most it); 0: Drake's default (rigid)."""
    props = ProximityProperties()
    if stiffness > 0:
        AddContactMaterial(point_stiffness=stiffness, friction=CoulombFriction(mu, mu),
                           properties=props)
    else:
        AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    return props


def AddBareObject(plant, obj: BareObject):
    """Adds ``obj`` (and its joint's base and joint) to an unfinalized plant; returns
    ``(instance, body, base body or None, joint or None)``. A free object (no joint) gets
    ``X_WO`` as its default floating pose."""
    instance_name, body_name, base_name, joint_name, mouth_name = obj.names
    instance = plant.AddModelInstance(instance_name)
    body = plant.AddRigidBody(body_name, instance, SpatialInertia(
        obj.mass, np.zeros(3), UnitInertia.SolidCylinder(obj.diameter / 2, obj.length,
                                                         [0, 0, 1])))
    shapes = [(body, Cylinder(obj.diameter / 2, obj.length), [0.9, 0.2, 0.2, 1])]
    base = joint = None
    spec = obj.joint.base if obj.joint is not None else None
    if spec is not None:
        base = plant.AddRigidBody(base_name, instance, SpatialInertia(
            spec.mass, np.zeros(3), UnitInertia.SolidCylinder(spec.diameter / 2, spec.length,
                                                              [0, 0, 1])))
        plant.WeldFrames(plant.world_frame(), base.body_frame(),
                         spec.X_WB.GetDeterministicValue() if obj.X_WB is None else obj.X_WB)
        shapes.append((base, Cylinder(spec.diameter / 2, spec.length), [0.3, 0.6, 0.9, 0.5]))
        if spec.neck_length > 0:
            shapes.append((base, Cylinder(spec.neck_diameter / 2, spec.neck_length),
                           [0.3, 0.6, 0.9, 0.5], RigidTransform([0, 0, spec.neck_offset])))
    for k, (b, shape, rgba, *X) in enumerate(shapes):
        X_BG = X[0] if X else RigidTransform()
        plant.RegisterCollisionGeometry(b, X_BG, shape, f"{b.name()}_collision{k or ''}",
                                        _proximity(obj.mu, obj.point_stiffness))
        plant.RegisterVisualGeometry(b, X_BG, shape, f"{b.name()}_visual{k or ''}",
                                     np.array(rgba))
    if obj.joint is not None:
        mouth = plant.AddFrame(FixedOffsetFrame(mouth_name, plant.world_frame(), obj.X_WO,
                                                instance))
        joint = plant.AddJoint(RevoluteJoint(joint_name, mouth, body.body_frame(), [0, 0, 1],
                                             damping=obj.joint.viscous))
        actuator = plant.AddJointActuator(f"{joint_name}_friction", joint,
                                          effort_limit=obj.joint.coulomb_torque)
        actuator.set_controller_gains(PdControllerGains(
            p=0.0, d=obj.joint.coulomb_torque / obj.joint.stiction_speed))
    else:
        plant.SetDefaultFloatingBaseBodyPose(body, obj.X_WO)
    return instance, body, base, joint


def FilterObjectBase(plant, scene_graph, body, base) -> None:
    """After Finalize: the object and its base do not collide (the thread is the joint)."""
    ids = [plant.GetCollisionGeometriesForBody(b) for b in (base, body)]
    scene_graph.collision_filter_manager().Apply(CollisionFilterDeclaration().ExcludeWithin(
        GeometrySet(ids[0] + ids[1])))
