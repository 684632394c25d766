"""ReactiveGrasp against closed-form behaviour with scripted fingertip forces.

The tactile input is a zero-order-hold script (finger i's force steps from 0 to
1 N at its own time), the measured wrist pose is the controller's own command
fed back (perfect tracking) unless a test says otherwise. With control period
h, a quantity that grows by r per update for every update at a time t_k = k h
before an event at t_c has grown by r (ceil(t_c / h) - 1) at the event (the
update at t = 0 counts for the approach, not for the closing, which starts on
the update after the arrival).
"""

import math

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.systems.reactive_grasp import (
    ReactiveGrasp,
    ReactiveGraspMode,
    ReactiveGraspParams,
    TaxelPadLayout,
    finger_command_groups,
)

H = 0.01  # s, control period of these tests
GROUPS = finger_command_groups("shadow")  # FF MF RF LF TH
FF, MF, RF, LF, TH = range(5)


def _hand(closing_fingers=(FF, MF, TH)):
    preshape = np.linspace(-0.1, 0.1, 20)
    closed = preshape.copy()
    for i in closing_fingers:
        closed[GROUPS[i]] += 0.8
    return preshape, closed


def _force_script(step_times, t_end=10.0):
    """(5,) fingertip forces: finger i is 0 N before step_times[i], 1 N after (None: never)."""
    times = sorted({0.0, t_end} | {t for t in step_times if t is not None})
    values = np.array([[1.0 if (s is not None and t >= s) else 0.0 for s in step_times]
                       for t in times]).T
    return PiecewisePolynomial.ZeroOrderHold(times, values)


def _simulate(controller, forces, measured=None, connect=None):
    builder = DiagramBuilder()
    grasp = builder.AddSystem(controller)
    if connect is not None:  # the test's own extra inputs
        connect(builder, grasp)
    tactile = builder.AddSystem(TrajectorySource(forces))
    builder.Connect(tactile.get_output_port(), grasp.get_tactile_input_port())
    if measured is None:  # perfect tracking: the command is the measurement
        builder.Connect(grasp.GetOutputPort("wrist_pose"),
                        grasp.get_wrist_pose_measured_input_port())
    else:
        source = builder.AddSystem(ConstantVectorSource(measured))
        builder.Connect(source.get_output_port(), grasp.get_wrist_pose_measured_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = grasp.GetMyContextFromRoot(simulator.get_context())

    def at(t):
        """Outputs after every update at times <= t (t is taken between two updates)."""
        simulator.AdvanceTo(t)
        return dict(
            wrist=grasp.GetOutputPort("wrist_pose").Eval(context).copy(),
            hand=grasp.GetOutputPort("hand_position").Eval(context).copy(),
            closing=grasp.GetOutputPort("closing").Eval(context).copy(),
            mode=ReactiveGraspMode(int(grasp.GetOutputPort("mode").Eval(context)[0])),
        )

    return at, context


def _updates_before(t_c):
    return math.ceil(t_c / H - 1e-9) - 1


def test_each_finger_stops_at_its_own_contact_then_squeezes_and_lifts():
    preshape, closed = _hand()
    p = ReactiveGraspParams(close_rate=2.0, max_closing=1.0, squeeze=0.3, squeeze_time=0.1,
                            hold_time=0.1, lift_height=0.05, lift_speed=0.5)
    pose = [0.1, -0.2, 0.3, 0.0, 0.5, 1.0]
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params=p, period=H)
    # FF touches at 0.155 s, MF at 0.255 s, TH at 0.3549 s; RF gets a force at
    # 0.1 s but is no grasp finger (closed == preshape), so it is ignored.
    contact = {FF: 0.155, MF: 0.255, TH: 0.3549}
    at, context = _simulate(grasp, _force_script([0.155, 0.255, 0.1, None, 0.3549]))
    out = at(0.2049)
    assert out["mode"] is ReactiveGraspMode.CLOSE
    # FF stopped at its contact, MF and TH still closing at close_rate per second.
    assert out["closing"][FF] == pytest.approx(p.close_rate * H * _updates_before(0.155))
    assert out["closing"][MF] == pytest.approx(p.close_rate * H * math.floor(0.2049 / H))
    out = at(0.3605)
    s_contact = {i: p.close_rate * H * _updates_before(t) for i, t in contact.items()}
    for i, s in s_contact.items():
        assert out["closing"][i] == pytest.approx(s, abs=1e-12)
        assert out["closing"][i] == pytest.approx(p.close_rate * contact[i], abs=p.close_rate * H)
    assert out["mode"] is ReactiveGraspMode.SQUEEZE
    # After the squeeze every grasp finger is `squeeze` further, the command
    # is preshape + s (closed - preshape) on its joints; RF and LF untouched.
    out = at(0.36 + p.squeeze_time + 0.5 * H)
    for i, s in s_contact.items():
        assert out["closing"][i] == pytest.approx(s + p.squeeze, abs=1e-12)
        g = GROUPS[i]
        np.testing.assert_allclose(out["hand"][g], preshape[g] + (s + p.squeeze)
                                   * (closed[g] - preshape[g]), atol=1e-12)
    for i in (RF, LF):
        np.testing.assert_allclose(out["hand"][GROUPS[i]], preshape[GROUPS[i]])
    # Lift: after the hold the wrist rises at lift_speed up to lift_height.
    lift_start = 0.36 + p.squeeze_time + p.hold_time
    out = at(lift_start + 0.05 + 0.5 * H)
    assert out["mode"] is ReactiveGraspMode.LIFT
    assert out["wrist"][2] - pose[2] == pytest.approx(p.lift_speed * 0.05, abs=p.lift_speed * H)
    out = at(lift_start + 0.5)
    np.testing.assert_allclose(out["wrist"], np.add(pose, [0, 0, p.lift_height, 0, 0, 0]))
    assert grasp.lift_complete(context)


