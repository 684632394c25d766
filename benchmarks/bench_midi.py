"""Latency from a MIDI message to a changed ``hand.position`` command.

The hand-control diagram (``BuildMidiHandControl``: the simulated Shadow
station driven by ``MidiHandControl``) runs in real time (target rate 1.0).
A sender thread plays the device: a fader control change every 40-80 ms
(random), alternating between two values, stamped with ``perf_counter`` when
sent. A simulator monitor (called after every 1 ms plant step) stamps the
first change of the control's ``position`` output after each message. The
latency is the difference; the rate limit is set high so every change is
one update.

Cases, side by side in every round (rounds interleave them, so ratios hold
while the shared machine's speed drifts):

- ``midi-in-process-5ms`` / ``midi-in-process-1ms``: ``MidiHandControl`` at
  its default 5 ms period and at 1 ms, reading an in-process ``mido`` port;
- ``midi-rtmidi-virtual-5ms``: the same through python-rtmidi (an rtmidi
  virtual output port and the input connected to it); only where an OS MIDI
  system exists (not in a container without ``/dev/snd/seq``);
- the floor, **no project MIDI code**: ``floor-queue-5ms`` / ``floor-queue-1ms``,
  a bare LeafSystem written here that polls a ``queue.SimpleQueue`` at the same
  period and writes the value into the same station's ``hand.position``.

An update polls at its period, so the expected latency is half a period on
average (uniform in 0..period) plus the update's own work and the
simulator's real-time pacing; p99 shows the scheduler's tail on a loaded
machine. A second table gives the work of one update of the control system
alone (no station, 1 ms period, idle and with one message per update)
against the floor's. Writes ``benchmarks/results/midi.json``.

    python benchmarks/bench_midi.py                 # 3 rounds x 4 s per case
    HANDLE_DRAKE_REDUCED=1 python benchmarks/bench_midi.py   # 1 round x 1.5 s
"""

from __future__ import annotations

import argparse
import os
import queue
import random
import threading
import time
from pathlib import Path

import mido
import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from handle_drake.apps.figure9.hand_control import BuildMidiHandControl
from handle_drake.base.results import ResultsRun, add_page_arguments
from handle_drake.base.testing import reduced
from handle_drake.devices.midi.ports import in_process_pair
from handle_drake.scenario import LoadScenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = """
hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.3]}}}
object: null
table: null
"""
FADER_CC = 20  # fader1 -> FFJ3
VALUES = (40, 90)


class QueueCommand(LeafSystem):
    """The floor: polls a stdlib queue every ``period`` s and holds the last value
    as the first entry of a 20-vector command (no MIDI, no mapping, no limits)."""

    def __init__(self, source: queue.SimpleQueue, period: float, nu: int = 20):
        super().__init__()
        self._source = source
        self._state = self.DeclareDiscreteState(nu)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareStateOutputPort("position", self._state)

    def _update(self, context, state):
        value = None
        while True:
            try:
                value = self._source.get_nowait()
            except queue.Empty:
                break
        if value is not None:
            command = context.get_discrete_state(0).value().copy()
            command[3] = value / 127.0  # FFJ3
            state.set_value(0, command)


def _floor_diagram(period: float):
    from handle_drake.station import MakeHandStation

    source = queue.SimpleQueue()
    builder = DiagramBuilder()
    station = builder.AddSystem(MakeHandStation(LoadScenario(data=SCENARIO)))
    control = builder.AddSystem(QueueCommand(source, period))
    builder.Connect(control.get_output_port(), station.GetInputPort("hand.position"))
    return builder.Build(), control, lambda value: source.put(value)


def _midi_diagram(period: float, transport: str):
    if transport == "in-process":
        device, host = in_process_pair()
    else:  # rtmidi virtual port and an input connected to it
        name = f"handle_drake bench {os.getpid()}"
        device = mido.open_output(name, virtual=True)
        match = [n for n in mido.get_input_names() if name in n]
        host = mido.open_input(match[0])
    built = BuildMidiHandControl(LoadScenario(data=SCENARIO), port=host, synergies=None,
                                 period=period, max_joint_velocity=1000.0)

    def send(value):
        device.send(mido.Message("control_change", control=FADER_CC, value=value))

    return built.diagram, built.control, send


def run_case(kind: str, period: float, seconds: float, transport: str = "in-process") -> dict:
    diagram, control, send = (_floor_diagram(period) if kind == "floor"
                              else _midi_diagram(period, transport))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    control_context = control.GetMyContextFromRoot(context)
    port = control.get_output_port(0) if kind == "floor" else control.get_position_output_port()
    simulator.Initialize()
    simulator.AdvanceTo(0.05)
    sent: list[float] = []
    changed: list[float] = []
    last = [port.Eval(control_context).copy()]

    def monitor(root_context):
        now = port.Eval(control_context)
        if not np.array_equal(now, last[0]):
            changed.append(time.perf_counter())
            last[0] = now.copy()
        from pydrake.systems.framework import EventStatus

        return EventStatus.Succeeded()

    simulator.set_monitor(monitor)
    simulator.set_target_realtime_rate(1.0)
    stop = threading.Event()
    rng = random.Random(0)

    def sender():
        i = 0
        while not stop.wait(rng.uniform(0.04, 0.08)):
            sent.append(time.perf_counter())
            send(VALUES[i % 2])
            i += 1

    thread = threading.Thread(target=sender, daemon=True)
    start_sim = context.get_time()
    wall = time.perf_counter()
    thread.start()
    simulator.AdvanceTo(start_sim + seconds)
    stop.set()
    thread.join()
    wall = time.perf_counter() - wall
    latencies = []
    changes = np.array(changed)
    for i, t in enumerate(sent[:-1]):
        after = changes[(changes >= t) & (changes < sent[i + 1])]
        if after.size:
            latencies.append(after[0] - t)
    return {"latencies_ms": [1e3 * v for v in latencies], "messages": len(sent),
            "answered": len(latencies), "realtime_factor": seconds / wall}


