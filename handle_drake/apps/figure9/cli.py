"""``handle-drake midi ...``: the MIDI controller experiments and live hand control.

- ``midi jog``: Figure 9, the Shadow hand turns the jog wheel with a palmar
  pinch; prints the wheel's true rotation against the ticks counted from MIDI.
- ``midi fader``: a fingertip pushes a fader; prints the MIDI value against
  the cap's position.
- ``midi control``: faders, knobs and the mode button drive the hand in real
  time (a MIDI device, or Meshcat sliders with ``--meshcat``), simulated or on
  the CAN hand with ``--hardware``.
- ``midi monitor``: what a real device's controls report, decoded by the
  mapping (check a device's preset against the mapping file).
- ``midi ports``: the MIDI devices python-rtmidi sees.
- ``midi write-scenarios DIR``: plans the two experiments and writes their
  scenario files (``diagrams/midi_jog_pinch.yaml``, ``midi_fader_push.yaml``).
"""

from __future__ import annotations

import time
from pathlib import Path

from handle_drake.apps.cli_support import check_hardware_server, start_meshcat

JOG_SCENARIO = "midi_jog_pinch.yaml"
FADER_SCENARIO = "midi_fader_push.yaml"


def register(subparsers) -> None:
    p = subparsers.add_parser("midi", help="the iControls Pro MIDI controller (Figure 9)")
    sub = p.add_subparsers(dest="midi_command", required=True, metavar="MIDI_COMMAND")

    q = sub.add_parser("jog", help="palmar pinch turns the jog wheel; MIDI ticks vs rotation")
    _add_run_arguments(q, JOG_SCENARIO)
    q.set_defaults(func=_cmd_jog)

    q = sub.add_parser("fader", help="a fingertip pushes a fader; MIDI value vs position")
    _add_run_arguments(q, FADER_SCENARIO)
    q.set_defaults(func=_cmd_fader)

    q = sub.add_parser("control", help="drive the hand from MIDI faders/knobs in real time")
    q.add_argument("--scenario", type=Path, default=None,
                   help="station scenario (default: the Shadow hand on a fixed mount)")
    q.add_argument("--override", default=None, help="YAML text applied on top of the scenario")
    q.add_argument("--mapping", type=Path, default=None, help="MIDI mapping file")
    q.add_argument("--port", default=None,
                   help="MIDI device name (substring; default: the mapping's port_name)")
    q.add_argument("--meshcat", action="store_true",
                   help="Meshcat sliders stand in for the faders (no MIDI device needed)")
    q.add_argument("--hardware", action="store_true",
                   help="drive the CAN hand of the scenario's !CanHandDriver")
    q.add_argument("--duration", type=float, default=60.0, help="seconds to run")
    q.set_defaults(func=_cmd_control)

    q = sub.add_parser("monitor", help="print what a MIDI device's controls report, decoded "
                                       "by the mapping (what a learner is told)")
    q.add_argument("--mapping", type=Path, default=None, help="MIDI mapping file")
    q.add_argument("--port", default=None,
                   help="MIDI device name (substring; default: the mapping's port_name)")
    q.add_argument("--duration", type=float, default=60.0, help="seconds to listen")
    q.set_defaults(func=_cmd_monitor)

    q = sub.add_parser("ports", help="list the MIDI devices python-rtmidi sees")
    q.set_defaults(func=_cmd_ports)

    q = sub.add_parser("write-scenarios", help="plan the experiments and write their YAML")
    q.add_argument("directory", type=Path,
                   help="folder to write midi_jog_pinch.yaml and midi_fader_push.yaml to")
    q.set_defaults(func=_cmd_write)


def _add_run_arguments(q, default_file: str) -> None:
    q.add_argument("--scenario", type=Path, default=None,
                   help=f"scenario file (default: diagrams/{default_file})")
    q.add_argument("--override", default=None, help="YAML text applied on top of the file")
    q.add_argument("--html", type=Path, default=None, help="save a self-contained HTML replay")
    q.add_argument("--meshcat", action="store_true", help="show it live in Meshcat")


