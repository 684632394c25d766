"""The instrument ports of the station, simulated and on hardware.

:func:`AddSimulatedInstruments` (called by ``MakeHandStation`` when the
scenario's object has an ``accelerometer``) puts the accelerometer on the
object body at ``X_OS`` and adds the estimators; :func:`WithHardwareInstruments`
(``hardware=True``) wraps the hardware station with the evdev driver of the real
device and the same estimators. Both export ``object.acceleration``,
``object.acceleration_counts``, ``object.roll_pitch``, ``object.at_rest``,
``object.free_fall`` and ``object.slip`` (see
:mod:`handle_drake.instruments.accelerometer`). The slip detector's ``command``
is the hand driver's ``position_commanded`` (and, with a floating wrist, the
wrist driver's ``desired_state``).
"""

from __future__ import annotations

from handle_drake.instruments.accelerometer import (
    AddInstrumentEstimators,
    AddObjectAccelerometer,
    default_sensor_pose,
    sensor_pose,
)

__all__ = ["AddSimulatedInstruments", "WithHardwareInstruments", "instrument_X_OS",
           "instrument_seed", "RECORDING_PREFIX"]

#: ``evdev_device: recording:FILE`` replays a recording (``evdev_driver.save_events``).
RECORDING_PREFIX = "recording:"


def instrument_X_OS(scenario):
    """The sensor pose ``X_OS`` of the scenario's object accelerometer: ``X_OS`` if
    given, else an instrumented device's named sensor frame, else
    :func:`~handle_drake.instruments.accelerometer.default_sensor_pose` (the object
    frame, or the surface point nearest to it when the origin is off the object)."""
    from handle_drake.instruments.catalogue import DEVICE_OBJECTS

    config = scenario.object.accelerometer
    if config.X_OS is not None:
        return config.X_OS.GetDeterministicValue()
    if scenario.object.kind in DEVICE_OBJECTS:
        return sensor_pose(scenario.object.kind, scenario.object.size)
    from handle_drake.station import object_spec

    return default_sensor_pose(object_spec(scenario))


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


def AddSimulatedInstruments(builder, plant, scenario, body) -> dict:
    """Adds the scenario's object accelerometer on ``body`` and its estimators to the
    station's builder (after the hand driver); exports the instrument ports."""
    config = scenario.object.accelerometer
    profile = config.profile(scenario.object.kind)
    device = AddObjectAccelerometer(builder, plant, body, instrument_X_OS(scenario), profile,
                                    seed=instrument_seed(scenario))
    systems = AddInstrumentEstimators(
        builder, device.GetOutputPort("acceleration"), device.GetOutputPort("counts"), profile,
        config.estimator_params(), command=_command_port(builder))
    systems["device"] = device
    # Ground truth for experiments (simulation only): the ideal specific force in S.
    builder.ExportOutput(builder.GetSubsystemByName("object_accelerometer_ideal")
                         .get_measurement_output_port(), "object.acceleration_true")
    return systems


def WithHardwareInstruments(station, scenario, source=None):
    """The hardware ``station`` plus the real accelerometer (evdev) and its estimators:
    a diagram exporting all of the station's ports and the instrument ports.

    ``source`` (for tests and replays) replaces the device named by
    ``object.accelerometer.evdev_device`` (a path, a device name, or
    ``recording:FILE``)."""
    from pydrake.systems.framework import DiagramBuilder

    from handle_drake.instruments.evdev_driver import (
        EvdevAccelerometer,
        load_events,
        open_device,
    )

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
    device = builder.AddNamedSystem("object_accelerometer", EvdevAccelerometer(source, profile))
    AddInstrumentEstimators(builder, device.GetOutputPort("acceleration"),
                            device.GetOutputPort("counts"), profile, config.estimator_params(),
                            command=inner.GetOutputPort("hand.position_commanded"))
    diagram = builder.Build()
    diagram.set_name(station.get_name() + "_instrumented")
    return diagram
