"""The arm models, :func:`AddArm` and the simulated joint driver.

The driver has the shape of Drake's ``IiwaDriver`` (``manipulation_station``):
the station exports ``<arm>.position`` (in, rad) and ``<arm>.position_commanded``,
``.position_measured``, ``.velocity_estimated``, ``.state_estimated`` (out), so a
controller written against it drives a real arm's driver the same way. The
command is sampled every ``control_period``, clamped to the joint limits and
rate limited to each joint's speed limit, then tracked by the plant's PD
actuators (SAP). Gravity is compensated (off for the arm and the hand), as the
PA10's servo controller does.
"""

from __future__ import annotations

import dataclasses as dc
import math
from types import SimpleNamespace

import numpy as np

from handle_drake.base.models import add_package, package_url
from handle_drake.systems.hand_driver import PdHandDriver

__all__ = ["ARM_SPECS", "ArmSpec", "AddArm", "AddArmDriver", "ArmDriver", "ARM_INSTANCE",
           "ARM_SIGNALS", "arm_initial_position", "get_arm_spec"]

ARM_INSTANCE = "arm"
#: The arm's exported outputs (``arm.<signal>``), as a real arm's driver gives them.
ARM_SIGNALS = ("position_commanded", "position_measured", "velocity_estimated",
               "state_estimated")


@dc.dataclass(frozen=True)
class ArmSpec:
    name: str
    model_relative_path: str
    base_body: str
    flange_frame: str
    joint_names: tuple[str, ...]
    lower: tuple[float, ...]  # rad
    upper: tuple[float, ...]  # rad
    velocity: tuple[float, ...]  # rad/s
    kp: tuple[float, ...]  # N m / rad
    kd: tuple[float, ...]  # N m s / rad
    # Link lengths (m) for closed-form checks: base to shoulder, upper arm,
    # forearm, wrist to flange (models/pa10/README.md).
    lengths: tuple[float, ...] = ()
    # The arm's links (bodies) a camera may be fixed to (``X_PB.base_frame: arm::<link>``).
    links: tuple[str, ...] = ()


def _deg(*values):
    return tuple(math.radians(v) for v in values)


ARM_SPECS = {
    "pa10": ArmSpec(
        name="pa10",
        model_relative_path="pa10/pa10_6c.sdf",
        base_body="base",
        flange_frame="flange",
        joint_names=("S1", "S2", "E1", "E2", "W1", "W2"),
        lower=_deg(-177, -90, -137, -255, -165, -255),
        upper=_deg(177, 90, 137, 255, 165, 255),
        velocity=(1.0, 1.0, 2.0, 2 * math.pi, 2 * math.pi, 2 * math.pi),
        # Stiff servos: a 0.2 kg load 0.5 m out sags < 1 mrad at S2.
        kp=(4000.0, 4000.0, 2000.0, 400.0, 400.0, 200.0),
        kd=(300.0, 300.0, 120.0, 20.0, 20.0, 8.0),
        lengths=(0.317, 0.450, 0.480, 0.070),
        links=("base", "link1", "link2", "link3", "link4", "link5", "link6"),
    ),
    # Shadow's 4-DOF air-muscle arm (the Paris platform; models/shadow_arm/README.md):
    # limits and speeds [SR]; the gains are ours (within [SR]'s effort limits, 70, 100,
    # 50 and 30 N m, for a 0.05 rad error).
    "shadow_arm": ArmSpec(
        name="shadow_arm",
        model_relative_path="shadow_arm/shadow_arm.sdf",
        base_body="base",
        flange_frame="flange",
        joint_names=("ShoulderJRotate", "ShoulderJSwing", "ElbowJSwing", "ElbowJRotate"),
        lower=(-math.pi / 4, 0.0, 0.52, -math.pi / 2),
        upper=(math.pi / 2, math.pi / 2, 2.09439510239, math.pi / 2),
        velocity=(1.0, 1.0, 1.0, 1.0),
        kp=(1200.0, 1600.0, 800.0, 400.0),
        kd=(120.0, 120.0, 50.0, 20.0),
        # Base to shoulder, upper arm, elbow to flange (hypot of 0.131 and 0.080), no
        # wrist: the same closed-form meaning as the PA10's.
        lengths=(0.5405, 0.369, math.hypot(0.131, 0.080), 0.0),
        links=("base", "trunk", "upperarm", "lowerarm", "handsupport"),
    ),
}