def _load(args, default_file: str):
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    path = args.scenario or diagrams_dir() / default_file
    return LoadScenario(filename=path, data=args.override)


def _cmd_jog(args) -> int:
    import sys

    from handle_drake.apps.figure9.experiments import (
        commanded_wrist_turn_deg,
        run_midi_scenario,
        wheel_followed,
    )

    scenario = _load(args, JOG_SCENARIO)
    result = run_midi_scenario(scenario, start_meshcat(args.meshcat or args.html is not None),
                               html=args.html)
    s = result.jog_summary()
    print(f"jog wheel ({result.ticks_per_turn} ticks per turn), palmar pinch:")
    print(f"  true rotation      {s['rotation_deg']:+8.2f} deg = {s['true_ticks']:+8.2f} ticks"
          f"  (largest {s['max_rotation_deg']:.1f} deg)")
    print(f"  counted from MIDI  {s['midi_ticks']:+5d} ticks   error {s['error_ticks']:+.2f} "
          f"ticks")
    wrist = commanded_wrist_turn_deg(scenario, result.times[0], result.times[-1])
    followed = wheel_followed(s["rotation_deg"], wrist)
    print(f"  wrist turned       {wrist:+8.2f} deg (script): the wheel "
          f"{'followed' if followed else 'did NOT follow'}")
    print(f"  messages: {result.counts['accepted']} accepted, {result.counts['rejected']} "
          f"rejected; simulated {result.times[-1]:.1f} s in {result.wall_time:.1f} s")
    if args.html:
        print(f"replay written to {args.html}")
    if not followed:
        print(f"handle-drake midi: the wheel turned {s['rotation_deg']:+.1f} deg where the "
              f"wrist turned {wrist:+.1f} deg: the pinch did not carry it", file=sys.stderr)
        return 1
    return 0 if abs(s["error_ticks"]) < 1.0 else 1


def _cmd_fader(args) -> int:
    from handle_drake.apps.figure9.experiments import run_midi_scenario
    from handle_drake.devices.midi.device import ControllerGeometry

    scenario = _load(args, FADER_SCENARIO)
    result = run_midi_scenario(scenario, start_meshcat(args.meshcat or args.html is not None),
                               html=args.html)
    travel = ControllerGeometry().fader_travel
    moved = [n for n in result.control_names if n.startswith("fader")]
    fader = max(moved, key=lambda n: result.position(n).max())
    s = result.fader_summary(fader, travel)
    print(f"{fader} pushed by the first finger: moved {s['travel_m'] * 1000:.1f} mm of "
          f"{travel * 1000:.0f} mm")
    print(f"  MIDI value {s['final_value']} (position gives {s['expected_value']}); "
          f"largest difference over the run {s['max_error_counts']} counts")
    print(f"  simulated {result.times[-1]:.1f} s in {result.wall_time:.1f} s")
    if args.html:
        print(f"replay written to {args.html}")
    ok = s["max_error_counts"] is not None and s["max_error_counts"] <= 1
    return 0 if ok else 1


def _cmd_ports(args) -> int:
    from handle_drake.devices.midi.ports import device_port_names

    inputs, outputs = device_port_names()
    print("MIDI inputs:  " + (", ".join(inputs) or "none"))
    print("MIDI outputs: " + (", ".join(outputs) or "none"))
    return 0


