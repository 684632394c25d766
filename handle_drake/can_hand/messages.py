"""The hand's CAN messages and pure encode/decode functions (no bus, no I/O).

The messages are declared once, in ``hand.dbc`` (read with cantools):

========  ==================  ====  =========  ==================================
id        name                DLC   direction  signals (little-endian)
========  ==================  ====  =========  ==================================
0x100+i   ``SETPOINT_i``       8    host->hand 4 x int16, 1e-4 rad: command entries 4i..4i+3
0x10F     ``SETPOINT_COMMIT``  4    host->hand SEQ u16, N_FRAMES u8, MODE u8
0x200+i   ``POSITION_i``       8    hand->host 4 x int16, 1e-4 rad: joints 4i..4i+3
0x210+i   ``TACTILE_i``        8    hand->host 4 x uint16, 1e-3 N: pads 4i..4i+3
0x220     ``STATUS``           8    hand->host SEQ_ACK u16, COUNTER u8, STATE u4,
                                               KIND u4, TIME u32 (1e-6 s)
========  ==================  ====  =========  ==================================

Joints are packed four to a frame in :class:`~handle_drake.can_hand.layout.HandLayout`
order: the command in ``actuated_joint_names`` order (Shadow 5 frames,
Barrett 1), the measured positions in ``joint_names`` order (6 / 2 frames),
tactile pads in fingertip order (2 / 1 frames); unused slots are zero. A
command is all setpoint frames followed by one commit, which the hand applies
atomically. Each hand cycle ends with STATUS, which closes a feedback set.

Bandwidth: an 8-byte standard frame is 111 bits plus stuffing (about 130), so
a 1 Mbit/s bus carries about 7,500 frames/s; a full Shadow cycle (9 feedback +
6 command frames) therefore fits about 500 times per second on real CAN. The
simulated buses here have no such limit.

Everything here is pure: :class:`HandCodec` turns vectors into
``(arbitration_id, bytes)`` pairs and back, raising
:class:`ForeignFrameError` for ids that are not the hand's and
:class:`MalformedFrameError` for a wrong length or an undecodable payload.
"""

from __future__ import annotations

import dataclasses as dc
import struct
from functools import cache
from pathlib import Path

import cantools
import numpy as np

from handle_drake.can_hand.layout import HAND_KIND_CODES, HandLayout

__all__ = [
    "DBC_PATH",
    "SETPOINT_BASE_ID",
    "COMMIT_ID",
    "POSITION_BASE_ID",
    "TACTILE_BASE_ID",
    "STATUS_ID",
    "STATE_INIT",
    "STATE_OK",
    "STATE_FAULT",
    "MODE_POSITION",
    "POSITION_SCALE",
    "TACTILE_SCALE",
    "CanFrameError",
    "ForeignFrameError",
    "MalformedFrameError",
    "Frame",
    "FeedbackSnapshot",
    "HandCodec",
    "FeedbackAssembler",
    "SetpointAssembler",
    "load_database",
]

DBC_PATH = Path(__file__).with_name("hand.dbc")

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


@cache
def load_database() -> cantools.database.can.Database:
    """The message database read from ``hand.dbc`` (cached)."""
    return cantools.database.load_file(str(DBC_PATH))


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
    """One complete hand cycle: positions (nq, rad), tactile (N), status fields."""

    q: np.ndarray
    tactile: np.ndarray
    seq_ack: int
    counter: int
    state: int
    hand_time: float  # s, the hand's clock (wraps at 2**32 us)


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
        raw = np.round(values / self.scale)
        low, high = self._raw_range
        if raw.size and (raw.min() < low or raw.max() > high):  # callers clip or check first
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


def _frames_for(n: int) -> int:
    return (n + SLOTS_PER_FRAME - 1) // SLOTS_PER_FRAME


