"""The station's per-step Python (tactile sensor, hand and wrist drivers) made cheaper
(issue 34) without changing a result: a fixed trial logs the same signals, bit for bit,
as with the straightforward implementations below (the code these systems had before:
one Python pass over every contact pair, ``np.clip``, ``np.concatenate``)."""

import numpy as np
import pytest

from handle_drake import station as station_module
from handle_drake.apps.demo import DEMO_SCENARIO
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.systems.hand_driver import PdHandDriver, WristDriver, pose_to_wrist_joints
from handle_drake.systems.tactile import FingertipTactile, _mean_normal
from handle_drake.trial.simulate import ScenarioRunner


def reference_normal_forces(contact_results, bodies, geometry_to_body):
    slot = {index: i for i, index in enumerate(bodies)}
    forces = np.zeros(len(bodies))
    for i in range(contact_results.num_point_pair_contacts()):
        info = contact_results.point_pair_contact_info(i)
        magnitude = abs(float(np.dot(info.contact_force(), info.point_pair().nhat_BA_W)))
        for body in (info.bodyA_index(), info.bodyB_index()):
            if body in slot:
                forces[slot[body]] += magnitude
    for i in range(contact_results.num_hydroelastic_contacts()):
        info = contact_results.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        magnitude = abs(float(np.dot(info.F_Ac_W().translational(), _mean_normal(surface))))
        for geometry in (surface.id_M(), surface.id_N()):
            body = geometry_to_body.get(geometry)
            if body in slot:
                forces[slot[body]] += magnitude
    return forces


class ReferenceTactile(FingertipTactile):
    def _calc(self, context, out):
        out.SetFromVector(reference_normal_forces(
            self._contact_port.Eval(context), self._bodies, self._geometry_to_body))


class ReferenceHandDriver(PdHandDriver):
    def target(self, context):
        if not self._command_port.HasValue(context):
            return self._initial
        target = self._command_port.Eval(context)
        if not np.all(np.isfinite(target)):
            return context.get_discrete_state(self._command_state).value()
        return np.clip(target, self._lower, self._upper)

    def _update_command(self, context, discrete_state):
        current = context.get_discrete_state(self._command_state).value()
        command = current + np.clip(self.target(context) - current, -self._max_step,
                                    self._max_step)
        discrete_state.set_value(self._command_state, command)
        discrete_state.set_value(self._desired_state, np.concatenate(
            [command[self._actuator_order], np.zeros(len(command))]))


class ReferenceWristDriver(WristDriver):
    def _update(self, context, discrete_state):
        if not self._pose_port.HasValue(context):
            return
        pose = self._pose_port.Eval(context)
        if np.all(np.isfinite(pose)):
            discrete_state.set_value(self._desired_state, np.concatenate(
                [pose_to_wrist_joints(pose)[self._actuator_order], np.zeros(6)]))


def _demo_logs(contact_model="point", duration=1.3, finite_commands=None):
    """The demo grasp (reach, close on the sphere: contacts from ~0.9 s) with every logger."""
    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO,
                            data=f"plant_config: {{contact_model: {contact_model}}}")
    runner = ScenarioRunner(scenario, finite_commands=finite_commands)
    result = runner.run(duration)
    return result, runner.harness.logs()


@pytest.mark.parametrize("contact_model", ["point", "hydroelastic_with_fallback"])
def test_the_station_logs_what_the_reference_systems_log(monkeypatch, contact_model):
    # the script's run: the drivers in Drake primitives (finite_commands, the default of a
    # scripted scenario); the station's Python drivers; the reference Python systems
    duration = 1.3 if contact_model == "point" else 1.05
    fast, fast_logs = _demo_logs(contact_model, duration)
    runner = ScenarioRunner(LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO))
    assert not isinstance(runner.station.GetSubsystemByName("hand_driver"), PdHandDriver)
    python, python_logs = _demo_logs(contact_model, duration, finite_commands=False)
    with monkeypatch.context() as patch:
        patch.setattr(station_module, "FingertipTactile", ReferenceTactile)
        patch.setattr(station_module, "PdHandDriver", ReferenceHandDriver)
        patch.setattr(station_module, "WristDriver", ReferenceWristDriver)
        reference, reference_logs = _demo_logs(contact_model, duration, finite_commands=False)
    assert len(fast.times) == len(reference.times) == round(duration / 0.01) + 1
    # The trial touches: several fingertips carry load (else the tactile check is empty).
    assert np.count_nonzero(reference.tactile[-1] > 0.1) >= 3
    for run, logs in ((fast, fast_logs), (python, python_logs)):
        np.testing.assert_array_equal(run.tactile, reference.tactile)
        np.testing.assert_array_equal(run.hand_position, reference.hand_position)
        np.testing.assert_array_equal(run.object_position, reference.object_position)
        assert logs.keys() == reference_logs.keys()
        for name, log in logs.items():
            np.testing.assert_array_equal(log.data(), reference_logs[name].data(),
                                          err_msg=name)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_hand_command_is_ignored_and_a_finite_one_rate_limited(bad):
    """The hand driver's update keeps its rules: a command with any non-finite entry
    holds the current command; a finite one moves it by at most max_joint_velocity x
    control_period per update, clamped to the joint limits."""
    from pydrake.systems.analysis import Simulator

    from handle_drake.station import MakeHandStation

    scenario = LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)
    station = MakeHandStation(scenario)
    driver = station.GetSubsystemByName("hand_driver")
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    commanded = station.GetOutputPort("hand.position_commanded")
    initial = commanded.Eval(context).copy()
    command = initial.copy()
    command[3] = bad
    station.GetInputPort("hand.position").FixValue(context, command)
    simulator.AdvanceTo(0.02)
    np.testing.assert_array_equal(commanded.Eval(context), initial)

    target = initial + 10.0  # far beyond every upper limit
    station.GetInputPort("hand.position").FixValue(context, target)
    period = scenario.driver.control_period
    simulator.AdvanceTo(0.02 + 2.5 * period)  # three updates: 0.02, +T, +2T
    moved = commanded.Eval(context) - initial
    step = scenario.driver.max_joint_velocity * period
    upper = driver._upper
    np.testing.assert_allclose(moved, np.minimum(3 * step, upper - initial), rtol=0, atol=1e-12)
