"""Glove recording format and the glove -> Shadow mapping, rule by rule."""

import json

import numpy as np
import pytest

from handle_drake.apps.inhand.glove import (
    GLOVE_SENSORS,
    GloveFormatError,
    GloveRecording,
    load_glove,
    save_glove,
)
from handle_drake.apps.inhand.mapping import glove_to_shadow
from handle_drake.apps.inhand.synthetic import DATA_DIR, screw_cap_rotation, star_rotation
from handle_drake.base.hands import actuated_position_limits, get_hand_spec

NAMES = list(get_hand_spec("shadow").actuated_joint_names)
S = {name: i for i, name in enumerate(GLOVE_SENSORS)}


def _angles(T=5, **columns):
    a = np.zeros((T, len(GLOVE_SENSORS)))
    for name, value in columns.items():
        a[:, S[name]] = value
    return a


def test_save_load_round_trip_and_calibration(tmp_path):
    rng = np.random.default_rng(0)
    raw = rng.integers(0, 255, (7, 22)).astype(float)
    gain, offset = rng.uniform(0.01, 0.02, 22), rng.uniform(50, 80, 22)
    rec = GloveRecording(np.arange(7) * 0.02, raw, gain, offset, {"task": "x"})
    back = load_glove(save_glove(rec, tmp_path / "r.json"))
    np.testing.assert_allclose(back.raw, raw)
    np.testing.assert_allclose(back.angles(), gain * (raw - offset), rtol=1e-5)
    assert back.meta == {"task": "x"}
    np.testing.assert_allclose(back.sensor("IMCP"), gain[4] * (raw[:, 4] - offset[4]), rtol=1e-5)
    # uncalibrated: raw values are the angles
    plain = GloveRecording(np.arange(7) * 0.02, raw)
    np.testing.assert_array_equal(plain.angles(), raw)


def test_shipped_demonstrations_are_the_generator_output():
    for make, name in ((screw_cap_rotation, "screw_cap_rotation"),
                       (star_rotation, "star_rotation")):
        shipped = load_glove(DATA_DIR / f"{name}.json")
        fresh = make()
        np.testing.assert_allclose(shipped.raw, fresh.raw)
        assert shipped.meta["synthetic"] is True
        assert np.all((shipped.raw >= 0) & (shipped.raw <= 255))


def _write(tmp_path, **changes):
    rec = GloveRecording(np.arange(4) * 0.02, np.ones((4, 22)))
    path = save_glove(rec, tmp_path / "g.json")
    doc = json.loads(path.read_text())
    doc.update(changes)
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("changes, message", [
    ({"sensors": list(GLOVE_SENSORS[:-1])}, r"missing \['WY'\]"),
    ({"raw": [[1.0] * 21] * 4}, r"raw\[0\]: expected 22 values, got 21"),
    ({"raw": [[1.0] * 21 + [None]] + [[1.0] * 22] * 3}, r"raw\[0\]: sensor WY has no value"),
    ({"raw": [[float("nan")] + [1.0] * 21] + [[1.0] * 22] * 3}, r"sensor TR has no value"),
    ({"time": [0.0, 0.02, 0.02, 0.04]}, r"time: expected strictly increasing"),
    ({"calibration": {"gain": [1.0] * 3, "offset": [0.0] * 22}},
     r"calibration.gain: expected 22 values, got 3"),
    ({"format": "something"}, r"format 'something'"),
])
def test_bad_glove_files_name_the_problem(tmp_path, changes, message):
    with pytest.raises(GloveFormatError, match=message):
        load_glove(_write(tmp_path, **changes))


def test_missing_file_and_not_json(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_glove(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(GloveFormatError, match="not a JSON glove recording"):
        load_glove(tmp_path / "bad.json")


def test_rule1_same_joints_and_j0_coupling():
    a = _angles(IMCP=0.4, IPIJ=0.3, IDIJ=0.2, TR=0.1, TMCP=0.25, TIJ=0.35, WP=0.1, WY=-0.2,
                PMCP=0.5)
    q = glove_to_shadow(a, coupling_ratio=1.0)[0]
    assert q[NAMES.index("FFJ3")] == pytest.approx(0.4)
    assert q[NAMES.index("FFJ2")] == pytest.approx(0.25)  # J0 = 0.5 = J1 + J2, J1 = J2
    assert q[NAMES.index("THJ5")] == pytest.approx(0.1)
    assert q[NAMES.index("THJ2")] == pytest.approx(0.25)
    assert q[NAMES.index("THJ1")] == pytest.approx(0.35)
    assert q[NAMES.index("WRJ1")] == pytest.approx(0.1)
    assert q[NAMES.index("WRJ2")] == pytest.approx(-0.2)
    assert q[NAMES.index("LFJ3")] == pytest.approx(0.5)
    # C5 hand: J1 = 1.1 J2, so J2 = J0 / 2.1
    q5 = glove_to_shadow(a, coupling_ratio=1.1)[0]
    assert q5[NAMES.index("FFJ2")] == pytest.approx(0.5 / 2.1)


def test_rule2_abductions_only_set_the_initial_value():
    a = _angles(T=6, IMA=np.linspace(0.2, 0.6, 6), MRA=np.linspace(0.1, 0.3, 6),
                RPA=np.linspace(0.3, 0.0, 6))
    q = glove_to_shadow(a)
    for joint, value in (("FFJ4", -0.1), ("MFJ4", 0.1), ("RFJ4", -0.1), ("LFJ4", -0.3)):
        np.testing.assert_allclose(q[:, NAMES.index(joint)], value)  # first sample, held


def test_rule3_thumb_index_abduction_drives_both_thumb_abduction_joints():
    a = _angles(TAB=np.linspace(0.15, 0.9, 5))
    q = glove_to_shadow(a)
    np.testing.assert_allclose(q[:, NAMES.index("THJ4")], 0.15)
    np.testing.assert_allclose(q[:, NAMES.index("THJ3")], 0.15)
    # the joint limits clip: THJ3 stops at 0.2094
    q = glove_to_shadow(_angles(TAB=0.9))
    lower, upper = actuated_position_limits(get_hand_spec("shadow"), 1.0)
    assert q[0, NAMES.index("THJ3")] == pytest.approx(upper[NAMES.index("THJ3")])
    assert q[0, NAMES.index("THJ4")] == pytest.approx(0.9)


def test_rule4_little_finger_carpometacarpal_is_zero():
    a = _angles(PA=0.7, PMCP=0.3, RPA=0.2)
    assert np.all(glove_to_shadow(a)[:, NAMES.index("LFJ5")] == 0.0)


def test_mapping_bad_input():
    with pytest.raises(ValueError, match=r"expected shape \(T, 22\)"):
        glove_to_shadow(np.zeros((3, 21)))
    bad = np.zeros((3, 22))
    bad[1, 4] = np.nan
    with pytest.raises(ValueError, match="finite"):
        glove_to_shadow(bad)
