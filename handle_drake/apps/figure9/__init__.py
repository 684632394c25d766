"""Figure 9: the hand works the MIDI controller; MIDI tells what moved."""