class HandCodec:
    """Encodes and decodes one hand's frames (pure; the layout fixes the sizes).

    Values outside a signal's range (|q| > 3.2767 rad, force outside
    0..65.535 N) raise ``ValueError`` when encoding setpoints; measured values
    are saturated to the representable range, as a sensor would.
    """

    def __init__(self, layout: HandLayout):
        if not isinstance(layout, HandLayout):
            raise TypeError(f"layout: expected a HandLayout, got {type(layout).__name__}")
        self.layout = layout
        db = load_database()
        self.num_setpoint_frames = _frames_for(layout.nu)
        self.num_position_frames = _frames_for(layout.nq)
        self.num_tactile_frames = _frames_for(layout.num_tactile)
        self._setpoints = [db.get_message_by_name(f"SETPOINT_{i}")
                           for i in range(self.num_setpoint_frames)]
        self._positions = [db.get_message_by_name(f"POSITION_{i}")
                           for i in range(self.num_position_frames)]
        self._tactiles = [db.get_message_by_name(f"TACTILE_{i}")
                          for i in range(self.num_tactile_frames)]
        self._commit = db.get_message_by_name("SETPOINT_COMMIT")
        self._status = db.get_message_by_name("STATUS")
        self._by_id = {}
        for i, m in enumerate(self._setpoints):
            self._by_id[m.frame_id] = ("setpoint", i, m)
        for i, m in enumerate(self._positions):
            self._by_id[m.frame_id] = ("position", i, m)
        for i, m in enumerate(self._tactiles):
            self._by_id[m.frame_id] = ("tactile", i, m)
        self._by_id[COMMIT_ID] = ("commit", 0, self._commit)
        self._by_id[STATUS_ID] = ("status", 0, self._status)
        self._q_limit = float(self._positions[0].signals[0].maximum)
        self._f_limit = float(self._tactiles[0].signals[0].maximum)
        self._packed = {m.frame_id: _PackedMessage(m) for m in
                        self._setpoints + self._positions + self._tactiles + [self._commit]}
        self._setpoint_frames = _SlotFrames(self._setpoints)
        self._position_frames = _SlotFrames(self._positions)
        self._tactile_frames = _SlotFrames(self._tactiles)
        self._status_struct = _StatusStruct(self._status)
        self._host_to_hand_ids = frozenset([m.frame_id for m in self._setpoints] + [COMMIT_ID])
        self._hand_to_host_ids = frozenset(
            [m.frame_id for m in self._positions + self._tactiles] + [STATUS_ID])

    # -- ids -------------------------------------------------------------
    @property
    def host_to_hand_ids(self) -> frozenset[int]:
        return self._host_to_hand_ids

    @property
    def hand_to_host_ids(self) -> frozenset[int]:
        return self._hand_to_host_ids

    # -- host -> hand -----------------------------------------------------
    def encode_setpoints(self, q_command, seq: int, mode: int = MODE_POSITION):
        """The frames of one command: ``[(id, data), ...]``, setpoints then commit.

        Args:
            q_command: nu positions (rad) in ``actuated_joint_names`` order.
            seq: command sequence number (taken modulo 2**16).
        """
        q = _checked(q_command, self.layout.nu, "q_command")
        if np.any(np.abs(q) > self._q_limit):
            raise ValueError(
                f"q_command: |q| must be <= {self._q_limit} rad to fit a setpoint frame, "
                f"got {q[np.abs(q) > self._q_limit].tolist()}"
            )
        frames = self._setpoint_frames.encode(q)
        frames.append((COMMIT_ID, self._packed[COMMIT_ID].encode(
            (int(seq) % 65536, self.num_setpoint_frames, int(mode)))))
        return frames

    # -- hand -> host -----------------------------------------------------
    def encode_feedback(self, q, tactile, seq_ack: int, counter: int, state: int,
                        hand_time: float):
        """One hand cycle's frames: positions, tactile, then STATUS.

        ``q`` (nq, rad) and ``tactile`` (N) are saturated to the frame ranges.
        ``hand_time`` (s) wraps at 2**32 microseconds.
        """
        q = np.clip(_checked(q, self.layout.nq, "q"), -self._q_limit, self._q_limit)
        f = np.clip(_checked(tactile, self.layout.num_tactile, "tactile"), 0.0, self._f_limit)
        frames = self._position_frames.encode(q) + self._tactile_frames.encode(f)
        status = self._status_struct
        if not 0 <= int(state) <= 15:
            raise ValueError(f"state: expected 0..15, got {state}")
        time_raw = int(round(hand_time / status.time_scale)) % (1 << 32)
        frames.append((STATUS_ID, status.encode(int(seq_ack) % 65536, int(counter) % 256,
                                                int(state), self.layout.kind_code, time_raw)))
        return frames

    # -- decoding -----------------------------------------------------------
    def decode(self, arbitration_id: int, data: bytes) -> Frame:
        """Decodes one frame of this hand.

        Raises:
            ForeignFrameError: the id is not one of this hand's messages.
            MalformedFrameError: the length differs from the DBC's or the
                payload cannot be decoded (e.g. an unknown hand kind).
        """
        entry = self._by_id.get(arbitration_id)
        if entry is None:
            raise ForeignFrameError(
                f"id 0x{arbitration_id:X} is not a {self.layout.kind} hand message")
        kind, index, message = entry
        data = bytes(data)
        if len(data) != message.length:
            raise MalformedFrameError(
                f"{message.name}: expected {message.length} data bytes, got {len(data)}"
            )
        packed = self._packed.get(arbitration_id)
        if packed is not None:
            values = packed.decode(data)
            if kind == "commit":
                return Frame(kind, index, dict(zip(packed.names, map(int, values), strict=True)))
            return Frame(kind, index, values)
        fields = self._status_struct.decode(data)  # the only message without a packed form
        if fields["KIND"] != self.layout.kind_code:
            names = {v: k for k, v in HAND_KIND_CODES.items()}
            raise MalformedFrameError(
                f"STATUS: hand kind {names.get(fields['KIND'], fields['KIND'])!r}, "
                f"expected {self.layout.kind!r}"
            )
        return Frame(kind, index, fields)


