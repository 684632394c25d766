"""Full-hand setpoint round trip through TCP and the CAN bus on loopback.

A client sends a full-hand command every 1 ms (1 kHz) to the CAN bus server,
which forwards it as setpoint frames to the simulated firmware (1 kHz hand
cycle); the round trip ends when a STATE whose ``seq_ack`` covers the command
comes back. Side by side in one run:

- ``inproc-virtual``: server, firmware and client as threads of this process
  on python-can's virtual bus;
- ``procs-udp``: ``handle-drake can-sim`` and ``can-server`` as separate
  processes on a udp_multicast bus (the deployment shape);

for the Shadow hand (20 commands, 24 joints: 6 setpoint + 9 feedback frames
per cycle) and the Barrett hand (4 frames). Targets: >= 1 kHz updates, p99
<= 2 ms. Writes ``benchmarks/results/can.json``.

    python benchmarks/bench_can.py            # 4 s per case
    HANDLE_DRAKE_REDUCED=1 python benchmarks/bench_can.py   # 1 s per case
"""

from __future__ import annotations

import json
import os
import random
import selectors
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from handle_drake.can_hand.client import CanHandClient  # noqa: E402
from handle_drake.can_hand.config import (  # noqa: E402
    BusConfig,
    CanFirmwareConfig,
    CanServerConfig,
)
from handle_drake.can_hand.firmware import SimulatedHandFirmware  # noqa: E402
from handle_drake.can_hand.layout import hand_layout  # noqa: E402
from handle_drake.can_hand.server import CanBusServer  # noqa: E402
from handle_drake.testing import pick  # noqa: E402

RATE = 1000.0  # Hz: command rate, server commit limit and firmware cycle
DURATION = pick(4.0, 1.0)  # s per case
WARMUP = 0.3  # s


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int | None = None) -> float:
    """User + system CPU time of a process (this one when None)."""
    if pid is None:
        t = os.times()
        return t.user + t.system
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def drive(client: CanHandClient, layout, duration: float, pids=()) -> dict:
    """Sends commands at RATE for ``duration`` s; returns rates, latencies, CPU use."""
    assert client.wait_for_state(15.0), client.last_error
    base = np.clip(np.zeros(layout.nu), layout.command_lower, layout.command_upper)
    span = 0.2 * (layout.command_upper - layout.command_lower)
    period = 1.0 / RATE
    # Warm-up, then measure.
    for seconds in (WARMUP, duration):
        client.latencies.clear()
        cpu0 = [cpu_seconds(None)] + [cpu_seconds(pid) for pid in pids]
        stats0 = client.request_stats(2.0)
        states0 = client.counters["states_received"]
        sent = 0
        start = time.perf_counter()
        next_time = start
        while True:
            now = time.perf_counter()
            if now - start >= seconds:
                break
            if now < next_time:
                time.sleep(min(next_time - now, 0.0005))
                continue
            sent += 1
            client.send_command(base + span * (0.5 + 0.5 * np.sin(2 * np.pi * 0.5 * (now - start))))
            next_time += period
        elapsed = time.perf_counter() - start
        cpu1 = [cpu_seconds(None)] + [cpu_seconds(pid) for pid in pids]
        time.sleep(0.05)  # let the last acknowledgements in
        stats1 = client.request_stats(2.0)
    latencies = np.array(client.latencies) * 1e3
    frames = (stats1.get("frames_tx", 0) - stats0.get("frames_tx", 0)
              + stats1.get("frames_rx", 0) - stats0.get("frames_rx", 0)
              - (stats1.get("echo_frames", 0) - stats0.get("echo_frames", 0)))
    return {
        "commands_per_s": sent / elapsed,
        "commits_per_s": (stats1["commits_tx"] - stats0.get("commits_tx", 0)) / elapsed,
        "states_per_s": (client.counters["states_received"] - states0) / elapsed,
        "hand_cycles_per_s": (stats1["hand_cycles"] - stats0["hand_cycles"]) / elapsed,
        "can_frames_per_s": frames / elapsed,
        "acked": int(latencies.size),
        "latency_ms_p50": float(np.percentile(latencies, 50)) if latencies.size else float("nan"),
        "latency_ms_p99": float(np.percentile(latencies, 99)) if latencies.size else float("nan"),
        "latency_ms_max": float(latencies.max()) if latencies.size else float("nan"),
        # CPU use (% of one core): this process, then the firmware and server processes
        "cpu_percent": [100 * (b - a) / elapsed for a, b in zip(cpu0, cpu1, strict=True)],
    }


