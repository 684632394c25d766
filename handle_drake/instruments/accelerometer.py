"""An accelerometer on the object: Drake's ``Accelerometer`` and a device model.

Drake's :class:`pydrake.systems.sensors.Accelerometer` gives the specific force
(proper acceleration) ``f_S = R_SW (a_WS - g_W)`` of a sensor frame S on a
body, continuously, when it is given the plant's gravity vector (without it a
body at rest would read zero). :class:`DeviceAccelerometer` turns that into
what a real device reports (:mod:`~handle_drake.instruments.profiles`): sampled
at the device rate and held, biased, noisy, saturated, quantised, in counts and
in m/s^2. :func:`AddObjectAccelerometer` adds both to a diagram; given
``estimators``, the device also runs the roll/pitch, free-fall and slip
estimators (:mod:`~handle_drake.instruments.estimators`) on each sample in its
own update (one event per sample, the device's). The evdev driver of a real
device carries the same estimators the same way, and
:func:`ExportInstrumentPorts` exports the same ports from either:

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

from functools import lru_cache

import numpy as np
from pydrake.common.containers import namedview
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import BasicVector
from pydrake.systems.sensors import Accelerometer

from handle_drake.instruments.estimators import EstimatorParams, InstrumentSystem
from handle_drake.instruments.profiles import (
    _NOISE_BLOCK,
    STANDARD_GRAVITY,
    DeviceProfile,
    _noise_block,
    device_bias,
    get_profile,
    sample_noise,
    to_counts,
)

__all__ = [
    "DeviceAccelerometer",
    "DeviceState",
    "device_reading",
    "sensor_pose",
    "default_sensor_pose",
    "check_sensor_pose",
    "AddObjectAccelerometer",
    "ExportInstrumentPorts",
    "INSTRUMENT_SIGNALS",
]

#: The signals every instrumented station exports as ``<object>.<signal>``.
INSTRUMENT_SIGNALS = ("acceleration", "acceleration_counts", "roll_pitch", "at_rest",
                      "free_fall", "slip")


#: The simulated device's own state (one discrete state group), by name: its last
#: reading (counts) and, for the averaging, the sensor point's position one and two
#: periods ago, its orientation one period ago (row-major) and the samples taken.
DeviceState = namedview("DeviceState", [
    "counts_x", "counts_y", "counts_z",
    "p1_x", "p1_y", "p1_z",  # p_WS(t - T)
    "p2_x", "p2_y", "p2_z",  # p_WS(t - 2T)
    *(f"R_WS_{i}{j}" for i in range(3) for j in range(3)),  # R_WS(t - T)
    "samples",
])
_DEVICE_SIZE = len(DeviceState.get_fields())
# Positions of the fields, for the per-sample update on plain floats.
_COUNTS, _P1, _P2, _R, _SAMPLES = (DeviceState.get_fields().index(name) for name in (
    "counts_x", "p1_x", "p2_x", "R_WS_00", "samples"))


def device_reading(f_S, profile: DeviceProfile, seed: int = 0, index: int = 0) -> np.ndarray:
    """The counts a device reports for the specific force ``f_S`` (3, m/s^2) at its
    sample ``index``: bias and noise added, then quantised and saturated."""
    f_S = np.asarray(f_S, dtype=float)
    if f_S.shape != (3,):
        raise ValueError(f"f_S: expected 3 values (m/s^2), got shape {f_S.shape}")
    return to_counts(f_S + device_bias(profile, seed) + sample_noise(profile, seed, index),
                     profile)


class DeviceAccelerometer(InstrumentSystem):
    """A consumer accelerometer: outputs ``counts`` (3) and ``acceleration`` (3, m/s^2
    = counts * lsb), sampled every ``1 / profile.rate_hz`` s from t = 0 and held
    between samples (sample k at t = k / rate uses noise sample k); zero before
    the first sample.

    Input ``specific_force`` (3, m/s^2, sensor frame): the instantaneous ideal
    reading (Drake's ``Accelerometer``). A real MEMS part low-passes before it
    decimates to its output rate (the BMA180's filter bandwidth is at most half
    the output rate). Sampling the instantaneous acceleration of a discrete
    simulation instead aliases its step-to-step velocity jitter: a 20 g
    JoyWarrior held in a tripod grasp reads +-1 g of noise that way, and
    +-0.2 g even from velocity differences over a period. With ``averaging``
    (default) the device reports the mean acceleration from the second
    difference of the sensor point's position over its last two periods (a
    triangular filter of 2T support, the reading delayed by T, as a decimating
    filter delays it): ``R_SW(t - T) ((p(t) - 2 p(t - T) + p(t - 2T)) / T^2 -
    g_W)``, from the free body's state (input ``body_state``: the plant's state
    output of the body's model instance, ``[qw qx qy qz x y z, w, v]``; a small
    vector, where the plant's ``body_poses`` would copy every body's pose into
    Python at each sample); positions of a discrete plant are smooth where its
    velocities jitter. The first two samples, with no history, are
    instantaneous readings. A welded body does not move: it needs no
    averaging (``AddObjectAccelerometer`` then reads Drake's sensor only).

    With ``estimators`` (:class:`~handle_drake.instruments.estimators.EstimatorParams`)
    the device also runs the roll/pitch, free-fall and slip estimators on each
    new sample in the same update (:class:`~handle_drake.instruments.estimators.
    InstrumentSystem`: their outputs and, with ``command_size``, the ``command``
    input); without, it is the device alone.

    With ``calibration`` (:class:`~handle_drake.instruments.calibration.
    AccelerometerCalibration`, e.g. the device's six-position calibration) the
    ``acceleration`` output, and what the estimators read, is the calibrated
    reading ``(counts * lsb - offset) / scale``; ``counts`` stay the device's own.
    """

    def __init__(self, profile: DeviceProfile | str, seed: int = 0, averaging: bool = False,
                 X_BS: RigidTransform | None = None, gravity_W=None,
                 estimators: EstimatorParams | None = None, command_size: int | None = None,
                 calibration=None):
        super().__init__()
        self.profile = get_profile(profile)
        self.calibration = calibration
        self._offset = list(calibration.offset) if calibration is not None else [0.0] * 3
        self._scale = list(calibration.scale) if calibration is not None else [1.0] * 3
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise TypeError(f"seed must be an int, got {type(seed).__name__}")
        self.seed = int(seed)
        self.averaging = bool(averaging)
        self._bias = device_bias(self.profile, self.seed).tolist()
        # The profile's derived numbers, once (properties computed per access).
        self._rate = self.profile.rate_hz
        self._inv_T2 = self.profile.rate_hz ** 2
        self._lsb = self.profile.lsb
        self._lo, self._hi = self.profile.count_limits
        self._input = self.DeclareVectorInputPort("specific_force", 3)
        if self.averaging:
            if X_BS is None or gravity_W is None:
                raise ValueError("averaging needs X_BS and gravity_W")
            self._p_BS = [float(v) for v in X_BS.translation()]
            self._R_BS = X_BS.rotation().matrix().ravel().tolist()  # row-major
            self._g_W = [float(v) for v in gravity_W]
            self._body_state = self.DeclareVectorInputPort("body_state", 13)
        self._declare_instrument(self.profile.period, DeviceState(np.zeros(_DEVICE_SIZE))[:],
                                 estimators, command_size)

    def device_state(self, context) -> DeviceState:
        """The device's own state in ``context``, by name (:data:`DeviceState`)."""
        return DeviceState(context.get_discrete_state(self._state).get_value())

    def _noise(self, index: int) -> list[float]:
        """:func:`~handle_drake.instruments.profiles.sample_noise` of sample ``index`` as
        floats (the same products, taken once per block of samples)."""
        if self.profile.noise_std_g == 0.0:
            return [0.0, 0.0, 0.0]
        block, row = divmod(index, _NOISE_BLOCK)
        return _noise_rows(self.seed, block, self.profile.noise_std_g * STANDARD_GRAVITY)[row]

    def _sample(self, context, state) -> list[float]:
        # Plain Python floats: a sample is a few dozen scalar operations, and tiny numpy
        # arrays cost more per operation than the arithmetic (this runs once per sample
        # of every trial; see benchmarks/bench_instruments.py).
        x = state.tolist()  # DeviceState, as floats: the positions of _COUNTS ... _SAMPLES
        f = None
        if self.averaging:
            qw, qx, qy, qz, bx, by, bz = self._body_state.Eval(context)[:7].tolist()
            R = _quaternion_rows(qw, qx, qy, qz)
            sx, sy, sz = self._p_BS
            p = [bx + R[0] * sx + R[1] * sy + R[2] * sz,
                 by + R[3] * sx + R[4] * sy + R[5] * sz,
                 bz + R[6] * sx + R[7] * sy + R[8] * sz]
            if x[_SAMPLES] >= 2:
                inv_T2 = self._inv_T2
                a_W = [(p[i] - 2 * x[_P1 + i] + x[_P2 + i]) * inv_T2 - self._g_W[i]
                       for i in range(3)]
                R_WS = x[_R:_R + 9]  # row-major R_WS(t - T): f_S = R_WS^T a_W
                f = [R_WS[j] * a_W[0] + R_WS[3 + j] * a_W[1] + R_WS[6 + j] * a_W[2]
                     for j in range(3)]
            x[_P2:_P2 + 3] = x[_P1:_P1 + 3]
            x[_P1:_P1 + 3] = p
            R_BS = self._R_BS
            x[_R:_R + 9] = [R[3 * i] * R_BS[j] + R[3 * i + 1] * R_BS[3 + j]
                            + R[3 * i + 2] * R_BS[6 + j] for i in range(3) for j in range(3)]
            x[_SAMPLES] += 1
        if f is None:
            f = self._input.Eval(context).tolist()
        noise = self._noise(int(round(context.get_time() * self._rate)))
        lsb, lo, hi, bias = self._lsb, self._lo, self._hi, self._bias
        counts = [min(max(round((f[i] + bias[i] + noise[i]) / lsb), lo), hi)
                  for i in range(3)]
        x[_COUNTS:_COUNTS + 3] = counts
        state[:] = x
        if self.calibration is None:
            return [c * lsb for c in counts]
        offset, scale = self._offset, self._scale
        return [(counts[i] * lsb - offset[i]) / scale[i] for i in range(3)]

    def _calc_counts(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).get_value()[
            _COUNTS:_COUNTS + 3])

    def _calc_acceleration(self, context, output: BasicVector):
        a = context.get_discrete_state(self._state).get_value()[_COUNTS:_COUNTS + 3] * self._lsb
        if self.calibration is not None:
            a = self.calibration.apply(a)
        output.SetFromVector(a)


@lru_cache(maxsize=64)
def _noise_rows(seed: int, block: int, scale: float) -> tuple[list[float], ...]:
    """A block of :func:`~handle_drake.instruments.profiles.sample_noise` as floats (the
    same products), cached: no state of the system changes outside its context."""
    return tuple((_noise_block(seed, block) * scale).tolist())


def _quaternion_rows(w: float, x: float, y: float, z: float) -> list[float]:
    """Row-major rotation matrix (9 floats) of the quaternion ``[w x y z]`` (normalised)."""
    n = (w * w + x * x + y * y + z * z) ** -0.5
    w, x, y, z = w * n, x * n, y * n, z * n
    return [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]


def sensor_pose(kind: str, size: float) -> RigidTransform:
    """``X_OS``: the named sensor frame of an instrumented catalogue object, or the
    object frame itself for any other kind."""
    from handle_drake.instruments.catalogue import DEVICE_OBJECTS

    device = DEVICE_OBJECTS.get(kind)
    if device is None:
        return RigidTransform()
    return RigidTransform(RollPitchYaw(np.radians(device.sensor_rpy_deg)),
                          np.asarray(device.sensor_xyz) * size)


def _in_object(spec, p, tolerance: float) -> bool:
    """True when the point ``p`` (O) is in one of the object's convex pieces (a mesh's
    convex decomposition) or within ``tolerance`` m of it."""
    from handle_drake.objects.queries import _halfspaces, _inside

    p = np.asarray(p, dtype=float).reshape(1, 3)
    return any(_inside(desc, p, tolerance)[0] for desc in _halfspaces(spec))


def default_sensor_pose(spec) -> RigidTransform:
    """``X_OS`` of an accelerometer the scenario places nowhere in particular: the
    object frame itself when its origin is in the object, else (a mug's origin is
    in its cavity, an L bracket's off its arms) the object's surface point
    nearest to the origin (of 4096 seeded surface samples: a sensor glued there),
    axes along O's."""
    return RigidTransform(np.array(_default_sensor_position(spec)))


@lru_cache(maxsize=64)
def _default_sensor_position(spec) -> tuple[float, float, float]:
    """``p_OS`` of :func:`default_sensor_pose`, once per object: scenario validation, the
    station and its recorders all ask (the surface sampling takes tens of ms)."""
    if _in_object(spec, np.zeros(3), 0.0):
        return (0.0, 0.0, 0.0)
    from handle_drake.objects import sample_surface

    points, _ = sample_surface(spec, 4096, rng=0)
    return tuple(float(v) for v in points[np.argmin(np.linalg.norm(points, axis=1))])


def check_sensor_pose(spec, X_OS: RigidTransform, tolerance: float = 0.002) -> None:
    """Raises ValueError when the sensor origin is not in or on the object (within
    ``tolerance`` m of its surface: a sensor may be glued on)."""
    p = np.asarray(X_OS.translation(), dtype=float).reshape(1, 3)
    if not np.all(np.isfinite(p)):
        raise ValueError(f"X_OS: sensor position must be finite, got {p.ravel().tolist()}")
    if not _in_object(spec, p, tolerance):
        raise ValueError(
            f"X_OS: the sensor at {np.round(p.ravel(), 4).tolist()} m (object frame) is off "
            f"the {spec.kind} (expected inside it or within {tolerance * 1e3:.0f} mm of its "
            "surface)")


def AddObjectAccelerometer(builder, plant, body, X_BS: RigidTransform,
                           profile: DeviceProfile | str, seed: int = 0,
                           name: str = "object_accelerometer", averaging: bool = True,
                           estimators: EstimatorParams | None = None, command=None,
                           calibration=None):
    """Adds Drake's ``Accelerometer`` on ``body`` at ``X_BS`` (with the plant's
    gravity) and a :class:`DeviceAccelerometer` behind it (averaging over its
    period by default); returns the device system (outputs ``counts``,
    ``acceleration``). The ideal sensor is named ``<name>_ideal``.

    With ``estimators`` the device also carries the roll/pitch, free-fall and slip
    estimators, updated in its own update at each sample (their outputs are the
    device's; :func:`ExportInstrumentPorts` exports them); ``command`` is the
    output port whose stillness enables the slip detector (the hand and wrist
    command); without it the slip output is a constant 0 (nothing tells whether
    the hand moves). ``calibration``: the device's (see :class:`DeviceAccelerometer`)."""
    ideal = builder.AddNamedSystem(
        f"{name}_ideal",
        Accelerometer(body, X_BS, plant.gravity_field().gravity_vector()))
    builder.Connect(plant.get_body_poses_output_port(), ideal.get_body_poses_input_port())
    builder.Connect(plant.get_body_spatial_velocities_output_port(),
                    ideal.get_body_velocities_input_port())
    builder.Connect(plant.get_body_spatial_accelerations_output_port(),
                    ideal.get_body_accelerations_input_port())
    gravity = plant.gravity_field().gravity_vector()
    instance = body.model_instance()
    # Averaging reads the body's free state: only for a floating body alone in its
    # model instance (a welded one does not move and reads Drake's sensor exactly).
    averaging = bool(averaging and body.is_floating_base_body()
                     and plant.num_multibody_states(instance) == 13)
    if estimators is None and command is not None:
        raise ValueError("command: the slip detector's command needs estimators")
    device = builder.AddNamedSystem(name, DeviceAccelerometer(
        profile, seed, averaging=averaging, X_BS=X_BS, gravity_W=gravity,
        estimators=estimators, command_size=None if command is None else command.size(),
        calibration=calibration))
    builder.Connect(ideal.get_measurement_output_port(), device.GetInputPort("specific_force"))
    if averaging:
        builder.Connect(plant.get_state_output_port(instance), device.GetInputPort("body_state"))
    if command is not None:
        builder.Connect(command, device.GetInputPort("command"))
    return device


def ExportInstrumentPorts(builder, device, prefix: str = "object") -> None:
    """Exports the instrument ports ``<prefix>.<signal>`` (module doc) of a device
    system that carries the estimators (a :class:`DeviceAccelerometer` or an
    :class:`~handle_drake.instruments.evdev_driver.EvdevAccelerometer` made with
    ``estimators``)."""
    if getattr(device, "estimators", None) is None:
        raise ValueError(f"{device.get_name()}: the device carries no estimators "
                         "(make it with estimators=EstimatorParams())")
    for signal in INSTRUMENT_SIGNALS:
        port = "counts" if signal == "acceleration_counts" else signal
        builder.ExportOutput(device.GetOutputPort(port), f"{prefix}.{signal}")
