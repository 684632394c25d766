"""Grasps planned from what the camera sees, and ``handle-drake perceive``."""
