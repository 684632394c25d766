"""The bus reader of the hot path (:class:`FrameSource`).

On a udp_multicast bus (a random group and port per test, loopback, TTL 1):
a burst of waiting frames is taken in one call without a wait per frame,
a node's own frames (looped back by the multicast bus) never reach it with
the kernel filter and come back as ECHO without a ``can.Message`` being
built without it, and every datagram, hostile ones included, is classified
as python-can's own ``recv`` classifies it (the reference, read side by
side from a second socket on the same group). The server and the simulated
hand on such a bus never see their own frames.
"""

import random
import select
import socket
import time
import uuid

import can
import msgpack
import pytest

import handle_drake.devices.can_hand.bus as bus_module
from handle_drake.devices.can_hand.bus import (
    BUS_ERROR,
    ECHO,
    GARBAGE,
    FrameSource,
    open_bus,
    receive,
)
from handle_drake.devices.can_hand.client import CanHandClient
from handle_drake.devices.can_hand.config import BusConfig, CanFirmwareConfig, CanServerConfig
from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
from handle_drake.devices.can_hand.layout import hand_layout
from handle_drake.devices.can_hand.server import CanBusServer

OWN = frozenset({0x100, 0x10F})  # the ids "this node" sends (a classic setpoint + commit)


def _group():
    return f"239.255.{random.randint(0, 255)}.{random.randint(1, 254)}", random.randint(
        20000, 60000)


@pytest.fixture
def buses(request):
    kernel_filter = getattr(request, "param", True)
    group, port = _group()
    config = BusConfig("udp_multicast", group, port=port, frame_format="classic")
    node = open_bus(config)  # the reader's own node (scoped socket)
    other = open_bus(config)  # another node on the same bus
    reference = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=1,
                        fd=True)  # python-can's own socket and recv: the reference
    source = FrameSource(node, echo_ids=OWN, kernel_filter=kernel_filter)
    yield group, port, node, other, reference, source
    source.close()
    for bus in (node, other, reference):
        bus.shutdown()


def _message(arbitration_id, data=b"\x01\x02\x03\x04\x05\x06\x07\x08"):
    return can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False)


def _settle():
    """Loopback multicast delivers within the send call; a short pause covers a loaded box."""
    time.sleep(0.02)


def _counting_select(monkeypatch):
    calls = []
    real = select.select

    def counted(*args):
        calls.append(args[3] if len(args) > 3 else None)
        return real(*args)

    monkeypatch.setattr(bus_module.select, "select", counted)
    return calls


def test_reads_the_scoped_socket_itself(buses):
    *_, source = buses
    assert source.direct


def test_a_burst_of_waiting_frames_is_taken_in_one_call_without_a_wait(buses, monkeypatch):
    _, _, node, other, _, source = buses
    for i in range(40):
        other.send(_message(0x200 + (i % 4), bytes([i] * 8)))
    _settle()
    selects = _counting_select(monkeypatch)
    batch = source.read(0.5, limit=64)
    assert len(batch) == 40
    assert [m.data[0] for m, why in batch] == list(range(40))  # in order, none lost
    assert all(why is None for _, why in batch)
    assert selects == []  # frames were waiting: no select at all (python-can: one per frame)
    # Nothing left: a zero timeout returns at once, a positive one waits once.
    assert source.read(0.0) == []
    start = time.monotonic()
    assert source.read(0.03) == []
    assert time.monotonic() - start >= 0.025
    assert len(selects) == 1


def test_limit_bounds_a_batch_and_the_rest_waits_for_the_next_call(buses):
    _, _, _, other, _, source = buses
    for i in range(10):
        other.send(_message(0x200, bytes([i] * 8)))
    _settle()
    first = source.read(0.5, limit=4)
    second = source.read(0.5, limit=64)
    assert [m.data[0] for m, _ in first] == [0, 1, 2, 3]
    assert [m.data[0] for m, _ in second] == list(range(4, 10))


