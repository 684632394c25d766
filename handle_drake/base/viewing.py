"""Where the Meshcat camera looks: every view and replay opens framed on the hand
and the object, not on the whole (mostly empty) world.

Meshcat's default camera sits metres away looking at the origin; a hand is a
few pixels wide there. :func:`frame_hand_and_object` points the camera at the
hand and the object from a fixed viewing direction (in front of the palm's
side, above the table) at the distance where the sphere bounding them fills
the view. ``Meshcat.SetCameraPose`` is recorded in ``StaticHtml()`` pages, so
a saved replay opens framed as well.
"""

from __future__ import annotations

import numpy as np

__all__ = ["VIEW_DIRECTION", "VERTICAL_FOV", "framing_points", "camera_framing",
           "frame_hand_and_object"]

# From the target towards the camera, in world: to the side (-y) and above, a
# little towards +x so that fingers along +x are seen from the front, at an angle.
VIEW_DIRECTION = np.array([0.45, -0.75, 0.5])
VERTICAL_FOV = np.radians(75.0)  # Meshcat's (three.js) default perspective camera
MARGIN = 0.04  # m: link geometry around the body origins used as points
MIN_RADIUS = 0.08  # m: never closer than a hand-sized scene


def camera_framing(points: np.ndarray, direction: np.ndarray = VIEW_DIRECTION,
                   fov: float = VERTICAL_FOV) -> tuple[np.ndarray, np.ndarray]:
    """``(p_WCamera, p_WTarget)`` that frames ``points`` (N x 3, m): the target is
    the centre of their bounding box, the camera looks at it along
    ``-direction`` from where a sphere holding all points (plus a margin) just
    fits the vertical field of view ``fov`` (rad)."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"points must be an N x 3 array with N >= 1, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError("points must be finite")
    direction = np.asarray(direction, dtype=float)
    norm = np.linalg.norm(direction)
    if direction.shape != (3,) or not np.isfinite(norm) or norm == 0:
        raise ValueError(f"direction must be a non-zero 3-vector, got {direction}")
    if not 0 < fov < np.pi:
        raise ValueError(f"fov must be in (0, pi) rad, got {fov}")
    target = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = max(MIN_RADIUS, float(np.linalg.norm(points - target, axis=1).max()) + MARGIN)
    distance = radius / np.sin(fov / 2)
    return target + distance * direction / norm, target


def framing_points(plant, plant_context) -> np.ndarray:
    """World positions (N x 3) of the hand's bodies and of the object body, if
    the plant has them (model instances ``hand`` and ``object``)."""
    points = []
    for name in ("hand", "object"):
        if not plant.HasModelInstanceNamed(name):
            continue
        instance = plant.GetModelInstanceByName(name)
        for index in plant.GetBodyIndices(instance):
            X_WB = plant.EvalBodyPoseInWorld(plant_context, plant.get_body(index))
            points.append(X_WB.translation())
    return np.array(points).reshape(-1, 3)


def frame_hand_and_object(meshcat, plant, plant_context,
                          extra_points: np.ndarray | None = None) -> np.ndarray:
    """Points ``meshcat``'s camera at the hand and object of ``plant`` in
    ``plant_context`` (and ``extra_points``, e.g. where they were earlier in a
    replay). Returns the points framed, so a caller can add later ones."""
    points = framing_points(plant, plant_context)
    if extra_points is not None and len(extra_points):
        points = np.vstack([points, extra_points])
    if len(points):
        camera, target = camera_framing(points)
        meshcat.SetCameraPose(camera, target)
    return points
