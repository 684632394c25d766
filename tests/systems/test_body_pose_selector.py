"""BodyPoseSelector picks exactly the plant's pose and velocity of one body."""

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from handle_drake.systems.tactile import BodyPoseSelector


def test_selector_outputs_the_chosen_body_of_the_plant():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.05))
    a = plant.AddRigidBody("a", inertia)
    b = plant.AddRigidBody("b", inertia)
    plant.Finalize()
    selector = builder.AddSystem(BodyPoseSelector(b))
    builder.Connect(plant.get_body_poses_output_port(), selector.GetInputPort("body_poses"))
    builder.Connect(plant.get_body_spatial_velocities_output_port(),
                    selector.GetInputPort("body_spatial_velocities"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    X_WA = RigidTransform(RollPitchYaw(0.1, 0.2, 0.3), [1.0, 2.0, 3.0])
    X_WB = RigidTransform(RollPitchYaw(-0.4, 0.5, 0.6), [0.1, -0.2, 0.7])
    plant.SetFreeBodyPose(plant_context, a, X_WA)
    plant.SetFreeBodyPose(plant_context, b, X_WB)
    plant.SetFreeBodySpatialVelocity(plant_context, b,
                                     _velocity([0.1, 0.2, 0.3], [1.0, -1.0, 0.5]))
    selector_context = selector.GetMyContextFromRoot(context)
    pose = selector.GetOutputPort("pose").Eval(selector_context)
    np.testing.assert_allclose(pose.GetAsMatrix4(), X_WB.GetAsMatrix4(), atol=1e-15)
    np.testing.assert_array_equal(selector.GetOutputPort("position").Eval(selector_context),
                                  pose.translation())
    V = selector.GetOutputPort("spatial_velocity").Eval(selector_context)
    np.testing.assert_allclose(V.rotational(), [0.1, 0.2, 0.3], atol=1e-15)
    np.testing.assert_allclose(V.translational(), [1.0, -1.0, 0.5], atol=1e-15)


def _velocity(w, v):
    from pydrake.multibody.math import SpatialVelocity

    return SpatialVelocity(np.array(w), np.array(v))
