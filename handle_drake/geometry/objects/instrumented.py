"""The report's instrumented objects (section 2.4, Figure 2) for the object catalogue.

Each device is a union of boxes with its published outer dimensions and mass,
and a named sensor frame S where its accelerometer sits (pose ``X_OS`` in the
object frame O). O follows the catalogue's convention (``handle_drake.geometry.objects``):
origin at the centre of the main body, +z up when the device lies on a table
in its natural resting pose (buttons up), +x along its longest edge.

This module holds plain data only (no Drake import): ``handle_drake.geometry.objects``
reads it to add the kinds to ``KINDS`` (usable wherever an object kind is
accepted: scenarios, ``simulate``, ``grasp``, ``babble``), and
``handle_drake.devices.accelerometer`` reads the sensor frames and default device
profiles.

Sources (outer dimensions and mass):

* ``joywarrior``: Code Mercenaries JoyWarrior24F14 in its optional plastic casing,
  35 x 37 x 25 mm (report section 2.4.3); the bare board is 30 x 33 x 5 mm, about
  5 g (report). The casing's mass is not published: ~2 mm ABS walls of that box
  are ~13 g, so 20 g with the board and the cable stub (an estimate).
* ``wiimote``: Nintendo RVL-CNT-01, 148 x 36.2 x 30.8 mm, 87 g without batteries
  (Nintendo's specification); with the two AA cells it needs to run (~23 g each):
  133 g. The ADXL330 sits on the main board near the middle of the remote, 20 mm
  towards the IR camera end, just below the board's mid-plane (from teardown
  photos; an estimate). Its axes (wiibrew.org): X to the left of the buttons'
  face... taken here as x_S = -y_O, y_S = +x_O (towards the IR camera), z_S = +z_O
  (out of the buttons' face).
* ``nunchuk``: Nintendo RVL-004, 113 x 38 x 37 mm, 71 g. Modelled as a grip box
  and a head box; the accelerometer sits in the head under the stick.
* ``sixaxis``: Sony Sixaxis (CECHZC1), about 157 x 95 x 55 mm overall, 137 g
  (Wikipedia "Sixaxis"; the outer size read off product drawings, approximate);
  modelled as a body box and two grip boxes behind its ends; the accelerometer
  is on the main board at the body's centre.
"""

from __future__ import annotations

import dataclasses as dc

__all__ = ["DeviceObject", "DEVICE_OBJECTS"]


@dc.dataclass(frozen=True)
class DeviceObject:
    """One instrumented object.

    proportions: every dimension as a multiple of ``size`` (the first is ``size``).
    mass: kg at the default size (the density follows from the pieces' volume).
    boxes: ``(name, centre (3), edges (3))`` in O, each as multiples of size.
    sensor_xyz: sensor origin in O, as multiples of size.
    sensor_rpy_deg: sensor axes in O (roll, pitch, yaw in degrees).
    device: the default accelerometer profile (``handle_drake.devices.accelerometer.PROFILES``).
    """

    kind: str
    default_size: float
    proportions: dict
    mass: float
    boxes: tuple
    sensor_xyz: tuple
    sensor_rpy_deg: tuple
    device: str
    color: tuple
    description: str

    def volume_at(self, size: float) -> float:
        return sum(e[0] * e[1] * e[2] for _, _, e in self.boxes) * size ** 3

    def box_list(self, size: float) -> list:
        """``(name, centre, edges)`` of the boxes in metres at ``size``."""
        return [(name, tuple(c * size for c in centre), tuple(e * size for e in edges))
                for name, centre, edges in self.boxes]

    def feet(self, size: float, radius: float) -> list:
        """Centres of small contact spheres of ``radius`` inside the bottom corners of
        the boxes that stand on the object's bottom face (see ``objects.contact_feet``)."""
        bottom = -self.proportions["height"] * size / 2
        out = []
        for _, (x, y, z), (ex, ey, ez) in self.box_list(size):
            if abs(z - ez / 2 - bottom) > 1e-9:
                continue
            for sx in (-1, 1):
                for sy in (-1, 1):
                    out.append((x + sx * (ex / 2 - radius), y + sy * (ey / 2 - radius),
                                bottom + radius))
        return out

    @property
    def density(self) -> float:
        """kg/m^3 giving ``mass`` at ``default_size``."""
        return self.mass / self.volume_at(self.default_size)


