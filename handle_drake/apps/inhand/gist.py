"""Action gist, control parameters (eq. 45) and Algorithm 1 / eq. 46 (report 5.3, 5.4).

Meta motion: one finger moving its joints in one direction over a time slot
(normalised time in [0, 1]). The action gist is the ordered list of the
demonstration's meta motions (by start time). Per finger the meta motion
varies :data:`FINGER_JOINTS` (Fig. 31 under the mapping rules: the abduction
joints only set the initial value, LFJ5 stays 0 and J1/J2 count once, as the
commanded J2 of the coupled pair), so ``L_joint`` is 2 for the fingers and 3
for the thumb (THJ5 rotation, THJ2, THJ1).

Segmentation rule (:func:`extract_gist`): a finger's flexion coordinate is the
sum of its meta-motion joints (rad), smoothed by a centred moving average of
``smooth`` s; a sample moves when the coordinate's speed exceeds ``min_speed``
rad/s, and its direction is the sign of the speed. A segment is a maximal run
of samples moving in one direction (runs of the same direction separated by
less than ``max_gap`` s are joined); segments changing the coordinate by less
than ``min_amplitude`` rad are dropped. A segment's joint variations are the
changes of each joint between its first and last sample.

Control parameters (eq. 45): per meta motion, in gist order, its start time
and the magnitudes of its ``L_joint`` variations, so ``d_m = sum_i (1 +
L_joint(finger(m_i)))``. The direction of every variation is fixed by the gist
(Alg. 2, 1*): the optimiser searches magnitudes in ``[0, A_lim]`` and start
times in ``[0, 1]``.

Algorithm 1 with the linear model of eq. 46: frame ``j = 1..N`` has normalised
time ``T = j / N``; each meta motion adds ``ramp(T) * variation`` with
``ramp = clip((T - start) / (end - start), 0, 1)`` to the initial joint angles
(a finished motion keeps its full variation). A meta motion ends where the
finger's next meta motion starts (the end time is redundant, 5.3); the last
one of a finger keeps its demonstrated duration (capped at T = 1). A motion
whose end is not after its start (the optimiser moved the next start before
it) is a step at its start.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.scenario import Keyframe

__all__ = [
    "check_parameter_vector",
    "FINGERS",
    "FINGER_JOINTS",
    "MetaMotion",
    "ActionGist",
    "extract_gist",
    "parameter_dimension",
    "frames",
    "GistMotionSource",
    "staged_gist",
]

FINGERS = ("TH", "FF", "MF", "RF", "LF")
FINGER_JOINTS: dict[str, tuple[str, ...]] = {
    "TH": ("THJ5", "THJ2", "THJ1"),
    "FF": ("FFJ3", "FFJ2"),
    "MF": ("MFJ3", "MFJ2"),
    "RF": ("RFJ3", "RFJ2"),
    "LF": ("LFJ3", "LFJ2"),
}
_NAMES = get_hand_spec("shadow").actuated_joint_names


@dc.dataclass(frozen=True)
class MetaMotion:
    """One finger's motion in one direction: normalised ``start < end``, ``variation`` (rad)."""

    finger: str
    start: float
    end: float
    variation: tuple[float, ...]  # per FINGER_JOINTS[finger], signed

    def __post_init__(self):
        if self.finger not in FINGER_JOINTS:
            raise ValueError(f"finger: expected one of {FINGERS}, got {self.finger!r}")
        if not (0.0 <= self.start < self.end <= 1.0):
            raise ValueError(f"meta motion of {self.finger}: expected 0 <= start < end <= 1, "
                             f"got start={self.start}, end={self.end}")
        n = len(FINGER_JOINTS[self.finger])
        variation = tuple(float(v) for v in self.variation)
        if len(variation) != n or not all(np.isfinite(variation)):
            raise ValueError(f"meta motion of {self.finger}: variation: expected {n} finite "
                             f"values ({', '.join(FINGER_JOINTS[self.finger])}), got {variation}")
        object.__setattr__(self, "variation", variation)

    @property
    def joints(self) -> tuple[str, ...]:
        return FINGER_JOINTS[self.finger]

    @property
    def directions(self) -> np.ndarray:
        """+1 / -1 per joint (a zero demonstrated variation counts as +1)."""
        return np.where(np.asarray(self.variation) < 0, -1.0, 1.0)


