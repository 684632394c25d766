"""The demo's keyframe script fed straight to a bare plant's PD inputs (no driver, no rate
limit): ``bench_station``'s ``model`` floor and ``bench_station_parts``' plant."""

from __future__ import annotations

import numpy as np
from pydrake.systems.primitives import MatrixGain, TrajectorySource

from handle_drake.base.hands import get_hand_spec
from handle_drake.station import hand_initial_command
from handle_drake.systems.hand_driver import WRIST_JOINTS, actuated_order
from handle_drake.trial.simulate import script_trajectories


def connect_script(builder, plant, hand, scenario) -> None:
    """Adds the scenario's hand and wrist script as ``TrajectorySource`` s into ``plant``'s
    desired-state inputs (actuator order; the wrist's ``[x y z roll pitch yaw]`` command
    as its joints ``[x y z yaw pitch roll]``)."""
    wrist = plant.GetModelInstanceByName("wrist")
    hand_traj, wrist_traj = script_trajectories(scenario, hand_initial_command(scenario))
    spec = get_hand_spec(scenario.hand.kind)
    wrist_map = np.eye(6)[[0, 1, 2, 5, 4, 3]]
    for instance, trajectory, order, pre in (
            (hand, hand_traj, actuated_order(plant, hand, spec.actuated_joint_names), None),
            (wrist, wrist_traj, actuated_order(plant, wrist, WRIST_JOINTS), wrist_map)):
        n = len(order)
        gain = np.zeros((2 * n, n))
        gain[np.arange(n), order] = 1.0
        if pre is not None:
            gain[:n] = gain[:n] @ pre
        source = builder.AddSystem(TrajectorySource(trajectory))
        matrix = builder.AddSystem(MatrixGain(gain))
        builder.Connect(source.get_output_port(), matrix.get_input_port())
        builder.Connect(matrix.get_output_port(), plant.get_desired_state_input_port(instance))
