"""Figure 8's recorder is Drake's own loggers (ZeroOrderHold + VectorLogSink): each
device sample is recorded fresh, SAMPLE_DELAY after the device's own instant."""

import math

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantValueSource,
    MatrixGain,
    TrajectorySource,
    VectorLogSink,
    ZeroOrderHold,
)
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.apps.figure8.experiments import RELEASE_PERIOD, SAMPLE_DELAY, _Recorder

PERIOD = 0.01  # the device's sample period (s)


def _fake_station(X_WO):
    """The ports the recorder reads: a 'device' that samples the time t every PERIOD
    at offset 0 (a discrete update, as the accelerometer's), the object pose, and an
    ideal sensor reading t on each axis."""
    builder = DiagramBuilder()
    clock = builder.AddSystem(TrajectorySource(PiecewisePolynomial.FirstOrderHold(
        [0.0, 10.0], np.array([[0.0, 10.0]]))))
    device = builder.AddSystem(ZeroOrderHold(PERIOD, 1))
    builder.Connect(clock.get_output_port(), device.get_input_port())
    for name, size in (("roll_pitch", 2), ("at_rest", 1), ("free_fall", 1), ("slip", 1),
                       ("acceleration", 3)):
        gain = builder.AddSystem(MatrixGain(np.ones((size, 1))))
        builder.Connect(device.get_output_port(), gain.get_input_port())
        builder.ExportOutput(gain.get_output_port(), f"object.{name}")
    ideal = builder.AddSystem(MatrixGain(np.ones((3, 1))))
    builder.Connect(clock.get_output_port(), ideal.get_input_port())
    builder.ExportOutput(ideal.get_output_port(), "object.acceleration_true")
    pose = builder.AddSystem(ConstantValueSource(AbstractValue.Make(X_WO)))
    builder.ExportOutput(pose.get_output_port(), "object.pose")
    return builder.Build()


@pytest.mark.parametrize("t_end", [0.1055, 0.1, 0.0931])
def test_each_device_sample_is_logged_once_fresh_and_at_its_delay(t_end):
    X_WO = RigidTransform(RollPitchYaw(0.1, -0.2, 0.0), [0.0, 0.0, 0.5])
    X_OS = RigidTransform([0.0, 0.0, 0.02])
    builder = DiagramBuilder()
    station = builder.AddSystem(_fake_station(X_WO))
    recorder = _Recorder.add(builder, station, PERIOD, X_OS)
    assert isinstance(recorder.samples, VectorLogSink)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    simulator.AdvanceTo(t_end)
    rows = recorder.rows(context)

    # Every sample instant k PERIOD + SAMPLE_DELAY up to the end, once, the last included.
    last = math.floor((t_end - SAMPLE_DELAY) / PERIOD + 1e-9)
    k = np.arange(last + 1)
    np.testing.assert_allclose(rows[:, 0], k * PERIOD + SAMPLE_DELAY, rtol=0, atol=1e-12)
    # Fresh: the device's sample of the same instant k PERIOD, not the one before.
    for column in range(4, 12):
        np.testing.assert_allclose(rows[:, column], k * PERIOD, rtol=0, atol=1e-12)
    # The true sensor pose (roll, pitch of R_WS; z of p_WS).
    X_WS = X_WO @ X_OS
    rpy = RollPitchYaw(X_WS.rotation()).vector()
    np.testing.assert_allclose(rows[:, 1:3], np.tile(rpy[:2], (len(k), 1)), atol=1e-12)
    np.testing.assert_allclose(rows[:, 3], X_WS.translation()[2], atol=1e-12)
    # The ideal sensor every RELEASE_PERIOD: |f| = sqrt(3) t.
    ideal = recorder.ideal_norms(context)
    np.testing.assert_allclose(np.diff(ideal[:, 0]), RELEASE_PERIOD, atol=1e-12)
    np.testing.assert_allclose(ideal[:, 1], math.sqrt(3) * ideal[:, 0], atol=1e-9)

    # A cleared recorder starts again.
    recorder.clear(context)
    assert recorder.ideal_norms(context).shape == (0, 2)
