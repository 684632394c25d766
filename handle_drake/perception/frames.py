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
from pathlib import Path

import numpy as np

__all__ = ["DepthFrame", "points_from_depth", "save_frame", "load_frame", "FORMAT"]

FORMAT = "handle_drake-depth-frame"
MAX_PNG_MM = 65535  # 16-bit


@dc.dataclass
class DepthFrame:
    depth: np.ndarray  # H x W, m, inf where invalid
    K: np.ndarray  # 3 x 3
    X_WC: np.ndarray  # 4 x 4

    def __post_init__(self):
        depth = np.asarray(self.depth)
        if depth.ndim != 2 or depth.size == 0:
            raise ValueError(f"depth must be a non-empty H x W image, got shape {depth.shape}")
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"K must be a finite 3 x 3 pinhole matrix with fx, fy > 0, got {K}")
        X = np.asarray(self.X_WC, dtype=float)
        if X.shape != (4, 4) or not np.all(np.isfinite(X)):
            raise ValueError(f"X_WC must be a finite 4 x 4 pose, got shape {X.shape}")
        R = X[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("X_WC: the rotation part is not a rotation matrix")
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

    if not (math.isfinite(depth_scale) and depth_scale > 0):
        raise ValueError(f"depth_scale must be finite and > 0 (m per unit), got {depth_scale}")
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


def load_frame(path: str | Path) -> DepthFrame:
    """Reads a frame's JSON sidecar and its 16-bit depth PNG."""
    from PIL import Image, UnidentifiedImageError

    from handle_drake.scenario_checks import read_text_file

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
    from handle_drake.scenario_checks import check_input_file

    png = check_input_file(path.parent / str(meta["depth_png"]), f"frame {path}: depth image")
    try:
        image = Image.open(png)
        units = np.asarray(image)
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as error:
        raise ValueError(f"frame {path}: cannot read depth image {png.name}: {error}") from None
    if units.ndim != 2 or units.dtype not in (np.uint16, np.int32, np.uint8):
        raise ValueError(f"frame {path}: {png.name} must be a single-channel 16-bit image, got "
                         f"shape {units.shape} of {units.dtype}")
    if units.shape != (meta["height"], meta["width"]):
        raise ValueError(f"frame {path}: image is {units.shape[1]} x {units.shape[0]}, the "
                         f"sidecar says {meta['width']} x {meta['height']}")
    scale = meta["depth_scale"]
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"frame {path}: depth_scale must be a number > 0, got {scale!r}")
    depth = np.where(units > 0, units.astype(np.float64) * scale, np.inf)
    try:
        return DepthFrame(depth=depth, K=np.array(meta["K"], dtype=float),
                          X_WC=np.array(meta["X_WC"], dtype=float))
    except (TypeError, ValueError) as error:
        raise ValueError(f"frame {path}: {error}") from None
