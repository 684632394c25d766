"""A model of the iCON iControls Pro built from primitive shapes.

Frame C (the controller) sits at the centre of the base's **bottom** face:
``x_C`` along the row of channel strips (left to right), ``y_C`` away from the
user (a fader's "up"), ``z_C`` up. Placing C on a table puts the device on it.

Dimensions. iCON publishes no drawing of the iControls Pro; the numbers below
are **estimates** (stated here, used everywhere): a 0.36 x 0.20 x 0.035 m
base of 1.2 kg; nine channel strips 0.026 m apart, each with a 60 mm
motorised fader (the common ALPS travel), an endless knob (14 mm diameter) and
a button; the master jog wheel (45 mm diameter, standing 22 mm proud of the
panel so that fingertips can pinch its rim) right of the strips with the
``mode`` button beside it. Edit :class:`ControllerGeometry` to match a device.

A free base (``fixed=False``) also has four 4 mm sphere feet at its bottom
corners, flush with the bottom face: box-on-box point contact has a single
contact point, on which the 1.4 kg device sank 12 mm into a table.

Joints (all children of the base, so the plant filters their contacts with
the base):

- ``fader1..9``: prismatic along ``y_C``, position 0 (bottom) to ``travel``;
- ``knob1..9``, ``jog``: revolute about ``z_C``, no limits (endless);
- ``button1..9``, ``mode``: prismatic along ``-z_C``, 0 (up) to
  ``button_travel``, a ``PrismaticSpring`` preloaded against the upper stop.

A real fader or knob is held by dry friction; Drake's discrete (SAP) plant
has no Coulomb joint friction, so viscous joint damping stands in for it: a
fingertip moving a control meets a force proportional to the speed, and a
released control stops within milliseconds (time constant inertia/damping:
~8 ms for the jog wheel, ~5 ms for a fader cap).
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.geometry import AddContactMaterial, Box, Cylinder, ProximityProperties, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    PrismaticSpring,
    RevoluteJoint,
    SpatialInertia,
)

__all__ = [
    "ControllerGeometry",
    "ControlJoint",
    "AddMidiController",
    "control_joints",
    "control_layout",
]

BASE_BODY = "base"


@dc.dataclass(frozen=True)
class ControllerGeometry:
    """Dimensions (m), masses (kg) and joint dynamics of the model (estimates, see module doc)."""

    base_size: tuple[float, float, float] = (0.36, 0.20, 0.035)
    base_mass: float = 1.2
    strips: int = 9
    strip_pitch: float = 0.026  # x distance between channel strips
    first_strip_x: float = -0.155  # x of strip 1 in C
    fader_y: float = -0.075  # y of a fader cap at position 0
    fader_travel: float = 0.060
    fader_cap: tuple[float, float, float] = (0.012, 0.020, 0.014)
    fader_mass: float = 0.010
    fader_damping: float = 2.0  # N*s/m
    knob_y: float = 0.040
    knob_radius: float = 0.007
    knob_height: float = 0.016
    knob_mass: float = 0.005
    knob_damping: float = 2.0e-4  # N*m*s/rad
    button_y: float = 0.070
    button_size: tuple[float, float, float] = (0.012, 0.008, 0.006)
    button_mass: float = 0.002
    button_travel: float = 0.003
    button_stiffness: float = 300.0  # N/m
    button_preload: float = 0.3  # N against the upper stop
    button_damping: float = 0.5  # N*s/m
    jog_xy: tuple[float, float] = (0.110, -0.030)
    jog_radius: float = 0.0225
    jog_height: float = 0.022
    jog_mass: float = 0.030
    jog_damping: float = 1.0e-3  # N*m*s/rad
    mode_xy: tuple[float, float] = (0.110, 0.060)
    mu: float = 0.9  # rubber caps and wheel rim

    def validate(self) -> ControllerGeometry:
        for field in dc.fields(self):
            value = getattr(self, field.name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise ValueError(f"ControllerGeometry.{field.name}: expected finite numbers, "
                                 f"got {value!r}")
            if field.name.endswith(("_size", "_cap", "_mass", "_radius", "_height", "_travel",
                                    "_stiffness", "_damping", "_pitch")) or field.name == "mu":
                if not all(v > 0 for v in values):
                    raise ValueError(f"ControllerGeometry.{field.name}: expected > 0, "
                                     f"got {value!r}")
        if not (isinstance(self.strips, int) and 1 <= self.strips <= 9):
            raise ValueError(f"ControllerGeometry.strips: expected 1-9, got {self.strips!r}")
        return self

    @property
    def panel_height(self) -> float:
        """z of the panel top in C (m)."""
        return self.base_size[2]


@dc.dataclass(frozen=True)
class ControlJoint:
    """One control of the model: its joint name, kind and travel (m; 2 pi for rotaries)."""

    name: str
    kind: str  # fader | knob | jog | button
    travel: float
    p_C: tuple[float, float, float]  # where the control's body frame sits at position 0


def control_layout(geometry: ControllerGeometry | None = None) -> list[ControlJoint]:
    """The model's controls in a fixed order: faders, knobs, jog, buttons, mode."""
    g = (geometry or ControllerGeometry()).validate()
    top = g.panel_height
    xs = [g.first_strip_x + i * g.strip_pitch for i in range(g.strips)]
    out = [ControlJoint(f"fader{i + 1}", "fader", g.fader_travel,
                        (x, g.fader_y, top + g.fader_cap[2] / 2)) for i, x in enumerate(xs)]
    out += [ControlJoint(f"knob{i + 1}", "knob", 2 * math.pi,
                         (x, g.knob_y, top + g.knob_height / 2)) for i, x in enumerate(xs)]
    out.append(ControlJoint("jog", "jog", 2 * math.pi,
                            (g.jog_xy[0], g.jog_xy[1], top + g.jog_height / 2)))
    out += [ControlJoint(f"button{i + 1}", "button", g.button_travel,
                         (x, g.button_y, top + g.button_size[2] / 2)) for i, x in enumerate(xs)]
    out.append(ControlJoint("mode", "button", g.button_travel,
                            (g.mode_xy[0], g.mode_xy[1], top + g.button_size[2] / 2)))
    return out


