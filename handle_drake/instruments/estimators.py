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
floats, its state in named groups: :data:`EstimatorState`).
:class:`EstimatorSystem` runs the same estimators behind any acceleration
signal. The plain functions are the reference the update is tested against,
output for output and sample for sample
(``tests/instruments/test_instrument_fused.py``).
"""

from __future__ import annotations

import dataclasses as dc
import math
import operator

import numpy as np
from pydrake.common.containers import namedview
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
    "EstimatorState",
    "InstrumentEstimators",
    "InstrumentSystem",
    "EstimatorSystem",
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


#: The estimators' counters and slip reference: one discrete state group, read by name.
EstimatorState = namedview("EstimatorState", [
    "taken",           # samples taken
    "low_samples",     # consecutive samples below the free-fall threshold
    "detection_time",  # s: the sample that completed the present free fall (NaN: none)
    "still_samples",   # consecutive samples with the command still
    "slip_samples",    # consecutive samples judged slipping
    "ref_x", "ref_y", "ref_z",  # the slip reference (NaN: none taken yet)
    "have_command",    # 1 once a command has been read
])
# Field positions, for the per-sample update on plain floats (see InstrumentEstimators).
(_TAKEN, _LOW, _DETECTED, _STILL, _SLIPPING, _REF, _, _, _HAVE_COMMAND) = range(
    len(EstimatorState.get_fields()))


class InstrumentEstimators:
    """The roll/pitch, free-fall and (with a ``command_size``) slip estimators as one
    update, for a device system to run in its own periodic update (not a System:
    :class:`InstrumentSystem` holds it and calls :meth:`declare_state` in its
    constructor). Its discrete state groups:

    - ``samples`` (``3 n``): the last ``n`` samples (as many as the longest window
      needs), sample ``k`` in row ``k % n``;
    - ``estimates``: :data:`EstimatorState`, by name;
    - ``command`` (``command_size``): the command read at the previous sample.

    :meth:`step` works on plain Python floats (tiny numpy arrays cost more per
    operation than the arithmetic). Where its float arithmetic could differ from
    the plain functions' numpy arithmetic in the last bits (a magnitude against the
    free-fall threshold, the slip test's magnitude and angle against their
    tolerances), a value within :attr:`BAND` of its threshold is decided by the
    plain functions' own expressions (``np.linalg.norm``, :func:`slip_indicator`),
    so every decision is theirs exactly. The outputs are computed by the plain
    functions (:func:`roll_pitch`, :func:`at_rest`) of the samples.
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
        self._n_mean = p.samples(p.window, period)  # roll/pitch's and the slip test's mean
        self._n_rest = max(self._n_mean, p.samples(p.rest_window, period), 2)
        self._n = self._n_rest  # the samples kept: the longest window
        self._fall_need = p.samples(p.free_fall_duration, period)
        self._settle = p.samples(p.settle_time, period)
        self._slip_need = p.samples(p.slip_duration, period)
        self._fall_threshold = p.free_fall_threshold * G0
        self._norm_tol = p.slip_norm_tol * G0
        # arccos(c) > angle_tol  <=>  c < cos(angle_tol) (never when angle_tol >= pi).
        self._cos_tol = math.cos(p.slip_angle_tol) if p.slip_angle_tol < math.pi else -math.inf
        self._groups = None

    def initial_estimates(self) -> EstimatorState:
        x = EstimatorState(np.zeros(len(EstimatorState.get_fields())))
        x.detection_time = math.nan
        x.ref_x = x.ref_y = x.ref_z = math.nan
        return x

    def declare_state(self, system: LeafSystem) -> set:
        """Declares the state groups on ``system`` (in its constructor); returns their
        tickets."""
        if self._groups is not None:
            raise RuntimeError("the estimators' state is declared once, by one system")
        samples = system.DeclareDiscreteState(3 * self._n)
        estimates = system.DeclareDiscreteState(self.initial_estimates()[:])
        command = (system.DeclareDiscreteState(self.command_size) if self.command_size
                   else None)
        self._groups = (samples, estimates, command)
        return {system.discrete_state_ticket(g) for g in self._groups if g is not None}

    def estimates(self, state) -> EstimatorState:
        """The :data:`EstimatorState` of a context's (or an update's) discrete state."""
        return EstimatorState(state.get_value(self._groups[1]))

    def step(self, state, t: float, f: list[float], command=None) -> None:
        """Takes the sample ``f`` (3 floats, m/s^2) at time ``t``: updates the
        estimators' groups of ``state`` (the update's writable ``DiscreteValues``) in
        place. ``command``: the command's values (a list), when the estimators have one."""
        samples_group, estimates_group, command_group = self._groups
        ring = state.get_mutable_value(samples_group)
        estimates = state.get_mutable_value(estimates_group)
        e = estimates.tolist()
        fx, fy, fz = f
        taken = int(e[_TAKEN])
        slot = 3 * (taken % self._n)
        ring[slot:slot + 3] = f
        taken += 1
        e[_TAKEN] = taken
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        threshold = self._fall_threshold
        if abs(norm - threshold) > self.BAND * threshold:
            low = norm < threshold
        else:  # at the threshold (or not finite): free_fall's own expression
            low = bool(np.linalg.norm(np.array(f, dtype=float)) < threshold)
        e[_LOW] = e[_LOW] + 1 if low else 0
        if e[_LOW] == self._fall_need:
            e[_DETECTED] = t
        elif e[_LOW] < self._fall_need:
            e[_DETECTED] = math.nan
        if self.command_size:
            previous = state.get_mutable_value(command_group)
            self._slip_step(ring, e, taken, command, previous.tolist())
            previous[:] = command
        estimates[:] = e

    def _slip_step(self, ring, e, taken, command, previous) -> None:
        """The slip method (module doc) on the estimates ``e`` (floats, in place)."""
        tol = self.params.still_tol
        # max |command - previous| <= tol, as each entry's (a NaN is not still)
        still = e[_HAVE_COMMAND] > 0 and all(map(tol.__ge__, map(abs, map(operator.sub, command,
                                                                           previous))))
        e[_HAVE_COMMAND] = 1.0
        if not still:
            e[_STILL:_REF + 3] = [0.0, 0.0, math.nan, math.nan, math.nan]
            return
        e[_STILL] += 1
        if e[_STILL] < self._settle:
            return
        if math.isnan(e[_REF]):  # no reference yet: one at rest (as numpy does it), or slip
            p = self.params
            if taken >= self._n_rest and at_rest(
                    self._recent(ring, self._n_rest, taken), p.rest_norm_tol, p.rest_std_tol,
                    p.rest_angle_tol):
                e[_REF:_REF + 3] = self._recent(ring, self._n_mean, taken).mean(axis=0).tolist()
            else:
                e[_SLIPPING] += 1
                return
        # The mean of the last samples, in order (the ring slots, oldest first).
        n, k = self._n, min(self._n_mean, taken, self._n)
        first = (taken - k) % n
        if first + k <= n:
            window = ring[3 * first:3 * (first + k)].tolist()
        else:
            window = ring[3 * first:3 * n].tolist() + ring[:3 * (first + k - n)].tolist()
        mx, my, mz = sum(window[0::3]) / k, sum(window[1::3]) / k, sum(window[2::3]) / k
        rx, ry, rz = e[_REF:_REF + 3]
        r_norm = max(math.sqrt(rx * rx + ry * ry + rz * rz), 1e-12)
        rx, ry, rz = rx / r_norm, ry / r_norm, rz / r_norm
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        cos = (mx * rx + my * ry + mz * rz) / max(norm, 1e-12)
        off = abs(norm - G0)
        band = self.BAND
        if (abs(off - self._norm_tol) > band * G0 and abs(cos - self._cos_tol) > band
                and math.isfinite(norm) and math.isfinite(r_norm)):
            flagged = off > self._norm_tol or cos < self._cos_tol
        else:  # near a threshold (or not finite): slip_indicator's own expression
            p = self.params
            flagged = bool(slip_indicator(self._recent(ring, self._n_mean, taken).mean(axis=0),
                                          np.array(e[_REF:_REF + 3]), p.slip_norm_tol,
                                          p.slip_angle_tol))
        e[_SLIPPING] = e[_SLIPPING] + 1 if flagged else 0.0

    def _recent(self, ring: np.ndarray, k: int, taken: int) -> np.ndarray:
        """The last ``min(k, taken)`` samples (k, 3), oldest first."""
        k = min(k, taken, self._n)
        return ring.reshape(self._n, 3)[(taken - k + np.arange(k)) % self._n]

    def recent(self, state, k: int) -> np.ndarray:
        """The last ``min(k, taken)`` samples of a context's discrete state, oldest first."""
        return self._recent(state.get_value(self._groups[0]), k,
                            int(self.estimates(state).taken))

    # Outputs, from a context's discrete state, by the plain functions.

    def roll_pitch(self, state) -> np.ndarray:
        recent = self.recent(state, self._n_mean)
        return roll_pitch(recent.mean(axis=0)) if len(recent) else np.zeros(2)

    def at_rest(self, state) -> float:
        p = self.params
        rest = int(self.estimates(state).taken) >= self._n_rest and at_rest(
            self.recent(state, self._n_rest), p.rest_norm_tol, p.rest_std_tol, p.rest_angle_tol)
        return 1.0 if rest else 0.0

    def free_fall(self, state) -> float:
        return 1.0 if self.estimates(state).low_samples >= self._fall_need else 0.0

    def detection_time(self, state) -> float:
        return float(self.estimates(state).detection_time)

    def slip(self, state) -> float:
        if not self.command_size:
            return 0.0
        return 1.0 if self.estimates(state).slip_samples >= self._slip_need else 0.0


