"""Full-hand setpoint round trip through TCP and the CAN bus on loopback.

A client sends a full-hand command at 1 kHz to the CAN bus server, which
forwards it as setpoint frames to the simulated firmware (1 kHz joint-model
step); the round trip ends when a STATE whose ``seq_ack`` covers the command
comes back. The firmware acknowledges as each hand does (``can-sim
--feedback``, see :mod:`handle_drake.devices.can_hand.firmware`): the Shadow
once per 1 kHz control cycle (a command waits 0-1 ms for the next cycle), the
Barrett at once, on receipt of the setpoint (FD) or its commit (classic),
with the last step's state, as the real hand's pucks answer the host's
request; ``procs-udp-cycle/barrett/...`` runs the Barrett chain with the
per-cycle firmware for comparison. Side by side in one run, each case in its
own child process:

- ``inproc-virtual``: server, firmware and client as threads of one process
  on python-can's virtual bus;
- ``procs-udp``: ``handle-drake can-sim`` and ``can-server`` as separate
  processes on a udp_multicast bus (the deployment shape), the client in a
  third process;
- ``procs-udp-rt``: the same with ``--rt-priority 50`` (the bus threads of
  the firmware and the server, and the client's receive thread, under
  SCHED_FIFO), as a control loop on a shared machine would run;

for the Shadow hand (20 commands, 24 joints) and the Barrett hand (4, 8), and
for both frame formats: ``classic`` (8-byte CAN 2.0 frames: Shadow 6 setpoint
+ 9 feedback frames per cycle, Barrett 2 + 4) and ``fd`` (CAN FD: one setpoint
frame, one feedback frame). The table also gives the bus time one cycle
would take on a real bus (classic 1 Mbit/s; FD 1 Mbit/s arbitration, 5 Mbit/s
data; unstuffed .. worst-case stuffing). With ``--baseline REV`` the classic
cases also run on ``handle_drake/devices/can_hand`` as of git revision REV
("before"), interleaved with the working tree ("after").

The floor, with no project code, measured in the same run:

- ``floor-udp-1``: python-can udp_multicast ping-pong of one frame between
  two processes at 1 kHz;
- ``floor-udp-shadow``: the same with a classic Shadow cycle's frame counts (7
  frames out, 9 back, the reply sent as soon as the 7th arrives);
- ``floor-udp-barrett``: the same with a classic Barrett cycle's (2 out: its setpoint
  frame and the commit; 4 back: 2 position, tactile, status);
- ``floor-udp-fd``: one 48-byte CAN FD frame out, one 64-byte frame back (the
  FD Shadow cycle);
- ``floor-tcp``: a bare TCP_NODELAY ping-pong of a COMMAND-sized message.

The chain's round trip cannot beat ``floor-tcp + floor-udp-shadow`` (classic)
or ``floor-tcp + floor-udp-fd`` (fd), plus, for a per-cycle hand, the wait for
its next cycle (uniform in 0..1 ms at 1 kHz). The command clock runs one hand period per
run slower than 1 kHz, so the phase between
command and hand cycle sweeps once through the cycle, as between two
independent clocks (otherwise a run's latency depends on its start phase).
Slower, not faster: the server commits at most ``max_setpoint_rate`` (1 kHz)
setpoints a second, and a client even 0.025 % faster than that limit queues
in its rate limiter (with half a slot of tolerance, the second half of a 4 s
run waited 0-0.5 ms per command: the limiter's delay, not the round trip's;
measured before 2026-11-27 evening; the server's default tolerance is one slot
since 2026-11-28, under which the faster clock reaches the limit only at the
run's end).

Targets: >= 1 kHz updates (state/s), p99 <= 2 ms. Writes
``benchmarks/results/can.json``; every figure comes with the load average.

    python benchmarks/bench_can.py                      # 4 s per case
    python benchmarks/bench_can.py --baseline 7f4a6f5   # before/after
    HANDLE_DRAKE_REDUCED=1 python benchmarks/bench_can.py   # 1 s per case
    python benchmarks/bench_can.py --rounds 3               # Barrett against Shadow, the page
    python benchmarks/bench_can.py --rounds 2 --hops --no-page   # each round trip's hops
"""

from __future__ import annotations

import argparse
import collections
import gc
import json
import os
import random
import selectors
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CODE = Path(os.environ.get("BENCH_CAN_CODE", ROOT))  # the handle_drake tree under test
sys.path.insert(0, str(CODE))

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.base.testing import pick  # noqa: E402

