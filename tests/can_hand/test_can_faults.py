"""Faults and attacks on the CAN chain, with real processes on loopback.

Each test starts ``handle-drake can-sim`` and ``can-server`` as subprocesses
on a random udp_multicast group and port and a free TCP port, attacks one
side (the bus or the TCP clients) and checks that both processes are still
alive, that a good client still receives the hand's STATE stream, and that
the server counted what it dropped. Every subprocess is stopped in teardown;
every wait is bounded.
"""

import os
import resource
import socket
import time

import msgpack
import pytest
from test_can_end_to_end import ROOT, Process, bus_args, free_port, random_bus

from handle_drake.devices.can_hand import protocol as P
from handle_drake.devices.can_hand.layout import hand_layout

SIM_RATE = 200.0  # Hz: the hand cycle rate the good client should keep seeing


@pytest.fixture
def processes():
    started = []
    yield started
    for process in started:
        process.stop()


def _chain(processes, *server_args, preexec_fn=None):
    group, bus_port = random_bus()
    processes.append(Process("can-sim", "--hand", "barrett", "--rate", str(SIM_RATE),
                             *bus_args(group, bus_port)))
    port = free_port()
    server = _ServerProcess(processes, port, group, bus_port, server_args, preexec_fn)
    return group, bus_port, port, server


class _ServerProcess(Process):
    def __init__(self, processes, port, group, bus_port, extra, preexec_fn):
        self._preexec_fn = preexec_fn
        args = ("can-server", "--hand", "barrett", "--listen", f"127.0.0.1:{port}",
                *bus_args(group, bus_port), *extra)
        if preexec_fn is None:
            super().__init__(*args)
        else:  # Process with a resource limit set in the child before exec
            import subprocess
            import sys
            env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep
                       + os.environ.get("PYTHONPATH", ""))
            self.popen = subprocess.Popen(
                [sys.executable, "-m", "handle_drake.devices.can_hand.cli", *args],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT,
                preexec_fn=preexec_fn)
            self.ready_line = self._read_ready(30.0)
        processes.append(self)

    def rss_kib(self):
        with open(f"/proc/{self.popen.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        raise AssertionError("no VmRSS")


class RawClient:
    """A minimal protocol client on a blocking socket: HELLO, then counts STATEs."""

    def __init__(self, port, hand="barrett", hello=True):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self.reader = P.FrameReader()
        layout = hand_layout(hand)
        self.info = P.HandInfo(layout.kind, layout.nq, layout.nu, layout.num_tactile)
        if hello:
            self.sock.sendall(P.pack_hello(self.info))

    def messages(self, duration):
        """Every (arrival time, type, payload) for ``duration`` s."""
        out, deadline = [], time.monotonic() + duration
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(65536)
            except (TimeoutError, ConnectionResetError):
                break
            if not data:
                break
            now = time.monotonic()
            out += [(now, t, p) for t, p in self.reader.feed(data)]
        return out

    def state_times(self, duration):
        return [t for t, kind, _ in self.messages(duration) if kind == P.STATE]

    def stats(self):
        self.sock.sendall(P.pack(P.STATS_REQ))
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            for _, kind, payload in self.messages(0.2):
                if kind == P.STATS:
                    return P.unpack_stats(payload)
        raise AssertionError("no STATS reply")

    def close(self):
        self.sock.close()


def _send_datagrams(group, bus_port, datagrams):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        for data in datagrams:
            s.sendto(data, (group, bus_port))


def _frame(**fields):
    base = dict(timestamp=0.0, arbitration_id=0x300, is_extended_id=False,
                is_remote_frame=False, is_error_frame=False, channel=None, dlc=0, data=b"",
                is_fd=False, bitrate_switch=False, error_state_indicator=False)
    base.update(fields)
    return msgpack.packb(base, use_bin_type=True)


def _alive(processes):
    return all(p.popen.poll() is None for p in processes)


def test_hostile_frames_on_the_bus_are_counted_and_both_processes_keep_running(processes):
    group, bus_port, port, _ = _chain(processes)
    client = RawClient(port)
    assert len(client.state_times(1.0)) > 0.3 * SIM_RATE
    hostile = [
        _frame(arbitration_id=300.5),  # the reproducer: killed both processes
        _frame(arbitration_id=0x110 + 0.5, dlc=8, data=b"\0" * 8, is_fd=True),
        _frame(arbitration_id=True),
        _frame(arbitration_id=2**40),
        _frame(is_fd="yes"), _frame(is_extended_id=3), _frame(is_error_frame=[]),
        _frame(data="text"), _frame(dlc=99), _frame(channel={"a": 1}),
        msgpack.packb([1, 2, 3]), msgpack.packb({"unknown": 1}), b"", b"\xff" * 3000,
        os.urandom(64), msgpack.packb({"arbitration_id": "0x110"}),
    ]
    _send_datagrams(group, bus_port, hostile * 3)
    times = client.state_times(1.0)
    assert _alive(processes)
    assert len(times) > 0.3 * SIM_RATE  # the stream goes on
    stats = client.stats()
    dropped = (stats.get("garbage_frames", 0) + stats.get("malformed_frames", 0)
               + stats.get("foreign_frames", 0))
    assert dropped >= len(hostile) * 3 - 3  # every one counted (a datagram or two may be lost)
    assert stats.get("frame_errors", 0) == 0  # each was recognised, none fell through
    client.close()


def test_garbage_datagrams_do_not_stall_the_state_stream(processes):
    """200 undecodable datagrams cost the bus thread microseconds each: before, each cost
    a 10 ms back-off sleep (a 2 s hole in the STATE stream)."""
    group, bus_port, port, _ = _chain(processes)
    client = RawClient(port)
    client.state_times(0.5)
    _send_datagrams(group, bus_port, [b"\x00garbage"] * 200)
    times = client.state_times(1.5)
    assert _alive(processes)
    gaps = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert len(times) > 0.3 * 1.5 * SIM_RATE and max(gaps) < 0.5
    assert client.stats()["garbage_frames"] >= 190
    client.close()


def test_datagrams_off_the_group_do_not_reach_the_bus(processes):
    """The bus socket is bound to the group on loopback: a unicast datagram to the bus
    port (what python-can's ("", port) socket would accept) is not a frame."""
    group, bus_port, port, _ = _chain(processes)
    client = RawClient(port)
    client.state_times(0.3)
    before = client.stats()["frames_rx"]
    garbage = [b"\x00garbage"] * 50
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for data in garbage:
            s.sendto(data, ("127.0.0.1", bus_port))
    client.state_times(0.5)
    stats = client.stats()
    assert stats.get("garbage_frames", 0) == 0
    _send_datagrams(group, bus_port, garbage)  # the same on the group does arrive
    client.state_times(0.5)
    assert client.stats()["garbage_frames"] >= 45
    assert stats["frames_rx"] > before  # the hand's own frames kept arriving
    client.close()


def test_client_cap_and_hello_timeout_free_the_server(processes):
    group, bus_port, port, _ = _chain(processes, "--max-clients", "8", "--hello-timeout", "2")
    idle = [socket.create_connection(("127.0.0.1", port), timeout=5.0) for _ in range(20)]
    time.sleep(0.5)
    refused = []
    for sock in idle:  # beyond the cap: told "server full", then closed
        sock.settimeout(0.05)
        try:
            refused.append(b"server full" in sock.recv(4096))
        except TimeoutError:
            refused.append(False)
    assert sum(refused) == 12
    # A good client is refused while the idle ones hold every slot...
    blocked = RawClient(port)
    assert blocked.state_times(0.3) == []
    blocked.close()
    time.sleep(2.0)  # ... and served once the hello timeout closed them
    for sock, was_refused in zip(idle, refused, strict=True):
        if not was_refused:
            sock.settimeout(2.0)
            assert sock.recv(4096) == b""  # closed by the server
        sock.close()
    good = RawClient(port)
    assert len(good.state_times(1.0)) > 0.3 * SIM_RATE
    stats = good.stats()
    assert stats["idle_clients_closed"] >= 8 and stats["clients_refused"] >= 13
    assert _alive(processes)
    good.close()


def _limit_files():
    resource.setrlimit(resource.RLIMIT_NOFILE, (64, 64))


def test_running_out_of_file_descriptors_does_not_kill_the_server(processes):
    """Under ``ulimit -n 64`` 100 connections exhaust the descriptors (EMFILE in accept):
    the accept thread survives, and once the idle ones time out a good client is served."""
    group, bus_port, port, server = _chain(processes, "--max-clients", "1000",
                                           "--hello-timeout", "0.5", preexec_fn=_limit_files)
    socks = []
    for _ in range(100):
        try:
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=2.0))
        except OSError:
            break
    time.sleep(1.5)
    assert server.popen.poll() is None
    for sock in socks:
        sock.close()
    time.sleep(0.5)
    good = RawClient(port)
    assert len(good.state_times(1.0)) > 0.3 * SIM_RATE
    stats = good.stats()
    assert stats["accept_errors"] >= 1 and stats["idle_clients_closed"] >= 1
    assert _alive(processes)
    good.close()


