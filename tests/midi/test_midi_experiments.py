"""Figure 9 in simulation: the hand moves the controller, MIDI reports it.

The scenarios are the planned files in diagrams/ (``handle-drake midi
write-scenarios`` writes them); the jog run is cut after the back-turn.
"""

import dataclasses as dc
import math

import numpy as np
import pytest

from handle_drake.demo import diagrams_dir
from handle_drake.midi.codec import fader_value
from handle_drake.midi.experiments import fader_push_scenario, run_midi_scenario
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
