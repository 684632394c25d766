"""The hand's CAN messages, classic and CAN FD layouts: byte layout, scaling,
rejection, frame assembly and bus time (no bus). Expected bytes are built by hand
with ``struct``; cantools (reading the DBC) is the reference for the fast codecs."""

import struct

import numpy as np
import pytest

from handle_drake.devices.can_hand.layout import HandLayout, hand_layout
from handle_drake.devices.can_hand.messages import (
    COMMIT_ID,
    POSITION_BASE_ID,
    POSITION_SCALE,
    SETPOINT_BASE_ID,
    STATUS_ID,
    TACTILE_BASE_ID,
    TACTILE_SCALE,
    FeedbackAssembler,
    ForeignFrameError,
    FrameFormatError,
    HandCodec,
    MalformedFrameError,
    SetpointAssembler,
    cycle_bus_time,
    frame_time,
    load_database,
    make_codec,
)


@pytest.fixture(scope="module")
def shadow():
    return HandCodec(hand_layout("shadow"))


@pytest.fixture(scope="module")
def barrett():
    return HandCodec(hand_layout("barrett"))


def test_dbc_declares_the_documented_scaling():
    db = load_database()
    assert POSITION_SCALE == pytest.approx(1e-4)
    assert TACTILE_SCALE == pytest.approx(1e-3)
    status = db.get_message_by_name("STATUS")
    assert status.frame_id == STATUS_ID and status.length == 8
    assert {s.name for s in status.signals} == {"SEQ_ACK", "COUNTER", "STATE", "KIND", "TIME"}


def test_frame_counts_follow_the_hand_sizes(shadow, barrett):
    # four 16-bit values per 8-byte frame: ceil(n / 4)
    assert (shadow.num_setpoint_frames, shadow.num_position_frames,
            shadow.num_tactile_frames) == (5, 6, 2)  # 20 commands, 24 joints, 5 pads
    assert (barrett.num_setpoint_frames, barrett.num_position_frames,
            barrett.num_tactile_frames) == (1, 2, 1)  # 4, 8, 3


def test_setpoint_bytes_are_little_endian_int16_of_1e4_per_rad(shadow):
    q = np.zeros(20)
    q[0], q[1], q[4] = 0.1, -0.25, 1.5708
    frames = shadow.encode_setpoints(q, seq=513)
    assert [fid for fid, _ in frames] == [SETPOINT_BASE_ID + i for i in range(5)] + [COMMIT_ID]
    # Independent truth: struct packing of round(q / 1e-4).
    assert frames[0][1] == struct.pack("<hhhh", 1000, -2500, 0, 0)
    assert frames[1][1] == struct.pack("<hhhh", 15708, 0, 0, 0)
    assert frames[-1][1] == struct.pack("<HBB", 513, 5, 0)


def test_feedback_round_trip_is_within_half_a_count(shadow):
    rng = np.random.default_rng(1)
    layout = shadow.layout
    q = rng.uniform(layout.joint_lower, layout.joint_upper)
    tactile = rng.uniform(0, 30, layout.num_tactile)
    frames = shadow.encode_feedback(q, tactile, seq_ack=70000, counter=300, state=1,
                                    hand_time=12.345678)
    assembler = FeedbackAssembler(shadow)
    snapshots = [assembler.push(shadow.decode(fid, data)) for fid, data in frames]
    assert all(s is None for s in snapshots[:-1])
    snap = snapshots[-1]
    assert np.max(np.abs(snap.q - q)) <= 0.5e-4 + 1e-12
    assert np.max(np.abs(snap.tactile - tactile)) <= 0.5e-3 + 1e-12
    assert snap.seq_ack == 70000 % 65536 and snap.counter == 300 % 256
    assert snap.hand_time == pytest.approx(12.345678, abs=1e-6)


