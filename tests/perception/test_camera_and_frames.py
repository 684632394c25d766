"""Depth model, point back-projection and the recorded-frame format against closed form."""

import numpy as np
import pytest

from handle_drake.devices.camera.frames import DepthFrame, load_frame, points_from_depth, save_frame
from handle_drake.devices.camera.profiles import (
    PROFILES,
    CameraProfile,
    apply_depth_model,
    disparity_step,
    get_profile,
)


def test_kinect_profile_matches_the_sensor_sheet_and_khoshelham_2012():
    kinect = get_profile("kinect_v1")
    assert (kinect.width, kinect.height) == (640, 480)
    assert kinect.fov_y_deg == 43.0
    assert (kinect.min_depth, kinect.max_depth) == (0.8, 4.0)
    # sigma(1 m) ~ 1.4 mm; the quantisation step at 1 m: 1/8 px / (580 px * 75 mm).
    assert kinect.noise_k == pytest.approx(1.425e-3)
    assert kinect.quant_k == pytest.approx(1 / 8 / (580 * 0.075))
    assert disparity_step() * 4.0 ** 2 == pytest.approx(0.0460, abs=2e-4)  # 4.6 cm at 4 m


def test_ideal_profile_keeps_depth_and_marks_out_of_range_pixels_invalid():
    ideal = PROFILES["ideal"]
    depth = np.array([[0.05, 0.5, 2.0], [np.nan, 0.0, 20.0]])
    out = apply_depth_model(depth, ideal)
    assert out[0, 1] == pytest.approx(0.5) and out[0, 2] == pytest.approx(2.0)
    # too close, NaN, zero and too far: all invalid (inf), never a point
    assert np.all(np.isinf(out[[0, 1, 1, 1], [0, 0, 1, 2]]))


def test_quantisation_puts_depth_on_the_disparity_grid_with_step_k_z_squared():
    profile = CameraProfile("q", 4, 4, 43.0, 0.1, 10.0, quant_k=disparity_step())
    z = np.linspace(1.0, 3.0, 2000).reshape(40, 50)
    out = apply_depth_model(z, profile).astype(float)
    levels = np.unique(out)
    # Adjacent levels differ by k z^2 (to first order) and rounding moves a
    # depth by at most half a step.
    steps = np.diff(levels)
    mid = levels[:-1]
    np.testing.assert_allclose(steps, profile.quant_k * mid ** 2, rtol=0.02)
    assert np.all(np.abs(out - z) <= 0.5 * profile.quant_k * z ** 2 * 1.02 + 1e-6)


def test_noise_sigma_grows_with_depth_squared_and_is_seeded():
    profile = CameraProfile("n", 4, 4, 43.0, 0.1, 10.0, noise_k=1.425e-3)
    flat = np.full((200, 200), 2.0)
    a = apply_depth_model(flat, profile, np.random.default_rng(3))
    b = apply_depth_model(flat, profile, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert np.std(a) == pytest.approx(1.425e-3 * 4.0, rel=0.03)  # 5.7 mm at 2 m
    with pytest.raises(ValueError, match="seeded rng"):
        apply_depth_model(flat, profile)


@pytest.mark.parametrize("kwargs, match", [
    (dict(width=0), "width"), (dict(height=-4), "height"), (dict(width=64.5), "width"),
    (dict(fov_y_deg=0.0), "fov_y_deg"), (dict(fov_y_deg=180.0), "fov_y_deg"),
    (dict(min_depth=2.0, max_depth=1.0), "min_depth"), (dict(noise_k=-1.0), "noise_k"),
])
def test_bad_profiles_name_the_field(kwargs, match):
    base = dict(name="x", width=64, height=48, fov_y_deg=43.0, min_depth=0.5, max_depth=4.0)
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        CameraProfile(**base)
    with pytest.raises(ValueError, match="unknown profile 'kinect_v3'"):
        get_profile("kinect_v3")


def test_back_projection_of_a_fronto_parallel_plane():
    K = np.array([[500.0, 0, 3.5], [0, 500.0, 2.5], [0, 0, 1]])
    depth = np.full((6, 8), 2.0)
    depth[0, 0] = np.inf  # invalid pixels give no point
    X_WC = np.eye(4)
    X_WC[:3, 3] = [1.0, 2.0, 3.0]
    points = points_from_depth(depth, K, X_WC)
    assert len(points) == 47
    np.testing.assert_allclose(points[:, 2], 5.0)  # z_C = 2 m, shifted by 3 m
    # Pixel (u, v) = (7, 5): x_C = (7 - 3.5) * 2 / 500, y_C = (5 - 2.5) * 2 / 500.
    np.testing.assert_allclose(points[-1], [1.0 + 0.014, 2.0 + 0.01, 5.0])


def test_frame_round_trips_through_a_16_bit_millimetre_png(tmp_path):
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.8, 3.0, size=(48, 64))
    depth[5, 5] = np.inf
    K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    X_WC = np.eye(4)
    path = save_frame(tmp_path / "cam", DepthFrame(depth, K, X_WC))
    loaded = load_frame(path)
    assert np.isinf(loaded.depth[5, 5])
    finite = np.isfinite(depth)
    assert np.max(np.abs(loaded.depth[finite] - depth[finite])) <= 0.0005 + 1e-6  # 1 mm units
    np.testing.assert_allclose(loaded.K, K)


def test_bad_frames_are_refused_with_the_reason(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        load_frame(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="directory"):
        load_frame(tmp_path)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="not a JSON"):
        load_frame(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text('{"format": "something-else"}')
    with pytest.raises(ValueError, match="format"):
        load_frame(tmp_path / "other.json")
    with pytest.raises(ValueError, match="X_WC"):
        DepthFrame(np.ones((2, 2)), np.eye(3), np.eye(3))
