"""Depth frames as files: what a real camera's tools save, and what the
detector reads in place of the simulated camera.

A frame is a 16-bit PNG of depth in millimetres (0 = no reading), as OpenNI
and the Kinect tools save it, plus a JSON sidecar with the camera's
intrinsics and pose::

    {"format": "handle_drake-depth-frame", "version": 1,
     "depth_png": "kinect.png",            # relative to the JSON file
     "depth_scale": 0.001,                 # m per PNG unit
     "width": 640, "height": 480,
     "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
     "X_WC": [[...4 x 4...]]}              # camera pose in world (Drake camera
                                            # frame: +z forward, +x right, +y down)

:func:`points_from_depth` turns a depth image into world points, so the same
detector runs on simulated and captured frames.
"""

from __future__ import annotations

import dataclasses as dc
import json
import math
import warnings
from pathlib import Path

import numpy as np

from handle_drake.base.checks import check_input_file, read_text_file

__all__ = ["DepthFrame", "points_from_depth", "save_frame", "load_frame", "FORMAT"]

FORMAT = "handle_drake-depth-frame"
VERSION = 1
MAX_PNG_MM = 65535  # 16-bit
#: pixels: the largest depth image read (16 Mpx; depth cameras give 0.3-5 Mpx). Checked
#: from the PNG header before decoding (a 108 Mpx PNG ran 22 s into a MemoryError).
MAX_PIXELS = 1 << 24
#: px: focal lengths fx, fy outside this range are not a camera's (a 640 px image
#: with fx = 1 px sees 175 degrees, with 1e5 px 0.4 degrees).
FOCAL_RANGE = (1.0, 1e5)
#: m per PNG unit: 1 um .. 1 cm (OpenNI/Kinect save mm: 0.001; some cameras 0.1 mm).
DEPTH_SCALE_RANGE = (1e-6, 0.01)
#: m: the camera's distance from the world origin.
MAX_CAMERA_DISTANCE = 100.0