def test_compiled_codec_matches_cantools_bit_for_bit(shadow):
    """The struct fast path and cantools (the DBC reference) agree on every frame."""
    db = load_database()
    rng = np.random.default_rng(7)
    layout = shadow.layout
    for _ in range(50):
        q = rng.uniform(layout.command_lower, layout.command_upper)
        seq = int(rng.integers(0, 65536))
        for fid, data in shadow.encode_setpoints(q, seq):
            message = db.get_message_by_frame_id(fid)
            fields = message.decode(data, decode_choices=False)
            assert message.encode(fields) == data
            decoded = shadow.decode(fid, data).values
            values = tuple(decoded.values()) if isinstance(decoded, dict) else decoded
            assert values == tuple(fields[s.name] for s in message.signals)
        frames = shadow.encode_feedback(rng.uniform(-3, 3, layout.nq),
                                        rng.uniform(0, 60, layout.num_tactile), 1, 2, 1, 0.5)
        for fid, data in frames[:-1]:
            message = db.get_message_by_frame_id(fid)
            chunk = shadow.decode(fid, data).values
            assert message.encode(dict(zip([s.name for s in message.signals], chunk,
                                           strict=True))) == data
        # STATUS (struct with two nibbles) against cantools, both directions.
        seq_ack, counter = int(rng.integers(0, 65536)), int(rng.integers(0, 256))
        state, hand_time = int(rng.integers(0, 3)), float(rng.uniform(0, 4000))
        fid, data = shadow.encode_feedback(np.zeros(layout.nq), np.zeros(layout.num_tactile),
                                           seq_ack, counter, state, hand_time)[-1]
        status = db.get_message_by_frame_id(fid)
        fields = status.decode(data, decode_choices=False)
        assert fields == {"SEQ_ACK": seq_ack, "COUNTER": counter, "STATE": state,
                          "KIND": 1, "TIME": pytest.approx(hand_time, abs=0.5e-6)}
        assert status.encode(fields) == data
        assert shadow.decode(fid, data).values == pytest.approx(fields, abs=0)


def test_status_fields_decode_from_hand_built_bytes(shadow):
    data = struct.pack("<HBBI", 42, 7, (1 << 4) | 1, 2_500_000)  # KIND shadow, STATE ok
    frame = shadow.decode(STATUS_ID, data)
    assert frame.kind == "status"
    assert frame.values["SEQ_ACK"] == 42 and frame.values["COUNTER"] == 7
    assert frame.values["STATE"] == 1 and frame.values["TIME"] == pytest.approx(2.5)


def test_measured_values_saturate_like_a_sensor(barrett):
    q = np.full(8, 10.0)  # beyond the int16 range
    frames = barrett.encode_feedback(q, [-1.0, 100.0, 1.0], 0, 0, 1, 0.0)
    assembler = FeedbackAssembler(barrett)
    snap = [assembler.push(barrett.decode(fid, d)) for fid, d in frames][-1]
    assert np.allclose(snap.q, 3.2767)
    assert np.allclose(snap.tactile, [0.0, 65.535, 1.0])


def test_foreign_and_malformed_frames_are_rejected(shadow, barrett):
    with pytest.raises(ForeignFrameError, match="0x7FF"):
        shadow.decode(0x7FF, bytes(8))
    # Barrett has one setpoint frame: SETPOINT_1 is not one of its messages.
    with pytest.raises(ForeignFrameError):
        barrett.decode(SETPOINT_BASE_ID + 1, bytes(8))
    with pytest.raises(MalformedFrameError, match="expected 8 data bytes, got 3"):
        shadow.decode(POSITION_BASE_ID, bytes(3))
    with pytest.raises(MalformedFrameError, match="expected 8 data bytes, got 9"):
        shadow.decode(TACTILE_BASE_ID, bytes(9))
    barrett_status = struct.pack("<HBBI", 0, 0, (2 << 4) | 1, 0)
    with pytest.raises(MalformedFrameError, match="expected 'shadow'"):
        shadow.decode(STATUS_ID, barrett_status)