@dc.dataclass(frozen=True)
class ActionGist:
    """The ordered meta motions of a demonstration (sorted by start time)."""

    motions: tuple[MetaMotion, ...]
    name: str = ""

    def __post_init__(self):
        motions = tuple(self.motions)
        if not motions:
            raise ValueError("gist: expected at least one meta motion, got none")
        if any(not isinstance(m, MetaMotion) for m in motions):
            raise TypeError("gist: expected MetaMotion entries")
        starts = [m.start for m in motions]
        if starts != sorted(starts):
            raise ValueError(f"gist: meta motions must be ordered by start time, got {starts}")
        for finger in FINGERS:
            own = [m for m in motions if m.finger == finger]
            for a, b in zip(own, own[1:], strict=False):
                if b.start < a.end - 1e-9:
                    raise ValueError(
                        f"gist: meta motions of {finger} overlap: [{a.start:.3f}, {a.end:.3f}] "
                        f"and [{b.start:.3f}, {b.end:.3f}]; one finger moves one way at a time")
        object.__setattr__(self, "motions", motions)

    def __len__(self) -> int:
        return len(self.motions)

    # --------------------------------------------------------------- eq. 45
    @property
    def dimension(self) -> int:
        """``d_m = sum_i (1 + L_joint(finger(m_i)))`` (eq. 45)."""
        return parameter_dimension([m.finger for m in self.motions])

    def slices(self) -> list[slice]:
        """Where each meta motion's ``[start, magnitudes...]`` sits in the parameter vector."""
        out, k = [], 0
        for m in self.motions:
            n = 1 + len(m.joints)
            out.append(slice(k, k + n))
            k += n
        return out

    def initial_parameters(self) -> np.ndarray:
        """The demonstration's own parameters: its start times and variation magnitudes."""
        return np.concatenate([[m.start, *np.abs(m.variation)] for m in self.motions])

    def bounds(self, limit: float | None = None, coupling_ratio: float = 1.0) -> np.ndarray:
        """(d_m, 2) box: start in [0, 1]; magnitude in [0, A_lim] (Alg. 2, 1*).

        ``A_lim`` is the joint's command range, or ``limit`` (rad) if given.
        """
        lower, upper = actuated_position_limits(get_hand_spec("shadow"), coupling_ratio)
        rows = []
        for m in self.motions:
            rows.append((0.0, 1.0))
            for joint in m.joints:
                i = _NAMES.index(joint)
                a_lim = float(upper[i] - lower[i]) if limit is None else float(limit)
                if not a_lim > 0:
                    raise ValueError(f"limit: expected > 0, got {limit}")
                rows.append((0.0, a_lim))
        return np.array(rows)

    def demo_end_offsets(self) -> np.ndarray:
        return np.array([m.end - m.start for m in self.motions])

    def as_dict(self) -> dict:
        return {"name": self.name, "motions": [dc.asdict(m) for m in self.motions]}

    @classmethod
    def from_dict(cls, data: dict) -> ActionGist:
        try:
            motions = tuple(MetaMotion(m["finger"], float(m["start"]), float(m["end"]),
                                       tuple(m["variation"])) for m in data["motions"])
        except (KeyError, TypeError) as error:
            raise ValueError(f"gist: malformed meta motion ({error})") from None
        return cls(motions, str(data.get("name", "")))


