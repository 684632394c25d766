"""GuardedGrasp: the approach, the contact guard, the back-off and the closing, in closed form.

With control period h and speed v, the travel after the update at t = k h is
``min((k + 1) v h, max_travel)`` (the update at t = 0 moves too); the
approach ends at the first update that sees contact or full travel.
"""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, ContactResults, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource

from handle_drake.systems.guarded_grasp import APPROACH, CLOSE, GuardedGrasp

H, SPEED, TRAVEL = 0.01, 0.5, 0.1  # s, m/s, m
START = np.array([0.0, 0.0, 0.3, np.pi, 0.0, 0.0])
PRESHAPE, CLOSED = np.array([0.1, 0.2]), np.array([1.0, 1.5])


def _controller(hand_bodies=(), object_bodies=(), standoff=0.0):
    return GuardedGrasp(START, [0, 0, -2.0], speed=SPEED, max_travel=TRAVEL, preshape=PRESHAPE,
                        closed=CLOSED, hand_bodies=hand_bodies, object_bodies=object_bodies,
                        standoff=standoff, period=H)


def _outputs(controller, context):
    c = controller.GetMyContextFromRoot(context)
    return {name: controller.GetOutputPort(name).Eval(c).copy()
            for name in ("wrist_pose", "hand_position", "mode", "contact_time")}


def _without_contact(controller):
    builder = DiagramBuilder()
    builder.AddSystem(controller)
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(ContactResults())))
    builder.Connect(source.get_output_port(), controller.get_contact_results_input_port())
    return Simulator(builder.Build())


def test_without_contact_it_travels_at_its_speed_then_closes_at_full_travel():
    controller = _controller()
    simulator = _without_contact(controller)
    simulator.AdvanceTo(5 * H + H / 2)  # updates at 0, h, ..., 5h
    out = _outputs(controller, simulator.get_context())
    travel = 6 * SPEED * H
    # The direction is normalised: straight down.
    np.testing.assert_allclose(out["wrist_pose"], START + [0, 0, -travel, 0, 0, 0], atol=1e-15)
    np.testing.assert_array_equal(out["hand_position"], PRESHAPE)
    assert out["mode"][0] == APPROACH and np.isnan(out["contact_time"][0])
    steps = int(round(TRAVEL / (SPEED * H)))  # 20 updates reach the end of the travel
    simulator.AdvanceTo((steps + 1) * H + H / 2)
    out = _outputs(controller, simulator.get_context())
    np.testing.assert_allclose(out["wrist_pose"][2], START[2] - TRAVEL, atol=1e-15)
    assert out["mode"][0] == CLOSE and np.isnan(out["contact_time"][0])
    np.testing.assert_array_equal(out["hand_position"], CLOSED)  # no back-off: closes at once


def _touching_plant(standoff):
    """Two free spheres that overlap from the start: the 'hand' and the 'object'
    (bodies welded to the world would have their collisions filtered)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=H), builder)
    inertia = SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.05))
    bodies = []
    for name, x in (("hand", 0.0), ("object", 0.09)):
        body = plant.AddRigidBody(name, inertia)
        plant.RegisterCollisionGeometry(body, RigidTransform(), Sphere(0.05), name,
                                        _friction())
        plant.SetDefaultFloatingBaseBodyPose(body, RigidTransform([x, 0, 0]))
        bodies.append(body.index())
    plant.Finalize()
    controller = builder.AddSystem(_controller([bodies[0]], [bodies[1]], standoff))
    builder.Connect(plant.get_contact_results_output_port(),
                    controller.get_contact_results_input_port())
    return controller, Simulator(builder.Build())


def _friction():
    from pydrake.multibody.plant import CoulombFriction

    return CoulombFriction(0.5, 0.5)


def test_contact_stops_the_approach_and_records_its_time():
    controller, simulator = _touching_plant(standoff=0.0)
    simulator.AdvanceTo(3 * H + H / 2)
    out = _outputs(controller, simulator.get_context())
    # The spheres touch from t = 0; the contact results of the first
    # update (t = 0) stop the hand where it started, and it closes at once.
    assert out["mode"][0] == CLOSE and out["contact_time"][0] == 0.0
    np.testing.assert_array_equal(out["wrist_pose"], START)
    np.testing.assert_array_equal(out["hand_position"], CLOSED)


def test_contact_of_other_bodies_does_not_stop_it():
    controller = _controller(hand_bodies=[], object_bodies=[])
    simulator = _without_contact(controller)
    simulator.AdvanceTo(H / 2)
    assert _outputs(controller, simulator.get_context())["mode"][0] == APPROACH


def test_set_trial_changes_a_trial_without_a_new_diagram():
    controller = _controller()
    simulator = _without_contact(controller)
    context = controller.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    start = START + [0.05, -0.02, 0, 0, 0, 0]
    controller.set_trial(context, start_pose6=start, preshape=[0.3, 0.4])
    simulator.Initialize()
    out = _outputs(controller, simulator.get_context())
    np.testing.assert_array_equal(out["hand_position"], [0.3, 0.4])
    np.testing.assert_array_equal(out["wrist_pose"][:2], start[:2])
    with pytest.raises(ValueError, match="expected 2 finite values"):
        controller.set_trial(context, closed=[1.0, np.nan])
    with pytest.raises(ValueError, match="expected 6 finite values"):
        controller.set_trial(context, start_pose6=[0.0] * 5)


@pytest.mark.parametrize("kwargs, message", [
    (dict(start_pose6=[0.0] * 5), "start_pose6 and direction"),
    (dict(direction=[0.0, 0.0, 0.0]), "direction must be a finite non-zero vector"),
    (dict(speed=0.0), "speed > 0"),
    (dict(closed=[1.0]), "preshape and closed"),
])
def test_bad_arguments_are_named(kwargs, message):
    args = dict(start_pose6=START, direction=[0, 0, -1], speed=SPEED, max_travel=TRAVEL,
                preshape=PRESHAPE, closed=CLOSED, hand_bodies=[], object_bodies=[])
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        GuardedGrasp(**args)
