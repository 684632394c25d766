"""The drivers in Drake primitives (HandDriverDiagram, WristDriverDiagram: the station's
``finite_commands``) against the Python drivers, on random finite commands: the same
commands, measurements and plant motion, bit for bit."""

import numpy as np
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
    WristDriver,
    WristDriverDiagram,
)


def _run(finite_commands, hand, wrist, times, data=""):
    """The demo station driven by piecewise-constant ``hand`` and ``wrist`` commands that
    change at ``times`` (between control periods and on them); what it reports there."""
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
        simulator.AdvanceTo(t)
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
