"""``handle-drake perceive``: render a scenario's cameras (or read recorded
frames), detect the objects on the table, and in simulation compare them
with the truth.

- ``perceive SCENARIO [--override YAML] [--json] [--save-frames DIR]``
- ``perceive --frame FRAME.json [--json]`` (a recorded frame, see
  :mod:`handle_drake.devices.camera.frames`)

JSON output::

    {"objects": [{"camera": "kinect", "position": [x, y, z], "extent": [l, w, h],
                  "yaw": rad, "kind": "box", "residual": m,
                  "error": {"position_mm": [..], "xy_mm": .., "z_mm": ..,
                            "yaw_deg": .. or null, "extent_mm": [..],
                            "kind_expected": "box", "kind_ok": true}}],
     "tables": [{"camera": "kinect", "normal": [..], "height": m}],
     "messages": [...]}

positions in the world frame in metres; ``position`` is the estimated centre
of the object's body frame (mid-height on its axis); ``error`` only in
simulation (the truth is the scenario's object).
"""

from __future__ import annotations

import dataclasses as dc
import json
import math
from pathlib import Path

import numpy as np

from handle_drake.devices.camera.frames import DepthFrame, load_frame, save_frame
from handle_drake.geometry.detect import Detection, DetectorParams, TablePlane, detect_objects

__all__ = ["CameraView", "render_views", "perceive_frame", "detection_error", "true_extent",
           "CATALOGUE_PRIMITIVE", "register"]

#: The primitive a catalogue object should be recognised as.
CATALOGUE_PRIMITIVE = {"sphere": "sphere", "cylinder": "cylinder", "mug": "cylinder",
                       "wine_glass": "cylinder", "star_prism": "cylinder",
                       "cuboid": "box", "rotated_cuboid": "box"}


@dc.dataclass
class CameraView:
    camera: str
    frame: DepthFrame
    plane: TablePlane | None
    detections: list[Detection]
    message: str = ""


def perceive_frame(camera: str, frame: DepthFrame,
                   params: DetectorParams | None = None) -> CameraView:
    params = DetectorParams() if params is None else params
    valid = np.isfinite(frame.depth) & (frame.depth > 0)
    if not valid.any():
        return CameraView(camera, frame, None, [],
                          f"camera {camera}: nothing in view (no valid depth pixel: everything "
                          f"is out of the sensor's range)")
    plane, detections = detect_objects(frame.points(), params, view=frame)
    message = ""
    if plane is None:
        message = f"camera {camera}: nothing in view (no table plane among the points)"
    elif not detections:
        message = f"camera {camera}: the table is in view, no object on it"
    return CameraView(camera, frame, plane, detections, message)


def render_views(scenario, params: DetectorParams | None = None, time: float = 0.0,
                 exclude_robot: bool = True) -> list[CameraView]:
    """Builds the simulated station, renders every camera at ``time`` (s) with
    the scenario's initial state, and detects.

    ``exclude_robot``: pixels whose render label belongs to the hand or the
    wrist (the label image: Drake labels each body's geometry) are dropped
    before detection, as a real system filters itself out with its known
    model and joint angles; otherwise a hand in view merges with the object
    into one wrong cluster. The views' frames are then the filtered depth.
    """
    from handle_drake.devices.camera.profiles import get_profile
    from handle_drake.devices.camera.sensors import camera_info
    from handle_drake.station import MakeHandStation

    params = DetectorParams() if params is None else params
    if not scenario.cameras:
        raise ValueError("cameras: the scenario has no camera; add one under 'cameras:' "
                         "(see diagrams/tabletop_perception.yaml)")
    station = MakeHandStation(scenario)
    context = station.CreateDefaultContext()
    context.SetTime(time)
    robot = robot_labels(station) if exclude_robot else np.empty(0, dtype=int)
    views = []
    for camera in scenario.cameras:
        image = station.GetOutputPort(f"{camera.name}.depth").Eval(context)
        depth = np.array(image.data)[:, :, 0]
        if robot.size:
            labels = np.array(station.GetOutputPort(f"{camera.name}.label").Eval(context).data)
            depth = np.where(np.isin(labels[:, :, 0], robot), np.inf, depth)
        X_WC = station.GetOutputPort(f"{camera.name}.pose").Eval(context)
        info = camera_info(get_profile(camera.profile))
        K = info.intrinsic_matrix()
        frame = DepthFrame(depth=depth, K=K, X_WC=X_WC.GetAsMatrix4())
        views.append(perceive_frame(camera.name, frame, params))
    return views


