"""F1 is the same physical finger on the CAN hand and in simulation.

Barrett's D-H table puts finger k's spread axis at r_k * 25 mm with r = -1 for
F1 and +1 for F2; the hand's pucks (F1, F2, F3, spread), libbarrett, GraspIt
and OpenRAVE name the fingers the same way. So a command for F1 must move the
finger on the palm's x < 0 side, whether it goes through the CAN hand (setpoint
signal ``SP_f1_prox``, what the real hand's F1 puck receives) or to the
simulated hand.
"""

import uuid

import can
import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from handle_drake.base.hands import AddHand, get_hand_spec
from handle_drake.devices.can_hand.config import (
    BusConfig,
    CanFirmwareConfig,
    CanHandDriverConfig,
    CanServerConfig,
)
from handle_drake.devices.can_hand.driver import AddCanHandDriver
from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
from handle_drake.devices.can_hand.frames import load_database
from handle_drake.devices.can_hand.layout import hand_layout
from handle_drake.devices.can_hand.server import CanBusServer
from handle_drake.scenario import LoadScenario
from handle_drake.station import GetPlant, MakeHandStation
from handle_drake.systems.tactile import HandJointsToPlantPositions

FINGERS = ("f1", "f2", "f3")
F1_FLEXION = 1.0  # rad


def hand_plant():
    """The Barrett model welded at its palm frame, as the hardware station draws it."""
    plant = MultibodyPlant(time_step=1e-3)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
    hand = AddHand(plant, "barrett", parser=Parser(plant), model_instance_name="hand")
    plant.WeldFrames(plant.world_frame(), plant.GetBodyByName("bh_base", hand).body_frame())
    plant.Finalize()
    return plant, hand


def tips_in_palm(plant, hand, context):
    base = plant.GetBodyByName("bh_base", hand).body_frame()
    return {f: plant.GetFrameByName(f"{f}_tip", hand).CalcPose(context, base).translation()
            for f in FINGERS}


def moved_finger(open_tips, tips):
    """The one finger whose tip moved (the others stay within 1 mm), and how far."""
    displacement = {f: float(np.linalg.norm(tips[f] - open_tips[f])) for f in FINGERS}
    finger = max(displacement, key=displacement.get)
    assert displacement[finger] > 0.03, displacement
    assert all(d < 1e-3 for f, d in displacement.items() if f != finger), displacement
    return finger


def f1_command(layout):
    command = np.zeros(layout.nu)
    command[layout.actuated_joint_names.index("f1_prox")] = F1_FLEXION
    return command


def test_model_puts_f1_at_negative_x_and_f2_at_positive_x():
    plant, hand = hand_plant()
    tips = tips_in_palm(plant, hand, plant.CreateDefaultContext())
    assert tips["f1"][0] == pytest.approx(-0.025) and tips["f2"][0] == pytest.approx(0.025)
    assert tips["f3"][1] > 0 > tips["f1"][1]  # F3 faces F1 and F2 across the palm


def test_f1_command_through_the_can_hand_moves_the_finger_at_negative_x():
    layout = hand_layout("barrett")
    bus = BusConfig("virtual", f"test-{uuid.uuid4().hex}")
    firmware_config = CanFirmwareConfig(hand_kind="barrett", bus=bus, rate=500.0,
                                        natural_frequency=8.0, position_noise=0.0,
                                        tactile_noise=0.0)
    plant, hand = hand_plant()
    open_tips = tips_in_palm(plant, hand, plant.CreateDefaultContext())
    command = f1_command(layout)
    database = load_database(bus.frame_format)
    sniffer = can.Bus(interface="virtual", channel=bus.channel, receive_own_messages=False)
    try:
        with CanBusServer(CanServerConfig(port=0, hand_kind="barrett", bus=bus),
                          layout=layout) as server, \
                SimulatedHandFirmware(firmware_config, layout=layout):
            builder = DiagramBuilder()
            driver = AddCanHandDriver(builder, CanHandDriverConfig(port=server.address[1]),
                                      layout, export=False)
            source = builder.AddSystem(ConstantVectorSource(command))
            builder.Connect(source.get_output_port(), driver.get_command_input_port())
            # What the hardware station draws: measured joints scattered into the model.
            scatter = builder.AddSystem(HandJointsToPlantPositions(plant, hand,
                                                                   layout.joint_names))
            builder.Connect(driver.GetOutputPort("position_measured"), scatter.get_input_port())
            diagram = builder.Build()
            try:
                assert driver.client.wait_for_state(3.0)
                simulator = Simulator(diagram)
                simulator.set_target_realtime_rate(1.0)
                simulator.AdvanceTo(1.0)
                q_plant = scatter.get_output_port().Eval(
                    scatter.GetMyContextFromRoot(simulator.get_context()))
            finally:
                driver.close()
        # The setpoint on the bus: F1's signal carries the flexion, nothing else moves.
        setpoints = []
        while (message := sniffer.recv(timeout=0.0)) is not None:
            if message.arbitration_id == database.get_message_by_name("BARRETT_SETPOINT").frame_id:
                setpoints.append(database.decode_message(message.arbitration_id, message.data))
    finally:
        sniffer.shutdown()
    assert setpoints, "no BARRETT_SETPOINT frame on the bus"
    last = setpoints[-1]
    assert last["SP_f1_prox"] == pytest.approx(F1_FLEXION, abs=1e-4)
    for signal in ("SP_f1_spread", "SP_f2_prox", "SP_f3_prox"):
        assert last[signal] == pytest.approx(0.0, abs=1e-4), signal

    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q_plant)
    tips = tips_in_palm(plant, hand, context)
    assert moved_finger(open_tips, tips) == "f1"
    assert open_tips["f1"][0] < 0 and tips["f1"][0] < 0  # the finger on the -x side


def test_f1_command_in_simulation_moves_the_finger_at_negative_x():
    scenario = LoadScenario(data="hand: {kind: barrett, mount: !FixedMount {}}\n"
                                 "object: null\ntable: null")
    station = MakeHandStation(scenario)
    plant = GetPlant(station)
    hand = plant.GetModelInstanceByName("hand")
    layout = hand_layout(get_hand_spec("barrett"))
    context = station.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    open_tips = tips_in_palm(plant, hand, plant_context)
    station.GetInputPort("hand.position").FixValue(context, f1_command(layout))
    simulator = Simulator(station, context)
    simulator.AdvanceTo(0.8)
    tips = tips_in_palm(plant, hand, plant_context)
    assert moved_finger(open_tips, tips) == "f1"
    assert open_tips["f1"][0] < 0 and tips["f1"][0] < 0
