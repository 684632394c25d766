"""Tabletop detection on rendered and synthetic point clouds, against the known geometry."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.apps.perception.perceive import CATALOGUE_PRIMITIVE, detection_error, render_views
from handle_drake.base.models import diagrams_dir
from handle_drake.geometry.detect import detect_objects, min_area_rectangle
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import GetPlant, MakeHandStation, object_body, object_initial_pose

SCENARIO = diagrams_dir() / "tabletop_perception.yaml"


def _camera(profile):
    return (f"cameras: [{{profile: {profile}, target: [0, 0, 0], config: {{name: kinect, "
            f"X_PB: {{translation: [-0.707, 0, 0.707]}}}}}}]\n")


def _object(kind, x=0.0, y=0.0, yaw_deg=0.0, size=0.06):
    return (f"object: {{kind: {kind}, size: {size}, X_WO: {{translation: [{x}, {y}, 0], "
            f"rotation: !Rpy {{deg: [0, 0, {yaw_deg}]}}}}}}\n")


def _views(kind, profile="ideal", **pose):
    scenario = LoadScenario(filename=SCENARIO, data=_object(kind, **pose) + _camera(profile))
    (view,) = render_views(scenario)
    return scenario, view


def test_a_box_is_found_within_5_mm_and_3_deg_and_the_table_within_1_deg():
    scenario, view = _views("cuboid", x=0.08, y=-0.05, yaw_deg=30)
    assert math.degrees(math.acos(view.plane.normal[2])) < 1.0
    (box,) = view.detections
    error = detection_error(box, scenario)
    assert box.kind == "box"
    assert error["xy_mm"] < 5.0 and abs(error["yaw_deg"]) < 3.0, error
    # The catalogue cuboid of size 6 cm: 60 x 36 x 90 mm (objects.PROPORTIONS).
    np.testing.assert_allclose(box.extent, [0.060, 0.036, 0.090], atol=0.004)


def test_a_box_is_found_within_1_cm_through_kinect_noise_at_1_m():
    scenario, view = _views("cuboid", "kinect_v1", x=-0.05, y=0.08, yaw_deg=-50)
    (box,) = view.detections
    error = detection_error(box, scenario)
    assert math.degrees(math.acos(view.plane.normal[2])) < 1.0
    assert error["xy_mm"] < 10.0 and abs(error["z_mm"]) < 10.0, error


def test_every_catalogue_kind_is_found_anywhere_within_15_cm_at_any_yaw():
    """One station per kind; the object is moved in the context (seeded poses)."""
    rng = np.random.default_rng(7)
    for kind in CATALOGUE_PRIMITIVE:
        scenario = LoadScenario(filename=SCENARIO, data=_object(kind) + _camera("kinect_v1"))
        station = MakeHandStation(scenario)
        plant = GetPlant(station)
        context = station.CreateDefaultContext()
        plant_context = plant.GetMyMutableContextFromRoot(context)
        z = object_initial_pose(scenario).translation()[2]
        for trial in range(2):
            radius, angle = 0.15 * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
            x, y = radius * math.cos(angle), radius * math.sin(angle)
            yaw = rng.uniform(0, 2 * math.pi)
            X_WO = RigidTransform(RollPitchYaw(0, 0, yaw), [x, y, z])
            plant.SetFreeBodyPose(plant_context, object_body(plant), X_WO)
            context.SetTime(0.01 * (trial + 1))  # a new frame (new noise)
            cloud = station.GetOutputPort("kinect.point_cloud").Eval(context).xyzs().T
            _, detections = detect_objects(cloud)
            assert len(detections) == 1, (kind, x, y, len(detections))
            xy_error = np.linalg.norm(detections[0].position[:2] - [x, y])
            assert xy_error < 0.012, (kind, x, y, xy_error)


def test_two_separated_objects_give_two_clusters_and_an_empty_table_none():
    rng = np.random.default_rng(1)
    table = np.column_stack([rng.uniform(-0.3, 0.3, 20000), rng.uniform(-0.3, 0.3, 20000),
                             rng.normal(0, 0.001, 20000)])

    def box(cx, cy, sx, sy, h, n=3000):
        p = np.column_stack([rng.uniform(-sx / 2, sx / 2, n), rng.uniform(-sy / 2, sy / 2, n),
                             np.full(n, h)])
        return p + [cx, cy, 0]

    plane, detections = detect_objects(np.vstack([table, box(-0.1, 0, 0.05, 0.03, 0.08),
                                                  box(0.12, 0.05, 0.04, 0.04, 0.05)]))
    assert len(detections) == 2
    centres = sorted(tuple(np.round(d.position[:2], 2)) for d in detections)
    assert centres == [(-0.1, 0.0), (0.12, 0.05)]
    plane, detections = detect_objects(table)
    assert plane is not None and detections == []
    assert detect_objects(np.empty((0, 3))) == (None, [])
    # Invalid pixels (non-finite points) are ignored, not an error.
    plane, detections = detect_objects(np.vstack([table, np.full((100, 3), np.nan)]))
    assert detections == []


def test_rendered_empty_table_gives_no_object():
    scenario = LoadScenario(filename=SCENARIO, data="object: null\n" + _camera("kinect_v1"))
    (view,) = render_views(scenario)
    assert view.plane is not None and view.detections == []
    assert "no object" in view.message


def test_min_area_rectangle_of_a_rotated_rectangle():
    angle = math.radians(20)
    R = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    corners = np.array([[-0.05, -0.02], [0.05, -0.02], [0.05, 0.02], [-0.05, 0.02]]) @ R.T
    centre, size, yaw = min_area_rectangle(corners + [0.3, -0.1])
    np.testing.assert_allclose(centre, [0.3, -0.1], atol=1e-12)
    np.testing.assert_allclose(size, [0.1, 0.04], atol=1e-12)
    assert yaw == pytest.approx(angle)


@pytest.mark.parametrize("override, match", [
    ("cameras: [{profile: kinect_v9, config: {name: k}}]", "unknown profile"),
    ("cameras: [{config: {name: k, X_PB: {base_frame: elbow}}}]", r"X_PB\.base_frame"),
    ("cameras: [{config: {name: k, X_PB: {translation: [0, 0, 1]}}}, {config: {name: k}}]",
     "duplicate"),
    ("cameras: [{config: {name: 'a.b'}}]", r"cameras\[0\]\.config\.name"),
    ("cameras: [{config: {name: k, X_PB: {translation: [0, 0, -0.02]}}}]", "inside the table"),
    ("cameras: [{target: [0, 0, 1], config: {name: k, X_PB: {translation: [0, 0, 1]}}}]",
     "own position"),
    ("cameras: [{target: [0, 0], config: {name: k, X_PB: {translation: [0, 0, 1]}}}]",
     "3 finite"),
    # The profile sets the render intrinsics; Drake's publishing fields are not used.
    ("cameras: [{profile: kinect_v1, config: {name: k, width: 1000}}]",
     r"cameras\[0\]\.config\.width: set by the profile 'kinect_v1'"),
    ("cameras: [{config: {name: k, focal: !FovDegrees {y: 60}}}]", r"config\.focal"),
    ("cameras: [{config: {name: k, fps: 30}}]", r"config\.fps: not used"),
    ("cameras: [{config: {name: k, X_BD: {translation: [0, 0.02, 0]}}}]", r"config\.X_BD"),
    ("cameras: [{config: {name: k}, parnet: world}]", r"cameras\[0\]\.parnet"),
    # The pre-Drake keys name their new place.
    ("cameras: [{name: k, profile: kinect_v1}]",
     r"cameras\[0\]\.name: moved .* cameras\[0\]\.config\.name"),
    ("cameras: [{profile: kinect_v1, X_PC: {translation: [0, 0, 1]}}]",
     r"cameras\[0\]\.X_PC: moved .* cameras\[0\]\.config\.X_PB"),
    ("cameras: [{profile: kinect_v1, parent: world}]", r"base_frame"),
    ("visualization_period: 0.1", r"visualization_period: renamed to "
                                  r"visualization\.publish_period"),
])
def test_bad_cameras_are_refused_naming_the_field(override, match):
    with pytest.raises(ScenarioError, match=match):
        LoadScenario(filename=SCENARIO, data=override)


def test_a_camera_looking_away_reports_nothing_in_view():
    scenario = LoadScenario(filename=SCENARIO, data=(
        "cameras: [{profile: kinect_v1, target: [0, 0, 3], "
        "config: {name: up, X_PB: {translation: [0, 0, 1]}}}]"))
    (view,) = render_views(scenario)
    assert view.detections == [] and "nothing in view" in view.message


def test_perceive_cli_json_and_recorded_frame_round_trip(tmp_path):
    override = _object("cuboid", x=0.05, y=0.05, yaw_deg=20)
    run = subprocess.run(
        [sys.executable, "-m", "handle_drake.cli", "perceive", str(SCENARIO), "--override",
         override, "--json", "--save-frames", str(tmp_path)],
        capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    (obj,) = report["objects"]
    assert obj["kind"] == "box" and obj["error"]["xy_mm"] < 10
    # The extent's error against the catalogue cuboid (60 x 36 x 90 mm), as documented.
    assert len(obj["error"]["extent_mm"]) == 3
    np.testing.assert_allclose(obj["extent"], [0.060, 0.036, 0.090], atol=0.006)
    np.testing.assert_allclose(obj["error"]["extent_mm"],
                               np.array(obj["extent"]) * 1000 - [60, 36, 90], atol=0.01)
    np.testing.assert_allclose(obj["position"][:2], [0.05, 0.05], atol=0.01)
    # The saved 16-bit PNG frame gives the same detection through --frame.
    again = subprocess.run(
        [sys.executable, "-m", "handle_drake.cli", "perceive", "--frame",
         str(tmp_path / "kinect.json"), "--json"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    (obj2,) = json.loads(again.stdout)["objects"]
    np.testing.assert_allclose(obj2["position"], obj["position"], atol=0.002)
    bad = subprocess.run([sys.executable, "-m", "handle_drake.cli", "perceive"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


def test_the_hand_in_view_is_filtered_out_by_its_render_labels(capsys):
    """A hand hovering over the table is a cluster of its own (a false object
    'standing' there); its render labels take it out of the cloud."""
    from handle_drake.apps.perception.perceive import robot_labels
    from handle_drake.cli import main

    hand = ("hand: {kind: shadow, mount: !FixedMount {X_WB: {translation: [-0.25, 0.0, 0.3], "
            "rotation: !Rpy {deg: [90, 0, 90]}}}}")
    scenario = LoadScenario(filename=diagrams_dir() / "tabletop_perception.yaml", data=hand)
    station = MakeHandStation(scenario)
    plant = station.GetSubsystemByName("plant")
    # Drake labels each body's geometry: every hand body, and nothing of the table or object.
    hand_bodies = {int(i) for i in plant.GetBodyIndices(plant.GetModelInstanceByName("hand"))}
    assert set(robot_labels(station).tolist()) == hand_bodies
    (kept,) = render_views(scenario, exclude_robot=False)
    (filtered,) = render_views(scenario)
    assert len(kept.detections) >= 2  # the object and the hand (its parts may split)
    (only,) = filtered.detections
    error = detection_error(only, scenario)
    assert error["kind_ok"] and error["xy_mm"] < 5.0
    assert main(["perceive", "--frame", "x.json", "--keep-robot"]) == 2
    assert "--keep-robot applies to a scenario" in capsys.readouterr().err


@pytest.mark.parametrize("seed", [0, 1])
def test_a_one_centimetre_sphere_is_seen_with_kinect_noise(seed):
    scenario = LoadScenario(
        filename=diagrams_dir() / "tabletop_perception.yaml",
        data=f"random_seed: {seed}\n"
             "object: {kind: sphere, size: 0.01, X_WO: {translation: [0.1, -0.1, 0]}}")
    (view,) = render_views(scenario)
    (only,) = view.detections
    assert detection_error(only, scenario)["xy_mm"] < 5.0
