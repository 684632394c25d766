"""The CAN bus server against the simulated firmware on an in-process virtual bus.

Every running-chain test runs on both frame formats (classic CAN 2.0 and CAN
FD). Faults: foreign, malformed and wrong-format frames, a server and a hand
on different formats, a setpoint flood, out-of-limit setpoints, a silent
client, malformed TCP messages and a client for another hand. Every loop is
bounded; every server, firmware and bus is stopped.
"""

import socket
import threading
import time
import uuid

import can
import numpy as np
import pytest

from handle_drake.devices.can_hand import protocol as P
from handle_drake.devices.can_hand.client import DISCONNECTED, CanHandClient
from handle_drake.devices.can_hand.config import BusConfig, CanFirmwareConfig, CanServerConfig
from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
from handle_drake.devices.can_hand.layout import hand_layout
from handle_drake.devices.can_hand.messages import (
    COMMIT_ID,
    POSITION_BASE_ID,
    STATUS_ID,
)
from handle_drake.devices.can_hand.server import (
    CanBusServer,
    CommitSchedule,
    VelocityEstimator,
    clamp_command,
    limit_setpoint,
)


def wait_until(predicate, timeout=3.0, step=0.01):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(step)
    return predicate()


@pytest.fixture(scope="module")
def layout():
    return hand_layout("shadow")


class Chain:
    """Server + firmware on a fresh virtual bus, plus spare bus handles for a test."""

    def __init__(self, layout, frame_format, firmware_format=None, **server_options):
        self.bus_config = BusConfig("virtual", f"test-{uuid.uuid4().hex}",
                                    frame_format=frame_format)
        self.layout = layout
        self.monitor = can.Bus(interface="virtual", channel=self.bus_config.channel)
        self.inject = can.Bus(interface="virtual", channel=self.bus_config.channel)
        self.server = CanBusServer(CanServerConfig(port=0, bus=self.bus_config, **server_options),
                                   layout=layout).start()
        firmware_bus = BusConfig("virtual", self.bus_config.channel,
                                 frame_format=firmware_format or frame_format)
        self.firmware = SimulatedHandFirmware(
            CanFirmwareConfig(bus=firmware_bus, rate=500.0), layout=layout).start()
        # The frame that applies a command: the classic commit, or the FD setpoint.
        codec = self.server.codec
        self.commit_id = COMMIT_ID if frame_format == "classic" else codec.setpoint_id
        self.port = self.server.address[1]
        self.clients = []

    def client(self, layout=None, **options):
        client = CanHandClient(layout or self.layout, "127.0.0.1", self.port, **options).start()
        self.clients.append(client)
        return client

    def close(self):
        for client in self.clients:
            client.close()
        self.firmware.stop()
        self.server.stop()
        self.monitor.shutdown()
        self.inject.shutdown()


@pytest.fixture(params=["classic", "fd"])
def frame_format(request):
    return request.param


@pytest.fixture
def chain(layout, frame_format, request):
    options = getattr(request, "param", {})
    chain = Chain(layout, frame_format, **options)
    yield chain
    chain.close()


# -- pure policy functions -------------------------------------------------------

def test_limit_setpoint_steps_at_most_max_step_and_stays_in_limits():
    lower, upper = np.array([0.0, -1.0, 0.0]), np.array([1.0, 1.0, 0.5])
    nxt = limit_setpoint([0.2, 0.0, 0.45], [0.9, -0.03, 0.9], 0.1, lower, upper)
    assert np.allclose(nxt, [0.3, -0.03, 0.5])
    q, clamped = clamp_command([2.0, -3.0, 0.2], lower, upper)
    assert clamped and np.allclose(q, [1.0, -1.0, 0.2])
    assert clamp_command([0.5, 0.5, 0.5], lower, upper)[1] is False


