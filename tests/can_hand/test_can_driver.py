"""The proxy driver LeafSystem and the hardware station (in-process virtual bus)."""

import socket
import time
import uuid

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.devices.can_hand.client import DISCONNECTED, STREAMING
from handle_drake.devices.can_hand.config import (
    BusConfig,
    CanFirmwareConfig,
    CanHandDriverConfig,
    CanServerConfig,
)
from handle_drake.devices.can_hand.driver import STATION_SIGNALS, AddCanHandDriver, CanHandProxy
from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
from handle_drake.devices.can_hand.layout import hand_layout
from handle_drake.devices.can_hand.server import CanBusServer

# The station contract (docs/ARCHITECTURE.md, "Station ports"): nq, nu, fingertips.
SIZES = {"shadow": (24, 20, 5), "barrett": (8, 4, 3)}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("kind", ["shadow", "barrett"])
def test_exported_ports_follow_the_station_contract(kind):
    nq, nu, nt = SIZES[kind]
    builder = DiagramBuilder()
    driver = AddCanHandDriver(builder, CanHandDriverConfig(port=free_port()), kind)
    try:
        diagram = builder.Build()
        inputs = {diagram.get_input_port(i).get_name(): diagram.get_input_port(i).size()
                  for i in range(diagram.num_input_ports())}
        outputs = {diagram.get_output_port(i).get_name(): diagram.get_output_port(i).size()
                   for i in range(diagram.num_output_ports())}
        assert inputs == {"hand.position": nu}
        assert outputs == {"hand.position_commanded": nu, "hand.position_measured": nq,
                           "hand.velocity_estimated": nq, "hand.state_estimated": 2 * nq,
                           "hand.tactile": nt}
        assert driver.GetOutputPort("connection_state").size() == 1
        assert set(STATION_SIGNALS) == {n.split(".", 1)[1] for n in outputs}
    finally:
        driver.close()


def test_without_a_server_it_outputs_the_initial_state_and_never_blocks():
    layout = hand_layout("shadow")
    initial = layout.command_lower + 0.25 * (layout.command_upper - layout.command_lower)
    # A server that accepts and never answers: the handshake hangs in the client thread.
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(1)
    config = CanHandDriverConfig(port=silent.getsockname()[1], period=0.002, connect_timeout=2.0)
    builder = DiagramBuilder()
    driver = builder.AddSystem(CanHandProxy(layout, config, initial_position=initial))
    source = builder.AddSystem(ConstantVectorSource(np.zeros(layout.nu)))
    builder.Connect(source.get_output_port(), driver.get_command_input_port())
    diagram = builder.Build()
    try:
        simulator = Simulator(diagram)
        start = time.perf_counter()
        simulator.AdvanceTo(0.5)  # 250 updates while the handshake is stuck
        elapsed = time.perf_counter() - start
        context = driver.GetMyContextFromRoot(simulator.get_context())
        assert elapsed < 1.0  # 2 s connect timeout: the update did not wait for it
        q = driver.GetOutputPort("position_measured").Eval(context)
        assert np.allclose(q, layout.joint_positions(initial))
        assert np.allclose(driver.GetOutputPort("position_commanded").Eval(context), initial)
        assert np.all(driver.GetOutputPort("velocity_estimated").Eval(context) == 0)
        assert driver.GetOutputPort("connection_state").Eval(context)[0] == DISCONNECTED
        state = driver.GetOutputPort("state_estimated").Eval(context)
        assert np.allclose(state, np.concatenate([layout.joint_positions(initial), np.zeros(24)]))
    finally:
        driver.close()
        silent.close()


def test_bad_arguments_and_inputs_raise_clear_errors():
    layout = hand_layout("barrett")
    port = free_port()
    with pytest.raises(ValueError, match="configured for a shadow hand, got a barrett"):
        CanHandProxy(layout, CanHandDriverConfig(port=port, hand_kind="shadow"))
    with pytest.raises(ValueError, match="expected 4 values"):
        CanHandProxy(layout, CanHandDriverConfig(port=port), initial_position=np.zeros(20))
    with pytest.raises(ValueError, match="period"):
        CanHandProxy(layout, CanHandDriverConfig(port=port, period=0.0))
    builder = DiagramBuilder()
    driver = builder.AddSystem(CanHandProxy(layout, CanHandDriverConfig(port=port)))
    source = builder.AddSystem(ConstantVectorSource(np.array([0.0, np.nan, 0.0, 0.0])))
    builder.Connect(source.get_output_port(), driver.get_command_input_port())
    try:
        simulator = Simulator(builder.Build())
        with pytest.raises(ValueError, match="'position' must be finite"):
            simulator.AdvanceTo(0.01)
    finally:
        driver.close()