RATE = 1000.0  # Hz: command rate, server commit limit and firmware cycle
DURATION = pick(4.0, 1.0)  # s per case
WARMUP = 0.3  # s
KINDS = ("shadow", "barrett")
FORMATS = ("classic", "fd")
CHAIN_CASES = ("inproc-virtual", "procs-udp", "procs-udp-rt")
RT_PRIORITY = 50  # SCHED_FIFO priority of the bus threads in the -rt case
FLOOR_CASES = ("floor-udp-1", "floor-udp-shadow", "floor-udp-barrett", "floor-udp-fd",
               "floor-tcp")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def random_group() -> tuple[str, int]:
    return f"239.255.{random.randint(0, 255)}.{random.randint(1, 254)}", random.randint(20000,
                                                                                       60000)


def cpu_seconds(pid: int | None = None) -> float:
    """User + system CPU time of a process (this one when None)."""
    if pid is None:
        t = os.times()
        return t.user + t.system
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def summary(latencies_s, elapsed: float, cpu0, cpu1) -> dict:
    latencies = np.asarray(latencies_s, dtype=float) * 1e3
    p = (np.percentile(latencies, [50, 90, 99]) if latencies.size
         else [float("nan")] * 3)
    return {
        "acked": int(latencies.size),
        "latency_ms_p50": float(p[0]), "latency_ms_p90": float(p[1]),
        "latency_ms_p99": float(p[2]),
        "latency_ms_max": float(latencies.max()) if latencies.size else float("nan"),
        # CPU use, % of one core: this process, then the firmware and server processes
        "cpu_percent": [100 * (b - a) / elapsed for a, b in zip(cpu0, cpu1, strict=True)],
    }


def sleep_until(deadline: float) -> None:
    """One sleep to the deadline (no polling loop)."""
    remaining = deadline - time.perf_counter()
    if remaining > 0:
        time.sleep(remaining)


# -- the chain -----------------------------------------------------------------------
class _CommandTrace(collections.OrderedDict):
    """Stands in for the client's table of unacknowledged commands: keeps, per seq, the
    time the command was written (the client's own stamp) and the time its STATE came."""

    def __init__(self):
        super().__init__()
        self.sent, self.acked = {}, {}

    def __setitem__(self, seq, t):
        self.sent[seq] = t
        super().__setitem__(seq, t)

    def pop(self, seq, *default):
        self.acked[seq] = time.perf_counter()
        return super().pop(seq, *default)


_TAG_STEP, _TAG_COUNT = 4e-4, 500  # rad per tag value (4 counts), distinct tags


def _tag_value(layout, seq: int) -> float:
    """The last joint's command that tags command ``seq`` (seq mod 500, 4e-4 rad apart)."""
    return float(layout.command_lower[-1]) + 0.05 + _TAG_STEP * (seq % _TAG_COUNT)


def _tag_of(layout, q_last: float) -> int:
    return int(round((q_last - float(layout.command_lower[-1]) - 0.05) / _TAG_STEP)) % _TAG_COUNT


def drive(client, layout, duration: float, pids=(), trace: bool = False) -> dict:
    """Sends commands at ~RATE for ``duration`` s; rates, latencies, CPU per process.

    ``trace``: also return, under ``"trace"``, the measured window's per-command send
    and acknowledgement times (``time.time`` scale) for :func:`hop_summary`.
    """
    assert client.wait_for_state(15.0), client.last_error
    # As the CLI processes do: the start-up heap (numpy, cantools, hand models) leaves
    # the garbage collector's reach, or a full collection stalls every thread 30-50 ms.
    gc.collect()
    gc.freeze()
    base = np.clip(np.zeros(layout.nu), layout.command_lower, layout.command_upper)
    span = 0.2 * (layout.command_upper - layout.command_lower)
    for seconds in (WARMUP, duration):
        # One hand period of drift per run: the phase sweeps the hand cycle once.
        # Slower than the server's commit limit (RATE), never faster: see the docstring.
        # (``procs-udp-fastclock`` keeps the clock this benchmark used before, for comparison.)
        drift = -1.0 if os.environ.get("BENCH_CAN_CLOCK") == "faster" else 1.0
        period = 1.0 / RATE + drift / RATE / (seconds * RATE)
        client.latencies.clear()
        if trace:
            with client._lock:
                client._sent_times = _CommandTrace()
        stats0 = client.request_stats(2.0)
        t_stats0 = time.perf_counter()
        cpu0 = [cpu_seconds(None)] + [cpu_seconds(pid) for pid in pids]
        states0 = client.counters["states_received"]
        sent = 0
        start = time.perf_counter()
        next_time = start
        while next_time - start < seconds:
            sleep_until(next_time)
            now = time.perf_counter()
            q = base + span * (0.5 + 0.5 * np.sin(np.pi * (now - start)))
            if trace:  # the last joint carries the command's seq (see hop_summary)
                q[-1] = _tag_value(layout, client._seq + 1)
            client.send_command(q)
            sent += 1
            next_time += period
        elapsed = time.perf_counter() - start
        cpu1 = [cpu_seconds(None)] + [cpu_seconds(pid) for pid in pids]
        states = client.counters["states_received"] - states0
        time.sleep(0.05)  # let the last acknowledgements in
        stats1 = client.request_stats(2.0)
        stats_window = time.perf_counter() - t_stats0  # server counters: request to request
    extra = {}
    if trace:
        offset = time.time() - time.perf_counter()  # perf_counter -> time.time (kernel stamps)
        table = client._sent_times
        extra["trace"] = [(seq, t + offset, table.acked[seq] + offset)
                          for seq, t in table.sent.items() if seq in table.acked]
    frames = (stats1.get("frames_tx", 0) - stats0.get("frames_tx", 0)
              + stats1.get("frames_rx", 0) - stats0.get("frames_rx", 0)
              - (stats1.get("echo_frames", 0) - stats0.get("echo_frames", 0)))
    return {
        "commands_per_s": sent / elapsed,
        "commits_per_s": (stats1["commits_tx"] - stats0.get("commits_tx", 0)) / stats_window,
        "states_per_s": states / elapsed,
        "hand_cycles_per_s": (stats1["hand_cycles"] - stats0["hand_cycles"]) / stats_window,
        "can_frames_per_s": frames / stats_window,
        **summary(client.latencies, elapsed, cpu0, cpu1), **extra,
    }