def staged_gist(gist: ActionGist, stages: int) -> ActionGist:
    """The gist performed ``stages`` times in sequence (strokes): stage ``s`` (0-based) is
    the gist's meta motions with their times mapped to ``[s / S, (s + 1) / S]``, each stage
    with its own parameters (eq. 45: ``S * d_m``). The frames of eq. 46 sum over all
    stages, so a stage continues from where the one before left the fingers."""
    if isinstance(stages, bool) or not isinstance(stages, int) or stages < 1:
        raise ValueError(f"stages: expected an integer >= 1, got {stages!r}")
    if stages == 1:
        return gist
    motions = [MetaMotion(m.finger, (s + m.start) / stages, (s + m.end) / stages, m.variation)
               for s in range(stages) for m in gist.motions]
    return ActionGist(tuple(motions), f"{gist.name}-{stages}stages")


def parameter_dimension(fingers) -> int:
    """Eq. 45 for a sequence of meta-motion fingers."""
    total = 0
    for finger in fingers:
        if finger not in FINGER_JOINTS:
            raise ValueError(f"finger: expected one of {FINGERS}, got {finger!r}")
        total += 1 + len(FINGER_JOINTS[finger])
    return total


def _moving_average(x, n):
    if n <= 1:
        return x.copy()
    kernel = np.ones(n) / n
    padded = np.pad(x, (n // 2, n - 1 - n // 2), mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def extract_gist(times, commands, fingers=FINGERS, smooth=0.1, min_speed=0.3,
                 min_amplitude=0.1, max_gap=0.08, name="") -> ActionGist:
    """Segments a mapped demonstration ((T,) s, (T, 20) rad) into its action gist.

    See the module doc for the rule; ``fingers`` limits the fingers looked at.
    """
    t = np.asarray(times, dtype=float)
    q = np.asarray(commands, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"times: expected at least 3 samples, got shape {t.shape}")
    if q.shape != (t.size, len(_NAMES)):
        raise ValueError(f"commands: expected shape ({t.size}, {len(_NAMES)}), got {q.shape}")
    if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(q)):
        raise ValueError("times must increase and commands be finite")
    for key, value in (("smooth", smooth), ("min_speed", min_speed),
                       ("min_amplitude", min_amplitude), ("max_gap", max_gap)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{key}: expected a finite value >= 0, got {value}")
    dt = float(np.median(np.diff(t)))
    t0, span = t[0], t[-1] - t[0]
    motions = []
    for finger in fingers:
        if finger not in FINGER_JOINTS:
            raise ValueError(f"fingers: expected names from {FINGERS}, got {finger!r}")
        cols = [_NAMES.index(j) for j in FINGER_JOINTS[finger]]
        s = _moving_average(q[:, cols].sum(axis=1), max(1, int(round(smooth / dt))))
        v = np.gradient(s, t)
        direction = np.where(v > min_speed, 1, np.where(v < -min_speed, -1, 0))
        runs = []  # [first, last, sign]
        for i, d in enumerate(direction):
            if d == 0:
                continue
            if runs and runs[-1][2] == d and t[i] - t[runs[-1][1]] <= max_gap + 1e-12:
                runs[-1][1] = i
            else:
                runs.append([i, i, int(d)])
        for first, last, _ in runs:
            if abs(s[last] - s[first]) < min_amplitude:
                continue
            variation = q[last, cols] - q[first, cols]
            motions.append(MetaMotion(finger, float((t[first] - t0) / span),
                                      float((t[last] - t0) / span), tuple(variation)))
    motions.sort(key=lambda m: (m.start, FINGERS.index(m.finger)))
    return ActionGist(tuple(motions), name)


def check_parameter_vector(c, size: int, what: str | None = None) -> np.ndarray:
    """``c`` as a flat float vector of ``size`` finite values (``what``: how the size
    error names them; default "N values (eq. 45)")."""
    c = np.asarray(c, dtype=float).reshape(-1)
    if c.size != size:
        raise ValueError(f"parameters: expected {what or f'{size} values (eq. 45)'}, "
                         f"got {c.size}")
    if not np.all(np.isfinite(c)):
        raise ValueError("parameters: expected finite values")
    return c


def _check_parameters(gist: ActionGist, c) -> np.ndarray:
    return check_parameter_vector(c, gist.dimension)


def schedule(gist: ActionGist, c):
    """Per meta motion: ``(start, end, signed variation)`` from the parameters ``c``."""
    c = _check_parameters(gist, c)
    out = []
    slices = gist.slices()
    offsets = gist.demo_end_offsets()
    for i, (m, sl) in enumerate(zip(gist.motions, slices, strict=True)):
        start = float(np.clip(c[sl][0], 0.0, 1.0))
        nxt = next((k for k in range(i + 1, len(gist)) if gist.motions[k].finger == m.finger),
                   None)
        if nxt is None:
            end = min(1.0, start + offsets[i])
        else:
            end = float(np.clip(c[slices[nxt]][0], 0.0, 1.0))
        out.append((start, max(start, end), m.directions * np.abs(c[sl][1:])))
    return out


def frames(gist: ActionGist, c, q0, n_frames: int, coupling_ratio: float = 1.0) -> np.ndarray:
    """Algorithm 1 / eq. 46: (n_frames, 20) joint-angle frames, frame j at ``T = j / N``."""
    if isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer) or n_frames < 1:
        raise ValueError(f"n_frames: expected an integer >= 1, got {n_frames!r}")
    T = np.arange(1, n_frames + 1) / n_frames
    return frames_at(gist, c, q0, T, coupling_ratio)


