#!/usr/bin/env python3
"""Generate ``bh8_280.sdf``: the Barrett BH8-280 hand from primitive shapes.

Run ``python models/barrett_hand/generate.py``; the generated file is committed
beside this script (a test checks it equals :func:`make_sdf`'s output).

Numbers: Barrett's BH8-series manual (D-H table of the fingers), Barrett's
published BH8-280 mass properties and jhu-lcsr/barrett_model
``models/hand.urdf.xacro`` (CAD-derived), as collected in
/work/shared/reference/hand_kinematics.md section 2; README.md gives the
source of every number. The SDF writer is the one of
``models/shadow_hand/generate.py`` (loaded from the file beside ours). What is
our own choice (effort and velocity limits, gains, inertias, link
cross-sections, the 45 degree distal bend within the 42-50 degree range) is
marked "ours" and listed in README.md.

Finger frames. Every finger is built in a local frame whose +y points away
from the palm centre (outward); the links run along their own +z, with their
palmar face on -y, and flexion is about +x, as on the Shadow hand. Zero
flexion is the real hand's fully open pose: the proximal joint frame is turned
-90 degrees about x (``FLEX_ZERO_RPY``), so at 0 the proximal link lies flat,
pointing radially outward at the height of the flexion axis, with its palmar
face up (the palm normal, +z); the distal link is bent 45 degrees up from it.
Positive flexion raises the finger toward the palm normal (vertical at pi/2)
and then over the palm (2.4435 rad = 140 degrees, 50 degrees past vertical).
This is the convention of jhu-lcsr/barrett_model (``med_joint`` at zero along
the knuckle's radial axis, ``dist_joint`` turned pi/4) and of the hand's
firmware, whose "open" (HO) position is 0. Sides as in Barrett's D-H table
(finger k's spread axis at r_k * 25 mm, r = -1, +1, 0 for F1, F2, F3; the
hand's pucks, libbarrett, GraspIt and OpenRAVE name the fingers the same
way): F1 at x = -0.025 with its spread axis along -z, F2 at x = +0.025 along
+z, F3 on +y. At spread 0 F1 and F2 face F3; spreading swings F1 toward -x and
F2 toward +x (mirror axes), and at spread pi both stand beside F3.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUTPUT = HERE / "bh8_280.sdf"
MODEL_NAME = "barrett_hand"


def _load_writer():
    path = HERE.parent / "shadow_hand" / "generate.py"
    spec = importlib.util.spec_from_file_location("handle_drake_shadow_generate", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


W = _load_writer()
Shape, Link, Joint = W.Shape, W.Link, W.Joint

# group: (kp [N m/rad], kd [N m s/rad], joint damping [N m s/rad], armature [kg m^2]) (ours)
GAINS = {
    "spread": (20.0, 0.6, 0.05, 1.0e-3),
    "prox": (20.0, 0.4, 0.05, 5.0e-4),
}
DISTAL_DAMPING = 0.01

SPREAD_AXIS_X = 0.025  # |x| of the F1/F2 spread axes (D-H Aw)
# (finger, side r_k of Barrett's D-H table): F1 at x = -0.025, spread axis -z;
# F2 at x = +0.025, spread axis +z.
SPREAD_SIDES = (("f1", -1.0), ("f2", 1.0))
SPREAD_AXIS_Z = 0.0415
FLEX_OUT = 0.05  # flexion axis, radially out from the spread axis (D-H A1)
FLEX_UP = 0.0339  # and up
F3_FLEX = (0.0, 0.05, 0.0754)
DISTAL_ALONG = 0.06994  # distal joint along the proximal link (barrett_model)
DISTAL_PALMAR = 0.003  # and toward its palmar side (barrett_model)
DISTAL_TIP = 0.050  # distal joint -> fingertip frame (barrett_model tip link, D-H A3)
DISTAL_TIP_END = 0.057  # end of the rounded tip (barrett_model: tip cylinder r 6.5 mm at 50.5 mm)
DISTAL_BEND = math.radians(45.0)  # fixed bend of the distal link (sheet: 42-50 deg)
# In the proximal link's frame (along +z, palmar face on -y).
DISTAL_JOINT_XYZ = (0.0, -DISTAL_PALMAR, DISTAL_ALONG)
# Proximal joint frame: the link's +z (along the finger) points outward (+y of the
# finger frame) and its palmar -y points up (+z) at zero flexion: the hand open flat.
FLEX_ZERO_RPY = (-math.pi / 2, 0.0, 0.0)
PROX_UPPER = math.radians(140.0)  # 2.4435 rad (D-H table, barrett_model)
DIST_UPPER = math.radians(48.0)  # covers PROX_UPPER / 3 = 0.8145 rad (barrett_model)

# Masses (kg) of Barrett's BH8-280 mass-properties page: the hand base (frame
# W, without the palm pad; it holds F3's fixed knuckle), link 1 (the spread
# knuckle of F1 and F2), link 2 (proximal), link 3 (distal). 1.188 kg in all;
# Barrett weighed the hand at 664 g (base) + 3 x 179 g (fingers) = 1.201 kg.
BASE_MASS = 0.59573
# The page's centre of mass of frame W, turned half a turn about z (F3 on +y here).
BASE_COM = (-5.1098e-5, 0.0050433, 0.036671)
KNUCKLE_MASS = 0.14109
PROXIMAL_MASS = 0.062139
DISTAL_MASS = 0.041377

FINGER_WIDTH = 0.022  # x extent of proximal and knuckle links (ours)
DISTAL_RADIUS = 0.009
PAD_SIZE = (0.014, 0.002, 0.030)

BASE_COLOR = (0.55, 0.55, 0.58, 1.0)
FINGER_COLOR = (0.3, 0.3, 0.32, 1.0)
MU = 1.0
PROXIMITY = W.proximity_xml(MU, 0.004)


def finger_links(prefix: str):
    """(proximal, distal) links of one finger in its local frame."""
    proximal = Link(
        f"{prefix}_proximal",
        PROXIMAL_MASS,
        (0, 0, DISTAL_ALONG / 2),
        W.solid_box_inertia(PROXIMAL_MASS, FINGER_WIDTH, 0.020, DISTAL_ALONG),
        [Shape("box", (FINGER_WIDTH, 0.020, 0.066), (0, 0, 0.037))],
        FINGER_COLOR,
    )
    r = DISTAL_RADIUS
    tip_end = DISTAL_TIP_END  # rounded end, 7 mm past the tip frame
    distal = Link(
        f"{prefix}_distal",
        DISTAL_MASS,
        (0, 0, 0.025),
        W.solid_cylinder_inertia(DISTAL_MASS, r, tip_end),
        [
            Shape("capsule", (r, tip_end - 2 * r), (0, 0, tip_end / 2)),
            # tactile pad on the palmar (-y) face, 0.5 mm proud of the capsule (ours)
            Shape(
                "box",
                PAD_SIZE,
                (0, -(r + 0.0005) + PAD_SIZE[1] / 2, 0.030),
                name=f"{prefix}_tip_pad",
            ),
        ],
        FINGER_COLOR,
    )
    return proximal, distal


def build():
    links, joints, poses = [], [], {}

    def add(link, joint):
        links.append(link)
        if joint is not None:
            joints.append(joint)
            poses[link.name] = (joint.parent, joint.xyz, joint.rpy)

    # Base: motor housing (cylinder r 0.045, the sheet's 0.042 base plus the
    # spacer up to the palm plate, ours), palm plate with its top at z 0.080, and
    # F3's fixed knuckle. Barrett's frame W mass includes that knuckle.
    add(
        Link(
            "bh_base",
            BASE_MASS,
            BASE_COM,
            W.solid_cylinder_inertia(BASE_MASS, 0.045, 0.08),
            [
                Shape("cylinder", (0.045, 0.064), (0, 0, 0.032)),
                Shape("box", (0.076, 0.046, 0.016), (0, 0, 0.072)),
                Shape("box", (FINGER_WIDTH, 0.030, 0.024), (0, 0.040, 0.070)),
            ],
            BASE_COLOR,
        ),
        None,
    )

    def joint(name, parent, child, xyz, rpy, axis, lower, upper, effort, velocity, group):
        return Joint(
            name,
            parent,
            child,
            xyz,
            rpy,
            axis,
            lower,
            upper,
            effort,
            velocity,
            group,
            gains=GAINS,
            unactuated_damping=DISTAL_DAMPING,
        )

    for p, sign in SPREAD_SIDES:
        # Knuckle frame on the spread axis, turned so that local +y points to world -y.
        add(
            Link(
                f"{p}_knuckle",
                KNUCKLE_MASS,
                (0, 0.03, 0.02),
                W.solid_box_inertia(KNUCKLE_MASS, FINGER_WIDTH, 0.06, 0.03),
                [Shape("box", (FINGER_WIDTH, 0.05, 0.026), (0, 0.032, 0.022))],
                BASE_COLOR,
            ),
            joint(
                f"{p}_spread",
                "bh_base",
                f"{p}_knuckle",
                (sign * SPREAD_AXIS_X, 0, SPREAD_AXIS_Z),
                (0, 0, math.pi),
                (0, 0, sign),
                0.0,
                math.pi,
                2.0,
                3.0,
                "spread" if p == "f1" else None,
            ),
        )
        proximal, distal = finger_links(p)
        add(
            proximal,
            joint(
                f"{p}_prox",
                f"{p}_knuckle",
                proximal.name,
                (0, FLEX_OUT, FLEX_UP),
                FLEX_ZERO_RPY,
                (1, 0, 0),
                0.0,
                PROX_UPPER,
                2.5,
                2.5,
                "prox",
            ),
        )
        add(
            distal,
            joint(
                f"{p}_dist",
                proximal.name,
                distal.name,
                DISTAL_JOINT_XYZ,
                (DISTAL_BEND, 0, 0),
                (1, 0, 0),
                0.0,
                DIST_UPPER,
                2.5,
                2.5,
                None,
            ),
        )

    proximal, distal = finger_links("f3")
    add(
        proximal,
        joint(
            "f3_prox",
            "bh_base",
            proximal.name,
            F3_FLEX,
            FLEX_ZERO_RPY,
            (1, 0, 0),
            0.0,
            PROX_UPPER,
            2.5,
            2.5,
            "prox",
        ),
    )
    add(
        distal,
        joint(
            "f3_dist",
            proximal.name,
            distal.name,
            DISTAL_JOINT_XYZ,
            (DISTAL_BEND, 0, 0),
            (1, 0, 0),
            0.0,
            DIST_UPPER,
            2.5,
            2.5,
            None,
        ),
    )
    return links, joints, poses


# The flexion hinges sit beside the palm plate; the proximal links' ends touch
# the housing by construction (ours: filtered, as the real hinge is).
BASE_GROUP = ("bh_base", "f1_knuckle", "f2_knuckle", "f1_proximal", "f2_proximal", "f3_proximal")


def make_sdf() -> str:
    links, joints, poses = build()
    extra = [W.frame_xml(f"f{i}_tip", f"f{i}_distal", (0, 0, DISTAL_TIP)) for i in (1, 2, 3)]
    extra.append(W.filter_group_xml("base_and_hinges", BASE_GROUP))
    return W.model_xml(
        MODEL_NAME, "models/barrett_hand/generate.py", links, joints, poses, extra, PROXIMITY
    )


def main():
    OUTPUT.write_text(make_sdf())
    print(f"wrote {OUTPUT}")


if __name__ == "__main__":
    main()