def _bus_kwargs(frame_format: str | None) -> dict:
    """BusConfig fields for a format (None: the code under test predates frame formats)."""
    return {} if frame_format is None else {"frame_format": frame_format}


def case_inproc(kind: str, frame_format: str | None) -> dict:
    from handle_drake.devices.can_hand.client import CanHandClient
    from handle_drake.devices.can_hand.config import BusConfig, CanFirmwareConfig, CanServerConfig
    from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
    from handle_drake.devices.can_hand.layout import hand_layout
    from handle_drake.devices.can_hand.server import CanBusServer

    layout = hand_layout(kind)
    bus = BusConfig("virtual", f"bench-{uuid.uuid4().hex}", **_bus_kwargs(frame_format))
    server = CanBusServer(CanServerConfig(port=0, hand_kind=kind, bus=bus,
                                          max_setpoint_rate=RATE, max_step=0.5),
                          layout=layout).start()
    firmware = SimulatedHandFirmware(CanFirmwareConfig(hand_kind=kind, bus=bus, rate=RATE),
                                     layout=layout).start()
    client = CanHandClient(layout, "127.0.0.1", server.address[1], record_latency=True).start()
    try:
        return drive(client, layout, DURATION)
    finally:
        client.close()
        firmware.stop()
        server.stop()


