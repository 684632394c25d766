"""The hand's CAN messages and pure encode/decode functions (no bus, no I/O).

Two layouts (``frame_format``), each declared once in a DBC read with cantools.

**fd** (``hand_fd.dbc``, the default): CAN FD frames (64-byte data field;
1 Mbit/s arbitration, 5 Mbit/s data with bit-rate switching), one frame per
direction per hand cycle, one pair of messages per hand:

========  ====================  =====  ==========  ===================================
id        name                  DLC    direction   signals (little-endian)
========  ====================  =====  ==========  ===================================
0x140     ``SHADOW_SETPOINT``   48     host->hand  SEQ u16, MODE u8, (reserved u8),
0x141     ``BARRETT_SETPOINT``  12                 ``SP_<joint>`` int16 1e-4 rad x nu
0x240     ``SHADOW_FEEDBACK``   64     hand->host  SEQ_ACK u16, STATE u4, KIND u4,
0x241     ``BARRETT_FEEDBACK``  32                 TIME u24 (1e-6 s), ``Q_<joint>`` int16
                                                   1e-4 rad x nq, ``F<k>`` u16 1e-3 N x nt
========  ====================  =====  ==========  ===================================

A setpoint frame carries the whole command and its sequence number, so it is
applied atomically on receipt (no commit frame); a feedback frame is the
whole hand cycle, acknowledgement included. Unused bytes up to the next valid
FD length are zero. The signal names carry the joint names; the codec checks
them against the hand model's order.

**classic** (``hand.dbc``): 8-byte CAN 2.0 frames, four 16-bit values each:

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

Bus time (:func:`frame_time`, :func:`cycle_bus_time`): a classic 8-byte
standard frame is 111 bits unstuffed and up to 135 with bit stuffing, about
125 us at 1 Mbit/s. A classic Shadow cycle (6 command + 9 feedback frames)
needs 1.6-2.0 ms of bus time, so a real 1 Mbit/s classic bus carries at most
about 500-600 Shadow cycles per second: a 1 kHz Shadow loop is physically
impossible there (the Barrett's 6 frames take 0.6-0.8 ms, 60-80 % of the bus
at 1 kHz). In CAN FD at 1/5 Mbit/s the Shadow cycle (48 + 64 bytes) takes
about 0.25-0.31 ms and the Barrett's (12 + 32 bytes) about 0.14-0.17 ms. The
simulated buses (virtual, udp_multicast) have no such limit.

Everything here is pure: :func:`make_codec` gives a :class:`HandCodec`
(classic) or :class:`FdHandCodec` (fd); both turn vectors into
``[(arbitration_id, bytes), ...]`` and, through the receivers of
:meth:`HandCodec.feedback_receiver` / :meth:`HandCodec.setpoint_receiver`,
raw frames back into hand cycles and commands, raising
:class:`ForeignFrameError` for ids that are not the hand's,
:class:`FrameFormatError` for a frame of the other layout or format (a CAN FD
frame on the classic layout, a classic frame on the FD layout) and
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
    "DBC_PATHS",
    "FRAME_FORMATS",
    "FD_LENGTHS",
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
    "FrameFormatError",
    "Frame",
    "FeedbackSnapshot",
    "HandCodec",
    "FeedbackAssembler",
    "SetpointAssembler",
    "FdHandCodec",
    "FdFeedbackDecoder",
    "FdSetpointDecoder",
    "make_codec",
    "load_database",
    "frame_time",
    "cycle_bus_time",
]

DBC_PATH = Path(__file__).with_name("hand.dbc")
FRAME_FORMATS = ("classic", "fd")
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


class _CodecIds:
    """The ids a codec accepts in each direction (both layouts)."""

    _host_to_hand_ids: frozenset[int]
    _hand_to_host_ids: frozenset[int]

    @property
    def host_to_hand_ids(self) -> frozenset[int]:
        return self._host_to_hand_ids

    @property
    def hand_to_host_ids(self) -> frozenset[int]:
        return self._hand_to_host_ids


class HandCodec(_CodecIds):
    """Encodes and decodes one hand's frames on the classic layout (pure).

    The layout fixes the sizes. Values outside a signal's range
    (|q| > 3.2767 rad, force outside 0..65.535 N) raise ``ValueError`` when
    encoding setpoints; measured values are saturated to the representable
    range, as a sensor would.
    """

    frame_format = "classic"
    is_fd = False
    #: s, the STATUS TIME field wraps here (2**32 us).
    time_wrap = float(1 << 32) * 1e-6

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
    def cycle_frame_lengths(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Data bytes of the frames of one command and of one hand cycle."""
        out = [m.length for m in self._setpoints] + [self._commit.length]
        back = [m.length for m in self._positions + self._tactiles] + [self._status.length]
        return tuple(out), tuple(back)

    def feedback_receiver(self) -> FeedbackAssembler:
        """The host's side: raw frames in, one :class:`FeedbackSnapshot` per complete cycle."""
        return FeedbackAssembler(self)

    def setpoint_receiver(self) -> SetpointAssembler:
        """The hand's side: raw frames in, ``(seq, q_command)`` per applied commit."""
        return SetpointAssembler(self)

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
            if arbitration_id in _database_ids("fd"):
                raise FrameFormatError(f"id 0x{arbitration_id:X} is a CAN FD layout message; "
                                       "this bus runs the classic layout")
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


