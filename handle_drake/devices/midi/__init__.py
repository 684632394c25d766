"""The iControls Pro MIDI controller (report sections 2.4.4 and 3.4, Figures 3 and 9).

Two uses of one device, behind the same ports in simulation and on hardware:

- an **instrumented object**: a model of the controller (faders, knobs, jog
  wheel, buttons as joints; :mod:`~handle_drake.devices.midi.device`) whose simulated
  control positions become the MIDI messages the device sends
  (:class:`~handle_drake.devices.midi.systems.MidiControllerEncoder`), so a learner
  knows what the hand moved without vision;
- a **hand-control interface**: faders and knobs drive the hand's joints or
  synergy amplitudes (:class:`~handle_drake.devices.midi.systems.MidiHandControl`),
  with motorised-fader feedback when the mode switches.

Modules: :mod:`~handle_drake.devices.midi.mapping` (the editable control -> message
file), :mod:`~handle_drake.devices.midi.codec` (pure translators),
:mod:`~handle_drake.devices.midi.ports` (mido ports: python-rtmidi for devices, an
in-process port, Meshcat sliders), :mod:`~handle_drake.devices.midi.systems`
(LeafSystems), :mod:`~handle_drake.apps.figure9.experiments` (Figure 9) and
:mod:`~handle_drake.apps.figure9.cli` (``handle-drake midi``).
"""
