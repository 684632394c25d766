"""SynergyController against closed-form behaviour: ramps at the velocity
limit, the synergy map, continuity across mode switches, fingertip tracking."""

import numpy as np
import pytest
from pydrake.common.value import Value
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.grasp.analysis import fit_record_synergies
from handle_drake.grasp.recordings import load_grasps
from handle_drake.grasp.synthetic import DATA_FILE
from handle_drake.systems.synergy_controller import ControlMode, SynergyController

SPEC = get_hand_spec("shadow")
LOWER, UPPER = actuated_position_limits(SPEC, 1.0)
V, DT = 2.0, 0.01


@pytest.fixture(scope="module")
def synergies():
    return fit_record_synergies(load_grasps(DATA_FILE), k=3)


def _rig(synergies, amplitudes, joint=None, tips=None, mode=ControlMode.SYNERGY, initial=None,
         mode_source=None):
    builder = DiagramBuilder()
    ctrl = builder.AddSystem(SynergyController(synergies, initial, max_joint_velocity=V,
                                               period=DT, mode=mode))
    src = builder.AddSystem(ConstantVectorSource(np.asarray(amplitudes, float)))
    builder.Connect(src.get_output_port(), ctrl.get_amplitudes_input_port())
    if joint is not None:
        j = builder.AddSystem(ConstantVectorSource(np.asarray(joint, float)))
        builder.Connect(j.get_output_port(), ctrl.get_joint_command_input_port())
    if tips is not None:
        t = builder.AddSystem(ConstantVectorSource(np.asarray(tips, float).ravel()))
        builder.Connect(t.get_output_port(), ctrl.get_fingertip_targets_input_port())
    if mode_source is not None:
        m = builder.AddSystem(ConstantValueSource(Value(mode_source)))
        builder.Connect(m.get_output_port(), ctrl.get_mode_input_port())
    diagram = builder.Build()
    sim = Simulator(diagram)
    return ctrl, sim


def _command(ctrl, sim):
    return ctrl.get_position_output_port().Eval(
        ctrl.GetMyContextFromRoot(sim.get_context())).copy()


def test_amplitude_step_ramps_at_the_velocity_limit_to_the_synergy_posture(synergies):
    a1 = 0.5 * (synergies.amplitude_min[:3] + synergies.amplitude_max[:3]) + 0.3 * np.ptp(
        np.c_[synergies.amplitude_min[:3], synergies.amplitude_max[:3]], axis=1)
    q0 = np.clip(synergies.mean, LOWER, UPPER)
    q1 = np.clip(synergies.mean + a1 @ synergies.components[:3], LOWER, UPPER)
    ctrl, sim = _rig(synergies, a1, initial=q0)
    delta = q1 - q0
    assert np.max(np.abs(delta)) > 5 * V * DT  # a step that takes several updates
    for n in (1, 3, 7):
        # Updates at t = 0, DT, 2 DT, ...: AdvanceTo(t) after n updates.
        sim.AdvanceTo((n - 1) * DT + DT / 2)
        expected = q0 + np.sign(delta) * np.minimum(np.abs(delta), n * V * DT)
        np.testing.assert_allclose(_command(ctrl, sim), expected, atol=1e-12)
    sim.AdvanceTo(np.max(np.abs(delta)) / V + 5 * DT)
    # Closed form target: mean + basis @ a (within the limits here).
    np.testing.assert_allclose(_command(ctrl, sim), q1, atol=1e-12)


def test_mode_switch_keeps_the_command_continuous(synergies):
    far = np.clip(synergies.mean + 1.0, LOWER, UPPER)
    ctrl, sim = _rig(synergies, np.zeros(3), joint=far, mode=ControlMode.SYNERGY,
                     initial=np.clip(synergies.mean - 0.3, LOWER, UPPER))
    sim.AdvanceTo(0.5 + DT / 2)  # sample between updates
    before = _command(ctrl, sim)
    np.testing.assert_allclose(before, np.clip(synergies.mean, LOWER, UPPER), atol=1e-12)
    ctrl.set_mode(ctrl.GetMyMutableContextFromRoot(sim.get_mutable_context()), "joint")
    last = before
    for k in range(1, 40):
        sim.AdvanceTo(0.5 + DT / 2 + k * DT)
        now = _command(ctrl, sim)
        assert np.max(np.abs(now - last)) <= V * DT + 1e-12
        last = now
    sim.AdvanceTo(2.0)
    np.testing.assert_allclose(_command(ctrl, sim), far, atol=1e-12)


def test_mode_input_port_overrides_the_state(synergies):
    target = np.clip(synergies.mean + 0.2, LOWER, UPPER)
    ctrl, sim = _rig(synergies, np.zeros(3), joint=target, mode=ControlMode.SYNERGY,
                     mode_source=ControlMode.JOINT)
    sim.AdvanceTo(1.0)
    np.testing.assert_allclose(_command(ctrl, sim), target, atol=1e-12)
    mode = ctrl.GetOutputPort("active_mode").Eval(ctrl.GetMyContextFromRoot(sim.get_context()))
    assert mode is ControlMode.JOINT


def test_cartesian_mode_moves_the_fingertips_to_reachable_targets(synergies):
    ctrl = SynergyController(synergies, max_joint_velocity=V, period=DT)
    # Targets: the fingertips of a different posture of the same hand (reachable).
    goal = np.clip(synergies.mean + 0.25 * np.sign(synergies.components[0]), LOWER, UPPER)
    tips = ctrl.fingertip_positions(goal)
    start = np.clip(synergies.mean, LOWER, UPPER)
    ctrl, sim = _rig(synergies, np.zeros(3), tips=tips, mode=ControlMode.CARTESIAN,
                     initial=start)
    error0 = np.max(np.linalg.norm(ctrl.fingertip_positions(start) - tips, axis=1))
    assert error0 > 0.01
    sim.AdvanceTo(1.5)
    got = ctrl.fingertip_positions(_command(ctrl, sim))
    assert np.max(np.linalg.norm(got - tips, axis=1)) < 1e-3
    cmd = _command(ctrl, sim)
    assert np.all(cmd >= LOWER - 1e-12) and np.all(cmd <= UPPER + 1e-12)


def test_commands_stay_within_limits_for_huge_amplitudes(synergies):
    ctrl, sim = _rig(synergies, np.array([50.0, -50.0, 50.0]))
    sim.AdvanceTo(3.0)
    cmd = _command(ctrl, sim)
    assert np.all(cmd >= LOWER - 1e-12) and np.all(cmd <= UPPER + 1e-12)
    assert np.any(np.isclose(cmd, LOWER) | np.isclose(cmd, UPPER))


def test_bad_arguments_raise_clear_errors(synergies):
    with pytest.raises(TypeError, match="Synergies"):
        SynergyController("not synergies")
    with pytest.raises(ValueError, match="max_joint_velocity"):
        SynergyController(synergies, max_joint_velocity=0.0)
    with pytest.raises(ValueError, match=r"expected shape \(20,\)"):
        SynergyController(synergies, initial_command=np.zeros(5))
    with pytest.raises(ValueError, match="unknown control mode"):
        SynergyController(synergies, mode="teleport")
    ctrl = SynergyController(synergies)
    with pytest.raises(ValueError, match="unknown control mode"):
        ctrl.set_mode(ctrl.CreateDefaultContext(), 7)
