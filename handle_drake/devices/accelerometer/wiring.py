"""The instrument ports of the station, simulated and on hardware.

:func:`AddSimulatedInstruments` (called by ``MakeHandStation`` when the
scenario's object has an ``accelerometer``) puts the accelerometer on the
object body at ``X_OS``, the estimators running in the device's own update
(one event per sample); :func:`WithHardwareInstruments` (``hardware=True``)
wraps the hardware station with the evdev driver of the real device, which
runs the same estimators the same way. Both export ``object.acceleration``,
``object.acceleration_counts``, ``object.roll_pitch``, ``object.at_rest``,
``object.free_fall`` and ``object.slip`` (see
:mod:`handle_drake.devices.accelerometer.sensor`). The slip detector's ``command``
is the hand driver's ``position_commanded`` (and, with a floating wrist, the
wrist driver's ``desired_state``), read at the sample instant: the command as
it was before the drivers' own updates at that instant, if any (the
estimators used to sample 0.1 ms after the device, after those updates).
"""

from __future__ import annotations

from handle_drake.devices.accelerometer.estimators import true_roll_pitch
from handle_drake.devices.accelerometer.evdev_driver import (
    EvdevAccelerometer,
    load_events,
    open_device,
)
from handle_drake.devices.accelerometer.profiles import STANDARD_GRAVITY
from handle_drake.devices.accelerometer.sensor import (
    AddObjectAccelerometer,
    ExportInstrumentPorts,
    default_sensor_pose,
    sensor_pose,
)
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS

__all__ = ["AddSimulatedInstruments", "WithHardwareInstruments", "instrument_X_OS",
           "instrument_seed", "RECORDING_PREFIX", "INSTRUMENT_LOG", "flag_intervals",
           "describe_instruments"]

#: ``evdev_device: recording:FILE`` replays a recording (``evdev_driver.save_events``).
RECORDING_PREFIX = "recording:"


def instrument_X_OS(scenario, spec):
    """The sensor pose ``X_OS`` of the scenario's object accelerometer (``spec``: the
    object's spec, ``scenario.object_spec``): ``X_OS`` if given, else an instrumented
    device's named sensor frame, else
    :func:`~handle_drake.devices.accelerometer.sensor.default_sensor_pose` (the object
    frame, or the surface point nearest to it when the origin is off the object)."""

    config = scenario.object.accelerometer
    if config.X_OS is not None:
        return config.X_OS.GetDeterministicValue()
    if scenario.object.kind in DEVICE_OBJECTS:
        return sensor_pose(scenario.object.kind, scenario.object.size)
    return default_sensor_pose(spec)


#: The instrument ports ``handle-drake simulate`` records (every ``harness.LOG_PERIOD``).
INSTRUMENT_LOG = ("object.acceleration", "object.roll_pitch", "object.at_rest",
                  "object.free_fall", "object.slip")


def flag_intervals(times, flag) -> list[tuple[float, float]]:
    """``(first, last)`` sample times of each run of ``flag > 0.5``."""
    import numpy as np

    on = np.asarray(flag, dtype=float).ravel() > 0.5
    times = np.asarray(times, dtype=float).ravel()
    edges = np.flatnonzero(np.diff(np.r_[0, on.astype(int), 0]))
    return [(float(times[a]), float(times[b - 1])) for a, b in zip(edges[::2], edges[1::2],
                                                                   strict=True)]


def describe_instruments(scenario, spec, logs, X_WO=None) -> str:
    """What the object's accelerometer said over a run, for ``handle-drake simulate``:
    the last reading and its roll/pitch (and the plant's true roll/pitch of the
    sensor frame, given the object pose ``X_WO`` at the end), and when free fall and
    slip were flagged. ``logs``: the ``VectorLog`` of each :data:`INSTRUMENT_LOG`
    port (a flag shorter than the log period may fall between two samples); ``spec``:
    the object's spec (``scenario.object_spec``)."""
    import numpy as np


    config = scenario.object.accelerometer
    profile = config.profile(scenario.object.kind)
    X_OS = instrument_X_OS(scenario, spec)
    times = logs["object.acceleration"].sample_times()
    lines = [f"object accelerometer ({profile.name}, {profile.rate_hz:g} Hz, +-{profile.range_g:g}"
             f" g, {profile.bits} bit) at X_OS = "
             f"{np.round(X_OS.translation() * 1e3, 1).tolist()} mm:"]
    if not len(times):
        return "\n".join(lines + ["  no samples (the run was too short)"])
    f = logs["object.acceleration"].data()[:, -1]
    roll, pitch = np.degrees(logs["object.roll_pitch"].data()[:, -1])
    rest = logs["object.at_rest"].data()[0, -1] > 0.5
    end = (f"  at {times[-1]:.2f} s: |f| = {np.linalg.norm(f) / STANDARD_GRAVITY:.3f} g, "
           f"roll {roll:+.1f} deg, pitch {pitch:+.1f} deg "
           f"({'at rest' if rest else 'not at rest: roll/pitch not valid'})")
    if X_WO is not None:
        true = np.degrees(true_roll_pitch((X_WO @ X_OS).rotation()))
        end += f"; true (plant) roll {true[0]:+.1f} deg, pitch {true[1]:+.1f} deg"
    lines.append(end)
    for name in ("free_fall", "slip"):
        spans = flag_intervals(times, logs[f"object.{name}"].data()[0])
        text = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in spans[:5]) or "never"
        more = f" (+{len(spans) - 5} more)" if len(spans) > 5 else ""
        lines.append(f"  {name.replace('_', ' ')} flagged: {text}{more}")
    return "\n".join(lines)


