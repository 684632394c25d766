"""MakeHandStation: one function from a scenario to a diagram, sim or hardware.

Both branches export the same ports (see ``docs/ARCHITECTURE.md``), so every
controller, trial and notebook is written once and runs against simulation
or the real hand.

Simulation ports (``nq`` joints, ``nu`` actuated joints of the hand):

================================  =====  ========================  ==========================
port                              dir    size                      units / frame
================================  =====  ========================  ==========================
``hand.position``                 in     nu                        rad, actuated joint order
``hand.position_commanded``       out    nu                        rad (rate-limited command)
``hand.position_measured``        out    nq                        rad, ``HandSpec.joint_names``
``hand.velocity_estimated``       out    nq                        rad/s
``hand.state_estimated``          out    2 nq                      positions then velocities
``hand.tactile``                  out    fingertips                N, normal force per fingertip
``wrist.pose``                    in     6                         ``[x y z r p y]`` (m, rad)
``wrist.pose_measured``           out    6                         same (floating wrist only)
``object.pose``                   out    ``RigidTransform``        ``X_WO``
``object.spatial_velocity``       out    ``SpatialVelocity``       ``V_WO`` in world
``object.position``               out    3                         m, ``p_WO``
``object.acceleration``           out    3                         m/s^2, sensor frame (*)
``object.acceleration_counts``    out    3                         device counts (*)
``object.roll_pitch``             out    2                         rad, from gravity (*)
``object.at_rest``                out    1                         1.0 at rest (*)
``object.free_fall``              out    1                         1.0 in free fall (*)
``object.slip``                   out    1                         1.0 while slipping (*)
``contact_results``               out    ``ContactResults``        world
``query_object``                  out    ``QueryObject``
``applied_spatial_force``         in     forces on bodies          the plant's (optional)
``body_poses``                    out    ``vector<RigidTransform>``  ``X_WB`` per body
``plant_state``                   out    plant nq + nv
``midi_controller.control_positions``  out  controls                m / rad (with a MIDI controller)
``midi_controller.midi``          out    ``MidiBatch``             MIDI the controller sent
``hand.taxels``                   out    pads x cells              Pa, taxel pressures (**)
``object.pose_estimated``         out    ``RigidTransform``        ``X_WO`` from touch (**)
``object.pose_covariance``        out    36                        6 x 6, [rotvec, p] (**)
``object.pose_quality``           out    2                         pads in contact, RMS m (**)
``object.pose_detected``          in     ``RigidTransform``        a camera's ``X_WO`` (**)
================================  =====  ========================  ==========================

(*) only with an ``object.accelerometer`` in the scenario (also on hardware,
read through evdev); see ``handle_drake.devices.accelerometer``.
(**) only with ``hand.taxels`` in the scenario (the estimator's with ``estimator: true``;
on hardware ``hand.taxels`` plays ``hand.taxels.recording``); see
``handle_drake.devices.taxels``.

The diagram's subsystems are named ``plant``, ``scene_graph``, ``hand_driver``,
``wrist_driver``, ``tactile``, ``object_pose`` and (a free object) ``object_position``;
:func:`GetPlant` returns the plant.
"""

