"""``object.position`` of a free object is read out of the plant's state by a
Demultiplexer (no Python call per logger sample, issue 34) and is, bit for bit, what
the Python ``BodyPoseSelector`` reads from the body's pose; anything but a free body on
a world-to-body quaternion floating joint keeps the selector."""

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    QuaternionFloatingJoint,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Demultiplexer

from handle_drake import station as station_module
from handle_drake.apps.demo import DEMO_SCENARIO
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.systems.tactile import BodyPoseSelector
from handle_drake.trial.simulate import ScenarioRunner

INERTIA = SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.05))


def _demo(duration=1.3):
    runner = ScenarioRunner(LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO))
    return runner, runner.run(duration), runner.harness.logs()


def test_the_demo_logs_the_same_object_position_as_the_python_selector(monkeypatch):
    runner, fast, fast_logs = _demo()
    assert isinstance(runner.station.GetSubsystemByName("object_position"), Demultiplexer)
    with monkeypatch.context() as patch:
        patch.setattr(station_module, "_free_body_position", lambda *args: None)
        python_runner, python, python_logs = _demo()
    assert not python_runner.station.HasSubsystemNamed("object_position")
    # the object moves (pushed, then grasped): the comparison is not of a constant
    assert np.ptp(python.object_position, axis=0).max() > 1e-3
    np.testing.assert_array_equal(fast.object_position, python.object_position)
    assert np.array_equal(np.signbit(fast.object_position), np.signbit(python.object_position))
    assert fast_logs.keys() == python_logs.keys()
    for name, log in fast_logs.items():
        np.testing.assert_array_equal(log.data(), python_logs[name].data(), err_msg=name)
        np.testing.assert_array_equal(log.sample_times(), python_logs[name].sample_times())
    # and it is the body's pose in the plant at the end
    plant = station_module.GetPlant(runner.station)
    body = station_module.object_body(plant)
    X_WO = body.EvalPoseInWorld(plant.GetMyContextFromRoot(runner.simulator.get_context()))
    np.testing.assert_array_equal(fast.object_position[-1], X_WO.translation())


def _plant_with(add):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.001), builder)
    body = add(plant)
    plant.Finalize()
    return builder, plant, body


def _free(plant):
    instance = plant.AddModelInstance("object")
    return plant.AddRigidBody("o", instance, INERTIA)


def test_a_free_body_position_is_its_pose_translation_bit_for_bit():
    builder, plant, body = _plant_with(_free)
    port = station_module._free_body_position(builder, plant, body)
    selector = builder.AddSystem(BodyPoseSelector(body))
    builder.Connect(plant.get_body_poses_output_port(), selector.GetInputPort("body_poses"))
    builder.Connect(plant.get_body_spatial_velocities_output_port(),
                    selector.GetInputPort("body_spatial_velocities"))
    builder.ExportOutput(port, "position")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    rng = np.random.default_rng(7)
    for _ in range(20):
        X = RigidTransform(RollPitchYaw(rng.uniform(-3, 3, 3)), rng.uniform(-2, 2, 3))
        plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(context), body, X)
        p = diagram.GetOutputPort("position").Eval(context)
        np.testing.assert_array_equal(
            p, selector.GetOutputPort("position").Eval(selector.GetMyContextFromRoot(context)))
        np.testing.assert_array_equal(p, X.translation())


def _welded(plant):
    body = _free(plant)
    plant.WeldFrames(plant.world_frame(), body.body_frame(), RigidTransform([0, 0, 1.0]))
    return body


def _offset_child_frame(plant):
    body = _free(plant)
    frame = plant.AddFrame(FixedOffsetFrame("offset", body.body_frame(),
                                            RigidTransform([0.01, 0, 0])))
    plant.AddJoint(QuaternionFloatingJoint("float", plant.world_frame(), frame))
    return body


def _two_bodies(plant):
    body = _free(plant)
    plant.AddRigidBody("o2", body.model_instance(), INERTIA)
    return body


def test_anything_but_a_free_body_keeps_the_python_selector():
    for add in (_welded, _offset_child_frame, _two_bodies):
        builder, plant, body = _plant_with(add)
        assert station_module._free_body_position(builder, plant, body) is None, add.__name__
