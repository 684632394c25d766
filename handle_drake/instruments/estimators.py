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
  for ``settle_time``, the reference is taken at the first sample where the
  object is at rest (the :func:`at_rest` test over the last ``rest_window``
  s): the window's mean specific force. Until then every sample counts as
  slipping (the hand is still and settled, so an object that is not at rest
  moves in the grasp: a slide already under way when the hand stops, whose
  steady specific force would otherwise become the reference). With a
  reference, slip is flagged when, for ``slip_duration``, the mean over the
  last ``window`` s (vibration of a held object averages out) is off: (a) its
  magnitude departs from 1 g by more than ``norm_tol`` (a static object feels
  exactly 1 g; one sliding on an incline of angle alpha with friction mu feels
  only the contact force, ``g0 cos(alpha) sqrt(1 + mu^2)``), or (b) its
  direction turns away from the reference by more than ``angle_tol`` (the
  object rotates in the grasp, or starts to slide down a slope: the contact
  force tilts by atan(mu) from the slope's normal). While the command moves,
  the detector is idle (0) and forgets its reference.

Thresholds are parameters (:class:`EstimatorParams`) with the defaults above.

In the station the estimators run inside the device's own update
(:class:`InstrumentSystem`: the simulated
:class:`~handle_drake.instruments.accelerometer.DeviceAccelerometer` and the
evdev driver of a real device): one periodic event per device sample updates
the reading and all three estimators (:class:`InstrumentEstimators`, on plain
floats). :class:`RollPitchEstimator`, :class:`FreeFallDetector` and
:class:`SlipDetector` are the same estimators as separate systems behind any
acceleration signal, each sampling it :attr:`_Sampled.OFFSET` s after the
device; they are the reference the fused update is tested against, output for
output and sample for sample (``tests/instruments/test_instrument_fused.py``).
"""

from __future__ import annotations

import dataclasses as dc
import math
import operator

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
    "InstrumentEstimators",
    "InstrumentSystem",
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
        p = self.params
        self._n_mean = p.samples(p.window, period)
        self._n_rest = max(self._n_mean, p.samples(p.rest_window, period), 2)
        # extra state: [still samples, samples flagged, reference (3; NaN: none yet),
        #               previous command (m), have previous command]
        super().__init__(period, self._n_rest,
                         np.r_[0.0, 0.0, np.full(3, np.nan), np.zeros(self._m + 1)])
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
            extra[2:5] = np.nan
            return
        extra[0] += 1
        if extra[0] < self._settle:
            return
        mean = self._recent(x, self._n_mean).mean(axis=0)
        if np.isnan(extra[2]):  # no reference yet: one at rest, or this sample slips
            if int(x[3 * self._n]) >= self._n_rest and at_rest(
                    self._recent(x, self._n_rest), p.rest_norm_tol, p.rest_std_tol,
                    p.rest_angle_tol):
                extra[2:5] = mean
            else:
                extra[1] += 1
                return
        flagged = slip_indicator(mean, extra[2:5], p.slip_norm_tol, p.slip_angle_tol)
        extra[1] = extra[1] + 1 if flagged else 0.0

    def _calc_slip(self, context, output: BasicVector):
        output.SetFromVector([1.0 if self._extra_state(context)[1] >= self._need else 0.0])


# ------------------------------------------------------------ fused, one update


class InstrumentEstimators:
    """:class:`RollPitchEstimator`, :class:`FreeFallDetector` and (with a
    ``command_size``) :class:`SlipDetector` as one update of one state vector,
    for a device system to run in its own periodic update (not a System:
    :class:`InstrumentSystem` holds it). The state is the separate systems'
    state in one vector: one ring of the last samples (as many as the longest
    window needs), then ``[samples taken, low samples, free-fall detection time]``
    and, with a command, ``[still samples, samples flagged, reference (3; NaN
    until taken), previous command (m), have previous command]``.

    :meth:`step` works on plain Python floats (tiny numpy arrays cost more per
    operation than the arithmetic) and writes only the new sample's ring slot
    and the tail. Where its float arithmetic could differ from the separate
    systems' numpy arithmetic in the last bits (a magnitude against the
    free-fall threshold, the slip test's magnitude and angle against their
    tolerances), a value within :attr:`BAND` of its threshold is decided by the
    separate systems' own expressions (``np.linalg.norm``,
    :func:`slip_indicator`), so every decision is theirs exactly. The outputs
    are computed as the separate systems compute them (:func:`roll_pitch`,
    :func:`at_rest` of the same samples).
    """

    #: Relative half-width of the band around a threshold where the numpy expression
    #: decides (the float and numpy values differ by a few ulps, far less than this).
    BAND = 1e-9

    def __init__(self, period: float, params: EstimatorParams | None = None,
                 command_size: int | None = None):
        self.params = p = params or EstimatorParams()
        self.period = period = _check_period(period)
        if command_size is not None and (
                isinstance(command_size, bool) or not isinstance(command_size, int | np.integer)
                or command_size < 1):
            raise ValueError(f"command_size must be an int >= 1, got {command_size!r}")
        self.command_size = 0 if command_size is None else int(command_size)
        # The separate systems' windows (samples): RollPitchEstimator's mean and ring
        # (its at-rest window), SlipDetector's ring (its mean).
        self._n_mean = p.samples(p.window, period)  # also SlipDetector's mean
        self._n_rest = max(self._n_mean, p.samples(p.rest_window, period), 2)
        self._n = self._n_rest  # the ring: the longest window
        self._fall_need = p.samples(p.free_fall_duration, period)
        self._settle = p.samples(p.settle_time, period)
        self._slip_need = p.samples(p.slip_duration, period)
        self._fall_threshold = p.free_fall_threshold * G0
        self._norm_tol = p.slip_norm_tol * G0
        # arccos(c) > angle_tol  <=>  c < cos(angle_tol) (never when angle_tol >= pi).
        self._cos_tol = math.cos(p.slip_angle_tol) if p.slip_angle_tol < math.pi else -math.inf
        self._tail = 3 * self._n
        m = self.command_size
        self._initial_tail = [0.0, 0.0, math.nan] + (
            [0.0, 0.0] + [math.nan] * 3 + [0.0] * (m + 1) if m else [])
        self._tail_end = self._tail + len(self._initial_tail)

    def initial_state(self) -> list[float]:
        return [0.0] * self._tail + self._initial_tail

    @property
    def size(self) -> int:
        return self._tail_end

    def step(self, x: np.ndarray, offset: int, t: float, f: list[float], command=None) -> None:
        """Takes the sample ``f`` (3 floats, m/s^2) at time ``t``: updates the
        estimators' state ``x[offset:offset + size]`` in place (``x``: the update's
        writable discrete state). ``command``: the command's values (a list), when
        the estimators have one."""
        fx, fy, fz = f
        n3, end = offset + self._tail, offset + self._tail_end
        tail = x[n3:end].tolist()
        taken = int(tail[0])
        slot = offset + 3 * (taken % self._n)
        x[slot:slot + 3] = f
        taken += 1
        tail[0] = taken
        # FreeFallDetector._step
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        threshold = self._fall_threshold
        if abs(norm - threshold) > self.BAND * threshold:
            low = norm < threshold
        else:  # at the threshold (or not finite): FreeFallDetector's own expression
            low = bool(np.linalg.norm(np.array(f, dtype=float)) < threshold)
        tail[1] = tail[1] + 1 if low else 0
        if tail[1] == self._fall_need:
            tail[2] = t
        elif tail[1] < self._fall_need:
            tail[2] = math.nan
        if self.command_size:
            self._slip_step(x, offset, tail, taken, command)
        x[n3:end] = tail

    def _slip_step(self, x, offset, tail, taken, command) -> None:
        """SlipDetector._step on ``tail`` (the state after the ring, as floats)."""
        m = self.command_size
        tol = self.params.still_tol
        # max |command - previous| <= tol, as each entry's (a NaN is not still)
        still = tail[-1] > 0 and all(map(tol.__ge__, map(abs, map(operator.sub, command,
                                                                   tail[8:8 + m]))))
        tail[8:8 + m] = command
        tail[-1] = 1.0
        if not still:
            tail[3:8] = [0.0, 0.0, math.nan, math.nan, math.nan]
            return
        tail[3] += 1
        if tail[3] < self._settle:
            return
        if math.isnan(tail[5]):  # no reference yet: one at rest (as numpy does it), or slip
            p = self.params
            if taken >= self._n_rest and at_rest(
                    self._recent(x, offset, self._n_rest, taken), p.rest_norm_tol,
                    p.rest_std_tol, p.rest_angle_tol):
                tail[5:8] = self._recent(x, offset, self._n_mean, taken).mean(axis=0).tolist()
            else:
                tail[4] += 1
                return
        # The mean of the last samples, in order (the ring slots, oldest first).
        n, k = self._n, min(self._n_mean, taken, self._n)
        first = (taken - k) % n
        if first + k <= n:
            window = x[offset + 3 * first:offset + 3 * (first + k)].tolist()
        else:
            window = (x[offset + 3 * first:offset + 3 * n].tolist()
                      + x[offset:offset + 3 * (first + k - n)].tolist())
        mx, my, mz = sum(window[0::3]) / k, sum(window[1::3]) / k, sum(window[2::3]) / k
        rx, ry, rz = tail[5:8]
        r_norm = max(math.sqrt(rx * rx + ry * ry + rz * rz), 1e-12)
        rx, ry, rz = rx / r_norm, ry / r_norm, rz / r_norm
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        cos = (mx * rx + my * ry + mz * rz) / max(norm, 1e-12)
        off = abs(norm - G0)
        band = self.BAND
        if (abs(off - self._norm_tol) > band * G0 and abs(cos - self._cos_tol) > band
                and math.isfinite(norm) and math.isfinite(r_norm)):
            flagged = off > self._norm_tol or cos < self._cos_tol
        else:  # near a threshold (or not finite): SlipDetector's own expression
            p = self.params
            flagged = bool(slip_indicator(self._recent(x, offset, self._n_mean, taken)
                                          .mean(axis=0), np.array(tail[5:8]),
                                          p.slip_norm_tol, p.slip_angle_tol))
        tail[4] = tail[4] + 1 if flagged else 0.0

    def _recent(self, x: np.ndarray, offset: int, k: int, taken: int | None = None
                ) -> np.ndarray:
        """The last ``min(k, taken)`` samples, oldest first (as ``_Sampled._recent``)."""
        if taken is None:
            taken = int(x[offset + self._tail])
        k = min(k, taken, self._n)
        ring = x[offset:offset + self._tail].reshape(self._n, 3)
        return ring[(taken - k + np.arange(k)) % self._n]

    # Outputs, from the state x[offset:], as the separate systems compute them.

    def roll_pitch(self, x: np.ndarray, offset: int) -> np.ndarray:
        recent = self._recent(x, offset, self._n_mean)
        return roll_pitch(recent.mean(axis=0)) if len(recent) else np.zeros(2)

    def at_rest(self, x: np.ndarray, offset: int) -> float:
        p = self.params
        rest = int(x[offset + self._tail]) >= self._n_rest and at_rest(
            self._recent(x, offset, self._n_rest), p.rest_norm_tol, p.rest_std_tol,
            p.rest_angle_tol)
        return 1.0 if rest else 0.0

    def free_fall(self, x: np.ndarray, offset: int) -> float:
        return 1.0 if x[offset + self._tail + 1] >= self._fall_need else 0.0

    def detection_time(self, x: np.ndarray, offset: int) -> float:
        return float(x[offset + self._tail + 2])

    def slip(self, x: np.ndarray, offset: int) -> float:
        if not self.command_size:
            return 0.0
        return 1.0 if x[offset + self._tail + 4] >= self._slip_need else 0.0


class InstrumentSystem(LeafSystem):
    """A device system (``counts`` and ``acceleration`` outputs) that can carry the
    estimators: one discrete state group ``[device state, estimator state]`` and
    one periodic update per device sample, at ``k * period``, which takes the
    device's sample (:meth:`_sample`, the subclass's) and, with estimators, steps
    them on it (:class:`InstrumentEstimators`) in the same update. Its outputs
    are then those of the separate estimator systems behind the device:
    ``roll_pitch`` (2), ``at_rest``, ``free_fall``, ``detection_time`` (the time
    of the sample that completed the free-fall run; the separate
    :class:`FreeFallDetector` reports its own update's, :attr:`_Sampled.OFFSET`
    later), ``slip`` (a constant 0.0 without a command: nothing tells whether the
    hand moves), and the input ``command`` (with a ``command_size``), which the
    update reads at the sample instant.
    """

    def _declare_instrument(self, period: float, device_state, estimators, command_size):
        """Declares the state, the update and the ports (the subclass's input ports
        first). ``estimators``: None (the device alone) or :class:`EstimatorParams`."""
        self._device_size = len(device_state)
        self.estimators = (None if estimators is None else
                           InstrumentEstimators(period, estimators, command_size))
        x0 = [float(v) for v in device_state]
        if self.estimators is not None:
            x0 += self.estimators.initial_state()
            if self.estimators.command_size:
                self._command = self.DeclareVectorInputPort("command",
                                                            self.estimators.command_size)
        self._state = self.DeclareDiscreteState(np.array(x0))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        ticket = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort("counts", 3, self._calc_counts, ticket)
        self.DeclareVectorOutputPort("acceleration", 3, self._calc_acceleration, ticket)
        if self.estimators is None:
            return
        est, o = self.estimators, self._device_size
        for name, size, value in (("roll_pitch", 2, est.roll_pitch),
                                  ("at_rest", 1, est.at_rest),
                                  ("free_fall", 1, est.free_fall),
                                  ("detection_time", 1, est.detection_time),
                                  ("slip", 1, est.slip)):
            if name == "slip" and not est.command_size:
                self.DeclareVectorOutputPort("slip", 1, lambda context, out: out.SetAtIndex(0, 0.0),
                                             {self.nothing_ticket()})
                continue
            self.DeclareVectorOutputPort(name, size, self._calc_estimate(value, o, size), ticket)

    def _calc_estimate(self, value, offset, size):
        state = self._state
        if size == 1:
            def calc(context, output):
                output.SetAtIndex(0, value(context.get_discrete_state(state).get_value(), offset))
        else:
            def calc(context, output):
                output.SetFromVector(value(context.get_discrete_state(state).get_value(), offset))
        return calc

    def _update(self, context, discrete_state):
        # Drake hands the update a copy of the current state: write what changes.
        x = discrete_state.get_mutable_value(self._state)
        f = self._sample(context, x)
        if self.estimators is not None:
            command = self._command.Eval(context).tolist() if self.estimators.command_size \
                else None
            self.estimators.step(x, self._device_size, context.get_time(), f, command)

    def _sample(self, context, x: np.ndarray) -> list[float] | None:
        """Takes the device's sample: updates the device state ``x[:device size]`` and
        returns the new ``acceleration`` (3 floats, m/s^2, as the output reads it; a
        device without estimators may return None)."""
        raise NotImplementedError

    def _calc_counts(self, context, output: BasicVector):
        raise NotImplementedError

    def _calc_acceleration(self, context, output: BasicVector):
        raise NotImplementedError
