"""Taxel arrays on the hand's pads and the object's pose estimated from touch.

- :mod:`.profiles`: the device profiles (grid, pitch, range, noise, bits, rate).
- :mod:`.pads`: where the grids sit and each cell's force from the contact results
  (hydroelastic pressure fields; point contacts spread by a Gaussian).
- :mod:`.sensor`: the sensor, a recorded stream's playback, the Meshcat drawing.
- :mod:`.estimator`: the object's pose in the hand from ports alone.
- :mod:`.locate`: the object's pose in the hand from one reading (the pick's release).
- :mod:`.wiring`: what the station calls.
"""
