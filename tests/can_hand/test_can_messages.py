"""The hand's CAN messages: byte layout, scaling, rejection, frame assembly (no bus)."""

import struct

import numpy as np
import pytest

from handle_drake.can_hand.layout import HandLayout, hand_layout
from handle_drake.can_hand.messages import (
    COMMIT_ID,
    POSITION_BASE_ID,
    POSITION_SCALE,
    SETPOINT_BASE_ID,
    STATUS_ID,
    TACTILE_BASE_ID,
    TACTILE_SCALE,
    FeedbackAssembler,
    ForeignFrameError,
    HandCodec,
    MalformedFrameError,
    SetpointAssembler,
    load_database,
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
