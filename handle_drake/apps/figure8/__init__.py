"""Figure 8: in-hand rotations measured by the object's own accelerometer."""