class _ClassicReceiver:
    """Raw frames of the classic layout in: the checks both directions share."""

    def __init__(self, codec: HandCodec):
        self._codec = codec
        self._decode = codec.decode
        self._classic_ids = codec.hand_to_host_ids | codec.host_to_hand_ids

    def feed(self, arbitration_id: int, data: bytes, is_fd: bool = False):
        """Decodes and pushes one raw frame (see :meth:`HandCodec.decode` for the errors).

        Raises:
            FrameFormatError: a CAN FD frame with one of the classic ids.
        """
        if is_fd and arbitration_id in self._classic_ids:
            raise FrameFormatError(f"id 0x{arbitration_id:X}: a CAN FD frame; the classic "
                                   "layout sends CAN 2.0 frames")
        return self.push(self._decode(arbitration_id, data))


class FeedbackAssembler(_ClassicReceiver):
    """Collects POSITION/TACTILE frames until STATUS closes a complete cycle.

    :meth:`push` returns a :class:`FeedbackSnapshot` when a STATUS arrives and
    every position frame of this cycle has been seen (tactile frames keep their
    last value when missing); otherwise None. ``incomplete`` counts STATUS
    frames dropped because positions were missing.
    """

    def __init__(self, codec: HandCodec):
        super().__init__(codec)
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


class SetpointAssembler(_ClassicReceiver):
    """The hand's side: stages SETPOINT frames and applies them on COMMIT.

    :meth:`push` returns ``(seq, q_command)`` when a commit arrives whose
    N_FRAMES matches and all setpoint frames were received since the previous
    commit; otherwise None (``rejected_commits`` counts those).
    """

    def __init__(self, codec: HandCodec):
        super().__init__(codec)
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


# -- CAN FD layout -------------------------------------------------------------------------

def _expect_signals(message, expected) -> None:
    """ValueError unless ``message`` holds exactly ``expected`` (name, start, length, signed)."""
    found = [(s.name, s.start, s.length, s.is_signed)
             for s in sorted(message.signals, key=lambda s: s.start)]
    if found != list(expected):
        diff = next(((f, e) for f, e in zip(found, expected, strict=False) if f != e),
                    (len(found), len(expected)))
        raise ValueError(f"{message.name}: the DBC's signals do not match the hand layout "
                         f"(found, expected): {diff}")
    for s in message.signals:
        if s.byte_order != "little_endian" or s.offset != 0 or s.is_float:
            raise ValueError(f"{message.name}.{s.name}: expected a little-endian integer")
    if not message.is_fd or message.length not in FD_LENGTHS:
        raise ValueError(f"{message.name}: expected a CAN FD message of a valid FD length")
    if expected[-1][1] + expected[-1][2] > 8 * message.length:
        raise ValueError(f"{message.name}: signals do not fit {message.length} bytes")


def _common_scale(message, prefix: str) -> float:
    scales = {float(s.scale) for s in message.signals if s.name.startswith(prefix)}
    if len(scales) != 1:
        raise ValueError(f"{message.name}: expected one scale for {prefix}*, got {scales}")
    return scales.pop()


