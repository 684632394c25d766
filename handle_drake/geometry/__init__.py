"""Geometry: the grasp objects (one ObjectSpec), grasp quality, tabletop detection.

Imports only :mod:`handle_drake.base`."""
