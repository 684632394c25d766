"""advance_sampling (trial.harness; the screw cap trial's one AdvanceTo per phase) reads at
each sample time the state that AdvanceTo(sample time) ends in, on a discrete plant (issue 45,
item 8)."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.trial.harness import advance_sampling

STEP = 0.002
# on the steps (0.05, 0.15: 0.15 / 0.002 is not exact in floating point) and between them
TIMES = [0.025, 0.05, 0.075, 0.15, 0.201, 0.3]


def _falling_body():
    """A free body falling from rest on a 2 ms discrete plant: its height changes every step."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=STEP)
    body = plant.AddRigidBody("ball", SpatialInertia(1.0, np.zeros(3),
                                                     UnitInertia.SolidSphere(0.1)))
    plant.Finalize()
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyContextFromRoot(context)
    simulator.Initialize()

    def height():
        return plant.EvalBodyPoseInWorld(plant_context, body).translation()[2]

    return simulator, height


def test_the_samples_are_the_states_advance_to_ends_in():
    simulator, height = _falling_body()
    expected = []
    for t in TIMES:  # the reference: one AdvanceTo per sample, as the trial did
        simulator.AdvanceTo(t)
        expected.append(height())
    assert len(set(expected)) == len(expected)  # every sample sees a different state

    simulator, height = _falling_body()
    steps, read = [], []
    stopped = advance_sampling(simulator, TIMES, lambda c: steps.append(c.get_time()),
                               lambda i, t: read.append((i, t, height())) and False)
    assert not stopped and [r[:2] for r in read] == list(enumerate(TIMES))
    assert [r[2] for r in read] == expected  # bit for bit
    assert len(steps) == round(TIMES[-1] / STEP)  # every plant step was seen
    # free fall, semi-implicit Euler: after n updates (those at 0, h, ..., before t) the
    # body is g h^2 n (n + 1) / 2 lower, independently of how it was sampled
    for (_, t, z) in read:
        n = int(np.ceil(t / STEP - 1e-6))
        assert z == pytest.approx(-9.81 * STEP**2 * n * (n + 1) / 2, rel=1e-9), t


def test_a_sample_can_stop_the_run_and_an_error_is_raised_again():
    simulator, height = _falling_body()
    seen = []
    assert advance_sampling(simulator, TIMES, lambda c: None,
                            lambda i, t: seen.append(i) or i == 2)
    assert seen == [0, 1, 2] and simulator.get_context().get_time() < TIMES[3]

    simulator, _ = _falling_body()

    def fails(i, t):
        raise RuntimeError("a sample's read failed")

    with pytest.raises(RuntimeError, match="a sample's read failed"):
        advance_sampling(simulator, TIMES, lambda c: None, fails)
    assert advance_sampling(simulator, [], lambda c: None, fails) is False
    assert simulator.get_context().get_time() < TIMES[1]  # stopped at the first sample
    # the monitor is cleared: the simulator runs on without it
    simulator.AdvanceTo(0.4)
    assert simulator.get_context().get_time() == 0.4
