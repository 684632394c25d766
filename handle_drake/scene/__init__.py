"""A table with several objects and the toy-sorting box (report section 2.2, Fig. 4).

- :mod:`handle_drake.scene.config`: the scenario's ``objects:`` and
  ``sorting_box:`` fields and their checks.
- :mod:`handle_drake.scene.plant`: the objects and the box in a plant, and the
  box's geometry (a lid with one shaped hole per catalogue object).
- :mod:`handle_drake.scene.random_scene`: seeded random scenes of 2-5 objects.
"""