@pytest.mark.parametrize("buses", [False], indirect=True)
def test_own_frames_come_back_as_echo_without_building_a_message(buses, monkeypatch):
    _, _, node, other, _, source = buses
    assert not source.kernel_filter
    node.send(_message(0x100))  # our own setpoint and commit: looped back by the bus
    node.send(_message(0x10F))
    other.send(_message(0x220))  # a frame from the hand
    other.send(_message(0x100))  # someone else on one of our ids: also not for us
    _settle()
    built = []

    class Counting(can.Message):
        def __init__(self, *args, **kwargs):
            built.append(kwargs.get("arbitration_id"))
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(bus_module.can, "Message", Counting)
    batch = source.read(0.5)
    assert [why for _, why in batch] == [ECHO, ECHO, None, ECHO]
    assert batch[2][0].arbitration_id == 0x220
    assert built == [0x220]  # only the frame that is not an echo was decoded


def test_the_kernel_filter_keeps_own_frames_from_waking_the_reader_only(buses):
    _, _, node, other, reference, source = buses
    assert source.kernel_filter  # Linux
    node.send(_message(0x100))
    node.send(_message(0x10F))
    other.send(_message(0x220))
    other.send(_message(0x100))  # an own id from another node: dropped as well
    node.send(can.Message(arbitration_id=0x100, data=b"", is_extended_id=True))  # not ours
    _settle()
    batch = source.read(0.5)
    assert [(m.arbitration_id, m.is_extended_id) for m, _ in batch] == [(0x220, False),
                                                                       (0x100, True)]
    assert source.read(0.0) == []
    # The filter is this node's alone: the other nodes receive every frame.
    seen = []
    while (message := reference.recv(0.1)) is not None:
        seen.append(message.arbitration_id)
    assert seen == [0x100, 0x10F, 0x220, 0x100, 0x100]


def _datagram(**fields):
    base = dict(timestamp=0.0, arbitration_id=0x220, is_extended_id=False,
                is_remote_frame=False, is_error_frame=False, channel=None, dlc=8,
                data=b"\0" * 8, is_fd=False, bitrate_switch=False, error_state_indicator=False)
    base.update(fields)
    return msgpack.packb(base, use_bin_type=True)


HOSTILE = [
    _datagram(), _datagram(arbitration_id=0x100), _datagram(arbitration_id=300.5),
    _datagram(arbitration_id=True), _datagram(arbitration_id=2 ** 40),
    _datagram(arbitration_id=0x100, is_extended_id=True),  # an own id, but extended
    _datagram(arbitration_id=0x10F, is_remote_frame=True, dlc=0, data=b""),
    _datagram(is_fd="yes"), _datagram(data="text"), _datagram(dlc=99),
    _datagram(channel={"a": 1}), msgpack.packb([1, 2, 3]), msgpack.packb({"unknown": 1}),
    b"", b"\xff" * 3000, b"\x00garbage", msgpack.packb({"arbitration_id": "0x110"}),
    msgpack.packb({"arbitration_id": [1]}),
]


def _summary(message, why):
    if message is None:
        return why
    return (message.arbitration_id, bytes(message.data), message.is_extended_id,
            message.is_remote_frame, message.is_fd)


@pytest.mark.parametrize("buses", [True, False], indirect=True)
def test_every_datagram_is_classified_as_python_can_classifies_it(buses):
    group, port, _, _, reference, source = buses
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        for data in HOSTILE:
            s.sendto(data, (group, port))
    _settle()
    ours = [_summary(m, why) for m, why in source.read(0.5, limit=100)]
    theirs = [_summary(*receive(reference, 0.2)) for _ in HOSTILE]
    # python-can decodes an own-id frame; here only a plain one is an echo: dropped in the
    # kernel by the filter, else returned as ECHO undecoded. Everything else as python-can.
    echo = [isinstance(t, tuple) and t[0] in OWN and not t[2] and not t[3] for t in theirs]
    assert sum(echo) == 1
    if source.kernel_filter:
        expected = [t for t, e in zip(theirs, echo, strict=True) if not e]
    else:
        expected = [ECHO if e else t for t, e in zip(theirs, echo, strict=True)]
    assert ours == expected
    assert ours.count(GARBAGE) >= 8 and BUS_ERROR not in ours