def _spawn(args, module=True) -> subprocess.Popen:
    """A child on the code under test that prints a line with ``ready``."""
    env = dict(os.environ, PYTHONPATH=str(CODE), BENCH_CAN_CODE=str(CODE),
               OPENBLAS_NUM_THREADS="1")
    command = ([sys.executable, "-m", "handle_drake.devices.can_hand.cli"] if module
               else [sys.executable, str(Path(__file__).resolve())])
    process = subprocess.Popen([*command, *args], stdout=subprocess.PIPE,
                               stderr=subprocess.DEVNULL, text=True, env=env, cwd=CODE)
    selector = selectors.DefaultSelector()
    selector.register(process.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + 30
    try:
        while time.monotonic() < deadline:
            if selector.select(0.5) and "ready" in process.stdout.readline():
                return process
            if process.poll() is not None:
                break
    finally:
        selector.close()
    process.kill()
    raise RuntimeError(f"{args[0]} did not start")


def _stop(processes) -> None:
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    for process in processes:
        try:
            process.wait(5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(5)


def case_procs(kind: str, frame_format: str | None, rt_priority: int = 0,
               feedback: str | None = None, hops: bool = False) -> dict:
    from handle_drake.devices.can_hand.client import CanHandClient
    from handle_drake.devices.can_hand.layout import hand_layout

    layout = hand_layout(kind)
    group, bus_port = random_group()
    bus = ["--bus", "udp_multicast", "--channel", group, "--bus-port", str(bus_port),
           "--hand", kind]
    if frame_format is not None:
        bus += ["--frame-format", frame_format]
    if rt_priority:
        bus += ["--rt-priority", str(rt_priority)]
    port = free_port()
    processes = []
    try:
        sim = ["--feedback", feedback] if feedback else []  # None: the hand's own
        processes.append(_spawn(["can-sim", *bus, "--rate", str(RATE), *sim]))
        processes.append(_spawn(["can-server", *bus, "--listen", f"127.0.0.1:{port}",
                                 "--max-rate", str(RATE), "--max-step", "0.5"]))
        rt = {"realtime_priority": rt_priority} if rt_priority else {}
        if rt_priority:  # the commanding thread too: it holds the GIL the client thread needs
            from handle_drake.devices.can_hand.bus import use_realtime_priority

            use_realtime_priority(rt_priority)
        tap_file = None
        if hops:  # a passive listener on the bus: kernel receive stamps of every frame
            tap_file = tempfile.NamedTemporaryFile(suffix=".json", delete=False).name
            processes.append(_spawn(["--child-tap", group, str(bus_port), tap_file],
                                    module=False))
        with CanHandClient(layout, "127.0.0.1", port, record_latency=True, **rt) as client:
            result = drive(client, layout, DURATION, pids=[p.pid for p in processes[:2]],
                           trace=hops)
        if hops:
            _stop(processes[2:])
            frames = json.loads(Path(tap_file).read_text())
            Path(tap_file).unlink()
            result["hops"] = hop_summary(result.pop("trace"), frames, kind, frame_format)
        return result
    finally:
        _stop(processes)


def tap_bus(group: str, port: int, path: str) -> None:
    """Records ``(kernel receive time, id, data hex)`` of every frame until SIGTERM.

    Wakes every 20 ms and drains the socket: the stamps are the kernel's (taken when
    the datagram reached this socket, i.e. when it was sent on loopback), so this
    process's own scheduling does not enter them, and it costs the chain few wake-ups.
    """
    bus = _udp_bus(group, port)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    frames = []
    print("ready", flush=True)
    while not stop:
        time.sleep(0.02)
        while (message := bus.recv(0.0)) is not None:
            frames.append((message.timestamp, message.arbitration_id, bytes(message.data).hex()))
    while (message := bus.recv(0.0)) is not None:
        frames.append((message.timestamp, message.arbitration_id, bytes(message.data).hex()))
    bus.shutdown()
    Path(path).write_text(json.dumps(frames))


def hop_summary(trace, frames, kind: str, frame_format: str) -> dict:
    """Splits each round trip into its hops, from the client's and the bus tap's stamps.

    - ``to_bus``: client writes the COMMAND -> the server's commit frame is on the bus
      (TCP, the server's I/O thread, encoding, send);
    - ``hand``: commit frame on the bus -> the hand's feedback acknowledging it is on the
      bus (classic: its STATUS frame, the cycle's last);
    - ``to_client``: that feedback on the bus -> the client has the STATE (the server's
      bus thread, TCP, the client's thread).

    Commands map to commits by a tag: while tracing, the last joint's command is
    ``_tag_value(seq)`` (commit seqs are the server's own, and a command coalesced by its
    rate limit has no commit: those commands are left out).
    """
    from handle_drake.devices.can_hand.layout import hand_layout
    from handle_drake.devices.can_hand.messages import make_codec

    layout = hand_layout(kind)
    codec = make_codec(layout, frame_format)
    setpoints, feedback = codec.setpoint_receiver(), codec.feedback_receiver()
    commits, acks = [], []  # (kernel time, commit seq, tag) / (kernel time, seq_ack)
    for t, arbitration_id, data in sorted(frames):
        data = bytes.fromhex(data)
        if arbitration_id in codec.host_to_hand_ids:
            applied = setpoints.feed(arbitration_id, data, codec.is_fd)
            if applied is not None:  # FD: the setpoint frame; classic: the commit frame
                commits.append((t, applied[0], _tag_of(layout, applied[1][-1])))
        elif arbitration_id in codec.hand_to_host_ids:
            snapshot = feedback.feed(arbitration_id, data, codec.is_fd)
            if snapshot is not None:  # classic: the STATUS frame, the cycle's last
                acks.append((t, snapshot.seq_ack))
    ack_times = np.array([t for t, _ in acks])
    ack_seqs = np.array([seq for _, seq in acks])
    # Each command's commit: the first commit carrying its tag after the command was
    # written (less 1 ms: the server may commit before the client's send() returns).
    by_tag = collections.defaultdict(list)
    for t, commit, tag in commits:
        by_tag[tag].append((t, commit))
    rows = []
    for seq, sent, acked in trace:
        found = [(t, c) for t, c in by_tag.get(seq % _TAG_COUNT, ()) if sent - 1e-3 <= t <= acked]
        if not found:
            continue  # coalesced into a later command by the server's rate limit
        t_commit, commit = found[0]
        i = np.searchsorted(ack_times, t_commit)
        covered = np.nonzero((ack_seqs[i:] - commit) % 65536 < 32768)[0]
        if covered.size == 0:
            continue
        t_ack = ack_times[i + covered[0]]
        if t_ack > acked:
            continue
        rows.append((t_commit - sent, t_ack - t_commit, acked - t_ack, acked - sent, sent))
    if not rows:
        return {"matched": 0}
    rows = np.array(rows)
    hops = rows[:, :4] * 1e3  # ms
    names = ("to_bus", "hand", "to_client")
    total = hops[:, 3]
    in_tail = total >= np.percentile(total, 99)
    tail = hops[in_tail]
    # When the slowest 1 % happened (s into the run): a few stalls, or spread out?
    tail_times = np.sort(rows[in_tail, 4] - rows[0, 4])
    episodes = 1 + int(np.sum(np.diff(tail_times) > 0.05)) if tail_times.size else 0
    worst = collections.Counter(names[k] for k in np.argmax(tail[:, :3], axis=1))
    return {
        "matched": len(rows), "commands": len(trace),
        "p50_ms": {n: float(np.percentile(hops[:, k], 50)) for k, n in enumerate(names)},
        "p99_ms": {n: float(np.percentile(hops[:, k], 99)) for k, n in enumerate(names)},
        "total_p99_ms": float(np.percentile(total, 99)),
        # the slowest 1 %: each hop's median there, and which hop was the largest how often
        "tail_median_ms": {n: float(np.median(tail[:, k])) for k, n in enumerate(names)},
        "tail_largest_hop": dict(worst), "tail_size": len(tail),
        # the slowest 1 % grouped into episodes (gaps > 50 ms between them)
        "tail_episodes": episodes, "tail_times_s": [round(float(t), 4) for t in tail_times],
    }


# -- the floor: no project code ----------------------------------------------------------
def _udp_bus(group: str, port: int):
    import can

    return can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=1, fd=True)


def _frame(arbitration_id: int, data: bytes, size: int):
    """A CAN 2.0 frame of ``data`` (size 8) or a CAN FD frame padded to ``size`` bytes."""
    import can

    fd = size > 8
    return can.Message(arbitration_id=arbitration_id, data=data.ljust(size, b"\0"),
                       is_extended_id=False, is_fd=fd, bitrate_switch=fd)


def echo_udp(group: str, port: int, n_in: int, n_out: int, size_out: int = 8) -> None:
    """Replies ``n_out`` frames (id 0x200+) each time frame ``n_in - 1`` (id 0x100+) arrives."""
    bus = _udp_bus(group, port)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print("ready", flush=True)
    while not stop:
        message = bus.recv(0.1)
        if message is None or message.arbitration_id != 0x100 + n_in - 1:
            continue  # our own replies, earlier frames of the burst
        for i in range(n_out):
            bus.send(_frame(0x200 + i, bytes(message.data[:8]), size_out))
    bus.shutdown()


def case_floor_udp(n_in: int, n_out: int, size_in: int = 8, size_out: int = 8) -> dict:
    group, port = random_group()
    echo = _spawn(["--child-echo-udp", group, str(port), str(n_in), str(n_out), str(size_out)],
                  module=False)
    bus = _udp_bus(group, port)
    try:
        latencies, start_times = [], {}
        for seconds in (WARMUP, DURATION):
            latencies.clear()
            cpu0 = [cpu_seconds(None), cpu_seconds(echo.pid)]
            start = time.perf_counter()
            next_time, seq = start, 0
            while next_time - start < seconds:
                sleep_until(next_time)
                seq += 1
                data = seq.to_bytes(8, "little")
                start_times[seq] = time.perf_counter()
                for i in range(n_in):
                    bus.send(_frame(0x100 + i, data, size_in))
                next_time += 1.0 / RATE
                # Receive until the next send is due.
                while (timeout := next_time - time.perf_counter()) > 0:
                    message = bus.recv(timeout)
                    if message is not None and message.arbitration_id == 0x200 + n_out - 1:
                        sent = start_times.pop(int.from_bytes(message.data[:8], "little"), None)
                        if sent is not None:
                            latencies.append(time.perf_counter() - sent)
            elapsed = time.perf_counter() - start
            cpu1 = [cpu_seconds(None), cpu_seconds(echo.pid)]
            start_times.clear()
        return {"commands_per_s": seq / elapsed, "states_per_s": len(latencies) / elapsed,
                **summary(latencies, elapsed, cpu0, cpu1)}
    finally:
        bus.shutdown()
        _stop([echo])


def echo_tcp(port: int) -> None:
    listen = socket.create_server(("127.0.0.1", port))
    print("ready", flush=True)
    connection, _ = listen.accept()
    connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    while data := connection.recv(65536):
        connection.sendall(data)


def case_floor_tcp() -> dict:
    port = free_port()
    echo = _spawn(["--child-echo-tcp", str(port)], module=False)
    size = 8 + 4 + 8 * 20  # a Shadow COMMAND
    try:
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            latencies = []
            for seconds in (WARMUP, DURATION):
                latencies.clear()
                cpu0 = [cpu_seconds(None), cpu_seconds(echo.pid)]
                start = time.perf_counter()
                next_time, n = start, 0
                while next_time - start < seconds:
                    sleep_until(next_time)
                    t = time.perf_counter()
                    sock.sendall(bytes(size))
                    got = 0
                    while got < size:
                        got += len(sock.recv(65536))
                    latencies.append(time.perf_counter() - t)
                    n += 1
                    next_time += 1.0 / RATE
                elapsed = time.perf_counter() - start
                cpu1 = [cpu_seconds(None), cpu_seconds(echo.pid)]
        return {"commands_per_s": n / elapsed, "states_per_s": len(latencies) / elapsed,
                **summary(latencies, elapsed, cpu0, cpu1)}
    finally:
        _stop([echo])


def bus_time_us(kind: str, frame_format: str) -> tuple[float, float]:
    """Bus time (us) of one command + one hand cycle: unstuffed, worst-case stuffing."""
    from handle_drake.devices.can_hand.layout import hand_layout
    from handle_drake.devices.can_hand.messages import cycle_bus_time, make_codec

    codec = make_codec(hand_layout(kind), frame_format)
    return (1e6 * cycle_bus_time(codec), 1e6 * cycle_bus_time(codec, worst_case_stuffing=True))


def run_case(case: str, kind: str, frame_format: str) -> dict:
    frame_format = None if frame_format == "-" else frame_format
    if case == "inproc-virtual":
        return case_inproc(kind, frame_format)
    hops = os.environ.get("BENCH_CAN_HOPS") == "1"
    if case == "procs-udp":
        return case_procs(kind, frame_format, hops=hops)
    if case == "procs-udp-fastclock":  # the earlier command clock, 1 period per run faster
        os.environ["BENCH_CAN_CLOCK"] = "faster"
        return case_procs(kind, frame_format)
    if case == "procs-udp-cycle":  # the firmware acknowledging once per cycle
        return case_procs(kind, frame_format, feedback="cycle", hops=hops)
    if case == "procs-udp-rt":
        return case_procs(kind, frame_format, RT_PRIORITY)
    if case == "floor-udp-1":
        return case_floor_udp(1, 1)
    if case == "floor-udp-shadow":
        return case_floor_udp(7, 9)
    if case == "floor-udp-barrett":
        return case_floor_udp(2, 4)
    if case == "floor-udp-fd":
        return case_floor_udp(1, 1, 48, 64)
    if case == "floor-tcp":
        return case_floor_tcp()
    cases = CHAIN_CASES + FLOOR_CASES + ("procs-udp-fastclock", "procs-udp-cycle")
    raise ValueError(f"case: expected one of {cases}, got {case!r}")


# -- the parent: one child process per case --------------------------------------------------
def baseline_tree(revision: str, directory: Path) -> Path:
    """The working tree's handle_drake with can_hand from ``revision`` (git archive)."""
    tree = directory / "baseline"
    shutil.copytree(ROOT / "handle_drake", tree / "handle_drake",
                    ignore=shutil.ignore_patterns("__pycache__", "can_hand"))
    (tree / "models").symlink_to(ROOT / "models")
    archive = subprocess.run(["git", "archive", revision, "handle_drake/devices/can_hand"],
                             cwd=ROOT,
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def child(code: Path, case: str, kind: str, frame_format: str = "-") -> dict:
    env = dict(os.environ, BENCH_CAN_CODE=str(code), PYTHONPATH=str(code),
               OPENBLAS_NUM_THREADS="1")
    result = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", case, kind,
                             frame_format],
                            capture_output=True, text=True, env=env, cwd=code, timeout=120)
    if result.returncode != 0:
        raise RuntimeError(f"{case}/{kind} failed:\n{result.stderr[-3000:]}")
    value = json.loads(result.stdout.strip().splitlines()[-1])
    value["load_average"] = os.getloadavg()
    return value


