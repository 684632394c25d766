"""The CAN FD layout (``hand_fd.dbc``): :class:`FdHandCodec` and its two decoders (pure).

See :mod:`handle_drake.devices.can_hand.messages` for the frame table.
"""

from __future__ import annotations

import struct

import numpy as np

from handle_drake.devices.can_hand.frames import (
    FD_LENGTHS,
    MODE_POSITION,
    FeedbackSnapshot,
    ForeignFrameError,
    FrameFormatError,
    MalformedFrameError,
    _checked,
    _CodecIds,
    _database_ids,
    load_database,
)
from handle_drake.devices.can_hand.layout import HAND_KIND_CODES, HandLayout


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
        q, f = self._saturated(q, tactile)
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
