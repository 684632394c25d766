"""WristDriver: the floating wrist's command and measurement, against closed form and physics."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from handle_drake.scenario import LoadScenario
from handle_drake.station import AddPlantModels
from handle_drake.systems.hand_driver import WRIST_JOINTS, WristDriver, pose_to_wrist_joints

START = np.array([0.1, -0.05, 0.3, np.pi, 0.0, 0.2])  # [x y z roll pitch yaw]
PERIOD = 0.005


def _wrist(command=None):
    """Plant (a Barrett hand on the floating wrist, nothing else) + WristDriver [+ command]."""
    scenario = LoadScenario(data="""
hand: {kind: barrett, mount: !FloatingWrist {}}
object: null
table: null
""")
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    hand = AddPlantModels(plant, scenario)
    plant.Finalize()
    wrist = plant.GetModelInstanceByName("wrist")
    # The hand's PD actuators hold it at zero (SAP needs their desired state).
    hold = builder.AddSystem(ConstantVectorSource(np.zeros(2 * plant.num_actuated_dofs(hand))))
    builder.Connect(hold.get_output_port(), plant.get_desired_state_input_port(hand))
    driver = builder.AddSystem(WristDriver(plant, wrist, START, control_period=PERIOD))
    builder.Connect(plant.get_state_output_port(), driver.get_plant_state_input_port())
    builder.Connect(driver.GetOutputPort("desired_state"),
                    plant.get_desired_state_input_port(wrist))
    if command is not None:
        source = builder.AddSystem(ConstantVectorSource(command))
        builder.Connect(source.get_output_port(), driver.get_pose_input_port())
    diagram = builder.Build()
    return diagram, plant, wrist, driver


def test_pose_measured_reads_the_wrist_joints_back_exactly():
    diagram, plant, wrist, driver = _wrist()
    context = diagram.CreateDefaultContext()
    pose = np.array([0.2, 0.1, -0.3, 0.4, -0.6, 1.2])
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = plant.GetPositions(plant_context)
    for name, value in zip(WRIST_JOINTS, pose_to_wrist_joints(pose), strict=True):
        q[plant.GetJointByName(name, wrist).position_start()] = value
    plant.SetPositions(plant_context, q)
    measured = driver.GetOutputPort("pose_measured").Eval(driver.GetMyContextFromRoot(context))
    np.testing.assert_array_equal(measured, pose)


def test_an_unconnected_command_holds_the_initial_pose():
    diagram, plant, wrist, driver = _wrist()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(3 * PERIOD)
    desired = driver.GetOutputPort("desired_state").Eval(
        driver.GetMyContextFromRoot(simulator.get_context()))
    # [q_d in actuator order; zero velocities]; the actuators follow WRIST_JOINTS.
    np.testing.assert_array_equal(desired[:6], pose_to_wrist_joints(START))
    np.testing.assert_array_equal(desired[6:], np.zeros(6))


def test_a_non_finite_command_is_ignored():
    diagram, plant, wrist, driver = _wrist(np.full(6, np.nan))
    simulator = Simulator(diagram)
    simulator.AdvanceTo(3 * PERIOD)
    desired = driver.GetOutputPort("desired_state").Eval(
        driver.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_array_equal(desired[:6], pose_to_wrist_joints(START))


def test_the_wrist_settles_on_the_commanded_pose():
    """PD tracking of a constant pose (gravity is off on the wrist and hand): the
    measured pose converges to the command."""
    target = np.array([0.15, 0.05, 0.25, np.pi - 0.1, 0.05, -0.3])
    diagram, plant, wrist, driver = _wrist(target)
    simulator = Simulator(diagram)
    plant.SetPositions(plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()),
                       wrist, pose_to_wrist_joints(START))
    simulator.AdvanceTo(1.5)
    measured = driver.GetOutputPort("pose_measured").Eval(
        driver.GetMyContextFromRoot(simulator.get_context()))
    np.testing.assert_allclose(measured, target, atol=1e-3)


def test_a_wrong_initial_pose_is_named():
    scenario_plant = _wrist()[1:3]
    with pytest.raises(ValueError, match="initial pose: expected 6 values"):
        WristDriver(*scenario_plant, [0.0, 0.0, 0.0])
