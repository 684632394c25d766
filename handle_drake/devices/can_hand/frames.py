"""What both CAN layouts share: the DBC files, ids, frame errors, and struct-compiled messages.

Pure (no bus, no I/O); the layouts themselves are described in
:mod:`handle_drake.devices.can_hand.messages`.
"""

from __future__ import annotations

import dataclasses as dc
import struct
from functools import cache
from pathlib import Path

import cantools
import numpy as np

from handle_drake.devices.can_hand.config import FRAME_FORMATS

DBC_PATH = Path(__file__).with_name("hand.dbc")
DBC_PATHS = {"classic": DBC_PATH, "fd": Path(__file__).with_name("hand_fd.dbc")}
#: The data lengths a CAN FD frame can have (DLC codes 0..15).
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)

SETPOINT_BASE_ID = 0x100
COMMIT_ID = 0x10F
POSITION_BASE_ID = 0x200
TACTILE_BASE_ID = 0x210
STATUS_ID = 0x220
STATE_INIT, STATE_OK, STATE_FAULT = 0, 1, 2
MODE_POSITION = 0
SLOTS_PER_FRAME = 4


class CanFrameError(ValueError):
    """A CAN frame the hand interface does not accept."""


class ForeignFrameError(CanFrameError):
    """The arbitration id is not one of the hand's messages."""


class MalformedFrameError(CanFrameError):
    """A hand message id with a wrong length or an undecodable payload."""


class FrameFormatError(MalformedFrameError):
    """A frame of the other layout or format: CAN FD on the classic layout, or vice versa."""


def _check_format(frame_format: str) -> str:
    if frame_format not in FRAME_FORMATS:
        raise ValueError(f"frame_format: expected one of {list(FRAME_FORMATS)}, "
                         f"got {frame_format!r}")
    return frame_format


@cache
def load_database(frame_format: str = "classic") -> cantools.database.can.Database:
    """The message database of a layout: ``hand.dbc`` (classic) or ``hand_fd.dbc`` (cached)."""
    return cantools.database.load_file(str(DBC_PATHS[_check_format(frame_format)]))


@cache
def _database_ids(frame_format: str) -> frozenset[int]:
    return frozenset(m.frame_id for m in load_database(frame_format).messages)


def _scale(message_name: str) -> float:
    return float(load_database().get_message_by_name(message_name).signals[0].scale)


POSITION_SCALE = _scale("POSITION_0")  # rad per count
TACTILE_SCALE = _scale("TACTILE_0")  # N per count


@dc.dataclass(frozen=True)
class Frame:
    """One decoded hand frame.

    ``kind`` is "setpoint", "commit", "position", "tactile" or "status";
    ``index`` is the frame's number within its kind (0 for commit/status);
    ``values`` holds the physical values (4 slots) or the named fields.
    """

    kind: str
    index: int
    values: tuple | dict


@dc.dataclass(frozen=True)
class FeedbackSnapshot:
    """One complete hand cycle: positions (nq, rad), tactile (N), status fields.

    ``counter`` is the classic STATUS cycle counter (None on the FD layout,
    whose frame has none: TIME shows lost cycles); ``hand_time`` is the hand's
    clock, wrapping at the codec's ``time_wrap``.
    """

    q: np.ndarray
    tactile: np.ndarray
    seq_ack: int
    counter: int | None
    state: int
    hand_time: float  # s


class _PackedMessage:
    """A DBC message of byte-aligned little-endian integer signals, compiled to a struct.

    cantools reads the declaration and stays the reference; its per-frame
    encode costs ~4-20 us in Python, a struct pack about 1 us, and a Shadow
    hand cycle is 15 frames at up to 1 kHz. The struct is built from the DBC's
    own start bits, lengths, signedness and scales (checked here); the tests
    compare both paths bit for bit.
    """

    _CODES = {(8, False): "B", (8, True): "b", (16, False): "H", (16, True): "h",
              (32, False): "I", (32, True): "i"}

    def __init__(self, message):
        signals = sorted(message.signals, key=lambda sig: sig.start)
        fmt, bit = "<", 0
        for sig in signals:
            code = self._CODES.get((sig.length, sig.is_signed))
            if (sig.byte_order != "little_endian" or sig.start != bit or code is None
                    or sig.offset != 0 or sig.is_float):
                raise ValueError(f"{message.name}.{sig.name}: not a byte-aligned integer signal")
            fmt += code
            bit += sig.length
        if bit != 8 * message.length:
            raise ValueError(f"{message.name}: signals cover {bit} of {8 * message.length} bits")
        self.name = message.name
        self.frame_id = message.frame_id
        self.length = message.length
        self.names = tuple(sig.name for sig in signals)
        self.scales = tuple(float(sig.scale) for sig in signals)
        self._struct = struct.Struct(fmt)

    def encode(self, values) -> bytes:
        return self._struct.pack(*[round(v / k) for v, k in zip(values, self.scales, strict=True)])

    def decode(self, data: bytes) -> tuple[float, ...]:
        return tuple(raw * k for raw, k in zip(self._struct.unpack(data), self.scales, strict=True))


