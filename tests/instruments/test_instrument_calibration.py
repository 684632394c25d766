"""Accelerometer calibration (six-position method) and thresholds that follow the device:
a resting device of every profile and seed is at rest, never flags slip, and reads
its roll and pitch within 1 degree once calibrated."""

import math

import numpy as np
import pytest
from pydrake.math import RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from handle_drake.instruments.accelerometer import DeviceAccelerometer
from handle_drake.instruments.calibration import (
    SIX_POSITIONS,
    AccelerometerCalibration,
    calibrate_device,
    device_estimator_params,
    device_rest_readings,
    residual_bias,
    six_position_calibration,
)
from handle_drake.instruments.config import AccelerometerConfig
from handle_drake.instruments.estimators import EstimatorParams, true_roll_pitch
from handle_drake.instruments.profiles import PROFILES, STANDARD_GRAVITY, device_bias

G0 = STANDARD_GRAVITY
NOISY = [name for name, p in PROFILES.items() if p.bias_std_g > 0]
SEEDS = range(20)
#: Rest orientations (roll, pitch, yaw; deg): level, tilted, steep.
ORIENTATIONS = [(0.0, 0.0, 0.0), (25.0, -15.0, 40.0), (-70.0, 50.0, -120.0)]


def test_six_positions_recover_a_known_offset_and_gain():
    offset, scale = np.array([0.3, -0.2, 0.45]), np.array([1.02, 0.97, 1.005])
    readings = scale * G0 * SIX_POSITIONS + offset  # m = s g u + b, exactly
    cal = six_position_calibration(readings)
    np.testing.assert_allclose(cal.offset, offset, atol=1e-12)
    np.testing.assert_allclose(cal.scale, scale, atol=1e-12)
    # the calibrated readings are gravity again
    np.testing.assert_allclose(cal.apply(readings), G0 * SIX_POSITIONS, atol=1e-12)
    with pytest.raises(ValueError, match="mean_readings"):
        six_position_calibration(readings[:5])
    with pytest.raises(ValueError, match="axis z"):
        six_position_calibration(readings[:4], SIX_POSITIONS[:4])
    with pytest.raises(ValueError, match="scale"):
        AccelerometerCalibration(scale=(1.0, 0.0, 1.0))


@pytest.mark.parametrize("device", NOISY)
def test_the_calibration_leaves_at_most_the_stated_residual_bias(device):
    profile = PROFILES[device]
    bound = residual_bias(profile, calibrated=True) * G0  # m/s^2, length of the vector
    worst = 0.0
    for seed in SEEDS:
        cal = calibrate_device(profile, seed)
        error = np.array(cal.offset) - device_bias(profile, seed)
        worst = max(worst, float(np.linalg.norm(error)))
        np.testing.assert_allclose(cal.scale, 1.0, atol=0.01)  # the model has unit gain
    assert worst <= bound
    # ... and far below the bias it removes (30 mg per axis; the JoyWarrior's 5 mg)
    assert worst < 0.5 * profile.bias_std_g * G0
    # the readings it is made from are the device's: quantised counts
    counts = device_rest_readings(profile, 0, samples=1) / profile.lsb
    np.testing.assert_allclose(counts, np.rint(counts), atol=1e-9)


