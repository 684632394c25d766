"""The evdev driver of a real accelerometer: on a recorded event stream (this kernel
has no /dev/uinput), through a virtual uinput device where one exists, and the
hardware station's instrument ports against the simulated station's."""

import math
import os
import socket

import numpy as np
import pytest
from pydrake.math import RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.devices.accelerometer.estimators import EstimatorParams
from handle_drake.devices.accelerometer.evdev_driver import (
    ABS_X,
    ABS_Y,
    ABS_Z,
    EV_ABS,
    EV_SYN,
    EvdevAccelerometer,
    RecordedEvents,
    load_events,
    save_events,
)
from handle_drake.devices.accelerometer.profiles import get_profile
from handle_drake.devices.accelerometer.sensor import INSTRUMENT_SIGNALS, ExportInstrumentPorts

PROFILE = get_profile("joywarrior24f14")
CENTRE = 2 ** 13  # the JoyWarrior's raw 14-bit readings are unsigned around 8192


def _stream(rpy, until=0.5, fall_until=0.6, rate=125.0):
    """Events of a JoyWarrior at rest at ``rpy`` (raw = centre + counts of 1 g), then
    free falling (0 g); one report (X, Y, Z, SYN) per sample."""
    f_S = RollPitchYaw(rpy).ToRotationMatrix().inverse() @ np.array([0, 0, 9.80665])
    counts = np.rint(f_S / PROFILE.lsb).astype(int)
    events = []
    for k in range(int(fall_until * rate)):
        t = k / rate
        values = counts if t < until else np.zeros(3, dtype=int)
        events += [(t, EV_ABS, code, CENTRE + int(v)) for code, v in
                   zip((ABS_X, ABS_Y, ABS_Z), values, strict=True)]
        events.append((t, EV_SYN, 0, 0))
    return events, counts


def _diagram(source):
    builder = DiagramBuilder()
    device = builder.AddSystem(EvdevAccelerometer(source, PROFILE, estimators=EstimatorParams()))
    ExportInstrumentPorts(builder, device)
    return builder.Build()


def test_recorded_stream_gives_counts_roll_pitch_and_free_fall(tmp_path):
    rpy = (math.radians(20), math.radians(-10), 0.3)
    events, counts = _stream(rpy)
    path = tmp_path / "joywarrior.events"
    save_events(path, events)
    diagram = _diagram(load_events(path))
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    simulator.AdvanceTo(0.4)
    np.testing.assert_array_equal(diagram.GetOutputPort("object.acceleration_counts")
                                  .Eval(context), counts)
    estimate = diagram.GetOutputPort("object.roll_pitch").Eval(context)
    bound = math.asin(math.sqrt(3) / 2 * PROFILE.lsb / 9.8) / math.cos(rpy[1])
    np.testing.assert_allclose(estimate, rpy[:2], atol=bound)
    assert diagram.GetOutputPort("object.at_rest").Eval(context)[0] == 1.0
    assert diagram.GetOutputPort("object.free_fall").Eval(context)[0] == 0.0
    simulator.AdvanceTo(0.59)
    assert diagram.GetOutputPort("object.free_fall").Eval(context)[0] == 1.0
    # A reset replays the stream from its start.
    context.SetTime(0.0)
    simulator.Initialize()
    simulator.AdvanceTo(0.1)
    np.testing.assert_array_equal(diagram.GetOutputPort("object.acceleration_counts")
                                  .Eval(context), counts)


