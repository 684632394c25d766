"""The MIDI controller in a station: model, encoder and exported ports.

``MakeHandStation`` calls these when the scenario has a ``midi_controller``
(a :class:`~handle_drake.scenario.MidiControllerConfig`); the station then also
exports

- ``midi_controller.control_positions`` (controls of the mapping, in the
  model's order: m for faders and buttons, rad for knobs and the jog wheel),
- ``midi_controller.midi`` (:class:`~handle_drake.midi.systems.MidiBatch`, the
  messages the simulated device sent at its last scan),

and has the subsystem ``midi_controller`` (a :class:`MidiControllerEncoder`).
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.math import RigidTransform

from handle_drake.midi.device import AddMidiController
from handle_drake.midi.mapping import LoadMidiMapping

__all__ = [
    "INSTANCE",
    "AddMidiControllerModel",
    "AddMidiControllerSystems",
    "controller_pose",
    "validate_midi_controller",
]

INSTANCE = "midi_controller"


def validate_midi_controller(config) -> None:
    """Checks a ``MidiControllerConfig``; raises ``ScenarioError`` naming the field."""
    from handle_drake.scenario import ScenarioError
    from handle_drake.scenario_checks import check_pose

    check_pose("midi_controller.X_WC", config.X_WC)  # names a NaN angle or axis
    try:
        X = config.X_WC.GetDeterministicValue()
    except Exception as error:
        raise ScenarioError(f"midi_controller.X_WC: {error}") from None
    if not np.all(np.isfinite(X.GetAsMatrix4())):
        raise ScenarioError("midi_controller.X_WC: pose must be finite")
    if not (math.isfinite(config.scan_period) and config.scan_period > 0):
        raise ScenarioError(
            f"midi_controller.scan_period must be a finite number > 0, got {config.scan_period}")
    from handle_drake.midi.device import check_mapping_on_device

    try:
        check_mapping_on_device(LoadMidiMapping(config.mapping or None))
    except (ValueError, FileNotFoundError) as error:
        raise ScenarioError(f"midi_controller.mapping: {error}") from None


def controller_pose(scenario) -> RigidTransform:
    """``X_WC`` of the controller at the start (on the table top with ``on_table``)."""
    config = scenario.midi_controller
    X_WC = config.X_WC.GetDeterministicValue()
    if config.on_table:
        p = X_WC.translation().copy()
        p[2] = scenario.table.top_height if scenario.table is not None else 0.0
        X_WC = RigidTransform(X_WC.rotation(), p)
    return X_WC


def AddMidiControllerModel(plant, scenario):
    """Adds the controller model to the unfinalized plant; returns its instance."""
    config = scenario.midi_controller
    return AddMidiController(plant, controller_pose(scenario), fixed=config.fixed,
                             name=INSTANCE)


def AddMidiControllerSystems(builder, plant, scenario):
    """Adds the encoder and exports the controller's ports; returns the encoder."""
    from handle_drake.midi.systems import MidiControllerEncoder

    config = scenario.midi_controller
    mapping = LoadMidiMapping(config.mapping or None)
    encoder = builder.AddNamedSystem(INSTANCE, MidiControllerEncoder(
        plant, plant.GetModelInstanceByName(INSTANCE), mapping, period=config.scan_period))
    builder.Connect(plant.get_state_output_port(), encoder.get_plant_state_input_port())
    builder.ExportOutput(encoder.GetOutputPort("control_positions"),
                         f"{INSTANCE}.control_positions")
    builder.ExportOutput(encoder.GetOutputPort("midi"), f"{INSTANCE}.midi")
    return encoder
