"""Pure MIDI translators: control positions <-> ``mido`` messages, no I/O.

Encoding (what the device sends, :class:`ControlEncoder`):

- **fader**: ``control_change`` with the absolute 7-bit position,
  ``value = round(127 * s / travel)`` for a cap at ``s`` in ``[0, travel]`` m.
- **knob / jog wheel**: ``control_change`` with a *relative* tick count. A
  rotary control at angle ``theta`` (rad) sits at tick index
  ``floor(theta * N / 2 pi)`` (``N`` ticks per turn, from the mapping); every
  change of the index is sent as the signed difference, split into messages of
  at most 63 ticks, each encoded by the mapping's ``relative_encoding``
  (:func:`encode_relative`). So the ticks sent since the start always equal
  ``floor(theta N / 2 pi) - floor(theta_0 N / 2 pi)``: the true rotation within
  one tick, in both directions, however fast the wheel turns.
- **button**: ``note_on`` (velocity 127) when pressed deeper than
  ``press_fraction`` of its travel, ``note_off`` (velocity 0) when back above
  ``release_fraction`` (hysteresis, like a real switch's snap action).

Decoding (what a host receives, :class:`MidiDecoder`): every message is
checked against the mapping; what does not fit is **ignored and counted** by
reason (``REJECT_REASONS``) - never raised - so a noisy cable, a wrong preset or
another device on the same port cannot stop a diagram.

``mido`` builds, validates and serialises the messages; this module only adds
the device's conventions (relative encodings, tick counting, the mapping),
which no library has.
"""

from __future__ import annotations

import collections
import dataclasses as dc
import math

import mido
import numpy as np

from handle_drake.devices.midi.mapping import RELATIVE_ENCODINGS, ControlMap, MidiMapping

__all__ = [
    "MAX_RELATIVE_TICKS",
    "REJECT_REASONS",
    "ControlEvent",
    "ControlCounts",
    "ControlEncoder",
    "MidiDecoder",
    "decode_relative",
    "encode_relative",
    "fader_value",
    "control_message",
]

MAX_RELATIVE_TICKS = 63
REJECT_REASONS = (
    "malformed",        # bytes that are not one MIDI message (bad status, data byte > 127, length)
    "sysex",            # system exclusive (the device's firmware chatter, not a control)
    "unknown_channel",  # a channel no control of the mapping uses
    "unknown_control",  # a controller / note number no control of the mapping uses
    "unexpected_type",  # a message type the mapping does not send (pitchwheel, clock, ...)
    "out_of_range",     # a relative value that encodes no tick count (e.g. 0, -0, 64 offset 0)
    "burst",            # beyond the per-update message budget of a receiver
)


def _check_encoding(encoding: str) -> None:
    if encoding not in RELATIVE_ENCODINGS:
        raise ValueError(
            f"relative_encoding: expected one of {list(RELATIVE_ENCODINGS)}, got {encoding!r}"
        )


def encode_relative(ticks: int, encoding: str) -> int:
    """The 7-bit data value of a relative move of ``ticks`` (1 <= |ticks| <= 63)."""
    _check_encoding(encoding)
    if isinstance(ticks, bool) or not isinstance(ticks, int | np.integer):
        raise TypeError(f"ticks: expected an integer, got {type(ticks).__name__}")
    ticks = int(ticks)
    if not 1 <= abs(ticks) <= MAX_RELATIVE_TICKS:
        raise ValueError(f"ticks: expected 1 <= |ticks| <= {MAX_RELATIVE_TICKS}, got {ticks}")
    if encoding == "signed_bit":
        return ticks if ticks > 0 else 64 - ticks
    if encoding == "twos_complement":
        return ticks & 0x7F
    return 64 + ticks  # binary_offset


def decode_relative(value: int, encoding: str) -> int | None:
    """The signed tick count of a relative data value, or None if it encodes none."""
    _check_encoding(encoding)
    value = int(value)
    if not 0 <= value <= 127:
        return None
    if encoding == "signed_bit":
        ticks = value if value < 64 else -(value - 64)
    elif encoding == "twos_complement":
        ticks = value if value < 64 else value - 128
    else:
        ticks = value - 64
    if ticks == 0 or abs(ticks) > MAX_RELATIVE_TICKS:
        return None
    return ticks