def update_cost(kind: str, updates: int, busy: bool) -> float:
    """Wall time (us) per update of the control system alone (no station), 1 ms
    period; ``busy``: one fader message arrives before every update."""
    period = 0.001
    builder = DiagramBuilder()
    if kind == "floor":
        source = queue.SimpleQueue()
        builder.AddSystem(QueueCommand(source, period))

        def send(value):
            source.put(value)
    else:
        from handle_drake.devices.midi.mapping import LoadMidiMapping
        from handle_drake.devices.midi.systems import MidiHandControl

        device, host = in_process_pair()
        builder.AddSystem(MidiHandControl("shadow", LoadMidiMapping(), port=host, period=period,
                                          max_joint_velocity=1000.0))

        def send(value):
            device.send(mido.Message("control_change", control=FADER_CC, value=value))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.01)
    start = time.perf_counter()
    t0 = simulator.get_context().get_time()
    for k in range(1, updates + 1):
        if busy:
            send(VALUES[k % 2])
        simulator.AdvanceTo(t0 + k * period)
    return 1e6 * (time.perf_counter() - start) / updates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=1 if reduced() else 3)
    parser.add_argument("--seconds", type=float, default=1.5 if reduced() else 4.0)
    add_page_arguments(parser, "midi", published={"rounds": 3, "seconds": 4.0})
    args = parser.parse_args()
    run = ResultsRun("MIDI controller: message latency against a queue floor", args)
    cases = [("midi-in-process-5ms", "midi", 0.005, "in-process"),
             ("floor-queue-5ms", "floor", 0.005, None),
             ("midi-in-process-1ms", "midi", 0.001, "in-process"),
             ("floor-queue-1ms", "floor", 0.001, None)]
    skipped = {}
    try:
        from handle_drake.devices.midi.ports import device_port_names

        device_port_names()
        cases.append(("midi-rtmidi-virtual-5ms", "midi", 0.005, "rtmidi"))
    except Exception as error:  # no ALSA sequencer / CoreMIDI
        skipped["midi-rtmidi-virtual-5ms"] = str(error)[:200]
    results = {name: {"latencies_ms": [], "messages": 0, "answered": 0, "rtf": []}
               for name, *_ in cases}
    for _ in range(args.rounds):
        for name, kind, period, transport in cases:
            out = run_case(kind, period, args.seconds, transport or "in-process")
            r = results[name]
            r["latencies_ms"] += out["latencies_ms"]
            r["messages"] += out["messages"]
            r["answered"] += out["answered"]
            r["rtf"].append(out["realtime_factor"])
    table = {}
    print(f"{'case':26s} {'msgs':>5s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s} "
          f"{'p50/floor':>9s} {'p99/floor':>9s} {'x real':>6s}")
    for name, *_ in cases:
        lat = np.array(results[name]["latencies_ms"])
        table[name] = {
            "messages": results[name]["messages"], "answered": results[name]["answered"],
            "p50_ms": float(np.percentile(lat, 50)) if lat.size else None,
            "p99_ms": float(np.percentile(lat, 99)) if lat.size else None,
            "max_ms": float(lat.max()) if lat.size else None,
            "realtime_factor": float(np.mean(results[name]["rtf"])),
        }
    for name, *_ in cases:
        row = table[name]
        floor = table.get("floor-queue-" + name.rsplit("-", 1)[-1])
        if row["p50_ms"] is None:
            print(f"{name:26s} no answers")
            continue
        ratio50 = row["p50_ms"] / floor["p50_ms"] if floor and floor["p50_ms"] else float("nan")
        ratio99 = row["p99_ms"] / floor["p99_ms"] if floor and floor["p99_ms"] else float("nan")
        row["p50_vs_floor"], row["p99_vs_floor"] = ratio50, ratio99
        print(f"{name:26s} {row['answered']:5d} {row['p50_ms']:7.2f} {row['p99_ms']:7.2f} "
              f"{row['max_ms']:7.2f} {ratio50:9.2f} {ratio99:9.2f} {row['realtime_factor']:6.2f}")
    for name, why in skipped.items():
        print(f"{name:26s} not run: {why}")
    updates = 500 if reduced() else 3000
    cost = {f"{kind}-{'busy' if busy else 'idle'}": [] for kind in ("midi", "floor")
            for busy in (False, True)}
    for _ in range(args.rounds):
        for kind in ("midi", "floor"):
            for busy in (False, True):
                cost[f"{kind}-{'busy' if busy else 'idle'}"].append(
                    update_cost(kind, updates, busy))
    cost = {k: float(np.median(v)) for k, v in cost.items()}
    print("\nwork per update, control system alone (us; median of rounds):")
    for load in ("idle", "busy"):
        midi, floor = cost["midi-" + load], cost["floor-" + load]
        print(f"  {load}: MidiHandControl {midi:7.1f}   floor {floor:7.1f}   ratio "
              f"{midi / floor:5.2f}")
    out = ROOT / "benchmarks" / "results"
    run.finish([{"case": name, **row} for name, row in table.items()]
               + [{"case": f"update cost {k} (us)", "median_us": v} for k, v in cost.items()],
               {"cases": table, "update_cost_us": cost, "skipped": skipped,
                "rounds": args.rounds, "seconds": args.seconds, "loadavg": os.getloadavg(),
                "cpus": os.cpu_count()}, out / "midi.json")
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; "
          f"wrote {out / 'midi.json'}")


if __name__ == "__main__":
    main()