def test_a_finger_without_contact_stops_at_max_closing():
    preshape, closed = _hand()
    p = ReactiveGraspParams(close_rate=2.0, max_closing=0.6, squeeze=0.2, squeeze_time=0.1)
    pose = np.zeros(6)
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params=p, period=H)
    at, _ = _simulate(grasp, _force_script([0.105, 0.105, None, None, None]))
    out = at(0.3 + 0.5 * H)  # 0.6 / 2.0 = 0.3 s to reach max_closing
    assert out["closing"][TH] == pytest.approx(p.max_closing)
    assert out["mode"] is ReactiveGraspMode.SQUEEZE
    out = at(0.6)
    assert out["closing"][TH] == pytest.approx(p.max_closing + p.squeeze)
    assert out["closing"][FF] == pytest.approx(p.close_rate * H * _updates_before(0.105)
                                               + p.squeeze)


def test_an_early_contact_slows_and_shifts_the_approach():
    preshape, closed = _hand()
    p = ReactiveGraspParams(approach_speed=0.1, slow_factor=0.25, shift_speed=0.02,
                            max_shift=0.004)
    start, goal = [0.0, 0.0, 0.3, 0, 0, 0], [0.0, 0.0, 0.1, 0, 0, 0]
    outward = np.zeros((5, 3))
    outward[FF] = [0.0, 1.0, 0.5]  # the sideways part (the approach is along z) is +y
    grasp = ReactiveGrasp(start, goal, preshape, closed, GROUPS, params=p,
                          finger_directions_B=outward, period=H)
    t_c = 0.505
    at, _ = _simulate(grasp, _force_script([t_c, None, None, None, None]))
    a = at(0.305)
    b = at(0.405)
    assert a["mode"] is ReactiveGraspMode.APPROACH
    assert (a["wrist"][2] - b["wrist"][2]) / 0.1 == pytest.approx(p.approach_speed)
    shifted = at(0.615)  # updates at 0.51 ... 0.61 s saw the contact
    n_touching = math.floor(0.615 / H) - math.floor(t_c / H)
    assert shifted["wrist"][1] == pytest.approx(p.shift_speed * H * n_touching, abs=1e-12)
    a = at(0.705)
    b = at(0.905)
    assert b["mode"] is ReactiveGraspMode.SLOW_APPROACH
    assert (a["wrist"][2] - b["wrist"][2]) / 0.2 == pytest.approx(
        p.slow_factor * p.approach_speed)
    # Travel so far: full speed on the updates before t_c, slowed after.
    n_fast = _updates_before(t_c) + 1  # the update at t = 0 moves too
    n_slow = round(0.905 / H) + 1 - n_fast
    travel = H * p.approach_speed * (n_fast + p.slow_factor * n_slow)
    assert start[2] - b["wrist"][2] == pytest.approx(travel)
    # Sideways shift along +y at shift_speed while touching, capped at max_shift.
    assert a["wrist"][0] == pytest.approx(0.0)
    assert a["wrist"][1] == pytest.approx(p.max_shift)  # 0.2 s * 0.02 m/s > 4 mm
    np.testing.assert_allclose(b["hand"], preshape)  # fingers stay in the pre-shape


