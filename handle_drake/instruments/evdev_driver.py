"""A real accelerometer through Linux ``evdev``: the same ports as the simulation.

The JoyWarrior24F14 enumerates as a USB HID joystick with three absolute axes
(``ABS_X``, ``ABS_Y``, ``ABS_Z``) carrying the raw 14-bit readings (report
section 2.4.3), so ``evdev`` reads it without a driver of ours. Two things the
report warns about are handled on opening: the kernel's joystick deadband
("flat") around the presumed centre, which would zero readings of a nearly
level sensor, is set to 0 (``set_absinfo``; needs write access to the device,
else a warning), and the raw value's centre is taken from the device's
``absinfo`` ((min + max) / 2), not assumed.

:class:`EvdevAccelerometer` is a LeafSystem with the outputs of
:class:`~handle_drake.instruments.accelerometer.DeviceAccelerometer` (``counts``,
``acceleration``): at the device rate it drains the pending events of its
source and holds the latest value per axis; made with ``estimators`` it also
runs the roll/pitch, free-fall and slip estimators on each reading in the same
update, as the simulated device does, so the hardware station exports the same
instrument ports. A source is anything with
``read_events(t) -> iterable of (type, code, value)``: :class:`LiveEvents`
wraps an ``evdev.InputDevice`` (non-blocking reads),
:class:`RecordedEvents` replays a recorded stream by its time stamps against
the simulation clock (the tests run on one: this kernel has no
``/dev/uinput``). :func:`record_events` writes such a recording from a device.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from pydrake.systems.framework import BasicVector

from handle_drake.instruments.estimators import EstimatorParams, InstrumentSystem
from handle_drake.instruments.profiles import DeviceProfile, get_profile

__all__ = [
    "EV_ABS",
    "ABS_X",
    "ABS_Y",
    "ABS_Z",
    "EvdevAccelerometer",
    "LiveEvents",
    "RecordedEvents",
    "open_device",
    "record_events",
    "load_events",
    "save_events",
]

# Linux input-event codes (linux/input-event-codes.h), so recordings need no evdev.
EV_SYN, EV_ABS = 0, 3
ABS_X, ABS_Y, ABS_Z = 0, 1, 2


class RecordedEvents:
    """A recorded event stream ``(t, type, code, value)`` (t in s from the start),
    replayed against the simulation time: ``read_events(t)`` returns the events
    stamped up to ``t`` not returned yet. :meth:`reset` rewinds."""

    def __init__(self, events):
        rows = [tuple(e) for e in events]
        for i, row in enumerate(rows):
            if len(row) != 4:
                raise ValueError(f"events[{i}]: expected (t, type, code, value), got {row!r}")
            if not math.isfinite(float(row[0])):
                raise ValueError(f"events[{i}]: time must be finite, got {row[0]!r}")
        times = [float(r[0]) for r in rows]
        if any(b < a for a, b in zip(times, times[1:], strict=False)):
            raise ValueError("events: time stamps must not decrease")
        self._times = np.asarray(times)
        self._events = [(int(r[1]), int(r[2]), int(r[3])) for r in rows]
        self._next = 0

    def reset(self) -> None:
        self._next = 0

    def read_events(self, t: float):
        end = int(np.searchsorted(self._times, t + 1e-9, side="right"))
        if end < self._next:  # the clock went back: a simulator reset
            self._next = 0
        out = self._events[self._next:end]
        self._next = max(self._next, end)
        return out


class LiveEvents:
    """Non-blocking reads from an ``evdev.InputDevice`` (ignores ``t``)."""

    def __init__(self, device):
        self.device = device

    def read_events(self, t: float):
        try:
            return [(e.type, e.code, e.value) for e in self.device.read()]
        except BlockingIOError:  # nothing pending
            return []

    def absinfo(self, code: int):
        return self.device.absinfo(code)


def open_device(name_or_path: str, axes=(ABS_X, ABS_Y, ABS_Z)):
    """Opens an evdev device by path (``/dev/input/eventN``) or by a part of its name
    (e.g. ``"JoyWarrior"``), removes the kernel deadband ("flat") of the axes and
    returns a :class:`LiveEvents`."""
    from handle_drake.extras import require_extra

    evdev = require_extra("evdev")  # the joywarrior extra

    if not isinstance(name_or_path, str) or not name_or_path:
        raise ValueError(f"evdev_device: expected a device path or name, got {name_or_path!r}")
    if name_or_path.startswith("/"):
        if not Path(name_or_path).exists():
            raise FileNotFoundError(f"evdev_device: {name_or_path} does not exist")
        try:
            device = evdev.InputDevice(name_or_path)
        except OSError as error:  # /dev/zero, a directory, a file, a tty: not evdev
            raise ValueError(f"evdev_device: {name_or_path} is not an input event device "
                             f"(/dev/input/eventN): {error.strerror or error}") from None
    else:
        found = []
        for p in evdev.list_devices():
            try:
                found.append(evdev.InputDevice(p))
            except OSError:  # unreadable (permissions) or gone: not a candidate
                continue
        matches = [d for d in found if name_or_path.lower() in d.name.lower()]
        if not matches:
            names = [d.name for d in found]
            raise FileNotFoundError(
                f"evdev_device: no input device named like {name_or_path!r}; found {names}")
        device = matches[0]
    for code in axes:
        try:
            device.set_absinfo(code, flat=0)
        except OSError as error:
            warnings.warn(f"{device.path}: cannot clear the joystick deadband of axis {code} "
                          f"({error}); readings near the centre may read as the centre",
                          stacklevel=2)
    return LiveEvents(device)


def save_events(path, events) -> None:
    """Writes ``(t, type, code, value)`` rows as text, one event a line."""
    lines = ["# t_s type code value (Linux input events; handle_drake.instruments)"]
    lines += [f"{float(t):.6f} {int(a)} {int(b)} {int(c)}" for t, a, b, c in events]
    Path(path).write_text("\n".join(lines) + "\n")


#: bytes: a recording is text, ~20 bytes an event (an hour at 1 kHz, 3 axes: ~220 MB).
MAX_RECORDING_BYTES = 256 << 20


def load_events(path) -> RecordedEvents:
    """Reads a recording written by :func:`save_events`.

    Raises FileNotFoundError when nothing is there, ValueError naming the
    recording for a directory, FIFO or device, a file that is not UTF-8 text or
    larger than :data:`MAX_RECORDING_BYTES`, and a line that is not
    ``t type code value``.
    """
    from handle_drake.scenario_checks import read_text_file

    text = read_text_file(path, "evdev_device: event recording", max_bytes=MAX_RECORDING_BYTES)
    path = Path(path)
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 4:
            raise ValueError(f"{path}:{number}: expected 't type code value', got {line!r}")
        try:
            rows.append((float(parts[0]), int(parts[1]), int(parts[2]), int(parts[3])))
        except ValueError:
            raise ValueError(f"{path}:{number}: not numbers: {line!r}") from None
    return RecordedEvents(rows)


def record_events(device: LiveEvents, seconds: float, path) -> int:
    """Records ``seconds`` of a live device's events to ``path``; returns the count."""
    import time

    start = time.monotonic()
    events = []
    while (now := time.monotonic() - start) < seconds:
        events += [(now, *e) for e in device.read_events(now)]
        time.sleep(0.001)
    save_events(path, events)
    return len(events)


