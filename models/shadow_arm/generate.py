"""Writes shadow_arm.sdf: Shadow Robot's 4-DOF air-muscle arm (the Paris platform's arm,
report section 2.2) from its published dimensions.

Run from this folder: ``python generate.py``. Every number is sourced in README.md
([SR] is Shadow's ``sr_description``). The frames are Shadow's: each link's frame
sits at its joint, placed in the parent's frame by the joint origin of [SR]
(``xyz``, then ``rpy``), and each axis is given in the child's frame, as in
[SR]'s URDF. At q = 0 the upper arm hangs straight down beside the trunk:

- ``base``: the base plate, z up; ``ShoulderJRotate`` turns the trunk about z.
- ``trunk``: ``ShoulderJSwing`` sits 0.134 m to its -y side, 0.5305 m up; the
  upper arm's frame is turned half a turn about y (its z points down).
- ``upperarm``: ``ElbowJSwing`` 0.369 m along its z (down at q = 0).
- ``lowerarm``: the elbow bracket; ``ElbowJRotate`` turns the hand support about
  an axis 0.080 m off the elbow (lowerarm x) and 0.131 m along it (lowerarm z).
- ``handsupport``: the hand's mounting plate; its frame ``flange`` is where the
  hand's forearm is bolted (the scenario's ``X_FH``; [SR] turns the hand half a
  turn about z there).

Collision shapes are boxes and cylinders (README.md says which are [SR]'s).
"""

from __future__ import annotations

import math
from pathlib import Path

# Joint origins in the parent link's frame ([SR] arm/xacro/*/shadowarm_*.urdf.xacro).
BASE_TO_ROTATE = 0.01  # ShoulderJRotate above the base plate
SHOULDER_Y = -0.134  # ShoulderJSwing, to the trunk's side
SHOULDER_Z = 0.5305  # ShoulderJSwing, above ShoulderJRotate
UPPER_ARM = 0.369  # ShoulderJSwing to ElbowJSwing
ELBOW_OFFSET_X = 0.080  # ElbowJSwing to the ElbowJRotate axis, across the forearm
ELBOW_TO_SUPPORT = 0.131  # ElbowJSwing to the hand support plate, along ElbowJRotate

# name, parent, child, origin xyz, origin rpy, axis (child frame), lower, upper (rad),
# velocity (rad/s), effort (N m) -- all [SR].
JOINTS = [
    ("ShoulderJRotate", "base", "trunk", (0, 0, BASE_TO_ROTATE), (0, 0, 0), (0, 0, 1),
     -math.pi / 4, math.pi / 2, 1.0, 70.0),
    ("ShoulderJSwing", "trunk", "upperarm", (0, SHOULDER_Y, SHOULDER_Z), (0, -math.pi, 0),
     (0, -1, 0), 0.0, math.pi / 2, 1.0, 100.0),
    ("ElbowJSwing", "upperarm", "lowerarm", (0, 0, UPPER_ARM), (0, 0, 0), (0, -1, 0),
     0.52, 2.09439510239, 1.0, 50.0),
    ("ElbowJRotate", "lowerarm", "handsupport", (ELBOW_OFFSET_X, 0, ELBOW_TO_SUPPORT), (0, 0, 0),
     (0, 0, -1), -math.pi / 2, math.pi / 2, 1.0, 30.0),
]

# Mass (kg) and centre of mass (link frame) per link: [SR]'s inertial origins and masses
# (their doc/ArmInertia.md: estimated from bounding volumes and the material's density).
MASS = {
    "base": (0.4, (0, 0, 0)),
    "trunk": (10.0, (0, 0, 0.26525)),
    "upperarm": (2.0, (0, 0, 0.1845)),
    "lowerarm": (1.7, (0.08, 0, 0.0625)),
    "handsupport": (0.75, (0, 0, 0)),
}

