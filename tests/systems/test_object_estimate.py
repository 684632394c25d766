"""ObjectEstimate.displacement: where one touch says the object is, against the
geometry of an object really displaced by a known vector (closed form: the
contact point and normal are computed on the displaced solid)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from handle_drake.systems.reactive_grasp import ObjectEstimate

RNG = np.random.default_rng(3)


def _unit(v):
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("case", range(20))
def test_a_sphere_is_located_fully_by_one_touch_anywhere_on_it(case):
    X_WO = RigidTransform(RollPitchYaw(RNG.uniform(-3, 3, 3)), RNG.uniform(-0.2, 0.2, 3))
    r = RNG.uniform(0.005, 0.05)
    d = RNG.uniform(-0.02, 0.02, 3)  # the true object is here, relative to the plan
    n = _unit(RNG.normal(size=3))  # any point of its surface
    p = X_WO.translation() + d + r * n
    estimate = ObjectEstimate("sphere", X_WO, radius=r)
    np.testing.assert_allclose(estimate.displacement(p, n), d, atol=1e-12)
    # The normal need not be unit length.
    np.testing.assert_allclose(estimate.displacement(p, 3 * n), d, atol=1e-12)


@pytest.mark.parametrize("case", range(20))
def test_a_cylinder_is_located_across_its_axis_only(case):
    X_WO = RigidTransform(RollPitchYaw(RNG.uniform(-3, 3, 3)), RNG.uniform(-0.2, 0.2, 3))
    axis = X_WO.rotation().matrix()[:, 2]
    r = RNG.uniform(0.005, 0.05)
    d = RNG.uniform(-0.02, 0.02, 3)
    across = _unit(np.cross(axis, RNG.normal(size=3)))  # a normal of the round wall
    p = X_WO.translation() + d + r * across + RNG.uniform(-0.04, 0.04) * axis
    got = ObjectEstimate("cylinder", X_WO, radius=r).displacement(p, across)
    np.testing.assert_allclose(got, d - (d @ axis) * axis, atol=1e-12)
    # A touch on an end face says nothing across the axis.
    assert not ObjectEstimate("cylinder", X_WO, radius=r).displacement(p, axis).any()


@pytest.mark.parametrize("case", range(20))
def test_a_box_is_located_along_the_touched_faces_normal_only(case):
    R = RotationMatrix(RollPitchYaw(RNG.uniform(-3, 3, 3)))
    X_WO = RigidTransform(R, RNG.uniform(-0.2, 0.2, 3))
    h = RNG.uniform(0.005, 0.05, 3)
    d = RNG.uniform(-0.004, 0.004, 3)  # less than the smallest half edge
    k, sign = int(RNG.integers(3)), float(RNG.choice([-1.0, 1.0]))
    face = sign * R.matrix()[:, k]
    in_face = RNG.uniform(-0.9, 0.9, 3) * h
    in_face[k] = sign * h[k]
    p = X_WO.translation() + d + R.matrix() @ in_face
    # A slightly tilted measured normal picks the same face.
    normal = _unit(face + 0.2 * _unit(RNG.normal(size=3)))
    got = ObjectEstimate("box", X_WO, half_extents=h).displacement(p, normal)
    np.testing.assert_allclose(got, (d @ face) * face, atol=1e-12)


def test_bad_input_names_the_problem():
    X = RigidTransform()
    with pytest.raises(ValueError, match="kind must be one of"):
        ObjectEstimate("mug", X, radius=0.01)
    with pytest.raises(ValueError, match="needs a radius"):
        ObjectEstimate("sphere", X)
    with pytest.raises(ValueError, match="needs a radius"):
        ObjectEstimate("cylinder", X, radius=-0.01)
    with pytest.raises(ValueError, match="half extents"):
        ObjectEstimate("box", X, half_extents=(0.01, 0.02))
    with pytest.raises(ValueError, match="half extents"):
        ObjectEstimate("box", X, half_extents=(0.01, 0.02, 0.0))
