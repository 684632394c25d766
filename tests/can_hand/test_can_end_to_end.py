"""The whole chain as real processes on loopback.

``handle-drake can-sim`` and ``handle-drake can-server`` run as subprocesses
on a udp_multicast CAN bus (a random group and port per test, TTL 1); a Drake
diagram drives the hand through the proxy driver over TCP on 127.0.0.1. The
tracking and server-restart tests run on both frame formats (``--frame-format
classic|fd``). Every subprocess is terminated (then killed) in teardown.
"""

import os
import random
import selectors
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.devices.can_hand.bus import socketcan_available
from handle_drake.devices.can_hand.client import DISCONNECTED, STREAMING
from handle_drake.devices.can_hand.config import CanHandDriverConfig
from handle_drake.devices.can_hand.driver import AddCanHandDriver
from handle_drake.devices.can_hand.layout import hand_layout

ROOT = Path(__file__).resolve().parents[2]
NATURAL_FREQUENCY = 5.0  # Hz, the simulated firmware's joint loops (critically damped)
NOISE = 0.0005  # rad
# Hand cycle rate of the simulated firmware. On the classic layout each cycle is 9
# Shadow frames, and a multicast socket also receives its own frames, so 1 kHz costs
# each Python process ~20k datagrams/s; 250 Hz keeps the test honest on a shared
# 2-core box for both formats (the benchmark measures 1 kHz).
SIM_RATE = 250.0
TRANSPORT_DELAY = 0.1  # s


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def random_bus():
    rng = random.Random()
    return f"239.255.{rng.randint(0, 255)}.{rng.randint(1, 254)}", rng.randint(20000, 60000)