def fader_value(position: float, travel: float) -> int:
    """The 7-bit value of a fader cap at ``position`` (m) of ``travel`` (m), clamped."""
    if not (math.isfinite(travel) and travel > 0):
        raise ValueError(f"travel must be a finite number > 0 (m), got {travel}")
    if not math.isfinite(position):
        raise ValueError(f"fader position must be finite, got {position}")
    return int(min(127, max(0, round(127.0 * position / travel))))


def control_message(control: ControlMap, value: int, encoding: str = "signed_bit"):
    """The ``mido.Message`` a control sends: ``value`` is the fader's 7-bit value,
    the signed tick count of a knob or jog, or 1/0 (pressed/released) of a button."""
    if control.kind == "fader":
        return mido.Message("control_change", channel=control.channel, control=control.number,
                            value=int(value))
    if control.relative:
        return mido.Message("control_change", channel=control.channel, control=control.number,
                            value=encode_relative(int(value), encoding))
    if value:
        return mido.Message("note_on", channel=control.channel, note=control.number,
                            velocity=127)
    return mido.Message("note_off", channel=control.channel, note=control.number, velocity=0)


@dc.dataclass(frozen=True)
class ControlEvent:
    """One decoded control event.

    ``value``: a fader's 7-bit value, a knob's or the jog's signed ticks, a
    button's 1 (pressed) or 0 (released).
    """

    name: str
    kind: str
    value: int


class ControlEncoder:
    """Control positions -> the messages the device sends (see module doc).

    Args:
        mapping: the :class:`MidiMapping`.
        names: the controls whose positions :meth:`messages` gets, in order.
        travels: m, per control: a fader's travel, a button's press travel
            (ignored for rotaries).
        initial_positions: m or rad, the positions at start (no message is
            sent for them).
        press_fraction / release_fraction: button hysteresis.
    """

    def __init__(self, mapping: MidiMapping, names, travels, initial_positions=None,
                 press_fraction: float = 0.6, release_fraction: float = 0.4):
        self._mapping = mapping
        self._controls = [mapping.control(n) for n in names]
        self._travels = np.asarray(travels, dtype=float)
        n = len(self._controls)
        if self._travels.shape != (n,):
            raise ValueError(f"travels: expected {n} values, got {self._travels.shape}")
        if not 0.0 < release_fraction < press_fraction < 1.0:
            raise ValueError(
                "button thresholds: expected 0 < release_fraction < press_fraction < 1, got "
                f"{release_fraction}, {press_fraction}"
            )
        self._press, self._release = press_fraction, release_fraction
        kinds = [c.kind for c in self._controls]
        self._kinds = tuple(np.array([i for i, k in enumerate(kinds) if k in group], dtype=int)
                            for group in (("fader",), ("knob", "jog"), ("button",)))
        if np.any(self._travels[np.r_[self._kinds[0], self._kinds[2]]] <= 0):
            raise ValueError("travels: faders and buttons need a travel > 0 (m)")
        self._ticks_per_radian = np.array(
            [mapping.ticks_per_turn(c) / (2 * math.pi) if c.relative else 0.0
             for c in self._controls])[self._kinds[1]]
        self.reset(np.zeros(n) if initial_positions is None else initial_positions)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self._controls]

    def _levels(self, positions, previous=None) -> np.ndarray:
        """Fader values, rotary tick indices and button states of ``positions``."""
        levels = np.empty(len(self._controls), dtype=np.int64)
        faders, rotary, buttons = self._kinds
        if faders.size:
            levels[faders] = np.clip(
                np.round(127.0 * positions[faders] / self._travels[faders]), 0, 127)
        if rotary.size:
            levels[rotary] = np.floor(positions[rotary] * self._ticks_per_radian + 1e-9)
        if buttons.size:
            depth = positions[buttons] / self._travels[buttons]
            pressed = (np.zeros(buttons.size, dtype=bool) if previous is None
                       else np.asarray(previous)[buttons] > 0)
            # Pressed: released only above release_fraction (hysteresis).
            levels[buttons] = np.where(pressed, depth > self._release, depth >= self._press)
        return levels

    def reset(self, positions) -> None:
        """Sets the state to ``positions`` without sending anything."""
        positions = np.asarray(positions, dtype=float)
        if positions.shape != (len(self._controls),) or not np.isfinite(positions).all():
            raise ValueError(
                f"positions: expected {len(self._controls)} finite values, got {positions.shape}"
            )
        self.levels = [int(v) for v in self._levels(positions)]

    def messages(self, positions) -> list:
        """The messages for a change from the last positions to ``positions``
        (non-finite positions keep their control's last level)."""
        levels, out = self.encode(self.levels, positions)
        self.levels = [int(v) for v in levels]
        return out

    def encode(self, previous, positions) -> tuple[np.ndarray, list]:
        """Pure: the levels at ``positions`` and the messages for the change from the
        levels ``previous`` (non-finite positions keep their control's level)."""
        positions = np.asarray(positions, dtype=float)
        previous = np.asarray(previous, dtype=np.int64)
        finite = np.isfinite(positions)
        levels = np.where(finite, self._levels(np.where(finite, positions, 0.0), previous),
                          previous)
        changed = np.nonzero(levels != previous)[0]
        out = []
        encoding = self._mapping.relative_encoding
        for i in changed:
            control = self._controls[i]
            if control.relative:
                change = int(levels[i] - previous[i])
                while change != 0:
                    chunk = max(-MAX_RELATIVE_TICKS, min(MAX_RELATIVE_TICKS, change))
                    out.append(control_message(control, chunk, encoding))
                    change -= chunk
            else:
                out.append(control_message(control, int(levels[i]), encoding))
        return levels, out


