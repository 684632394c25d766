"""Seeing the table: simulated depth cameras, recorded frames, tabletop object
detection (report section 2.3)."""

from handle_drake.devices.camera.profiles import (
    PROFILES,
    CameraProfile,
    apply_depth_model,
    get_profile,
)

__all__ = ["PROFILES", "CameraProfile", "apply_depth_model", "get_profile"]