def test_recordings_refuse_bad_rows(tmp_path):
    with pytest.raises(ValueError, match="must not decrease"):
        RecordedEvents([(0.1, EV_ABS, 0, 1), (0.0, EV_ABS, 0, 1)])
    with pytest.raises(ValueError, match=r"events\[0\]"):
        RecordedEvents([(0.1, EV_ABS, 0)])
    bad = tmp_path / "bad.events"
    bad.write_text("0.0 3 0\n")
    with pytest.raises(ValueError, match="bad.events:1"):
        load_events(bad)
    with pytest.raises(FileNotFoundError):
        load_events(tmp_path / "missing.events")
    with pytest.raises(TypeError, match="read_events"):
        EvdevAccelerometer(object(), PROFILE)
    with pytest.raises(ValueError, match="axes"):
        EvdevAccelerometer(RecordedEvents([]), PROFILE, axes=(0, 0, 1))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_hardware_station_exports_the_simulated_instrument_ports(tmp_path):
    from handle_drake.scenario import LoadScenario
    from handle_drake.station import MakeHandStation

    events, counts = _stream((0.2, 0.1, 0.0))
    path = tmp_path / "jw.events"
    save_events(path, events)
    base = ("hand: {kind: shadow, mount: !FixedMount {}}\n"
            f"object: {{kind: joywarrior, accelerometer: {{evdev_device: 'recording:{path}'}}}}\n")
    hardware = MakeHandStation(
        LoadScenario(data=base + f"driver: !CanHandDriver {{port: {_free_port()}}}"),
        hardware=True)
    try:
        sim = MakeHandStation(LoadScenario(
            data=base.replace("mount: !FixedMount {}",
                              "mount: !FixedMount {X_WB: {translation: [0, 0, 1]}}")))

        def ports(diagram):
            out = [diagram.get_output_port(i) for i in range(diagram.num_output_ports())]
            return {p.get_name(): p.size() for p in out
                    if p.get_name().startswith("object.") and p.get_name().split(".")[1]
                    in INSTRUMENT_SIGNALS}

        assert ports(hardware) == ports(sim)
        assert len(ports(sim)) == len(INSTRUMENT_SIGNALS)
        context = hardware.CreateDefaultContext()
        hardware.GetInputPort("hand.position").FixValue(context, np.zeros(20))
        simulator = Simulator(hardware, context)
        simulator.AdvanceTo(0.1)
        np.testing.assert_array_equal(
            hardware.GetOutputPort("object.acceleration_counts").Eval(context), counts)
    finally:
        hardware.GetSubsystemByName("station").GetSubsystemByName("hand_driver").close()


def test_hardware_station_needs_the_device():
    from handle_drake.scenario import LoadScenario
    from handle_drake.station import MakeHandStation

    scenario = LoadScenario(data="hand: {mount: !FixedMount {}}\nobject: {kind: joywarrior, "
                                 "accelerometer: {}}\n"
                                 f"driver: !CanHandDriver {{port: {_free_port()}}}")
    with pytest.raises(ValueError, match="evdev_device"):
        MakeHandStation(scenario, hardware=True)


@pytest.mark.skipif(not os.path.exists("/dev/uinput"),
                    reason="no /dev/uinput in this kernel: the recorded-stream tests cover it")
def test_virtual_uinput_joystick():  # pragma: no cover - needs the uinput module
    import time

    import evdev
    from evdev import AbsInfo, UInput

    from handle_drake.devices.accelerometer.evdev_driver import open_device

    info = AbsInfo(value=CENTRE, min=0, max=2 ** 14 - 1, fuzz=0, flat=0, resolution=0)
    capabilities = {evdev.ecodes.EV_ABS: [(ABS_X, info), (ABS_Y, info), (ABS_Z, info)]}
    with UInput(capabilities, name="JoyWarrior test") as ui:
        time.sleep(0.2)
        source = open_device("JoyWarrior test")
        diagram = _diagram(source)
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        for code, value in ((ABS_X, CENTRE), (ABS_Y, CENTRE), (ABS_Z, CENTRE + 4096)):
            ui.write(evdev.ecodes.EV_ABS, code, value)
        ui.syn()
        time.sleep(0.05)
        simulator.AdvanceTo(0.1)
        np.testing.assert_array_equal(
            diagram.GetOutputPort("object.acceleration_counts").Eval(context), [0, 0, 4096])


