"""The MIDI hand-control diagram: a station (simulated or CAN hand) driven by
:class:`~handle_drake.devices.midi.systems.MidiHandControl`.

The control system's ``position`` output is wired to the station's
``hand.position`` input and nothing else, so the same diagram runs on the
simulated station and on the CAN hand station (``hardware=True``).
"""

from __future__ import annotations

import dataclasses as dc

from handle_drake.devices.midi.mapping import LoadMidiMapping, MidiMapping
from handle_drake.devices.midi.systems import MidiHandControl
from handle_drake.grasp.planning import default_synergies
from handle_drake.station import hand_initial_command
from handle_drake.systems.hand_driver import rpy_pose6
from handle_drake.trial.harness import TrialHarness

__all__ = ["MidiHandControlDiagram", "BuildMidiHandControl"]


@dc.dataclass
class MidiHandControlDiagram:
    diagram: object
    station: object
    control: MidiHandControl
    harness: TrialHarness  # built it; ``handle-drake midi control`` runs its simulator


def BuildMidiHandControl(scenario, port=None, feedback_port=None,
                         mapping: MidiMapping | None = None, synergies="default",
                         meshcat=None, hardware: bool = False,
                         **control_options) -> MidiHandControlDiagram:
    """Station + :class:`MidiHandControl` (+ the wrist held at its initial pose), built by
    the :class:`~handle_drake.trial.harness.TrialHarness` like every station diagram.

    Args:
        scenario: the station's scenario (its ``script`` is not used).
        port / feedback_port: mido ports (a device, an in-process port,
            :class:`~handle_drake.devices.midi.ports.MeshcatFaderPort`).
        mapping: default: the shipped iControls Pro mapping.
        synergies: "default" (the project's synergies fitted on the shipped
            grasp data; Shadow hand only), a ``Synergies`` or None (joint mode only).
        control_options: passed on to :class:`MidiHandControl`.
    """

    mapping = LoadMidiMapping() if mapping is None else mapping
    if isinstance(synergies, str):
        if synergies != "default":
            raise ValueError(f"synergies: expected 'default', a Synergies or None, got "
                             f"{synergies!r}")
        synergies = None
        if scenario.hand.kind == "shadow":
            synergies = default_synergies().synergies
    control_options.setdefault("initial_command", hand_initial_command(scenario))
    control_options.setdefault("coupling_ratio", scenario.hand.coupling_ratio)

    def add_control(builder, station):
        control = builder.AddNamedSystem("midi_hand_control", MidiHandControl(
            scenario.hand.kind, mapping, synergies=synergies, port=port,
            feedback_port=feedback_port, **control_options))
        builder.Connect(control.get_position_output_port(),
                        station.GetInputPort("hand.position"))
        if station.HasInputPort("wrist.pose"):
            from pydrake.systems.primitives import ConstantVectorSource


            pose = rpy_pose6(scenario.hand.mount.X_WB.GetDeterministicValue())
            builder.Connect(builder.AddSystem(ConstantVectorSource(pose)).get_output_port(),
                            station.GetInputPort("wrist.pose"))
        return control

    harness = TrialHarness(scenario, add_control, log=(), meshcat=meshcat, hardware=hardware)
    return MidiHandControlDiagram(harness.diagram, harness.station, harness.controller, harness)
