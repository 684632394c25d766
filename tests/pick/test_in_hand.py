"""Locating the held object from its contacts with the hand (issue 33: the release is
corrected by the object measured in the hand after the lift)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.apps.pick.execute import locate_object
from handle_drake.geometry.objects import ObjectSpec, dimensions

CUBOID = ObjectSpec(kind="cuboid", size=0.06)
SPHERE = ObjectSpec(kind="sphere", size=0.06)


def _on_faces(X_WO, spec, faces):
    """Contact points and outward normals (world) on the cuboid's faces: each face as
    (axis, sign, offset along the two other axes)."""
    d = dimensions(spec)
    half = 0.5 * np.array([d["width"], d["depth"], d["height"]])
    R = X_WO.rotation().matrix()
    points, normals = [], []
    for axis, sign, (u, v) in faces:
        p_O = np.zeros(3)
        p_O[axis] = sign * half[axis]
        others = [k for k in range(3) if k != axis]
        p_O[others[0]], p_O[others[1]] = u, v
        points.append(X_WO @ p_O)
        normals.append(sign * R[:, axis])
    return np.array(points), np.array(normals)


def test_a_cuboid_pushed_and_turned_between_two_faces_is_found_across_them():
    """Thumb on one wide face, three fingers on the other: the centre across the faces
    and the turn about the vertical come from the contacts; along the faces (which no
    contact constrains) the prediction stands."""
    X_true = RigidTransform(RollPitchYaw(0.0, 0.0, 0.4), [0.1, -0.2, 0.15])
    # Predicted: 12 mm off across the faces (the object's y), 6 deg less yaw.
    X_pred = RigidTransform(RollPitchYaw(0.0, 0.0, 0.4 - np.radians(6.0)),
                            X_true @ np.array([0.0, 0.012, 0.0]))
    points, normals = _on_faces(X_true, CUBOID, [
        (1, -1, (0.0, 0.01)), (1, 1, (-0.015, 0.0)), (1, 1, (0.0, 0.012)),
        (1, 1, (0.015, -0.01))])
    X = locate_object(CUBOID, X_pred, points, normals)
    y_true = X_true.rotation().matrix()[:, 1]
    # Across the faces: exact; the yaw: exact (the faces' normal turned with it).
    assert (X.translation() - X_true.translation()) @ y_true == pytest.approx(0, abs=1e-4)
    angle = (X.rotation().inverse() @ X_true.rotation()).ToAngleAxis().angle()
    assert np.degrees(angle) < 0.1
    # The prediction was 12 mm and 6 deg off: the located pose is not it.
    assert np.linalg.norm(X_pred.translation() - X_true.translation()) > 0.011


def test_a_cuboid_touched_on_three_faces_is_found_exactly():
    X_true = RigidTransform(RollPitchYaw(0.1, -0.05, 1.2), [0.0, 0.3, 0.2])
    X_pred = RigidTransform(RollPitchYaw(0.1, -0.05, 1.1), [0.01, 0.31, 0.19])
    points, normals = _on_faces(X_true, CUBOID, [
        (0, 1, (0.0, 0.01)), (0, -1, (0.01, 0.0)), (1, 1, (0.0, 0.0)), (1, -1, (0.01, 0.02)),
        (2, -1, (0.0, 0.0)), (2, -1, (0.01, 0.01))])
    X = locate_object(CUBOID, X_pred, points, normals)
    # Within the weak pull of the prediction (PRIOR_WEIGHT): 0.1 deg, 0.5 mm.
    angle = (X.rotation().inverse() @ X_true.rotation()).ToAngleAxis().angle()
    assert np.degrees(angle) < 0.1
    np.testing.assert_allclose(X.translation(), X_true.translation(), atol=5e-4)


def test_a_sphere_centre_is_one_radius_inside_each_contact():
    centre = np.array([0.05, -0.1, 0.2])
    directions = np.array([[1.0, 0.0, 0.2], [-0.5, 0.8, 0.0], [-0.5, -0.8, -0.1]])
    normals = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    points = centre + 0.03 * normals
    X = locate_object(SPHERE, RigidTransform([0.07, -0.1, 0.19]), points, normals)
    np.testing.assert_allclose(X.translation(), centre, atol=1e-12)
