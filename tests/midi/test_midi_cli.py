"""``handle-drake midi``: errors are one line and exit 2; live control runs."""

import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import mido

from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main
from handle_drake.devices.midi import ports
from handle_drake.devices.midi.ports import ALSA_SEQUENCER
from handle_drake.scenario import DumpScenario, LoadScenario

ROOT = Path(__file__).resolve().parents[2]


def test_control_without_a_device_is_a_clear_error(capsys):
    assert main(["midi", "control", "--port", "no-such-device", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "handle-drake midi: error: no MIDI" in err and "Traceback" not in err


def test_control_with_meshcat_sliders_runs(capsys):
    assert main(["midi", "control", "--meshcat", "--duration", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "driving the shadow hand" in out and "'accepted': 0" in out


def test_bad_arguments_exit_2(tmp_path, capsys):
    assert main(["midi", "jog", "--scenario", str(tmp_path / "none.yaml")]) == 2
    assert main(["midi", "fader", "--override", "midi_controller: {scan_period: -1}"]) == 2
    assert "scan_period" in capsys.readouterr().err
    assert main(["midi", "control", "--meshcat", "--duration", "-1"]) == 2
    assert main(["midi", "control", "--meshcat", "--mapping", str(tmp_path / "m.yaml")]) == 2


def test_real_midi_device_without_a_midi_system_is_one_line(monkeypatch, tmp_path, capsys):
    # ``midi ports``, ``midi control`` and ``midi monitor`` (the real-device path) in a fresh
    # interpreter, stderr as the user sees it (with what C libraries write to
    # file descriptor 2): with no ALSA sequencer, exit 2 and one line each (no
    # libasound chatter, no traceback); with one, the ports are listed.
    code = ("import sys; from handle_drake.cli import main; "
            "sys.exit(100 * main(['midi', 'ports']) + 10 * main(['midi', 'control', "
            "'--duration', '0.1', '--port', 'iControls-absent']) + main(['midi', 'monitor', "
            "'--duration', '0.1', '--port', 'iControls-absent']))")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd=ROOT, timeout=120)
    if not os.path.exists(ALSA_SEQUENCER):
        assert run.returncode == 222, run.stderr
        lines = run.stderr.splitlines()
        assert len(lines) == 3, run.stderr
        for line in lines:
            assert line.startswith("handle-drake midi: error: no MIDI system available: "
                                   f"the ALSA sequencer {ALSA_SEQUENCER} does not exist")
    else:
        assert run.returncode == 22 and "MIDI inputs:" in run.stdout
        assert run.stderr.count("no MIDI device matching 'iControls-absent'") == 2
        # The missing-sequencer message, forced.
        monkeypatch.setattr(ports, "ALSA_SEQUENCER", str(tmp_path / "seq"))
        assert main(["midi", "ports"]) == 2
        assert f"the ALSA sequencer {tmp_path / 'seq'} does not exist" in capsys.readouterr().err


def test_write_scenarios_writes_files_that_load_back_to_the_shipped_ones(
        tmp_path, monkeypatch, capsys):
    # Planning the jog pinch takes ~10 s; the shipped file stands in for the
    # plan (test_shipped_scenarios_match_what_the_planner_writes checks the
    # fader plan against its file). What is tested: the written text.
    import handle_drake.apps.figure9.experiments as experiments

    shipped = {name: LoadScenario(filename=diagrams_dir() / name)
               for name in ("midi_jog_pinch.yaml", "midi_fader_push.yaml")}
    monkeypatch.setattr(experiments, "jog_pinch_scenario",
                        lambda: shipped["midi_jog_pinch.yaml"])
    assert main(["midi", "write-scenarios", str(tmp_path / "out")]) == 0
    for name, scenario in shipped.items():
        written = LoadScenario(filename=tmp_path / "out" / name)
        assert written.object is None and written.midi_controller is not None
        assert DumpScenario(written) == DumpScenario(scenario)
    assert capsys.readouterr().out.count("wrote ") == 2


def test_jog_and_fader_commands_run_and_report_what_midi_counted(tmp_path, capsys):
    # Cut short (the jog after ~20 degrees of the turn, the fader after the
    # first millimetres of the push); the full runs are in test_midi_experiments.
    assert main(["midi", "jog", "--override", "simulation_duration: 1.7"]) == 0
    out = capsys.readouterr().out
    true_ticks = float(re.search(r"= *([-+\d.]+) ticks", out).group(1))
    counted = int(re.search(r"counted from MIDI *([-+\d]+) ticks", out).group(1))
    assert true_ticks > 2 and abs(counted - true_ticks) < 1.0, out
    html = tmp_path / "replay" / "fader.html"
    assert main(["midi", "fader", "--override", "simulation_duration: 0.9",
                 "--html", str(html)]) == 0
    out = capsys.readouterr().out
    moved = float(re.search(r"fader5 pushed by the first finger: moved ([\d.]+) mm", out)[1])
    assert moved > 1.0, out
    assert html.is_file() and "meshcat" in html.read_text()[:200000].lower()


def test_control_on_hardware_needs_an_answering_can_server(capsys):
    # Nothing listens on a port just freed: a one-line error before any build,
    # instead of "driving" a hand that is not there.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["midi", "control", "--meshcat", "--hardware", "--duration", "0.1",
                 "--scenario", str(diagrams_dir() / "shadow_can_hand.yaml"), "--override",
                 f"driver: !CanHandDriver {{host: 127.0.0.1, port: {port}}}"]) == 2
    err = capsys.readouterr().err
    assert f"expected a CAN bus server at 127.0.0.1:{port}" in err and "Traceback" not in err
    assert main(["midi", "control", "--meshcat", "--hardware", "--duration", "0.1"]) == 2
    assert "driver: !CanHandDriver" in capsys.readouterr().err


def test_monitor_prints_what_the_device_reports(monkeypatch, capsys):
    # An in-process port plays the device (no MIDI system here).
    device, host = ports.in_process_pair()
    _, output = ports.in_process_pair()
    monkeypatch.setattr(ports, "open_device_ports", lambda name: (host, output))
    for message in (mido.Message("control_change", control=22, value=77),  # fader3
                    mido.Message("control_change", control=60, value=3),  # jog +3
                    mido.Message("control_change", control=60, value=64 + 1),  # jog -1
                    mido.Message("note_on", note=84, velocity=127),  # mode pressed
                    mido.Message("sysex", data=[1, 2]),
                    mido.Message("control_change", channel=5, control=22, value=1)):
        device.send(message)
    assert main(["midi", "monitor", "--duration", "0.2"]) == 0
    lines = [" ".join(line.split()) for line in capsys.readouterr().out.splitlines()]
    assert lines[1:] == ["fader3 77", "jog +3 ticks (net +3)", "jog -1 ticks (net +2)",
                         "mode pressed (presses: 1)",
                         "ignored (sysex): sysex data=(1,2) time=0",
                         "ignored (unknown_channel): control_change channel=5 control=22 "
                         "value=1 time=0",
                         "messages: 4 accepted, 2 ignored (sysex 1, unknown_channel 1)"]
    assert host.closed
    assert main(["midi", "monitor", "--duration", "0"]) == 2


def test_simulate_reports_what_the_controller_midi_said(capsys):
    """``simulate`` of a MIDI scenario: a fader pushed 1 s into the push reads, through
    MIDI, the value its cap position gives (round(127 s / travel), within one count:
    the receiver reads the scan before)."""
    assert main(["simulate", str(diagrams_dir() / "midi_fader_push.yaml"),
                 "--duration", "1.0"]) == 0
    out = capsys.readouterr().out
    line = re.search(r"fader5 +at +([\d.]+) of (\d+) mm \(value (\d+)\); MIDI value (\d+)", out)
    assert line, out
    position, travel, value, midi = (float(line[1]), float(line[2]), int(line[3]), int(line[4]))
    assert position > 2.0  # mm: the fingertip moved the cap
    assert abs(value - 127 * position / travel) <= 0.5 + 127 * 0.05 / travel  # printed 0.1 mm
    assert abs(midi - value) <= 1
    accepted = int(re.search(r"MIDI controller: (\d+) messages accepted, 0 ignored", out)[1])
    assert accepted >= midi  # a message per count the cap passed (at least)
