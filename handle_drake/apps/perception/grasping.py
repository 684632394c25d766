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
from pydrake.math import RigidTransform, RotationMatrix

from handle_drake.apps.perception.perceive import detection_error, render_views
from handle_drake.apps.perception.scenes import TabletopScene
from handle_drake.base.models import diagrams_dir
from handle_drake.devices.camera.config import drake_camera_config
from handle_drake.geometry.detect import Detection, detect
from handle_drake.geometry.objects import KINDS, ObjectSpec
from handle_drake.grasp.planning import resting_pose
from handle_drake.scenario import DepthCamera, LoadScenario, ObjectConfig
from handle_drake.station import object_initial_pose
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

__all__ = ["PerceivedObject", "perceive_object", "planner_input", "PLANNABLE", "PerceivedTrial",
           "aimed_trial_scenario", "perceived_grasp_trial", "select_detection"]

PLANNABLE = ("sphere", "cylinder", "cuboid")


@dc.dataclass
class PerceivedObject:
    kind: str
    size: float  # m, catalogue size as perceived
    X_WO: RigidTransform  # perceived resting pose
    true_size: float
    true_X_WO: RigidTransform
    detection: Detection
    selection: str = ""  # which detection was taken and why (select_detection)

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


def _tabletop_view(object_config, profile: str, seed: int):
    """``(scenario, view)``: ``object_config`` on the table of
    ``diagrams/tabletop_perception.yaml``, rendered through its camera (made a
    ``profile`` camera) with the scenario's noise seed ``seed``, and detected."""

    scenario = LoadScenario(filename=diagrams_dir() / "tabletop_perception.yaml")
    scenario.object = object_config
    scenario.random_seed = int(seed)
    camera = scenario.cameras[0]
    scenario.cameras = [DepthCamera(profile=profile, target=list(camera.target),
                                    config=drake_camera_config(profile, camera.name,
                                                               camera.config.X_PB))]
    (view,) = render_views(scenario)
    return scenario, view


def select_detection(detections, size: float, near_xy, size_of=None
                     ) -> tuple[Detection, str]:
    """The detection to grasp, chosen by what the robot is told, never by the
    truth: among the detections whose size (``size_of(detection)``, m;
    default the footprint's length ``extent[0]``) is within 25 % of the
    requested ``size``, the one nearest (horizontally) the commanded
    position ``near_xy`` (m, world); if none has that size, the one nearest
    ``near_xy``. Returns ``(detection, why)``, ``why`` a sentence naming the
    choice (for the user)."""
    if not detections:
        raise ValueError("perception: no object detected")
    size_of = (lambda d: float(d.extent[0])) if size_of is None else size_of
    near_xy = np.asarray(near_xy, dtype=float)
    sized = [d for d in detections if abs(size_of(d) - size) <= 0.25 * size]
    pool = sized or list(detections)
    chosen = min(pool, key=lambda d: float(np.linalg.norm(d.position[:2] - near_xy)))
    index = next(i for i, d in enumerate(detections) if d is chosen)
    p = chosen.position
    rule = ("of the requested size (within 25 %)" if sized else
            "none has the requested size (within 25 %)")
    why = (f"took detection {index + 1} of {len(detections)} ({chosen.kind} at "
           f"[{p[0]:+.3f}, {p[1]:+.3f}] m): the one nearest the commanded position "
           f"[{near_xy[0]:+.3f}, {near_xy[1]:+.3f}] m, {rule}")
    return chosen, why


def perceive_object(kind: str, size: float, xy=(0.0, 0.0), yaw: float = 0.0,
                    profile: str = "kinect_v1", seed: int = 0, near_xy=None,
                    clutter=()) -> PerceivedObject:
    """Renders the true object (resting pose at ``xy``, ``yaw`` rad) through
    the tabletop camera and returns what the planner is given.

    The detection planned on is chosen as a robot would, from the request
    alone (:func:`select_detection`): the requested size, nearest the
    commanded position ``near_xy`` (default ``xy``, where the user says the
    object rests). ``clutter``: other objects on the table
    (:class:`handle_drake.apps.perception.scenes.SceneObject`, standing upright);
    then the table is rendered without the hand
    (:class:`~handle_drake.apps.perception.scenes.TabletopScene`)."""

    if kind not in PLANNABLE:
        raise ValueError(f"kind: the planner grasps {list(PLANNABLE)}, got {kind!r}")
    X_WO = resting_pose(kind, size, xy=xy, yaw=yaw)
    if clutter:
        detections, message = _cluttered_view(kind, size, X_WO, clutter, profile, seed)
    else:
        _, view = _tabletop_view(ObjectConfig(kind=kind, size=size, X_WO=Transform(X_WO),
                                              on_table=False), profile, seed)
        detections, message = view.detections, view.message
    if not detections:
        raise ValueError(f"perception: no object detected ({message or 'empty view'})")
    detection, why = select_detection(detections, size, xy if near_xy is None else near_xy,
                                      size_of=lambda d: planner_input(kind, d)[0])
    perceived_size, X_WO_perceived = planner_input(kind, detection)
    return PerceivedObject(kind, perceived_size, X_WO_perceived, float(size), X_WO, detection,
                           why)


