"""The camera framing that every Meshcat view and replay opens with."""

import numpy as np
import pytest

from handle_drake.base.viewing import MARGIN, MIN_RADIUS, VERTICAL_FOV, camera_framing


def test_framing_puts_the_bounding_sphere_just_inside_the_field_of_view():
    centre = np.array([0.2, -0.1, 0.3])
    radius = 0.15
    # The 6 extreme points of a sphere: bounding-box centre = sphere centre.
    points = centre + radius * np.vstack([np.eye(3), -np.eye(3)])
    direction = np.array([0.0, -3.0, 4.0])  # |d| = 5
    camera, target = camera_framing(points, direction)
    np.testing.assert_allclose(target, centre, atol=1e-12)
    offset = camera - target
    # Looking along -direction...
    np.testing.assert_allclose(offset / np.linalg.norm(offset), direction / 5, atol=1e-12)
    # ...from where the sphere (plus the margin) subtends exactly the vertical FOV.
    half_angle = np.arcsin((radius + MARGIN) / np.linalg.norm(offset))
    assert half_angle == pytest.approx(VERTICAL_FOV / 2, rel=1e-12)


def test_a_single_point_is_framed_at_hand_scale():
    camera, target = camera_framing(np.zeros((1, 3)), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(target, 0)
    assert camera[2] == pytest.approx(MIN_RADIUS / np.sin(VERTICAL_FOV / 2))


@pytest.mark.parametrize("points, direction, match", [
    (np.zeros((0, 3)), [1, 0, 0], "N x 3"),
    (np.zeros((4, 2)), [1, 0, 0], "N x 3"),
    (np.full((2, 3), np.nan), [1, 0, 0], "finite"),
    (np.zeros((2, 3)), [0, 0, 0], "non-zero"),
])
def test_bad_input_names_the_problem(points, direction, match):
    with pytest.raises(ValueError, match=match):
        camera_framing(points, np.array(direction, dtype=float))