class FdHandCodec(_CodecIds):
    """Encodes and decodes one hand's frames on the CAN FD layout (pure).

    One ``<HAND>_SETPOINT`` frame per command, one ``<HAND>_FEEDBACK`` frame
    per hand cycle (``hand_fd.dbc``). Same units, limits and saturation as
    :class:`HandCodec`, and the same :meth:`encode_setpoints` /
    :meth:`encode_feedback` / receiver interface, so the server and the
    firmware do not depend on the layout. The frames are packed with
    ``struct`` and numpy from offsets read and checked from the DBC (cantools'
    per-frame encode is the reference in the tests, bit for bit).
    """

    frame_format = "fd"
    is_fd = True

    def __init__(self, layout: HandLayout):
        if not isinstance(layout, HandLayout):
            raise TypeError(f"layout: expected a HandLayout, got {type(layout).__name__}")
        self.layout = layout
        db = load_database("fd")
        name = layout.kind.upper()
        sp = db.get_message_by_name(f"{name}_SETPOINT")
        fb = db.get_message_by_name(f"{name}_FEEDBACK")
        nq, nu, nt = layout.nq, layout.nu, layout.num_tactile
        _expect_signals(sp, [("SEQ", 0, 16, False), ("MODE", 16, 8, False)]
                        + [(f"SP_{j}", 32 + 16 * i, 16, True)
                           for i, j in enumerate(layout.actuated_joint_names)])
        _expect_signals(fb, [("SEQ_ACK", 0, 16, False), ("STATE", 16, 4, False),
                             ("KIND", 20, 4, False), ("TIME", 24, 24, False)]
                        + [(f"Q_{j}", 48 + 16 * i, 16, True)
                           for i, j in enumerate(layout.joint_names)]
                        + [(f"F{k}", 48 + 16 * (nq + k), 16, False) for k in range(nt)])
        self.setpoint_message, self.feedback_message = sp, fb
        self.setpoint_id, self.feedback_id = sp.frame_id, fb.frame_id
        self.position_scale = _common_scale(sp, "SP_")
        if _common_scale(fb, "Q_") != self.position_scale:
            raise ValueError(f"{fb.name}: positions and setpoints must share one scale")
        self.tactile_scale = _common_scale(fb, "F")
        self.time_scale = float(fb.get_signal_by_name("TIME").scale)
        self.time_wrap = float(1 << 24) * self.time_scale
        self._q_limit = float(fb.get_signal_by_name(f"Q_{layout.joint_names[0]}").maximum)
        self._f_limit = float(fb.get_signal_by_name("F0").maximum) if nt else 0.0
        self._sp_head = struct.Struct("<HBx")  # SEQ, MODE, reserved byte
        self._fb_head = struct.Struct("<HB")  # SEQ_ACK, STATE | KIND << 4; TIME follows
        self._sp_pad = bytes(sp.length - 4 - 2 * nu)
        self._fb_pad = bytes(fb.length - 6 - 2 * nq - 2 * nt)
        self._host_to_hand_ids = frozenset([self.setpoint_id])
        self._hand_to_host_ids = frozenset([self.feedback_id])
        self._classic_ids = _database_ids("classic")

    @property
    def cycle_frame_lengths(self) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """Data bytes of the frames of one command and of one hand cycle."""
        return (self.setpoint_message.length,), (self.feedback_message.length,)

    def feedback_receiver(self) -> FdFeedbackDecoder:
        return FdFeedbackDecoder(self)

    def setpoint_receiver(self) -> FdSetpointDecoder:
        return FdSetpointDecoder(self)

    def check_id(self, arbitration_id: int) -> None:
        """Nothing for this hand's ids; FrameFormatError or ForeignFrameError otherwise."""
        if arbitration_id in self._host_to_hand_ids or arbitration_id in self._hand_to_host_ids:
            return
        if arbitration_id in self._classic_ids:
            raise FrameFormatError(f"id 0x{arbitration_id:X} is a classic layout message; "
                                   "this bus runs the fd layout")
        raise ForeignFrameError(
            f"id 0x{arbitration_id:X} is not a {self.layout.kind} hand message")

    # -- host -> hand -----------------------------------------------------
    def encode_setpoints(self, q_command, seq: int, mode: int = MODE_POSITION):
        """``[(id, data)]``: one frame with the whole command (rad, command order) and ``seq``."""
        q = _checked(q_command, self.layout.nu, "q_command")
        if np.any(np.abs(q) > self._q_limit):
            raise ValueError(
                f"q_command: |q| must be <= {self._q_limit} rad to fit a setpoint frame, "
                f"got {q[np.abs(q) > self._q_limit].tolist()}"
            )
        raw = np.round(q / self.position_scale).astype("<i2")
        return [(self.setpoint_id, self._sp_head.pack(int(seq) % 65536, int(mode))
                 + raw.tobytes() + self._sp_pad)]

    # -- hand -> host -----------------------------------------------------
    def encode_feedback(self, q, tactile, seq_ack: int, counter: int, state: int,
                        hand_time: float):
        """``[(id, data)]``: one frame with the whole hand cycle.

        Same arguments as :meth:`HandCodec.encode_feedback`; ``counter`` has no
        field here (the TIME stamps show lost cycles). ``hand_time`` (s) wraps
        at 2**24 microseconds (16.8 s).
        """
        q = np.clip(_checked(q, self.layout.nq, "q"), -self._q_limit, self._q_limit)
        f = np.clip(_checked(tactile, self.layout.num_tactile, "tactile"), 0.0, self._f_limit)
        if not 0 <= int(state) <= 15:
            raise ValueError(f"state: expected 0..15, got {state}")
        time_raw = int(round(hand_time / self.time_scale)) % (1 << 24)
        data = (self._fb_head.pack(int(seq_ack) % 65536, (self.layout.kind_code << 4) | int(state))
                + time_raw.to_bytes(3, "little")
                + np.round(q / self.position_scale).astype("<i2").tobytes()
                + np.round(f / self.tactile_scale).astype("<u2").tobytes() + self._fb_pad)
        return [(self.feedback_id, data)]


