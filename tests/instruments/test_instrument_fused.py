"""The estimators in the device's own update (one event per sample) against the plain
functions of the module (``roll_pitch``, ``at_rest``, ``free_fall``, ``slip_indicator``) and
the slip method its doc states, computed here sample by sample from the whole history:
every output exactly equal at every sample.

Two levels: the estimators alone (:class:`EstimatorSystem`), on scripted sequences of
rest, rotation, free fall, impacts, slip, values exactly at the thresholds and signed
zeros, with a command that is still, moves, and is still again; and the device model
on a box that falls onto an incline and slides or rests there (noise, bias,
quantisation; four devices, seeds and thresholds), against the reference applied to
what the device alone reads.
"""

import math

import numpy as np
import pytest
from pydrake.geometry import AddContactMaterial, Box, ProximityProperties
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.instruments.accelerometer import AddObjectAccelerometer, DeviceAccelerometer
from handle_drake.instruments.estimators import (
    EstimatorParams,
    EstimatorState,
    EstimatorSystem,
    InstrumentEstimators,
    at_rest,
    roll_pitch,
    slip_indicator,
)
from handle_drake.instruments.profiles import STANDARD_GRAVITY as G0
from handle_drake.instruments.profiles import get_profile, sample_noise
from handle_drake.objects import AddObject, ObjectSpec, resting_height

M = 4  # command size
ESTIMATES = ("roll_pitch", "at_rest", "free_fall", "detection_time", "slip")


def _reference(f, c, params: EstimatorParams, period: float) -> list[dict]:
    """The outputs after each sample ``f[k]`` (the command ``c[k]`` at its instant, or
    ``c`` None), from the plain functions and the module doc's method."""
    p = params
    n_mean = p.samples(p.window, period)
    n_rest = max(n_mean, p.samples(p.rest_window, period), 2)
    fall_need = p.samples(p.free_fall_duration, period)
    settle, slip_need = p.samples(p.settle_time, period), p.samples(p.slip_duration, period)
    out = []
    low, detected, still, slipping, ref, previous = 0, math.nan, 0, 0, None, None
    for k in range(len(f)):
        history = f[:k + 1]
        mean = history[-n_mean:].mean(axis=0)
        rest = k + 1 >= n_rest and at_rest(history[-n_rest:], p.rest_norm_tol, p.rest_std_tol,
                                           p.rest_angle_tol)
        low = low + 1 if np.linalg.norm(f[k]) < p.free_fall_threshold * G0 else 0
        if low == fall_need:
            detected = k * period
        elif low < fall_need:
            detected = math.nan
        if c is not None:
            is_still = previous is not None and np.max(np.abs(c[k] - previous)) <= p.still_tol
            previous = c[k]
            if not is_still:
                still, slipping, ref = 0, 0, None
            else:
                still += 1
                if still >= settle:
                    if ref is None and rest:  # the reference: the first sample at rest
                        ref = mean
                    if ref is None:  # settled and not at rest: slipping
                        slipping += 1
                    else:
                        flagged = slip_indicator(mean, ref, p.slip_norm_tol, p.slip_angle_tol)
                        slipping = slipping + 1 if flagged else 0
        out.append({"roll_pitch": roll_pitch(mean), "at_rest": [float(rest)],
                    "free_fall": [float(low >= fall_need)], "detection_time": [detected],
                    "slip": [float(slipping >= slip_need)]})
    return out


def _outputs(system, context) -> dict:
    system_context = system.GetMyContextFromRoot(context)
    return {name: np.array(system.GetOutputPort(name).Eval(system_context))
            for name in ESTIMATES}


def _compare_outputs(system, context, want: dict, seen: dict, outputs=None) -> None:
    outputs = outputs or _outputs(system, context)
    for name in ESTIMATES:
        have = outputs[name]
        expected = np.array(want[name], dtype=float)
        if name == "detection_time":
            assert np.isnan(have[0]) == np.isnan(expected[0]), (want, have)
            if not np.isnan(expected[0]):
                assert have[0] == pytest.approx(expected[0], abs=1e-12), (want, have)
                seen["detected"] = seen.get("detected", 0) + 1
            continue
        assert np.array_equal(expected, have), (name, expected, have)
        assert np.array_equal(np.signbit(expected), np.signbit(have)), (name, expected, have)
        seen.setdefault(name, set()).add(tuple(np.round(expected, 6)))


