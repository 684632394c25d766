"""Grasp classes (report Tables 1-2), recorded grasps, PCA synergies and planning.

Modules:

- :mod:`~handle_drake.grasp.taxonomy`: the eight grasp classes, Table 1 (grasp
  centre vs. object size), Table 2 (approach vectors), report <-> palm frame.
- :mod:`~handle_drake.grasp.recordings`: the ``handle_drake-grasps`` CSV format.
- :mod:`~handle_drake.grasp.synergies`: PCA synergies, choice of k,
  reconstruction error, amplitude-vs-size regression.
- :mod:`~handle_drake.grasp.kinematics`: grasp IK on the Shadow model.
- :mod:`~handle_drake.grasp.planning`: ``plan_grasp`` (class + object + pose ->
  pre-shape, hand pose, stand-off, keyframes for a floating-wrist scenario).
- :mod:`~handle_drake.apps.planning.cli`: ``handle-drake grasp`` and ``handle-drake synergies``.
"""