def _checked(value, size: int, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name}: expected {size} values, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, got {array.tolist()}")
    return array


class FeedbackAssembler:
    """Collects POSITION/TACTILE frames until STATUS closes a complete cycle.

    :meth:`push` returns a :class:`FeedbackSnapshot` when a STATUS arrives and
    every position frame of this cycle has been seen (tactile frames keep their
    last value when missing); otherwise None. ``incomplete`` counts STATUS
    frames dropped because positions were missing.
    """

    def __init__(self, codec: HandCodec):
        self._codec = codec
        layout = codec.layout
        self._q = np.zeros(codec.num_position_frames * SLOTS_PER_FRAME)
        self._f = np.zeros(codec.num_tactile_frames * SLOTS_PER_FRAME)
        self._seen = np.zeros(codec.num_position_frames, dtype=bool)
        self._nq, self._nt = layout.nq, layout.num_tactile
        self.incomplete = 0

    def push(self, frame: Frame) -> FeedbackSnapshot | None:
        k = SLOTS_PER_FRAME
        if frame.kind == "position":
            self._q[frame.index * k:(frame.index + 1) * k] = frame.values
            self._seen[frame.index] = True
        elif frame.kind == "tactile":
            self._f[frame.index * k:(frame.index + 1) * k] = frame.values
        elif frame.kind == "status":
            complete = bool(self._seen.all())
            self._seen[:] = False
            if not complete:
                self.incomplete += 1
                return None
            v = frame.values
            return FeedbackSnapshot(
                q=self._q[:self._nq].copy(), tactile=self._f[:self._nt].copy(),
                seq_ack=v["SEQ_ACK"], counter=v["COUNTER"], state=v["STATE"],
                hand_time=v["TIME"],
            )
        return None


class SetpointAssembler:
    """The hand's side: stages SETPOINT frames and applies them on COMMIT.

    :meth:`push` returns ``(seq, q_command)`` when a commit arrives whose
    N_FRAMES matches and all setpoint frames were received since the previous
    commit; otherwise None (``rejected_commits`` counts those).
    """

    def __init__(self, codec: HandCodec):
        self._codec = codec
        self._q = np.zeros(codec.num_setpoint_frames * SLOTS_PER_FRAME)
        self._seen = np.zeros(codec.num_setpoint_frames, dtype=bool)
        self._nu = codec.layout.nu
        self.rejected_commits = 0

    def push(self, frame: Frame):
        k = SLOTS_PER_FRAME
        if frame.kind == "setpoint":
            self._q[frame.index * k:(frame.index + 1) * k] = frame.values
            self._seen[frame.index] = True
        elif frame.kind == "commit":
            complete = bool(self._seen.all())
            self._seen[:] = False
            if not complete or frame.values["N_FRAMES"] != self._codec.num_setpoint_frames:
                self.rejected_commits += 1
                return None
            return frame.values["SEQ"], self._q[:self._nu].copy()
        return None
