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

Joints are packed four to a frame in :class:`~handle_drake.devices.can_hand.layout.HandLayout`
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

Modules: :mod:`.frames` (what both layouts share), :mod:`.classic`,
:mod:`.fd`, :mod:`.timing` (bus time); this module holds :func:`make_codec`
and re-exports the public names. Everything here is pure: :func:`make_codec`
gives a :class:`HandCodec` (classic) or :class:`FdHandCodec` (fd); both turn vectors into
``[(arbitration_id, bytes), ...]`` and, through the receivers of
:meth:`HandCodec.feedback_receiver` / :meth:`HandCodec.setpoint_receiver`,
raw frames back into hand cycles and commands, raising
:class:`ForeignFrameError` for ids that are not the hand's,
:class:`FrameFormatError` for a frame of the other layout or format (a CAN FD
frame on the classic layout, a classic frame on the FD layout) and
:class:`MalformedFrameError` for a wrong length or an undecodable payload.
"""

from __future__ import annotations

from handle_drake.devices.can_hand.classic import FeedbackAssembler, HandCodec, SetpointAssembler
from handle_drake.devices.can_hand.fd import FdFeedbackDecoder, FdHandCodec, FdSetpointDecoder
from handle_drake.devices.can_hand.frames import (
    COMMIT_ID,
    DBC_PATH,
    DBC_PATHS,
    FD_LENGTHS,
    FRAME_FORMATS,
    MODE_POSITION,
    POSITION_BASE_ID,
    POSITION_SCALE,
    SETPOINT_BASE_ID,
    STATE_FAULT,
    STATE_INIT,
    STATE_OK,
    STATUS_ID,
    TACTILE_BASE_ID,
    TACTILE_SCALE,
    CanFrameError,
    FeedbackSnapshot,
    ForeignFrameError,
    Frame,
    FrameFormatError,
    MalformedFrameError,
    _check_format,
    load_database,
)
from handle_drake.devices.can_hand.layout import HandLayout
from handle_drake.devices.can_hand.timing import cycle_bus_time, frame_time

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


def make_codec(layout: HandLayout, frame_format: str = "fd") -> HandCodec | FdHandCodec:
    """The codec of ``frame_format`` ("classic": :class:`HandCodec`, "fd": :class:`FdHandCodec`)."""
    if _check_format(frame_format) == "fd":
        return FdHandCodec(layout)
    return HandCodec(layout)
