"""The hardware branch of ``MakeHandStation``: the CAN hand behind the bus server.

The diagram exports the same ``hand.*`` ports as the simulated station
(``hand.position`` in; ``hand.position_commanded``, ``hand.position_measured``,
``hand.velocity_estimated``, ``hand.state_estimated``, ``hand.tactile`` out),
so controllers are written once. The simulation-only ports (contacts, query
object, plant state, object pose) do not exist here. With a Meshcat, a
MultibodyPlant of the hand is built only to draw the measured joint positions.
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

from handle_drake.can_hand.config import CanHandDriverConfig
from handle_drake.can_hand.driver import AddCanHandDriver
from handle_drake.can_hand.layout import hand_layout

__all__ = ["MakeHardwareStation", "driver_config", "HandJointsToPlantPositions"]


def driver_config(driver) -> CanHandDriverConfig:
    """A :class:`CanHandDriverConfig` from a scenario's ``!CanHandDriver`` (same field names)."""
    if isinstance(driver, CanHandDriverConfig):
        values = dc.asdict(driver)
    elif dc.is_dataclass(driver):
        values = {f.name: getattr(driver, f.name) for f in dc.fields(driver)}
    else:
        raise TypeError(f"driver: expected a CanHandDriver dataclass, got {type(driver).__name__}")
    known = {f.name for f in dc.fields(CanHandDriverConfig)}
    config = CanHandDriverConfig(**{k: v for k, v in values.items() if k in known})
    config.validate()
    return config


class HandJointsToPlantPositions(LeafSystem):
    """Scatters hand joint positions into a plant's position vector (for drawing).

    Ports: input ``hand_positions`` (nq, rad, ``HandSpec.joint_names`` order);
    output ``plant_positions`` (plant nq, rad; other entries at their defaults).
    Holds the (non-owned by its consumer) plant so it lives as long as the diagram.
    """

    def __init__(self, plant, model_instance, joint_names):
        super().__init__()
        self._plant = plant
        self._index = np.array([plant.GetJointByName(n, model_instance).position_start()
                                for n in joint_names], dtype=int)
        self._default = plant.GetPositions(plant.CreateDefaultContext())
        self.DeclareVectorInputPort("hand_positions", len(joint_names))
        self.DeclareVectorOutputPort("plant_positions", plant.num_positions(), self._calc)

    def plant(self):
        return self._plant

    def _calc(self, context, output: BasicVector):
        q = self._default.copy()
        q[self._index] = self.get_input_port().Eval(context)
        output.SetFromVector(q)


def MakeHardwareStation(scenario, meshcat=None):
    """The hardware station for ``scenario`` (its driver must be a ``!CanHandDriver``).

    The driver's TCP client starts connecting at once; the diagram's
    ``hand_driver`` subsystem reports the link on ``connection_state``.
    Only a fixed mount is supported: the CAN hand has no wrist actuator.
    """
    from handle_drake.hands import get_hand_spec
    from handle_drake.scenario import FixedMount

    if not isinstance(scenario.hand.mount, FixedMount):
        raise ValueError(
            "hardware station: the CAN hand has no wrist actuator; expected a FixedMount, "
            f"got {type(scenario.hand.mount).__name__}"
        )
    config = driver_config(scenario.driver)
    spec = get_hand_spec(scenario.hand.kind)
    layout = hand_layout(spec, scenario.hand.coupling_ratio)
    for name in scenario.hand.initial_position:
        if name not in layout.actuated_joint_names:
            raise ValueError(f"hand.initial_position: {name!r} is not an actuated joint")
    initial = np.clip([scenario.hand.initial_position.get(n, 0.0)
                       for n in layout.actuated_joint_names],
                      layout.command_lower, layout.command_upper)

    builder = DiagramBuilder()
    driver = AddCanHandDriver(builder, config, layout, initial_position=initial)
    if meshcat is not None:
        _add_visualization(builder, driver, scenario, spec, meshcat)
    diagram = builder.Build()
    diagram.set_name("hand_station_hardware")
    return diagram


def _add_visualization(builder, driver, scenario, spec, meshcat) -> None:
    from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams, Role, SceneGraph
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant
    from pydrake.systems.rendering import MultibodyPositionToGeometryPose

    from handle_drake.hands import AddHand

    scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
    # Not added to the diagram: it only converts positions to geometry poses.
    plant = MultibodyPlant(time_step=scenario.time_step)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    hand = AddHand(plant, scenario.hand.kind, coupling_ratio=scenario.hand.coupling_ratio,
                   parser=Parser(plant), model_instance_name="hand")
    plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(spec.base_body, hand).body_frame(),
                     scenario.hand.mount.X_WB.GetDeterministicValue())
    plant.Finalize()
    scatter = builder.AddNamedSystem(
        "visualization_positions", HandJointsToPlantPositions(plant, hand, spec.joint_names))
    to_pose = builder.AddNamedSystem("to_geometry_pose", MultibodyPositionToGeometryPose(plant))
    builder.Connect(driver.GetOutputPort("position_measured"), scatter.get_input_port())
    builder.Connect(scatter.get_output_port(), to_pose.get_input_port())
    builder.Connect(to_pose.get_output_port(),
                    scene_graph.get_source_pose_port(plant.get_source_id()))
    MeshcatVisualizer.AddToBuilder(
        builder, scene_graph, meshcat,
        MeshcatVisualizerParams(publish_period=scenario.visualization_period,
                                role=Role.kIllustration, prefix="illustration"))