@pytest.mark.parametrize("tolerance", [0.5, 1.0])
def test_commit_schedule_passes_jittered_commands_at_the_limit_and_bounds_any_window(tolerance):
    rate = 1000.0
    slot = 1.0 / rate
    rng = np.random.default_rng(3)
    # A client at exactly the limit whose commands arrive up to `tolerance` slots late
    # (a sleeping sender wakes late, never early) never waits.
    schedule = CommitSchedule(rate, tolerance)
    for k in range(2000):
        now = k * slot + rng.uniform(0.0, tolerance) * slot
        assert now >= schedule.earliest()
        schedule.commit(now)
    # ... but one later than that holds the next, on-time command for the difference.
    schedule = CommitSchedule(rate, tolerance)
    schedule.commit(0.0)
    schedule.commit(slot + (tolerance + 0.3) * slot)
    assert schedule.earliest() - 2 * slot == pytest.approx(0.3 * slot)
    # A flood: commit whenever allowed, with arrivals every 0.05 slot.
    schedule, commits = CommitSchedule(rate, tolerance), []
    for now in np.arange(0.0, 0.5, 0.05 * slot):
        if now >= schedule.earliest():
            schedule.commit(now)
            commits.append(now)
    commits = np.array(commits)
    # GCRA bound: any window of T seconds holds at most 1 + tolerance + rate * T commits,
    # and the bound is reached (a burst of floor(1 + tolerance) commits, one arrival apart).
    for width in (0.0, 0.5 * slot, 3 * slot, 100 * slot):
        counts = np.searchsorted(commits, commits + width, side="right") - np.arange(commits.size)
        assert counts.max() <= 1 + tolerance + rate * width + 1e-9, (width, counts.max())
    assert counts.max() >= rate * 100 * slot
    burst = np.searchsorted(commits, commits[0] + 0.05 * slot + 1e-12, side="right")
    assert burst == int(1 + tolerance)
    assert len(commits) == pytest.approx(rate * 0.5, abs=2)  # and the long-run rate is the limit
    # A late commit does not push the next slot back beyond now + slot.
    schedule = CommitSchedule(rate, tolerance)
    schedule.commit(0.0)
    schedule.commit(0.01)  # 9 slots late
    assert schedule.earliest() == pytest.approx(0.01 + (1 - tolerance) * slot)


def test_bad_rate_tolerances_are_refused_in_one_line(capsys):
    from handle_drake.devices.can_hand.cli import main as cli_main

    for bad in (-0.5, float("nan"), float("inf"), 11.0, "1", True):
        with pytest.raises(ValueError, match="^rate_tolerance: expected"):
            CanServerConfig(rate_tolerance=bad).validate()
    bus = BusConfig("virtual", f"tolerance-{uuid.uuid4().hex}")
    server = CanBusServer(CanServerConfig(port=0, bus=bus, rate_tolerance=0.5))
    assert server._schedule._tolerance == pytest.approx(0.5e-3)  # 0.5 slot at 1 kHz
    assert cli_main(["can-server", "--bus", "virtual", "--rate-tolerance", "-1"]) == 2
    assert capsys.readouterr().err.strip() == (
        "handle-drake can-server: rate_tolerance: expected a finite number >= 0, got -1.0")


@pytest.mark.parametrize("tolerance", [0.5, 1.0])
def test_commit_schedule_queues_a_client_faster_than_the_limit_by_up_to_the_tolerance(tolerance):
    """A 1 kHz client whose clock drifts one slot per 4 s against the 1 kHz limit:
    slower, it never waits; faster, its commands wait once the drift passes the tolerance,
    growing to it, as GCRA's closed form says (k (slot - P) - tolerance slot)."""
    rate, n = 1000.0, 4000
    slot = 1.0 / rate
    for sign in (+1, -1):
        period = slot + sign * slot / n
        schedule, waits = CommitSchedule(rate, tolerance), []
        for k in range(n):
            now = k * period
            commit = max(now, schedule.earliest())
            waits.append(commit - now)
            schedule.commit(commit)
        waits = np.array(waits)
        if sign > 0:
            assert waits.max() == 0.0
        else:
            k = np.arange(n)
            expected = np.maximum(0.0, k * (slot - period) - tolerance * slot)
            assert np.allclose(waits, expected, atol=1e-12)
            assert (waits > 0).mean() == pytest.approx(1 - tolerance, abs=0.01)
            assert waits.max() == pytest.approx((1 - tolerance) * slot, abs=1e-3 * slot)