# ----------------------------------------------------------- scripted samples


def _gravity(rng, n, noise_g, rpy=None):
    rpy = rng.uniform(-0.6, 0.6, 3) if rpy is None else rpy
    R = RollPitchYaw(rpy).ToRotationMatrix().matrix()
    return R.T @ [0.0, 0.0, G0] + rng.normal(0.0, noise_g * G0, (n, 3))


def _script(rng, params: EstimatorParams) -> tuple[np.ndarray, np.ndarray]:
    """Accelerations (N, 3) and commands (N, M), one per sample."""
    parts = [_gravity(rng, 60, 0.005)]
    # a rotation: gravity's direction turns through 40 samples
    a, b = rng.uniform(-0.6, 0.6, 3), rng.uniform(-0.6, 0.6, 3)
    parts.append(np.array([_gravity(rng, 1, 0.002, a + (b - a) * s)[0]
                           for s in np.linspace(0, 1, 40)]))
    parts.append(_gravity(rng, 50, 0.0, b))  # noiseless rest
    # free fall, with magnitudes at and about the threshold
    thr = params.free_fall_threshold * G0
    fall = rng.normal(0.0, 0.05 * G0, (12, 3))
    u = rng.normal(size=(6, 3))
    fall[::2] = u / np.linalg.norm(u, axis=1)[:, None] * thr
    fall[1] = [0.0, 0.0, thr]
    fall[3] = [thr, 0.0, 0.0]
    fall[5] = [0.0, -thr * (1 + 1e-12), 0.0]
    parts.append(fall)
    parts.append(rng.normal(0.0, 5 * G0, (4, 3)))  # impact
    parts.append(_gravity(rng, 50, 0.003))
    # slip: the magnitude drops, then the direction turns, then exactly at the tolerances
    parts.append(0.85 * _gravity(rng, 20, 0.003, b))
    parts.append(_gravity(rng, 20, 0.003, b + [math.radians(5.0), 0.0, 0.0]))
    edge = np.zeros((12, 3))
    edge[:, 2] = G0 * (1 + params.slip_norm_tol * rng.choice([-1.0, 1.0], 12))
    parts.append(edge)
    tilt = params.slip_angle_tol
    parts.append(np.tile(G0 * np.array([0.0, math.sin(tilt), math.cos(tilt)]), (12, 1)))
    parts.append(_gravity(rng, 40, 0.002, [0.0, 0.0, 0.0]))
    parts.append(np.tile([0.0, 0.0, -0.0], (6, 1)))  # signed zeros
    parts.append(_gravity(rng, 80, 0.01))
    f = np.vstack(parts)
    n = len(f)
    # command: still, moves, still with changes within still_tol, a step, still again
    c = np.tile(rng.normal(size=M), (n, 1))
    move = slice(n // 3, n // 3 + 30)
    c[move] += np.linspace(0.0, 0.2, 30)[:, None]
    c[n // 3 + 30:] += 0.2
    jitter = slice(n // 3 + 30, 2 * n // 3)
    c[jitter] += rng.uniform(-0.4, 0.4, (jitter.stop - jitter.start, M)) * params.still_tol
    c[2 * n // 3 + 40:, 1] += 3 * params.still_tol
    c[n // 6, 2] = np.nan  # a NaN command is not still (twice: as it comes and goes)
    return f, c


def _compare_scripted(f, c, period, params, with_command=True):
    builder = DiagramBuilder()
    system = builder.AddSystem(EstimatorSystem(period, params, M if with_command else None))
    builder.ExportInput(system.GetInputPort("acceleration"), "acceleration")
    if with_command:
        builder.ExportInput(system.GetInputPort("command"), "command")
    else:
        assert not system.HasInputPort("command")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    reference = _reference(f, c if with_command else None, params, period)
    seen = {}
    for k in range(len(f)):
        diagram.GetInputPort("acceleration").FixValue(context, f[k])
        if with_command:
            diagram.GetInputPort("command").FixValue(context, c[k])
        simulator.AdvanceTo(k * period + period / 2)  # sample k at k T
        _compare_outputs(system, context, reference[k], seen)
    # the state, by name: every sample taken, the held sample is the last one
    state = system.GetMyContextFromRoot(context).get_discrete_state()
    assert system.estimators.estimates(state).taken == len(f)
    assert isinstance(system.estimators.estimates(state), EstimatorState)
    np.testing.assert_array_equal(system.estimators.recent(state, 1)[0], f[-1])
    return seen


@pytest.mark.parametrize("seed, period", [(0, 0.008), (1, 0.01), (2, 0.001)])
def test_estimators_equal_the_plain_functions_exactly(seed, period):
    params = EstimatorParams()
    f, c = _script(np.random.default_rng(seed), params)
    if period < 0.004:  # each sample 4 times: the windows span as many samples
        f, c = np.repeat(f, 4, axis=0), np.repeat(c, 4, axis=0)
    seen = _compare_scripted(f, c, period, params)
    # the script exercises every output: at rest and not, free fall and slip flagged
    assert seen["at_rest"] == {(0.0,), (1.0,)}
    assert seen["free_fall"] == {(0.0,), (1.0,)}
    assert seen["slip"] == {(0.0,), (1.0,)}
    assert seen["detected"] >= 1  # samples with a free fall detected (and its time)


def test_estimators_equal_the_plain_functions_with_other_parameters():
    # short windows and settle time: the slip test runs on most samples
    params = EstimatorParams(window=0.02, rest_window=0.05, settle_time=0.03,
                             slip_duration=0.016, free_fall_duration=0.01,
                             slip_angle_tol=math.radians(4.0))
    f, c = _script(np.random.default_rng(3), params)
    seen = _compare_scripted(f, c, 0.008, params)
    assert seen["slip"] == {(0.0,), (1.0,)}


def test_estimators_without_a_command_have_a_constant_zero_slip():
    params = EstimatorParams()
    f, c = _script(np.random.default_rng(4), params)
    seen = _compare_scripted(f[:150], c[:150], 0.008, params, with_command=False)
    assert seen["slip"] == {(0.0,)}


# ----------------------------------------------------------- the device model


def _incline_diagram(profile, seed, params, alpha_deg, mu, drop):
    """A box released ``drop`` m above a plane inclined by alpha (slides when
    tan(alpha) > mu), carrying the device twice: alone, and with the estimators in its
    update. The command: still, a move, still (returned, to read at the samples)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    R = RotationMatrix.MakeXRotation(math.radians(alpha_deg))
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    X_WP = RigidTransform(R, [0, 0, 0])
    plant.RegisterCollisionGeometry(plant.world_body(), X_WP @ RigidTransform([0, 0, -0.025]),
                                    Box(2, 2, 0.05), "plane", props)
    spec = ObjectSpec("cuboid", 0.04, mu=mu, dimensions={"depth": 0.03, "height": 0.02})
    AddObject(plant, spec, name="object")
    body = plant.GetBodyByName("base_link")
    plant.SetDefaultFloatingBaseBodyPose(
        body, X_WP @ RigidTransform(RollPitchYaw(0.1, -0.2, 0.3).ToRotationMatrix(),
                                    [0, 0, resting_height(spec) + drop]))
    plant.Finalize()
    # Steps half-way between samples.
    T = profile.period
    times = np.array([0.0, 0.1, 0.1 + 0.5 * T, 0.2 + 0.5 * T, 0.25 + 0.5 * T, 2.0])
    values = np.zeros((M, len(times)))
    values[0, 2:] = 0.3
    values[1, 3:] = 0.5
    values[2, 4:] = 0.5 + 0.5 * params.still_tol  # within still_tol: still
    command = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times,
                                                                                   values)))
    X_BS = RigidTransform(RollPitchYaw(0.2, 0.1, -0.4).ToRotationMatrix(), [0.01, -0.005, 0.004])
    alone = AddObjectAccelerometer(builder, plant, body, X_BS, profile, seed=seed,
                                   name="alone")
    fused = AddObjectAccelerometer(builder, plant, body, X_BS, profile, seed=seed,
                                   name="fused", estimators=params,
                                   command=command.get_output_port())
    return builder.Build(), alone, fused, command


@pytest.mark.parametrize("device, seed, params, alpha, mu", [
    ("joywarrior24f14", 0, EstimatorParams(), 30.0, 0.2),
    ("wiimote", 3, EstimatorParams(settle_time=0.1, rest_window=0.08), 10.0, 0.8),
    ("ideal", 1, EstimatorParams(settle_time=0.05, slip_norm_tol=0.05, window=0.01), 30.0, 0.2),
    ("nunchuk", 7, EstimatorParams(), 25.0, 0.25),
])
def test_device_with_estimators_equals_the_device_and_the_plain_functions(
        device, seed, params, alpha, mu):
    profile = get_profile(device)
    diagram, alone, fused, command = _incline_diagram(profile, seed, params, alpha, mu,
                                                      drop=0.08)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    T = profile.period
    n = int(round(0.7 / T))
    f, c, outputs, seen = [], [], [], {}
    for k in range(n):
        simulator.AdvanceTo(k * T)  # the command as the sample k reads it, at its instant
        c.append(command.get_output_port().Eval(command.GetMyContextFromRoot(context)))
        simulator.AdvanceTo(k * T + T / 2)
        for name in ("counts", "acceleration"):
            want = alone.GetOutputPort(name).Eval(alone.GetMyContextFromRoot(context))
            have = fused.GetOutputPort(name).Eval(fused.GetMyContextFromRoot(context))
            assert np.array_equal(want, have), (k, name, want, have)
        f.append(np.array(alone.GetOutputPort("acceleration").Eval(
            alone.GetMyContextFromRoot(context))))
        outputs.append(_outputs(fused, context))
    for want, have in zip(_reference(np.array(f), np.array(c), params, T), outputs,
                          strict=True):
        _compare_outputs(fused, context, want, seen, have)
    # the device's state, by name: the samples it averaged over, its last counts
    state = fused.device_state(fused.GetMyContextFromRoot(context))
    assert state.samples == n
    np.testing.assert_array_equal([state.counts_x, state.counts_y, state.counts_z],
                                  fused.GetOutputPort("counts").Eval(
                                      fused.GetMyContextFromRoot(context)))
    # the run exercises the flags: it falls (free fall), lands, rests or slides
    assert seen["free_fall"] == {(0.0,), (1.0,)}
    assert (1.0,) in seen["at_rest"] or alpha > 20
    assert (1.0,) in seen["slip"] or mu > 0.5
    assert len(seen["roll_pitch"]) > 10


def test_the_device_noise_is_the_profiles_sample_noise():
    profile = get_profile("wiimote")
    device = DeviceAccelerometer(profile, seed=5)
    for index in (0, 1, 1023, 1024, 1025, 5000, 3, 2047):  # across noise blocks
        assert device._noise(index) == sample_noise(profile, 5, index).tolist()
    assert DeviceAccelerometer("ideal")._noise(7) == [0.0, 0.0, 0.0]


def test_estimators_bad_parameters():
    with pytest.raises(ValueError, match="command_size"):
        InstrumentEstimators(0.008, None, 0)
    with pytest.raises(ValueError, match="period"):
        InstrumentEstimators(0.0)
    with pytest.raises(ValueError, match="period"):
        EstimatorSystem(-1.0)
    from pydrake.systems.framework import DiagramBuilder as Builder

    from handle_drake.instruments.accelerometer import ExportInstrumentPorts

    builder = Builder()
    device = builder.AddSystem(DeviceAccelerometer("wiimote"))
    with pytest.raises(ValueError, match="no estimators"):
        ExportInstrumentPorts(builder, device)
