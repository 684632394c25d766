"""Accelerometer calibration: the six-position method, and thresholds that follow the device.

Report section 2.4.3 recommends "a quick calibration of the device": a consumer
accelerometer's zero-g offset (30 mg per axis for a Wiimote, Nunchuk or
Sixaxis, :mod:`~handle_drake.instruments.profiles`) tilts the at-rest roll and
pitch by degrees and moves the at-rest magnitude off 1 g by as much as the
at-rest and slip tests allow.

**Six-position method** (the standard static calibration of a three-axis
accelerometer): the device rests in six orientations, each axis in turn
pointing up and down; at rest it reads ``m = s * f + b`` per axis, with the
specific force ``f = g0 u`` (``u``: the world's up in the sensor frame, one of
``+-e_x, +-e_y, +-e_z``). Per axis ``k`` the six mean readings give the
least-squares fit of the gain ``s_k`` and offset ``b_k`` of ``m_ik = s_k g0
u_ik + b_k`` (:func:`six_position_calibration`): with the six positions,
``s_k g0 = (m_{+k} - m_{-k}) / 2`` and ``b_k`` the mean of the axis's six
readings. The calibrated reading is ``(m - b) / s``.

In simulation the calibration is made as on the bench, from the device's own
rest readings (:func:`device_rest_readings`: the profile's bias, its noise from
a stream independent of the run's, quantisation and saturation, over
``samples`` readings per position), so it leaves what a real calibration leaves:
each mean reading is off by at most half a count (the rounding, when the noise
is too small to dither it) plus the noise's mean (:func:`residual_bias`).

**Thresholds** (:func:`device_estimator_params`): the at-rest and slip
tolerances on the magnitude (``rest_norm_tol``, ``slip_norm_tol``) and on the
direction (``rest_angle_tol``, ``slip_angle_tol``) are at least what the
device's own errors can reach at rest, so that a resting device is always at
rest and never flags slip: the magnitude can be off by the bias left (the
calibration's residual, or without calibration the drawn bias itself, its
length taken at 4.5 standard deviations), half a count of rounding per axis, and 4 standard
deviations of the noise's window mean; a direction by a count per axis between
two window means plus their noise. Each floor has a 1.5 safety factor; the
defaults of :class:`~handle_drake.instruments.estimators.EstimatorParams` stay
where they are already wider (docs/results/accelerometer_calibration.md gives
the numbers per profile). A value the scenario sets in ``estimators`` is kept
as given.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

from handle_drake.instruments.profiles import (
    STANDARD_GRAVITY,
    DeviceProfile,
    device_bias,
    get_profile,
    to_counts,
)

__all__ = [
    "SIX_POSITIONS",
    "AccelerometerCalibration",
    "six_position_calibration",
    "device_rest_readings",
    "calibrate_device",
    "residual_bias",
    "device_estimator_params",
    "CALIBRATION_SAMPLES",
]

G0 = STANDARD_GRAVITY

#: The six rest positions: the world's up in the sensor frame (+x, -x, +y, -y, +z, -z up).
SIX_POSITIONS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                         dtype=float)

#: Readings averaged per position (1 s at 100 Hz).
CALIBRATION_SAMPLES = 100

#: Safety factor on the threshold floors.
SAFETY = 1.5


@dc.dataclass(frozen=True)
class AccelerometerCalibration:
    """Per axis: the reading is ``scale * f + offset`` (m/s^2); :meth:`apply` inverts it."""

    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self):
        offset = np.asarray(self.offset, dtype=float).ravel()
        scale = np.asarray(self.scale, dtype=float).ravel()
        if offset.shape != (3,) or not np.all(np.isfinite(offset)):
            raise ValueError(f"calibration offset: expected 3 finite values, got {self.offset!r}")
        if scale.shape != (3,) or not np.all(np.isfinite(scale)) or np.any(scale <= 0):
            raise ValueError(f"calibration scale: expected 3 finite values > 0, got "
                             f"{self.scale!r}")
        object.__setattr__(self, "offset", tuple(float(v) for v in offset))
        object.__setattr__(self, "scale", tuple(float(v) for v in scale))

    def apply(self, reading) -> np.ndarray:
        """The calibrated specific force (m/s^2) of raw readings (..., 3), m/s^2."""
        return (np.asarray(reading, dtype=float) - self.offset) / self.scale


def six_position_calibration(mean_readings, positions=SIX_POSITIONS,
                             g: float = G0) -> AccelerometerCalibration:
    """The least-squares gain and offset per axis from mean rest readings (N, 3; m/s^2)
    at the ``positions`` (N, 3: the world's up in the sensor frame, unit vectors;
    default the six of :data:`SIX_POSITIONS`). Each axis needs positions where it
    reads +g and -g (or two different levels)."""
    m = np.asarray(mean_readings, dtype=float)
    u = np.asarray(positions, dtype=float)
    if m.ndim != 2 or m.shape[1] != 3 or u.shape != m.shape:
        raise ValueError(f"mean_readings: expected ({len(u)}, 3) readings, one per position, "
                         f"got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("mean_readings: expected finite values")
    offset, scale = np.zeros(3), np.ones(3)
    for k in range(3):
        A = np.column_stack([g * u[:, k], np.ones(len(u))])
        if np.linalg.matrix_rank(A) < 2:
            raise ValueError(f"positions: axis {'xyz'[k]} never changes its reading "
                             "(give positions with it up and down)")
        (s, b), *_ = np.linalg.lstsq(A, m[:, k], rcond=None)
        if not s > 0:
            raise ValueError(f"mean_readings: axis {'xyz'[k]} reads less up than down "
                             f"(gain {s:.3g}): check the positions' order")
        offset[k], scale[k] = b, s
    return AccelerometerCalibration(tuple(offset), tuple(scale))


def device_rest_readings(profile: DeviceProfile | str, seed: int = 0,
                         samples: int = CALIBRATION_SAMPLES,
                         positions=SIX_POSITIONS) -> np.ndarray:
    """Mean readings (N, 3; m/s^2 = counts * lsb) of the simulated device resting in
    each of ``positions``: its bias (drawn with ``seed``, as the run's), noise from a
    stream of its own (``(seed, 2, position)``: not the run's samples), quantised
    and saturated, ``samples`` readings per position."""
    profile = get_profile(profile)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        raise ValueError(f"samples: expected an int >= 1, got {samples!r}")
    bias = device_bias(profile, seed)
    sigma = profile.noise_std_g * G0
    out = []
    for i, up in enumerate(np.asarray(positions, dtype=float)):
        noise = np.random.default_rng((int(seed), 2, i)).standard_normal((samples, 3)) * sigma
        counts = to_counts(G0 * up + bias + noise, profile)
        out.append(counts.mean(axis=0) * profile.lsb)
    return np.array(out)


def calibrate_device(profile: DeviceProfile | str, seed: int = 0,
                     samples: int = CALIBRATION_SAMPLES) -> AccelerometerCalibration:
    """The six-position calibration of the simulated device ``(profile, seed)`` from
    its own rest readings (:func:`device_rest_readings`)."""
    return six_position_calibration(device_rest_readings(profile, seed, samples))


def residual_bias(profile: DeviceProfile | str, calibrated: bool,
                  samples: int = CALIBRATION_SAMPLES) -> float:
    """A bound (g) on the length of the bias vector a device's readings keep:
    calibrated, half a count (the rounding of the calibration's mean readings) plus
    4 standard deviations of their noise's mean, per axis; uncalibrated, its bias
    (``|bias_g|``, or 4.5 ``bias_std_g``: the length of a drawn bias exceeds it
    with probability 3e-4)."""
    profile = get_profile(profile)
    lsb_g = profile.lsb / G0
    if calibrated:
        return math.sqrt(3) * (0.5 * lsb_g + 4 * profile.noise_std_g / math.sqrt(samples))
    if profile.bias_g is not None:
        return float(np.linalg.norm(profile.bias_g))
    return 4.5 * profile.bias_std_g


def device_floors(profile: DeviceProfile | str, calibrated: bool, params=None) -> dict:
    """The smallest tolerances (g, rad) the device's own errors allow (module doc):
    ``rest_norm_tol``, ``slip_norm_tol``, ``rest_angle_tol``, ``slip_angle_tol``."""
    from handle_drake.instruments.estimators import EstimatorParams

    profile = get_profile(profile)
    p = params or EstimatorParams()
    lsb_g = profile.lsb / G0
    bias = residual_bias(profile, calibrated)
    noise = profile.noise_std_g

    def mean_noise(window: float) -> float:
        return noise / math.sqrt(p.samples(window, profile.period))

    # |mean| - 1 g: the bias left, half a count per axis (a vector of 3), and noise.
    def norm_floor(window: float) -> float:
        return bias + math.sqrt(3) * 0.5 * lsb_g + 4 * mean_noise(window)

    # The angle between two window means of one resting reading: a count per axis
    # and the difference of two means' noise (the bias is common to both).
    def angle_floor(window: float) -> float:
        return math.sqrt(3) * lsb_g + 4 * math.sqrt(2) * mean_noise(window)

    return {"rest_norm_tol": SAFETY * norm_floor(p.rest_window),
            "slip_norm_tol": SAFETY * norm_floor(p.window),
            "rest_angle_tol": SAFETY * angle_floor(p.rest_window / 2),
            "slip_angle_tol": SAFETY * angle_floor(p.window)}


def device_estimator_params(profile: DeviceProfile | str, calibrated: bool,
                            given: dict | None = None):
    """:class:`~handle_drake.instruments.estimators.EstimatorParams` for the device: the
    ``given`` values (the scenario's ``estimators``) as they are, the others at least
    the device's floors (:func:`device_floors`)."""
    from handle_drake.instruments.estimators import EstimatorParams

    given = dict(given or {})
    base = EstimatorParams(**given)
    changes = {name: max(getattr(base, name), floor)
               for name, floor in device_floors(profile, calibrated, base).items()
               if name not in given}
    return dc.replace(base, **changes)