class _FdDecoder:
    """One direction of the FD layout: the id, name and length of its message."""

    def __init__(self, codec, message):
        self._codec = codec
        self._id = message.frame_id
        self._name = message.name
        self._length = message.length

    def _is_mine(self, arbitration_id: int, data: bytes, is_fd: bool) -> bool:
        """True for a well-formed frame of this message; False for the layout's
        other direction; raises for foreign ids, CAN 2.0 frames and wrong
        lengths (the receiver counts each kind)."""
        if arbitration_id != self._id:
            self._codec.check_id(arbitration_id)
            return False
        if not is_fd:
            raise FrameFormatError(f"{self._name}: a CAN 2.0 frame; the fd layout sends CAN "
                                   "FD frames")
        if len(data) != self._length:
            raise MalformedFrameError(
                f"{self._name}: expected {self._length} data bytes, got {len(data)}")
        return True


class FdFeedbackDecoder(_FdDecoder):
    """The host's side of the FD layout: one feedback frame is one :class:`FeedbackSnapshot`.

    :meth:`feed` returns the snapshot, None for the hand's other (host-to-hand)
    ids, and raises :class:`ForeignFrameError`, :class:`FrameFormatError` (a
    classic frame, or a classic layout id) or :class:`MalformedFrameError`
    (length, hand kind). ``incomplete`` is always 0 (a cycle is one frame).
    """

    incomplete = 0

    def __init__(self, codec: FdHandCodec):
        super().__init__(codec, codec.feedback_message)
        self._nq, self._nt = codec.layout.nq, codec.layout.num_tactile
        self._f_offset = 6 + 2 * self._nq
        self._kind = codec.layout.kind_code
        self._head = codec._fb_head
        self._scales = codec.position_scale, codec.tactile_scale, codec.time_scale

    def feed(self, arbitration_id: int, data: bytes, is_fd: bool = True):
        if not self._is_mine(arbitration_id, data, is_fd):
            return None
        seq_ack, nibbles = self._head.unpack_from(data)
        if nibbles >> 4 != self._kind:
            names = {v: k for k, v in HAND_KIND_CODES.items()}
            raise MalformedFrameError(f"{self._name}: hand kind "
                                      f"{names.get(nibbles >> 4, nibbles >> 4)!r}, expected "
                                      f"{self._codec.layout.kind!r}")
        q_scale, f_scale, t_scale = self._scales
        return FeedbackSnapshot(
            q=np.frombuffer(data, "<i2", self._nq, 6) * q_scale,
            tactile=np.frombuffer(data, "<u2", self._nt, self._f_offset) * f_scale,
            seq_ack=seq_ack, counter=None, state=nibbles & 0xF,
            hand_time=int.from_bytes(data[3:6], "little") * t_scale)