def case_inproc(kind: str) -> dict:
    layout = hand_layout(kind)
    bus = BusConfig("virtual", f"bench-{uuid.uuid4().hex}")
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


def _spawn(*args) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.Popen([sys.executable, "-m", "handle_drake.can_hand.cli", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               env=env, cwd=ROOT)
    selector = selectors.DefaultSelector()
    selector.register(process.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if selector.select(0.5) and "ready" in process.stdout.readline():
            selector.close()
            return process
        if process.poll() is not None:
            break
    selector.close()
    process.kill()
    raise RuntimeError(f"{args[0]} did not start")


def case_procs(kind: str) -> dict:
    layout = hand_layout(kind)
    group = f"239.255.{random.randint(0, 255)}.{random.randint(1, 254)}"
    bus = ["--bus", "udp_multicast", "--channel", group,
           "--bus-port", str(random.randint(20000, 60000)), "--hand", kind]
    port = free_port()
    processes = []
    try:
        processes.append(_spawn("can-sim", *bus, "--rate", str(RATE)))
        processes.append(_spawn("can-server", *bus, "--listen", f"127.0.0.1:{port}",
                                "--max-rate", str(RATE), "--max-step", "0.5"))
        with CanHandClient(layout, "127.0.0.1", port, record_latency=True) as client:
            return drive(client, layout, DURATION, pids=[p.pid for p in processes])
    finally:
        for process in processes:
            process.send_signal(signal.SIGTERM)
        for process in processes:
            try:
                process.wait(5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5)


def main() -> None:
    cases = {}
    for kind in ("shadow", "barrett"):
        cases[f"inproc-virtual/{kind}"] = case_inproc(kind)
        cases[f"procs-udp/{kind}"] = case_procs(kind)
    load = os.getloadavg()
    header = (f"{'case':<24}{'cmd/s':>8}{'commit/s':>9}{'state/s':>8}{'CAN fr/s':>9}"
              f"{'p50 ms':>8}{'p99 ms':>8}{'max ms':>8}  {'CPU % (self/sim/server)':<24}targets")
    print(f"full-hand setpoint round trip, {RATE:.0f} Hz, {DURATION:.0f} s per case, "
          f"load average {load[0]:.1f} on {os.cpu_count()} cores")
    print(header)
    for name, r in cases.items():
        ok = r["states_per_s"] >= 0.95 * RATE and r["latency_ms_p99"] <= 2.0
        print(f"{name:<24}{r['commands_per_s']:8.0f}{r['commits_per_s']:9.0f}"
              f"{r['states_per_s']:8.0f}{r['can_frames_per_s']:9.0f}{r['latency_ms_p50']:8.2f}"
              f"{r['latency_ms_p99']:8.2f}{r['latency_ms_max']:8.1f}  "
              f"{'/'.join(f'{c:.0f}' for c in r['cpu_percent']):<24}{'met' if ok else 'MISSED'}")
    ratios = {kind: cases[f"procs-udp/{kind}"]["latency_ms_p50"]
              / cases[f"inproc-virtual/{kind}"]["latency_ms_p50"] for kind in ("shadow", "barrett")}
    for kind, ratio in ratios.items():
        print(f"p50 latency, processes/udp over in-process/virtual ({kind}): {ratio:.2f}x")
    out = ROOT / "benchmarks" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "can.json").write_text(json.dumps(
        {"rate_hz": RATE, "duration_s": DURATION, "load_average": load,
         "cpu_count": os.cpu_count(), "cases": cases, "p50_ratio_procs_over_inproc": ratios},
        indent=2))
    print(f"wrote {out / 'can.json'}")


if __name__ == "__main__":
    main()