from __future__ import annotations

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.multibody.tree import (
    PdControllerGains,
    PrismaticJoint,
    QuaternionFloatingJoint,
    RevoluteJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Demultiplexer
from pydrake.visualization import ApplyVisualizationConfig

from handle_drake.base.hands import (
    AddHand,
    actuated_position_limits,
    actuated_to_joint_positions,
    get_hand_spec,
    set_effort_limits,
)
from handle_drake.base.port_names import HAND, HAND_COMMAND, HAND_SIGNALS, WRIST
from handle_drake.devices.accelerometer.wiring import (
    AddSimulatedInstruments,
    WithHardwareInstruments,
    instrument_X_OS,
)
from handle_drake.devices.arm.model import AddArm, AddArmDriver
from handle_drake.devices.camera.sensors import AddCameras
from handle_drake.devices.can_hand.config import driver_config
from handle_drake.devices.can_hand.driver import AddCanHandDriver
from handle_drake.devices.can_hand.layout import hand_layout
from handle_drake.devices.midi.wiring import AddMidiControllerModel, AddMidiControllerSystems
from handle_drake.devices.taxels.wiring import (
    AddPoseEstimator,
    AddTaxelMeshcat,
    AddTaxelPlayback,
    AddTaxels,
)
from handle_drake.geometry.objects import (
    BODY_NAME,
    AddObject,
    AddTable,
    dimensions,
    resting_height,
)
from handle_drake.scenario import (
    Arm,
    CanHandDriver,
    FixedMount,
    FloatingWrist,
    Scenario,
    SimHandDriver,
    is_bare,
    object_spec,
    validate_scenario,
)
from handle_drake.scene.jointed import AddBareObject, BareObject, FilterObjectBase, ThreadJoint
from handle_drake.scene.plant import AddSceneModels, ExportSceneObjects
from handle_drake.systems.hand_driver import (
    MEASURED_OUTPUTS,
    WRIST_JOINTS,
    HandDriverDiagram,
    PdHandDriver,
    WristDriver,
    WristDriverDiagram,
    rpy_pose6,
)
from handle_drake.systems.tactile import (
    BodyPoseSelector,
    FingertipTactile,
    HandJointsToPlantPositions,
)

__all__ = [
    "MakeHandStation",
    "MakeHardwareStation",
    "GetPlant",
    "hand_initial_command",
    "object_body",
    "object_initial_pose",
    "set_default_hand_positions",
]

#: The simulated station's outputs of the table above (cameras, scene objects and the
#: MIDI controller add their own).
STATION_OUTPUTS = (
    *(f"{HAND}.{s}" for s in HAND_SIGNALS), "wrist.pose_measured",
    *(f"object.{s}" for s in ("pose", "spatial_velocity", "position", "acceleration",
                              "acceleration_counts", "roll_pitch", "at_rest", "free_fall",
                              "slip", "joint_position")),
    "contact_results", "query_object", "body_poses", "plant_state")

HAND_INSTANCE = HAND
WRIST_INSTANCE = WRIST
OBJECT_INSTANCE = "object"


def MakeHandStation(scenario: Scenario, meshcat=None, hardware: bool = False,
                    finite_commands: bool = False, outputs=None):
    """Builds the station diagram for ``scenario``.

    Args:
        scenario: a validated :class:`Scenario` (``LoadScenario`` validates).
        meshcat: an optional ``pydrake.geometry.Meshcat`` to draw into.
        hardware: build the interface to the real hand (the scenario's driver
            must then be a ``CanHandDriver``); the plant is used only for
            visualisation.
        finite_commands: the caller connects ``hand.position`` (and ``wrist.pose``) to
            commands that are finite by construction (planned or validated before the
            run: a scenario's keyframe script, an in-hand trial's frames). The simulated
            drivers are then Drake primitives (:class:`HandDriverDiagram`,
            :class:`WristDriverDiagram`: the same commands, no Python call per control
            period) instead of the Python drivers that hold on a non-finite or
            unconnected command.
        outputs: the station outputs the caller reads (simulation only; None, the
            default: all). Given, the systems feeding only other outputs are left out:
            the fingertip sensor (``hand.tactile``), the measured-state selectors of a
            :class:`HandDriverDiagram` (``hand.position_measured``,
            ``hand.velocity_estimated``, ``hand.state_estimated``; the first alone: one
            selector) and of a :class:`WristDriverDiagram` (``wrist.pose_measured``), the
            object's pose selector and position split (``object.pose``,
            ``object.spatial_velocity``, ``object.position``): every system costs the
            simulator work at every step.
            Outputs needing no system of their own (the plant's, the commanded
            position) and the scenario's devices are always there. A name that is no
            station output is refused; one this scenario lacks is absent.
    """
    validate_scenario(scenario)
    if hardware:
        if not isinstance(scenario.driver, CanHandDriver):
            raise ValueError(
                "hardware=True needs a !CanHandDriver driver in the scenario, got "
                f"{type(scenario.driver).__name__}"
            )
        station = MakeHardwareStation(scenario, meshcat=meshcat)
        if scenario.object is not None and scenario.object.accelerometer is not None:
            station = WithHardwareInstruments(station, scenario)
        return station
    if not isinstance(scenario.driver, SimHandDriver):
        raise ValueError(
            "a simulated station needs a !SimHandDriver driver, got "
            f"{type(scenario.driver).__name__}"
            "; pass hardware=True to drive a CAN hand"
        )

    builder = DiagramBuilder()
    # Drake's config as the scenario gives it (scenario.default_plant_config:
    # SAP, point contact, outputs computed on demand).
    plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)
    hand = AddPlantModels(plant, scenario)
    plant.Finalize()
    wanted = _Outputs(outputs)
    _add_hand_systems(builder, plant, hand, scenario, finite_commands, wanted)
    if isinstance(scenario.hand.mount, Arm):
        AddArmDriver(builder, plant, scenario.hand.mount)
    if scenario.objects:
        ExportSceneObjects(builder, plant, scenario)
    if isinstance(scenario.hand.mount, FloatingWrist):
        _add_wrist_driver(builder, plant, scenario, finite_commands, wanted)
    if scenario.object is not None:
        _add_object_systems(builder, plant, scenario, wanted, scene_graph)
    builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
    # external forces on bodies (e.g. an object's weight reversed: the in-hand held test)
    builder.ExportInput(plant.get_applied_spatial_force_input_port(), "applied_spatial_force")
    builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")
    builder.ExportOutput(plant.get_body_poses_output_port(), "body_poses")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    if scenario.cameras:
        AddCameras(builder, plant, scene_graph, scenario, hand)
    if scenario.midi_controller is not None:
        AddMidiControllerSystems(builder, plant, scenario)
    _add_visualization(builder, plant, scene_graph, meshcat, scenario)  # with a meshcat
    _add_taxel_systems(builder, plant, scene_graph, hand, scenario, meshcat)
    diagram = builder.Build()
    diagram.set_name("hand_station")
    wanted.check(diagram)
    return diagram


