"""``handle-drake midi``: errors are one line and exit 2; live control runs."""

from handle_drake.cli import main


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
