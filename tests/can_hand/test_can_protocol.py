"""The framed TCP protocol between proxy and server (pure, no sockets)."""

import struct

import numpy as np
import pytest

from handle_drake.devices.can_hand import protocol as P


def test_header_layout_is_the_documented_one():
    frame = P.pack(P.STATS_REQ)
    assert frame == b"HC" + bytes([1, P.STATS_REQ]) + struct.pack("<I", 0)
    frame = P.pack_command(7, [0.5, -1.0])
    assert frame[:8] == b"HC\x01\x03" + struct.pack("<I", 4 + 16)
    assert frame[8:] == struct.pack("<Idd", 7, 0.5, -1.0)


def test_reader_reassembles_messages_split_anywhere():
    info = P.HandInfo("barrett", 8, 4, 3)
    state = P.StateMessage(seq_ack=5, hand_state=1, flags=P.FLAG_HOLDING, hand_time=1.25,
                           q=np.arange(8.0), v=-np.arange(8.0), tactile=np.array([1.0, 2, 3]),
                           setpoint=np.array([0.1, 0.2, 0.3, 0.4]))
    stream = P.pack_hello(info) + P.pack_command(1, np.ones(4)) + P.pack_state(state)
    for cut in range(len(stream) + 1):
        reader = P.FrameReader()
        messages = reader.feed(stream[:cut]) + reader.feed(stream[cut:])
        assert [t for t, _ in messages] == [P.HELLO, P.COMMAND, P.STATE]
    assert P.unpack_hello(messages[0][1]) == info
    seq, q = P.unpack_command(messages[1][1], 4)
    assert seq == 1 and np.array_equal(q, np.ones(4))
    back = P.unpack_state(messages[2][1], info)
    assert back.seq_ack == 5 and back.flags == P.FLAG_HOLDING and back.hand_time == 1.25
    assert np.array_equal(back.q, state.q) and np.array_equal(back.v, state.v)
    assert np.array_equal(back.tactile, state.tactile)
    assert np.array_equal(back.setpoint, state.setpoint)


def test_broken_streams_raise_protocol_errors():
    with pytest.raises(P.ProtocolError, match="bad magic"):
        P.FrameReader().feed(b"XX\x01\x03\x00\x00\x00\x00")
    with pytest.raises(P.ProtocolError, match="version 9, expected 1"):
        P.FrameReader().feed(b"HC\x09\x03\x00\x00\x00\x00")
    with pytest.raises(P.ProtocolError, match="at most 65536"):
        P.FrameReader().feed(b"HC\x01\x03" + struct.pack("<I", 1 << 20))


def test_bad_payloads_raise_payload_errors():
    payload = P.pack_command(1, np.zeros(4))[8:]
    with pytest.raises(P.PayloadError, match="expected 20 joint values, got 4"):
        P.unpack_command(payload, 20)
    nan = P.pack_command(1, [0.0, np.nan, 0.0, 0.0])[8:]
    with pytest.raises(P.PayloadError, match="finite"):
        P.unpack_command(nan, 4)
    with pytest.raises(P.PayloadError, match="STATE"):
        P.unpack_state(b"\x00" * 10, P.HandInfo("shadow", 24, 20, 5))
    with pytest.raises(P.PayloadError, match="JSON"):
        P.unpack_stats(b"[1, 2")
    with pytest.raises(ValueError, match="message_type"):
        P.pack(99)
