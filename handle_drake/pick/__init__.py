"""Pick and place on the Hamburg platform (issue 33): perceive, plan the grasp and
the arm's motion, execute, and put the object in its hole of the sorting box.

- :mod:`.scenes`: seeded random scenes of 2-5 objects on the scenario's table.
- :mod:`.plan`: :func:`plan_pick` (grasp planner + arm IK + collision-checked
  joint paths).
- :mod:`.execute`: runs a plan on the simulated station, judges "in the box".
- :mod:`.cli`: ``handle-drake pick``.
"""