def robot_labels(station) -> np.ndarray:
    """The render labels of the hand's, wrist's and arm's geometry in ``station``,
    and of the sorting box (a known fixture, as the robot is known), read from
    each perception geometry's ``("label", "id")`` property."""
    from pydrake.geometry import Role

    from handle_drake.station import HAND_INSTANCE, WRIST_INSTANCE

    plant = station.GetSubsystemByName("plant")
    inspector = station.GetSubsystemByName("scene_graph").model_inspector()
    labels = set()
    for name in (HAND_INSTANCE, WRIST_INSTANCE, "arm", "sorting_box"):
        if not plant.HasModelInstanceNamed(name):
            continue
        for body_index in plant.GetBodyIndices(plant.GetModelInstanceByName(name)):
            frame_id = plant.GetBodyFrameIdIfExists(body_index)
            if frame_id is None:
                continue
            for geometry in inspector.GetGeometries(frame_id, Role.kPerception):
                properties = inspector.GetPerceptionProperties(geometry)
                if properties.HasProperty("label", "id"):
                    labels.add(int(properties.GetProperty("label", "id")))
    return np.array(sorted(labels), dtype=int)


def _true_yaw(kind: str, R_WO: np.ndarray) -> float | None:
    """World yaw (rad) of the footprint's major axis, or None if the
    footprint has no axis (round objects)."""
    from handle_drake.geometry.objects import ROTATED_CUBOID_YAW

    if CATALOGUE_PRIMITIVE.get(kind) != "box":
        return None
    yaw = math.atan2(R_WO[1, 0], R_WO[0, 0])
    return yaw + (ROTATED_CUBOID_YAW if kind == "rotated_cuboid" else 0.0)


def true_extent(spec, R_WO: np.ndarray | None = None) -> np.ndarray | None:
    """What a detection's ``extent`` should read for a catalogue object
    standing upright (m): the footprint's length and width (a box's two
    horizontal edges, longer first; a round object's diameter, a mug's cup
    without its handle) and the height. None for a mesh or an object not
    upright (``R_WO`` tilted)."""
    from handle_drake.geometry.objects import dimensions, total_height

    if spec.kind not in CATALOGUE_PRIMITIVE:
        return None
    if R_WO is not None and abs(float(np.asarray(R_WO)[2, 2]) - 1.0) > 1e-6:
        return None
    d = dimensions(spec)
    if CATALOGUE_PRIMITIVE[spec.kind] == "box":
        length, width = sorted((d["width"], d["depth"]), reverse=True)
    else:
        length = width = d["diameter"]
    return np.array([length, width, total_height(spec)])


def detection_error(detection: Detection, scenario) -> dict:
    """Errors of a detection against the scenario's object (its initial pose); with
    several objects (``objects:``), against the one nearest to it on the table:
    position (mm; ``xy_mm`` horizontal, ``z_mm``), yaw (deg, boxes),
    ``extent_mm`` (detected minus true length, width, height, mm; None for a
    mesh or a tilted object, see :func:`true_extent`) and whether the kind is
    right."""
    from handle_drake.scene.config import initial_pose, scene_objects, spec_of

    truth = [(o, initial_pose(o, scenario.table)) for _, o in scene_objects(scenario)]
    obj, X_WO = min(truth, key=lambda t: float(np.linalg.norm(
        t[1].translation()[:2] - detection.position[:2])))
    delta = detection.position - X_WO.translation()
    kind = obj.kind
    yaw_true = _true_yaw(kind, X_WO.rotation().matrix())
    yaw_error = None
    if yaw_true is not None and detection.kind == "box":
        # A rectangle's axis is defined modulo pi.
        yaw_error = math.degrees((detection.yaw - yaw_true + math.pi / 2) % math.pi
                                 - math.pi / 2)
    # A mesh (or an instrumented device) is no primitive: its detected kind
    # cannot be right or wrong (kind_expected and kind_ok are None).
    expected = CATALOGUE_PRIMITIVE.get(kind)
    extent = true_extent(spec_of(obj), X_WO.rotation().matrix())
    return {"position_mm": [round(float(v) * 1000, 2) for v in delta],
            "xy_mm": round(float(np.linalg.norm(delta[:2])) * 1000, 2),
            "z_mm": round(float(delta[2]) * 1000, 2),
            "yaw_deg": None if yaw_error is None else round(yaw_error, 2),
            "extent_mm": None if extent is None else
            [round(float(v) * 1000, 2) for v in np.asarray(detection.extent) - extent],
            "kind_expected": expected,
            "kind_ok": None if expected is None else detection.kind == expected}