class _Outputs:
    """Which of the station's outputs to build (:func:`MakeHandStation`'s ``outputs``)."""

    def __init__(self, names):
        if names is not None and (isinstance(names, str) or not all(
                isinstance(n, str) for n in names)):
            raise ValueError(f"outputs: expected a collection of port names, got {names!r}")
        self._names = None if names is None else frozenset(names)
        self._left_out = set()

    def __call__(self, *names) -> bool:
        """Whether any of ``names`` is read; those not are noted as left out."""
        if self._names is None or not self._names.isdisjoint(names):
            return True
        self._left_out.update(names)
        return False

    def check(self, diagram) -> None:
        if self._names is None:
            return
        built = {diagram.get_output_port(i).get_name()
                 for i in range(diagram.num_output_ports())}
        # a documented output this scenario lacks (no object, no wrist) is simply absent
        unknown = sorted(self._names - built - self._left_out - set(STATION_OUTPUTS))
        if unknown:
            raise ValueError(f"outputs: no station output is named {unknown[0]!r}; this "
                             f"scenario's station has {sorted(built | self._left_out)}")


def _add_hand_systems(builder, plant, hand, scenario: Scenario,
                      finite_commands: bool = False, wanted=None) -> None:
    """The simulated hand driver and the fingertip sensors; exports the ``hand.*`` ports
    (those ``wanted`` reads: :class:`_Outputs`)."""
    wanted = wanted or _Outputs(None)
    spec = get_hand_spec(scenario.hand.kind)
    lower, upper = actuated_position_limits(spec, scenario.hand.coupling_ratio)
    initial = hand_initial_command(scenario)
    set_default_hand_positions(plant, hand, spec, initial, scenario.hand.coupling_ratio)

    # the Python driver computes its measured outputs itself (no systems to leave out)
    options = {"measured": [s for s in MEASURED_OUTPUTS if wanted(f"{HAND}.{s}") or (
        s == "position_measured" and _estimating(scenario))]} if finite_commands else {}
    driver = builder.AddNamedSystem(
        "hand_driver",
        (HandDriverDiagram if finite_commands else PdHandDriver)(
            plant, hand, spec, initial, lower, upper,
            max_joint_velocity=scenario.driver.max_joint_velocity,
            control_period=scenario.driver.control_period, **options,
        ),
    )
    if driver.HasInputPort("plant_state"):
        builder.Connect(plant.get_state_output_port(), driver.get_plant_state_input_port())
    builder.Connect(driver.GetOutputPort("desired_state"), plant.get_desired_state_input_port(hand))
    builder.ExportInput(driver.get_command_input_port(), f"{HAND}.{HAND_COMMAND}")

    tactile = None
    if wanted(f"{HAND}.tactile"):
        tips = [plant.GetFrameByName(name, hand).body() for name in spec.fingertip_frames]
        tactile = builder.AddNamedSystem("tactile", FingertipTactile(plant, tips))
        builder.Connect(plant.get_contact_results_output_port(),
                        tactile.get_contact_results_input_port())
    # The port contract (handle_drake.base.port_names), as the hardware branch exports it.
    for signal in HAND_SIGNALS:
        source = tactile if signal == "tactile" else driver
        if source is not None and source.HasOutputPort(signal):
            builder.ExportOutput(source.GetOutputPort(signal), f"{HAND}.{signal}")