def instrument_seed(scenario) -> int:
    config = scenario.object.accelerometer
    return scenario.random_seed if config.seed is None else config.seed


def _command_port(builder):
    """The hand (and wrist) command the slip detector watches, as one port."""
    from pydrake.systems.primitives import Multiplexer

    hand = builder.GetSubsystemByName("hand_driver").GetOutputPort("position_commanded")
    if not builder.HasSubsystemNamed("wrist_driver"):
        return hand
    wrist = builder.GetSubsystemByName("wrist_driver").GetOutputPort("desired_state")
    mux = builder.AddNamedSystem("instrument_command", Multiplexer([hand.size(), wrist.size()]))
    builder.Connect(hand, mux.get_input_port(0))
    builder.Connect(wrist, mux.get_input_port(1))
    return mux.get_output_port()


def AddSimulatedInstruments(builder, plant, scenario, body, spec) -> dict:
    """Adds the scenario's object accelerometer on ``body`` (object spec ``spec``), with its
    estimators, to the station's builder (after the hand driver); exports the instrument
    ports."""
    config = scenario.object.accelerometer
    profile = config.profile(scenario.object.kind)
    seed = instrument_seed(scenario)
    device = AddObjectAccelerometer(builder, plant, body, instrument_X_OS(scenario, spec), profile,
                                    seed=seed,
                                    estimators=config.estimator_params(scenario.object.kind),
                                    command=_command_port(builder),
                                    calibration=config.calibration(scenario.object.kind, seed))
    ExportInstrumentPorts(builder, device)
    # Ground truth for experiments (simulation only): the ideal specific force in S.
    builder.ExportOutput(builder.GetSubsystemByName("object_accelerometer_ideal")
                         .get_measurement_output_port(), "object.acceleration_true")
    return {"device": device}


def WithHardwareInstruments(station, scenario, source=None):
    """The hardware ``station`` plus the real accelerometer (evdev) and its estimators:
    a diagram exporting all of the station's ports and the instrument ports.

    ``source`` (for tests and replays) replaces the device named by
    ``object.accelerometer.evdev_device`` (a path, a device name, or
    ``recording:FILE``)."""
    from pydrake.systems.framework import DiagramBuilder


    config = scenario.object.accelerometer
    profile = config.profile(scenario.object.kind)
    if source is None:
        name = config.evdev_device
        if not name:
            raise ValueError("object.accelerometer.evdev_device: hardware=True needs the real "
                             "device (/dev/input/eventN, a device name, or recording:FILE)")
        source = (load_events(name[len(RECORDING_PREFIX):]) if name.startswith(RECORDING_PREFIX)
                  else open_device(name))
    builder = DiagramBuilder()
    inner = builder.AddNamedSystem("station", station)
    for i in range(station.num_input_ports()):
        port = station.get_input_port(i)
        builder.ExportInput(port, port.get_name())
    for i in range(station.num_output_ports()):
        port = station.get_output_port(i)
        builder.ExportOutput(port, port.get_name())
    command = inner.GetOutputPort("hand.position_commanded")
    device = builder.AddNamedSystem("object_accelerometer", EvdevAccelerometer(
        # A real device's readings are raw here (its calibration would come from its own
        # six rest positions): thresholds for an uncalibrated device.
        source, profile, estimators=config.estimator_params(scenario.object.kind,
                                                            calibrated=False),
        command_size=command.size()))
    builder.Connect(command, device.GetInputPort("command"))
    ExportInstrumentPorts(builder, device)
    diagram = builder.Build()
    diagram.set_name(station.get_name() + "_instrumented")
    return diagram
