"""Figure 8: a JoyWarrior held in a planned tripod grasp, turned by the wrist, then
dropped; its own accelerometer against the plant's truth."""

import json
import math

import pytest

from handle_drake.apps.figure8.experiments import figure8_scenario
from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main
from handle_drake.devices.accelerometer.estimators import EstimatorParams
from handle_drake.devices.accelerometer.profiles import get_profile
from handle_drake.scenario import LoadScenario


def test_joywarrior_tripod_rotation_is_measured_by_the_object_itself(tmp_path):
    """The user's path: ``handle-drake instruments --quick`` (turn 25 deg and back)."""
    out = tmp_path / "figure8.json"
    assert main(["instruments", "--device", "joywarrior", "--quick", "--json", str(out),
                 "--plot", str(tmp_path / "figure8.png"), "--html", str(tmp_path / "r.html")]) == 0
    assert (tmp_path / "figure8.png").stat().st_size > 10_000
    # --html starts Meshcat and saves one replay per device (NAME_<device>.html).
    replay = (tmp_path / "r_joywarrior.html").read_text()
    assert "meshcat" in replay.lower() and len(replay) > 100_000
    (s,) = json.loads(out.read_text())
    assert s["device"] == "joywarrior" and s["grasp_class"] == "tripod"
    assert s["held_through_rotations"]
    # At rest the estimate is within ~1 deg of the truth (noise 1.2 mg, bias ~5 mg,
    # vibration of the held object); during the 25 deg turn the error stays bounded.
    assert s["rest_roll_pitch_deg"]["rms"] < 1.0
    assert s["rest_roll_pitch_deg"]["max"] < 2.5
    assert s["at_rest_flag_at_rest"] > 0.9
    # The turn itself is visible: the truth moves ~25 deg between the two rest phases.
    assert s["moving_roll_pitch_deg"]["rms"] < 10.0
    assert s["false_free_fall_held"] == 0 and s["false_slip_held"] == 0
    # Free fall: flagged within the stated duration plus two device periods (the
    # decimation filter's delay and the sampling phase) of the release.
    params, period = EstimatorParams(), get_profile("joywarrior24f14").period
    assert 0 < s["detection_delay_ms"] <= (params.free_fall_duration + 2 * period) * 1e3 + 1e-6
    assert math.isfinite(s["release_time"]) and 4.0 < s["release_time"] < s["sim_time"]


def test_committed_experiment_diagrams_are_current(tmp_path):
    assert main(["instruments", "--write-scenarios", str(tmp_path)]) == 0
    # the written files equal the committed ones (text, and numbers to 1e-4: the IK's last
    # digits move with numpy's version) in tests/test_written_scenarios.py; here each loads
    written = sorted(tmp_path.glob("instrumented_*.yaml"))
    assert [p.name for p in written] == ["instrumented_joywarrior_tripod.yaml",
                                         "instrumented_wiimote_parallel_extension.yaml"]
    for path in written:
        assert (diagrams_dir() / path.name).is_file(), path.name
        scenario = LoadScenario(filename=path)
        assert scenario.object.accelerometer is not None


def test_bad_experiment_input(capsys):
    with pytest.raises(ValueError, match="device"):
        figure8_scenario("sixaxis")
    with pytest.raises(ValueError, match="rotations"):
        figure8_scenario("joywarrior", rotations=((1.0,),))
    with pytest.raises(SystemExit):
        main(["instruments", "--device", "nunchuk"])
    assert "invalid choice" in capsys.readouterr().err
    assert main(["instruments", "--seed", "-1"]) == 2
    assert "--seed" in capsys.readouterr().err