def frames_at(gist: ActionGist, c, q0, T, coupling_ratio: float = 1.0) -> np.ndarray:
    """Joint angles (len(T), 20) at normalised times ``T`` (eq. 46 summed over the gist)."""
    q0 = np.asarray(q0, dtype=float).reshape(-1)
    if q0.size != len(_NAMES):
        raise ValueError(f"q0: expected {len(_NAMES)} command values, got {q0.size}")
    T = np.atleast_1d(np.asarray(T, dtype=float))
    q = np.tile(q0, (T.size, 1))
    for m, (start, end, variation) in zip(gist.motions, schedule(gist, c), strict=True):
        if end > start:
            ramp = np.clip((T - start) / (end - start), 0.0, 1.0)
        else:
            ramp = (T >= start).astype(float)
        cols = [_NAMES.index(j) for j in m.joints]
        q[:, cols] += ramp[:, None] * variation[None, :]
    lower, upper = actuated_position_limits(get_hand_spec("shadow"), coupling_ratio)
    return np.clip(q, lower, upper)


class GistMotionSource(LeafSystem):
    """Drives ``hand.position`` with the frames of Algorithm 1 (a zero-order hold of frames).

    Frame ``j`` (``T = j / N``) is sent during ``[(j - 1), j) * duration / N``;
    after the motion the last frame is held. The control parameters are a
    numeric parameter of the context (``set_parameters``), so one diagram
    replays any parameter vector on the simulated or the CAN hand station.
    """

    def __init__(self, gist: ActionGist, q0, duration: float, n_frames: int = 50,
                 coupling_ratio: float = 1.0, parameters=None):
        super().__init__()
        if not (np.isfinite(duration) and duration > 0):
            raise ValueError(f"duration: expected a finite value > 0 s, got {duration}")
        if isinstance(n_frames, bool) or not isinstance(n_frames, int) or n_frames < 1:
            raise ValueError(f"n_frames: expected an integer >= 1, got {n_frames!r}")
        self._gist = gist
        self._q0 = np.asarray(q0, dtype=float).copy()
        if self._q0.size != len(_NAMES):
            raise ValueError(f"q0: expected {len(_NAMES)} command values, got {self._q0.size}")
        self._duration = float(duration)
        self._n = int(n_frames)
        self._ratio = coupling_ratio
        c0 = gist.initial_parameters() if parameters is None else \
            _check_parameters(gist, parameters)
        self._c_index = self.DeclareNumericParameter(BasicVector(c0))
        self._cache_key, self._cache = None, None
        self.DeclareVectorOutputPort("hand_position", len(_NAMES), self._calc)

    def set_parameters(self, context, c) -> None:
        c = _check_parameters(self._gist, c)
        context.get_mutable_numeric_parameter(self._c_index).SetFromVector(c)

    def frame_index(self, t: float) -> int:
        """The frame (1..N) sent at time ``t`` (s)."""
        return int(min(self._n, max(1, np.floor(t / self._duration * self._n + 1e-9) + 1)))

    def frame_indices(self, times) -> np.ndarray:
        """:meth:`frame_index` of every time in ``times`` (s), in one numpy pass: the same
        floating-point operations in the same order, element-wise."""
        t = np.asarray(times, dtype=float)
        index = np.floor(t / self._duration * self._n + 1e-9) + 1
        return np.minimum(self._n, np.maximum(1, index)).astype(int)

    def frames_for(self, parameters) -> np.ndarray:
        """The (N, 20) frames of ``parameters`` (as the output sends them)."""
        return self._frames(np.asarray(parameters, dtype=float))

    def held_frames(self, parameters, period: float, end_time: float):
        """What the output sends at the times ``k period`` (k = 0.. up to ``end_time``, s)
        as a zero-order-hold trajectory whose breaks sit half a period before each such
        time (no ambiguity there; one segment per run of equal frames): played by a
        ``TrajectorySource`` into a driver that samples its command every ``period``, it
        gives the driver the same command at every sample as this system, without a
        Python call per sample."""
        n = int(np.ceil(end_time / period - 1e-9)) + 1
        values = self.frames_for(parameters)[self.frame_indices(np.arange(n) * period) - 1]
        if not np.isfinite(values).all():  # where the commands enter (a driver in Drake
            raise ValueError("parameters: their frames are not finite")  # primitives)
        breaks = (np.arange(n) - 0.5) * period
        keep = np.r_[True, np.any(values[1:] != values[:-1], axis=1)]
        breaks, values = np.append(breaks[keep], breaks[-1] + period), values[keep]
        return PiecewisePolynomial.ZeroOrderHold(breaks, np.vstack([values, values[-1]]).T)

    def held_keyframes(self, parameters, period: float, end_time: float, offset: float,
                       q0=None) -> list:
        """:meth:`held_frames` as a scenario's keyframe ``script`` starting at ``offset`` s
        (after the settle): the script interpolates linearly, so each change of frame is
        two keyframes a quarter period either side of its break (the first naming only
        the joints that change), and between them the command is constant: at every
        sample ``offset + k period`` the station's driver reads the same command as from
        :meth:`held_frames` (exactly: a linear segment between equal values is that
        value). ``q0``: the command before (default the source's)."""
        n = int(np.ceil(end_time / period - 1e-9)) + 1
        values = self.frames_for(parameters)[self.frame_indices(np.arange(n) * period) - 1]
        previous = self._q0 if q0 is None else np.asarray(q0, dtype=float)
        script = []
        for k in range(n):
            changed = np.flatnonzero(values[k] != previous)
            if changed.size:
                t = offset + (k - 0.5) * period
                script.append(Keyframe(time=float(t - period / 4)))
                script.append(Keyframe(time=float(t + period / 4), hand={
                    _NAMES[j]: float(values[k][j]) for j in changed}))
                previous = values[k]
        return script

    def _frames(self, c) -> np.ndarray:
        # A cache of a pure function: all N frames of the parameter vector ``c`` read from
        # the context, kept for the last ``c`` seen (one per trial). Keyed by ``c`` itself,
        # so any context gets its own parameters' frames (tests/test_leaf_state.py ALLOWED).
        key = c.tobytes()
        if self._cache_key != key:
            self._cache = frames(self._gist, c, self._q0, self._n, self._ratio)
            self._cache_key = key
        return self._cache

    def _calc(self, context, output):
        c = context.get_numeric_parameter(self._c_index).get_value()
        output.SetFromVector(self._frames(np.asarray(c))[self.frame_index(context.get_time()) - 1])