def _cmd_monitor(args) -> int:
    from handle_drake.devices.midi import ports
    from handle_drake.devices.midi.codec import ControlCounts, MidiDecoder
    from handle_drake.devices.midi.mapping import LoadMidiMapping

    if not (args.duration > 0):
        raise ValueError(f"--duration must be > 0 s, got {args.duration}")
    mapping = LoadMidiMapping(args.mapping)
    port, output = ports.open_device_ports(args.port or mapping.port_name)
    output.close()
    decoder, counts = MidiDecoder(mapping), ControlCounts(mapping)
    print(f"listening to {port.name} for {args.duration:g} s (Ctrl-C stops)", flush=True)
    deadline = time.monotonic() + args.duration
    try:
        while time.monotonic() < deadline:
            for message in port.iter_pending():
                before = decoder.rejected.copy()
                event = decoder.decode(message)
                if event is None:  # the one reason it counted
                    (reason,) = decoder.rejected - before
                    print(f"  ignored ({reason}): {message}", flush=True)
                    continue
                counts.add(event)
                if event.kind == "fader":
                    text = f"{event.value:4d}"
                elif event.kind == "button":
                    text = f"{'pressed' if event.value else 'released'} (presses: " \
                           f"{counts[event.name]})"
                else:
                    text = f"{event.value:+4d} ticks (net {counts[event.name]:+d})"
                print(f"{event.name:8s} {text}", flush=True)
            time.sleep(0.002)
    finally:
        port.close()
    rejected = ", ".join(f"{r} {n}" for r, n in decoder.rejected.items() if n)
    print(f"messages: {decoder.accepted} accepted, {decoder.total_rejected} ignored"
          + (f" ({rejected})" if rejected else ""))
    return 0


def _cmd_control(args) -> int:
    from handle_drake.apps.figure9.hand_control import BuildMidiHandControl
    from handle_drake.devices.midi.mapping import LoadMidiMapping
    from handle_drake.scenario import LoadScenario

    if not (args.duration > 0):
        raise ValueError(f"--duration must be > 0 s, got {args.duration}")
    mapping = LoadMidiMapping(args.mapping)
    data = args.override
    if args.scenario is None:
        data = ("hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.3]}}}\n"
                "object: null\ntable: null\n" + (data or ""))
    scenario = LoadScenario(filename=args.scenario, data=data)
    if args.hardware:
        check_hardware_server(scenario)
    meshcat = start_meshcat(args.meshcat)
    if args.meshcat:
        from handle_drake.devices.midi.ports import MeshcatFaderPort

        port = feedback = MeshcatFaderPort(meshcat, mapping)
    else:
        from handle_drake.devices.midi.ports import open_device_ports

        port, feedback = open_device_ports(args.port or mapping.port_name)
    built = BuildMidiHandControl(scenario, port=port, feedback_port=feedback, mapping=mapping,
                                 meshcat=meshcat, hardware=args.hardware)
    harness = built.harness
    harness.simulator.set_target_realtime_rate(1.0)  # a person plays it, also in simulation
    print(f"driving the {scenario.hand.kind} hand for {args.duration:.0f} s "
          "(mode button toggles joint/synergy mode; Ctrl-C stops)", flush=True)
    start = time.perf_counter()
    try:
        harness.initialize()
        harness.advance(args.duration)
    finally:
        port.close()
        if feedback is not port:
            feedback.close()
    counts = built.control.midi_counts(harness.controller_context())
    print(f"ran {time.perf_counter() - start:.1f} s; messages: {counts}")
    return 0


def _cmd_write(args) -> int:
    from handle_drake.apps.figure9.experiments import fader_push_scenario, jog_pinch_scenario
    from handle_drake.scenario import DumpScenario

    args.directory.mkdir(parents=True, exist_ok=True)
    for name, build, note in (
            (JOG_SCENARIO, jog_pinch_scenario,
             "Figure 9: palmar pinch on the jog wheel (planned), turn +60 deg, back 20 deg"),
            (FADER_SCENARIO, fader_push_scenario,
             "a fingertip pushes fader5 40 mm up its slot")):
        path = args.directory / name
        text = DumpScenario(build())  # writes object: null itself
        path.write_text(f"# {note}.\n# Written by: handle-drake midi write-scenarios "
                        f"{args.directory}\n# Run: handle-drake midi "
                        f"{'jog' if name == JOG_SCENARIO else 'fader'} (or handle-drake "
                        f"simulate {path.name})\n" + text)
        print(f"wrote {path}")
    return 0