def _add_wrist_driver(builder, plant, scenario: Scenario,
                      finite_commands: bool = False, wanted=None) -> None:
    """The floating wrist's driver; exports ``wrist.pose`` and ``wrist.pose_measured``
    (that one when ``wanted`` reads it: :class:`_Outputs`)."""
    wanted = wanted or _Outputs(None)
    wrist = plant.GetModelInstanceByName(WRIST_INSTANCE)
    # the Python driver computes pose_measured itself (no system to leave out)
    options = {"measured": wanted("wrist.pose_measured") or _estimating(scenario)} \
        if finite_commands else {}
    wrist_driver = builder.AddNamedSystem(
        "wrist_driver",
        (WristDriverDiagram if finite_commands else WristDriver)(
            plant, wrist, rpy_pose6(scenario.hand.mount.X_WB.GetDeterministicValue()),
            control_period=scenario.driver.control_period, **options),
    )
    if wrist_driver.HasInputPort("plant_state"):
        builder.Connect(plant.get_state_output_port(),
                        wrist_driver.get_plant_state_input_port())
    builder.Connect(wrist_driver.GetOutputPort("desired_state"),
                    plant.get_desired_state_input_port(wrist))
    builder.ExportInput(wrist_driver.get_pose_input_port(), "wrist.pose")
    if wrist_driver.HasOutputPort("pose_measured"):
        builder.ExportOutput(wrist_driver.GetOutputPort("pose_measured"), "wrist.pose_measured")


def _add_object_systems(builder, plant, scenario: Scenario, wanted=None,
                        scene_graph=None) -> None:
    """The object's pose selector (``object.*`` ports; those ``wanted`` reads:
    :class:`_Outputs`), its accelerometer and its joint's systems, if any."""
    wanted = wanted or _Outputs(None)
    position = None
    if wanted("object.position"):
        position = _free_body_position(builder, plant, object_body(plant))
    if wanted("object.pose", "object.spatial_velocity") or (
            position is None and wanted("object.position")):
        selector = builder.AddNamedSystem("object_pose", BodyPoseSelector(object_body(plant)))
        builder.Connect(plant.get_body_poses_output_port(), selector.GetInputPort("body_poses"))
        builder.Connect(plant.get_body_spatial_velocities_output_port(),
                        selector.GetInputPort("body_spatial_velocities"))
        for name in ("pose", "spatial_velocity") + (("position",) if position is None else ()):
            if wanted(f"object.{name}"):
                builder.ExportOutput(selector.GetOutputPort(name), f"object.{name}")
    if position is not None:
        builder.ExportOutput(position, "object.position")
    if scenario.object.accelerometer is not None:
        AddSimulatedInstruments(builder, plant, scenario, object_body(plant),
                                object_spec(scenario))
    if scenario.object.joint is not None:
        _add_object_joint(builder, plant, scene_graph, wanted)


def _add_object_joint(builder, plant, scene_graph, wanted) -> None:
    """An object on a joint (``object.joint``): its friction actuator's reference (0), the
    object and its base kept from colliding, and ``object.joint_position`` (rad) when
    ``wanted``."""
    body = object_body(plant)
    instance = body.model_instance()
    bodies = [plant.get_body(i) for i in plant.GetBodyIndices(instance)]
    if len(bodies) > 1:  # the welded base (the bottle): the thread is the joint
        FilterObjectBase(plant, scene_graph, body, bodies[1])
    zero = builder.AddNamedSystem("object_joint_reference", ConstantVectorSource(np.zeros(2)))
    builder.Connect(zero.get_output_port(), plant.get_desired_state_input_port(instance))
    if wanted("object.joint_position"):
        split = builder.AddNamedSystem("object_joint_state", Demultiplexer([1, 1]))
        builder.Connect(plant.get_state_output_port(instance), split.get_input_port())
        builder.ExportOutput(split.get_output_port(0), "object.joint_position")


