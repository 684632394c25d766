#!/usr/bin/env python3
"""Generate ``shadow_hand_right.sdf``: the Shadow Dexterous Hand (right, E/C6
kinematics) built from primitive shapes.

Run from anywhere: ``python models/shadow_hand/generate.py``. It rewrites
``shadow_hand_right.sdf`` beside this script; the generated file is committed
and must be regenerated whenever this script changes (a test checks that the
committed file equals the output of :func:`make_sdf`).

Every number comes from /work/shared/reference/hand_kinematics.md section 1
(the public figures of shadow-robot/sr_common and MuJoCo Menagerie). No file
of those repositories is copied: the shapes and the SDF are written here from
the numbers. What is our own choice (inertias, forearm/wrist shapes, PD gains,
damping, armature, tactile pads) is marked "ours" below and in README.md.

Conventions. Each link frame is the child frame of the joint that moves it
(URDF style: the joint frame equals the child link frame, the link pose is
given relative to the parent link). Axes are expressed in the child frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

MODEL_NAME = "shadow_hand"
OUTPUT = Path(__file__).resolve().parent / "shadow_hand_right.sdf"

FINGERS = ("ff", "mf", "rf", "lf")

# --------------------------------------------------------------------------
# Dynamics parameters (ours). Rationale in README.md "Actuation". The PD runs
# inside MultibodyPlant (SAP treats it implicitly), torque clamped at the
# sheet's effort limit. kd is chosen near critical damping for the effective
# inertia (link inertia + armature) at the open pose; joint damping and
# armature (reflected rotor inertia, Menagerie uses 2e-4 kg m^2) make the
# tiny finger links well conditioned for 1-5 ms steps.
# group: (kp [N m/rad], kd [N m s/rad], joint damping [N m s/rad], armature [kg m^2])
GAINS = {
    "wrist": (50.0, 2.0, 0.5, 2.0e-3),
    "finger": (3.0, 0.06, 0.02, 2.0e-4),
    "thumb_base": (6.0, 0.12, 0.02, 2.0e-4),  # THJ5, THJ4: heaviest thumb links
    "thumb": (3.0, 0.05, 0.02, 2.0e-4),  # THJ3..THJ1
}
# The unactuated distal joints (xFJ1) get damping only (no actuator, so no
# armature in Drake's model; the coupler ties them to J2).
DISTAL_DAMPING = 0.005

MU = 1.0  # Coulomb friction of the skin (ours; Menagerie uses 1.0 as well)
RESOLUTION_HINT = 0.004  # m, rigid hydroelastic mesh size of round shapes

PAD_SIZE = (0.014, 0.002, 0.018)  # x, y (thickness), z of the tactile pad box, m (ours)


# --------------------------------------------------------------------------
# Small SDF writer
@dataclass
class Shape:
    kind: str  # box | cylinder | capsule | sphere
    size: tuple  # box: (x,y,z); cylinder/capsule: (radius, length); sphere: (radius,)
    xyz: tuple = (0.0, 0.0, 0.0)
    rpy: tuple = (0.0, 0.0, 0.0)
    name: str = ""

    def geometry_xml(self) -> str:
        if self.kind == "box":
            return f"<box><size>{_v(self.size)}</size></box>"
        if self.kind == "sphere":
            return f"<sphere><radius>{_f(self.size[0])}</radius></sphere>"
        r, length = self.size
        return f"<{self.kind}><radius>{_f(r)}</radius><length>{_f(length)}</length></{self.kind}>"


@dataclass
class Link:
    name: str
    mass: float
    com: tuple
    inertia: tuple  # ixx, iyy, izz about the com, axes of the link frame
    collisions: list = field(default_factory=list)
    color: tuple = (0.2, 0.2, 0.22, 1.0)


@dataclass
class Joint:
    name: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple
    axis: tuple
    lower: float
    upper: float
    effort: float
    velocity: float
    group: str | None  # key of GAINS, None = unactuated
    jtype: str = "revolute"
    gains: dict | None = None  # table the group refers to (default: GAINS)
    unactuated_damping: float = 0.0

    def dynamics(self):
        """(kp, kd, damping, armature); kp = kd = armature = None when unactuated."""
        if self.group is None:
            return None, None, self.unactuated_damping, None
        return (self.gains or GAINS)[self.group]


def _f(x: float) -> str:
    s = f"{x:.15g}"
    return "0" if s == "-0" else s


def _v(values) -> str:
    return " ".join(_f(x) for x in values)


def solid_box_inertia(m, x, y, z):
    return (m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12)


def solid_cylinder_inertia(m, r, length):
    """Solid cylinder along z."""
    i_perp = m * (3 * r * r + length * length) / 12
    return (i_perp, i_perp, m * r * r / 2)


def solid_sphere_inertia(m, r):
    i = 2 * m * r * r / 5
    return (i, i, i)


def cylinder_along_x(inertia):
    ixx, iyy, izz = inertia
    return (izz, iyy, ixx)


def proximity_xml(mu: float, resolution_hint: float) -> str:
    """Rigid hydroelastic (so compliant objects get hydroelastic contact) with friction mu."""
    return f"""<drake:proximity_properties>
          <drake:rigid_hydroelastic/>
          <drake:mesh_resolution_hint>{_f(resolution_hint)}</drake:mesh_resolution_hint>
          <drake:mu_dynamic>{_f(mu)}</drake:mu_dynamic>
          <drake:mu_static>{_f(mu)}</drake:mu_static>
        </drake:proximity_properties>"""


PROXIMITY = proximity_xml(MU, RESOLUTION_HINT)


def link_xml(link: Link, pose_parent: str | None, xyz, rpy, proximity: str = PROXIMITY) -> str:
    ixx, iyy, izz = link.inertia
    relative = f' relative_to="{pose_parent}"' if pose_parent else ""
    parts = [
        f'    <link name="{link.name}">',
        f"      <pose{relative}>{_v(xyz)} {_v(rpy)}</pose>",
        "      <inertial>",
        f"        <pose>{_v(link.com)} 0 0 0</pose>",
        f"        <mass>{_f(link.mass)}</mass>",
        f"        <inertia><ixx>{ixx:.6g}</ixx><ixy>0</ixy><ixz>0</ixz>"
        f"<iyy>{iyy:.6g}</iyy><iyz>0</iyz><izz>{izz:.6g}</izz></inertia>",
        "      </inertial>",
    ]
    for i, shape in enumerate(link.collisions):
        name = shape.name or f"{link.name}_collision_{i}"
        color = (0.75, 0.3, 0.2, 1.0) if name.endswith("_pad") else link.color
        parts += [
            f'      <collision name="{name}">',
            f"        <pose>{_v(shape.xyz)} {_v(shape.rpy)}</pose>",
            f"        <geometry>{shape.geometry_xml()}</geometry>",
            f"        {proximity}",
            "      </collision>",
            f'      <visual name="{name}_visual">',
            f"        <pose>{_v(shape.xyz)} {_v(shape.rpy)}</pose>",
            f"        <geometry>{shape.geometry_xml()}</geometry>",
            f"        <material><diffuse>{_v(color)}</diffuse></material>",
            "      </visual>",
        ]
    parts.append("    </link>")
    return "\n".join(parts)


def joint_xml(joint: Joint) -> str:
    parts = [
        f'    <joint name="{joint.name}" type="{joint.jtype}">',
        f"      <parent>{joint.parent}</parent>",
        f"      <child>{joint.child}</child>",
        "      <axis>",
        f"        <xyz>{_v(joint.axis)}</xyz>",
        "        <limit>",
        f"          <lower>{_f(joint.lower)}</lower>",
        f"          <upper>{_f(joint.upper)}</upper>",
        # Drake's SDFormat parser adds an actuator only when effort != 0.
        f"          <effort>{_f(joint.effort if joint.group else 0.0)}</effort>",
        f"          <velocity>{_f(joint.velocity)}</velocity>",
        "        </limit>",
    ]
    kp, kd, damping, armature = joint.dynamics()
    parts += [
        f"        <dynamics><damping>{_f(damping)}</damping></dynamics>",
        "      </axis>",
    ]
    if joint.group:
        parts += [
            f'      <drake:controller_gains p="{_f(kp)}" d="{_f(kd)}"/>',
            f"      <drake:rotor_inertia>{_f(armature)}</drake:rotor_inertia>",
            "      <drake:gear_ratio>1</drake:gear_ratio>",
        ]
    parts.append("    </joint>")
    return "\n".join(parts)


# --------------------------------------------------------------------------
# The hand (numbers: hand_kinematics.md section 1)
SKIN = (0.16, 0.16, 0.17, 1.0)
FINGER_COLOR = (0.25, 0.25, 0.27, 1.0)
HALF_PI = math.pi / 2
J3_LOWER = -0.2618
TIP_Z = 0.026
THUMB_TIP_Z = 0.0275


def pad(prefix: str, z_center: float, radius: float) -> Shape:
    """Thin box on the palmar (-y) face of a distal link, 0.5 mm proud of its capsule."""
    x, y, z = PAD_SIZE
    return Shape(
        "box", PAD_SIZE, (0.0, -(radius + 0.0005) + y / 2, z_center), name=f"{prefix}tip_pad"
    )


def capsule(radius, cyl_half_length, z, name=""):
    return Shape("capsule", (radius, 2 * cyl_half_length), (0.0, 0.0, z), name=name)


def capsule_span(radius, z0, z1):
    """Capsule whose rounded ends reach z0 and z1."""
    return Shape("capsule", (radius, (z1 - z0) - 2 * radius), (0.0, 0.0, (z0 + z1) / 2))


def build():
    links: list[Link] = []
    joints: list[Joint] = []
    poses: dict[str, tuple] = {}  # child link -> (parent, xyz, rpy)

    def add(link, joint):
        links.append(link)
        if joint is not None:
            joints.append(joint)
            poses[link.name] = (joint.parent, joint.xyz, joint.rpy)

    # Forearm (ours: the sheet gives mass and com only): cylinder r 0.045 up to z 0.18.
    add(
        Link(
            "forearm",
            3.0,
            (0, 0, 0.09),
            solid_cylinder_inertia(3.0, 0.045, 0.18),
            # (ours) the housing up to z 0.18 and a neck under the wrist
            [
                Shape("cylinder", (0.045, 0.18), (0, 0, 0.09)),
                Shape("cylinder", (0.02, 0.035), (0, -0.005, 0.1975)),
            ],
            SKIN,
        ),
        None,
    )
    # Wrist (ours): the WRJ1 housing, a capsule along x around the wrist.
    add(
        Link(
            "wrist",
            0.1,
            (0, 0, 0.029),
            cylinder_along_x(solid_cylinder_inertia(0.1, 0.014, 0.03)),
            [Shape("capsule", (0.014, 0.03), (0, 0, 0.029), (0, HALF_PI, 0))],
            SKIN,
        ),
        Joint(
            "WRJ2",
            "forearm",
            "wrist",
            (0, -0.010, 0.21301),
            (0, 0, 0),
            (0, 1, 0),
            -0.5236,
            0.1745,
            10,
            2,
            "wrist",
        ),
    )
    # Palm: the sheet's two main boxes plus (ours) a box under the first-finger side,
    # so the palmar face is closed across its width (the LF side is the metacarpal).
    add(
        Link(
            "palm",
            0.3,
            (0, 0, 0.035),
            solid_box_inertia(0.3, 0.084, 0.024, 0.1),
            [
                Shape("box", (0.062, 0.007, 0.098), (0.011, 0.0085, 0.038)),
                Shape("box", (0.036, 0.017, 0.098), (-0.002, -0.0035, 0.038)),
                Shape("box", (0.026, 0.017, 0.042), (0.029, -0.0035, 0.066)),
            ],
            SKIN,
        ),
        Joint(
            "WRJ1",
            "wrist",
            "palm",
            (0, 0, 0.034),
            (0, 0, 0),
            (1, 0, 0),
            -0.6981,
            0.4887,
            30,
            2,
            "wrist",
        ),
    )

    knuckle_origin = {
        "ff": ((0.033, 0, 0.095), (0, -1, 0)),
        "mf": ((0.011, 0, 0.099), (0, -1, 0)),
        "rf": ((-0.011, 0, 0.095), (0, 1, 0)),
        "lf": ((0, 0, 0.06579), (0, 1, 0)),  # from lfmetacarpal
    }
    for f in FINGERS:
        F = f.upper()
        knuckle_parent = "palm"
        if f == "lf":
            add(
                Link(
                    "lfmetacarpal",
                    0.030,
                    (0.002, 0, 0.033),
                    solid_box_inertia(0.030, 0.022, 0.024, 0.050),
                    [Shape("box", (0.022, 0.024, 0.050), (0.002, 0, 0.033))],
                    SKIN,
                ),
                Joint(
                    "LFJ5",
                    "palm",
                    "lfmetacarpal",
                    (-0.033, 0, 0.02071),
                    (0, 0, 0),
                    (0.573576, 0, 0.819152),
                    0.0,
                    0.7854,
                    2,
                    2,
                    "finger",
                ),
            )
            knuckle_parent = "lfmetacarpal"
        xyz, axis = knuckle_origin[f]
        add(
            Link(
                f"{f}knuckle",
                0.008,
                (0, 0, 0),
                cylinder_along_x(solid_cylinder_inertia(0.008, 0.009, 0.018)),
                [Shape("cylinder", (0.009, 0.018), (0, 0, 0), (0, HALF_PI, 0))],
                FINGER_COLOR,
            ),
            Joint(
                f"{F}J4",
                knuckle_parent,
                f"{f}knuckle",
                xyz,
                (0, 0, 0),
                axis,
                -0.3491,
                0.3491,
                2,
                2,
                "finger",
            ),
        )
        add(
            Link(
                f"{f}proximal",
                0.030,
                (0, 0, 0.0225),
                solid_cylinder_inertia(0.030, 0.009, 0.058),
                [capsule(0.009, 0.020, 0.025)],
                FINGER_COLOR,
            ),
            Joint(
                f"{F}J3",
                f"{f}knuckle",
                f"{f}proximal",
                (0, 0, 0),
                (0, 0, 0),
                (1, 0, 0),
                J3_LOWER,
                HALF_PI,
                2,
                2,
                "finger",
            ),
        )
        add(
            Link(
                f"{f}middle",
                0.017,
                (0, 0, 0.0125),
                solid_cylinder_inertia(0.017, 0.009, 0.043),
                [capsule(0.009, 0.0125, 0.0125)],
                FINGER_COLOR,
            ),
            Joint(
                f"{F}J2",
                f"{f}proximal",
                f"{f}middle",
                (0, 0, 0.045),
                (0, 0, 0),
                (1, 0, 0),
                0.0,
                HALF_PI,
                2,
                2,
                "finger",
            ),
        )
        distal = capsule_span(0.0085, 0.005, 0.032)
        add(
            Link(
                f"{f}distal",
                0.013,
                (0, 0, 0.012),
                solid_cylinder_inertia(0.013, 0.0085, 0.027),
                [distal, pad(f, 0.019, 0.0085)],
                FINGER_COLOR,
            ),
            Joint(
                f"{F}J1",
                f"{f}middle",
                f"{f}distal",
                (0, 0, 0.025),
                (0, 0, 0),
                (1, 0, 0),
                0.0,
                HALF_PI,
                2,
                2,
                None,
                unactuated_damping=DISTAL_DAMPING,
            ),
        )

    # Thumb
    add(
        Link(
            "thbase",
            0.010,
            (0, 0, 0),
            solid_sphere_inertia(0.010, 0.013),
            [Shape("sphere", (0.013,))],
            FINGER_COLOR,
        ),
        Joint(
            "THJ5",
            "palm",
            "thbase",
            (0.034, -0.00858, 0.029),
            (0, math.pi / 4, 0),
            (0, 0, -1),
            -1.0472,
            1.0472,
            5,
            4,
            "thumb_base",
        ),
    )
    add(
        Link(
            "thproximal",
            0.040,
            (0, 0, 0.019),
            solid_cylinder_inertia(0.040, 0.0105, 0.039),
            [capsule(0.0105, 0.009, 0.019)],
            FINGER_COLOR,
        ),
        Joint(
            "THJ4",
            "thbase",
            "thproximal",
            (0, 0, 0),
            (0, 0, 0),
            (1, 0, 0),
            0.0,
            1.2217,
            3,
            4,
            "thumb_base",
        ),
    )
    add(
        Link(
            "thhub",
            0.005,
            (0, 0, 0),
            solid_sphere_inertia(0.005, 0.011),
            [Shape("sphere", (0.011,))],
            FINGER_COLOR,
        ),
        Joint(
            "THJ3",
            "thproximal",
            "thhub",
            (0, 0, 0.038),
            (0, 0, 0),
            (1, 0, 0),
            -0.2094,
            0.2094,
            2,
            4,
            "thumb",
        ),
    )
    add(
        Link(
            "thmiddle",
            0.020,
            (0, 0, 0.016),
            solid_cylinder_inertia(0.020, 0.009, 0.04),
            [capsule(0.009, 0.009, 0.012), Shape("sphere", (0.010,), (0, 0, 0.03))],
            FINGER_COLOR,
        ),
        Joint(
            "THJ2",
            "thhub",
            "thmiddle",
            (0, 0, 0),
            (0, 0, 0),
            (0, -1, 0),
            -0.6981,
            0.6981,
            2,
            2,
            "thumb",
        ),
    )
    add(
        Link(
            "thdistal",
            0.017,
            (0, 0, 0.01375),
            solid_cylinder_inertia(0.017, 0.010, 0.032),
            [capsule_span(0.010, 0.003, 0.035), pad("th", 0.020, 0.010)],
            FINGER_COLOR,
        ),
        Joint(
            "THJ1",
            "thmiddle",
            "thdistal",
            (0, 0, 0.032),
            (0, 0, -HALF_PI),
            (1, 0, 0),
            J3_LOWER,
            HALF_PI,
            1,
            4,
            "thumb",
        ),
    )
    return links, joints, poses


def tip_frames():
    frames = [(f"{f}tip", f"{f}distal", TIP_Z) for f in FINGERS]
    frames.append(("thtip", "thdistal", THUMB_TIP_Z))
    return frames


# Links whose geometry overlaps near the palm by construction (the joint housings
# sit inside the palm in the real hand). Pairs that are not parent/child are not
# filtered by Drake automatically, so we declare them (ours).
PALM_GROUP = (
    "forearm",
    "wrist",
    "palm",
    "lfmetacarpal",
    "ffknuckle",
    "mfknuckle",
    "rfknuckle",
    "lfknuckle",
    "ffproximal",
    "mfproximal",
    "rfproximal",
    "lfproximal",
    "thbase",
    "thproximal",
    "thhub",
)


# The thumb's proximal capsule reaches past THJ3 into the middle link's capsule
# (two joints apart, so not filtered automatically).
THUMB_GROUP = ("thproximal", "thhub", "thmiddle")


def frame_xml(name: str, link: str, xyz) -> str:
    return (
        f'    <frame name="{name}" attached_to="{link}">\n'
        f'      <pose relative_to="{link}">{_v(xyz)} 0 0 0</pose>\n'
        "    </frame>"
    )


def filter_group_xml(name: str, members) -> str:
    lines = "\n".join(f"      <drake:member>{m}</drake:member>" for m in members)
    return (
        f'    <drake:collision_filter_group name="{name}">\n{lines}\n'
        f"      <drake:ignored_collision_filter_group>{name}"
        "</drake:ignored_collision_filter_group>\n"
        "    </drake:collision_filter_group>"
    )


def model_xml(
    model_name: str, generator: str, links, joints, poses, extra, proximity=PROXIMITY
) -> str:
    """The SDFormat document of one model: links, joints, then ``extra`` elements."""
    body = []
    for link in links:
        parent, xyz, rpy = poses.get(link.name, (None, (0, 0, 0), (0, 0, 0)))
        body.append(link_xml(link, parent, xyz, rpy, proximity))
    body += [joint_xml(j) for j in joints]
    body += list(extra)
    header = (
        '<?xml version="1.0"?>\n'
        f"<!-- Generated by {generator}; do not edit by hand. -->\n"
        '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">\n'
        f'  <model name="{model_name}">\n'
    )
    return header + "\n".join(body) + "\n  </model>\n</sdf>\n"


def make_sdf() -> str:
    links, joints, poses = build()
    extra = [frame_xml(name, link, (0, 0, z)) for name, link, z in tip_frames()]
    extra.append(filter_group_xml("palm_and_finger_bases", PALM_GROUP))
    extra.append(filter_group_xml("thumb_chain", THUMB_GROUP))
    return model_xml(MODEL_NAME, "models/shadow_hand/generate.py", links, joints, poses, extra)


def main():
    OUTPUT.write_text(make_sdf())
    print(f"wrote {OUTPUT}")


if __name__ == "__main__":
    main()
