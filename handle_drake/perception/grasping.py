"""Grasps planned from what the camera sees (report section 2.3 -> 3).

:func:`perceive_object` places the true object on the table of
``diagrams/tabletop_perception.yaml``, renders its Kinect, detects, and turns
the detection into what the grasp planner takes: the catalogue size and the
resting pose ``X_WO``. The plan is then executed on the *true* object
(``run_plan(..., world_object=...)``), so the perception error reaches the
hand as it would on a real robot.

From a detection to the planner's input (kinds the planner grasps):

- ``sphere``: size = the fitted sphere's diameter; centre from the fit.
- ``cuboid`` (upright): size = the footprint's long side (the catalogue
  cuboid's ``width``; depth and height follow its proportions), yaw = the long
  side's direction, centre = the footprint rectangle's centre.
- ``cylinder`` (lying on its side, as the planner grasps it): size = the
  diameter = the detected height; its axis is the footprint's long side, so
  ``resting_pose``'s yaw (axis along (-sin yaw, cos yaw)) is that direction
  minus 90 deg.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform

from handle_drake.perception.detect import Detection

__all__ = ["PerceivedObject", "perceive_object", "planner_input", "PLANNABLE"]

PLANNABLE = ("sphere", "cylinder", "cuboid")


@dc.dataclass
class PerceivedObject:
    kind: str
    size: float  # m, catalogue size as perceived
    X_WO: RigidTransform  # perceived resting pose
    true_size: float
    true_X_WO: RigidTransform
    detection: Detection

    def errors(self) -> dict:
        """Position (mm, xy and z), yaw (deg, modulo the object's symmetry;
        None for a sphere) and size (mm) errors of the perceived pose."""
        dp = self.X_WO.translation() - self.true_X_WO.translation()
        yaw = None
        if self.kind != "sphere":
            period = math.pi  # a box's footprint and a lying cylinder's axis
            a, b = (math.atan2(X.rotation().matrix()[1, 0], X.rotation().matrix()[0, 0])
                    for X in (self.X_WO, self.true_X_WO))
            yaw = math.degrees((a - b + period / 2) % period - period / 2)
        return {"xy_mm": float(np.linalg.norm(dp[:2]) * 1000), "z_mm": float(dp[2] * 1000),
                "yaw_deg": yaw, "size_mm": float((self.size - self.true_size) * 1000)}


def planner_input(kind: str, detection: Detection, table_height: float = 0.0
                  ) -> tuple[float, RigidTransform]:
    """``(size, X_WO)`` for ``plan_grasp`` from a detection of a ``kind``
    object (see the module doc)."""
    from handle_drake.grasp.planning import resting_pose

    if kind not in PLANNABLE:
        raise ValueError(f"kind: the planner grasps {list(PLANNABLE)}, got {kind!r}")
    xy = detection.position[:2]
    if kind == "sphere":
        size, yaw = float(detection.extent[0]), 0.0
    elif kind == "cuboid":
        size, yaw = float(detection.extent[0]), float(detection.yaw)
    else:
        size, yaw = float(detection.extent[2]), float(detection.yaw) - math.pi / 2
    return size, resting_pose(kind, size, xy=xy, yaw=yaw, table_height=table_height)


def perceive_object(kind: str, size: float, xy=(0.0, 0.0), yaw: float = 0.0,
                    profile: str = "kinect_v1", seed: int = 0) -> PerceivedObject:
    """Renders the true object (resting pose at ``xy``, ``yaw`` rad) through
    the tabletop camera and returns what the planner is given."""
    from handle_drake.demo import diagrams_dir
    from handle_drake.grasp.planning import resting_pose
    from handle_drake.perception.perceive import render_views
    from handle_drake.scenario import CameraConfig, LoadScenario, ObjectConfig

    if kind not in PLANNABLE:
        raise ValueError(f"kind: the planner grasps {list(PLANNABLE)}, got {kind!r}")
    X_WO = resting_pose(kind, size, xy=xy, yaw=yaw)
    scenario = LoadScenario(filename=diagrams_dir() / "tabletop_perception.yaml")
    scenario.object = ObjectConfig(kind=kind, size=size, X_WO=Transform(X_WO), on_table=False)
    scenario.random_seed = int(seed)
    camera = scenario.cameras[0]
    scenario.cameras = [CameraConfig(name=camera.name, profile=profile, parent=camera.parent,
                                     X_PC=camera.X_PC, target=list(camera.target))]
    (view,) = render_views(scenario)
    if not view.detections:
        raise ValueError(f"perception: no object detected ({view.message or 'empty view'})")
    truth = X_WO.translation()[:2]
    detection = min(view.detections, key=lambda d: float(np.linalg.norm(d.position[:2] - truth)))
    perceived_size, X_WO_perceived = planner_input(kind, detection)
    return PerceivedObject(kind, perceived_size, X_WO_perceived, float(size), X_WO, detection)
