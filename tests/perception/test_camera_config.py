"""Scenarios use Drake's own config types: a camera is Drake's ``CameraConfig``
plus the device profile, Meshcat is Drake's ``VisualizationConfig``."""

import math

import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.multibody.meshcat import ContactVisualizer
from pydrake.systems.sensors import CameraConfig, RgbdSensor

from handle_drake.base.models import diagrams_dir
from handle_drake.devices.camera.config import DepthCamera, drake_camera_config
from handle_drake.devices.camera.profiles import PROFILES
from handle_drake.scenario import DumpScenario, LoadScenario
from handle_drake.station import MakeHandStation

SCENARIO = diagrams_dir() / "tabletop_perception.yaml"


@pytest.mark.parametrize("name", sorted(PROFILES))
def test_the_station_renders_with_the_profiles_pinhole_intrinsics(name):
    # Closed form: f = (H / 2) / tan(fov_y / 2), principal point at the pixel centre
    # ((W - 1) / 2, (H - 1) / 2), as before the camera became Drake's CameraConfig.
    profile = PROFILES[name]
    f = profile.height / 2 / math.tan(math.radians(profile.fov_y_deg) / 2)
    K = [[f, 0, (profile.width - 1) / 2], [0, f, (profile.height - 1) / 2], [0, 0, 1]]
    scenario = LoadScenario(filename=SCENARIO, data=f"cameras: [{{profile: {name}, target: "
                            "[0, 0, 0], config: {name: k, X_PB: {translation: [-0.7, 0, 0.7]}}}]")
    station = MakeHandStation(scenario)
    sensor = station.GetSubsystemByName("camera_k")
    assert isinstance(sensor, RgbdSensor)
    for camera in (sensor.default_depth_render_camera(), sensor.default_color_render_camera()):
        intrinsics = camera.core().intrinsics()
        np.testing.assert_allclose(intrinsics.intrinsic_matrix(), K, rtol=1e-12)
        assert (intrinsics.width(), intrinsics.height()) == (profile.width, profile.height)
        assert camera.core().clipping().near() == 0.01 and camera.core().clipping().far() == 20
    depth = sensor.default_depth_render_camera().depth_range()
    assert (depth.min_depth(), depth.max_depth()) == (0.02, 15.0)
    image = station.GetOutputPort("k.depth").Eval(station.CreateDefaultContext())
    assert (image.width(), image.height()) == (profile.width, profile.height)


def test_camera_scenarios_load_and_round_trip_through_drakes_camera_config():
    files = [p for p in sorted(diagrams_dir().glob("*.yaml")) if "profile:" in p.read_text()]
    assert len(files) >= 2  # tabletop_perception, hamburg_setup
    for path in files:
        scenario = LoadScenario(filename=path)
        (camera,) = scenario.cameras
        assert isinstance(camera, DepthCamera) and isinstance(camera.config, CameraConfig)
        # The Paris Kinect is on the arm's trunk (diagrams/paris_setup.yaml).
        parent = "arm::trunk" if path.name == "paris_setup.yaml" else "world"
        assert camera.name == "kinect" and camera.parent == parent
        again = LoadScenario(data=DumpScenario(scenario)).cameras[0]
        assert repr(again) == repr(camera)


def test_the_profile_factory_fills_drakes_config():
    config = drake_camera_config("kinect_v1", "kin")
    assert (config.width, config.height, config.name) == (640, 480, "kin")
    assert config.focal.y == 43.0 and config.focal.x is None
    # Drake's own YAML defaults, not the profile's, are what a bare config holds.
    assert CameraConfig().focal.y != 43.0


def _visualisers(data=""):
    scenario = LoadScenario(filename=diagrams_dir() / "shadow_sphere_grasp.yaml", data=data)
    station = MakeHandStation(scenario, meshcat=Meshcat())
    return [s for s in station.GetSystems()
            if isinstance(s, MeshcatVisualizer | ContactVisualizer)]


def test_meshcat_visualisers_follow_the_scenarios_visualization_config():
    default = _visualisers()
    # The project's defaults: the illustration and the contact forces, at 32 Hz.
    assert sorted(type(s).__name__ for s in default) == ["ContactVisualizer",
                                                         "MeshcatVisualizer"]
    (illustration,) = [s for s in default if isinstance(s, MeshcatVisualizer)]
    # A MeshcatVisualizer's recording runs at its publish rate.
    assert illustration.StartRecording().frames_per_second() == pytest.approx(32)
    chosen = _visualisers("visualization: {publish_period: 0.1, publish_contacts: false, "
                          "publish_proximity: true}")
    assert [type(s).__name__ for s in chosen] == ["MeshcatVisualizer"] * 2
    for system in chosen:
        assert system.StartRecording().frames_per_second() == pytest.approx(10)
