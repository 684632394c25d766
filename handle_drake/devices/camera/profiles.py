"""Depth camera profiles and the depth-noise model.

A profile is what a user knows of their sensor: resolution, field of view,
valid depth range, depth noise and depth quantisation. Two ship:

- ``kinect_v1``: Microsoft Kinect (first generation) / PrimeSense Carmine, the
  report's sensor (section 2.3). 640 x 480 depth at 57 x 43 deg field of view,
  valid 0.8-4.0 m (OpenNI's default range). Depth noise, from Khoshelham and
  Elberink (2012), "Accuracy and resolution of Kinect depth data for indoor
  mapping applications", Sensors 12(2): random error sigma(z) = 1.425e-3 z^2
  (m, z in m; "about 1.4 mm at 1 m, 4 cm at 5 m"). Quantisation: the sensor
  measures disparity in 1/8 pixel steps (f = 580 px, baseline b = 75 mm), so
  a depth z can only take values on a grid of step q(z) = z^2 / (8 f b) =
  2.87e-3 z^2 m (2.9 mm at 1 m, 4.6 cm at 4 m), as in that paper's figure 6.
- ``ideal``: the same optics without noise or quantisation, range 0.1-10 m,
  for tests against exact geometry.

The noise model is a plain function (:func:`apply_depth_model`); the station
wraps it in a LeafSystem between Drake's ``RgbdSensor`` and the point cloud.
Invalid pixels (outside the range, or no surface) are ``inf`` in depth, as
Drake's depth images mark "too far", and produce no point.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np

__all__ = ["CameraProfile", "PROFILES", "get_profile", "apply_depth_model",
           "disparity_step"]


@dc.dataclass(frozen=True)
class CameraProfile:
    name: str
    width: int  # px
    height: int  # px
    fov_y_deg: float  # vertical field of view
    min_depth: float  # m, closer is invalid
    max_depth: float  # m, farther is invalid
    noise_k: float = 0.0  # sigma(z) = noise_k * z^2 (m, z in m)
    quant_k: float = 0.0  # depth step q(z) = quant_k * z^2 (m); 0: continuous

    def __post_init__(self):
        for field in ("width", "height"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                raise ValueError(f"camera profile {self.name!r}: {field} must be a positive "
                                 f"integer number of pixels, got {value!r}")
        if not (math.isfinite(self.fov_y_deg) and 0 < self.fov_y_deg < 180):
            raise ValueError(f"camera profile {self.name!r}: fov_y_deg must be in (0, 180) deg, "
                             f"got {self.fov_y_deg!r}")
        if not (math.isfinite(self.min_depth) and math.isfinite(self.max_depth)
                and 0 < self.min_depth < self.max_depth):
            raise ValueError(f"camera profile {self.name!r}: need 0 < min_depth < max_depth "
                             f"(m), got {self.min_depth!r}, {self.max_depth!r}")
        for field in ("noise_k", "quant_k"):
            value = getattr(self, field)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"camera profile {self.name!r}: {field} must be finite and "
                                 f">= 0, got {value!r}")

    @property
    def fov_x_deg(self) -> float:
        """Horizontal field of view for square pixels."""
        fy = math.radians(self.fov_y_deg)
        return math.degrees(2 * math.atan(math.tan(fy / 2) * self.width / self.height))

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return self.height / 2 / math.tan(math.radians(self.fov_y_deg) / 2)

    def intrinsics(self) -> np.ndarray:
        """The 3 x 3 pinhole matrix K (principal point at the image centre)."""
        f = self.focal_px
        return np.array([[f, 0, (self.width - 1) / 2],
                         [0, f, (self.height - 1) / 2],
                         [0, 0, 1.0]])


def disparity_step(focal_px: float = 580.0, baseline: float = 0.075,
                   subpixel: float = 1 / 8) -> float:
    """``quant_k`` of a structured-light sensor: q(z) = subpixel z^2 / (f b)."""
    return subpixel / (focal_px * baseline)


PROFILES: dict[str, CameraProfile] = {
    # 57 x 43 deg, 640 x 480: the vertical FOV gives 43 deg, the horizontal
    # follows from the aspect ratio (55.1 deg for square pixels; the sheet's
    # 57 deg is the nominal, lens-distortion included).
    "kinect_v1": CameraProfile("kinect_v1", 640, 480, 43.0, 0.8, 4.0,
                               noise_k=1.425e-3, quant_k=disparity_step()),
    "ideal": CameraProfile("ideal", 640, 480, 43.0, 0.1, 10.0),
}


def get_profile(name: str) -> CameraProfile:
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"camera profile: unknown profile {name!r}; expected one of "
                         f"{sorted(PROFILES)}") from None


def apply_depth_model(depth: np.ndarray, profile: CameraProfile,
                      rng: np.random.Generator | None = None) -> np.ndarray:
    """A true depth image (m, H x W, ``inf`` or ``nan`` where nothing is seen)
    as the sensor reports it: Gaussian noise of sigma ``noise_k z^2``, depth
    quantised to steps of ``quant_k z^2``, and ``inf`` outside the valid range
    (and for non-finite or non-positive input pixels). Returns a new float32
    array."""
    z = np.array(depth, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"depth must be an H x W image, got shape {z.shape}")
    valid = np.isfinite(z) & (z > 0)
    z = np.where(valid, z, 1.0)  # placeholder: invalid pixels are marked at the end
    if profile.noise_k > 0:
        if rng is None:
            raise ValueError(f"profile {profile.name!r} is noisy: pass a seeded rng")
        noise = rng.standard_normal(z.shape)
        z = np.where(valid, z + profile.noise_k * z * z * noise, z)
    if profile.quant_k > 0:
        # Disparity d ~ 1/z is what the sensor quantises: z on the grid
        # 1 / (n * quant_k), whose local step is quant_k z^2.
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(valid, 1.0 / (np.round(1.0 / (profile.quant_k * z)) * profile.quant_k),
                         z)
    valid &= np.isfinite(z) & (z >= profile.min_depth) & (z <= profile.max_depth)
    return np.where(valid, z, np.inf).astype(np.float32)
