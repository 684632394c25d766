"""Hand models and handle_drake.base.hands, against the public reference sheet.

The joint tables below are typed in from /work/shared/reference/hand_kinematics.md
(sections 1 and 2), independently of the generators, and the fingertip
positions are composed by hand from them. Simulations weld the hand base to
the world (the station owns mounts).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import Box
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import JointActuatorIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.base.hands import (
    HAND_SPECS,
    AddHand,
    actuated_position_limits,
    actuated_to_joint_positions,
    get_hand_spec,
    joint_position_indices,
    joint_to_actuated_positions,
    pad_geometry_ids,
)
from handle_drake.base.models import models_dir
from handle_drake.base.testing import load_file_module

PI = math.pi
HALF_PI = PI / 2
MODELS = Path(models_dir())

# ---------------------------------------------------------------------------
# The reference sheet, section 1 (Shadow, right hand, E-series).
# name: (parent, child, origin xyz, rpy, axis (child frame), lower, upper, effort, velocity)
SHADOW_SHEET = {
    "WRJ2": (
        "forearm",
        "wrist",
        (0, -0.010, 0.21301),
        (0, 0, 0),
        (0, 1, 0),
        -0.5236,
        0.1745,
        10,
        2,
    ),
    "WRJ1": ("wrist", "palm", (0, 0, 0.034), (0, 0, 0), (1, 0, 0), -0.6981, 0.4887, 30, 2),
    "LFJ5": (
        "palm",
        "lfmetacarpal",
        (-0.033, 0, 0.02071),
        (0, 0, 0),
        (0.573576, 0, 0.819152),
        0.0,
        0.7854,
        2,
        2,
    ),
    "THJ5": (
        "palm",
        "thbase",
        (0.034, -0.00858, 0.029),
        (0, PI / 4, 0),
        (0, 0, -1),
        -1.0472,
        1.0472,
        5,
        4,
    ),
    "THJ4": ("thbase", "thproximal", (0, 0, 0), (0, 0, 0), (1, 0, 0), 0.0, 1.2217, 3, 4),
    "THJ3": ("thproximal", "thhub", (0, 0, 0.038), (0, 0, 0), (1, 0, 0), -0.2094, 0.2094, 2, 4),
    "THJ2": ("thhub", "thmiddle", (0, 0, 0), (0, 0, 0), (0, -1, 0), -0.6981, 0.6981, 2, 2),
    "THJ1": (
        "thmiddle",
        "thdistal",
        (0, 0, 0.032),
        (0, 0, -HALF_PI),
        (1, 0, 0),
        -0.2618,
        1.5708,
        1,
        4,
    ),
}
_KNUCKLE = {
    "FF": ("palm", (0.033, 0, 0.095), (0, -1, 0)),
    "MF": ("palm", (0.011, 0, 0.099), (0, -1, 0)),
    "RF": ("palm", (-0.011, 0, 0.095), (0, 1, 0)),
    "LF": ("lfmetacarpal", (0, 0, 0.06579), (0, 1, 0)),
}
for _F, (_parent, _xyz, _axis) in _KNUCKLE.items():
    _f = _F.lower()
    SHADOW_SHEET[f"{_F}J4"] = (
        _parent,
        f"{_f}knuckle",
        _xyz,
        (0, 0, 0),
        _axis,
        -0.3491,
        0.3491,
        2,
        2,
    )
    SHADOW_SHEET[f"{_F}J3"] = (
        f"{_f}knuckle",
        f"{_f}proximal",
        (0, 0, 0),
        (0, 0, 0),
        (1, 0, 0),
        -0.2618,
        1.5708,
        2,
        2,
    )
    SHADOW_SHEET[f"{_F}J2"] = (
        f"{_f}proximal",
        f"{_f}middle",
        (0, 0, 0.045),
        (0, 0, 0),
        (1, 0, 0),
        0.0,
        1.5708,
        2,
        2,
    )
    SHADOW_SHEET[f"{_F}J1"] = (
        f"{_f}middle",
        f"{_f}distal",
        (0, 0, 0.025),
        (0, 0, 0),
        (1, 0, 0),
        0.0,
        1.5708,
        2,
        2,
    )
SHADOW_TIP_Z = {"fftip": 0.026, "mftip": 0.026, "rftip": 0.026, "lftip": 0.026, "thtip": 0.0275}
# Sheet masses (kg): forearm, wrist, palm, 4 x (knuckle, proximal, middle, distal + tip),
# lfmetacarpal, thumb (base, proximal, hub, middle, distal + tip).
SHADOW_MASS = (
    3.0
    + 0.1
    + 0.3
    + 4 * (0.008 + 0.030 + 0.017 + 0.013)
    + 0.030
    + (0.010 + 0.040 + 0.005 + 0.020 + 0.017)
)

# Section 2 (Barrett BH8-280): Barrett's BH8-280 mass-properties page, per link (kg):
# hand base (frame W, without palm pad; F3's fixed knuckle is part of it), the F1/F2
# spread knuckle (link 1), proximal (link 2), distal (link 3). Barrett weighed the
# hand at 664 g + 3 x 179 g = 1.201 kg.
BARRETT_MASS = 0.59573 + 2 * 0.14109 + 3 * (0.062139 + 0.041377)
BARRETT_WEIGHED = 0.664 + 3 * 0.179
PROX_UPPER = math.radians(140.0)
# Distal joint 69.94 mm along the proximal link and 3 mm to its palmar side (our link
# frames: along +z, palmar face on -y).
DISTAL_XYZ = (0, -0.003, 0.06994)


def Rx(a):
    return RotationMatrix.MakeXRotation(a).matrix()


def Ry(a):
    return RotationMatrix.MakeYRotation(a).matrix()


def Rz(a):
    return RotationMatrix.MakeZRotation(a).matrix()


def ez(length):
    return np.array([0.0, 0.0, length])


# ---------------------------------------------------------------------------
# Fixtures and helpers


class DrakeWarnings(logging.Handler):
    def __init__(self):
        super().__init__(level=logging.WARNING)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


@pytest.fixture
def drake_warnings():
    handler = DrakeWarnings()
    logger = logging.getLogger("drake")
    logger.addHandler(handler)
    yield handler.messages
    logger.removeHandler(handler)


def build(kind, time_step=1e-3, coupling_ratio=None, strict=True):
    """Diagram with the hand welded to the world; returns (diagram, plant, hand, spec)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=time_step, discrete_contact_approximation="sap"), builder
    )
    parser = Parser(builder)
    if strict:
        parser.SetStrictParsing()  # Drake parser warnings become errors
    hand = AddHand(plant, kind, coupling_ratio=coupling_ratio, parser=parser)
    spec = get_hand_spec(kind)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(spec.base_body, hand))
    plant.Finalize()
    return builder.Build(), plant, hand, spec


