"""The classic CAN 2.0 layout (``hand.dbc``): :class:`HandCodec` and its two receivers (pure).

See :mod:`handle_drake.devices.can_hand.messages` for the frame table.
"""

from __future__ import annotations

import numpy as np

from handle_drake.devices.can_hand.frames import (
    COMMIT_ID,
    MODE_POSITION,
    SLOTS_PER_FRAME,
    STATUS_ID,
    FeedbackSnapshot,
    ForeignFrameError,
    Frame,
    FrameFormatError,
    MalformedFrameError,
    _checked,
    _CodecIds,
    _database_ids,
    _frames_for,
    _PackedMessage,
    _SlotFrames,
    _StatusStruct,
    load_database,
)
from handle_drake.devices.can_hand.layout import HAND_KIND_CODES, HandLayout


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
        q, f = self._saturated(q, tactile)
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
