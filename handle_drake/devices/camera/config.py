"""The scenario field of a depth camera: Drake's ``CameraConfig`` plus the
device profile.

No ``from __future__ import annotations`` here: Drake's YAML reader needs real
types (see ``handle_drake.scenario``).

.. code-block:: yaml

    cameras:
      - profile: kinect_v1           # handle_drake.devices.camera.PROFILES
        target: [0, 0, 0]            # optional look-at point (m, world)
        config:                      # Drake's pydrake.systems.sensors.CameraConfig
          name: kinect
          X_PB: {base_frame: world, translation: [-0.707, 0, 0.707]}

``config`` is Drake's own ``CameraConfig`` (as in RussTedrake/manipulation's
scenarios): ``name`` names the station's ``<name>.*`` ports, ``X_PB`` is the
camera's pose in its parent frame ``X_PB.base_frame``: ``world`` (the default,
a fixed camera), ``wrist`` (the hand's base body, moving with it) or, with the
hand on an ``!Arm``, ``arm::<link>`` (a link of the arm: the Paris platform's
Kinect on the arm's trunk, ``arm::trunk``). The
camera frame follows Drake's convention: +z along the optical axis, +x to the
right of the image, +y down. With ``target`` (world-fixed cameras only), only
``X_PB``'s translation is used and the camera looks at ``target`` with the
image's up direction as close to world +z as possible.

What Drake's type cannot say lives beside it: the device ``profile`` (depth
noise, quantisation, valid range) and the look-at ``target``. The profile also
fixes the render intrinsics: :func:`drake_camera_config` writes its ``width``,
``height`` and vertical field of view (``focal``), the principal point at the
image centre and the renderer's clipping and depth ranges into the
``CameraConfig``; a YAML that sets one of these to another value is refused
with the field named. The station renders on demand (``RgbdSensor``), so
``CameraConfig``'s publishing fields (``fps``, ``capture_offset``,
``output_delay``, ``rgb``, ``depth``, ``label``, ``show_rgb``,
``do_compress``, ``lcm_bus``, ``background``) and the body offsets ``X_BC``,
``X_BD`` (one optical frame for colour and depth) keep Drake's defaults.
"""

import dataclasses as dc

import numpy as np
from pydrake.common.schema import Transform
from pydrake.systems.sensors import CameraConfig

from handle_drake.devices.camera.profiles import CameraProfile, get_profile

__all__ = ["ARM_PARENT_PREFIX", "CAMERA_PARENTS", "CameraConfig", "DepthCamera", "RENDERER",
           "drake_camera_config", "resolve_camera_config"]

#: The render engine the station adds for its cameras (RenderEngineVtk).
RENDERER = "handle_drake_vtk"
#: Parent frames a camera's ``X_PB.base_frame`` may name (None means world).
CAMERA_PARENTS = ("world", "wrist")
#: Prefix of a camera parent that is a link of the scenario's arm (``arm::trunk``).
ARM_PARENT_PREFIX = "arm::"
# The renderer's ranges are wider than any profile's valid depth range: the
# profile's depth model marks what lies outside it.
_CLIPPING = (0.01, 20.0)  # m
_DEPTH_RANGE = (0.02, 15.0)  # m
#: CameraConfig fields the profile sets (the render intrinsics and ranges).
PROFILE_FIELDS = ("width", "height", "focal", "center_x", "center_y", "clipping_near",
                  "clipping_far", "z_near", "z_far", "renderer_name", "renderer_class")
#: CameraConfig fields the station does not use (Drake's LCM image publishing).
UNUSED_FIELDS = ("fps", "capture_offset", "output_delay", "rgb", "depth", "label", "show_rgb",
                 "do_compress", "lcm_bus", "background")


def drake_camera_config(profile: CameraProfile | str, name: str = "camera",
                        X_PB: Transform | None = None) -> CameraConfig:
    """Drake's ``CameraConfig`` of a ``profile`` camera: its resolution, vertical
    field of view (square pixels, principal point at the image centre), this
    station's renderer and clipping/depth ranges, then ``name`` and ``X_PB``."""
    if isinstance(profile, str):
        profile = get_profile(profile)
    return CameraConfig(
        name=name, width=profile.width, height=profile.height,
        focal=CameraConfig.FovDegrees(y=profile.fov_y_deg),
        clipping_near=_CLIPPING[0], clipping_far=_CLIPPING[1],
        z_near=_DEPTH_RANGE[0], z_far=_DEPTH_RANGE[1],
        renderer_name=RENDERER, X_PB=Transform() if X_PB is None else X_PB)


@dc.dataclass
class DepthCamera:
    """A depth camera rendered by Drake's ``RgbdSensor``: Drake's
    ``CameraConfig`` plus the device ``profile`` and an optional look-at
    ``target`` (see the module doc)."""

    profile: str = "kinect_v1"  # see handle_drake.devices.camera.PROFILES
    target: list[float] = dc.field(default_factory=list)  # m, world; [] for none
    config: CameraConfig = dc.field(default_factory=lambda: CameraConfig(name="camera"))

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def parent(self) -> str:
        """``world``, ``wrist`` or ``arm::<link>``: ``config.X_PB.base_frame`` (None is
        world)."""
        return self.config.X_PB.base_frame or "world"


def _same(a, b) -> bool:
    if isinstance(a, CameraConfig.FovDegrees | CameraConfig.FocalLength):
        return type(a) is type(b) and repr(a) == repr(b)
    return a == b or (isinstance(a, float) and isinstance(b, float) and np.isclose(a, b))


def resolve_camera_config(camera: DepthCamera, where: str, error=ValueError) -> CameraConfig:
    """``camera.config`` with the profile's fields written in (the camera's
    config is updated in place and returned). Raises ``error`` naming
    ``<where>.config.<field>`` when the YAML set a profile field to another
    value than the profile's, or changed a field the station does not use."""
    profile = get_profile(camera.profile)
    drake_default = CameraConfig()
    want = drake_camera_config(profile, camera.config.name, camera.config.X_PB)
    for field in PROFILE_FIELDS:
        value = getattr(camera.config, field)
        if not (_same(value, getattr(drake_default, field))
                or _same(value, getattr(want, field))):
            raise error(f"{where}.config.{field}: set by the profile {profile.name!r} "
                        f"({getattr(want, field)!r}); got {value!r} (choose a profile instead)")
        setattr(camera.config, field, getattr(want, field))
    for field in UNUSED_FIELDS:
        if not _same(getattr(camera.config, field), getattr(drake_default, field)):
            raise error(f"{where}.config.{field}: not used by the station (it renders on "
                        f"demand, without LCM images); leave Drake's default "
                        f"{getattr(drake_default, field)!r}")
    for field in ("X_BC", "X_BD"):
        X = getattr(camera.config, field)
        if X.base_frame is not None or not (X.IsDeterministic() and np.allclose(
                X.GetDeterministicValue().GetAsMatrix4(), np.eye(4))):
            raise error(f"{where}.config.{field}: colour and depth share one optical frame: "
                        f"leave it the identity and give the pose in X_PB")
    return camera.config