def simulate(kind, command, duration, time_step=1e-3, coupling_ratio=None, record_dt=None):
    """Simulates a constant PD command; returns (times, q in joint_names order)."""
    diagram, plant, hand, spec = build(kind, time_step, coupling_ratio)
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    command = np.asarray(command, dtype=float)
    plant.get_desired_state_input_port(hand).FixValue(
        plant_context, np.concatenate([command, np.zeros_like(command)])
    )
    index = joint_position_indices(plant, hand, spec)
    simulator = Simulator(diagram, context)
    times = np.arange(0.0, duration + 1e-12, record_dt or duration)
    q = []
    for t in times:
        simulator.AdvanceTo(t)
        q.append(plant.GetPositions(plant_context)[index])
    return times, np.array(q)


def actuators_of(plant, instance):
    """Actuators of ``instance`` in index order (works before Finalize)."""
    all_actuators = (
        plant.get_joint_actuator(JointActuatorIndex(i)) for i in range(plant.num_actuators())
    )
    return [a for a in all_actuators if a.model_instance() == instance]


def command_for(spec, **values):
    command = np.zeros(spec.num_actuated)
    for name, value in values.items():
        command[spec.actuated_joint_names.index(name)] = value
    return command


# ---------------------------------------------------------------------------
# Joint tables against the sheet


def test_shadow_joints_match_sheet():
    plant = MultibodyPlant(time_step=0.0)
    parser = Parser(plant)
    parser.SetStrictParsing()
    hand = parser.AddModels(MODELS / "shadow_hand/shadow_hand_right.sdf")[0]
    spec = get_hand_spec("shadow")
    assert plant.GetModelInstanceName(hand) == "shadow_hand"
    assert len(SHADOW_SHEET) == 24
    assert sorted(spec.joint_names) == sorted(SHADOW_SHEET)
    movable = [plant.get_joint(i) for i in plant.GetJointIndices(hand)]
    assert sorted(j.name() for j in movable) == sorted(SHADOW_SHEET)
    actuated = {a.joint().name(): a for a in actuators_of(plant, hand)}
    for name, (
        parent,
        child,
        xyz,
        rpy,
        axis,
        lower,
        upper,
        effort,
        velocity,
    ) in SHADOW_SHEET.items():
        joint = plant.GetJointByName(name, hand)
        assert joint.type_name() == "revolute", name
        assert joint.parent_body().name() == parent, name
        assert joint.child_body().name() == child, name
        X_PJ = joint.frame_on_parent().GetFixedPoseInBodyFrame()
        expected = RigidTransform(
            RollPitchYaw(np.array(rpy, dtype=float)), np.array(xyz, dtype=float)
        )
        assert X_PJ.IsNearlyEqualTo(expected, 1e-12), name
        # the joint frame is the child link frame, so the axis is in the child frame
        assert (
            joint.frame_on_child()
            .GetFixedPoseInBodyFrame()
            .IsNearlyEqualTo(RigidTransform(), 1e-12)
        ), name
        np.testing.assert_allclose(
            joint.revolute_axis(), np.array(axis) / np.linalg.norm(axis), atol=1e-6, err_msg=name
        )
        # the sheet rounds to 4 decimals (1.5708 is pi/2 in the model)
        assert joint.position_lower_limits()[0] == pytest.approx(lower, abs=5e-5), name
        assert joint.position_upper_limits()[0] == pytest.approx(upper, abs=5e-5), name
        assert joint.velocity_upper_limits()[0] == pytest.approx(velocity), name
        if name in ("FFJ1", "MFJ1", "RFJ1", "LFJ1"):
            assert name not in actuated, f"{name} is coupled to J2 and must not be actuated"
        else:
            assert actuated[name].effort_limit() == pytest.approx(effort), name
            assert actuated[name].has_controller(), name
    assert plant.num_actuators() == 20
    plant.Finalize()
    assert plant.CalcTotalMass(plant.CreateDefaultContext()) == pytest.approx(SHADOW_MASS)