class FdSetpointDecoder(_FdDecoder):
    """The hand's side of the FD layout: one setpoint frame is one applied command.

    :meth:`feed` returns ``(seq, q_command)``, None for the hand's own
    (hand-to-host) ids, and raises like :meth:`FdFeedbackDecoder.feed`.
    ``rejected_commits`` is always 0 (a command cannot arrive half).
    """

    rejected_commits = 0

    def __init__(self, codec: FdHandCodec):
        super().__init__(codec, codec.setpoint_message)
        self._nu = codec.layout.nu
        self._head = codec._sp_head
        self._scale = codec.position_scale

    def feed(self, arbitration_id: int, data: bytes, is_fd: bool = True):
        if not self._is_mine(arbitration_id, data, is_fd):
            return None
        seq, _mode = self._head.unpack_from(data)
        return seq, np.frombuffer(data, "<i2", self._nu, 4) * self._scale


def make_codec(layout: HandLayout, frame_format: str = "fd") -> HandCodec | FdHandCodec:
    """The codec of ``frame_format`` ("classic": :class:`HandCodec`, "fd": :class:`FdHandCodec`)."""
    if _check_format(frame_format) == "fd":
        return FdHandCodec(layout)
    return HandCodec(layout)


# -- bus time ---------------------------------------------------------------------------------

def frame_time(data_bytes: int, fd: bool, nominal_bitrate: float = 1e6,
               data_bitrate: float = 5e6, worst_case_stuffing: bool = False) -> float:
    """Seconds one standard-id data frame occupies the bus, interframe space included.

    Classic CAN 2.0A: ``47 + 8 s`` bits, plus up to ``floor((33 + 8 s) / 4)``
    stuff bits (Davis, Burns, Bril, Lukkien 2007: 111 / 135 bits for 8 bytes).
    CAN FD with bit-rate switching (ISO 11898-1:2015 field lengths): 30 bits
    at the nominal rate (SOF, id, RRS, IDE, FDF, res, BRS; CRC delimiter,
    ACK, ACK delimiter, EOF, IFS) and at the data rate ESI, DLC, the data,
    the 4-bit stuff count, the CRC (17 bits up to 16 data bytes, 21 above) and
    its fixed stuff bits (6 or 7). ``worst_case_stuffing`` adds one bit per
    four of the dynamically stuffed fields (an upper bound).
    """
    if fd:
        if data_bytes not in FD_LENGTHS:
            raise ValueError(f"data_bytes: expected a CAN FD length {FD_LENGTHS}, "
                             f"got {data_bytes}")
        crc, fixed = (17, 6) if data_bytes <= 16 else (21, 7)
        nominal, data = 30, 1 + 4 + 8 * data_bytes + 4 + crc + fixed
        if worst_case_stuffing:
            nominal += 4  # SOF..BRS: 17 bits
            data += (5 + 8 * data_bytes) // 4
        return nominal / nominal_bitrate + data / data_bitrate
    if not 0 <= data_bytes <= 8:
        raise ValueError(f"data_bytes: expected 0..8 for a classic frame, got {data_bytes}")
    bits = 47 + 8 * data_bytes
    if worst_case_stuffing:
        bits += (33 + 8 * data_bytes) // 4
    return bits / nominal_bitrate


def cycle_bus_time(codec, nominal_bitrate: float = 1e6, data_bitrate: float = 5e6,
                   worst_case_stuffing: bool = False) -> float:
    """Seconds of bus time of one command plus one hand cycle of ``codec``'s layout."""
    out, back = codec.cycle_frame_lengths
    return sum(frame_time(n, codec.is_fd, nominal_bitrate, data_bitrate, worst_case_stuffing)
               for n in (*out, *back))
