"""Figure 9 in simulation: the hand moves the controller, MIDI reports it.

The scenarios are the planned files in diagrams/ (``handle-drake midi
write-scenarios`` writes them); the jog run is cut after the back-turn.
"""

import dataclasses as dc
import math
import re

import numpy as np
import pytest

from handle_drake.apps.figure9.experiments import fader_push_scenario, run_midi_scenario
from handle_drake.base.models import diagrams_dir
from handle_drake.devices.midi.codec import fader_value
from handle_drake.scenario import LoadScenario


def test_palmar_pinch_turns_the_jog_wheel_and_midi_counts_its_rotation():
    scenario = LoadScenario(filename=diagrams_dir() / "midi_jog_pinch.yaml",
                            data="simulation_duration: 3.1")
    result = run_midi_scenario(scenario)
    s = result.jog_summary()
    # The wrist turned 60 degrees then 20 back; the pinched wheel followed.
    assert 45 < s["max_rotation_deg"] < 75
    assert 25 < s["rotation_deg"] < s["max_rotation_deg"] - 8
    # Within one tick of the true rotation, after turning both ways.
    assert abs(s["midi_ticks"] - s["true_ticks"]) < 1.0
    assert s["peak_midi_ticks"] > s["midi_ticks"]
    assert result.counts["rejected"] == 0
    # only the wheel moved (before the free fingers were tucked: knob9 -58 deg, mode pressed)
    for name in result.control_names:
        if name != "jog":
            swing = float(np.abs(result.position(name) - result.position(name)[0]).max())
            assert swing < (math.radians(1.0) if name.startswith("knob") else 0.5e-3), name


def test_fingertip_pushes_a_fader_and_the_midi_value_follows():
    scenario = LoadScenario(filename=diagrams_dir() / "midi_fader_push.yaml",
                            data="simulation_duration: 1.8")
    result = run_midi_scenario(scenario)
    travel = 0.060
    s = result.fader_summary("fader5", travel)
    assert s["travel_m"] > 0.02  # the fingertip moved the cap
    assert s["max_error_counts"] <= 1
    assert s["final_value"] == fader_value(result.position("fader5")[-1], travel)
    others = [n for n in result.control_names if n.startswith("fader") and n != "fader5"]
    assert max(np.abs(result.position(n)).max() for n in others) < 1e-3


def test_shipped_scenarios_match_what_the_planner_writes():
    shipped = LoadScenario(filename=diagrams_dir() / "midi_fader_push.yaml")
    fresh = fader_push_scenario()
    assert [k.time for k in shipped.script] == [k.time for k in fresh.script]
    for a, b in zip(shipped.script, fresh.script, strict=True):
        assert np.allclose(a.wrist, b.wrist) and a.hand == pytest.approx(b.hand)
    assert shipped.object is None and shipped.midi_controller is not None


def test_experiment_arguments_are_checked():
    with pytest.raises(ValueError, match="fader"):
        fader_push_scenario(fader="fader10")
    with pytest.raises(ValueError, match="push"):
        fader_push_scenario(push=0.5)
    with pytest.raises(ValueError, match="midi_controller"):
        run_midi_scenario(LoadScenario(data="object: null"))
    from handle_drake.scenario import GuardedGraspController

    with pytest.raises(ValueError, match="scenario.controller"):  # the receiver takes its place
        run_midi_scenario(dc.replace(fader_push_scenario(), controller=GuardedGraspController()))
    assert math.isfinite(fader_push_scenario().simulation_duration)


def _wrist_yaws(scenario) -> np.ndarray:
    return np.degrees([k.wrist[5] for k in scenario.script if k.wrist])


@pytest.fixture(scope="module")
def clockwise_pinch():
    """The pinch turning the wheel clockwise past the wrist's yaw of -180 degrees
    (the planned grasp's yaw is -144 deg: -75 then 25 further is -244 deg)."""
    from handle_drake.apps.figure9.experiments import jog_pinch_scenario

    return jog_pinch_scenario(turn_deg=-75, back_deg=25)


def test_a_clockwise_turn_past_180_degrees_keeps_the_wrist_yaw_continuous(clockwise_pinch):
    yaws = _wrist_yaws(clockwise_pinch)
    # no keyframe jumps (RollPitchYaw wraps -184 deg to +176: the long way round)
    assert np.abs(np.diff(yaws)).max() < 10.0
    assert yaws.min() < -180.0
    # the turn the script makes: -75, then 25 further the same way
    from handle_drake.apps.figure9.experiments import commanded_wrist_turn_deg

    scenario = clockwise_pinch
    assert commanded_wrist_turn_deg(scenario, 0.0, scenario.simulation_duration) == \
        pytest.approx(-100.0, abs=1e-9)


def test_midi_jog_fails_when_the_wheel_does_not_follow_the_wrist(clockwise_pinch, tmp_path,
                                                                   capsys):
    from handle_drake.cli import main
    from handle_drake.scenario import DumpScenario

    fixed = tmp_path / "clockwise.yaml"
    fixed.write_text(DumpScenario(clockwise_pinch))
    assert main(["midi", "jog", "--scenario", str(fixed)]) == 0
    out = capsys.readouterr().out
    wheel = float(re.search(r"true rotation *([-+\d.]+) deg", out)[1])
    assert -110 < wheel < -80, out  # the wheel turned clockwise with the wrist
    assert "the wheel followed" in out
    # The same script with the yaw wrapped to [-180, 180) (as before the fix): the wrist
    # goes the long way round and the command must not report success.
    wrapped = dc.replace(clockwise_pinch, script=[
        dc.replace(k, wrist=[*k.wrist[:5], (k.wrist[5] + math.pi) % (2 * math.pi) - math.pi])
        if k.wrist else k for k in clockwise_pinch.script])
    old = tmp_path / "wrapped.yaml"
    old.write_text(DumpScenario(wrapped))
    assert main(["midi", "jog", "--scenario", str(old)]) == 1
    captured = capsys.readouterr()
    assert "did NOT follow" in captured.out
    assert "the pinch did not carry it" in captured.err and "Traceback" not in captured.err


def test_a_turn_without_a_back_turn_is_a_valid_scenario():
    from handle_drake.apps.figure9.experiments import jog_pinch_scenario
    from handle_drake.scenario import DumpScenario

    scenario = jog_pinch_scenario(turn_deg=25, back_deg=0)
    times = [k.time for k in scenario.script]
    assert np.all(np.diff(times) > 0)
    loaded = LoadScenario(data=DumpScenario(scenario))  # validates the script
    yaws = _wrist_yaws(loaded)
    assert yaws[-1] - yaws[0] == pytest.approx(25.0, abs=1e-6)