def test_velocity_estimator_matches_a_first_order_filter_of_the_slope():
    dt, tau, slope = 0.001, 0.01, 0.7
    estimator = VelocityEstimator(1, tau)
    estimator.update([0.0], 0.0)
    alpha = dt / (tau + dt)
    v = estimator.update([slope * dt], dt)
    assert v[0] == pytest.approx(alpha * slope)  # first filtered sample
    for k in range(2, 201):
        v = estimator.update([slope * k * dt], k * dt)
    assert v[0] == pytest.approx(slope * (1 - (1 - alpha) ** 200), rel=1e-9)
    # The hand clock wraps at 2**32 us; the difference still uses dt.
    wrap = float(1 << 32) * 1e-6
    estimator = VelocityEstimator(1, 0.0)
    estimator.update([0.0], wrap - 0.0005)
    assert estimator.update([0.001], 0.0005)[0] == pytest.approx(1.0)


def test_configs_reject_unknown_frame_formats_and_priorities():
    with pytest.raises(ValueError, match="frame_format: expected one of"):
        BusConfig(frame_format="canfd").validate()
    for bad in (-1, 100, 2.5, True):
        with pytest.raises(ValueError, match="realtime_priority: expected an integer in 0..99"):
            CanServerConfig(realtime_priority=bad).validate()
    with pytest.raises(ValueError, match="realtime_priority"):
        CanFirmwareConfig(realtime_priority=-3).validate()
    assert BusConfig().frame_format == "fd"


def test_realtime_priority_applies_to_the_calling_thread_only():
    import os

    from handle_drake.devices.can_hand.bus import use_realtime_priority

    assert use_realtime_priority(0) is False
    result = {}

    def worker():
        result["applied"] = use_realtime_priority(10)
        result["policy"] = os.sched_getscheduler(0)

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join(5.0)
    if not result["applied"]:
        pytest.skip("this process may not use SCHED_FIFO (no CAP_SYS_NICE or rtprio limit)")
    assert result["policy"] == os.SCHED_FIFO
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the test's own thread is untouched


# -- the running server ---------------------------------------------------------

def test_chain_streams_the_true_hand_state(chain):
    client = chain.client()
    assert client.wait_for_state(3.0)
    state, _ = client.latest()
    truth = chain.layout.joint_positions(chain.firmware.model.q)
    # 5 sigma of the firmware's sensor noise plus half a count of quantisation
    assert np.max(np.abs(state.q - truth)) < 5 * 0.0005 + 0.5e-4


def _frame(arbitration_id, data, fd=False, extended=False):
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=extended,
                       is_fd=fd, bitrate_switch=fd)