def _estimating(scenario: Scenario) -> bool:
    """Whether the scenario asks for the object's pose estimated from touch (it reads the
    measured hand joints and wrist pose)."""
    return scenario.hand.taxels is not None and scenario.hand.taxels.estimator


def _add_taxel_systems(builder, plant, scene_graph, hand, scenario: Scenario, meshcat) -> None:
    """The taxel arrays (``hand.taxels``), their Meshcat drawing and, when the scenario
    asks, the object's pose estimator fed by the station's measured ports only."""
    config = scenario.hand.taxels
    if config is None:
        return
    seed = config.seed if config.seed is not None else scenario.random_seed
    sensor = AddTaxels(builder, plant, scene_graph, hand, config, seed)
    if meshcat is not None:
        AddTaxelMeshcat(builder, plant, sensor, meshcat, scenario.visualization.publish_period)
    if config.estimator:
        mount = scenario.hand.mount
        wrist = builder.GetSubsystemByName("wrist_driver") \
            if isinstance(mount, FloatingWrist) else None
        # the object's accelerometer, when it has one (added before: _add_object_systems)
        instrumented = scenario.object.accelerometer is not None
        AddPoseEstimator(
            builder, sensor, config, scenario.hand.kind, scenario.hand.coupling_ratio,
            object_spec(scenario), object_initial_pose(scenario),
            builder.GetSubsystemByName("hand_driver").GetOutputPort("position_measured"),
            hand_pose=None if wrist is None else wrist.GetOutputPort("pose_measured"),
            X_WB=None if wrist is not None else mount.X_WB.GetDeterministicValue(),
            roll_pitch=builder.GetSubsystemByName("object_accelerometer").GetOutputPort(
                "roll_pitch") if instrumented else None,
            X_OS=instrument_X_OS(scenario, object_spec(scenario)) if instrumented else None)


def _free_body_position(builder, plant, body):
    """``p_WB`` of a free body as a copy out of the plant's state, or None.

    For a body whose model instance has one joint, a quaternion floating joint from the
    world frame to the body frame (no offset frames), ``X_WB`` is the joint's ``X_FM`` and
    its translation is the joint's ``q[4:7]`` (``q = [qw qx qy qz x y z]``): a
    ``Demultiplexer`` of the instance's state output port gives the same numbers, bit for
    bit, as the body's pose, with no Python call (a logger samples ``object.position`` at
    100 Hz). Anything else (welded, offset frames, other joints) returns None: the caller
    keeps :class:`BodyPoseSelector`'s ``position``.
    """
    instance = body.model_instance()
    joints = [plant.get_joint(i) for i in plant.GetJointIndices(instance)]
    if (len(joints) != 1 or not isinstance(joints[0], QuaternionFloatingJoint)
            or joints[0].frame_on_parent().index() != plant.world_frame().index()
            or joints[0].frame_on_child().index() != body.body_frame().index()
            or plant.num_positions(instance) != 7 or plant.num_velocities(instance) != 6):
        return None
    split = builder.AddNamedSystem("object_position", Demultiplexer([4, 3, 6]))
    builder.Connect(plant.get_state_output_port(instance), split.get_input_port())
    return split.get_output_port(1)


def AddPlantModels(plant, scenario: Scenario):
    """Adds hand, mount, table and object to an unfinalized plant; returns the hand instance."""
    hand = AddHand(plant, scenario.hand.kind, coupling_ratio=scenario.hand.coupling_ratio,
                   model_instance_name=HAND_INSTANCE)
    spec = get_hand_spec(scenario.hand.kind)
    base_frame = plant.GetBodyByName(spec.base_body, hand).body_frame()
    mount = scenario.hand.mount
    if isinstance(mount, FixedMount):
        plant.WeldFrames(plant.world_frame(), base_frame, mount.X_WB.GetDeterministicValue())
    elif isinstance(mount, Arm):

        AddArm(plant, mount, base_frame)
        plant.set_gravity_enabled(hand, False)
    else:
        _add_floating_wrist(plant, base_frame, mount)
        plant.set_gravity_enabled(hand, False)

    set_effort_limits(plant, hand, scenario.hand.effort_limits, scenario.hand.effort_scale)
    if scenario.table is not None:
        AddTable(plant, top_height=scenario.table.top_height,
                 size=(scenario.table.size_x, scenario.table.size_y))
    if scenario.object is not None and is_bare(scenario.object):
        o = scenario.object
        AddBareObject(plant, BareObject(
            diameter=o.size, length=dimensions(object_spec(scenario))["height"], mass=o.mass,
            mu=o.mu, X_WO=object_initial_pose(scenario), point_stiffness=o.point_stiffness,
            joint=o.joint, names=_bare_names(o)))
    elif scenario.object is not None:
        AddObject(plant, object_spec(scenario), name=OBJECT_INSTANCE,
                  hydroelastic=scenario.plant_config.contact_model != "point")
        if scenario.object.fixed:
            plant.WeldFrames(plant.world_frame(), object_body(plant).body_frame(),
                             object_initial_pose(scenario))
        else:
            plant.SetDefaultFloatingBaseBodyPose(object_body(plant),
                                                 object_initial_pose(scenario))
    if scenario.objects or scenario.sorting_box is not None:

        AddSceneModels(plant, scenario)
    if scenario.midi_controller is not None:
        AddMidiControllerModel(plant, scenario)
    return hand


