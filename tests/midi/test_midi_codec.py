"""MIDI encoding against hand-computed bytes and mido's own parser; tick counting."""

import math

import mido
import numpy as np
import pytest

from handle_drake.devices.midi.codec import (
    ControlCounts,
    ControlEncoder,
    MidiDecoder,
    control_message,
    decode_relative,
    encode_relative,
    fader_value,
)
from handle_drake.devices.midi.mapping import LoadMidiMapping


@pytest.fixture(scope="module")
def mapping():
    return LoadMidiMapping()


# (ticks, signed_bit, twos_complement, binary_offset), computed by hand.
RELATIVE_TABLE = [
    (1, 0x01, 0x01, 0x41),
    (5, 0x05, 0x05, 0x45),
    (63, 0x3F, 0x3F, 0x7F),
    (-1, 0x41, 0x7F, 0x3F),
    (-3, 0x43, 0x7D, 0x3D),
    (-63, 0x7F, 0x41, 0x01),
]


@pytest.mark.parametrize("ticks, signed_bit, twos, offset", RELATIVE_TABLE)
def test_relative_encodings_match_hand_computed_values(ticks, signed_bit, twos, offset):
    for encoding, value in (("signed_bit", signed_bit), ("twos_complement", twos),
                            ("binary_offset", offset)):
        assert encode_relative(ticks, encoding) == value
        assert decode_relative(value, encoding) == ticks


def test_relative_values_without_ticks_are_none():
    assert decode_relative(0, "signed_bit") is None
    assert decode_relative(64, "signed_bit") is None  # "minus zero"
    assert decode_relative(64, "binary_offset") is None
    assert decode_relative(64, "twos_complement") is None  # -64 is beyond 63 ticks
    with pytest.raises(ValueError, match="ticks"):
        encode_relative(64, "signed_bit")
    with pytest.raises(ValueError, match="relative_encoding"):
        encode_relative(1, "gray")


def test_messages_bytes_match_hand_computed_and_mido_parses_them(mapping):
    fader = mapping.control("fader1")  # CC 20, channel 1
    jog = mapping.control("jog")  # CC 60
    mode = mapping.control("mode")  # note 84
    cases = [
        (control_message(fader, 64), [0xB0, 20, 64]),
        (control_message(jog, -3, "signed_bit"), [0xB0, 60, 0x43]),
        (control_message(jog, 7, "twos_complement"), [0xB0, 60, 0x07]),
        (control_message(mode, 1), [0x90, 84, 127]),
        (control_message(mode, 0), [0x80, 84, 0]),
    ]
    for message, expected in cases:
        assert message.bytes() == expected
        assert mido.Message.from_bytes(expected) == message
        assert mido.parse(bytes(expected)) == message


def test_fader_value_is_7_bit_and_clamped():
    assert fader_value(0.0, 0.06) == 0
    assert fader_value(0.06, 0.06) == 127
    assert fader_value(0.03, 0.06) == 64  # round(63.5) -> 64 (half to even)
    assert fader_value(-0.01, 0.06) == 0 and fader_value(0.07, 0.06) == 127


@pytest.mark.parametrize("turns", [2.37, -1.81])
def test_known_wheel_rotation_gives_known_ticks(mapping, turns):
    """A wheel turned by `turns` revolutions in small random steps (and one big
    jump) sends floor(turns * N) ticks net, i.e. the rotation within one tick."""
    n = mapping.jog_ticks_per_turn
    encoder = ControlEncoder(mapping, ["jog"], [0.0])
    rng = np.random.default_rng(1)
    target = 2 * math.pi * turns
    angles = np.sort(rng.uniform(0, 1, 200))[:: 1 if turns > 0 else 1] * target
    angles = np.concatenate([angles, [target * 0.5, target]])  # back, then a jump
    decoder, counts = MidiDecoder(mapping), ControlCounts(mapping)
    for angle in angles:
        for message in encoder.messages([angle]):
            counts.add(decoder.decode(mido.Message.from_bytes(message.bytes())))
    expected = math.floor(turns * n)
    assert counts["jog"] == expected
    assert abs(counts["jog"] - turns * n) < 1.0
    assert decoder.total_rejected == 0


def test_fast_spin_is_split_into_63_tick_messages(mapping):
    encoder = ControlEncoder(mapping, ["jog"], [0.0])
    messages = encoder.messages([2 * math.pi * 3])  # 3 turns in one step: 192 ticks
    ticks = [decode_relative(m.value, mapping.relative_encoding) for m in messages]
    assert ticks == [63, 63, 63, 3]


def test_button_hysteresis(mapping):
    encoder = ControlEncoder(mapping, ["button1"], [0.004])
    sent = []
    for depth in (0.001, 0.0025, 0.0023, 0.002, 0.0018, 0.0015, 0.0025):
        sent += [m.type for m in encoder.messages([depth])]
    assert sent == ["note_on", "note_off", "note_on"]


def test_bad_input_is_counted_not_raised(mapping):
    decoder = MidiDecoder(mapping)
    bad = [
        mido.Message("sysex", data=[0x00, 0x20, 0x29]),
        mido.Message("control_change", channel=5, control=20, value=3),  # unknown channel
        mido.Message("control_change", channel=0, control=99, value=3),  # unknown controller
        mido.Message("pitchwheel", channel=0, pitch=100),
        mido.Message("control_change", channel=0, control=60, value=0),  # jog: no ticks
        [0xB0, 20, 200],  # data byte > 127
        [0x42],  # a data byte without status
        [],
        b"\xf0\x01",  # unterminated sysex
    ]
    for message in bad:
        assert decoder.decode(message) is None
    assert decoder.accepted == 0
    assert decoder.rejected == {"sysex": 1, "unknown_channel": 1, "unknown_control": 1,
                                "unexpected_type": 1, "out_of_range": 1, "malformed": 4}
    event = decoder.decode([0xB0, 20, 100])
    assert (event.name, event.value) == ("fader1", 100)