def test_foreign_malformed_and_wrong_format_frames_are_rejected_and_counted(chain, frame_format):
    client = chain.client()
    assert client.wait_for_state(3.0)
    before = chain.server.stats()
    fd = frame_format == "fd"
    feedback_id = chain.server.codec.feedback_id if fd else POSITION_BASE_ID
    length = 64 if fd else 8
    injected = {"foreign_frames": [], "malformed_frames": [], "wrong_format_frames": []}
    injected["foreign_frames"] += [_frame(0x7FF - i, bytes(8)) for i in range(20)]
    injected["foreign_frames"] += [_frame(0x7FF - i, bytes(64), fd=True) for i in range(20)]
    # A hand id, but as an extended frame.
    injected["foreign_frames"] += [_frame(feedback_id, bytes(length), fd, True)] * 10
    # Wrong length.
    injected["malformed_frames"] += [_frame(feedback_id, bytes(3), fd)] * 20
    if fd:  # the other hand's kind in the Shadow feedback frame
        wrong_kind = bytes([0, 0, 0x21]) + bytes(61)
        injected["malformed_frames"] += [_frame(feedback_id, wrong_kind, True)] * 10
        injected["foreign_frames"] += [_frame(0x241, bytes(32), True)] * 5  # Barrett's
        # The right id sent as a CAN 2.0 frame; the classic layout's ids.
        injected["wrong_format_frames"] += [_frame(feedback_id, bytes(8), False)] * 10
        injected["wrong_format_frames"] += [_frame(STATUS_ID, bytes(8), False)] * 10
    else:  # a Barrett's STATUS on a Shadow bus
        injected["malformed_frames"] += [_frame(STATUS_ID, bytes([0, 0, 0, 0x21, 0, 0, 0, 0]))] * 10
        # A classic id sent as a CAN FD frame; the FD layout's ids.
        injected["wrong_format_frames"] += [_frame(POSITION_BASE_ID, bytes(8), True)] * 10
        injected["wrong_format_frames"] += [_frame(0x240, bytes(64), True)] * 10
    frames = [f for group in injected.values() for f in group]
    for i in np.random.default_rng(0).permutation(len(frames)):
        chain.inject.send(frames[i])
    expected = {k: before.get(k, 0) + len(v) for k, v in injected.items()}

    def counted():
        stats = chain.server.stats()
        return all(stats.get(k, 0) >= n for k, n in expected.items())

    assert wait_until(counted), (chain.server.stats(), expected)
    after = chain.server.stats()
    assert {k: after.get(k, 0) for k in expected} == expected  # each counted once, as its kind
    # Still streaming the true state.
    cycles = after["hand_cycles"]
    assert wait_until(lambda: chain.server.stats()["hand_cycles"] > cycles + 20)
    state, _ = client.latest()
    truth = chain.layout.joint_positions(chain.firmware.model.q)
    assert np.max(np.abs(state.q - truth)) < 5 * 0.0005 + 0.5e-4


def test_server_and_hand_on_different_frame_formats_count_and_never_stream(layout,
                                                                          frame_format):
    """A mis-configured pair: every frame of the other format is counted, nothing crashes,
    no hand state reaches the client, and no setpoint moves the hand."""
    other = "classic" if frame_format == "fd" else "fd"
    chain = Chain(layout, frame_format, firmware_format=other)
    try:
        client = chain.client()
        assert client.wait_for_state(3.0, state=1)  # connected ...
        start = chain.firmware.model.setpoint.copy()
        client.send_command(np.clip(start + 0.1, layout.command_lower, layout.command_upper))
        assert wait_until(lambda: chain.server.stats().get("wrong_format_frames", 0) > 50)
        time.sleep(0.1)
        assert client.latest()[0] is None  # ... but never streaming
        assert chain.server.stats().get("hand_cycles", 0) == 0
        # The hand rejects and counts the server's command frames (injected: the server
        # itself sends none before it has seen the hand's position).
        target = np.clip(start + 0.1, layout.command_lower, layout.command_upper)
        frames = chain.server.codec.encode_setpoints(target, seq=5)
        for arbitration_id, data in frames:
            chain.inject.send(_frame(arbitration_id, data, fd=frame_format == "fd"))
        assert wait_until(lambda: chain.firmware.counters["wrong_format_frames"] >= len(frames))
        assert chain.firmware.counters["commits_applied"] == 0
        assert np.array_equal(chain.firmware.model.setpoint, start)
        assert chain.firmware.is_alive() and all(t.is_alive() for t in chain.server._threads)
    finally:
        chain.close()


@pytest.mark.parametrize("chain", [{"max_setpoint_rate": 100.0, "max_step": 0.5}],
                         indirect=True)
