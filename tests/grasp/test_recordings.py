"""The handle_drake-grasps file format: round trip and clear errors on bad files."""

from datetime import UTC, datetime

import numpy as np
import pytest

from handle_drake.base.hands import get_hand_spec
from handle_drake.grasp.recordings import (
    SHADOW_JOINT_NAMES,
    GraspRecords,
    load_grasps,
    save_grasps,
)
from handle_drake.grasp.taxonomy import GraspClass


def _records(n=4, seed=0):
    rng = np.random.default_rng(seed)
    return GraspRecords(
        q=rng.uniform(0.0, 0.3, size=(n, 24)),
        grasp_classes=["tripod", "lateral", "tip_pinch", "parallel_extension"][:n],
        object_shapes=["sphere", "box", "sphere", "cylinder"][:n],
        object_dims=[(0.04,), (0.005, 0.06, 0.08), (0.02,), (0.03, 0.1)][:n],
        experimenters=["exp1", "exp2", "exp1", "exp3"][:n],
        timestamps=[datetime(2012, 2, 14, 10, 0, i, tzinfo=UTC) for i in range(n)],
    )


def test_joint_names_match_the_hand_spec():
    assert SHADOW_JOINT_NAMES == get_hand_spec("shadow").joint_names


def test_round_trip(tmp_path):
    rec = _records()
    path = save_grasps(tmp_path / "g.csv", rec)
    back = load_grasps(path)
    np.testing.assert_allclose(back.q, rec.q, atol=1e-6)  # 6 decimals in the file
    assert back.grasp_classes == [GraspClass.TRIPOD, GraspClass.LATERAL, GraspClass.TIP_PINCH,
                                  GraspClass.PARALLEL_EXTENSION]
    assert back.object_shapes == rec.object_shapes
    assert back.object_dims == rec.object_dims
    assert back.experimenters == rec.experimenters
    assert back.timestamps == rec.timestamps
    np.testing.assert_allclose(back.sizes, [0.04, 0.005, 0.02, 0.03])
    assert len(back.of_class("lateral")) == 1


def _write(tmp_path, text):
    path = tmp_path / "user.csv"
    path.write_text(text)
    return path


def _user_file(tmp_path, unit="deg", order=None, row_edit=None, magic=None):
    names = list(SHADOW_JOINT_NAMES) if order is None else order
    header = ["grasp_class", "timestamp", "experimenter", "object_shape", "object_dims_m", *names]
    values = {n: str(float(i)) for i, n in enumerate(SHADOW_JOINT_NAMES)}  # 0..23 degrees
    row = {"grasp_class": "TRIPOD", "timestamp": "2012-02-14T10:00:00", "experimenter": "glove",
           "object_shape": "sphere", "object_dims_m": "0.05", **values}
    if row_edit:
        row.update(row_edit)
    lines = [magic or f"# handle_drake-grasps format=1 angle_unit={unit}",
             "# recorded with a CyberGlove", ",".join(header),
             ",".join(row.get(h, "0") for h in header)]
    return _write(tmp_path, "\n".join(lines) + "\n")