def _resting_run(config: AccelerometerConfig, seed: int, rpy_deg, duration=1.5):
    """The device (as the station builds it from ``config``) at rest at ``rpy_deg``,
    the hand's command still: the logged at_rest, slip and roll/pitch after the first
    settle time."""
    profile = config.profile()
    R_WS = RollPitchYaw(np.radians(rpy_deg)).ToRotationMatrix()
    f_S = R_WS.inverse() @ np.array([0.0, 0.0, G0])
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(f_S))
    command = builder.AddSystem(ConstantVectorSource(np.zeros(2)))
    device = builder.AddSystem(DeviceAccelerometer(
        profile, seed, estimators=config.estimator_params(), command_size=2,
        calibration=config.calibration(None, seed)))
    builder.Connect(source.get_output_port(), device.GetInputPort("specific_force"))
    builder.Connect(command.get_output_port(), device.GetInputPort("command"))
    logs = {}
    for name in ("at_rest", "slip", "roll_pitch"):
        port = device.GetOutputPort(name)
        logs[name] = builder.AddSystem(VectorLogSink(port.size(), profile.period))
        builder.Connect(port, logs[name].get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    t = logs["slip"].FindLog(context).sample_times()
    after = t > EstimatorParams().settle_time
    out = {name: log.FindLog(context).data()[:, after] for name, log in logs.items()}
    out["error_deg"] = np.degrees(np.abs(out["roll_pitch"].T - true_roll_pitch(R_WS))).max()
    return out


@pytest.mark.parametrize("device", NOISY)
def test_a_calibrated_resting_device_is_at_rest_never_slips_and_reads_within_1_deg(device):
    config = AccelerometerConfig(device=device)  # calibrated: the default
    worst = 0.0
    for seed in SEEDS:
        for rpy in ORIENTATIONS:
            run = _resting_run(config, seed, rpy)
            assert run["at_rest"].all(), (device, seed, rpy)
            assert not run["slip"].any(), (device, seed, rpy)
            worst = max(worst, run["error_deg"])
    assert worst < 1.0, worst


def test_uncalibrated_wiimote_is_off_by_degrees_but_its_thresholds_still_hold():
    # calibrated: false: the drawn bias tilts roll/pitch (30 mg per axis ~ 1.7 deg);
    # the thresholds widen with it, so the resting device is still at rest, no slip.
    config = AccelerometerConfig(device="wiimote", calibrated=False)
    assert config.calibration(None, 0) is None
    errors = []
    for seed in SEEDS:
        run = _resting_run(config, seed, ORIENTATIONS[0], duration=0.8)
        assert run["at_rest"].all() and not run["slip"].any(), seed
        errors.append(run["error_deg"])
    assert max(errors) > 3.0 and np.median(errors) > 1.0  # what calibration removes
    # the default thresholds would not hold for it (30 mg bias vs rest_norm_tol 50 mg)
    params = device_estimator_params("wiimote", calibrated=False)
    assert params.rest_norm_tol > 3 * EstimatorParams().rest_norm_tol


def test_thresholds_given_in_the_scenario_are_kept_and_defaults_follow_the_device():
    given = device_estimator_params("wiimote", calibrated=False, given={"slip_norm_tol": 0.05})
    assert given.slip_norm_tol == 0.05
    # a calibrated device of these profiles needs no more than the defaults
    for device in NOISY:
        assert device_estimator_params(device, calibrated=True) == EstimatorParams()
    # a coarse device does: 6 bits over +-2 g is 62 mg a count
    coarse = PROFILES["wiimote"].replace(bits=6)
    assert device_estimator_params(coarse, calibrated=True).rest_norm_tol > 0.05
    assert math.isclose(device_estimator_params("ideal", calibrated=True).rest_norm_tol, 0.05)


def test_a_resting_wiimote_scenario_is_calibrated_unless_it_says_not(tmp_path):
    from handle_drake.run import ScenarioRunner
    from handle_drake.scenario import LoadScenario

    base = ("hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 1.5]}}}\n"
            "random_seed: 13\nsimulation_duration: 1.2\n")
    rolls = {}
    for calibrated in (True, False):
        scenario = LoadScenario(data=base + "object: {kind: wiimote, accelerometer: "
                                f"{{calibrated: {str(calibrated).lower()}}}}}")
        runner = ScenarioRunner(scenario, log=("object.roll_pitch", "object.at_rest",
                                               "object.slip"))
        runner.reset()
        runner.harness.advance(scenario.simulation_duration)
        logs = runner.harness.logs()
        t = logs["object.slip"].sample_times()
        later = t > 0.3
        assert not logs["object.slip"].data()[0].any()
        assert logs["object.at_rest"].data()[0, later].all()
        rolls[calibrated] = np.degrees(np.abs(logs["object.roll_pitch"].data()[:, later])).max()
    # the Wiimote lies flat on the table: roll = pitch = 0
    assert rolls[True] < 1.0 < rolls[False]