def test_barrett_joints_match_sheet():
    plant = MultibodyPlant(time_step=0.0)
    parser = Parser(plant)
    parser.SetStrictParsing()
    hand = parser.AddModels(MODELS / "barrett_hand/bh8_280.sdf")[0]
    spec = get_hand_spec("barrett")
    expected = {
        # name: parent, child, xyz in parent, axis in child, lower, upper
        # Barrett's D-H table: F1's spread axis at x = -0.025, F2's at +0.025
        "f1_spread": ("bh_base", "f1_knuckle", (-0.025, 0, 0.0415), None, 0, PI),
        "f2_spread": ("bh_base", "f2_knuckle", (0.025, 0, 0.0415), None, 0, PI),
        "f1_prox": ("f1_knuckle", "f1_proximal", None, (1, 0, 0), 0, PROX_UPPER),
        "f2_prox": ("f2_knuckle", "f2_proximal", None, (1, 0, 0), 0, PROX_UPPER),
        "f3_prox": ("bh_base", "f3_proximal", (0, 0.05, 0.0754), (1, 0, 0), 0, PROX_UPPER),
        "f1_dist": ("f1_proximal", "f1_distal", DISTAL_XYZ, (1, 0, 0), 0, math.radians(48)),
        "f2_dist": ("f2_proximal", "f2_distal", DISTAL_XYZ, (1, 0, 0), 0, math.radians(48)),
        "f3_dist": ("f3_proximal", "f3_distal", DISTAL_XYZ, (1, 0, 0), 0, math.radians(48)),
    }
    assert sorted(spec.joint_names) == sorted(expected)
    for name, (parent, child, xyz, axis, lower, upper) in expected.items():
        joint = plant.GetJointByName(name, hand)
        assert joint.type_name() == "revolute"
        assert (joint.parent_body().name(), joint.child_body().name()) == (parent, child)
        if xyz is not None:
            np.testing.assert_allclose(
                joint.frame_on_parent().GetFixedPoseInBodyFrame().translation(), xyz, atol=1e-12
            )
        if axis is not None:
            np.testing.assert_allclose(joint.revolute_axis(), axis, atol=1e-12)
        assert joint.position_lower_limits()[0] == pytest.approx(lower, abs=1e-9)
        assert joint.position_upper_limits()[0] == pytest.approx(upper, abs=1e-9)
    # F1's spread axis points along -z of the palm, F2's along +z (mirror fingers)
    for name, sign in (("f1_spread", -1.0), ("f2_spread", 1.0)):
        joint = plant.GetJointByName(name, hand)
        R_BJ = joint.frame_on_parent().GetFixedPoseInBodyFrame().rotation()
        np.testing.assert_allclose(R_BJ @ joint.revolute_axis(), [0, 0, sign], atol=1e-12)
    # distal range covers the coupled proximal range
    assert math.radians(48) >= PROX_UPPER / 3
    assert [a.joint().name() for a in actuators_of(plant, hand)] == [
        "f1_spread",
        "f1_prox",
        "f2_prox",
        "f3_prox",
    ]
    plant.Finalize()
    total = plant.CalcTotalMass(plant.CreateDefaultContext())
    assert total == pytest.approx(BARRETT_MASS)
    assert abs(total - BARRETT_WEIGHED) <= 0.05 * BARRETT_WEIGHED
    for body, mass in (("bh_base", 0.59573), ("f1_knuckle", 0.14109), ("f2_knuckle", 0.14109)):
        assert plant.GetBodyByName(body, hand).default_mass() == pytest.approx(mass)
    for k in (1, 2, 3):
        assert plant.GetBodyByName(f"f{k}_proximal", hand).default_mass() == pytest.approx(0.062139)
        assert plant.GetBodyByName(f"f{k}_distal", hand).default_mass() == pytest.approx(0.041377)