def test_degrees_and_any_column_order(tmp_path):
    order = list(reversed(SHADOW_JOINT_NAMES))
    rec = load_grasps(_user_file(tmp_path, unit="deg", order=order))
    np.testing.assert_allclose(rec.q[0], np.deg2rad(np.arange(24.0)))
    assert rec.grasp_classes == [GraspClass.TRIPOD]


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(magic="timestamp,experimenter"), "line 1 must be '# handle_drake-grasps"),
        (dict(magic="# handle_drake-grasps format=7"), "unsupported format version '7'"),
        (dict(magic="# handle_drake-grasps format=1 angle_unit=grad"), "angle_unit must be"),
        (dict(order=list(SHADOW_JOINT_NAMES[:-1])), r"missing columns \['THJ1'\]"),
        (dict(order=[*SHADOW_JOINT_NAMES[:-1], "THJ0"]), r"unknown columns \['THJ0'\]"),
        (dict(row_edit={"grasp_class": "power_grip"}), ":4: grasp_class: unknown grasp class"),
        (dict(row_edit={"THJ2": "nan"}), ":4: THJ2 must be finite"),
        (dict(row_edit={"FFJ3": "abc"}), ":4: FFJ3 is not a number"),
        (dict(row_edit={"object_shape": "torus"}), "object_shape must be one of"),
        (dict(row_edit={"object_dims_m": "0.05 0.1"}),
         "a sphere needs 1 object_dims_m values, got 2"),
        (dict(row_edit={"object_dims_m": "-0.05"}), r"object_dims_m must be in \(0, 2\] m"),
        (dict(row_edit={"timestamp": "yesterday"}), "timestamp is not ISO 8601"),
        (dict(row_edit={"experimenter": ""}), "experimenter must be a non-empty id"),
    ],
)
def test_malformed_files_raise_clear_errors(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        load_grasps(_user_file(tmp_path, **kwargs))


def test_other_malformed_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="no grasp recording file"):
        load_grasps(tmp_path / "missing.csv")
    with pytest.raises(ValueError, match="empty file"):
        load_grasps(_write(tmp_path, ""))
    good = _user_file(tmp_path).read_text().splitlines()
    with pytest.raises(ValueError, match="header but no grasps"):
        load_grasps(_write(tmp_path, "\n".join(good[:3])))
    with pytest.raises(ValueError, match=r":4: expected 29 fields, got 28"):
        load_grasps(_write(tmp_path, "\n".join(good[:3] + [good[3].rsplit(",", 1)[0]])))


def test_joint_limits_are_checked(tmp_path):
    spec = get_hand_spec("shadow")
    limits = (spec.joint_lower_limits, spec.joint_upper_limits)
    # Radians 0..23 put most joints far past their limits; WRJ1 (1 rad) is the
    # first one outside [-0.698, 0.489].
    path = _user_file(tmp_path, unit="rad")
    with pytest.raises(ValueError, match=r"WRJ1 = 1.0000 rad is outside its limits"):
        load_grasps(path, joint_limits=limits)
    with pytest.raises(ValueError, match=r"expected two arrays of shape \(24,\)"):
        load_grasps(path, joint_limits=(np.zeros(3), np.ones(3)))


def test_records_validate_in_memory():
    with pytest.raises(ValueError, match=r"q: expected shape \(N, 24\), got \(2, 20\)"):
        GraspRecords(np.zeros((2, 20)), ["tripod"] * 2, ["sphere"] * 2, [(0.04,)] * 2,
                     ["a"] * 2, [datetime.now()] * 2)
    with pytest.raises(ValueError, match="experimenters: expected 2 entries, got 1"):
        GraspRecords(np.zeros((2, 24)), ["tripod"] * 2, ["sphere"] * 2, [(0.04,)] * 2,
                     ["a"], [datetime.now()] * 2)
    with pytest.raises(TypeError, match="records must be GraspRecords"):
        save_grasps("x.csv", {"q": np.zeros(24)})


def test_shipped_synthetic_data_is_valid():
    from handle_drake.grasp.synthetic import DATA_FILE

    spec = get_hand_spec("shadow")
    rec = load_grasps(DATA_FILE, (spec.joint_lower_limits, spec.joint_upper_limits),
                      limit_tolerance=1e-6)
    assert 50 <= len(rec) and DATA_FILE.stat().st_size < 1_000_000
    names = spec.joint_names
    for f in ("FF", "MF", "RF", "LF"):  # generated with J1 = 1.0 * J2
        np.testing.assert_allclose(rec.q[:, names.index(f"{f}J1")],
                                   rec.q[:, names.index(f"{f}J2")], atol=2e-6)
    np.testing.assert_allclose(rec.q[:, :2], 0.0, atol=1e-6)  # wrist at rest