def test_the_optional_centring_close_shifts_the_wrist_while_only_some_fingers_touch():
    """close_shift_speed > 0: from the first grasp finger's contact until every
    grasp finger touches, the wrist moves along the touching finger's outward
    direction at close_shift_speed, capped at max_shift + max_close_shift; off
    (the default), the wrist stays where the approach left it."""
    preshape, closed = _hand()
    pose = np.zeros(6)
    outward = np.zeros((5, 3))
    outward[FF] = [0.0, 1.0, 0.0]
    forces = _force_script([0.105, 0.255, None, None, 0.3549])  # FF, then MF, then TH
    p = ReactiveGraspParams(close_rate=1.0, close_shift_speed=0.02, max_shift=0.0,
                            max_close_shift=0.003)
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params=p,
                          finger_directions_B=outward, period=H)
    at, _ = _simulate(grasp, forces)
    out = at(0.2049)  # updates at 0.11 ... 0.20 s saw FF alone
    assert out["mode"] is ReactiveGraspMode.CLOSE
    np.testing.assert_allclose(out["wrist"][:3], [0.0, 0.02 * H * 10, 0.0], atol=1e-12)
    out = at(0.5)  # capped at 3 mm, and still there after every finger touched
    np.testing.assert_allclose(out["wrist"][:3], [0.0, 0.003, 0.0], atol=1e-12)
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, period=H,
                          finger_directions_B=outward)
    at, _ = _simulate(grasp, forces)
    np.testing.assert_allclose(at(0.5)["wrist"], pose)


def _cop_pads():
    """FF's and TH's 4 x 4 pads (3.5 mm across, 4.5 mm along) facing each other: FF's
    pad (body 1, at the identity) looks along world +x, its u along +y, its v along
    +z; TH's (body 2, turned half a turn about z) looks along -x, its u along -y.
    Pressed: FF's cell (row 1, col 3) at u = +5.25 mm, TH's cells (row 2, cols 0 and 1)
    at u = -5.25 and -1.75 mm (centre of pressure u = -3.5 mm); a reading under the
    noise floor on FF's cell (row 3, col 0) is empty."""
    centres = np.array([[(c - 1.5) * 0.0035, (r - 1.5) * 0.0045]
                        for r in range(4) for c in range(4)])
    R_BP = RotationMatrix(np.column_stack([[0.0, 1, 0], [0.0, 0, 1], [1.0, 0, 0]]))
    pads = [None] * 5
    pads[FF] = TaxelPadLayout(0, centres, 0.0035 * 0.0045, 1, RigidTransform(R_BP, [0, 0, 0]),
                              noise_floor=3000.0)
    pads[TH] = TaxelPadLayout(16, centres, 0.0035 * 0.0045, 2, RigidTransform(R_BP, [0, 0, 0]),
                              noise_floor=3000.0)
    taxels = np.zeros(32)
    taxels[1 * 4 + 3] = 1e5
    taxels[3 * 4 + 0] = 2000.0  # under the floor
    taxels[16 + 2 * 4 + 0] = taxels[16 + 2 * 4 + 1] = 1e5
    poses = [RigidTransform(), RigidTransform(),
             RigidTransform(RollPitchYaw(0, 0, np.pi), [0.3, 0.0, 0.0])]

    def connect(builder, grasp):
        source = builder.AddSystem(ConstantVectorSource(taxels))
        builder.Connect(source.get_output_port(), grasp.get_taxels_input_port())
        body = builder.AddSystem(ConstantValueSource(AbstractValue.Make(poses)))
        builder.Connect(body.get_output_port(), grasp.get_body_poses_input_port())

    return pads, connect


