"""The object accelerometer against closed form: counts of a welded object at known
roll/pitch, free fall, saturation, sample-and-hold, profiles and bad input."""

import math

import numpy as np
import pytest
from pydrake.math import RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.devices.accelerometer.estimators import true_roll_pitch
from handle_drake.devices.accelerometer.profiles import (
    PROFILES,
    STANDARD_GRAVITY,
    DeviceProfile,
    counts_to_acceleration,
    get_profile,
    to_counts,
)
from handle_drake.devices.accelerometer.sensor import (
    DeviceAccelerometer,
    device_reading,
    sensor_pose,
)
from handle_drake.geometry.objects import ObjectSpec, dimensions, mass_properties, total_height
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS
from handle_drake.scenario import LoadScenario, ScenarioError
from handle_drake.station import MakeHandStation

G = 9.81  # Drake's default gravity (m/s^2)
HAND_AWAY = "hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 1.5]}}}\n"


def _station(object_yaml: str, table: bool = True):
    scenario = LoadScenario(data=HAND_AWAY + object_yaml + ("" if table else "\ntable: null"))
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    station.GetInputPort("hand.position").FixValue(context, np.zeros(20))
    return scenario, station, simulator, context


def _out(station, context, name):
    return station.GetOutputPort(name).Eval(context)


@pytest.mark.parametrize("kind,rpy_deg,sensor_rpy_deg", [
    ("joywarrior", (0, 0, 0), None),
    ("joywarrior", (25, -40, 70), None),
    ("wiimote", (-60, 30, -20), None),
    ("cylinder", (10, 55, 0), (0, 0, 30)),
])
def test_welded_object_reads_gravity_counts_and_roll_pitch_within_quantisation(
        kind, rpy_deg, sensor_rpy_deg):
    sensor = "" if sensor_rpy_deg is None else (
        f", X_OS: {{translation: [0, 0, 0.01], rotation: !Rpy {{deg: {list(sensor_rpy_deg)}}}}}")
    _, station, simulator, context = _station(
        f"object: {{kind: {kind}, fixed: true, on_table: false, "
        f"X_WO: {{translation: [0.3, 0.3, 0.4], rotation: !Rpy {{deg: {list(rpy_deg)}}}}}, "
        f"accelerometer: {{noise: false{sensor}}}}}")
    simulator.AdvanceTo(0.25)  # a full at-rest window (160 ms)
    R_WO = RollPitchYaw(np.radians(rpy_deg)).ToRotationMatrix()
    if sensor_rpy_deg is None:
        R_OS = sensor_pose(kind, ObjectSpec.default(kind).size).rotation()
    else:
        R_OS = RollPitchYaw(np.radians(sensor_rpy_deg)).ToRotationMatrix()
    R_WS = R_WO @ R_OS
    profile = get_profile(DEVICE_OBJECTS[kind].device if kind in DEVICE_OBJECTS
                          else "joywarrior24f14")
    f_S = R_WS.inverse() @ np.array([0.0, 0.0, G])  # a body at rest feels +g up
    expected = np.rint(f_S / profile.lsb)
    counts = _out(station, context, "object.acceleration_counts")
    np.testing.assert_array_equal(counts, expected)
    np.testing.assert_allclose(_out(station, context, "object.acceleration"),
                               expected * profile.lsb)
    # Quantisation moves the vector by at most |d| = sqrt(3)/2 lsb: the tilt then
    # moves by at most asin(|d| / |f|); roll is divided by cos(pitch).
    d = math.sqrt(3) / 2 * profile.lsb
    tilt = math.asin(d / (G - d))
    true = true_roll_pitch(R_WS)
    estimate = _out(station, context, "object.roll_pitch")
    assert abs(estimate[1] - true[1]) <= tilt
    assert abs(estimate[0] - true[0]) <= tilt / math.cos(true[1]) + 1e-12
    assert _out(station, context, "object.at_rest")[0] == 1.0
    assert _out(station, context, "object.free_fall")[0] == 0.0