def test_setpoint_flood_is_rate_limited_and_the_last_command_wins(chain):
    layout = chain.layout
    commits = []
    stop = threading.Event()

    def watch():
        while not stop.is_set():
            message = chain.monitor.recv(0.05)
            if message is not None and message.arbitration_id == chain.commit_id:
                commits.append(time.monotonic())

    # The server's own commit times (the clock its rate limit runs on): the receiver's
    # clock adds the bus's delivery jitter, which can shorten the window it sees.
    booked = []
    schedule = chain.server._schedule
    book = schedule.commit

    def spy(now):
        booked.append(now)
        book(now)

    schedule.commit = spy
    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    client = chain.client()
    assert client.wait_for_state(3.0)
    client.close()
    booked.clear()
    sock = socket.create_connection(("127.0.0.1", chain.port), timeout=2.0)
    try:
        sock.sendall(P.pack_hello(P.HandInfo("shadow", layout.nq, layout.nu, layout.num_tactile)))
        base = np.clip(np.zeros(layout.nu), layout.command_lower, layout.command_upper)
        sent = 0
        t_end = time.monotonic() + 0.6
        while time.monotonic() < t_end:
            batch = b""
            for _ in range(50):
                sent += 1
                q = base + 0.2 * np.sin(sent / 200.0)
                batch += P.pack_command(sent, q)
            sock.sendall(batch)
        final = np.clip(base + 0.2 * np.sin(sent / 200.0), layout.command_lower,
                        layout.command_upper)
        assert wait_until(lambda: chain.server.stats().get("commands_rx", 0) == sent, 5.0)
        time.sleep(0.1)
    finally:
        sock.close()
        stop.set()
        watcher.join(1.0)
    stats = chain.server.stats()
    assert sent > 2000  # a flood: far more than 100 Hz
    assert len(commits) >= 10
    assert stats["commits_tx"] == len(commits)
    # Every commit of the flood was booked by the rate limit at the time it was sent, and
    # 100 Hz with one slot of tolerance (GCRA): at most 2 + 100 T in any T seconds.
    assert chain.server.config.rate_tolerance == 1.0
    assert len(booked) >= 10 and len(booked) <= len(commits)
    t = np.asarray(booked)
    for i in range(len(t)):
        in_window = np.searchsorted(t, t[i] + 0.2, side="right") - i
        assert in_window <= 2 + 100.0 * 0.2 + 1e-9
    assert len(t) <= 2 + 100.0 * (t[-1] - t[0]) + 1e-9
    assert stats["commands_coalesced"] >= sent - stats["commits_tx"] - 1
    # No lost state: the last command is what the hand tracks.
    assert np.allclose(chain.firmware.model.setpoint, final, atol=0.5e-4 + 1e-12)


def test_out_of_limit_commands_are_clamped(chain):
    layout = chain.layout
    client = chain.client()
    assert client.wait_for_state(3.0)
    high = layout.command_upper + 1.0
    high[::2] = layout.command_lower[::2] - 1.0  # every other joint below its lower limit
    expected = np.where(np.arange(layout.nu) % 2 == 0, layout.command_lower, layout.command_upper)

    def settled():
        client.send_command(high)
        state, _ = client.latest()
        return np.allclose(state.setpoint, expected, atol=1e-12)

    assert wait_until(settled, 5.0, step=0.005)
    state, _ = client.latest()
    assert state.flags & P.FLAG_CLAMPED
    assert chain.server.stats()["commands_clamped"] >= 1
    # The hand reaches the limits and never goes past them (noise aside).
    assert wait_until(lambda: np.max(np.abs(chain.firmware.model.q - expected)) < 1e-3, 5.0)
    assert np.all(chain.firmware.model.q <= layout.command_upper + 1e-12)
    assert np.all(chain.firmware.model.q >= layout.command_lower - 1e-12)


@pytest.mark.parametrize("chain", [{"max_setpoint_rate": 200.0, "max_step": 0.001,
                                    "watchdog": 0.15}], indirect=True)