@pytest.mark.parametrize("kind", ["shadow", "barrett"])
def test_generated_sdf_is_committed(kind):
    """The committed SDF equals its generator's output (regenerate after editing)."""
    folder = {"shadow": "shadow_hand", "barrett": "barrett_hand"}[kind]
    path = MODELS / folder / "generate.py"
    module = load_file_module(path, f"test_generate_{kind}")
    committed = (MODELS / get_hand_spec(kind).model_relative_path).read_text()
    assert module.make_sdf() == committed


# ---------------------------------------------------------------------------
# Forward kinematics composed by hand from the sheet


def shadow_tips_by_hand(q):
    """p_F(tip) of the five fingertips in the forearm frame, from the sheet.

    ``q`` maps joint names to angles; absent joints are 0. Rotations about the
    sheet's axes (all axes are unit vectors in the child frame).
    """

    def rot(name, axis):
        unit = np.array(axis, dtype=float) / np.linalg.norm(axis)
        return RotationMatrix(AngleAxis(q.get(name, 0.0), unit)).matrix()

    R_FW = rot("WRJ2", (0, 1, 0))
    p_FW = np.array([0, -0.010, 0.21301])
    R_FP = R_FW @ rot("WRJ1", (1, 0, 0))
    p_FP = p_FW + R_FW @ ez(0.034)
    tips = {}
    for F, (_, xyz, axis) in _KNUCKLE.items():
        R, p = R_FP, p_FP
        if F == "LF":
            p = p + R @ np.array([-0.033, 0, 0.02071])
            R = R @ rot("LFJ5", (0.573576, 0, 0.819152))
        p = p + R @ np.array(xyz)
        R = R @ rot(f"{F}J4", axis) @ rot(f"{F}J3", (1, 0, 0))
        p = p + R @ ez(0.045)
        R = R @ rot(f"{F}J2", (1, 0, 0))
        p = p + R @ ez(0.025)
        R = R @ rot(f"{F}J1", (1, 0, 0))
        tips[f"{F.lower()}tip"] = (p + R @ ez(0.026), R)
    p = p_FP + R_FP @ np.array([0.034, -0.00858, 0.029])
    R = R_FP @ Ry(PI / 4) @ rot("THJ5", (0, 0, -1)) @ rot("THJ4", (1, 0, 0))
    p = p + R @ ez(0.038)
    R = R @ rot("THJ3", (1, 0, 0)) @ rot("THJ2", (0, -1, 0))
    p = p + R @ ez(0.032)
    R = R @ Rz(-HALF_PI) @ rot("THJ1", (1, 0, 0))
    tips["thtip"] = (p + R @ ez(0.0275), R)
    return tips


def shadow_plant_context():
    plant = MultibodyPlant(time_step=0.0)
    hand = Parser(plant).AddModels(MODELS / "shadow_hand/shadow_hand_right.sdf")[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("forearm", hand))
    plant.Finalize()
    return plant, hand, plant.CreateDefaultContext()


def test_shadow_fingertips_at_zero_pose():
    plant, hand, context = shadow_plant_context()
    palm = np.array([0, -0.010, 0.21301 + 0.034])
    finger = 0.045 + 0.025 + 0.026
    thumb_R = Ry(PI / 4) @ Rz(-HALF_PI)
    expected = {
        "fftip": palm + [0.033, 0, 0.095 + finger],
        "mftip": palm + [0.011, 0, 0.099 + finger],
        "rftip": palm + [-0.011, 0, 0.095 + finger],
        "lftip": palm + [-0.033, 0, 0.02071 + 0.06579 + finger],
        "thtip": palm
        + [0.034, -0.00858, 0.029]
        + Ry(PI / 4) @ ez(0.038 + 0.032)
        + thumb_R @ ez(0.0275),
    }
    assert expected["fftip"][2] == pytest.approx(0.43801)
    assert expected["thtip"] == pytest.approx(
        palm + [0.034 + 0.0975 / math.sqrt(2), -0.00858, 0.029 + 0.0975 / math.sqrt(2)]
    )
    for name, p in expected.items():
        X_WT = plant.GetFrameByName(name, hand).CalcPoseInWorld(context)
        np.testing.assert_allclose(X_WT.translation(), p, atol=1e-9, err_msg=name)
    X_WT = plant.GetFrameByName("thtip", hand).CalcPoseInWorld(context)
    np.testing.assert_allclose(X_WT.rotation().matrix(), thumb_R, atol=1e-9)
    # the thumb's THJ1 and THJ2 axes are parallel (palm -y) at the zero pose
    for joint in ("THJ1", "THJ2"):
        J = plant.GetJointByName(joint, hand)
        axis_W = J.frame_on_child().CalcPoseInWorld(context).rotation() @ J.revolute_axis()
        np.testing.assert_allclose(axis_W, [0, -1, 0], atol=1e-9)


