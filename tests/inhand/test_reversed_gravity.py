"""ReversedGravity: the weight reversed while switched on, computed once per switch."""

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.apps.inhand.task import ReversedGravity


class _Counting(ReversedGravity):
    calls = 0

    def _calc(self, context, output):
        type(self).calls += 1
        super()._calc(context, output)


def _free_body(step=1e-3):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=step), builder)
    body = plant.AddRigidBody("ball", SpatialInertia(0.2, np.zeros(3),
                                                     UnitInertia.SolidSphere(0.02)))
    plant.Finalize()
    reverse = builder.AddSystem(_Counting(plant, body))
    builder.Connect(reverse.get_output_port(), plant.get_applied_spatial_force_input_port())
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(context), body, RigidTransform())
    return simulator, plant, body, reverse


def test_the_weight_is_reversed_while_on_and_computed_once_per_switch():
    simulator, plant, body, reverse = _free_body()
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyContextFromRoot(context)
    _Counting.calls = 0
    simulator.AdvanceTo(0.1)  # 100 steps off: free fall
    assert _Counting.calls == 1  # one evaluation, cached: no Python call per step
    v_off = plant.EvalBodySpatialVelocityInWorld(plant_context, body).translational()
    g = plant.gravity_field().gravity_vector()
    np.testing.assert_allclose(v_off, 0.1 * g, rtol=1e-9)  # v = g t (semi-implicit Euler)
    reverse.set_reversed(reverse.GetMyContextFromRoot(context), True)
    simulator.AdvanceTo(0.3)  # 200 steps on: the weight reversed, a = -g
    assert _Counting.calls == 2
    v_on = plant.EvalBodySpatialVelocityInWorld(plant_context, body).translational()
    np.testing.assert_allclose(v_on, v_off - 0.2 * g, rtol=1e-9, atol=1e-12)
    reverse.set_reversed(reverse.GetMyContextFromRoot(context), False)
    simulator.AdvanceTo(0.4)
    assert _Counting.calls == 3
    v_back = plant.EvalBodySpatialVelocityInWorld(plant_context, body).translational()
    np.testing.assert_allclose(v_back, v_on + 0.1 * g, rtol=1e-9, atol=1e-12)


def test_the_force_is_twice_the_weight_at_the_centre_of_mass():
    simulator, plant, body, reverse = _free_body()
    context = simulator.get_mutable_context()
    sub = reverse.GetMyContextFromRoot(context)
    assert reverse.get_output_port().Eval(sub) == []
    reverse.set_reversed(sub, True)
    (force,) = reverse.get_output_port().Eval(sub)
    assert force.body_index == body.index()
    np.testing.assert_array_equal(force.p_BoBq_B, np.zeros(3))
    np.testing.assert_allclose(force.F_Bq_W.translational(),
                               -2 * 0.2 * plant.gravity_field().gravity_vector())
    assert not force.F_Bq_W.rotational().any()
