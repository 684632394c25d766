"""The instrumented devices wherever an object kind is accepted (grasp), and an
accelerometer on any object: a mug (its origin is in its cavity) and a mesh."""

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main
from handle_drake.devices.accelerometer.sensor import check_sensor_pose
from handle_drake.devices.accelerometer.wiring import instrument_X_OS
from handle_drake.geometry.objects import ObjectSpec, dimensions
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
    X_OS = instrument_X_OS(scenario, object_spec(scenario))
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
    X_OS = instrument_X_OS(scenario, object_spec(scenario))
    assert np.linalg.norm(X_OS.translation()) > 0.005
    check_sensor_pose(object_spec(scenario), X_OS, tolerance=1e-4)
    with pytest.raises(ScenarioError, match=r"object\.accelerometer\.X_OS: .* off the mesh"):
        LoadScenario(filename=path, data="object: {accelerometer: "
                                         "{X_OS: {translation: [0.5, 0, 0]}}}")
    with pytest.raises(ScenarioError, match=r"object\.accelerometer\.device"):
        LoadScenario(filename=path, data="object: {accelerometer: {device: foo}}")


def test_simulate_reports_the_free_fall_of_a_dropped_joywarrior(tmp_path, capsys):
    """``handle-drake simulate`` with ``object.accelerometer``: a JoyWarrior dropped
    from 5 cm onto the table falls for sqrt(2 h / g) = 101 ms, then rests level."""
    h = 0.05
    path = tmp_path / "drop.yaml"
    path.write_text(HAND_AWAY + "object: {kind: joywarrior, on_table: false, "
                    f"X_WO: {{translation: [0.3, 0.3, {0.0125 + h}]}}, "
                    "accelerometer: {noise: false}}\nsimulation_duration: 0.5\n")
    assert main(["simulate", str(path)]) == 0
    out = capsys.readouterr().out
    line = next(s for s in out.splitlines() if "free fall flagged" in s)
    (span,) = line.split(": ", 1)[1].split(", ")
    start, end = (float(v) for v in span.removesuffix(" s").split("-"))
    fall = math.sqrt(2 * h / G)
    period = 0.008
    # Flagged after the stated 24 ms (3 samples) of near-zero g; it ends at the impact
    # (the 2-period filter sees it at the next sample); the log samples every 10 ms.
    log = 0.01
    assert 0.016 <= start <= 0.024 + period + log
    assert fall - log - 0.002 <= end <= fall + period
    assert "slip flagged: never" in out
    rest = next(s for s in out.splitlines() if "at 0.50 s" in s)
    assert "(at rest)" in rest and "|f| = 1.00" in rest
    assert "roll +0.0 deg, pitch -0.0 deg" in rest or "roll +0.0 deg, pitch +0.0 deg" in rest
