"""The instrumented devices wherever an object kind is accepted (grasp), and an
accelerometer on any object: a mug (its origin is in its cavity) and a mesh."""

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from handle_drake.cli import main
from handle_drake.demo import diagrams_dir
from handle_drake.instruments.accelerometer import check_sensor_pose
from handle_drake.instruments.station import instrument_X_OS
from handle_drake.objects import ObjectSpec, dimensions
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import MakeHandStation, object_spec

G = 9.81
HAND_AWAY = "hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 1.5]}}}\n"


def test_grasp_plans_and_lifts_a_wiimote_across_its_published_width(tmp_path, capsys):
    """``handle-drake grasp --object wiimote`` (no --size: the device's own)."""
    saved = tmp_path / "wiimote.yaml"
    assert main(["grasp", "--class", "parallel_extension", "--object", "wiimote",
                 "--save-scenario", str(saved)]) == 0
    out = capsys.readouterr().out
    # Planned on its bounding box, fingers across the 36.2 mm width (Nintendo's spec).
    assert "grasp width 3.6 cm" in out and "HELD" in out
    override = LoadScenario(data=saved.read_text())
    assert override.object.kind == "wiimote"
    assert override.object.size == pytest.approx(0.148)


def test_grasp_refuses_what_it_cannot_do_with_a_device(capsys):
    assert main(["grasp", "--class", "tripod", "--object", "joywarrior", "--perceived"]) == 2
    assert "--perceived" in capsys.readouterr().err
    # The Sixaxis is 95 mm deep: too large for a parallel extension (at most 60 mm).
    assert main(["grasp", "--class", "parallel_extension", "--object", "sixaxis"]) == 2
    assert "too large" in capsys.readouterr().err


def test_a_mug_carries_an_accelerometer_glued_inside_its_wall():
    scenario = LoadScenario(data=HAND_AWAY + "object: {kind: mug, size: 0.08, "
                                             "accelerometer: {noise: false}}")
    spec = object_spec(scenario)
    X_OS = instrument_X_OS(scenario)
    # The mug's origin is in its cavity: the nearest surface is the inner wall, at the
    # inner radius (diameter / 2 - wall) from the axis, at mid-height.
    d = dimensions(ObjectSpec("mug", 0.08))
    p = X_OS.translation()
    assert math.hypot(p[0], p[1]) == pytest.approx(d["diameter"] / 2 - d["wall"], abs=1e-3)
    assert abs(p[2]) < 0.005
    check_sensor_pose(spec, X_OS, tolerance=1e-6)  # on the surface
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    station.GetInputPort("hand.position").FixValue(context, np.zeros(20))
    simulator.AdvanceTo(0.3)
    # Upright on the table, sensor axes along the mug's: it feels +1 g along z.
    f = station.GetOutputPort("object.acceleration").Eval(context)
    np.testing.assert_allclose(f, [0, 0, G], atol=0.01 * G)
    np.testing.assert_allclose(station.GetOutputPort("object.roll_pitch").Eval(context), 0,
                               atol=math.radians(0.6))
    assert station.GetOutputPort("object.at_rest").Eval(context)[0] == 1.0


def test_a_mesh_object_accelerometer_is_validated_like_any_other():
    path = diagrams_dir() / "barrett_mesh_bracket_grasp.yaml"
    scenario = LoadScenario(filename=path, data="object: {accelerometer: {}}")
    # The L bracket's bounding-box centre is off its arms: the sensor moves to its surface.
    X_OS = instrument_X_OS(scenario)
    assert np.linalg.norm(X_OS.translation()) > 0.005
    check_sensor_pose(object_spec(scenario), X_OS, tolerance=1e-4)
    with pytest.raises(ScenarioError, match=r"object\.accelerometer\.X_OS: .* off the mesh"):
        LoadScenario(filename=path, data="object: {accelerometer: "
                                         "{X_OS: {translation: [0.5, 0, 0]}}}")
    with pytest.raises(ScenarioError, match=r"object\.accelerometer\.device"):
        LoadScenario(filename=path, data="object: {accelerometer: {device: foo}}")
