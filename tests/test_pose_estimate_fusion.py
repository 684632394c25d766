"""The in-hand pose estimator's motion model (the object carried by the touching pads) and
its use of the object's accelerometer, built from ports alone and scored against the
plant's truth read by separate code."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.base.hands import get_hand_spec
from handle_drake.base.models import diagrams_dir
from handle_drake.devices.taxels.estimator import InHandPoseEstimator
from handle_drake.geometry.objects import ObjectSpec
from handle_drake.scenario import LoadScenario
from handle_drake.station import MakeHandStation
from handle_drake.trial.simulate import ScenarioRunner

SYMMETRY = [RollPitchYaw(r).ToRotationMatrix() for r in
            ([0, 0, 0], [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi])]


def _pads():
    probe = MakeHandStation(LoadScenario(data="hand: {taxels: {}}"), outputs=("hand.taxels",))
    return probe.GetSubsystemByName("taxels").pads


def _estimator(pads, prior=None, **kwargs):
    prior = RigidTransform() if prior is None else prior
    return InHandPoseEstimator("shadow", None, pads, ObjectSpec("cuboid", 0.05), prior,
                               X_WB=RigidTransform(), **kwargs)


def test_the_object_is_carried_by_the_touching_pad():
    """One touching pad: the object keeps its pose in that pad's frame (the pad's forward
    kinematics, computed here by the estimator's own pad_poses at both joint sets); a
    second pad moving the other way widens the process noise; still joints change
    nothing and give the still noise."""
    pads = _pads()
    estimator = _estimator(pads, still_position_std=0.0005, still_angle_std=0.01)
    names = get_hand_spec("shadow").joint_names
    q0 = np.zeros(len(names))
    q1 = q0.copy()
    q1[names.index("FFJ3")], q1[names.index("FFJ2")] = 0.4, 0.3
    ff = next(i for i, p in enumerate(pads) if p.body_name.startswith("ff")
              and "distal" in p.body_name)
    X_BO = RigidTransform(RollPitchYaw(0.1, -0.2, 0.3), [0.03, -0.05, 0.35])
    before, after = estimator.pad_poses(q0)[ff], estimator.pad_poses(q1)[ff]
    moved, std = estimator.carry(X_BO, q0, q1, [(ff, 2.0)])
    X_PO_before, X_PO_after = before.inverse() @ X_BO, after.inverse() @ moved
    np.testing.assert_allclose(X_PO_after.GetAsMatrix4(), X_PO_before.GetAsMatrix4(),
                               atol=1e-9)
    assert np.linalg.norm(moved.translation() - X_BO.translation()) > 0.01  # it moved
    assert std[3] > 0.005  # the motion's noise, not the still one
    kept, still = estimator.carry(X_BO, q1, q1, [(ff, 2.0)])
    np.testing.assert_allclose(kept.GetAsMatrix4(), X_BO.GetAsMatrix4(), atol=1e-12)
    np.testing.assert_allclose(still, [0.01] * 3 + [0.0005] * 3, rtol=1e-9)
    # the thumb still while the finger moves: the two disagree, the noise grows
    th = next(i for i, p in enumerate(pads) if p.body_name.startswith("th")
              and "distal" in p.body_name)
    _, both = estimator.carry(X_BO, q0, q1, [(ff, 2.0), (th, 2.0)])
    assert both[3] > 0.5 * std[3]


def _after_glitch(consistency: float, until: float) -> RollPitchYaw:
    """No touch, fixed base; the object's accelerometer reads level, then a glitch (-2.2
    rad roll: a first sample, a jerk) read by the update at 0.05 s, then level again; the
    prior is 0.15, -0.1, 0.3 rad (roll, pitch, yaw). The estimate's angles at ``until``."""
    pads = _pads()
    prior = RigidTransform(RollPitchYaw(0.15, -0.1, 0.3), [0.3, 0.0, 0.05])
    builder = DiagramBuilder()
    estimator = builder.AddSystem(_estimator(pads, prior, X_OS=RigidTransform(),
                                             gravity_consistency=consistency))
    cells = sum(p.cells for p in pads)
    for name, value in (("hand_positions", np.zeros(24)), ("taxels", np.zeros(cells))):
        builder.Connect(builder.AddSystem(ConstantVectorSource(value)).get_output_port(),
                        estimator.GetInputPort(name))
    readings = PiecewisePolynomial.ZeroOrderHold([0.0, 0.04, 0.09, 2.0],
                                                 np.array([[0, -2.2, 0, 0], [0, -0.1, 0, 0]]))
    builder.Connect(builder.AddSystem(TrajectorySource(readings)).get_output_port(),
                    estimator.GetInputPort("roll_pitch"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(until)
    pose = estimator.GetOutputPort("pose").Eval(
        estimator.GetMyContextFromRoot(simulator.get_context()))
    return RollPitchYaw(pose.rotation())


def test_a_transient_accelerometer_reading_is_not_taken_for_gravity():
    """A reading is used only when it agrees with the one before (the first never): the
    glitch is left out (the roll just after it is still the prior's), then the level
    readings level the estimate and its yaw (unobservable by gravity) stays the prior's.
    Taking every reading (consistency 10 rad) pulls the roll towards the glitch."""
    assert abs(_after_glitch(0.1, 0.07).vector()[0] - 0.15) < 0.01
    assert _after_glitch(10.0, 0.07).vector()[0] < -0.5
    rpy = _after_glitch(0.1, 1.0).vector()
    assert abs(rpy[0]) < 0.02 and abs(rpy[1]) < 0.02
    assert abs(rpy[2] - 0.3) < 0.05


@pytest.mark.parametrize("name", ["grasp_parallel_extension.yaml"])
def test_the_station_estimate_with_the_accelerometer_holds_the_cuboid(name):
    """The station's estimator fed by the object's accelerometer (the scenario's): over the
    holding phase (1.3 s to the end, 10 Hz) within 5 mm and 5 deg RMS of the plant's pose
    (read here only), the prior 8 mm and 8 deg off."""
    scenario = LoadScenario(filename=diagrams_dir() / name, data=(
        "hand: {taxels: {estimator: true}}\nobject: {accelerometer: {}}"))
    runner = ScenarioRunner(scenario)
    estimator = runner.station.GetSubsystemByName("object_pose_estimator")
    assert estimator.GetInputPort("roll_pitch").HasValue(
        estimator.GetMyContextFromRoot(runner.context))
    context = estimator.GetMyMutableContextFromRoot(runner.simulator.get_mutable_context())
    x = context.get_discrete_state_vector().value().copy()
    offset = RigidTransform(RollPitchYaw(np.radians([5.0, -4.0, 4.6])), [0.005, -0.004, 0.0045])
    prior = estimator._unpack(x) @ offset
    x[:4], x[4:7] = prior.rotation().ToQuaternion().wxyz(), prior.translation()
    context.SetDiscreteState(x)
    station_context = runner.station.GetMyContextFromRoot(runner.context)
    errors = []
    for t in np.arange(1.3, scenario.simulation_duration + 1e-9, 0.1):
        runner.simulator.AdvanceTo(t)
        truth = runner.station.GetOutputPort("object.pose").Eval(station_context)
        estimate = runner.station.GetOutputPort("object.pose_estimated").Eval(station_context)
        R = truth.rotation().inverse() @ estimate.rotation()
        errors.append((np.linalg.norm(truth.translation() - estimate.translation()),
                       min(abs((R @ S).ToAngleAxis().angle()) for S in SYMMETRY)))
    position, angle = np.sqrt(np.mean(np.square(errors), axis=0))
    assert position < 0.005 and np.degrees(angle) < 5.0, (position, np.degrees(angle))


def test_a_pinch_reports_its_unobserved_turn_and_slide_as_the_prior_spread():
    """Two contacts on opposite faces of a 5 cm cuboid (x = +-25 mm, the pads' normals
    against the faces): the fit's covariance keeps the prior's spread (0.2 rad, 1 cm) for
    the turn about the contacts' line and the slide along the faces, is far tighter across
    the faces and tighter for their tilt (the normals): closed form, no simulation."""
    estimator = _estimator(_pads())
    points = np.array([[0.025, 0.0, 0.0], [-0.025, 0.0, 0.0]])
    normals = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    prior = RigidTransform(RollPitchYaw(0.0, 0.05, -0.04), [0.002, 0.003, -0.002])
    std = np.array([0.2] * 3 + [0.01] * 3)
    X_BO, cov, rms, _ = estimator.fit(points, normals, [(prior, std)])
    assert rms < 1e-4
    assert abs(X_BO.translation()[0]) < 1e-4  # centred between the faces
    np.testing.assert_allclose(X_BO.translation()[1:], [0.003, -0.002], atol=1e-4)
    sd = np.sqrt(np.diag(cov))
    assert sd[0] == pytest.approx(0.2, rel=0.05)  # the turn about x: the prior's
    assert np.all(sd[4:] == pytest.approx(0.01, rel=0.05))  # the slide along y, z
    assert sd[3] < 0.002  # the faces' distance: observed by the touch
    # the tilt: by the two normals (0.3 rad each): tighter than the prior's
    assert sd[1] < 0.8 * sd[0] and sd[2] < 0.8 * sd[0]
