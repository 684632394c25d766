"""``MakeHandStation(outputs=...)`` (issue 34): a station built for the outputs its caller
reads leaves out the systems that feed only the others, and simulates the same plant,
bit for bit (nothing left out feeds the plant)."""

import numpy as np
import pytest
from pydrake.systems.framework import Diagram

from handle_drake.apps.demo import DEMO_SCENARIO
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.station import STATION_OUTPUTS, MakeHandStation
from handle_drake.systems.hand_driver import MEASURED_OUTPUTS
from handle_drake.trial.harness import TrialHarness
from handle_drake.trial.simulate import ScenarioRunner

# the demo grasp (its keyframe script closes the fingers on a sphere, lifted by the
# floating wrist): fingertip forces and the object's pose change over the run
DEMO = diagrams_dir() / DEMO_SCENARIO
SCENARIO = """
hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 0.3]}}}
object: {kind: cylinder, on_table: false, X_WO: {translation: [0.33, 0, 0.37]}}
table: null
"""


def _leaf_names(system, prefix=""):
    names = []
    for sub in system.GetSystems():
        if isinstance(sub, Diagram):
            names += _leaf_names(sub, f"{prefix}{sub.get_name()}/")
        else:
            names.append(prefix + sub.get_name())
    return names


def _run(outputs, finite_commands=True, duration=0.9):
    runner = ScenarioRunner(LoadScenario(filename=DEMO), log=(), outputs=outputs,
                            finite_commands=finite_commands)
    runner.reset()
    runner.harness.initialize()
    runner.harness.advance(duration)
    return runner.station, runner.station.GetMyContextFromRoot(runner.context)


def test_no_outputs_leaves_out_the_sensors_and_selectors_and_simulates_the_same_plant():
    full, full_context = _run(None)
    lean, lean_context = _run(())
    left_out = set(_leaf_names(full)) - set(_leaf_names(lean))
    assert left_out == {"tactile", "object_pose", "object_position",
                        "hand_driver/state_estimated", "hand_driver/measured",
                        "wrist_driver/pose_measured"}
    assert set(_leaf_names(lean)) < set(_leaf_names(full))
    for name in ("hand.tactile", "hand.position_measured", "object.pose", "object.position",
                 "wrist.pose_measured"):
        assert full.HasOutputPort(name) and not lean.HasOutputPort(name)
    # the plant's own ports and the commanded position need no system: always there
    for name in ("plant_state", "contact_results", "hand.position_commanded"):
        assert lean.HasOutputPort(name)
    state = full.GetOutputPort("plant_state").Eval(full_context)
    assert np.abs(state - lean.GetOutputPort("plant_state").Eval(lean_context)).max() == 0.0
    # the run moved the finger and the object: the equality is not of a state at rest
    assert np.abs(full.GetOutputPort("hand.tactile").Eval(full_context)).max() > 0.0


@pytest.mark.parametrize("finite_commands", [True, False])
def test_the_outputs_read_are_built_and_read_what_the_full_station_reads(finite_commands):
    read = ("hand.tactile", "hand.position_measured", "object.position")
    full, full_context = _run(None, finite_commands)
    lean, lean_context = _run(read, finite_commands)
    for name in read:
        np.testing.assert_array_equal(lean.GetOutputPort(name).Eval(lean_context),
                                      full.GetOutputPort(name).Eval(full_context))
    assert not lean.HasOutputPort("object.pose")
    # object.position of a free object needs no pose selector (a split of the state)
    assert "object_pose" not in _leaf_names(lean)


def test_a_measured_position_alone_is_one_selector_and_reads_the_full_stations_bits():
    # the demo logs hand.position_measured, not the velocity: one 0/1 selection of the
    # plant state instead of the state selector and its split; the wrist's pose_measured,
    # read, has its own selector, unread none
    read = ("hand.position_measured", "wrist.pose_measured")
    full, full_context = _run(None)
    lean, lean_context = _run(read)
    names = _leaf_names(lean)
    assert "hand_driver/position_measured" in names
    assert {"hand_driver/state_estimated", "hand_driver/measured"}.isdisjoint(names)
    assert "wrist_driver/pose_measured" in names
    assert not lean.HasOutputPort("hand.velocity_estimated")
    for name in read:
        value = lean.GetOutputPort(name).Eval(lean_context)
        expected = full.GetOutputPort(name).Eval(full_context)
        # bit for bit, sign bits included; and the fingers moved (not a state at rest)
        assert value.tobytes() == expected.tobytes()
    assert np.abs(lean.GetOutputPort("hand.position_measured").Eval(lean_context)).max() > 0.1
    velocity, _ = _run(("hand.position_measured", "hand.velocity_estimated"))
    assert {"hand_driver/state_estimated", "hand_driver/measured"} <= set(
        _leaf_names(velocity))


