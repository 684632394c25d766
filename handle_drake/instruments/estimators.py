"""What an object's own accelerometer tells about it (report section 2.4).

An accelerometer measures the specific force ``f_S = R_SW (a_WS - g_W)``
(proper acceleration, m/s^2, in its frame S): at rest ``f_S`` is gravity's
reaction, ``+g0`` along world up, in free fall it is zero. Three estimators,
each a plain function of samples first and a LeafSystem sampling the
accelerometer output at the device rate:

* **roll and pitch** (:func:`roll_pitch`): with ``R_WS = Rz(yaw) Ry(pitch)
  Rx(roll)`` (Drake's ``RollPitchYaw``), ``f_S = g0 [-sin p, cos p sin r,
  cos p cos r]``, so ``roll = atan2(f_y, f_z)`` and ``pitch = atan2(-f_x,
  hypot(f_y, f_z))``; yaw is not observable. Valid at rest only, which
  :func:`at_rest` flags over the last ``rest_window`` s: the mean magnitude is
  within ``rest_norm_tol`` of 1 g, no axis has a standard deviation above
  ``rest_std_tol`` (vibration), and the mean of the window's second half points
  within ``rest_angle_tol`` of its first half's (no rotation). The angles are
  those of the mean over the last ``window`` s (a moving average: less noise
  at rest, a lag of half a window while moving).
* **free fall** (:func:`free_fall`): the magnitude stays below ``threshold``
  (default 0.3 g) for ``free_fall_duration`` (default 24 ms, three JoyWarrior
  samples); the report: "a falling object is easily detected, because the
  total measured acceleration is zero in this case".
* **slip** (:func:`slip_indicator`), the method stated: while the hand's
  command is still, a held object is static. After the command has been still
  for ``settle_time``, the window's mean specific force is the reference; slip
  is flagged when, for ``slip_duration``, the mean over the last ``window`` s
  (vibration of a held object averages out) is off: (a) its magnitude departs
  from 1 g by
  more than ``norm_tol`` (a static object feels exactly 1 g; one sliding on an
  incline of angle alpha with friction mu feels only the contact force,
  ``g0 cos(alpha) sqrt(1 + mu^2)``), or (b) its direction turns away from the
  reference by more than ``angle_tol`` (the object rotates in the grasp). While
  the command moves, the detector is idle (0) and forgets its reference.

Thresholds are parameters (:class:`EstimatorParams`) with the defaults above.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from handle_drake.instruments.profiles import STANDARD_GRAVITY

__all__ = [
    "EstimatorParams",
    "roll_pitch",
    "true_roll_pitch",
    "angle_difference",
    "at_rest",
    "free_fall",
    "slip_indicator",
    "RollPitchEstimator",
    "FreeFallDetector",
    "SlipDetector",
]

G0 = STANDARD_GRAVITY


@dc.dataclass(frozen=True)
class EstimatorParams:
    """Thresholds of the estimators (g = 9.80665 m/s^2).

    window: s, moving average of roll/pitch and slip (default 40 ms: 5 JoyWarrior samples).
    rest_window: s, the at-rest test's window (default 160 ms: 20 samples).
    rest_norm_tol: g, at rest when the mean magnitude is within this of 1 g ...
    rest_std_tol: g, ... no axis has a standard deviation above this ...
    rest_angle_tol: rad, ... and the means of the window's halves differ by less.
    free_fall_threshold: g, free fall when the magnitude is below this ...
    free_fall_duration: s, ... for this long.
    slip_norm_tol: g, slip when the magnitude departs from 1 g by more than this ...
    slip_angle_tol: rad, ... or the direction turns more than this from the reference ...
    slip_duration: s, ... for this long, while the command is still.
    still_tol: command units (rad, m), the command is still when no entry changes
        by more than this between two samples ...
    settle_time: s, ... and the reference is taken after it has been still this long
        (300 ms: the floating wrist's PD loop still turns the hand ~0.1 s after its command stops).
    """

    window: float = 0.04
    rest_window: float = 0.16
    rest_norm_tol: float = 0.05
    rest_std_tol: float = 0.1
    rest_angle_tol: float = math.radians(2.0)
    free_fall_threshold: float = 0.3
    free_fall_duration: float = 0.024
    slip_norm_tol: float = 0.08
    slip_angle_tol: float = math.radians(3.0)
    slip_duration: float = 0.04
    still_tol: float = 1e-4
    settle_time: float = 0.3

    def __post_init__(self):
        for field in dc.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"estimators.{field.name} must be a finite number > 0, "
                                 f"got {value!r}")
            object.__setattr__(self, field.name, float(value))

    def samples(self, duration: float, period: float) -> int:
        """``duration`` in whole samples of ``period`` (at least 1)."""
        return max(1, int(math.ceil(duration / period - 1e-9)))


def _as_samples(f) -> np.ndarray:
    f = np.asarray(f, dtype=float)
    if f.shape[-1:] != (3,):
        raise ValueError(f"acceleration: expected shape (..., 3), got {f.shape}")
    return f


def roll_pitch(f_S) -> np.ndarray:
    """``[roll, pitch]`` (rad) from the specific force ``f_S`` (..., 3) of a body at
    rest (see the module doc); shape (..., 2)."""
    f = _as_samples(f_S)
    roll = np.arctan2(f[..., 1], f[..., 2])
    pitch = np.arctan2(-f[..., 0], np.hypot(f[..., 1], f[..., 2]))
    return np.stack([roll, pitch], axis=-1)


def true_roll_pitch(R_WS) -> np.ndarray:
    """``[roll, pitch]`` (rad) of a sensor orientation (``RotationMatrix`` or 3x3):
    the angles :func:`roll_pitch` estimates (Drake's ``RollPitchYaw``)."""
    from pydrake.math import RollPitchYaw, RotationMatrix

    R = R_WS if isinstance(R_WS, RotationMatrix) else RotationMatrix(np.asarray(R_WS))
    rpy = RollPitchYaw(R)
    return np.array([rpy.roll_angle(), rpy.pitch_angle()])


def angle_difference(a, b) -> np.ndarray:
    """``a - b`` wrapped to [-pi, pi)."""
    return (np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi


def at_rest(window_f, norm_tol: float = 0.05, std_tol: float = 0.1,
            angle_tol: float = math.radians(2.0), g: float = G0) -> bool:
    """True when the samples ``window_f`` (N >= 2, 3; m/s^2) look like a body at rest:
    the mean magnitude is within ``norm_tol`` g of 1 g, no axis has a standard
    deviation above ``std_tol`` g, and the means of the first and second half
    point within ``angle_tol`` rad of each other."""
    f = _as_samples(window_f).reshape(-1, 3)
    if len(f) < 2:
        return False
    mean_norm = np.linalg.norm(f.mean(axis=0))
    half = len(f) // 2
    a, b = f[:half].mean(axis=0), f[half:].mean(axis=0)
    cos = a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12)
    return bool(abs(mean_norm - g) <= norm_tol * g
                and np.max(f.std(axis=0)) <= std_tol * g
                and math.acos(min(1.0, max(-1.0, cos))) <= angle_tol)


def free_fall(f, threshold: float = 0.3, min_samples: int = 3, g: float = G0) -> np.ndarray:
    """Per sample of ``f`` (T, 3): True once the magnitude has been below
    ``threshold`` g for the last ``min_samples`` samples."""
    f = _as_samples(f).reshape(-1, 3)
    low = np.linalg.norm(f, axis=1) < threshold * g
    run = np.zeros(len(low), dtype=int)
    count = 0
    for i, is_low in enumerate(low):
        count = count + 1 if is_low else 0
        run[i] = count
    return run >= min_samples


def slip_indicator(f, f_ref, norm_tol: float = 0.08, angle_tol: float = math.radians(3.0),
                   g: float = G0) -> np.ndarray:
    """Per sample of ``f`` (..., 3): True when it is not what a static object feels
    (magnitude off 1 g by more than ``norm_tol`` g) or its direction has turned
    more than ``angle_tol`` rad from the reference ``f_ref`` (3,)."""
    f = _as_samples(f)
    f_ref = _as_samples(f_ref)
    norm = np.linalg.norm(f, axis=-1)
    ref = f_ref / max(np.linalg.norm(f_ref), 1e-12)
    cos = np.clip((f @ ref) / np.maximum(norm, 1e-12), -1.0, 1.0)
    return (np.abs(norm - g) > norm_tol * g) | (np.arccos(cos) > angle_tol)


# ----------------------------------------------------------------------- systems


def _check_period(period) -> float:
    if isinstance(period, bool) or not isinstance(period, int | float | np.number) \
            or not math.isfinite(period) or period <= 0:
        raise ValueError(f"period must be a finite number > 0 (s), got {period!r}")
    return float(period)


class _Sampled(LeafSystem):
    """Samples the 3-vector input ``acceleration`` every ``period`` s, ``offset`` s
    after the device's own sample instants (so it reads the fresh sample, not the
    previous one), into a ring of ``n`` samples kept in the discrete state."""

    #: s after the device's sample instant (the device updates at k * period).
    OFFSET = 1e-4

    def __init__(self, period: float, n: int, extra):
        super().__init__()
        self._period = _check_period(period)
        self._n = int(n)
        extra = np.asarray(extra, dtype=float).ravel()
        self._input = self.DeclareVectorInputPort("acceleration", 3)
        # [ring (n x 3), number of samples taken, extra state ...]
        self._state = self.DeclareDiscreteState(np.r_[np.zeros(3 * self._n + 1), extra])
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, self.OFFSET, self._update)

    def _recent(self, x: np.ndarray, k: int) -> np.ndarray:
        """The last ``min(k, taken)`` samples, oldest first."""
        taken = int(x[3 * self._n])
        k = min(k, taken, self._n)
        ring = x[: 3 * self._n].reshape(self._n, 3)
        return ring[(taken - k + np.arange(k)) % self._n]

    def _update(self, context, discrete_state):
        x = context.get_discrete_state(self._state).get_value().copy()
        f = self._input.Eval(context)
        taken = int(x[3 * self._n])
        ring = x[: 3 * self._n].reshape(self._n, 3)
        ring[taken % self._n] = f
        x[3 * self._n] = taken + 1
        self._step(context, x, f)
        discrete_state.get_mutable_vector(self._state).SetFromVector(x)

    def _step(self, context, x: np.ndarray, f: np.ndarray) -> None:
        """Updates the extra state ``x[3n+1:]`` in place."""

    def _extra_state(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).get_value()[3 * self._n + 1:]


class RollPitchEstimator(_Sampled):
    """Roll and pitch of the sensor frame from its accelerometer (valid at rest).

    Input ``acceleration`` (3, m/s^2, sensor frame). Outputs ``roll_pitch`` (2,
    rad, of the mean over ``window``; zeros before the first sample) and
    ``at_rest`` (1: 1.0 when :func:`at_rest` holds over a full ``rest_window``).
    """

    def __init__(self, period: float, params: EstimatorParams | None = None):
        self.params = params or EstimatorParams()
        period = _check_period(period)
        self._n_mean = self.params.samples(self.params.window, period)
        n = max(self._n_mean, self.params.samples(self.params.rest_window, period), 2)
        super().__init__(period, n, [])
        self.DeclareVectorOutputPort("roll_pitch", 2, self._calc_roll_pitch,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("at_rest", 1, self._calc_at_rest,
                                     {self.discrete_state_ticket(self._state)})

    def _calc_roll_pitch(self, context, output: BasicVector):
        recent = self._recent(context.get_discrete_state(self._state).get_value(), self._n_mean)
        output.SetFromVector(roll_pitch(recent.mean(axis=0)) if len(recent) else np.zeros(2))

    def _calc_at_rest(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state).get_value()
        p = self.params
        rest = int(x[3 * self._n]) >= self._n and at_rest(
            self._recent(x, self._n), p.rest_norm_tol, p.rest_std_tol, p.rest_angle_tol)
        output.SetFromVector([1.0 if rest else 0.0])


class FreeFallDetector(_Sampled):
    """Free fall: input ``acceleration`` (3, m/s^2); output ``free_fall`` (1: 1.0 once
    the magnitude has stayed below ``free_fall_threshold`` g for
    ``free_fall_duration`` s) and ``detection_time`` (1: s, when the present free
    fall was flagged, NaN when not in free fall)."""

    def __init__(self, period: float, params: EstimatorParams | None = None):
        self.params = params or EstimatorParams()
        period = _check_period(period)
        self._need = self.params.samples(self.params.free_fall_duration, period)
        # extra state: [consecutive low samples, detection time]
        super().__init__(period, 1, [0.0, np.nan])
        self.DeclareVectorOutputPort("free_fall", 1, self._calc_free_fall,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("detection_time", 1, self._calc_time,
                                     {self.discrete_state_ticket(self._state)})

    def _step(self, context, x, f):
        extra = x[3 * self._n + 1:]
        low = np.linalg.norm(f) < self.params.free_fall_threshold * G0
        extra[0] = extra[0] + 1 if low else 0
        if extra[0] == self._need:
            extra[1] = context.get_time()
        elif extra[0] < self._need:
            extra[1] = np.nan

    def _calc_free_fall(self, context, output: BasicVector):
        output.SetFromVector([1.0 if self._extra_state(context)[0] >= self._need else 0.0])

    def _calc_time(self, context, output: BasicVector):
        output.SetFromVector([self._extra_state(context)[1]])


class SlipDetector(_Sampled):
    """Slip of a held object (method in the module doc).

    Inputs: ``acceleration`` (3, m/s^2) and ``command`` (``command_size``: what
    moves the hand, e.g. the hand's joint command and the wrist pose; the
    detector runs only while it is still). Output ``slip`` (1: 1.0 while slip
    is detected).
    """

    def __init__(self, period: float, command_size: int, params: EstimatorParams | None = None):
        self.params = params or EstimatorParams()
        period = _check_period(period)
        if isinstance(command_size, bool) or not isinstance(command_size, int | np.integer) \
                or command_size < 1:
            raise ValueError(f"command_size must be an int >= 1, got {command_size!r}")
        self._m = int(command_size)
        self._settle = self.params.samples(self.params.settle_time, period)
        self._need = self.params.samples(self.params.slip_duration, period)
        # extra state: [still samples, samples flagged, reference (3), previous command (m),
        #               have previous command]
        super().__init__(period, self.params.samples(self.params.window, period),
                         np.zeros(2 + 3 + self._m + 1))
        self._command = self.DeclareVectorInputPort("command", self._m)
        self.DeclareVectorOutputPort("slip", 1, self._calc_slip,
                                     {self.discrete_state_ticket(self._state)})

    def _step(self, context, x, f):
        p = self.params
        extra = x[3 * self._n + 1:]
        command = self._command.Eval(context)
        previous = extra[5:5 + self._m]
        still = extra[-1] > 0 and np.max(np.abs(command - previous)) <= p.still_tol
        previous[:] = command
        extra[-1] = 1.0
        if not still:
            extra[0] = extra[1] = 0.0
            extra[2:5] = 0.0
            return
        extra[0] += 1
        if extra[0] < self._settle:
            return
        mean = self._recent(x, self._n).mean(axis=0)
        if extra[0] == self._settle:
            extra[2:5] = mean
        flagged = slip_indicator(mean, extra[2:5], p.slip_norm_tol, p.slip_angle_tol)
        extra[1] = extra[1] + 1 if flagged else 0.0

    def _calc_slip(self, context, output: BasicVector):
        output.SetFromVector([1.0 if self._extra_state(context)[1] >= self._need else 0.0])
