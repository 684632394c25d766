"""diagrams/hamburg_setup.yaml: the arm, the hand, the wall Kinect, four objects, the box."""

import warnings

import numpy as np
from pydrake.systems.analysis import Simulator

from handle_drake.demo import diagrams_dir
from handle_drake.perception.perceive import render_views
from handle_drake.scenario import LoadScenario
from handle_drake.scene.config import scene_objects
from handle_drake.scene.plant import in_box, initial_pose
from handle_drake.station import GetPlant, MakeHandStation

PATH = diagrams_dir() / "hamburg_setup.yaml"


def test_hamburg_setup_loads_and_simulates_at_rest():
    scenario = LoadScenario(filename=PATH)
    assert type(scenario.hand.mount).__name__ == "Arm"
    assert len(scene_objects(scenario)) == 4 and scenario.sorting_box is not None
    assert [c.profile for c in scenario.cameras] == ["kinect_v1"]
    scenario.cameras = []  # rendering is tested below; the dynamics here
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        station = MakeHandStation(scenario)
        simulator = Simulator(station)
        simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    plant = GetPlant(station)
    assert np.all(np.isfinite(plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))))
    np.testing.assert_allclose(station.GetOutputPort("arm.position_measured").Eval(context),
                               scenario.hand.mount.initial_position, atol=1e-3)
    for name, o in scene_objects(scenario):
        p = station.GetOutputPort(f"{name}.position").Eval(context)
        np.testing.assert_allclose(p, initial_pose(o, scenario.table).translation(), atol=2e-3)
        assert not in_box(scenario, p)


def test_the_kinect_sees_the_four_objects_and_not_the_arm_or_the_box():
    scenario = LoadScenario(filename=PATH)
    (view,) = render_views(scenario)
    found = np.array([d.position[:2] for d in view.detections])
    assert len(found) == 4
    for _, o in scene_objects(scenario):
        true_xy = np.array(o.X_WO.translation[:2], dtype=float)
        assert np.min(np.linalg.norm(found - true_xy, axis=1)) < 0.01


def test_perceive_judges_each_detection_against_its_own_object():
    """With several objects, a detection's error is against the object it stands for
    (before: always against ``object``, so three of four read 18-27 cm off)."""
    from handle_drake.perception.perceive import detection_error

    scenario = LoadScenario(filename=PATH)
    (view,) = render_views(scenario)
    for detection in view.detections:
        error = detection_error(detection, scenario)
        assert error["xy_mm"] < 10 and error["kind_ok"], error