def _proximity(mu: float) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    return props


def _register(plant, body, shape, X, name, rgba, mu):
    plant.RegisterCollisionGeometry(body, X, shape, f"{name}_collision", _proximity(mu))
    plant.RegisterVisualGeometry(body, X, shape, f"{name}_visual", np.array(rgba))


def AddMidiController(plant, X_WC: RigidTransform | None = None, fixed: bool = True,
                      name: str = "midi_controller",
                      geometry: ControllerGeometry | None = None):
    """Adds the controller to an unfinalized plant; returns its model instance.

    ``fixed``: weld the base to the world at ``X_WC`` (on the table), else the
    base is a free body whose default pose is ``X_WC``.
    """
    g = (geometry or ControllerGeometry()).validate()
    if plant.is_finalized():
        raise ValueError("AddMidiController needs an unfinalized plant")
    X_WC = RigidTransform() if X_WC is None else X_WC
    instance = plant.AddModelInstance(name)
    base = plant.AddRigidBody(BASE_BODY, instance, SpatialInertia.SolidBoxWithMass(
        g.base_mass, *g.base_size))
    # The base body frame is C (bottom centre); the box is centred above it.
    X_CBox = RigidTransform([0.0, 0.0, g.base_size[2] / 2])
    _register(plant, base, Box(*g.base_size), X_CBox, "base", [0.15, 0.15, 0.17, 1.0], g.mu)
    if not fixed:
        # Feet: box-on-box point contact has one contact point (the deepest);
        # four small spheres at the bottom corners, flush with the bottom face,
        # let the free base rest flat on a table (as the instrumented objects do).
        foot = 0.004
        for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
            p_CF = [sx * (g.base_size[0] / 2 - foot), sy * (g.base_size[1] / 2 - foot), foot]
            plant.RegisterCollisionGeometry(base, RigidTransform(p_CF), Sphere(foot),
                                            f"base_foot{i}_collision", _proximity(g.mu))
    if fixed:
        plant.WeldFrames(plant.world_frame(), base.body_frame(), X_WC)
    else:
        plant.SetDefaultFloatingBaseBodyPose(base, X_WC)

    z = np.array([0.0, 0.0, 1.0])
    for control in control_layout(g):
        X_CJ = RigidTransform(list(control.p_C))
        if control.kind == "fader":
            inertia = SpatialInertia.SolidBoxWithMass(g.fader_mass, *g.fader_cap)
            shape, rgba = Box(*g.fader_cap), [0.85, 0.85, 0.85, 1.0]
        elif control.kind == "knob":
            inertia = SpatialInertia.SolidCylinderWithMass(g.knob_mass, g.knob_radius,
                                                           g.knob_height, z)
            shape, rgba = Cylinder(g.knob_radius, g.knob_height), [0.3, 0.3, 0.32, 1.0]
        elif control.kind == "jog":
            inertia = SpatialInertia.SolidCylinderWithMass(g.jog_mass, g.jog_radius,
                                                           g.jog_height, z)
            shape, rgba = Cylinder(g.jog_radius, g.jog_height), [0.25, 0.25, 0.28, 1.0]
        else:
            inertia = SpatialInertia.SolidBoxWithMass(g.button_mass, *g.button_size)
            shape, rgba = Box(*g.button_size), [0.8, 0.3, 0.2, 1.0]
        body = plant.AddRigidBody(control.name, instance, inertia)
        _register(plant, body, shape, RigidTransform(), control.name, rgba, g.mu)
        rest = plant.AddFrame(FixedOffsetFrame(f"{control.name}_rest", base.body_frame(), X_CJ))
        if control.kind == "fader":
            joint = plant.AddJoint(PrismaticJoint(
                control.name, rest, body.body_frame(), [0.0, 1.0, 0.0],
                pos_lower_limit=0.0, pos_upper_limit=g.fader_travel, damping=g.fader_damping))
            joint.set_default_translation(0.0)
        elif control.kind == "button":
            joint = plant.AddJoint(PrismaticJoint(
                control.name, rest, body.body_frame(), [0.0, 0.0, -1.0],
                pos_lower_limit=0.0, pos_upper_limit=g.button_travel,
                damping=g.button_damping))
            plant.AddForceElement(PrismaticSpring(
                joint, -g.button_preload / g.button_stiffness, g.button_stiffness))
        else:
            damping = g.jog_damping if control.kind == "jog" else g.knob_damping
            joint = plant.AddJoint(RevoluteJoint(
                control.name, rest, body.body_frame(), z, damping=damping))
    return instance


def control_joints(plant, instance, names):
    """The joints of the controls ``names`` (e.g. ``[c.name for c in control_layout()]``)."""
    return [plant.GetJointByName(n, instance) for n in names]


def check_mapping_on_device(mapping, geometry: ControllerGeometry | None = None) -> None:
    """Raises ValueError naming the first control of ``mapping`` the modelled device
    lacks (a name not on it, or on it as another kind): the simulated controller
    sends only the controls it has, so such a mapping would send nothing for them."""
    layout = {c.name: c.kind for c in control_layout(geometry)}
    for i, control in enumerate(mapping.controls):
        kind = layout.get(control.name)
        if kind is None:
            raise ValueError(
                f"controls[{i}].name: the {mapping.device} model has no control "
                f"{control.name!r}; expected one of {', '.join(layout)}")
        if kind != control.kind:
            raise ValueError(f"controls[{i}] ({control.name!r}).kind: on the {mapping.device} "
                             f"model {control.name} is a {kind}, got {control.kind!r}")