def test_free_fall_reads_zero_and_is_detected_after_the_stated_time():
    _, station, simulator, context = _station(
        "object: {kind: joywarrior, on_table: false, X_WO: {translation: [0.3, 0.3, 2.0]}, "
        "accelerometer: {noise: false}}", table=False)
    simulator.AdvanceTo(0.1)
    counts = _out(station, context, "object.acceleration_counts")
    assert np.max(np.abs(counts)) <= 1  # ~0 g (within one count of rounding)
    assert _out(station, context, "object.free_fall")[0] == 1.0
    assert _out(station, context, "object.at_rest")[0] == 0.0
    # Samples at 0, 8, 16 ms are all below 0.3 g: flagged at the third (24 ms stated
    # duration = 3 samples), in the 16 ms sample's own update.
    device = station.GetSubsystemByName("object_accelerometer")
    t = device.GetOutputPort("detection_time").Eval(device.GetMyContextFromRoot(context))
    assert t[0] == pytest.approx(0.016, abs=1e-12)


def test_saturation_at_the_range():
    _, station, simulator, context = _station(
        "object: {kind: joywarrior, fixed: true, on_table: false, "
        "X_WO: {translation: [0.3, 0.3, 0.4]}, accelerometer: {noise: false, range_g: 0.5}}")
    simulator.AdvanceTo(0.05)
    profile = get_profile("joywarrior24f14").replace(range_g=0.5)
    counts = _out(station, context, "object.acceleration_counts")
    assert counts[2] == profile.count_limits[1] == 2 ** 13 - 1  # 1 g clipped at 0.5 g
    assert _out(station, context, "object.acceleration")[2] == pytest.approx(
        (2 ** 13 - 1) * profile.lsb)
    np.testing.assert_array_equal(to_counts([-5 * G, 0.0, 5 * G], profile),
                                  [-2 ** 13, 0, 2 ** 13 - 1])


