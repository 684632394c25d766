"""Grasp classes (report Tables 1-2), recorded grasps, PCA synergies and planning.

Modules:

- :mod:`~handle_drake.grasp.taxonomy`: the eight grasp classes, Table 1 (grasp
  centre vs. object size), Table 2 (approach vectors), report <-> palm frame.
- :mod:`~handle_drake.grasp.recordings`: the ``handle_drake-grasps`` CSV format.
- :mod:`~handle_drake.grasp.synergies`: PCA synergies, choice of k,
  reconstruction error, amplitude-vs-size regression.
"""