def test_bad_setpoints_raise_clear_errors(shadow):
    with pytest.raises(ValueError, match="expected 20 values"):
        shadow.encode_setpoints(np.zeros(4), seq=0)
    with pytest.raises(ValueError, match="finite"):
        shadow.encode_setpoints(np.full(20, np.nan), seq=0)
    with pytest.raises(ValueError, match="3.2767"):
        shadow.encode_setpoints(np.full(20, 4.0), seq=0)
    with pytest.raises(TypeError, match="HandLayout"):
        HandCodec("shadow")


def test_feedback_without_all_positions_is_dropped(shadow):
    layout = shadow.layout
    frames = shadow.encode_feedback(np.zeros(layout.nq), np.zeros(5), 1, 0, 1, 0.0)
    assembler = FeedbackAssembler(shadow)
    for fid, data in frames:
        if fid == POSITION_BASE_ID + 2:
            continue  # lost on the bus
        assert assembler.push(shadow.decode(fid, data)) is None
    assert assembler.incomplete == 1


def test_setpoints_apply_only_on_a_complete_commit(shadow):
    q = np.linspace(0.0, 0.19, 20)
    frames = shadow.encode_setpoints(q, seq=9)
    hand = SetpointAssembler(shadow)
    results = [hand.push(shadow.decode(fid, d)) for fid, d in frames]
    seq, applied = results[-1]
    assert seq == 9 and np.max(np.abs(applied - q)) <= 0.5e-4 + 1e-12
    # A commit with a setpoint frame missing is rejected, not half-applied.
    for fid, data in frames:
        if fid != SETPOINT_BASE_ID + 3:
            last = hand.push(shadow.decode(fid, data))
    assert last is None and hand.rejected_commits == 1
    # N_FRAMES that does not match the hand.
    for fid, data in frames[:-1]:
        hand.push(shadow.decode(fid, data))
    assert hand.push(shadow.decode(COMMIT_ID, struct.pack("<HBB", 10, 4, 0))) is None
    assert hand.rejected_commits == 2


def test_layout_couples_followers_to_leaders():
    layout = hand_layout("shadow", coupling_ratio=1.1)
    q = np.zeros(layout.nu)
    q[layout.actuated_joint_names.index("FFJ2")] = 0.5
    full = layout.joint_positions(q)
    assert full[layout.joint_names.index("FFJ1")] == pytest.approx(0.55)
    # The leader's limit keeps the follower inside its own (FFJ1 <= pi/2).
    upper = layout.command_upper[layout.actuated_joint_names.index("FFJ2")]
    assert upper == pytest.approx((np.pi / 2) / 1.1, abs=1e-4)
    barrett = hand_layout("barrett")
    full = barrett.joint_positions([0.3, 1.2, 0.6, 0.9])
    expected = {"f1_spread": 0.3, "f2_spread": 0.3, "f1_dist": 0.4, "f2_dist": 0.2,
                "f3_dist": 0.3}
    for name, value in expected.items():
        assert full[barrett.joint_names.index(name)] == pytest.approx(value)


def test_layout_rejects_inconsistent_input():
    with pytest.raises(ValueError, match="expected 2 values"):
        HandLayout("barrett", ("a", "b"), ("a",), (), [0.0], [1.0], [0.0], [1.0], ())
    with pytest.raises(ValueError, match="kind"):
        HandLayout("allegro", ("a",), ("a",), (), [0.0], [1.0], [0.0], [1.0], ())
    with pytest.raises(TypeError, match="HandSpec"):
        hand_layout(3)
    with pytest.raises(ValueError, match="unknown hand"):
        hand_layout("allegro")


# -- the CAN FD layout (hand_fd.dbc) -------------------------------------------------------

@pytest.fixture(scope="module")
def shadow_fd():
    return make_codec(hand_layout("shadow"), "fd")


