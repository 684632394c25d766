"""An accelerometer on the object: Drake's ``Accelerometer`` and a device model.

Drake's :class:`pydrake.systems.sensors.Accelerometer` gives the specific force
(proper acceleration) ``f_S = R_SW (a_WS - g_W)`` of a sensor frame S on a
body, continuously, when it is given the plant's gravity vector (without it a
body at rest would read zero). :class:`DeviceAccelerometer` turns that into
what a real device reports (:mod:`~handle_drake.instruments.profiles`): sampled
at the device rate and held, biased, noisy, saturated, quantised, in counts and
in m/s^2. :func:`AddObjectAccelerometer` adds both to a diagram;
:func:`AddInstrumentEstimators` adds the estimators
(:mod:`~handle_drake.instruments.estimators`) behind any source of the
``acceleration`` signal (this device model, or the evdev driver of a real
device) and exports the same ports either way:

=============================  ====  ====================================================
port                           size  units / frame
=============================  ====  ====================================================
``<object>.acceleration``      3     m/s^2, specific force in the sensor frame S
``<object>.acceleration_counts`` 3   device counts (integers)
``<object>.roll_pitch``        2     rad, roll and pitch of S from gravity (valid at rest)
``<object>.at_rest``           1     1.0 when the readings look like rest
``<object>.free_fall``         1     1.0 while free fall is detected
``<object>.slip``              1     1.0 while slip is detected (hand command still)
=============================  ====  ====================================================
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.systems.sensors import Accelerometer

from handle_drake.instruments.estimators import (
    EstimatorParams,
    FreeFallDetector,
    RollPitchEstimator,
    SlipDetector,
)
from handle_drake.instruments.profiles import (
    DeviceProfile,
    device_bias,
    get_profile,
    sample_noise,
    to_counts,
)

__all__ = [
    "DeviceAccelerometer",
    "device_reading",
    "sensor_pose",
    "check_sensor_pose",
    "AddObjectAccelerometer",
    "AddInstrumentEstimators",
    "INSTRUMENT_SIGNALS",
]

#: The signals every instrumented station exports as ``<object>.<signal>``.
INSTRUMENT_SIGNALS = ("acceleration", "acceleration_counts", "roll_pitch", "at_rest",
                      "free_fall", "slip")


def device_reading(f_S, profile: DeviceProfile, seed: int = 0, index: int = 0) -> np.ndarray:
    """The counts a device reports for the specific force ``f_S`` (3, m/s^2) at its
    sample ``index``: bias and noise added, then quantised and saturated."""
    f_S = np.asarray(f_S, dtype=float)
    if f_S.shape != (3,):
        raise ValueError(f"f_S: expected 3 values (m/s^2), got shape {f_S.shape}")
    return to_counts(f_S + device_bias(profile, seed) + sample_noise(profile, seed, index),
                     profile)


class DeviceAccelerometer(LeafSystem):
    """A consumer accelerometer: input ``specific_force`` (3, m/s^2, ideal, sensor
    frame); outputs ``counts`` (3) and ``acceleration`` (3, m/s^2 = counts * lsb).

    Samples every ``1 / profile.rate_hz`` s from t = 0 (sample k at t = k / rate
    uses noise sample k) and holds the reading between samples; zero before
    the first sample.
    """

    def __init__(self, profile: DeviceProfile | str, seed: int = 0):
        super().__init__()
        self.profile = get_profile(profile)
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise TypeError(f"seed must be an int, got {type(seed).__name__}")
        self.seed = int(seed)
        self._bias = device_bias(self.profile, self.seed)
        self._input = self.DeclareVectorInputPort("specific_force", 3)
        self._counts = self.DeclareDiscreteState(3)
        self.DeclarePeriodicDiscreteUpdateEvent(self.profile.period, 0.0, self._sample)
        self.DeclareStateOutputPort("counts", self._counts)
        self.DeclareVectorOutputPort("acceleration", 3, self._calc_acceleration,
                                     {self.discrete_state_ticket(self._counts)})

    def _sample(self, context, discrete_state):
        index = int(round(context.get_time() * self.profile.rate_hz))
        f = self._input.Eval(context)
        noise = sample_noise(self.profile, self.seed, index)
        discrete_state.get_mutable_vector(self._counts).SetFromVector(
            to_counts(f + self._bias + noise, self.profile))

    def _calc_acceleration(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._counts).get_value()
                             * self.profile.lsb)


def sensor_pose(kind: str, size: float) -> RigidTransform:
    """``X_OS``: the named sensor frame of an instrumented catalogue object, or the
    object frame itself for any other kind."""
    from handle_drake.instruments.catalogue import DEVICE_OBJECTS

    device = DEVICE_OBJECTS.get(kind)
    if device is None:
        return RigidTransform()
    return RigidTransform(RollPitchYaw(np.radians(device.sensor_rpy_deg)),
                          np.asarray(device.sensor_xyz) * size)


def check_sensor_pose(spec, X_OS: RigidTransform, tolerance: float = 0.002) -> None:
    """Raises ValueError when the sensor origin is not in or on the object (within
    ``tolerance`` m of its surface: a sensor may be glued on)."""
    from handle_drake.objects import _halfspaces, _inside

    p = np.asarray(X_OS.translation(), dtype=float).reshape(1, 3)
    if not np.all(np.isfinite(p)):
        raise ValueError(f"X_OS: sensor position must be finite, got {p.ravel().tolist()}")
    if not any(_inside(desc, p, tolerance)[0] for desc in _halfspaces(spec)):
        raise ValueError(
            f"X_OS: the sensor at {np.round(p.ravel(), 4).tolist()} m (object frame) is off "
            f"the {spec.kind} (expected inside it or within {tolerance * 1e3:.0f} mm of its "
            "surface)")


def AddObjectAccelerometer(builder, plant, body, X_BS: RigidTransform,
                           profile: DeviceProfile | str, seed: int = 0,
                           name: str = "object_accelerometer"):
    """Adds Drake's ``Accelerometer`` on ``body`` at ``X_BS`` (with the plant's
    gravity) and a :class:`DeviceAccelerometer` behind it; returns the device
    system (outputs ``counts``, ``acceleration``). The ideal sensor is named
    ``<name>_ideal``."""
    ideal = builder.AddNamedSystem(
        f"{name}_ideal",
        Accelerometer(body, X_BS, plant.gravity_field().gravity_vector()))
    builder.Connect(plant.get_body_poses_output_port(), ideal.get_body_poses_input_port())
    builder.Connect(plant.get_body_spatial_velocities_output_port(),
                    ideal.get_body_velocities_input_port())
    builder.Connect(plant.get_body_spatial_accelerations_output_port(),
                    ideal.get_body_accelerations_input_port())
    device = builder.AddNamedSystem(name, DeviceAccelerometer(profile, seed))
    builder.Connect(ideal.get_measurement_output_port(), device.get_input_port())
    return device


def AddInstrumentEstimators(builder, acceleration, counts, profile: DeviceProfile,
                            params: EstimatorParams | None = None, command=None,
                            prefix: str = "object", export: bool = True) -> dict:
    """Adds the roll/pitch, free-fall and slip estimators behind the output port
    ``acceleration`` (3, m/s^2), sampling at the device rate, and exports the
    instrument ports ``<prefix>.<signal>`` (module doc). ``command`` is the
    output port whose stillness enables the slip detector (the hand and wrist
    command); without it the slip output is a constant 0 (nothing tells whether
    the hand moves). Returns the systems by name."""
    from pydrake.systems.primitives import ConstantVectorSource

    params = params or EstimatorParams()
    period = profile.period
    systems = {
        "roll_pitch": builder.AddNamedSystem(f"{prefix}_roll_pitch",
                                             RollPitchEstimator(period, params)),
        "free_fall": builder.AddNamedSystem(f"{prefix}_free_fall",
                                            FreeFallDetector(period, params)),
    }
    for system in systems.values():
        builder.Connect(acceleration, system.GetInputPort("acceleration"))
    if command is not None:
        slip = builder.AddNamedSystem(f"{prefix}_slip",
                                      SlipDetector(period, command.size(), params))
        builder.Connect(acceleration, slip.GetInputPort("acceleration"))
        builder.Connect(command, slip.GetInputPort("command"))
        slip_port = slip.GetOutputPort("slip")
        systems["slip"] = slip
    else:
        slip_port = builder.AddNamedSystem(f"{prefix}_slip_unknown",
                                           ConstantVectorSource([0.0])).get_output_port()
    if export:
        builder.ExportOutput(acceleration, f"{prefix}.acceleration")
        builder.ExportOutput(counts, f"{prefix}.acceleration_counts")
        builder.ExportOutput(systems["roll_pitch"].GetOutputPort("roll_pitch"),
                             f"{prefix}.roll_pitch")
        builder.ExportOutput(systems["roll_pitch"].GetOutputPort("at_rest"), f"{prefix}.at_rest")
        builder.ExportOutput(systems["free_fall"].GetOutputPort("free_fall"),
                             f"{prefix}.free_fall")
        builder.ExportOutput(slip_port, f"{prefix}.slip")
    return systems