@dc.dataclass
class DepthFrame:
    depth: np.ndarray  # H x W, m, inf where invalid
    K: np.ndarray  # 3 x 3
    X_WC: np.ndarray  # 4 x 4

    def __post_init__(self):
        depth = np.asarray(self.depth)
        if depth.ndim != 2 or depth.size == 0:
            raise ValueError(f"depth must be a non-empty H x W image, got shape {depth.shape}")
        if depth.size > MAX_PIXELS:
            raise ValueError(f"depth: expected at most {MAX_PIXELS} pixels, got "
                             f"{depth.shape[1]} x {depth.shape[0]}")
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"K must be a finite 3 x 3 pinhole matrix with fx, fy > 0, got {K}")
        height, width = depth.shape
        lo, hi = FOCAL_RANGE
        for name, value in (("fx", K[0, 0]), ("fy", K[1, 1])):
            if not lo <= value <= hi:
                raise ValueError(f"K: focal length {name} must be in [{lo:g}, {hi:g}] px, got "
                                 f"{value:g}")
        for name, value, size in (("cx", K[0, 2], width), ("cy", K[1, 2], height)):
            if not 0 <= value <= size:
                raise ValueError(f"K: principal point {name} must lie in the {width} x {height} "
                                 f"image ([0, {size}] px), got {value:g}")
        if K[1, 0] != 0 or np.any(K[2] != (0, 0, 1)) or abs(K[0, 1]) > K[0, 0]:
            raise ValueError(f"K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with |s| <= fx, "
                             f"got {K.tolist()}")
        X = np.asarray(self.X_WC, dtype=float)
        if X.shape != (4, 4) or not np.all(np.isfinite(X)):
            raise ValueError(f"X_WC must be a finite 4 x 4 pose, got shape {X.shape}")
        if np.any(X[3] != (0, 0, 0, 1)):
            raise ValueError(f"X_WC: the last row of a pose must be [0, 0, 0, 1], got "
                             f"{X[3].tolist()}")
        R = X[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("X_WC: the rotation part is not a rotation matrix")
        if np.linalg.norm(X[:3, 3]) > MAX_CAMERA_DISTANCE:
            raise ValueError(f"X_WC: the camera must be within {MAX_CAMERA_DISTANCE:g} m of the "
                             f"world origin, got {np.linalg.norm(X[:3, 3]):.3g} m")
        self.depth = depth.astype(np.float32)
        self.K, self.X_WC = K, X

    def points(self) -> np.ndarray:
        return points_from_depth(self.depth, self.K, self.X_WC)


def points_from_depth(depth: np.ndarray, K: np.ndarray, X_WC: np.ndarray) -> np.ndarray:
    """World points (N x 3, m) of the valid pixels (finite, > 0) of a depth
    image (m, along the optical axis) taken by a pinhole camera ``K`` at
    ``X_WC``."""
    depth = np.asarray(depth, dtype=float)
    v, u = np.nonzero(np.isfinite(depth) & (depth > 0))
    z = depth[v, u]
    x = (u - K[0, 2]) * z / K[0, 0]
    y = (v - K[1, 2]) * z / K[1, 1]
    p_C = np.column_stack([x, y, z])
    return p_C @ X_WC[:3, :3].T + X_WC[:3, 3]


def save_frame(path: str | Path, frame: DepthFrame, depth_scale: float = 0.001) -> Path:
    """Writes ``<path>.json`` and ``<path>.png``; returns the JSON path. Depth
    beyond the 16-bit range (65.535 m at mm scale) is stored as 0 (invalid)."""
    from PIL import Image

    lo, hi = DEPTH_SCALE_RANGE
    if isinstance(depth_scale, bool) or not isinstance(depth_scale, int | float) or \
            not (math.isfinite(depth_scale) and lo <= depth_scale <= hi):
        raise ValueError(f"depth_scale: expected metres per PNG unit in [{lo:g}, {hi:g}], got "
                         f"{depth_scale!r}")
    path = Path(path)
    if path.suffix in (".json", ".png"):
        path = path.with_suffix("")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"frame directory does not exist: {path.parent}")
    units = np.round(np.where(np.isfinite(frame.depth), frame.depth, 0) / depth_scale)
    units = np.where((units > 0) & (units <= MAX_PNG_MM), units, 0).astype(np.uint16)
    png = path.with_suffix(".png")
    Image.fromarray(units).save(png)
    meta = {"format": FORMAT, "version": 1, "depth_png": png.name, "depth_scale": depth_scale,
            "width": int(frame.depth.shape[1]), "height": int(frame.depth.shape[0]),
            "K": frame.K.tolist(), "X_WC": frame.X_WC.tolist()}
    json_path = path.with_suffix(".json")
    json_path.write_text(json.dumps(meta, indent=1))
    return json_path


def _has_non_number(value) -> bool:
    """True for text, booleans or null anywhere in nested lists (numpy reads "1" and true)."""
    if isinstance(value, list):
        return any(_has_non_number(v) for v in value)
    return isinstance(value, bool) or not isinstance(value, int | float)


def _sidecar_number(path, meta, key, integer=False):
    value = meta[key]
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        raise ValueError(f"frame {path}: {key}: expected {kind}, got {value!r}"[:300])
    return value


def _read_depth_png(path: Path, png: Path) -> np.ndarray:
    """The frame's depth image as an array of PNG units (checked: a PNG, at most
    :data:`MAX_PIXELS`, a single-channel 16-bit mode); errors name the frame ``path``."""
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():  # the pixel cap below says it in one line
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(png)
        with image:
            if image.format != "PNG":
                raise ValueError(f"frame {path}: depth_png: expected a PNG image, got "
                                 f"{image.format} ({png.name})")
            if image.width * image.height > MAX_PIXELS:
                raise ValueError(f"frame {path}: depth_png: expected at most {MAX_PIXELS} "
                                 f"pixels, got {image.width} x {image.height}")
            # Pillow opens a 16-bit grey PNG as "I;16" (older versions: "I").
            if image.mode not in ("I;16", "I;16B", "I"):
                raise ValueError(f"frame {path}: depth_png: expected a single-channel 16-bit "
                                 f"PNG (depth in units of depth_scale), got mode {image.mode} "
                                 f"({png.name})")
            units = np.asarray(image)
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError, SyntaxError) as error:
        raise ValueError(f"frame {path}: cannot read depth image {png.name}: {error}") from None
    return units