def _bare_names(o) -> tuple:
    """The plant's names of a bare object: instance, body, base, joint, joint frame."""
    joint = o.joint if o.joint is not None else ThreadJoint()
    base = joint.base.name if joint.base is not None else "base"
    return (OBJECT_INSTANCE, BODY_NAME, base, joint.name, f"{OBJECT_INSTANCE}_mouth")


def object_initial_pose(scenario: Scenario) -> RigidTransform:
    """``X_WO`` at the start; ``on_table`` puts the object on the table top."""
    X_WO = scenario.object.X_WO.GetDeterministicValue()
    if scenario.object.on_table:
        top = scenario.table.top_height if scenario.table is not None else 0.0

        height = resting_height(object_spec(scenario))
        p = X_WO.translation().copy()
        p[2] = top + height
        X_WO = RigidTransform(X_WO.rotation(), p)
    return X_WO


def object_body(plant):
    instance = plant.GetModelInstanceByName(OBJECT_INSTANCE)
    bodies = plant.GetBodyIndices(instance)
    return plant.get_body(bodies[0])


def _add_floating_wrist(plant, base_frame, mount: FloatingWrist) -> None:
    wrist = plant.AddModelInstance(WRIST_INSTANCE)
    # Light links between the six joints; the arm they stand for is gravity
    # compensated, so their mass only sets the wrist's dynamics.
    inertia = SpatialInertia(0.1, np.zeros(3), UnitInertia.SolidSphere(0.02))
    parent = plant.world_frame()
    axes = [np.array(a, dtype=float) for a in
            ([1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 1, 0], [1, 0, 0])]
    for i, (name, axis) in enumerate(zip(WRIST_JOINTS, axes, strict=True)):
        child = plant.AddRigidBody(f"{name}_link", wrist, inertia).body_frame()
        if i < 3:
            joint = PrismaticJoint(name, parent, child, axis, -2.0, 2.0, 0.0)
            gains = PdControllerGains(p=mount.translation_kp, d=mount.translation_kd)
        else:
            joint = RevoluteJoint(name, parent, child, axis, 0.0)
            gains = PdControllerGains(p=mount.rotation_kp, d=mount.rotation_kd)
        joint = plant.AddJoint(joint)
        actuator = plant.AddJointActuator(name, joint)
        actuator.set_controller_gains(gains)
        parent = child
    # Welded, so that all six joints and actuators belong to the wrist instance.
    plant.WeldFrames(parent, base_frame, RigidTransform())
    plant.set_gravity_enabled(wrist, False)
    # Default joint positions give the mount's initial pose.
    x, y, z, roll, pitch, yaw = rpy_pose6(mount.X_WB.GetDeterministicValue())
    for name, value in zip(WRIST_JOINTS, (x, y, z, yaw, pitch, roll), strict=True):
        plant.GetJointByName(name, wrist).set_default_positions([value])


def hand_initial_command(scenario: Scenario) -> np.ndarray:
    """The first command: ``hand.initial_position`` (0 elsewhere), within limits."""
    spec = get_hand_spec(scenario.hand.kind)
    lower, upper = actuated_position_limits(spec, scenario.hand.coupling_ratio)
    command = np.array([scenario.hand.initial_position.get(name, 0.0)
                        for name in spec.actuated_joint_names])
    return np.clip(command, lower, upper)