def get_arm_spec(kind: str) -> ArmSpec:
    if kind not in ARM_SPECS:
        raise ValueError(f"unknown arm {kind!r}; expected one of {sorted(ARM_SPECS)}")
    return ARM_SPECS[kind]


def arm_initial_position(mount) -> np.ndarray:
    spec = get_arm_spec(mount.kind)
    if mount.initial_position:
        return np.asarray(mount.initial_position, dtype=float)
    return np.zeros(len(spec.joint_names))


def AddArm(plant, mount, hand_base_frame=None, name: str = ARM_INSTANCE):
    """Parses the ``mount``'s arm into ``plant`` (before Finalize), welds its base
    at ``mount.X_WB``, sets its servo gains and initial joint positions, and
    bolts ``hand_base_frame`` (if given) to its flange at ``mount.X_FH``.
    Gravity is turned off for the arm (the driver compensates it). Returns the
    arm's model instance."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.tree import JointActuatorIndex, PdControllerGains

    spec = get_arm_spec(mount.kind)
    parser = Parser(plant)
    add_package(parser)
    (instance,) = parser.AddModelsFromUrl(package_url(spec.model_relative_path))
    plant.RenameModelInstance(instance, name)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(spec.base_body, instance),
                     mount.X_WB.GetDeterministicValue())
    kp = mount.kp or spec.kp
    kd = mount.kd or spec.kd
    actuators = [plant.get_joint_actuator(JointActuatorIndex(i))
                 for i in range(plant.num_actuators())]
    by_joint = {a.joint().name(): a for a in actuators if a.model_instance() == instance}
    if sorted(by_joint) != sorted(spec.joint_names):
        raise RuntimeError(f"{spec.model_relative_path}: actuated joints {sorted(by_joint)} "
                           f"differ from {list(spec.joint_names)}")
    for i, joint_name in enumerate(spec.joint_names):
        by_joint[joint_name].set_controller_gains(PdControllerGains(p=kp[i], d=kd[i]))
    for joint_name, q in zip(spec.joint_names, arm_initial_position(mount), strict=True):
        plant.GetJointByName(joint_name, instance).set_default_angle(q)
    if hand_base_frame is not None:
        plant.WeldFrames(plant.GetFrameByName(spec.flange_frame, instance), hand_base_frame,
                         mount.X_FH.GetDeterministicValue())
    plant.set_gravity_enabled(instance, False)
    return instance


class ArmDriver(PdHandDriver):
    """The simulated arm driver: the hand driver's sampled, clamped command with
    one speed limit per joint (``spec.velocity``)."""

    def __init__(self, plant, instance, spec: ArmSpec, initial, control_period: float):
        names = SimpleNamespace(actuated_joint_names=spec.joint_names,
                                joint_names=spec.joint_names)
        super().__init__(plant, instance, names, initial, spec.lower, spec.upper,
                         max_joint_velocity=1.0, control_period=control_period)
        self._max_step = np.asarray(spec.velocity) * control_period


def AddArmDriver(builder, plant, mount, name: str = ARM_INSTANCE):
    """Adds the arm's driver to a station being built (after Finalize) and
    exports ``<name>.position`` and ``<name>.<signal>`` for :data:`ARM_SIGNALS`."""
    spec = get_arm_spec(mount.kind)
    instance = plant.GetModelInstanceByName(name)
    driver = builder.AddNamedSystem(
        f"{name}_driver",
        ArmDriver(plant, instance, spec, arm_initial_position(mount), mount.control_period))
    builder.Connect(plant.get_state_output_port(), driver.get_plant_state_input_port())
    builder.Connect(driver.GetOutputPort("desired_state"),
                    plant.get_desired_state_input_port(instance))
    builder.ExportInput(driver.get_command_input_port(), f"{name}.position")
    for signal in ARM_SIGNALS:
        builder.ExportOutput(driver.GetOutputPort(signal), f"{name}.{signal}")
    return driver