class Process:
    """A CLI subprocess that printed its ``ready`` line."""

    def __init__(self, *args, timeout=30.0):
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.popen = subprocess.Popen(
            [sys.executable, "-m", "handle_drake.devices.can_hand.cli", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
        self.ready_line = self._read_ready(timeout)

    def _read_ready(self, timeout):
        selector = selectors.DefaultSelector()
        selector.register(self.popen.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + timeout
        try:
            while time.monotonic() < deadline:
                if selector.select(max(0.0, deadline - time.monotonic())):
                    line = self.popen.stdout.readline()
                    if "ready" in line:
                        return line.strip()
                    if not line and self.popen.poll() is not None:
                        break
        finally:
            selector.close()
        self.stop()
        raise RuntimeError(f"process did not become ready: {self.popen.stderr.read()[-2000:]}")

    def stop(self, sig=signal.SIGTERM, timeout=5.0):
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(timeout)
        for stream in (self.popen.stdout, self.popen.stderr):
            stream.close()
        return self.popen.returncode


def bus_args(group, bus_port, frame_format="fd"):
    return ["--bus", "udp_multicast", "--channel", group, "--bus-port", str(bus_port),
            "--frame-format", frame_format]


@pytest.fixture
def processes():
    started = []
    yield started
    for process in started:
        process.stop(signal.SIGKILL if process.popen.poll() is None else signal.SIGTERM)


def start_sim(processes, group, bus_port, hand="shadow", frame_format="fd"):
    p = Process("can-sim", "--hand", hand, "--natural-frequency", str(NATURAL_FREQUENCY),
                "--noise", str(NOISE), "--rate", str(SIM_RATE),
                *bus_args(group, bus_port, frame_format))
    processes.append(p)
    return p


def start_server(processes, group, bus_port, port, hand="shadow", frame_format="fd"):
    p = Process("can-server", "--hand", hand, "--listen", f"127.0.0.1:{port}",
                *bus_args(group, bus_port, frame_format))
    processes.append(p)
    return p


class WallClock(LeafSystem):
    """Records (simulated time, this process's monotonic clock) every ``period``: the
    simulator keeps real time only as well as the machine lets it, and the hand's
    physics runs on the wall clock."""

    def __init__(self, period: float):
        super().__init__()
        self.samples = []
        self.DeclarePeriodicPublishEvent(period, 0.0, self._record)
        self.DeclareInitializationPublishEvent(self._record)

    def _record(self, context):
        self.samples.append((context.get_time(), time.monotonic()))

    def wall(self, t):
        """Wall time at which the simulation was at time(s) ``t``."""
        sim, wall = np.array(self.samples).T
        return np.interp(t, sim, wall)


@pytest.mark.parametrize("frame_format", ["classic", "fd"])
def test_udp_multicast_chain_tracks_a_closing_trajectory(processes, frame_format):
    """Measured follows the command: at rest within 0.005 rad (10 sigma of the sensor
    noise) once settled; on the ramp with the closed-form lag 2 / wn = 63.7 ms of a
    critically damped loop plus the transport's delay (never less than the physics:
    -10 ms for sampling). Unloaded, the transport adds about 6 ms.

    On a loaded machine the simulator falls behind real time and catches up (its
    command ramp is then not the planned slope in the hand's time), so both are measured
    on the wall clock, which the hand's physics runs on: the lag as the wall time between
    the command reaching a value and the hand measuring it, the velocity estimate against
    the measured positions' own rate of change. (Real-time figures: benchmarks/bench_can.py.)
    """
    group, bus_port = random_bus()
    port = free_port()
    sim = start_sim(processes, group, bus_port, frame_format=frame_format)
    start_server(processes, group, bus_port, port, frame_format=frame_format)
    assert f"frames={frame_format}" in sim.ready_line
    layout = hand_layout("shadow")

    builder = DiagramBuilder()
    driver = AddCanHandDriver(builder, CanHandDriverConfig(port=port, period=0.002), layout,
                              export=False)
    q0 = np.clip(np.zeros(layout.nu), layout.command_lower, layout.command_upper)
    q1 = layout.command_lower + 0.6 * (layout.command_upper - layout.command_lower)
    t_ramp, t_end = (0.3, 1.1), 2.0
    trajectory = PiecewisePolynomial.FirstOrderHold([0.0, *t_ramp], np.stack([q0, q0, q1], 1))
    source = builder.AddSystem(TrajectorySource(trajectory))
    builder.Connect(source.get_output_port(), driver.get_command_input_port())
    q_log = LogVectorOutput(driver.GetOutputPort("position_measured"), builder, 0.005)
    v_log = LogVectorOutput(driver.GetOutputPort("velocity_estimated"), builder, 0.005)
    clock = builder.AddSystem(WallClock(0.005))
    diagram = builder.Build()
    try:
        assert driver.client.wait_for_state(10.0), driver.client.last_error
        simulator = Simulator(diagram)
        simulator.set_target_realtime_rate(1.0)
        simulator.AdvanceTo(t_end)
        context = simulator.get_context()
        # A starved hand process runs its physics behind the wall clock: rest is judged
        # from when the hand has settled (or 10 s later: a hand that never settles fails).
        measured = driver.GetOutputPort("position_measured")
        while (np.max(np.abs(layout.actuated_positions(measured.Eval(
                driver.GetMyContextFromRoot(context))) - q1)) > 0.005
               and context.get_time() < t_end + 10.0):
            simulator.AdvanceTo(context.get_time() + 0.1)
        t_rest = context.get_time() + 0.2  # then it stays there
        simulator.AdvanceTo(t_rest)
        t = q_log.FindLog(context).sample_times()
        q = np.array([layout.actuated_positions(x) for x in q_log.FindLog(context).data().T])
        v = np.array([layout.actuated_positions(x) for x in v_log.FindLog(context).data().T])
    finally:
        driver.close()

    slope = (q1 - q0) / (t_ramp[1] - t_ramp[0])
    moving = np.abs(slope) > 0.3
    assert moving.sum() >= 10
    # Rest: the last 0.2 s sit on the final command.
    rest = t > t_rest - 0.2
    assert np.max(np.abs(q[rest] - q1)) < 0.005, np.max(np.abs(q[rest] - q1))
    # Ramp, after the loop's transient (~5 / wn): constant lag of 2 zeta / wn seconds,
    # on the wall clock: when the hand measured q, minus when the command was q.
    wn = 2 * np.pi * NATURAL_FREQUENCY
    ramp = (t > t_ramp[0] + 0.3) & (t < t_ramp[1] - 0.02)
    w = clock.wall(t[ramp])
    commanded_at = t_ramp[0] + (q[ramp][:, moving] - q0[moving]) / slope[moving]
    lag = w[:, None] - clock.wall(commanded_at)
    # Never ahead of the physics (causality, -10 ms for sampling); behind it by the
    # transport, which on a quiet machine is within TRANSPORT_DELAY (bench_can.py measures
    # it in real time) and on a loaded one by as much as the processes are starved: here
    # only that the hand follows at all.
    assert 2.0 / wn - 0.01 < np.median(lag) < 1.0, np.median(lag)
    # The server's velocity estimate (the hand's own clock) matches the hand's measured
    # motion over the ramp: both averaged over the same wall-clock window.
    rate = (q[ramp][-1, moving] - q[ramp][0, moving]) / (w[-1] - w[0])
    v_mean = np.trapezoid(v[ramp][:, moving], w, axis=0) / (w[-1] - w[0])
    # The estimate is low-passed (the server's tau): where the simulator's pace jumped
    # (behind, then catching up: the command's slope on the wall clock changes), the
    # filtered estimate trails the changing rate, so the tolerance widens with the
    # unevenness of the pace measured in this run.
    sim, wall = np.array(clock.samples).T
    inside = (sim > t_ramp[0] + 0.3) & (sim < t_ramp[1])
    pace = np.diff(wall[inside]) / np.diff(sim[inside])
    steady = np.percentile(np.abs(pace - 1.0), 90) < 0.25
    rtol = 0.15 if steady else 0.4
    assert np.allclose(v_mean, rate, rtol=rtol, atol=0.05), (v_mean, rate, steady)


@pytest.mark.parametrize("frame_format", ["classic", "fd"])
def test_server_killed_mid_run_then_back(processes, frame_format):
    """Disconnected -> holds the last measurement; server back -> reconnects, and
    the command changed during the outage reaches the hand."""
    group, bus_port = random_bus()
    port = free_port()
    start_sim(processes, group, bus_port, hand="barrett", frame_format=frame_format)
    server = start_server(processes, group, bus_port, port, hand="barrett",
                          frame_format=frame_format)
    layout = hand_layout("barrett")
    builder = DiagramBuilder()
    driver = AddCanHandDriver(builder, CanHandDriverConfig(port=port, reconnect_interval=0.1),
                              layout, export=False)
    first = np.array([0.3, 0.8, 0.8, 0.8])
    command = builder.AddSystem(ConstantVectorSource(first))
    builder.Connect(command.get_output_port(), driver.get_command_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(1.0)
    context = driver.GetMyContextFromRoot(simulator.get_context())

    def out(name):
        return driver.GetOutputPort(name).Eval(context).copy()

    def advance_until(predicate, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            simulator.AdvanceTo(simulator.get_context().get_time() + 0.05)
            if predicate():
                return True
        return False

    try:
        assert driver.client.wait_for_state(10.0), driver.client.last_error
        assert advance_until(lambda: np.allclose(layout.actuated_positions(
            out("position_measured")), first, atol=0.005), 5.0)
        server.popen.kill()  # SIGKILL: no goodbye
        server.popen.wait(5.0)
        assert advance_until(lambda: out("connection_state")[0] == DISCONNECTED, 2.0)
        held = out("position_measured")
        assert advance_until(lambda: False, 0.3) is False  # keep simulating while down
        assert np.array_equal(out("position_measured"), held)  # holds, no jumps
        assert np.all(out("velocity_estimated") == 0)
        assert np.allclose(layout.actuated_positions(held), first, atol=0.005)
        # The controller moves on during the outage.
        second = np.array([0.6, 1.4, 1.0, 1.2])
        command.get_mutable_source_value(
            command.GetMyContextFromRoot(simulator.get_context())).set_value(second)
        simulator.AdvanceTo(simulator.get_context().get_time() + 0.1)
        start_server(processes, group, bus_port, port, hand="barrett", frame_format=frame_format)
        assert advance_until(lambda: out("connection_state")[0] == STREAMING, 10.0)
        assert advance_until(lambda: np.allclose(layout.actuated_positions(
            out("position_measured")), second, atol=0.005), 5.0)
        assert driver.client.counters["disconnects"] == 1
        assert driver.client.counters["connects"] == 2
    finally:
        driver.close()


def test_cli_processes_stop_cleanly_on_sigint_and_sigterm(processes):
    server = Process("can-server", "--listen", "127.0.0.1:0", "--bus", "virtual", "--with-sim",
                     "--channel", f"cli-{os.getpid()}")
    processes.append(server)
    host, port = server.ready_line.split()[2].rsplit(":", 1)
    assert host == "127.0.0.1" and int(port) > 0
    with socket.create_connection((host, int(port)), timeout=2.0):
        pass  # it serves
    assert server.stop(signal.SIGINT) == 0
    group, bus_port = random_bus()
    sim = start_sim(processes, group, bus_port)
    assert sim.stop(signal.SIGTERM) == 0


def test_cli_reports_bad_arguments(processes):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    result = subprocess.run(
        [sys.executable, "-m", "handle_drake.devices.can_hand.cli", "can-server",
         "--listen", "nope"],
        capture_output=True, text=True, env=env, cwd=ROOT, timeout=30)
    assert result.returncode == 2 and "expected HOST:PORT" in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "handle_drake.devices.can_hand.cli", "can-sim", "--bus", "socketcan",
         "--channel", "nosuchcan7"], capture_output=True, text=True, env=env, cwd=ROOT, timeout=30)
    assert result.returncode == 2 and "no network interface 'nosuchcan7'" in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "handle_drake.devices.can_hand.cli", "can-sim",
         "--frame-format", "canfd"],
        capture_output=True, text=True, env=env, cwd=ROOT, timeout=30)
    assert result.returncode == 2 and "invalid choice: 'canfd'" in result.stderr


@pytest.mark.skipif(not socketcan_available("vcan0"),
                    reason="SocketCAN interface vcan0 does not exist (no vcan module in this "
                           "kernel); the socketcan bus is the same code path as udp_multicast "
                           "behind python-can")
def test_socketcan_chain_streams(processes):
    port = free_port()
    processes.append(Process("can-sim", "--bus", "socketcan", "--channel", "vcan0"))
    processes.append(Process("can-server", "--listen", f"127.0.0.1:{port}", "--bus", "socketcan",
                             "--channel", "vcan0"))
    from handle_drake.devices.can_hand.client import CanHandClient

    with CanHandClient(hand_layout("shadow"), "127.0.0.1", port) as client:
        assert client.wait_for_state(10.0)


def test_same_scenario_runs_on_the_can_hand_and_in_simulation(processes):
    """diagrams/shadow_can_hand.yaml: one file, two drivers, the same closed hand."""
    from handle_drake.base.hands import get_hand_spec
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario
    from handle_drake.trial.simulate import ScenarioRunner

    group, bus_port = random_bus()
    port = free_port()
    start_sim(processes, group, bus_port)
    start_server(processes, group, bus_port, port)
    path = diagrams_dir() / "shadow_can_hand.yaml"
    names = get_hand_spec("shadow").joint_names
    closed = {"FFJ3": 1.2, "MFJ2": 1.0, "THJ4": 0.6}
    duration = 2.6  # the script closes by 1.5 s and holds until 3 s

    hardware = ScenarioRunner(LoadScenario(filename=path,
                                           data=f"driver: !CanHandDriver {{port: {port}}}"),
                              hardware=True).run(duration)
    simulated = ScenarioRunner(LoadScenario(filename=path,
                                            data="driver: !SimHandDriver {}")).run(duration)
    assert hardware.wall_time >= 0.9 * duration  # real time, not faster
    for joint, value in closed.items():
        i = names.index(joint)
        assert hardware.hand_position[-1, i] == pytest.approx(value, abs=0.03), joint
        assert simulated.hand_position[-1, i] == pytest.approx(value, abs=0.03), joint