class EvdevAccelerometer(InstrumentSystem):
    """A real accelerometer read through evdev; outputs ``counts`` (3) and
    ``acceleration`` (3, m/s^2), as :class:`DeviceAccelerometer`, and with
    ``estimators`` the same estimator outputs (and ``command`` input, with
    ``command_size``), updated in the same periodic update as the reading.

    Args:
        source: a :class:`LiveEvents`, :class:`RecordedEvents` or anything with
            ``read_events(t)``.
        profile: the device profile (its rate is the polling rate; its bits
            set the default centre ``2**(bits-1)`` of raw unsigned readings).
        axes: the ABS codes of the sensor's x, y, z.
        signs: +-1 per axis (a device mounted with flipped axes).
        centre: raw value of 0 g per axis; default: from the device's absinfo
            ((min + max + 1) // 2) when it has one, else ``2**(bits-1)``.
        estimators: :class:`~handle_drake.instruments.estimators.EstimatorParams`
            to run the estimators on each reading, or None (the device alone).
        command_size: the size of the slip detector's ``command`` input (None: no
            slip detection, the ``slip`` output is a constant 0).
    """

    def __init__(self, source, profile: DeviceProfile | str, axes=(ABS_X, ABS_Y, ABS_Z),
                 signs=(1, 1, 1), centre=None, estimators: EstimatorParams | None = None,
                 command_size: int | None = None):
        super().__init__()
        if not hasattr(source, "read_events"):
            raise TypeError(f"source must have read_events(t), got {type(source).__name__}")
        self.source = source
        self.profile = get_profile(profile)
        self._axes = tuple(int(a) for a in axes)
        if len(self._axes) != 3 or len(set(self._axes)) != 3:
            raise ValueError(f"axes: expected 3 distinct ABS codes, got {axes!r}")
        self._signs = np.asarray(signs, dtype=float)
        if self._signs.shape != (3,) or not np.all(np.isin(self._signs, (-1.0, 1.0))):
            raise ValueError(f"signs: expected 3 values of +-1, got {signs!r}")
        if centre is None:
            centre = [self._default_centre(code) for code in self._axes]
        self._centre = np.asarray(centre, dtype=float)
        if self._centre.shape != (3,) or not np.all(np.isfinite(self._centre)):
            raise ValueError(f"centre: expected 3 finite raw values, got {centre!r}")
        self._slot = {code: i for i, code in enumerate(self._axes)}
        # Raw values, held; start at the centre (0 g) until the first event.
        self._declare_instrument(self.profile.period, self._centre.tolist(), estimators,
                                 command_size)

    def _default_centre(self, code: int) -> float:
        absinfo = getattr(self.source, "absinfo", None)
        if absinfo is not None:
            try:
                info = absinfo(code)
                return float((info.min + info.max + 1) // 2)
            except (OSError, AttributeError):
                pass
        return float(2 ** (self.profile.bits - 1))

    def _sample(self, context, state) -> list[float] | None:
        raw = state[:3].tolist()
        slot = self._slot
        for ev_type, code, value in self.source.read_events(context.get_time()):
            if ev_type == EV_ABS and code in slot:
                raw[slot[code]] = value
        state[:3] = raw
        if self.estimators is None:
            return None
        return (self._counts(state[:3]) * self.profile.lsb).tolist()

    def _counts(self, raw) -> np.ndarray:
        lo, hi = self.profile.count_limits
        return np.clip(self._signs * (raw - self._centre), lo, hi)

    def counts(self, context) -> np.ndarray:
        return self._counts(context.get_discrete_state(self._state).get_value()[:3])

    def _calc_counts(self, context, output: BasicVector):
        output.SetFromVector(self.counts(context))

    def _calc_acceleration(self, context, output: BasicVector):
        output.SetFromVector(self.counts(context) * self.profile.lsb)
