"""The drivers in Drake primitives (HandDriverDiagram, WristDriverDiagram: the station's
``finite_commands``) against the Python drivers, and the planned hand driver
(``finite_commands="planned"``) against the primitive one, on random finite commands: the
same commands, measurements and plant motion, bit for bit."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.apps.demo import DEMO_SCENARIO
from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.station import MakeHandStation
from handle_drake.systems.hand_driver import (
    HandDriverDiagram,
    PdHandDriver,
    PlannedHandDriver,
    WristDriver,
    WristDriverDiagram,
    plan_hand_commands,
)


def _run(finite_commands, hand, wrist, times, data="", offset=0.0):
    """The demo station driven by piecewise-constant ``hand`` and ``wrist`` commands that
    change at ``times`` (between control periods and on them); what it reports there
    (``offset`` s later)."""
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO, data=data)
    builder = DiagramBuilder()
    station = builder.AddSystem(MakeHandStation(scenario, finite_commands=finite_commands))
    for name, values in (("hand.position", hand), ("wrist.pose", wrist)):
        source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(
            np.r_[times, times[-1] + 1.0], np.vstack([values, values[-1]]).T)))
        builder.Connect(source.get_output_port(), station.GetInputPort(name))
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    sub = station.GetMyContextFromRoot(context)
    out = {name: [] for name in ("hand.position_commanded", "hand.position_measured",
                                 "hand.velocity_estimated", "hand.state_estimated",
                                 "wrist.pose_measured", "plant_state")}
    for t in times[1:]:
        simulator.AdvanceTo(t + offset)
        for name, rows in out.items():
            rows.append(station.GetOutputPort(name).Eval(sub).copy())
    return station, {name: np.array(rows) for name, rows in out.items()}


def test_the_primitive_drivers_command_and_measure_what_the_python_drivers_do():
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)
    station = MakeHandStation(scenario)
    hand0 = station.GetOutputPort("hand.position_commanded").Eval(
        station.CreateDefaultContext()).copy()
    rng = np.random.default_rng(34)
    times = np.r_[0.0, np.cumsum(rng.uniform(0.003, 0.03, 24))]  # ~0.4 s
    # commands within and beyond the joint limits (clamped), far (rate limited) and near
    hand = hand0 + rng.uniform(-2.0, 2.0, (len(times), hand0.size))
    hand[5:8] = hand0 + rng.uniform(-0.01, 0.01, (3, hand0.size))
    wrist0 = station.GetOutputPort("wrist.pose_measured").Eval(
        station.CreateDefaultContext()).copy()
    wrist = wrist0 + rng.uniform(-0.02, 0.02, (len(times), 6))
    fast_station, fast = _run(True, hand, wrist, times)
    slow_station, slow = _run(False, hand, wrist, times)
    assert isinstance(fast_station.GetSubsystemByName("hand_driver"), HandDriverDiagram)
    assert isinstance(fast_station.GetSubsystemByName("wrist_driver"), WristDriverDiagram)
    assert isinstance(slow_station.GetSubsystemByName("hand_driver"), PdHandDriver)
    assert isinstance(slow_station.GetSubsystemByName("wrist_driver"), WristDriver)
    commanded = slow["hand.position_commanded"]
    # the commands were clamped and rate limited (else the comparison shows little)
    steps = np.abs(np.diff(commanded, axis=0))
    assert steps.max() > 0.01 and np.any(commanded == scenario_limits(scenario)[1])
    for name in slow:
        np.testing.assert_array_equal(fast[name], slow[name], err_msg=name)


def scenario_limits(scenario):
    return actuated_position_limits(get_hand_spec(scenario.hand.kind),
                                    scenario.hand.coupling_ratio)


def test_the_primitive_hand_driver_resets_to_a_set_initial_command():
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)
    station = MakeHandStation(scenario, finite_commands=True)
    driver = station.GetSubsystemByName("hand_driver")
    context = station.CreateDefaultContext()
    lower, upper = scenario_limits(scenario)
    wanted = upper + 1.0  # clamped to the limits, as PdHandDriver does
    driver.set_initial_command(driver.GetMyMutableContextFromRoot(context), wanted)
    np.testing.assert_array_equal(
        station.GetOutputPort("hand.position_commanded").Eval(context), upper)


@pytest.mark.parametrize("data", [
    "",  # the demo: 1 ms plant steps, the driver every 5 ms
    "plant_config: {time_step: 0.002}",  # the in-hand trials': 2 ms steps, 5 ms driver
    "plant_config: {time_step: 0.002}\ndriver: !SimHandDriver {control_period: 0.002}",
])
def test_the_planned_hand_driver_hands_the_plant_what_the_primitive_driver_does(data):
    # The same random commands (clamped, rate limited, changing between and on control
    # periods): once sampled by the primitive driver during the run, once as the targets
    # the planned driver is given before it (their values at the driver's update times).
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO, data=data)
    period = scenario.driver.control_period
    station = MakeHandStation(scenario)
    hand0 = station.GetOutputPort("hand.position_commanded").Eval(
        station.CreateDefaultContext()).copy()
    rng = np.random.default_rng(35)
    times = np.r_[0.0, np.cumsum(rng.choice([period, 0.007, 0.0113, 0.05], 40))]
    hand = hand0 + rng.uniform(-2.0, 2.0, (len(times), hand0.size))
    wrist0 = station.GetOutputPort("wrist.pose_measured").Eval(
        station.CreateDefaultContext()).copy()
    wrist = np.tile(wrist0, (len(times), 1))
    # read 0.03 ms after each change: never within 1e-9 s of a driver update, where the
    # two sides' floating-point times could fall on different sides of it
    sampled_station, sampled = _run(True, hand, wrist, times, data, offset=3e-5)
    # the planned driver: the wrist as before, the hand's targets at k * period
    builder = DiagramBuilder()
    planned_station = builder.AddSystem(MakeHandStation(scenario, finite_commands="planned"))
    assert not planned_station.HasInputPort("hand.position")
    source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(
        np.r_[times, times[-1] + 1.0], np.vstack([wrist, wrist[-1]]).T)))
    builder.Connect(source.get_output_port(), planned_station.GetInputPort("wrist.pose"))
    driver = planned_station.GetSubsystemByName("hand_driver")
    assert isinstance(driver, PlannedHandDriver)
    k = np.arange(int(np.ceil(times[-1] / period)) + 1)
    targets = hand[np.searchsorted(times, k * period, side="right") - 1]
    cmd = driver.plan(targets)
    simulator = Simulator(builder.Build())
    sub = planned_station.GetMyContextFromRoot(simulator.get_mutable_context())
    for i, t in enumerate(times[1:]):
        simulator.AdvanceTo(t + 3e-5)
        for name, rows in sampled.items():
            np.testing.assert_array_equal(planned_station.GetOutputPort(name).Eval(sub),
                                          rows[i], err_msg=f"{name} at {t}")
    # the run was rate limited and clamped (else the comparison shows little)
    assert np.abs(np.diff(cmd, axis=0)).max() == pytest.approx(
        scenario.driver.max_joint_velocity * period)
    assert np.any(cmd == scenario_limits(scenario)[1])


def test_planned_commands_follow_the_rate_limit_and_clamp_in_closed_form():
    # one joint from 0 to a target of 1.05 at 0.1 per update: 0.1 k (as repeated sums),
    # then exactly the target; a second joint's target beyond its upper limit 0.25 is
    # clamped to it; a target equal to the command moves nothing
    targets = np.tile([1.05, 3.0, 0.0], (15, 1))
    cmd = plan_hand_commands(np.zeros(3), targets, np.full(3, -1.0), np.array([2.0, 0.25, 1]),
                             0.1)
    expected = np.cumsum(np.full(10, 0.1))
    np.testing.assert_allclose(cmd[1:11, 0], expected, rtol=0, atol=1e-12)
    assert np.all(cmd[11:, 0] == 1.05) and cmd[10, 0] < 1.05
    np.testing.assert_allclose(cmd[:4, 1], [0.0, 0.1, 0.2, 0.25], rtol=0, atol=1e-15)
    assert np.all(cmd[3:, 1] == 0.25) and np.all(cmd[:, 2] == 0.0)
    assert cmd.shape == (16, 3)


def test_the_planned_driver_refuses_targets_it_cannot_play():
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)
    driver = MakeHandStation(scenario, finite_commands="planned").GetSubsystemByName(
        "hand_driver")
    nu = driver.initial_command.size
    for bad, match in ((np.zeros((3, nu + 1)), "targets: expected"),
                       (np.zeros((0, nu)), "targets: expected"),
                       (np.full((2, nu), np.nan), "targets: not finite")):
        with pytest.raises(ValueError, match=match):
            driver.plan(bad)
    with pytest.raises(ValueError, match="finite_commands: expected"):
        MakeHandStation(scenario, finite_commands="yes")