@pytest.fixture(scope="module")
def barrett_fd():
    return make_codec(hand_layout("barrett"), "fd")


def test_fd_dbc_declares_can_fd_frames_of_valid_lengths():
    db = load_database("fd")
    assert db.dbc.attributes["BusType"].value == "CAN FD"
    # One command frame and one feedback frame per hand; lengths hand-computed:
    # setpoint 4 + 2 nu bytes, feedback 6 + 2 nq + 2 nt bytes, rounded up to an FD length.
    expected = {"SHADOW_SETPOINT": (0x140, 48), "SHADOW_FEEDBACK": (0x240, 64),   # 44, 64
                "BARRETT_SETPOINT": (0x141, 12), "BARRETT_FEEDBACK": (0x241, 32)}  # 12, 28
    assert {m.name: (m.frame_id, m.length) for m in db.messages} == expected
    assert all(m.is_fd and not m.is_extended_frame for m in db.messages)
    assert not any(m.is_fd for m in load_database("classic").messages)
    with pytest.raises(ValueError, match="frame_format: expected one of"):
        load_database("canfd")


def test_fd_setpoint_bytes_are_one_frame_with_seq_and_all_joints(shadow_fd):
    q = np.zeros(20)
    q[0], q[1], q[4], q[19] = 0.1, -0.25, 1.5708, -3.2767
    ((fid, data),) = shadow_fd.encode_setpoints(q, seq=70001)
    assert fid == 0x140 and len(data) == 48
    raw = [0] * 20
    raw[0], raw[1], raw[4], raw[19] = 1000, -2500, 15708, -32767
    # SEQ 70001 mod 65536 = 4465, MODE 0, a reserved byte, 20 int16, 4 zero pad bytes.
    assert data == struct.pack("<HBx20h4x", 4465, 0, *raw)
    seq, applied = shadow_fd.setpoint_receiver().feed(fid, data, True)
    assert seq == 4465 and np.max(np.abs(applied - q)) <= 0.5e-4 + 1e-12


def test_fd_feedback_is_one_frame_with_status_positions_and_forces(shadow_fd):
    layout = shadow_fd.layout
    q = np.zeros(layout.nq)
    q[0], q[23] = -0.5236, 1.5708
    tactile = np.array([0.0, 1.0, 2.5, 65.535, 0.001])
    ((fid, data),) = shadow_fd.encode_feedback(q, tactile, seq_ack=70000, counter=9, state=1,
                                               hand_time=12.345678)
    raw_q = [0] * 24
    raw_q[0], raw_q[23] = -5236, 15708
    # SEQ_ACK 70000 mod 65536 = 4464; STATE 1 | KIND 1 (shadow) << 4 = 0x11;
    # TIME 12 345 678 us as 3 bytes; 24 int16 (1e-4 rad); 5 uint16 (1e-3 N).
    expected = (struct.pack("<HB", 4464, 0x11) + (12_345_678).to_bytes(3, "little")
                + struct.pack("<24h5H", *raw_q, 0, 1000, 2500, 65535, 1))
    assert fid == 0x240 and data == expected and len(data) == 64
    snap = shadow_fd.feedback_receiver().feed(fid, data, True)
    assert snap.seq_ack == 4464 and snap.state == 1 and snap.counter is None
    assert snap.hand_time == pytest.approx(12.345678, abs=1e-9)
    assert np.allclose(snap.q, q, atol=1e-12) and np.allclose(snap.tactile, tactile, atol=1e-12)


def test_fd_time_wraps_at_2_to_the_24_microseconds(shadow_fd):
    layout = shadow_fd.layout
    assert shadow_fd.time_wrap == pytest.approx(16.777216)
    ((fid, data),) = shadow_fd.encode_feedback(np.zeros(layout.nq), np.zeros(5), 0, 0, 1, 20.0)
    snap = shadow_fd.feedback_receiver().feed(fid, data, True)
    assert snap.hand_time == pytest.approx(20.0 - 16.777216, abs=1e-9)


