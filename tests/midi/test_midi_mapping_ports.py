"""The mapping file and the MIDI ports (in-process, Meshcat sliders, devices)."""

import threading

import mido
import pytest
from pydrake.geometry import Meshcat

from handle_drake.devices.midi.mapping import DEFAULT_MAPPING_FILE, LoadMidiMapping
from handle_drake.devices.midi.ports import (
    MeshcatFaderPort,
    MidiPortError,
    in_process_pair,
    open_device_ports,
)


def test_default_mapping_has_the_icontrols_pro_controls():
    mapping = LoadMidiMapping()
    assert len(mapping.names("fader")) == 9 and len(mapping.names("knob")) == 9
    assert mapping.names("jog") == ["jog"] and "mode" in mapping.names("button")
    assert mapping.find("control_change", 0, 60).name == "jog"
    assert mapping.find("note", 0, 84).name == "mode"
    assert mapping.find("control_change", 3, 60) is None


@pytest.mark.parametrize("override, field", [
    ("relative_encoding: gray", "relative_encoding"),
    ("jog_ticks_per_turn: 0", "jog_ticks_per_turn"),
    ("controls: [{name: a, kind: slider}]", "kind"),
    ("controls: [{name: a, number: 128}]", "number"),
    ("controls: [{name: a, number: 1}, {name: b, number: 1}]", "same message"),
    ("controls: [{name: a}, {name: a, number: 2}]", "duplicate"),
    ("colour: red", "unknown"),
])
def test_bad_mapping_names_the_field(override, field):
    with pytest.raises(ValueError, match=field):
        LoadMidiMapping(data=override)


def test_mapping_file_can_be_edited(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(DEFAULT_MAPPING_FILE.read_text().replace("number: 60", "number: 61"))
    assert LoadMidiMapping(path).control("jog").number == 61
    with pytest.raises(FileNotFoundError, match="nothing.yaml"):
        LoadMidiMapping(tmp_path / "nothing.yaml")


def test_in_process_ports_carry_messages_both_ways_and_across_threads():
    device, host = in_process_pair()
    device.send(mido.Message("control_change", control=20, value=5))
    host.send(mido.Message("control_change", control=21, value=6))
    assert [m.value for m in host.iter_pending()] == [5]
    assert [m.value for m in device.iter_pending()] == [6]
    assert host.poll() is None
    sender = threading.Thread(target=lambda: [device.send(mido.Message("note_on", note=n))
                                              for n in range(100)])
    sender.start()
    received = [host.receive().note for _ in range(100)]
    sender.join()
    assert received == list(range(100))
    host.close()
    device.send(mido.Message("note_on", note=1))  # nobody listening: dropped, no error


def test_device_ports_fail_with_a_clear_error():
    # No ALSA sequencer here ("no MIDI system"); with one but no device, "no MIDI device".
    with pytest.raises(MidiPortError, match="no MIDI (system|device)"):
        open_device_ports("iControls-that-is-not-connected")
    with pytest.raises(ValueError, match="port name"):
        open_device_ports("")


def test_meshcat_sliders_act_as_faders():
    meshcat = Meshcat()
    port = MeshcatFaderPort(meshcat, LoadMidiMapping())
    assert list(port.iter_pending()) == []
    meshcat.SetSliderValue("MIDI fader3", 77)
    assert list(port.iter_pending()) == [mido.Message("control_change", control=22, value=77)]
    assert list(port.iter_pending()) == []  # only changes are sent
    port.send(mido.Message("control_change", control=21, value=99))  # motorised feedback
    assert meshcat.GetSliderValue("MIDI fader2") == 99
    assert list(port.iter_pending()) == []  # feedback is not echoed
    port.close()