class _SlotFrames:
    """A run of DBC messages (``<NAME>_0``, ``<NAME>_1``, ...) of 4 equal 16-bit slots each.

    Encodes a whole vector in one numpy pass (one rounding, one cast, one
    ``tobytes``) instead of a struct pack per frame: a Shadow cycle has 6
    position frames, and a 1 kHz hand cycle leaves little room per frame.
    Built from the messages' own declarations (checked equal across the run,
    and by :class:`_PackedMessage`); rounds half to even like Python's
    ``round``, so the bytes equal the per-frame path's.
    """

    def __init__(self, messages):
        packed = [_PackedMessage(m) for m in messages]
        first = messages[0].signals[0]
        layout = [(s.length, s.is_signed, float(s.scale)) for m in messages for s in m.signals]
        if any(entry != (16, first.is_signed, float(first.scale)) for entry in layout) or any(
                len(m.signals) != SLOTS_PER_FRAME for m in messages):
            raise ValueError(f"{messages[0].name}...: expected {SLOTS_PER_FRAME} equal 16-bit "
                             "signals per frame")
        self.ids = tuple(m.frame_id for m in messages)
        self.scale = float(first.scale)
        self._dtype = np.dtype("<i2" if first.is_signed else "<u2")
        info = np.iinfo(self._dtype)
        self._raw_range = (info.min, info.max)
        self._size = len(messages) * SLOTS_PER_FRAME
        self._packed = packed

    def encode(self, values: np.ndarray) -> list[tuple[int, bytes]]:
        """``[(id, 8 bytes), ...]`` of ``values`` (at most 4 per frame, zero-padded)."""
        # np.rint is np.round's decimals=0 path (half to even) without its Python
        # wrapper; the ufunc reductions likewise (a few us a call at 1 kHz per frame run).
        raw = np.rint(values / self.scale)
        low, high = self._raw_range
        if raw.size and (_min(raw) < low or _max(raw) > high):  # callers clip or check first
            raise ValueError(f"values out of the frame range {low * self.scale}.."
                             f"{high * self.scale}, got {values.tolist()}")
        data = raw.astype(self._dtype).tobytes() + bytes(2 * (self._size - raw.size))
        return [(frame_id, data[8 * i:8 * i + 8]) for i, frame_id in enumerate(self.ids)]


class _StatusStruct:
    """STATUS (SEQ_ACK u16, COUNTER u8, STATE u4, KIND u4, TIME u32 us) as one struct.

    The two nibbles are not byte-aligned, so :class:`_PackedMessage` does not
    apply; the layout is checked against the DBC here, and the tests compare
    both directions with cantools bit for bit.
    """

    _LAYOUT = (("SEQ_ACK", 0, 16), ("COUNTER", 16, 8), ("STATE", 24, 4), ("KIND", 28, 4),
               ("TIME", 32, 32))

    def __init__(self, message):
        found = tuple((s.name, s.start, s.length) for s in sorted(message.signals,
                                                                   key=lambda s: s.start))
        if found != self._LAYOUT or message.length != 8 or any(
                s.is_signed or s.offset != 0 or s.byte_order != "little_endian"
                for s in message.signals):
            raise ValueError(f"STATUS: expected the layout {self._LAYOUT}, got {found}")
        self.time_scale = float(message.get_signal_by_name("TIME").scale)
        self._struct = struct.Struct("<HBBI")

    def encode(self, seq_ack: int, counter: int, state: int, kind: int, time_raw: int) -> bytes:
        return self._struct.pack(seq_ack, counter, (kind << 4) | state, time_raw)

    def decode(self, data: bytes) -> dict:
        seq_ack, counter, nibbles, time_raw = self._struct.unpack(data)
        return {"SEQ_ACK": seq_ack, "COUNTER": counter, "STATE": nibbles & 0xF,
                "KIND": nibbles >> 4, "TIME": time_raw * self.time_scale}


_min, _max = np.minimum.reduce, np.maximum.reduce


def _frames_for(n: int) -> int:
    return (n + SLOTS_PER_FRAME - 1) // SLOTS_PER_FRAME


class _CodecIds:
    """The ids a codec accepts in each direction (both layouts), and the feedback's
    values saturated to its frame ranges."""

    _host_to_hand_ids: frozenset[int]
    _hand_to_host_ids: frozenset[int]
    _q_limit: float
    _f_limit: float

    def _saturated(self, q, tactile) -> tuple[np.ndarray, np.ndarray]:
        """``q`` (nq) to +-the position range, ``tactile`` to 0..the force range (checked
        finite; np.minimum/np.maximum: np.clip's values without its wrappers)."""
        q = np.minimum(np.maximum(_checked(q, self.layout.nq, "q"), -self._q_limit),
                       self._q_limit)
        f = np.minimum(np.maximum(_checked(tactile, self.layout.num_tactile, "tactile"), 0.0),
                       self._f_limit)
        return q, f

    @property
    def host_to_hand_ids(self) -> frozenset[int]:
        return self._host_to_hand_ids

    @property
    def hand_to_host_ids(self) -> frozenset[int]:
        return self._hand_to_host_ids



def _checked(value, size: int, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name}: expected {size} values, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, got {array.tolist()}")
    return array