def test_shadow_fingertips_at_bent_pose():
    plant, hand, context = shadow_plant_context()
    rng = np.random.default_rng(7)
    spec = get_hand_spec("shadow")
    q = rng.uniform(spec.joint_lower_limits, spec.joint_upper_limits)
    plant.SetPositions(context, hand, _to_plant_order(plant, hand, spec, q))
    expected = shadow_tips_by_hand(dict(zip(spec.joint_names, q, strict=True)))
    for name, (p, R) in expected.items():
        X_WT = plant.GetFrameByName(name, hand).CalcPoseInWorld(context)
        np.testing.assert_allclose(X_WT.translation(), p, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(X_WT.rotation().matrix(), R, atol=1e-9, err_msg=name)


def test_flexion_moves_fingertips_to_the_palmar_side():
    """+FFJ3 curls the finger toward the palm (-y); +THJ1 moves the thumb tip to -y of thdistal."""
    plant, hand, context = shadow_plant_context()
    p0 = plant.GetFrameByName("fftip", hand).CalcPoseInWorld(context).translation()
    plant.GetJointByName("FFJ3", hand).set_angle(context, 0.5)
    p1 = plant.GetFrameByName("fftip", hand).CalcPoseInWorld(context).translation()
    # rotation about +x of the knuckle by 0.5 rad, lever 0.096 m
    np.testing.assert_allclose(
        p1 - p0, [0, -0.096 * math.sin(0.5), -0.096 * (1 - math.cos(0.5))], atol=1e-9
    )
    # thumb: rotation about thdistal's +x (world -y at the zero pose), lever 0.0275 m
    R_WD = plant.GetBodyByName("thdistal", hand).EvalPoseInWorld(context).rotation().matrix()
    t0 = plant.GetFrameByName("thtip", hand).CalcPoseInWorld(context).translation()
    plant.GetJointByName("THJ1", hand).set_angle(context, 0.5)
    t1 = plant.GetFrameByName("thtip", hand).CalcPoseInWorld(context).translation()
    np.testing.assert_allclose(
        R_WD.T @ (t1 - t0),
        [0, -0.0275 * math.sin(0.5), -0.0275 * (1 - math.cos(0.5))],
        atol=1e-9,
    )


def _to_plant_order(plant, hand, spec, q):
    """Positions of ``hand`` in the plant's order from a joint_names-ordered vector."""
    q_plant = np.zeros(plant.num_positions(hand))
    offset = min(plant.GetJointByName(n, hand).position_start() for n in spec.joint_names)
    for name, value in zip(spec.joint_names, q, strict=True):
        q_plant[plant.GetJointByName(name, hand).position_start() - offset] = value
    return q_plant


def _homogeneous(R=None, p=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = p
    return T


def _rpy(roll, pitch, yaw):
    """URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return Rz(yaw) @ Ry(pitch) @ Rx(roll)


def barrett_reference_tip(finger: str, spread: float, prox: float) -> np.ndarray:
    """Fingertip of ``finger`` in the palm frame from the BH8-280's reference chain.

    Written out from the references, not from our SDF, in jhu-lcsr/barrett_model's
    frames (each link along its own x, joint axes along z, flexion turns x toward
    +y, the palmar side); F3 on +y. Barrett's D-H table: finger k's spread axis at
    r_k * 25 mm, r = (-1, +1) for (F1, F2), F1's along -z and F2's along +z, 41.5 mm
    above the base; flexion axis 50 mm out from it (A1) and 33.9 mm up; F3's at
    (0, 0.05, 0.0754). Distal joint 69.94 mm along the proximal link and 3 mm to its
    palmar side, turned pi/4; fingertip 50 mm along the distal link (A3). The
    distal follows the proximal at 1/3 (libbarrett's 125 / 375 ratios).
    """
    dist = prox / 3.0
    if finger in ("f1", "f2"):
        r = -1.0 if finger == "f1" else 1.0
        T = _homogeneous(_rpy(0, 0, -PI / 2), (r * 0.025, 0.0, 0.0415))
        T = T @ _homogeneous(Rz(r * spread))  # axis r * z: F1 about -z, F2 about +z
        T = T @ _homogeneous(_rpy(PI / 2, 0, 0), (0.05, 0.0, 0.0339))
    else:
        T = _homogeneous(_rpy(PI / 2, 0, PI / 2), (0.0, 0.05, 0.0754))
    T = T @ _homogeneous(Rz(prox))
    T = T @ _homogeneous(_rpy(0, 0, PI / 4), (0.06994, 0.003, 0.0))
    T = T @ _homogeneous(Rz(dist))
    return (T @ np.array([0.05, 0.0, 0.0, 1.0]))[:3]


def test_barrett_reference_chain_sanity():
    """The written-out chain itself: the open hand, by hand."""
    s45 = math.sqrt(0.5)
    # F3 open: 0.05 + 0.06994 + 0.05 cos 45 out, 0.003 + 0.05 sin 45 above its axis
    np.testing.assert_allclose(
        barrett_reference_tip("f3", 0.0, 0.0),
        [0, 0.05 + 0.06994 + 0.05 * s45, 0.0754 + 0.003 + 0.05 * s45], atol=1e-12)
    # F1 on x < 0 and F2 on x > 0, both toward -y; spreading moves them apart
    f1, f2 = barrett_reference_tip("f1", 0.0, 0.0), barrett_reference_tip("f2", 0.0, 0.0)
    np.testing.assert_allclose(f2, f1 * np.array([-1, 1, 1]), atol=1e-12)  # mirror images
    assert f1[0] == pytest.approx(-0.025) and f2[0] == pytest.approx(0.025)
    assert f1[1] == pytest.approx(-(0.05 + 0.06994 + 0.05 * s45))
    assert barrett_reference_tip("f1", 0.5, 0.0)[0] < -0.025
    assert barrett_reference_tip("f2", 0.5, 0.0)[0] > 0.025


def test_barrett_fingertips_follow_the_reference_chain():
    """All three tip frames against the reference chain over spread 0..pi and
    flexion 0..2.0 rad (distal = proximal / 3): worst error <= 1 mm."""
    plant = MultibodyPlant(time_step=0.0)
    hand = Parser(plant).AddModels(MODELS / "barrett_hand/bh8_280.sdf")[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("bh_base", hand))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    spec = get_hand_spec("barrett")
    worst = 0.0
    for spread in np.linspace(0.0, PI, 7):
        for prox in np.linspace(0.0, 2.0, 9):
            q = dict(f1_spread=spread, f2_spread=spread, f1_prox=prox, f2_prox=prox,
                     f3_prox=prox, f1_dist=prox / 3, f2_dist=prox / 3, f3_dist=prox / 3)
            plant.SetPositions(
                context, hand, _to_plant_order(plant, hand, spec, [q[n] for n in spec.joint_names])
            )
            for finger in ("f1", "f2", "f3"):
                p_model = plant.GetFrameByName(f"{finger}_tip", hand).CalcPoseInWorld(
                    context).translation()
                p_ref = barrett_reference_tip(finger, spread, prox)
                worst = max(worst, float(np.linalg.norm(p_model - p_ref)))
    assert worst <= 1e-3, f"worst fingertip error {worst * 1e3:.3f} mm"


# ---------------------------------------------------------------------------
# Geometry: pads, no self-contact at rest, hydroelastic contact with soft objects


@pytest.mark.parametrize("kind", ["shadow", "barrett"])
def test_pads_face_the_palmar_side_and_stand_proud(kind):
    diagram, plant, hand, spec = build(kind)
    scene_graph = diagram.GetSubsystemByName("scene_graph")
    inspector = scene_graph.model_inspector()
    pads = pad_geometry_ids(plant, hand, spec, inspector)
    assert len(pads) == len(spec.fingertip_frames)
    for (body_name, _), pad in zip(spec.pad_geometries, pads, strict=True):
        body = plant.GetBodyByName(body_name, hand)
        shape = inspector.GetShape(pad)
        assert isinstance(shape, Box)
        X_BG = inspector.GetPoseInFrame(pad)
        pad_face_y = X_BG.translation()[1] - shape.depth() / 2  # Box depth is its y size
        others = [g for g in plant.GetCollisionGeometriesForBody(body) if g != pad]
        for other in others:
            other_shape = inspector.GetShape(other)
            lowest = inspector.GetPoseInFrame(other).translation()[1] - other_shape.radius()
            assert pad_face_y < lowest, (
                "the pad must be the first surface touched on the palmar side"
            )
        assert X_BG.translation()[1] < 0


@pytest.mark.parametrize("kind", ["shadow", "barrett"])
def test_no_self_contact_at_rest(kind):
    diagram, plant, hand, spec = build(kind)
    context = diagram.CreateDefaultContext()
    query = plant.get_geometry_query_input_port().Eval(plant.GetMyContextFromRoot(context))
    assert query.ComputePointPairPenetration() == []


def test_soft_object_gets_hydroelastic_contact_on_the_pad():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(
            time_step=1e-3,
            discrete_contact_approximation="sap",
            contact_model="hydroelastic_with_fallback",
        ),
        builder,
    )
    hand = AddHand(plant, "shadow")
    spec = get_hand_spec("shadow")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("forearm", hand))
    radius = 0.01
    sphere = Parser(plant).AddModelsFromString(
        f"""<?xml version="1.0"?>
<sdf version="1.9" xmlns:drake="http://drake.mit.edu"><model name="ball"><link name="ball">
  <inertial><mass>0.01</mass></inertial>
  <collision name="ball"><geometry><sphere><radius>{radius}</radius></sphere></geometry>
    <drake:proximity_properties><drake:compliant_hydroelastic/>
      <drake:hydroelastic_modulus>1e5</drake:hydroelastic_modulus>
      <drake:mesh_resolution_hint>0.005</drake:mesh_resolution_hint>
    </drake:proximity_properties></collision></link></model></sdf>""",
        "sdf",
    )[0]
    # A ball 1 mm into the first finger's pad from the palmar side (pad face at y = -0.009 of
    # ffdistal, whose origin is at p_W below in the zero pose), held by the world.
    p_WD = np.array([0.033, -0.010, 0.21301 + 0.034 + 0.095 + 0.045 + 0.025])
    p_WS = p_WD + [0, -0.009 - radius + 0.001, 0.019]
    plant.WeldFrames(
        plant.world_frame(), plant.GetFrameByName("ball", sphere), RigidTransform(p_WS)
    )
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    # a discrete plant reports the contacts of its last step
    Simulator(diagram, context).AdvanceTo(plant.time_step())
    results = plant.get_contact_results_output_port().Eval(plant.GetMyContextFromRoot(context))
    pad = pad_geometry_ids(plant, hand, spec, scene_graph.model_inspector())[0]
    ids = [
        {
            results.hydroelastic_contact_info(i).contact_surface().id_M(),
            results.hydroelastic_contact_info(i).contact_surface().id_N(),
        }
        for i in range(results.num_hydroelastic_contacts())
    ]
    assert any(pad in pair for pair in ids), "the pad must touch the soft ball hydroelastically"


# ---------------------------------------------------------------------------
# Simulation


@pytest.mark.parametrize("kind", ["shadow", "barrett"])
def test_random_actuation_stays_finite_without_warnings(kind, drake_warnings):
    diagram, plant, hand, spec = build(kind)
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    lower, upper = actuated_position_limits(spec)
    rng = np.random.default_rng(0)
    port = plant.get_desired_state_input_port(hand)
    simulator = Simulator(diagram, context)
    for k in range(5):  # a new random command every 20 ms, 0.1 s in all
        command = rng.uniform(lower, upper)
        port.FixValue(plant_context, np.concatenate([command, np.zeros(spec.num_actuated)]))
        simulator.AdvanceTo(0.02 * (k + 1))
        assert np.all(np.isfinite(plant.GetPositionsAndVelocities(plant_context)))
    assert drake_warnings == []


@pytest.mark.parametrize("ratio", [1.0, 1.1])
def test_shadow_coupler_holds(ratio):
    spec = get_hand_spec("shadow")
    command = command_for(spec, FFJ2=0.9, MFJ2=1.2, RFJ2=1.3, LFJ2=0.5)
    _, q = simulate("shadow", command, 0.4, coupling_ratio=ratio)
    for f in ("FF", "MF", "RF", "LF"):
        j1, j2 = q[-1][spec.joint_names.index(f"{f}J1")], q[-1][spec.joint_names.index(f"{f}J2")]
        assert j1 == pytest.approx(ratio * j2, abs=1e-4), f
        assert j2 == pytest.approx(command[spec.actuated_joint_names.index(f"{f}J2")], abs=0.02)


@pytest.mark.parametrize("time_step", [1e-3, 5e-3])
def test_pd_reaches_command_without_overshoot(time_step):
    """Steps of 0.8-1.0 rad on free joints settle within 0.02 rad by 0.3 s and do not overshoot."""
    spec = get_hand_spec("shadow")
    steps = dict(WRJ1=0.4, FFJ3=1.0, FFJ4=-0.3, THJ4=1.0, THJ5=0.8, LFJ5=0.6)
    command = command_for(spec, **steps)
    times, q = simulate("shadow", command, 0.4, time_step=time_step, record_dt=0.01)
    settled = times >= 0.3 - 1e-9
    for name, target in steps.items():
        trace = q[:, spec.joint_names.index(name)]
        assert np.all(np.abs(trace[settled] - target) < 0.02), (name, trace[settled][0])
        # no overshoot: monotone up to 5 mrad (wrist motion drags LFJ5 by ~3 mrad)
        assert np.max(np.sign(target) * (trace - trace[-1])) < 0.005, f"{name} overshoots"


def test_barrett_couplings_hold_in_simulation():
    spec = get_hand_spec("barrett")
    # small flexion: with the 45 deg distal bend, F1 and F2 tips meet over the palm
    # when both spread and flexion are large (a real collision, not a PD failure)
    command = command_for(spec, f1_spread=0.5, f1_prox=0.3, f2_prox=0.25, f3_prox=0.35)
    _, q = simulate("barrett", command, 0.5)
    value = dict(zip(spec.joint_names, q[-1], strict=True))
    assert value["f2_spread"] == pytest.approx(value["f1_spread"], abs=1e-4)
    for i in (1, 2, 3):
        assert value[f"f{i}_dist"] == pytest.approx(value[f"f{i}_prox"] / 3, abs=1e-4)
    np.testing.assert_allclose(
        [value["f1_spread"], value["f1_prox"], value["f2_prox"], value["f3_prox"]],
        [0.5, 0.3, 0.25, 0.35],
        atol=0.02,
    )


def test_two_hands_in_one_plant():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap"), builder
    )
    left = AddHand(plant, "shadow", model_instance_name="first")
    right = AddHand(plant, "shadow", coupling_ratio=1.1, model_instance_name="second")
    assert plant.GetModelInstanceName(left) == "first"
    assert plant.GetModelInstanceName(right) == "second"
    assert plant.num_actuators() == 40
    with pytest.raises(ValueError, match="already has a model named 'first'"):
        AddHand(plant, "barrett", model_instance_name="first")


# ---------------------------------------------------------------------------
# Spec and vector helpers


def test_specs_sizes_and_orders():
    shadow, barrett = HAND_SPECS["shadow"], HAND_SPECS["barrett"]
    assert (shadow.num_joints, shadow.num_actuated) == (24, 20)
    assert (barrett.num_joints, barrett.num_actuated) == (8, 4)
    assert " ".join(shadow.actuated_joint_names) == (
        "WRJ2 WRJ1 FFJ4 FFJ3 FFJ2 MFJ4 MFJ3 MFJ2 RFJ4 RFJ3 RFJ2 LFJ5 LFJ4 LFJ3 LFJ2 "
        "THJ5 THJ4 THJ3 THJ2 THJ1"
    )
    assert " ".join(shadow.joint_names[:6]) == "WRJ2 WRJ1 FFJ4 FFJ3 FFJ2 FFJ1"
    assert shadow.joint_names[-5:] == ("THJ5", "THJ4", "THJ3", "THJ2", "THJ1")
    kp, kd = shadow.pd_gains
    assert kp.shape == kd.shape == (20,) and np.all(kp > 0) and np.all(kd > 0)


def test_actuated_to_joint_positions_and_back():
    spec = get_hand_spec("shadow")
    command = np.linspace(0.1, 0.5, 20)
    q = actuated_to_joint_positions(spec, command, 1.1)
    value = dict(zip(spec.joint_names, q, strict=True))
    for f in ("FF", "MF", "RF", "LF"):
        assert value[f"{f}J1"] == pytest.approx(1.1 * value[f"{f}J2"])
    np.testing.assert_array_equal(joint_to_actuated_positions(spec, q), command)
    barrett = get_hand_spec("barrett")
    qb = actuated_to_joint_positions(barrett, [0.3, 0.9, 0.6, 1.2])
    np.testing.assert_allclose(qb, [0.3, 0.9, 0.3, 0.3, 0.6, 0.2, 1.2, 0.4])


def test_effective_limits_respect_the_coupling():
    spec = get_hand_spec("shadow")
    lower, upper = actuated_position_limits(spec, 1.1)
    j2 = spec.actuated_joint_names.index("FFJ2")
    assert upper[j2] == pytest.approx(HALF_PI / 1.1)
    assert lower[j2] == 0.0
    _, upper_c6 = actuated_position_limits(spec, 1.0)
    assert upper_c6[j2] == pytest.approx(HALF_PI)
    q = actuated_to_joint_positions(spec, upper, 1.1)
    assert np.all(q <= spec.joint_upper_limits + 1e-12)


# ---------------------------------------------------------------------------
# Bad input


def test_unknown_hand_names_valid_ones():
    with pytest.raises(
        ValueError, match=r"unknown hand 'allegro'; expected one of \['barrett', 'shadow'\]"
    ):
        get_hand_spec("allegro")
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap"), builder
    )
    with pytest.raises(ValueError, match="unknown hand"):
        AddHand(plant, "allegro")


@pytest.mark.parametrize("ratio", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_coupling_ratio(ratio):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap"), builder
    )
    with pytest.raises(ValueError, match="coupling_ratio"):
        AddHand(plant, "shadow", coupling_ratio=ratio)
    with pytest.raises(ValueError, match="coupling_ratio"):
        actuated_to_joint_positions(get_hand_spec("shadow"), np.zeros(20), ratio)


def test_other_bad_input():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="sap"), builder
    )
    with pytest.raises(TypeError, match="coupling_ratio"):
        AddHand(plant, "shadow", coupling_ratio="1.1")
    with pytest.raises(ValueError, match="fixed"):
        AddHand(plant, "barrett", coupling_ratio=1.1)
    with pytest.raises(ValueError, match="expected a vector of size 20, got shape"):
        actuated_to_joint_positions(get_hand_spec("shadow"), np.zeros(19))
    with pytest.raises(ValueError, match="finite"):
        joint_to_actuated_positions(get_hand_spec("barrett"), [0, 0, 0, np.nan, 0, 0, 0, 0])
    tamsi, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=1e-3, discrete_contact_approximation="tamsi"),
        DiagramBuilder(),
    )
    with pytest.raises(ValueError, match="SAP"):
        AddHand(tamsi, "shadow")
    plant.Finalize()
    with pytest.raises(ValueError, match="before plant.Finalize"):
        AddHand(plant, "shadow")
