"""The hand-control diagram runs unchanged on the CAN hand station (hardware=True).

A ``can-server --with-sim`` subprocess (simulated hand firmware on a
udp_multicast bus with a random group and port, TCP on a free loopback port)
stands in for the real hand.
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

import mido
import pytest
from pydrake.systems.analysis import Simulator

from handle_drake.apps.figure9.hand_control import BuildMidiHandControl
from handle_drake.base.hands import get_hand_spec
from handle_drake.devices.midi.ports import in_process_pair
from handle_drake.scenario import LoadScenario

ROOT = Path(__file__).resolve().parents[2]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def can_hand():
    rng = random.Random()
    port = free_port()
    group = f"239.255.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    process = subprocess.Popen(
        [sys.executable, "-m", "handle_drake.devices.can_hand.cli", "can-server", "--with-sim",
         "--listen", f"127.0.0.1:{port}", "--bus", "udp_multicast", "--channel", group,
         "--bus-port", str(rng.randint(20000, 60000))],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    selector = selectors.DefaultSelector()
    selector.register(process.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + 30
    ready = False
    while time.monotonic() < deadline and not ready:
        if selector.select(max(0.0, deadline - time.monotonic())):
            line = process.stdout.readline()
            ready = "ready" in line
            if not line and process.poll() is not None:
                break
    selector.close()
    try:
        if not ready:
            pytest.fail(f"can-server did not start: {process.stderr.read()[-2000:]}")
        yield port
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(5)
        process.stdout.close()
        process.stderr.close()


def test_fader_drives_the_can_hand(can_hand):
    scenario = LoadScenario(data=f"""
hand: {{mount: !FixedMount {{X_WB: {{translation: [0, 0, 0.3]}}}}}}
object: null
table: null
driver: !CanHandDriver {{host: 127.0.0.1, port: {can_hand}}}
""")
    device, host = in_process_pair()
    built = BuildMidiHandControl(scenario, port=host, synergies=None, hardware=True,
                                 max_joint_velocity=2.0)
    simulator = Simulator(built.diagram)
    simulator.set_target_realtime_rate(1.0)
    simulator.AdvanceTo(0.3)
    device.send(mido.Message("control_change", control=20, value=127))  # fader1: FFJ3
    simulator.AdvanceTo(2.5)
    q = built.station.GetOutputPort("hand.position_measured").Eval(
        built.station.GetMyContextFromRoot(simulator.get_context()))
    names = get_hand_spec("shadow").joint_names
    assert q[names.index("FFJ3")] == pytest.approx(1.5708, abs=0.03)
    assert abs(q[names.index("MFJ3")]) < 0.03