def test_the_cop_centring_close_moves_the_wrist_onto_the_pads_centres_of_pressure():
    """cop_shift_gain > 0: while some grasp fingers touch (FF from 0.105 s, TH from
    0.155 s, MF never), each update moves the wrist by gain h times the mean offset
    (world) of the touching fingers' centres of pressure from their pad centres,
    horizontal (z dropped), capped at max_shift + max_cop_shift; off (the default),
    the wrist stays."""
    preshape, closed = _hand()
    pose = np.zeros(6)
    pads, connect = _cop_pads()
    forces = _force_script([0.105, None, None, None, 0.155])
    p = ReactiveGraspParams(close_rate=1.0, cop_shift_gain=2.0, max_shift=0.0,
                            max_cop_shift=0.002)
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params=p, period=H,
                          taxel_pads=pads, taxel_cells=32)
    at, context = _simulate(grasp, forces, connect=connect)
    # FF alone: its centre of pressure is 5.25 mm along +y (and 2.25 mm down along the
    # pad, which the centring leaves out)
    ff = np.array([0.0, 0.00525, 0.0])
    np.testing.assert_allclose(grasp.cop_offset(context, np.array([1, 0, 0, 0, 0], bool)), ff,
                               atol=1e-12)
    # TH's is 3.5 mm along -u, which is world +y on the opposing pad
    both = grasp.cop_offset(context, np.array([1, 0, 0, 0, 1], bool))
    np.testing.assert_allclose(both, [0.0, 0.5 * (0.00525 + 0.0035), 0.0], atol=1e-12)
    out = at(0.2049)  # updates 0.11 ... 0.15 saw FF alone, 0.16 ... 0.20 both
    assert out["mode"] is ReactiveGraspMode.CLOSE
    expected = p.cop_shift_gain * H * (5 * 0.00525 + 5 * 0.5 * (0.00525 + 0.0035))
    np.testing.assert_allclose(out["wrist"][:3], [0.0, expected, 0.0], atol=1e-12)
    np.testing.assert_allclose(out["wrist"][3:], 0.0)
    out = at(0.5)  # capped at max_cop_shift
    np.testing.assert_allclose(out["wrist"][:3], [0.0, p.max_cop_shift, 0.0], atol=1e-12)
    # the default (gain 0), same images: the wrist stays where the approach left it
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, period=H, taxel_pads=pads,
                          taxel_cells=32)
    at, _ = _simulate(grasp, forces, connect=connect)
    np.testing.assert_allclose(at(0.5)["wrist"], pose)


def test_the_open_fingers_wait_while_the_cop_offset_is_over_cop_hold_above():
    """cop_hold_above: the open grasp finger (MF) does not close while the touching
    pads' offset (5.25, then 4.375 mm) is over 2 mm and the centring still moves the
    wrist; once the shift reaches its cap (2 mm: after 0.525 mm with FF alone and
    17 steps of 0.0875 mm) it closes on at close_rate."""
    preshape, closed = _hand()
    pose = np.zeros(6)
    pads, connect = _cop_pads()
    p = ReactiveGraspParams(close_rate=1.0, cop_shift_gain=2.0, max_shift=0.0,
                            max_cop_shift=0.002, cop_hold_above=0.002)
    grasp = ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params=p, period=H,
                          taxel_pads=pads, taxel_cells=32)
    at, _ = _simulate(grasp, _force_script([0.105, None, None, None, 0.155]), connect=connect)
    before = at(0.1049)["closing"][MF]
    assert before == pytest.approx(p.close_rate * H * 10)
    assert at(0.3249)["closing"][MF] == pytest.approx(before, abs=1e-12)  # waited
    out = at(0.4049)  # the cap was reached at 0.32 s: closing again from 0.33 s
    assert out["closing"][MF] == pytest.approx(before + p.close_rate * H * 8, abs=1e-12)
    np.testing.assert_allclose(out["wrist"][:3], [0.0, p.max_cop_shift, 0.0], atol=1e-12)
    # the longest wait: the 2 mm cap at the slowest waiting rate, gain x 2 mm = 4 mm/s
    assert grasp.cop_hold_duration() == pytest.approx(0.002 / 0.004 + 4 * H)


def test_taxel_pads_are_checked():
    preshape, closed = _hand()
    pads, _ = _cop_pads()
    pose = np.zeros(6)
    with pytest.raises(ValueError, match="taxel_pads: expected 5 entries"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, taxel_pads=pads[:4], taxel_cells=32)
    with pytest.raises(ValueError, match="do not fit the 20 taxels"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, taxel_pads=pads, taxel_cells=20)
    with pytest.raises(ValueError, match="taxel_cells needs taxel_pads"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, taxel_cells=20)
    with pytest.raises(ValueError, match="cop_shift_gain must be >= 0"):
        ReactiveGraspParams(cop_shift_gain=-1.0).validate()