def test_fd_limits_and_saturation(barrett_fd):
    with pytest.raises(ValueError, match="3.2767"):
        barrett_fd.encode_setpoints([0.0, 0.0, 3.3, 0.0], seq=0)
    with pytest.raises(ValueError, match="expected 4 values"):
        barrett_fd.encode_setpoints(np.zeros(20), seq=0)
    with pytest.raises(ValueError, match="state: expected 0..15"):
        barrett_fd.encode_feedback(np.zeros(8), np.zeros(3), 0, 0, 16, 0.0)
    ((fid, data),) = barrett_fd.encode_feedback(np.full(8, -10.0), [-1.0, 100.0, 1.0], 0, 0, 1, 0.0)
    assert fid == 0x241 and len(data) == 32 and data[28:] == bytes(4)  # 28 bytes + pad
    snap = barrett_fd.feedback_receiver().feed(fid, data, True)
    assert np.allclose(snap.q, -3.2767) and np.allclose(snap.tactile, [0.0, 65.535, 1.0])


def test_fd_codec_matches_cantools_bit_for_bit(shadow_fd, barrett_fd):
    rng = np.random.default_rng(11)
    db = load_database("fd")
    for codec in (shadow_fd, barrett_fd):
        layout = codec.layout
        for _ in range(30):
            q = rng.uniform(layout.command_lower, layout.command_upper)
            ((fid, data),) = codec.encode_setpoints(q, int(rng.integers(0, 65536)))
            message = db.get_message_by_frame_id(fid)
            fields = message.decode(data, decode_choices=False)
            assert message.encode(fields) == data
            seq, applied = codec.setpoint_receiver().feed(fid, data, True)
            assert seq == fields["SEQ"]
            assert applied.tolist() == [fields[f"SP_{j}"] for j in layout.actuated_joint_names]
            qm = rng.uniform(-3.2, 3.2, layout.nq)
            f = rng.uniform(0, 60, layout.num_tactile)
            seq_ack, state, t = int(rng.integers(0, 65536)), int(rng.integers(0, 3)), 9.87654
            ((fid, data),) = codec.encode_feedback(qm, f, seq_ack, 0, state, t)
            message = db.get_message_by_frame_id(fid)
            fields = message.decode(data, decode_choices=False)
            assert message.encode(fields) == data
            assert fields["KIND"] == layout.kind_code and fields["STATE"] == state
            snap = codec.feedback_receiver().feed(fid, data, True)
            assert snap.q.tolist() == [fields[f"Q_{j}"] for j in layout.joint_names]
            assert snap.tactile.tolist() == [fields[f"F{k}"] for k in range(layout.num_tactile)]
            assert snap.seq_ack == fields["SEQ_ACK"] == seq_ack
            assert snap.hand_time == pytest.approx(fields["TIME"], abs=1e-12)