class InstrumentSystem(LeafSystem):
    """A device system (``counts`` and ``acceleration`` outputs) that can carry the
    estimators: the device's own discrete state group, the estimators' groups
    (:class:`InstrumentEstimators`), and one periodic update per device sample, at
    ``k * period``, which takes the device's sample (:meth:`_sample`, the
    subclass's) and, with estimators, steps them on it in the same update. Outputs
    with estimators: ``roll_pitch`` (2), ``at_rest``, ``free_fall``,
    ``detection_time`` (the time of the sample that completed the free-fall run),
    ``slip`` (a constant 0.0 without a command: nothing tells whether the hand
    moves), and the input ``command`` (with a ``command_size``), which the update
    reads at the sample instant.
    """

    def _declare_instrument(self, period: float, device_state, estimators, command_size):
        """Declares the state, the update and the ports (the subclass's input ports
        first). ``estimators``: None (the device alone) or :class:`EstimatorParams`."""
        self._device_size = len(device_state)
        self.estimators = (None if estimators is None else
                           InstrumentEstimators(period, estimators, command_size))
        self._state = self.DeclareDiscreteState(np.array([float(v) for v in device_state]))
        ticket = {self.discrete_state_ticket(self._state)}
        if self.estimators is not None:
            estimator_tickets = self.estimators.declare_state(self)
            if self.estimators.command_size:
                self._command = self.DeclareVectorInputPort("command",
                                                            self.estimators.command_size)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort("counts", 3, self._calc_counts, ticket)
        self.DeclareVectorOutputPort("acceleration", 3, self._calc_acceleration, ticket)
        if self.estimators is None:
            return
        est = self.estimators
        for name, size, value in (("roll_pitch", 2, est.roll_pitch),
                                  ("at_rest", 1, est.at_rest),
                                  ("free_fall", 1, est.free_fall),
                                  ("detection_time", 1, est.detection_time),
                                  ("slip", 1, est.slip)):
            if name == "slip" and not est.command_size:
                self.DeclareVectorOutputPort("slip", 1, lambda context, out: out.SetAtIndex(0, 0.0),
                                             {self.nothing_ticket()})
                continue
            self.DeclareVectorOutputPort(name, size, self._calc_estimate(value, size),
                                         estimator_tickets)

    @staticmethod
    def _calc_estimate(value, size):
        if size == 1:
            def calc(context, output):
                output.SetAtIndex(0, value(context.get_discrete_state()))
        else:
            def calc(context, output):
                output.SetFromVector(value(context.get_discrete_state()))
        return calc

    def _update(self, context, discrete_state):
        # Drake hands the update a copy of the current state: write what changes.
        f = self._sample(context, discrete_state.get_mutable_value(self._state))
        if self.estimators is not None:
            command = self._command.Eval(context).tolist() if self.estimators.command_size \
                else None
            self.estimators.step(discrete_state, context.get_time(), f, command)

    def _sample(self, context, x: np.ndarray) -> list[float] | None:
        """Takes the device's sample: updates the device's state ``x`` and returns the
        new ``acceleration`` (3 floats, m/s^2, as the output reads it; a device
        without estimators may return None)."""
        raise NotImplementedError

    def _calc_counts(self, context, output: BasicVector):
        raise NotImplementedError

    def _calc_acceleration(self, context, output: BasicVector):
        raise NotImplementedError


class EstimatorSystem(InstrumentSystem):
    """The estimators behind any acceleration signal: input ``acceleration`` (3, m/s^2,
    sensor frame), sampled every ``period`` s from t = 0 (and, with a
    ``command_size``, input ``command``); outputs the estimates of
    :class:`InstrumentSystem` and the held sample as ``counts`` and ``acceleration``."""

    def __init__(self, period: float, params: EstimatorParams | None = None,
                 command_size: int | None = None):
        super().__init__()
        self._input = self.DeclareVectorInputPort("acceleration", 3)
        self._declare_instrument(_check_period(period), [0.0, 0.0, 0.0],
                                 params or EstimatorParams(), command_size)

    def _sample(self, context, x):
        f = self._input.Eval(context).tolist()
        x[:] = f
        return f

    def _calc_counts(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).get_value())

    _calc_acceleration = _calc_counts