def test_a_client_that_never_reads_is_cut_off_and_good_clients_keep_their_rate(processes):
    """A client floods STATS requests and never reads: the server's memory stays bounded
    (before: +23 MB/s), the good client keeps its STATE rate, and the hog is disconnected
    once its capped backlog has stayed full for the slow-client timeout."""
    group, bus_port, port, server = _chain(processes, "--max-client-backlog", "8192")
    good = RawClient(port)
    baseline = len(good.state_times(1.0))
    hog = RawClient(port)
    hog.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    hog.sock.settimeout(0.05)
    request = P.pack(P.STATS_REQ) * 512
    rss_before = server.rss_kib()

    def flood(seconds):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:  # never reads a byte
            try:
                hog.sock.sendall(request)
            except TimeoutError:
                continue
            except OSError:
                return True
        return False

    flood(2.0)
    rate = len(good.state_times(1.0))
    grown = server.rss_kib() - rss_before
    deadline = time.monotonic() + 15.0
    while good.stats().get("slow_clients_closed", 0) < 1 and time.monotonic() < deadline:
        flood(0.5)
    assert good.stats().get("slow_clients_closed", 0) == 1
    assert _alive(processes)
    assert rate > 0.5 * baseline
    assert grown < 20_000  # KiB
    hog.close()
    good.close()