class MidiDecoder:
    """Incoming messages -> :class:`ControlEvent` s; bad input counted, never raised.

    ``decode`` takes a ``mido.Message`` or raw bytes (a sequence of ints, as a
    raw-port callback delivers them). ``rejected`` counts the ignored messages
    by reason (``REJECT_REASONS``); ``accepted`` counts the decoded ones.
    """

    def __init__(self, mapping: MidiMapping):
        self._mapping = mapping
        self.accepted = 0
        self.rejected: collections.Counter = collections.Counter()

    @property
    def mapping(self) -> MidiMapping:
        return self._mapping

    def reject(self, reason: str, count: int = 1) -> None:
        self.rejected[reason] += count

    @property
    def total_rejected(self) -> int:
        return sum(self.rejected.values())

    def decode(self, message) -> ControlEvent | None:
        if not isinstance(message, mido.Message):
            try:
                message = mido.Message.from_bytes(list(message))
            except (ValueError, TypeError, KeyError, IndexError):
                self.reject("malformed")
                return None
        kind = message.type
        if kind == "sysex":
            self.reject("sysex")
            return None
        if kind not in ("control_change", "note_on", "note_off"):
            self.reject("unexpected_type")
            return None
        if not self._mapping.has_channel(message.channel):
            self.reject("unknown_channel")
            return None
        if kind == "control_change":
            control = self._mapping.find("control_change", message.channel, message.control)
        else:
            control = self._mapping.find("note", message.channel, message.note)
        if control is None:
            self.reject("unknown_control")
            return None
        if control.kind == "fader":
            value = message.value
        elif control.relative:
            value = decode_relative(message.value, self._mapping.relative_encoding)
            if value is None:
                self.reject("out_of_range")
                return None
        else:
            value = int(kind == "note_on" and message.velocity > 0)
        self.accepted += 1
        return ControlEvent(control.name, control.kind, int(value))


class ControlCounts:
    """What the controls did, accumulated from decoded events (the learner's view).

    ``values`` (one per control of the mapping, in file order): a fader's last
    7-bit value (-1 before any), the net ticks of a knob or the jog, the
    number of presses of a button; ``pressed``: each button's state (1/0).
    Both are plain arrays so a system can keep them in its state.
    """

    def __init__(self, mapping: MidiMapping, values=None, pressed=None):
        self.names = mapping.names()
        self._index = {n: i for i, n in enumerate(self.names)}
        self.values = (np.array([-1.0 if mapping.control(n).kind == "fader" else 0.0
                                 for n in self.names])
                       if values is None else np.array(values, dtype=float))
        self.pressed = (np.zeros(len(self.names)) if pressed is None
                        else np.array(pressed, dtype=float))

    def __getitem__(self, name: str) -> int:
        return int(self.values[self._index[name]])

    def add(self, event: ControlEvent) -> None:
        i = self._index[event.name]
        if event.kind == "fader":
            self.values[i] = event.value
        elif event.kind == "button":
            if event.value and not self.pressed[i]:
                self.values[i] += 1
            self.pressed[i] = float(bool(event.value))
        else:
            self.values[i] += event.value