def _report(views, scenario=None) -> dict:
    objects, tables, messages = [], [], []
    for view in views:
        if view.message:
            messages.append(view.message)
        if view.plane is not None:
            tables.append({"camera": view.camera,
                           "normal": [float(v) for v in view.plane.normal],
                           "height": float(view.plane.offset / max(view.plane.normal[2], 1e-9))})
        for detection in view.detections:
            entry = {"camera": view.camera, **detection.as_dict()}
            if scenario is not None and (scenario.object is not None or scenario.objects):
                entry["error"] = detection_error(detection, scenario)
            objects.append(entry)
    return {"objects": objects, "tables": tables, "messages": messages}


def _print_report(report: dict) -> None:
    for message in report["messages"]:
        print(message)
    for table in report["tables"]:
        tilt = math.degrees(math.acos(min(1.0, abs(table["normal"][2]))))
        print(f"camera {table['camera']}: table at z = {table['height']:.4f} m, "
              f"normal tilted {tilt:.2f} deg from vertical")
    for i, obj in enumerate(report["objects"]):
        p, e = obj["position"], obj["extent"]
        print(f"object {i} ({obj['camera']}): {obj['kind']} at "
              f"[{p[0]:+.4f}, {p[1]:+.4f}, {p[2]:+.4f}] m, extent "
              f"{e[0] * 1000:.0f} x {e[1] * 1000:.0f} x {e[2] * 1000:.0f} mm, "
              f"yaw {math.degrees(obj['yaw']):.1f} deg, "
              f"fit residual {obj['residual'] * 1000:.2f} mm")
        if "error" in obj:
            err = obj["error"]
            yaw = "n/a" if err["yaw_deg"] is None else f"{err['yaw_deg']:+.2f} deg"
            if err["kind_expected"] is None:
                kind = "n/a (the object is no primitive)"
            else:
                kind = (f"{'ok' if err['kind_ok'] else 'WRONG'} "
                        f"(expected {err['kind_expected']})")
            extent = ("n/a" if err["extent_mm"] is None else
                      " x ".join(f"{v:+.0f}" for v in err["extent_mm"]) + " mm")
            print(f"  error against the truth: xy {err['xy_mm']:.1f} mm, z {err['z_mm']:+.1f} mm, "
                  f"yaw {yaw}, extent {extent}, kind {kind}")
    if not report["objects"]:
        print("no object detected")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "perceive", help="render the scenario's depth cameras and detect objects on the table")
    p.add_argument("scenario", nargs="?", type=Path, default=None,
                   help="scenario YAML with cameras (see diagrams/tabletop_perception.yaml)")
    p.add_argument("--override", default=None, help="YAML text applied on top of the file")
    p.add_argument("--frame", type=Path, default=None,
                   help="a recorded frame's JSON sidecar instead of a scenario")
    p.add_argument("--json", action="store_true", help="print the detections as JSON")
    p.add_argument("--keep-robot", action="store_true",
                   help="keep the hand's pixels (by default its render labels are filtered out)")
    p.add_argument("--save-frames", type=Path, default=None,
                   help="write each camera's depth frame (16-bit PNG + JSON) to this directory")
    p.set_defaults(func=_cmd_perceive)


def _cmd_perceive(args) -> int:
    from handle_drake.scenario import LoadScenario

    if (args.scenario is None) == (args.frame is None):
        raise ValueError("give either a SCENARIO file or --frame FRAME.json (not both)")
    if args.save_frames is not None:
        if args.save_frames.exists() and not args.save_frames.is_dir():
            raise ValueError(f"--save-frames: {args.save_frames} exists and is not a directory")
        args.save_frames.mkdir(parents=True, exist_ok=True)
    scenario = None
    if args.frame is not None:
        if args.override is not None:
            raise ValueError("--override applies to a scenario, not to --frame")
        if args.keep_robot:
            raise ValueError("--keep-robot applies to a scenario's cameras, not to --frame")
        views = [perceive_frame(args.frame.stem, load_frame(args.frame))]
    else:
        scenario = LoadScenario(filename=args.scenario, data=args.override)
        views = render_views(scenario, exclude_robot=not args.keep_robot)
    if args.save_frames is not None:
        for view in views:
            save_frame(args.save_frames / view.camera, view.frame)
    report = _report(views, scenario)
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        _print_report(report)
    return 0
