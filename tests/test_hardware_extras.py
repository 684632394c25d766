"""Hardware extras: without python-rtmidi (extra ``midi-device``) or evdev (extra
``joywarrior``) the commands that need them fail in one line naming the extra, exit 2.

Both packages are installed in the test environment ([test] extra): the missing
package is simulated by ``sys.modules[name] = None`` (Python then refuses the import
as it refuses a package that is not there)."""

import socket
import sys

import pytest

from handle_drake.cli import main
from handle_drake.extras import MissingExtraError, require_extra


@pytest.fixture
def no_rtmidi(monkeypatch):
    monkeypatch.setitem(sys.modules, "rtmidi", None)


@pytest.fixture
def no_evdev(monkeypatch):
    monkeypatch.setitem(sys.modules, "evdev", None)


def _one_line_naming(err: str, extra: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert f"pip install 'handle_drake[{extra}]'" in lines[0]
    assert "Traceback" not in err


@pytest.mark.parametrize("argv", [
    ["midi", "ports"],
    ["midi", "monitor", "--duration", "1"],
    ["midi", "monitor", "--port", "iControls", "--duration", "1"],
    ["midi", "control", "--duration", "1"],
])
def test_midi_device_commands_name_the_midi_device_extra(no_rtmidi, capsys, argv):
    assert main(argv) == 2
    captured = capsys.readouterr()
    _one_line_naming(captured.err, "midi-device")
    assert "python-rtmidi" in captured.err


def test_midi_without_a_device_needs_no_rtmidi(no_rtmidi):
    # The in-process port and the decoder are mido alone.
    import mido

    from handle_drake.midi.ports import in_process_pair

    device, host = in_process_pair()
    device.send(mido.Message("control_change", control=60, value=3))
    assert [m.value for m in host.iter_pending()] == [3]


def test_a_real_joywarrior_names_the_joywarrior_extra(no_evdev, capsys, tmp_path):
    from handle_drake.instruments.evdev_driver import open_device

    with pytest.raises(MissingExtraError, match=r"pip install 'handle_drake\[joywarrior\]'"):
        open_device("/dev/input/event0")
    # Through a command: simulate --hardware with a JoyWarrior on evdev (a listener on
    # loopback stands in for the CAN server the command checks first).
    scenario = ("hand: {kind: shadow, mount: !FixedMount {}}\n"
                "object: {kind: joywarrior, accelerometer: {evdev_device: JoyWarrior}}\n")
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        path = tmp_path / "jw.yaml"
        path.write_text(scenario + f"driver: !CanHandDriver {{port: {port}}}\n")
        code = main(["simulate", str(path), "--hardware"])
    assert code == 2
    _one_line_naming(capsys.readouterr().err, "joywarrior")


def test_require_extra_returns_the_module_when_installed():
    assert require_extra("evdev").__name__ == "evdev"
    with pytest.raises(KeyError):
        require_extra("numpy")  # not an extra