def _cluttered_view(kind, size, X_WO, clutter, profile, seed):
    """Detections of the object at ``X_WO`` among ``clutter`` (rendered
    without the hand)."""

    scene = TabletopScene(list(clutter), profile=profile, seed=seed,
                          extra=[(ObjectSpec(kind, float(size)), X_WO)])
    return detect(scene.frame(0.0)), ""


# --------------------------------------------------- the seven babbling objects
@dc.dataclass
class PerceivedTrial:
    """One of the seven grasp objects perceived on the table and grasped
    centred on its perceived pose (see :func:`perceived_grasp_trial`)."""

    kind: str
    true_xy_yaw: tuple  # (m, m, rad): where the object stood
    error: dict | None  # detection_error(): xy_mm, z_mm, yaw_deg, kind_ok; None: not seen
    offset_O: tuple  # (m, m): the hand's aim error in the object's frame
    yaw_error: float  # rad, the hand's yaw about the object against the trial's (see below)
    metric: float  # BW value of the grasp aimed at the perception (nan: not seen)
    force_closure: bool

    def as_dict(self) -> dict:
        return dc.asdict(self)


def aimed_trial_scenario(trial, offset_O, yaw_error: float = 0.0):
    """The babbling trial's scenario (``space='offset'``) with the hand aimed
    ``offset_O`` (m, object frame) off the object's axis and turned
    ``yaw_error`` (rad) about the vertical through its aim point: the grasp
    a perception error of that size produces, the object staying where the
    trial has it."""

    if not isinstance(trial, GraspTrial) or trial.config.space != "offset":
        raise ValueError("trial: expected a GraspTrial in the 'offset' space")
    offset_O = np.asarray(offset_O, dtype=float)
    if offset_O.shape != (2,) or not np.isfinite(offset_O).all():
        raise ValueError(f"offset_O: expected 2 finite values, got {offset_O}")
    if not math.isfinite(yaw_error):
        raise ValueError(f"yaw_error: expected a finite angle, got {yaw_error}")
    scenario = trial.scenario(offset_O)
    ctrl = scenario.controller
    start = np.array(ctrl.start_pose, dtype=float)
    c, s = math.cos(yaw_error), math.sin(yaw_error)
    rel = start[:2] - offset_O
    start[:2] = offset_O + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]])
    start[5] += yaw_error  # roll-pitch-yaw: the yaw turns about the world vertical
    return dc.replace(scenario, controller=dc.replace(ctrl, start_pose=start.tolist()))


def perceived_grasp_trial(kind: str, xy=(0.0, 0.0), yaw: float = 0.0, hand: str = "barrett",
                          profile: str = "kinect_v1", seed: int = 0, trial=None
                          ) -> PerceivedTrial:
    """Perceives a grasp object of the babbling experiments (any of the seven
    kinds, at its babbling size) standing on the table of
    ``diagrams/tabletop_perception.yaml`` at ``xy`` with ``yaw``, then runs
    the babbling grasp trial (guarded approach from above, close, BW metric)
    with the hand centred on the *perceived* centre and turned with the
    perceived yaw (box footprints; a round footprint has none, so the hand
    keeps its world yaw). The trial's object stands at the origin, so the
    error is carried into its frame; from the truth the same trial scores
    ``trial.evaluate([0, 0])``. ``trial``: a
    ``GraspTrial`` of that kind to reuse (its diagram is built once)."""

    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {list(KINDS)}, got {kind!r}")
    if trial is None:
        trial = GraspTrial(GraspTrialConfig(hand=hand, object=kind, space="offset"))
    if trial.config.object != kind:
        raise ValueError(f"trial: its object is {trial.config.object!r}, not {kind!r}")
    X = Transform(RigidTransform(RotationMatrix.MakeZRotation(float(yaw)),
                                 [float(xy[0]), float(xy[1]), 0.0]))
    scenario, view = _tabletop_view(ObjectConfig(kind=kind, size=trial.config.object_size,
                                                 X_WO=X, on_table=True), profile, seed)
    X_WO = object_initial_pose(scenario)
    truth = X_WO.translation()[:2]
    if not view.detections:
        return PerceivedTrial(kind, (float(xy[0]), float(xy[1]), float(yaw)), None,
                              (math.nan, math.nan), math.nan, math.nan, False)
    # Chosen as a robot would: the kind's size, nearest where it was told to look.
    detection, _ = select_detection(view.detections, trial.config.object_size, xy)
    error = detection_error(detection, scenario)
    R_OW = X_WO.rotation().inverse().matrix()
    d_W = np.array([*(detection.position[:2] - truth), 0.0])
    offset_O = (R_OW @ d_W)[:2]
    # A box footprint gives its yaw (the hand turns with it, off by the error);
    # a round footprint gives none, so the hand keeps its world yaw and meets
    # the object turned by -yaw (a mug's handle; nothing for a sphere).
    yaw_error = -float(yaw) if error["yaw_deg"] is None else math.radians(error["yaw_deg"])
    # The trial's own runner (built once, shared with trial.evaluate).
    runner = trial.runner
    result = runner.run(scenario=aimed_trial_scenario(trial, offset_O, yaw_error))
    return PerceivedTrial(kind, (float(xy[0]), float(xy[1]), float(yaw)), error,
                          (float(offset_O[0]), float(offset_O[1])), float(yaw_error),
                          float(result.score.value), bool(result.score.force_closure))