def load_frame(path: str | Path) -> DepthFrame:
    """Reads a frame's JSON sidecar and its 16-bit depth PNG.

    Raises FileNotFoundError, or ValueError naming the field: not the format or
    version, a width/height/depth_scale that is not a number of the right kind
    or range, an image larger than :data:`MAX_PIXELS`, an image that is not a
    single-channel 16-bit PNG (an 8-bit PNG would be millimetres up to 0.255 m,
    a 32-bit TIFF holds signed values), intrinsics or a pose out of range
    (:class:`DepthFrame`).
    """
    text = read_text_file(path, "frame", max_bytes=1 << 20)  # the sidecar is < 1 kB
    path = Path(path)
    try:
        meta = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as error:
        raise ValueError(f"frame {path}: not a JSON file ({error})"[:300]) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"frame {path}: expected a JSON object with format {FORMAT!r}")
    for key in ("depth_png", "depth_scale", "width", "height", "K", "X_WC"):
        if key not in meta:
            raise ValueError(f"frame {path}: missing field {key!r}")
    version = meta.get("version", VERSION)
    if isinstance(version, bool) or version != VERSION:
        raise ValueError(f"frame {path}: version: expected {VERSION}, got {version!r}"[:300])
    width = _sidecar_number(path, meta, "width", integer=True)
    height = _sidecar_number(path, meta, "height", integer=True)
    if width < 1 or height < 1 or width * height > MAX_PIXELS:
        raise ValueError(f"frame {path}: width, height: expected at least 1 and at most "
                         f"{MAX_PIXELS} pixels in all, got {width} x {height}")
    scale = _sidecar_number(path, meta, "depth_scale")
    lo, hi = DEPTH_SCALE_RANGE
    if not (math.isfinite(scale) and lo <= scale <= hi):
        raise ValueError(f"frame {path}: depth_scale: expected metres per PNG unit in "
                         f"[{lo:g}, {hi:g}] (0.001: millimetres), got {scale!r}")
    if not isinstance(meta["depth_png"], str) or not meta["depth_png"]:
        raise ValueError(f"frame {path}: depth_png: expected a file name, got "
                         f"{meta['depth_png']!r}"[:300])
    png = check_input_file(path.parent / meta["depth_png"], f"frame {path}: depth_png")
    units = _read_depth_png(path, png)
    if units.ndim != 2 or units.dtype.kind not in "iu" or units.min(initial=0) < 0 or \
            units.max(initial=0) > MAX_PNG_MM:
        raise ValueError(f"frame {path}: depth_png: expected a single-channel 16-bit image, got "
                         f"shape {units.shape} of {units.dtype}")
    if units.shape != (height, width):
        raise ValueError(f"frame {path}: image is {units.shape[1]} x {units.shape[0]}, the "
                         f"sidecar says {width} x {height}")
    depth = np.where(units > 0, units.astype(np.float64) * scale, np.inf)
    matrices = {}
    for key, shape in (("K", (3, 3)), ("X_WC", (4, 4))):
        value = meta[key]
        try:
            if _has_non_number(value):
                raise TypeError
            matrices[key] = np.array(value, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"frame {path}: {key}: expected a {shape[0]} x {shape[1]} matrix "
                             f"of numbers, got {value!r}"[:300]) from None
    try:
        return DepthFrame(depth=depth, **matrices)
    except (TypeError, ValueError) as error:
        raise ValueError(f"frame {path}: {error}") from None