# Collision/visual shapes per link: ("box", (sx, sy, sz), (x, y, z)) or
# ("cylinder", radius, length, (x, y, z)) along the link's z. The first one sets the
# link's rotational inertia (a solid of the link's mass).
SHAPES = {
    "base": [("box", (0.145, 0.145, 0.012), (0, 0, 0.005))],
    "trunk": [("box", (0.170, 0.170, 0.580), (0, 0.02, 0.30))],
    # [SR]'s box spans z -0.075..0.395; ours stops 0.04 short of the elbow axis so that
    # the flexed elbow bracket does not touch it (README.md).
    "upperarm": [("box", (0.170, 0.133, 0.400), (0, 0, 0.125))],
    "lowerarm": [("box", (0.06, 0.08, 0.1), (0.08, 0, 0.0625))],
    "handsupport": [("cylinder", 0.07, 0.006, (0, 0, 0))],
}
COLORS = {"base": "0.3 0.3 0.32 1", "trunk": "0.55 0.55 0.58 1", "upperarm": "0.7 0.7 0.72 1",
          "lowerarm": "0.55 0.55 0.58 1", "handsupport": "0.8 0.8 0.82 1"}


def _inertia(mass, shape):
    if shape[0] == "box":
        sx, sy, sz = shape[1]
        return (mass * (sy**2 + sz**2) / 12, mass * (sx**2 + sz**2) / 12,
                mass * (sx**2 + sy**2) / 12)
    _, r, length, _ = shape
    ixx = mass * (3 * r**2 + length**2) / 12
    return ixx, ixx, mass * r**2 / 2


def _fmt(values) -> str:
    return " ".join(f"{v:.12g}" for v in values)


def _link(name: str, pose: str) -> str:
    mass, com = MASS[name]
    ixx, iyy, izz = _inertia(mass, SHAPES[name][0])
    out = [f'    <link name="{name}">', pose,
           "      <inertial>", f"        <pose>{_fmt(com)} 0 0 0</pose>",
           f"        <mass>{mass}</mass>",
           f"        <inertia><ixx>{ixx:.6g}</ixx><ixy>0</ixy><ixz>0</ixz><iyy>{iyy:.6g}</iyy>"
           f"<iyz>0</iyz><izz>{izz:.6g}</izz></inertia>",
           "      </inertial>"]
    for i, shape in enumerate(SHAPES[name]):
        if shape[0] == "box":
            geometry = f"<geometry><box><size>{_fmt(shape[1])}</size></box></geometry>"
            where = shape[2]
        else:
            geometry = (f"<geometry><cylinder><radius>{shape[1]}</radius>"
                        f"<length>{shape[2]}</length></cylinder></geometry>")
            where = shape[3]
        pose_line = f"        <pose>{_fmt(where)} 0 0 0</pose>"
        out += [f'      <collision name="{name}_collision_{i}">', pose_line,
                f"        {geometry}", "      </collision>",
                f'      <visual name="{name}_visual_{i}">', pose_line, f"        {geometry}",
                f"        <material><diffuse>{COLORS[name]}</diffuse></material>",
                "      </visual>"]
    out.append("    </link>")
    return "\n".join(out)


def sdf_text() -> str:
    parts = ['<?xml version="1.0"?>',
             "<!-- Generated by generate.py; see README.md for the sources. -->",
             '<sdf version="1.9">', '  <model name="shadow_arm">',
             _link("base", "      <pose>0 0 0 0 0 0</pose>")]
    for joint, parent, child, xyz, rpy, axis, lo, hi, velocity, effort in JOINTS:
        pose = f'      <pose relative_to="{parent}">{_fmt(xyz)} {_fmt(rpy)}</pose>'
        parts.append(_link(child, pose))
        parts += [f'    <joint name="{joint}" type="revolute">',
                  f"      <parent>{parent}</parent>", f"      <child>{child}</child>",
                  "      <axis>", f"        <xyz>{_fmt(axis)}</xyz>",
                  f"        <limit><lower>{lo:.6f}</lower><upper>{hi:.6f}</upper>"
                  f"<velocity>{velocity:.6f}</velocity><effort>{effort}</effort></limit>",
                  "      </axis>", "    </joint>"]
    parts += ['    <frame name="flange" attached_to="handsupport">',
              '      <pose relative_to="handsupport">0 0 0 0 0 0</pose>',
              "    </frame>", "  </model>", "</sdf>", ""]
    return "\n".join(parts)


if __name__ == "__main__":
    path = Path(__file__).with_name("shadow_arm.sdf")
    path.write_text(sdf_text())
    print(f"wrote {path}")