@pytest.mark.parametrize("signal", ["velocity_estimated", "state_estimated"])
def test_any_one_measured_signal_alone_is_one_selector_with_the_full_stations_bits(signal):
    full, full_context = _run(None)
    lean, lean_context = _run((f"hand.{signal}",))
    names = [n for n in _leaf_names(lean) if n.startswith("hand_driver/")]
    assert f"hand_driver/{signal}" in names and "hand_driver/measured" not in names
    others = set(MEASURED_OUTPUTS) - {signal}
    assert not any(lean.HasOutputPort(f"hand.{other}") for other in others)
    value = lean.GetOutputPort(f"hand.{signal}").Eval(lean_context)
    assert value.tobytes() == full.GetOutputPort(f"hand.{signal}").Eval(full_context).tobytes()
    assert np.abs(value).max() > 0.01  # the hand moves at the end of the run (not at rest)


@pytest.mark.parametrize("measured, message", [
    ("position_measured", "measured: expected True, False or names of"),
    (("position_measurd",), "measured: 'position_measurd' is not one of"),
])
def test_a_bad_measured_value_of_the_primitive_driver_is_refused_in_one_line(measured,
                                                                            message):
    from handle_drake.systems.hand_driver import _measured_read

    with pytest.raises(ValueError, match=message) as error:
        _measured_read(measured)
    assert "\n" not in str(error.value)


def test_object_pose_alone_builds_the_selector_without_the_position_split():
    lean, context = _run(("object.pose",))
    names = _leaf_names(lean)
    assert "object_pose" in names and "object_position" not in names
    full, full_context = _run(None)
    assert lean.GetOutputPort("object.pose").Eval(context).IsExactlyEqualTo(
        full.GetOutputPort("object.pose").Eval(full_context))


@pytest.mark.parametrize("outputs, message", [
    (("hand.tactil",), "outputs: no station output is named 'hand.tactil'"),
    ("hand.tactile", "outputs: expected a collection of port names"),
    ((3,), "outputs: expected a collection of port names"),
])
def test_a_bad_outputs_value_is_refused_in_one_line(outputs, message):
    with pytest.raises(ValueError, match=message) as error:
        MakeHandStation(LoadScenario(data=SCENARIO), outputs=outputs)
    assert "\n" not in str(error.value)


def test_a_documented_output_the_scenario_lacks_is_simply_absent():
    # no object: object.pose is a station output of other scenarios, not a typo
    station = MakeHandStation(LoadScenario(data="object: null\ntable: null"),
                              outputs=("object.pose", "hand.tactile"))
    assert not station.HasOutputPort("object.pose") and station.HasOutputPort("hand.tactile")
    assert "object.pose" in STATION_OUTPUTS


def test_the_harness_builds_the_outputs_it_logs():
    harness = TrialHarness(LoadScenario(data=SCENARIO), outputs=(),
                           log=("hand.position_measured",))
    assert harness.station.HasOutputPort("hand.position_measured")
    assert not harness.station.HasOutputPort("hand.tactile")
    harness.reset()
    harness.initialize()
    harness.advance(0.05)
    assert harness.logs()["hand.position_measured"].data().shape[1] > 0
    with pytest.raises(ValueError, match="outputs: expected a collection"):
        TrialHarness(LoadScenario(data=SCENARIO), outputs="hand.tactile")


def test_each_logged_port_logs_its_values_every_log_period_and_a_reset_empties_them():
    log = ("hand.position_measured", "hand.tactile", "object.position")
    runner = ScenarioRunner(LoadScenario(filename=DEMO), log=log)
    runner.reset()  # initializes: the first sample, at t = 0
    runner.harness.advance(1.2)  # the fingers have closed on the sphere
    logs = runner.harness.logs()
    assert list(logs) == list(log)
    context = runner.station.GetMyContextFromRoot(runner.context)
    for name, port_log in logs.items():
        port = runner.station.GetOutputPort(name)
        np.testing.assert_allclose(port_log.sample_times(), np.arange(121) * 0.01,
                                   rtol=0, atol=1e-12)
        assert port_log.data().shape == (port.size(), 121)
        # the last sample, at the end of the run, is the port in the final context
        np.testing.assert_array_equal(port_log.data()[:, -1], port.Eval(context), err_msg=name)
    assert logs["hand.tactile"].data()[:, -1].max() > 0  # fingertips on the sphere...
    assert logs["object.position"].data()[2, -1] > 0  # ... resting on the table
    runner.harness.reset()  # a new trial starts with empty logs
    assert all(port_log.num_samples() == 0 for port_log in runner.harness.logs().values())