class _FakeInputDevice:
    """What the live path uses of ``evdev.InputDevice`` (this kernel has no uinput):
    name, path, absinfo, set_absinfo and non-blocking read()."""

    def __init__(self, path, name="Code Mercenaries JoyWarrior24F14", writable=True):
        self.path, self.name, self.writable = path, name, writable
        self.flat = {code: 64 for code in (ABS_X, ABS_Y, ABS_Z)}  # the kernel's deadband
        self.pending = []

    def absinfo(self, code):
        from evdev import AbsInfo

        return AbsInfo(value=CENTRE, min=0, max=2 ** 14 - 1, fuzz=0, flat=self.flat[code],
                       resolution=0)

    def set_absinfo(self, code, flat=None):
        if not self.writable:
            raise PermissionError(13, "Permission denied")
        self.flat[code] = flat

    def read(self):
        if not self.pending:
            raise BlockingIOError(11, "Resource temporarily unavailable")
        events, self.pending = self.pending, []
        return iter(events)


def _fake_evdev(monkeypatch, devices):
    import evdev

    by_path = {d.path: d for d in devices}
    monkeypatch.setattr(evdev, "list_devices", lambda: list(by_path))
    monkeypatch.setattr(evdev, "InputDevice", lambda path: by_path[path])
    monkeypatch.setattr("handle_drake.devices.accelerometer.evdev_driver.Path.exists",
                        lambda self: str(self) in by_path)


def test_live_device_found_by_name_deadband_cleared_and_read(monkeypatch):
    from evdev import InputEvent

    from handle_drake.devices.accelerometer.evdev_driver import LiveEvents, open_device

    mouse = _FakeInputDevice("/dev/input/event3", name="USB Optical Mouse")
    joy = _FakeInputDevice("/dev/input/event7")
    _fake_evdev(monkeypatch, [mouse, joy])
    source = open_device("joywarrior")  # case-insensitive part of the name
    assert isinstance(source, LiveEvents) and source.device is joy
    # The report's warning: the kernel's joystick deadband would zero a level sensor.
    assert joy.flat == {ABS_X: 0, ABS_Y: 0, ABS_Z: 0} and mouse.flat[ABS_X] == 64
    assert open_device("/dev/input/event7").device is joy
    assert source.read_events(0.0) == []  # nothing pending: no blocking
    diagram = _diagram(source)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    # 1 g on z: the centre (min + max + 1) / 2 = 8192 from absinfo, plus 4096 counts.
    joy.pending = [InputEvent(0, 0, EV_ABS, ABS_Z, CENTRE + 4096),
                   InputEvent(0, 0, EV_ABS, ABS_X, CENTRE - 100),
                   InputEvent(0, 0, EV_SYN, 0, 0)]
    simulator.AdvanceTo(0.01)
    np.testing.assert_array_equal(
        diagram.GetOutputPort("object.acceleration_counts").Eval(context), [-100, 0, 4096])
    np.testing.assert_allclose(diagram.GetOutputPort("object.acceleration").Eval(context)[2],
                               9.80665)
    simulator.AdvanceTo(0.05)  # no new events: the last values are held
    np.testing.assert_array_equal(
        diagram.GetOutputPort("object.acceleration_counts").Eval(context), [-100, 0, 4096])


def test_live_device_errors_and_a_read_only_device(monkeypatch):
    from handle_drake.devices.accelerometer.evdev_driver import open_device

    joy = _FakeInputDevice("/dev/input/event7", writable=False)
    _fake_evdev(monkeypatch, [joy])
    with pytest.warns(UserWarning, match="deadband"):
        source = open_device("JoyWarrior")
    assert source.device is joy
    with pytest.raises(FileNotFoundError,
                       match=r"no input device named like 'Wiimote'.*JoyWarrior"):
        open_device("Wiimote")
    with pytest.raises(FileNotFoundError, match="/dev/input/event9 does not exist"):
        open_device("/dev/input/event9")
    with pytest.raises(ValueError, match="evdev_device"):
        open_device("")
