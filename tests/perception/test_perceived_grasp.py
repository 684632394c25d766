"""Planning from what the camera sees: detection -> planner input, executed on the truth."""

import math

import numpy as np
import pytest
from pydrake.common.schema import Transform

from handle_drake.grasp.planning import plan_grasp, resting_pose
from handle_drake.perception.detect import Detection
from handle_drake.perception.grasping import perceive_object, planner_input
from handle_drake.scenario import ObjectConfig


def _detection(position, extent, yaw, kind):
    return Detection(position=np.array(position), extent=np.array(extent), yaw=yaw, kind=kind,
                     residual=0.0, residuals={}, num_points=100)


def test_planner_input_from_a_detection_in_closed_form():
    box = _detection([0.1, -0.05, 0.045], [0.06, 0.036, 0.09], math.radians(30), "box")
    size, X_WO = planner_input("cuboid", box)
    assert size == pytest.approx(0.06)
    np.testing.assert_allclose(X_WO.GetAsMatrix4(),
                               resting_pose("cuboid", 0.06, (0.1, -0.05),
                                            math.radians(30)).GetAsMatrix4())
    # A cylinder lying on its side: diameter = detected height, axis = the
    # footprint's long side, which resting_pose puts along (-sin yaw, cos yaw).
    lying = _detection([0.0, 0.02, 0.03], [0.12, 0.06, 0.06], math.radians(10), "box")
    size, X_WO = planner_input("cylinder", lying)
    assert size == pytest.approx(0.06)
    axis = X_WO.rotation().matrix()[:, 2]  # the cylinder's axis (its z) in world
    np.testing.assert_allclose(abs(axis @ [math.cos(math.radians(10)),
                                           math.sin(math.radians(10)), 0]), 1, atol=1e-12)
    with pytest.raises(ValueError, match="planner grasps"):
        planner_input("mug", box)


def test_a_perceived_cuboid_is_close_enough_to_plan_on():
    perceived = perceive_object("cuboid", 0.075, xy=(0.06, -0.04), yaw=math.radians(35), seed=3)
    errors = perceived.errors()
    assert errors["xy_mm"] < 5 and abs(errors["yaw_deg"]) < 3, errors
    assert abs(errors["size_mm"]) < 0.1 * 75, errors
    plan = plan_grasp("tripod", ("cuboid", perceived.size), perceived.X_WO)
    # Executed on the truth: the scenario holds the true object, not the estimate.
    truth = ObjectConfig(kind="cuboid", size=0.075, X_WO=Transform(perceived.true_X_WO),
                         on_table=False)
    scenario = plan.to_scenario(world_object=truth)
    assert scenario.object.size == 0.075
    np.testing.assert_allclose(scenario.object.X_WO.GetDeterministicValue().translation(),
                               perceived.true_X_WO.translation())
    assert plan.to_scenario().object.size == pytest.approx(perceived.size)


def test_the_object_planned_on_is_chosen_by_the_request_not_by_the_truth():
    """Was the detection nearest the true pose. Now: the requested size,
    nearest the commanded position. Two 75 mm cuboids and a 40 mm sphere:
    told to look near the second cuboid, it is the one planned on (the truth,
    the first, is not consulted); the sphere, nearer the commanded spot but
    not of the requested size, is passed over."""
    from handle_drake.perception.grasping import select_detection
    from handle_drake.perception.scenes import SceneObject

    other = SceneObject("cuboid", 0.075, (-0.08, 0.08), math.radians(10))
    ball = SceneObject("sphere", 0.04, (-0.10, -0.02))
    perceived = perceive_object("cuboid", 0.075, xy=(0.06, -0.04), yaw=math.radians(35),
                                near_xy=(-0.10, 0.02), clutter=[other, ball])
    np.testing.assert_allclose(perceived.X_WO.translation()[:2], other.xy, atol=0.005)
    assert "took detection" in perceived.selection and "requested size" in perceived.selection
    # Told to look near the first, it takes the first.
    perceived = perceive_object("cuboid", 0.075, xy=(0.06, -0.04), yaw=math.radians(35),
                                clutter=[other, ball])
    assert perceived.errors()["xy_mm"] < 5
    # No detection of the requested size: the nearest the commanded spot, said so.
    small = _detection([0.0, 0.0, 0.02], [0.04, 0.04, 0.04], 0.0, "sphere")
    far = _detection([0.2, 0.0, 0.02], [0.045, 0.045, 0.04], 0.0, "sphere")
    chosen, why = select_detection([far, small], 0.2, (0.01, 0.0))
    assert chosen is small and "none has the requested size" in why
    with pytest.raises(ValueError, match="no object detected"):
        select_detection([], 0.05, (0, 0))