def test_fd_wrong_format_length_and_foreign_frames_are_rejected(shadow_fd, shadow):
    layout = shadow_fd.layout
    host = shadow_fd.feedback_receiver()
    hand = shadow_fd.setpoint_receiver()
    ((fb_id, fb),) = shadow_fd.encode_feedback(np.zeros(layout.nq), np.zeros(5), 0, 0, 1, 0.0)
    ((sp_id, sp),) = shadow_fd.encode_setpoints(np.zeros(layout.nu), 1)
    with pytest.raises(MalformedFrameError, match="expected 64 data bytes, got 48"):
        host.feed(fb_id, fb[:48], True)
    with pytest.raises(MalformedFrameError, match="expected 48 data bytes, got 8"):
        hand.feed(sp_id, sp[:8], True)
    with pytest.raises(FrameFormatError, match="a CAN 2.0 frame"):
        hand.feed(sp_id, sp, False)  # right id and bytes, but not sent as an FD frame
    with pytest.raises(FrameFormatError, match="classic layout message"):
        host.feed(POSITION_BASE_ID, bytes(8), False)
    with pytest.raises(ForeignFrameError, match="0x241"):
        host.feed(0x241, bytes(32), True)  # a Barrett's feedback on a Shadow bus
    barrett_kind = bytes([0, 0, 0x21]) + fb[3:]
    with pytest.raises(MalformedFrameError, match="hand kind 'barrett'"):
        host.feed(fb_id, barrett_kind, True)
    # Each side ignores the other direction's frame.
    assert host.feed(sp_id, sp, True) is None and hand.feed(fb_id, fb, True) is None
    # The classic layout rejects FD frames and the FD layout's ids.
    classic_host = shadow.feedback_receiver()
    ((pos_id, pos), *_) = shadow.encode_feedback(np.zeros(layout.nq), np.zeros(5), 0, 0, 1, 0.0)
    with pytest.raises(FrameFormatError, match="a CAN FD frame"):
        classic_host.feed(pos_id, pos, True)
    with pytest.raises(FrameFormatError, match="CAN FD layout message"):
        classic_host.feed(fb_id, fb, True)
    assert isinstance(FrameFormatError("x"), MalformedFrameError)  # callers may count it so


def test_fd_codec_checks_the_dbc_against_the_hand_model():
    real = hand_layout("barrett")
    # The last two joints swapped: the DBC's Q_f3_prox would carry f3_dist.
    names = (*real.joint_names[:-2], real.joint_names[-1], real.joint_names[-2])
    swapped = HandLayout("barrett", names, real.actuated_joint_names, (), real.command_lower,
                         real.command_upper, real.joint_lower, real.joint_upper, ())
    with pytest.raises(ValueError, match="do not match the hand layout.*Q_f3_dist"):
        make_codec(swapped, "fd")
    with pytest.raises(ValueError, match="frame_format"):
        make_codec(real, "CAN-FD")


def test_bus_time_of_frames_and_cycles():
    # Classic standard frames (Davis et al. 2007): 47 + 8 s bits, worst case
    # + floor((33 + 8 s) / 4) stuff bits: 8 bytes 111 / 135 bits, 4 bytes 79 / 95.
    assert frame_time(8, fd=False) == pytest.approx(111e-6)
    assert frame_time(8, fd=False, worst_case_stuffing=True) == pytest.approx(135e-6)
    assert frame_time(4, fd=False, worst_case_stuffing=True) == pytest.approx(95e-6)
    # CAN FD, 64 bytes: 30 bits at 1 Mbit/s + (1 + 4 + 512 + 4 + 21 + 7) bits at 5 Mbit/s.
    assert frame_time(64, fd=True) == pytest.approx(30e-6 + 549 / 5e6)
    # 12 bytes: CRC-17 and 6 fixed stuff bits: 1 + 4 + 96 + 4 + 17 + 6 = 128 data-phase bits.
    assert frame_time(12, fd=True) == pytest.approx(30e-6 + 128 / 5e6)
    with pytest.raises(ValueError, match="CAN FD length"):
        frame_time(44, fd=True)
    with pytest.raises(ValueError, match="0..8"):
        frame_time(12, fd=False)
    # A classic Shadow cycle: 14 eight-byte frames and a 4-byte commit, over 1 ms at 1 Mbit/s.
    shadow = hand_layout("shadow")
    assert cycle_bus_time(make_codec(shadow, "classic")) == pytest.approx((14 * 111 + 79) * 1e-6)
    assert cycle_bus_time(make_codec(shadow, "classic"), worst_case_stuffing=True) > 1.9e-3
    # FD: one 48-byte and one 64-byte frame, a quarter of the bus at 1 kHz.
    assert cycle_bus_time(make_codec(shadow, "fd")) == pytest.approx(
        frame_time(48, True) + frame_time(64, True))
    assert cycle_bus_time(make_codec(shadow, "fd"), worst_case_stuffing=True) < 0.35e-3