def test_other_buses_are_read_through_python_can_a_batch_at_a_time():
    channel = f"test-{uuid.uuid4().hex}"
    node = can.Bus(interface="virtual", channel=channel)
    other = can.Bus(interface="virtual", channel=channel)
    source = FrameSource(node, echo_ids=OWN)
    try:
        assert not source.direct
        for i in range(5):
            other.send(_message(0x200, bytes([i] * 8)))
        batch = source.read(0.5)
        assert [m.data[0] for m, _ in batch] == list(range(5))
        assert source.read(0.01) == []
    finally:
        source.close()
        node.shutdown()
        other.shutdown()


def test_a_closed_source_reports_a_bus_error_not_a_crash(buses):
    *_, source = buses
    source._socket.close()
    assert source.read(0.01) == [(None, BUS_ERROR)]


def _barrett_chain(frame_format):
    """A started server and simulated Barrett hand on a fresh udp_multicast group."""
    group, port = _group()
    bus = BusConfig("udp_multicast", group, port=port, frame_format=frame_format)
    layout = hand_layout("barrett")
    server = CanBusServer(CanServerConfig(port=0, hand_kind="barrett", bus=bus), layout=layout)
    firmware = SimulatedHandFirmware(CanFirmwareConfig(hand_kind="barrett", bus=bus, rate=500.0),
                                     layout=layout)
    server.start()
    firmware.start()
    return layout, server, firmware


@pytest.mark.parametrize("frame_format", ["classic", "fd"])
def test_server_and_hand_never_receive_their_own_frames(frame_format):
    """Before, each got its own frames back from the multicast bus and decoded them (the
    server 2 per classic Barrett command, the hand 4 per reply), a wake-up each."""
    layout, server, firmware = _barrett_chain(frame_format)
    client = CanHandClient(layout, "127.0.0.1", server.address[1]).start()
    try:
        assert server._source.kernel_filter and firmware._source.kernel_filter
        # one thread serves the clients and the bus (see the server's docstring)
        assert server.one_thread and [t.name for t in server._threads] == ["can-server-io"]
        assert client.wait_for_state(5.0)
        for k in range(50):
            client.send_command(layout.command_lower + 0.1 + 0.001 * k)
            time.sleep(0.004)
        deadline = time.monotonic() + 3.0
        while firmware.counters["commits_applied"] < 40 and time.monotonic() < deadline:
            time.sleep(0.01)
        stats = server.stats()
    finally:
        client.close()
        firmware.stop()
        server.stop()
    assert stats["commits_tx"] >= 40 and firmware.counters["commits_applied"] >= 40
    assert stats["hand_cycles"] >= 40
    assert stats.get("echo_frames", 0) == 0 and firmware.counters["echo_frames"] == 0


def test_a_one_thread_server_backs_off_a_failing_bus_and_keeps_serving_clients():
    """The bus socket is waited on with the clients' sockets: a bus whose reads fail (and
    which stays readable) is polled again after a doubling back-off, not in a spin; a
    client is served meanwhile, and the hand's state flows again once the bus recovers."""
    layout, server, firmware = _barrett_chain("classic")
    clients = [CanHandClient(layout, "127.0.0.1", server.address[1]).start()]
    failing = {"on": False, "reads": 0}
    read = server._source.read

    def flaky_read(timeout, limit=64):
        if failing["on"]:
            failing["reads"] += 1
            return [(None, BUS_ERROR)]
        return read(timeout, limit)

    server._source.read = flaky_read
    try:
        assert server.one_thread and clients[0].wait_for_state(5.0)
        failing["on"] = True
        start = time.monotonic()
        clients.append(CanHandClient(layout, "127.0.0.1", server.address[1]).start())
        assert clients[1].wait_for_state(2.0, state=1)  # handshake served during the failure
        time.sleep(max(0.0, 0.4 - (time.monotonic() - start)))
        failing["on"] = False
        errors = server.stats().get("bus_rx_errors", 0)
        # the hand's frames kept the socket readable all along: 1, 2, 4 ... 256 ms apart
        assert 3 <= failing["reads"] <= 12 and errors == failing["reads"]
        states = clients[1].counters["states_received"]
        deadline = time.monotonic() + 3.0
        while clients[1].counters["states_received"] < states + 20 and \
                time.monotonic() < deadline:
            time.sleep(0.01)
        assert clients[1].counters["states_received"] >= states + 20  # the bus is back
        assert all(t.is_alive() for t in server._threads)
    finally:
        for client in clients:
            client.close()
        firmware.stop()
        server.stop()