def set_default_hand_positions(plant, hand, spec, command, coupling_ratio) -> None:
    """Sets the ``hand`` instance's joints' default positions to the actuated ``command``
    (one value per actuated joint of ``spec``, coupled joints by ``coupling_ratio``)."""
    q = actuated_to_joint_positions(spec, command, coupling_ratio)
    for name, value in zip(spec.joint_names, q, strict=True):
        plant.GetJointByName(name, hand).set_default_positions([value])


def _add_visualization(builder, plant, scene_graph, meshcat, scenario) -> None:
    # Drake's ApplyVisualizationConfig adds the Meshcat (and contact) visualisers the
    # scenario's VisualizationConfig asks for; its LCM messages go to a null bus.
    # Nothing without a Meshcat.
    if meshcat is None:
        return
    meshcat.Delete()
    ApplyVisualizationConfig(scenario.visualization, builder, plant=plant,
                             scene_graph=scene_graph, meshcat=meshcat,
                             lcm=DrakeLcm("memq://null"))


def GetPlant(station):
    """The station's MultibodyPlant."""
    return station.GetSubsystemByName("plant")


def MakeHardwareStation(scenario: Scenario, meshcat=None):
    """The hardware station for ``scenario`` (its driver must be a ``!CanHandDriver``):
    the CAN hand behind the bus server, with the simulated station's ``hand.*``
    ports (:mod:`handle_drake.base.port_names`; the simulation-only ports do not exist here).
    With a Meshcat, a plant of the hand is built only to draw the measured joints.

    The driver's TCP client starts connecting at once; the diagram's
    ``hand_driver`` subsystem reports the link on ``connection_state``.
    Only a fixed mount is supported: the CAN hand has no wrist actuator.
    """

    if not isinstance(scenario.hand.mount, FixedMount):
        raise ValueError(
            "hardware station: the CAN hand has no wrist actuator; expected a FixedMount, "
            f"got {type(scenario.hand.mount).__name__}"
        )
    config = driver_config(scenario.driver)
    spec = get_hand_spec(scenario.hand.kind)
    layout = hand_layout(spec, scenario.hand.coupling_ratio)
    for name in scenario.hand.initial_position:
        if name not in layout.actuated_joint_names:
            raise ValueError(f"hand.initial_position: {name!r} is not an actuated joint")
    initial = np.clip([scenario.hand.initial_position.get(n, 0.0)
                       for n in layout.actuated_joint_names],
                      layout.command_lower, layout.command_upper)

    builder = DiagramBuilder()
    driver = AddCanHandDriver(builder, config, layout, initial_position=initial)
    if scenario.hand.taxels is not None:
        if not scenario.hand.taxels.recording:
            raise ValueError("hardware station: hand.taxels needs a recording (the taxel "
                             "stream to play back) until a real taxel driver exists")
        AddTaxelPlayback(builder, scenario.hand.taxels)
    if meshcat is not None:
        _add_hardware_visualization(builder, driver, scenario, spec, meshcat)
    diagram = builder.Build()
    diagram.set_name("hand_station_hardware")
    return diagram


def _add_hardware_visualization(builder, driver, scenario, spec, meshcat) -> None:
    from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role, SceneGraph
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import ApplyMultibodyPlantConfig, MultibodyPlant
    from pydrake.systems.rendering import MultibodyPositionToGeometryPose

    scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
    # Not added to the diagram: it only converts positions to geometry poses.
    plant = MultibodyPlant(time_step=scenario.plant_config.time_step)
    ApplyMultibodyPlantConfig(scenario.plant_config, plant)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    hand = AddHand(plant, scenario.hand.kind, coupling_ratio=scenario.hand.coupling_ratio,
                   parser=Parser(plant), model_instance_name="hand")
    plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(spec.base_body, hand).body_frame(),
                     scenario.hand.mount.X_WB.GetDeterministicValue())
    plant.Finalize()

    scatter = builder.AddNamedSystem(
        "visualization_positions", HandJointsToPlantPositions(plant, hand, spec.joint_names))
    to_pose = builder.AddNamedSystem("to_geometry_pose", MultibodyPositionToGeometryPose(plant))
    builder.Connect(driver.GetOutputPort("position_measured"), scatter.get_input_port())
    builder.Connect(scatter.get_output_port(), to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))
    MeshcatVisualizer.AddToBuilder(
        builder, scene_graph, meshcat,
        MeshcatVisualizerParams(publish_period=scenario.visualization.publish_period,
                                role=Role.kIllustration, prefix="illustration"))