def test_silent_client_makes_the_server_hold(chain):
    layout = chain.layout
    client = chain.client()
    assert client.wait_for_state(3.0)
    j = layout.actuated_joint_names.index("FFJ3")
    start = chain.firmware.model.setpoint.copy()
    target = start.copy()
    target[j] = layout.command_upper[j]  # 1.57 rad away; 0.2 rad/s at most
    client.send_command(target)  # ... and then silence
    assert wait_until(lambda: chain.server.stats().get("watchdog_holds", 0) == 1, 2.0)
    time.sleep(0.1)
    held = chain.firmware.model.setpoint.copy()
    time.sleep(0.3)
    assert np.array_equal(chain.firmware.model.setpoint, held)  # frozen
    moved = held[j] - start[j]
    # 0.001 rad per commit at <= 200 commits/s during the 0.15 s watchdog (+50 ms slack).
    assert 0.0 < moved <= 0.001 * 200 * 0.2 + 1e-4
    assert target[j] - held[j] > 1.0  # nowhere near the stale target
    state, _ = client.latest()
    assert state.flags & P.FLAG_HOLDING
    # A new command resumes.
    client.send_command(target)
    assert wait_until(lambda: chain.firmware.model.setpoint[j] > held[j] + 0.005, 2.0)


def test_client_for_another_hand_is_refused(chain):
    barrett = hand_layout("barrett")
    client = chain.client(barrett, reconnect_interval=0.05)
    assert wait_until(lambda: "shadow" in client.last_error, 3.0)
    assert client.connection_state == DISCONNECTED
    assert chain.server.stats()["rejected_clients"] >= 1


def test_malformed_tcp_messages_are_rejected_and_counted(chain):
    layout = chain.layout
    info = P.HandInfo("shadow", layout.nq, layout.nu, layout.num_tactile)

    def read_until(sock, reader, wanted, timeout=2.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            data = sock.recv(65536)
            if not data:
                return None
            for message_type, payload in reader.feed(data):
                if message_type == wanted:
                    return payload
        return None

    with socket.create_connection(("127.0.0.1", chain.port), timeout=2.0) as sock:
        reader = P.FrameReader()
        sock.sendall(P.pack_hello(info))
        assert read_until(sock, reader, P.WELCOME) is not None
        sock.sendall(P.pack_command(1, np.zeros(4)))  # Barrett-sized command
        error = read_until(sock, reader, P.ERROR)
        assert b"expected 20 joint values, got 4" in error
        sock.sendall(P.pack(P.STATS_REQ))  # the connection survives a bad payload
        stats = P.unpack_stats(read_until(sock, reader, P.STATS))
        assert stats["commands_rejected"] == 1
        sock.sendall(b"GARBAGE!" * 4)  # broken framing: ERROR, then closed
        assert b"bad magic" in read_until(sock, reader, P.ERROR)
        sock.settimeout(2.0)
        assert wait_until(lambda: _closed(sock), 2.0)
    assert chain.server.stats()["malformed_messages"] == 1
    client = chain.client()
    assert client.wait_for_state(3.0)  # others are still served


def _closed(sock):
    try:
        return sock.recv(65536) == b""
    except OSError:
        return True


def test_welcome_comes_before_any_state_while_the_hand_streams(chain):
    """The I/O thread handles a HELLO outside its I/O lock but marks the client greeted and
    queues WELCOME under it: the bus thread, streaming STATEs meanwhile, never gets a STATE
    in first. Also a command handled between the hand's cycles still reaches the hand."""
    layout = chain.layout
    info = P.HandInfo("shadow", layout.nq, layout.nu, layout.num_tactile)
    assert wait_until(lambda: chain.server.stats().get("hand_cycles", 0) > 10, 3.0)
    firsts = []
    for _ in range(30):
        with socket.create_connection(("127.0.0.1", chain.port), timeout=2.0) as sock:
            sock.sendall(P.pack_hello(info))
            reader, deadline, messages = P.FrameReader(), time.monotonic() + 2.0, []
            while not messages and time.monotonic() < deadline:
                messages = reader.feed(sock.recv(65536))
            firsts.append(messages[0][0] if messages else None)
            sock.sendall(P.pack_command(1, np.clip(np.full(layout.nu, 0.3),
                                                   layout.command_lower, layout.command_upper)))
    assert firsts == [P.WELCOME] * 30
    assert wait_until(lambda: chain.server.stats().get("commits_tx", 0) >= 1, 2.0)