def test_sample_and_hold_at_the_device_rate():
    profile = DeviceProfile("test", range_g=4.0, bits=16, rate_hz=125.0)
    builder = DiagramBuilder()
    # The input ramps 1 m/s^2 per ms on x.
    ramp = PiecewisePolynomial.FirstOrderHold([0.0, 1.0], np.array([[0, 1000], [0, 0], [0, 0]]))
    source = builder.AddSystem(TrajectorySource(ramp))
    device = builder.AddSystem(DeviceAccelerometer(profile))
    builder.Connect(source.get_output_port(), device.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    device_context = device.GetMyContextFromRoot(context)
    for t, sampled_at in ((0.001, 0.0), (0.0079, 0.0), (0.0081, 0.008), (0.0159, 0.008),
                          (0.0161, 0.016), (0.05, 0.048)):
        simulator.AdvanceTo(t)
        held = device.GetOutputPort("acceleration").Eval(device_context)[0]
        expected = min(np.rint(1000 * sampled_at / profile.lsb), 2 ** 15 - 1) * profile.lsb
        assert held == pytest.approx(expected), (t, sampled_at)


def test_noise_and_bias_are_seeded_and_have_the_profile_statistics():
    profile = get_profile("wiimote").replace(bits=24, range_g=16.0)  # fine steps
    f = np.array([0.0, 0.0, STANDARD_GRAVITY])
    readings = np.array([counts_to_acceleration(device_reading(f, profile, 7, k), profile)
                         for k in range(4000)])
    again = counts_to_acceleration(device_reading(f, profile, 7, 123), profile)
    np.testing.assert_array_equal(readings[123], again)  # same seed and index: same reading
    other = counts_to_acceleration(device_reading(f, profile, 8, 123), profile)
    assert not np.allclose(readings[123], other)
    noise = readings - readings.mean(axis=0)
    std = profile.noise_std_g * STANDARD_GRAVITY
    np.testing.assert_allclose(noise.std(axis=0), std, rtol=0.06)
    bias = readings.mean(axis=0) - f
    assert np.all(np.abs(bias) < 4 * profile.bias_std_g * STANDARD_GRAVITY)
    assert np.linalg.norm(bias) > 3 * std / math.sqrt(len(readings))  # a bias is present


def test_profiles_match_their_sources():
    jw = PROFILES["joywarrior24f14"]
    assert (jw.bits, jw.rate_hz, jw.range_g) == (14, 125.0, 2.0)  # report 2.4.3
    assert jw.counts_per_g == pytest.approx(4096.0)  # BMA180 at +-2 g: 0.25 mg
    assert PROFILES["wiimote"].counts_per_g == pytest.approx(512 / 3)
    assert PROFILES["sixaxis"].counts_per_g == pytest.approx(113.8, abs=0.1)


@pytest.mark.parametrize("kind,dims_mm,mass", [
    ("joywarrior", (37, 35, 25), 0.020),
    ("wiimote", (148, 36.2, 30.8), 0.133),
    ("nunchuk", (113, 38, 37), 0.071),
    ("sixaxis", (157, 95, 55), 0.137),
])
def test_instrumented_objects_have_their_published_size_and_mass(kind, dims_mm, mass):
    spec = ObjectSpec.default(kind)
    from handle_drake.geometry.objects import surface_mesh

    extent = np.ptp(surface_mesh(spec).vertices, axis=0)
    np.testing.assert_allclose(extent * 1000, dims_mm, atol=1e-6)
    assert total_height(spec) == pytest.approx(dims_mm[2] / 1000)
    assert mass_properties(spec).mass == pytest.approx(mass)
    assert dimensions(spec)  # the named dimensions exist
    from handle_drake.devices.accelerometer.sensor import check_sensor_pose

    check_sensor_pose(spec, sensor_pose(kind, spec.size), tolerance=0.0)  # inside


@pytest.mark.parametrize("override,field", [
    ("{device: foo}", "object.accelerometer.device"),
    ("{rate_hz: 0}", "object.accelerometer.rate_hz"),
    ("{rate_hz: -125}", "object.accelerometer.rate_hz"),
    ("{range_g: 0}", "object.accelerometer.range_g"),
    ("{bits: 1}", "object.accelerometer.bits"),
    ("{bits: 33}", "object.accelerometer.bits"),
    ("{seed: -3}", "object.accelerometer.seed"),
    ("{X_OS: {translation: [0.2, 0, 0]}}", "object.accelerometer.X_OS"),
    ("{estimators: {free_fall_threshold: 0}}", "object.accelerometer.estimators"),
    ("{estimators: {bogus: 1}}", "object.accelerometer.estimators"),
])
def test_bad_accelerometer_fields_name_the_field(override, field):
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        LoadScenario(data=f"object: {{kind: cylinder, accelerometer: {override}}}")


def test_bad_profiles_are_refused():
    with pytest.raises(ValueError, match="rate_hz"):
        DeviceProfile("x", range_g=2.0, bits=10, rate_hz=0.0)
    with pytest.raises(ValueError, match="range_g"):
        DeviceProfile("x", range_g=-1.0, bits=10, rate_hz=100.0)
    with pytest.raises(ValueError, match="bits"):
        DeviceProfile("x", range_g=2.0, bits=64, rate_hz=100.0)
    with pytest.raises(ValueError, match="unknown accelerometer"):
        get_profile("joywarrior")
    with pytest.raises(TypeError, match="seed"):
        DeviceAccelerometer("wiimote", seed=1.5)


def test_a_sensor_glued_on_the_surface_is_accepted_and_off_it_refused():
    ok = LoadScenario(data="object: {kind: cylinder, size: 0.05, accelerometer: "
                           "{X_OS: {translation: [0.026, 0, 0]}}}")  # 1 mm off the wall
    assert ok.object.accelerometer.X_OS is not None
    with pytest.raises(ScenarioError, match="off the cylinder"):
        LoadScenario(data="object: {kind: cylinder, size: 0.05, accelerometer: "
                          "{X_OS: {translation: [0.03, 0, 0]}}}")


def test_stations_without_an_accelerometer_export_no_instrument_ports():
    from handle_drake.devices.accelerometer.sensor import INSTRUMENT_SIGNALS

    station = MakeHandStation(LoadScenario(data=HAND_AWAY + "object: {kind: wiimote}"))
    assert not any(station.HasOutputPort(f"object.{s}") for s in INSTRUMENT_SIGNALS)
    station = MakeHandStation(LoadScenario(
        data=HAND_AWAY + "object: {kind: wiimote, accelerometer: {}}"))
    assert all(station.HasOutputPort(f"object.{s}") for s in INSTRUMENT_SIGNALS)


def test_instrumented_kinds_are_accepted_where_object_kinds_are():
    from handle_drake.geometry.objects import DEFAULT_SIZE, KINDS
    from handle_drake.trial.grasp_trial import GraspTrialConfig

    for kind in DEVICE_OBJECTS:
        assert kind in KINDS
        assert GraspTrialConfig(object=kind).object_size == DEFAULT_SIZE[kind]  # babble
        LoadScenario(data=f"object: {{kind: {kind}}}")  # scenarios, simulate