def _box(name, centre, edges, size):
    return (name, tuple(c / size for c in centre), tuple(e / size for e in edges))


def _joywarrior() -> DeviceObject:
    s = 0.037
    w, d, h = 0.037, 0.035, 0.025
    return DeviceObject(
        kind="joywarrior", default_size=s,
        proportions={"width": 1.0, "depth": d / s, "height": h / s},
        mass=0.020,
        boxes=(_box("casing", (0, 0, 0), (w, d, h), s),),
        # The board lies flat on the casing's floor, 5 mm thick: the chip at its centre.
        sensor_xyz=(0.0, 0.0, (-h / 2 + 0.004) / s), sensor_rpy_deg=(0.0, 0.0, 0.0),
        device="joywarrior24f14", color=(0.95, 0.45, 0.05, 1.0),
        description="Code Mercenaries JoyWarrior24F14 in its casing (35 x 37 x 25 mm)",
    )


def _wiimote() -> DeviceObject:
    s = 0.148
    w, d, h = 0.148, 0.0362, 0.0308
    return DeviceObject(
        kind="wiimote", default_size=s,
        proportions={"length": 1.0, "width": d / s, "height": h / s},
        mass=0.133,
        boxes=(_box("body", (0, 0, 0), (w, d, h), s),),
        sensor_xyz=(0.020 / s, 0.0, -0.003 / s), sensor_rpy_deg=(0.0, 0.0, 90.0),
        device="wiimote", color=(0.96, 0.96, 0.96, 1.0),
        description="Nintendo Wiimote (148 x 36.2 x 30.8 mm, 133 g with batteries)",
    )


def _nunchuk() -> DeviceObject:
    s = 0.113
    # Grip 75 mm (x) x 38 x 30 mm, head 38 x 38 x 37 mm at the +x end; bottoms aligned.
    grip, head = (0.075, 0.038, 0.030), (0.038, 0.038, 0.037)
    z0 = -0.037 / 2
    return DeviceObject(
        kind="nunchuk", default_size=s,
        proportions={"length": 1.0, "width": 0.038 / s, "height": 0.037 / s},
        mass=0.071,
        boxes=(_box("grip", (-s / 2 + grip[0] / 2, 0, z0 + grip[2] / 2), grip, s),
               _box("head", (s / 2 - head[0] / 2, 0, 0), head, s)),
        sensor_xyz=((s / 2 - head[0] / 2) / s, 0.0, 0.0), sensor_rpy_deg=(0.0, 0.0, 0.0),
        device="nunchuk", color=(0.92, 0.92, 0.92, 1.0),
        description="Nintendo Nunchuk (113 x 38 x 37 mm, 71 g)",
    )


def _sixaxis() -> DeviceObject:
    s = 0.157
    # Body 157 x 55 x 30 mm lying on the table; two grips 35 x 40 x 55 mm (the
    # thickest part) behind its ends (y < 0), sharing the body's back face.
    body, grip = (0.157, 0.055, 0.030), (0.035, 0.040, 0.055)
    h = grip[2]
    zb = -h / 2 + body[2] / 2
    yb = grip[1] / 2  # body centre: the overall depth 95 mm is centred on O
    yg = yb - body[1] / 2 - grip[1] / 2
    xg = s / 2 - grip[0] / 2
    return DeviceObject(
        kind="sixaxis", default_size=s,
        proportions={"length": 1.0, "width": (body[1] + grip[1]) / s, "height": h / s},
        mass=0.137,
        boxes=(_box("body", (0, yb, zb), body, s),
               _box("grip_left", (-xg, yg, 0), grip, s),
               _box("grip_right", (xg, yg, 0), grip, s)),
        sensor_xyz=(0.0, yb / s, zb / s), sensor_rpy_deg=(0.0, 0.0, 0.0),
        device="sixaxis", color=(0.15, 0.15, 0.15, 1.0),
        description="Sony Sixaxis (about 157 x 95 x 55 mm, 137 g)",
    )


#: kind -> DeviceObject, in the catalogue's order.
DEVICE_OBJECTS: dict[str, DeviceObject] = {
    d.kind: d for d in (_joywarrior(), _wiimote(), _nunchuk(), _sixaxis())
}