def test_driver_closes_the_hand_onto_a_virtual_object():
    """Grasp closing through the whole chain; the fingertip force is k * (setpoint - stop)."""
    layout = hand_layout("barrett")
    bus = BusConfig("virtual", f"test-{uuid.uuid4().hex}")
    firmware_config = CanFirmwareConfig(hand_kind="barrett", bus=bus, rate=500.0,
                                        object_closure=0.5, tactile_noise=0.0,
                                        contact_stiffness=20.0)
    with CanBusServer(CanServerConfig(port=0, hand_kind="barrett", bus=bus),
                      layout=layout) as server, \
            SimulatedHandFirmware(firmware_config, layout=layout):
        builder = DiagramBuilder()
        driver = AddCanHandDriver(builder, CanHandDriverConfig(port=server.address[1]), layout,
                                  export=False)
        open_q = np.zeros(4)
        closed = np.array([0.0, 2.0, 2.0, 2.0])  # proximal flexion; the object stops at 1.22
        trajectory = PiecewisePolynomial.FirstOrderHold([0.0, 0.1, 0.6],
                                                        np.stack([open_q, open_q, closed], 1))
        source = builder.AddSystem(TrajectorySource(trajectory))
        builder.Connect(source.get_output_port(), driver.get_command_input_port())
        tactile_log = LogVectorOutput(driver.GetOutputPort("tactile"), builder, 0.01)
        diagram = builder.Build()
        try:
            assert driver.client.wait_for_state(3.0)
            simulator = Simulator(diagram)
            simulator.set_target_realtime_rate(1.0)
            simulator.AdvanceTo(1.2)
            context = driver.GetMyContextFromRoot(simulator.get_context())
            stop = 0.5 * layout.joint_upper[layout.joint_names.index("f1_prox")]
            q = driver.GetOutputPort("position_measured").Eval(context)
            prox = [layout.joint_names.index(n) for n in ("f1_prox", "f2_prox", "f3_prox")]
            dist = [layout.joint_names.index(n) for n in ("f1_dist", "f2_dist", "f3_dist")]
            assert np.allclose(q[prox], stop, atol=3e-3)  # stopped by the object
            assert np.allclose(q[dist], stop / 3, atol=3e-3)  # coupled distal joints
            tactile = driver.GetOutputPort("tactile").Eval(context)
            assert np.allclose(tactile, 20.0 * (2.0 - stop), atol=2e-3)
            assert np.allclose(driver.GetOutputPort("position_commanded").Eval(context), closed,
                               atol=1e-9)
            assert driver.GetOutputPort("connection_state").Eval(context)[0] == STREAMING
            assert tactile_log.FindLog(simulator.get_context()).data()[:, 0].max() < 0.01
        finally:
            driver.close()


SCENARIO = """
hand: {kind: shadow, mount: !FixedMount {}}
object: null
driver: !CanHandDriver {port: %d}
"""


def test_hardware_station_exports_the_simulated_station_hand_ports():
    from handle_drake.scenario import LoadScenario
    from handle_drake.station import MakeHandStation, MakeHardwareStation

    scenario = LoadScenario(data=SCENARIO % free_port())
    hardware = MakeHardwareStation(scenario)
    try:
        sim_scenario = LoadScenario(data=SCENARIO.replace("!CanHandDriver {port: %d}",
                                                          "!SimHandDriver {}"))
        sim = MakeHandStation(sim_scenario)

        def hand_ports(diagram):
            ports = [diagram.get_input_port(i) for i in range(diagram.num_input_ports())]
            ports += [diagram.get_output_port(i) for i in range(diagram.num_output_ports())]
            return {p.get_name(): p.size() for p in ports if p.get_name().startswith("hand.")}

        assert hand_ports(hardware) == hand_ports(sim)
        assert len(hand_ports(sim)) == 6
    finally:
        hardware.GetSubsystemByName("hand_driver").close()


def test_hardware_station_refuses_a_floating_wrist():
    from handle_drake.scenario import LoadScenario
    from handle_drake.station import MakeHardwareStation

    scenario = LoadScenario(data=SCENARIO.replace("!FixedMount {}", "!FloatingWrist {}")
                            % free_port())
    with pytest.raises(ValueError, match="FixedMount"):
        MakeHardwareStation(scenario)