def rounds(n: int, run: ResultsRun, old_clock: bool = False, hops: bool = False) -> None:
    """Barrett against Shadow without RT priority, interleaved and repeated, floors in each round.

    Each round runs every procs-udp case, the Barrett with per-cycle feedback
    (``procs-udp-cycle``) and the UDP/TCP floors once, in a random order, so
    the load of the machine falls on all cases alike; the table gives, per case, the median
    and range over rounds of p50 and p99 and how often p99 met 2 ms.
    """
    names = [f"procs-udp/{k}/{f}" for k in KINDS for f in FORMATS] + list(FLOOR_CASES)
    # The Barrett's firmware acknowledging once per cycle, as before 2026-11-27 evening
    # (the Shadow's behaviour): the same chain with and without the wait for the cycle.
    names += [f"procs-udp-cycle/barrett/{f}" for f in FORMATS]
    if hops:  # the chains only, each with a bus tap (see hop_summary)
        names = [name for name in names if name.startswith("procs-")]
        os.environ["BENCH_CAN_HOPS"] = "1"
    if old_clock:  # the same chains under the clock used before 2026-11-27 evening
        names += [f"procs-udp-fastclock/{k}/{f}" for k in KINDS for f in FORMATS]
    rng = random.Random(0)
    runs: dict[str, list] = {name: [] for name in names}
    load_start = os.getloadavg()
    for r in range(n):
        order = names[:]
        rng.shuffle(order)
        for name in order:
            parts = name.split("/")
            result = (child(ROOT, parts[0], parts[1], parts[2]) if len(parts) == 3
                      else child(ROOT, name, "-"))
            result["round"] = r
            runs[name].append(result)
            print(f"  round {r} {name}: p50 {result['latency_ms_p50']:.2f} ms, "
                  f"p99 {result['latency_ms_p99']:.2f} ms, load {result['load_average'][0]:.1f}",
                  flush=True)
            if "hops" in result:
                print(f"    hops: {json.dumps(result['hops'])}", flush=True)
    load_end = os.getloadavg()
    print(f"\n{n} rounds, {DURATION:.0f} s per case, load average {load_start[0]:.1f} at start, "
          f"{load_end[0]:.1f} at end")
    print(f"{'case':<28}{'state/s':>8}{'p50 med':>9}{'p99 med':>9}{'p99 min':>9}{'p99 max':>9}"
          f"{'p99<=2':>8}")
    table = {}
    for name in names:
        p50 = np.array([x["latency_ms_p50"] for x in runs[name]])
        p99 = np.array([x["latency_ms_p99"] for x in runs[name]])
        states = np.array([x.get("states_per_s", np.nan) for x in runs[name]])
        # a round whose floor lost every reply (no latency) is nan: left out, and counted
        table[name] = {"p50_median_ms": float(np.nanmedian(p50)),
                       "p99_median_ms": float(np.nanmedian(p99)),
                       "p99_min_ms": float(np.nanmin(p99)), "p99_max_ms": float(np.nanmax(p99)),
                       "p99_met": int(np.sum(p99 <= 2.0)), "rounds": n,
                       "rounds_without_reply": int(np.sum(np.isnan(p99))),
                       "states_per_s_median": float(np.nanmedian(states))}
        t = table[name]
        print(f"{name:<28}{t['states_per_s_median']:8.0f}{t['p50_median_ms']:9.2f}"
              f"{t['p99_median_ms']:9.2f}{t['p99_min_ms']:9.2f}{t['p99_max_ms']:9.2f}"
              f"{t['p99_met']:>5}/{n}")
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    json_name = "can_rounds_hops.json" if hops else "can_rounds.json"
    run.finish([{"case": name, **t} for name, t in table.items()],
               {"rate_hz": RATE, "duration_s": DURATION, "cpu_count": os.cpu_count(),
                "rounds": n, "load_average_start": load_start, "load_average_end": load_end,
                "summary": table, "runs": runs}, out / json_name)
    print(f"wrote {run.output(out / json_name)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--baseline", default=None,
                        help="git revision whose can_hand runs as 'before' (side by side)")
    parser.add_argument("--child", nargs=3, metavar=("CASE", "KIND", "FORMAT"),
                        help=argparse.SUPPRESS)
    parser.add_argument("--only", default=None,
                        help="run only the chain cases whose name contains this text")
    parser.add_argument("--rounds", type=int, default=0,
                        help="repeat procs-udp (both hands, both formats) and the floors N times, "
                             "in a shuffled order each round; writes can_rounds.json")
    parser.add_argument("--old-clock", action="store_true",
                        help="with --rounds: also run each chain under the command clock used "
                             "before (one hand period per run faster than 1 kHz: it queued in "
                             "the server's 1 kHz commit limit), as procs-udp-fastclock/...")
    parser.add_argument("--hops", action="store_true",
                        help="with --rounds and --no-page: run the chains only, each with a "
                             "passive bus tap, and split every round trip into its hops "
                             "(client -> bus, hand, bus -> client); writes can_rounds_hops.json")
    parser.add_argument("--child-echo-udp", nargs=5, help=argparse.SUPPRESS)
    parser.add_argument("--child-tap", nargs=3, help=argparse.SUPPRESS)
    parser.add_argument("--child-echo-tcp", nargs=1, type=int, help=argparse.SUPPRESS)
    add_page_arguments(parser, "can", published={"only": False})
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run_case(*args.child)), flush=True)
        return
    if args.child_echo_udp:
        group, port, n_in, n_out, size_out = args.child_echo_udp
        echo_udp(group, int(port), int(n_in), int(n_out), int(size_out))
        return
    if args.child_tap:
        group, port, path = args.child_tap
        tap_bus(group, int(port), path)
        return
    if args.child_echo_tcp:
        echo_tcp(args.child_echo_tcp[0])
        return
    if args.rounds < 0:
        parser.error(f"--rounds: expected a count >= 0, got {args.rounds}")
    if args.old_clock and not args.rounds:
        parser.error("--old-clock: only with --rounds")
    if args.hops and not (args.rounds and args.no_page):
        parser.error("--hops: only with --rounds and --no-page (its tap perturbs the chain: "
                     "its figures do not go on the page)")
    if args.rounds:
        rounds(args.rounds, ResultsRun("CAN hand: interleaved rounds, Barrett against Shadow",
                                       args, published={"rounds": 4, "only": False}),
               old_clock=args.old_clock, hops=args.hops)
        return
    run = ResultsRun("CAN hand: full-hand setpoint round trip at 1 kHz", args)

    with tempfile.TemporaryDirectory() as tmp:
        versions = {"after": ROOT}
        if args.baseline:
            versions = {"before": baseline_tree(args.baseline, Path(tmp)), "after": ROOT}
        load_start = os.getloadavg()
        cases = {}
        for kind in KINDS:
            for case in CHAIN_CASES:
                for frame_format in FORMATS:  # interleaved: same load for both
                    for version, code in versions.items():
                        if version == "before" and (frame_format != "classic"
                                                    or case.endswith("-rt")):
                            continue  # the baseline may predate the fd layout and rt
                        name = (f"{case}/{kind}/{frame_format}"
                                + (f"/{version}" if args.baseline else ""))
                        if args.only and args.only not in name:
                            continue
                        cases[name] = child(code, case, kind,
                                            "-" if version == "before" else frame_format)
                        cases[name]["bus_us_per_cycle"] = bus_time_us(kind, frame_format)
                        print(f"  {name}: p50 {cases[name]['latency_ms_p50']:.2f} ms, "
                              f"p99 {cases[name]['latency_ms_p99']:.2f} ms", flush=True)
        for case in FLOOR_CASES:
            if not args.only:
                cases[case] = child(ROOT, case, "-")
        load_end = os.getloadavg()

    print(f"\nfull-hand setpoint round trip, {RATE:.0f} Hz, {DURATION:.0f} s per case, "
          f"{os.cpu_count()} cores; load average at start {load_start[0]:.1f}, "
          f"at end {load_end[0]:.1f}")
    print(f"{'case':<36}{'cmd/s':>6}{'commit/s':>9}{'state/s':>8}{'frame/s':>8}{'p50':>6}"
          f"{'p90':>6}{'p99':>7}{'max':>7}  {'CPU % self/sim/server':<22}{'bus us/cyc':>11}"
          f"{'load':>5}  targets")
    for name, r in cases.items():
        ok = r["states_per_s"] >= 0.95 * RATE and r["latency_ms_p99"] <= 2.0
        commits = f"{r['commits_per_s']:9.0f}" if "commits_per_s" in r else f"{'-':>9}"
        frames = f"{r['can_frames_per_s']:8.0f}" if "can_frames_per_s" in r else f"{'-':>8}"
        bus = "{:.0f}-{:.0f}".format(*r["bus_us_per_cycle"]) if "bus_us_per_cycle" in r else "-"
        print(f"{name:<36}{r['commands_per_s']:6.0f}{commits}{r['states_per_s']:8.0f}{frames}"
              f"{r['latency_ms_p50']:6.2f}{r['latency_ms_p90']:6.2f}{r['latency_ms_p99']:7.2f}"
              f"{r['latency_ms_max']:7.1f}  {'/'.join(f'{c:.0f}' for c in r['cpu_percent']):<22}"
              f"{bus:>11}{r['load_average'][0]:5.1f}  {'met' if ok else 'MISSED'}")
    print("latencies in ms; a chain case meets the targets with state/s >= 950 and p99 <= 2 ms; "
          "bus us/cyc: one command + one hand cycle on a real bus (unstuffed-worst stuffing), "
          "> 1000 cannot run at 1 kHz")
    floor = {}
    if "floor-tcp" in cases:
        for fmt, udp in (("classic", "floor-udp-shadow"), ("fd", "floor-udp-fd")):
            floor[fmt] = cases["floor-tcp"]["latency_ms_p99"] + cases[udp]["latency_ms_p99"]
            print(f"floor p99 without the hand's cycle wait (tcp + {udp}): {floor[fmt]:.2f} ms")
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    table = [{"case": name, **{k: v for k, v in r.items() if k.startswith(
        ("commands_per_s", "commits_per_s", "states_per_s", "can_frames_per_s", "latency_ms"))}}
        for name, r in cases.items()]
    run.finish(table, {"rate_hz": RATE, "duration_s": DURATION, "cpu_count": os.cpu_count(),
                       "baseline": args.baseline, "load_average_start": load_start,
                       "load_average_end": load_end, "cases": cases,
                       "floor_p99_ms_tcp_plus_udp": floor}, out / "can.json")
    print(f"wrote {out / 'can.json'}")


if __name__ == "__main__":
    main()
