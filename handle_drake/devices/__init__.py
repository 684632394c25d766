"""Devices: the CAN hand, accelerometers, the MIDI controller, depth cameras.

Each has its configuration, pure translators, LeafSystems and one function
that adds it to a station's builder. Imports only the layers below."""