def test_multiple_unexpected_contacts_stop_the_approach():
    preshape, closed = _hand()
    p = ReactiveGraspParams(approach_speed=0.1, slow_factor=0.5)
    start, goal = [0.0, 0.0, 0.3, 0, 0, 0], [0.0, 0.0, 0.1, 0, 0, 0]
    grasp = ReactiveGrasp(start, goal, preshape, closed, GROUPS, params=p, period=H)
    at, _ = _simulate(grasp, _force_script([0.205, 0.3051, None, None, None]))
    stop = at(0.3149)
    assert stop["mode"] is ReactiveGraspMode.STOPPED
    n_fast = _updates_before(0.205) + 1
    n_slow = _updates_before(0.3051) + 1 - n_fast
    travel = H * p.approach_speed * (n_fast + p.slow_factor * n_slow)
    # Held where the (perfectly tracked) wrist was: the travel up to the stop.
    assert start[2] - stop["wrist"][2] == pytest.approx(travel, abs=1e-12)
    later = at(2.0)
    assert later["mode"] is ReactiveGraspMode.STOPPED
    np.testing.assert_allclose(later["wrist"], stop["wrist"])
    np.testing.assert_allclose(later["hand"], preshape)


def test_closing_waits_for_the_measured_wrist_to_arrive():
    preshape, closed = _hand()
    p = ReactiveGraspParams(approach_speed=1.0, arrival_tolerance=0.002, arrival_timeout=0.3)
    start, goal = [0.0, 0.0, 0.15, 0, 0, 0], [0.0, 0.0, 0.1, 0, 0, 0]
    grasp = ReactiveGrasp(start, goal, preshape, closed, GROUPS, params=p, period=H)
    # The measured wrist never leaves the start (a blocked arm): the command
    # completes its travel after 0.05 s, the closing begins arrival_timeout later.
    at, _ = _simulate(grasp, _force_script([None] * 5), measured=np.array(start))
    assert at(0.3349)["mode"] is ReactiveGraspMode.APPROACH
    out = at(0.3651)
    assert out["mode"] is ReactiveGraspMode.CLOSE
    # A tracked wrist closes right on arrival instead.
    grasp = ReactiveGrasp(start, goal, preshape, closed, GROUPS, params=p, period=H)
    at, _ = _simulate(grasp, _force_script([None] * 5))
    assert at(0.0651)["mode"] is ReactiveGraspMode.CLOSE


def test_bad_input_raises_clear_errors():
    preshape, closed = _hand()
    pose = np.zeros(6)
    with pytest.raises(ValueError, match="start_pose6: expected 6"):
        ReactiveGrasp(np.zeros(5), pose, preshape, closed, GROUPS)
    with pytest.raises(ValueError, match="expected equal 1-D sizes"):
        ReactiveGrasp(pose, pose, preshape, closed[:19], GROUPS)
    with pytest.raises(ValueError, match="disjoint indices"):
        ReactiveGrasp(pose, pose, preshape, closed, [[0, 1], [1, 2]])
    with pytest.raises(ValueError, match="no grasp finger"):
        ReactiveGrasp(pose, pose, preshape, preshape, GROUPS)
    with pytest.raises(ValueError, match="grasp_fingers: expected 5"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, grasp_fingers=[True, False])
    with pytest.raises(ValueError, match="slow_factor must be in"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS,
                      params=ReactiveGraspParams(slow_factor=2.0))
    with pytest.raises(ValueError, match="close_rate must be > 0"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS,
                      params=ReactiveGraspParams(close_rate=0.0))
    with pytest.raises(ValueError, match=r"finger_directions_B: expected \(5, 3\)"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, finger_directions_B=np.zeros(3))
    with pytest.raises(TypeError, match="ReactiveGraspParams"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS, params={"squeeze": 0.1})
    with pytest.raises(RuntimeError, match="no contact_results|has no contact_results"):
        ReactiveGrasp(pose, pose, preshape, closed, GROUPS).get_contact_results_input_port()
