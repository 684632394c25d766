"""``handle-drake pick``: perceive the table, pick one object, put it in its hole.

``handle-drake pick SCENARIO [--scene-seed N] [--object N | --kind K] --place box
[--true-poses] [--html PATH] [--json]``

The scenario needs an ``!Arm`` mount, a ``sorting_box`` and (unless
``--true-poses``) a camera. ``--scene-seed N`` replaces its objects with a
seeded random scene of 2-5 (:mod:`handle_drake.apps.pick.scenes`). The objects are
perceived (the first camera that sees the table; ``--true-poses``: the
scenario's own poses) and listed nearest to the arm's base first; ``--object
N`` picks the N-th, ``--kind K`` the first of kind K, else the first of a kind the
sorting box has a hole for (every catalogue kind standing upright and a user's mesh:
:data:`PICKABLE`; the kind as perceived, :func:`seen_kind`). The plan (:func:`plan_pick`) is
made on what was perceived: the objects as detected are the obstacles of the
arm's IK. The run is simulated. A line is printed as each phase ends
(perceive, plan, approach, close, lift, carry, release) with its time (the
simulated phases: simulated and wall-clock seconds); the last line says "in the
box" or why not, whole. Exit status: 0 in the box; 1 an attempt that failed (the
object was grasped at and not put in); 2 bad input (one line on stderr); 3
nothing to attempt: no object seen, none of a pickable kind, or no grasp class
with a reachable, collision-free pick.
"""

from __future__ import annotations

import dataclasses as dc
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from handle_drake.base.arguments import seed_int

__all__ = ["register", "perceived_objects", "choose_target", "EXIT_CODES", "exit_code"]

#: The catalogue kind the planner is given for each detected primitive.
DETECTED_KIND = {"sphere": "sphere", "box": "cuboid", "cylinder": "cylinder"}
PICKABLE = ("sphere", "cuboid", "cylinder", "rotated_cuboid", "mug", "wine_glass",
            "star_prism", "mesh")
#: ``pick``'s result ``status`` -> the command's exit status (2 is bad input, raised
#: before any work as a ValueError).
EXIT_CODES = {"in_box": 0, "failed": 1, "nothing_to_pick": 3}


def register(subparsers) -> None:
    p = subparsers.add_parser("pick", help="perceive, pick an object with the arm and hand, "
                                           "put it in the sorting box")
    p.add_argument("scenario", type=Path, help="scenario YAML with an !Arm mount and a "
                                               "sorting_box (diagrams/hamburg_setup.yaml)")
    p.add_argument("--override", default=None, help="YAML text applied on top of the file")
    p.add_argument("--scene-seed", type=seed_int, default=None, metavar="N",
                   help="replace the objects with a seeded random scene of 2-5")
    p.add_argument("--scene-kinds", default="sphere,cuboid", metavar="K,K|all",
                   help="with --scene-seed: the kinds drawn (default sphere,cuboid; 'all': "
                        "every kind the sorting box has a hole for)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--object", type=int, default=None, metavar="N",
                       help="pick the N-th object (0 = nearest to the arm)")
    which.add_argument("--kind", default=None, choices=PICKABLE,
                       help="pick the nearest object of this kind")
    p.add_argument("--place", default="box", choices=("box",),
                   help="where to put it (the sorting box's hole for its kind)")
    p.add_argument("--true-poses", action="store_true",
                   help="plan on the scenario's true object poses instead of perceiving")
    p.add_argument("--scripted-close", action="store_true",
                   help="close the hand with the open-loop ramp to the planned closing "
                        "command instead of the reactive tactile close")
    p.add_argument("--no-release-correction", action="store_true",
                   help="release where the plan put the object in the hand, without "
                        "measuring it there after the lift")
    p.add_argument("--html", type=Path, default=None, help="save a self-contained HTML replay")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--grasp-db", type=Path, default=None, metavar="PATH",
                   help="grasp database to plan with (default: the shipped one, "
                        "handle_drake/apps/pick/data/grasp_database.json)")
    p.add_argument("--build-grasp-db", action="store_true",
                   help="compute the grasp database for the scenario's sorting-box objects "
                        "(every grasp class of pick's class order) into --grasp-db or the "
                        "shipped file, and exit; entries it holds are kept unless --rebuild")
    p.add_argument("--rebuild", action="store_true",
                   help="with --build-grasp-db: recompute every entry")
    p.set_defaults(func=_cmd_pick)


def perceived_objects(scenario):
    """``(objects, message)``: ObjectConfigs as perceived by the first camera that
    sees the table (kind from the detected primitive, size and pose from
    :func:`handle_drake.apps.perception.grasping.planner_input`)."""
    from pydrake.common.schema import Transform

    from handle_drake.apps.perception.grasping import planner_input
    from handle_drake.apps.perception.perceive import render_views
    from handle_drake.scenario import ObjectConfig

    views = render_views(scenario)
    view = next((v for v in views if v.plane is not None), None)
    if view is None:
        return [], "; ".join(v.message for v in views) or "no camera sees the table"
    table = scenario.table.top_height if scenario.table is not None else 0.0
    out = []
    for d in view.detections:
        kind = seen_kind(scenario, d)
        if kind in ("sphere", "cuboid"):
            size, X_WO = planner_input(kind, d, table)
            out.append(ObjectConfig(kind=kind, size=size, X_WO=Transform(X_WO), on_table=False,
                                    fixed=True))
        elif kind in PICKABLE:  # standing upright where seen, turned as seen
            out.append(_upright(scenario, kind, d, table))
        else:  # an obstacle only: a cylinder of the detected extent
            diameter, height = float(d.extent[0]), float(d.extent[2])
            X = Transform(translation=[float(v) for v in d.position])
            out.append(ObjectConfig(kind="cylinder", size=diameter,
                                    dimensions={"height": height}, X_WO=X, on_table=False,
                                    fixed=True))
    return out, view.message


#: A round detection is the sorting box's user mesh when its height and its footprint's
#: half length are this close (m) to the mesh's (and not to the kind it was told as).
MESH_MATCH = 0.006


def seen_kind(scenario, detection) -> str:
    """The catalogue kind of a detection: the detector's shape
    (:func:`handle_drake.geometry.detect.round_shape`: sphere, cuboid, cylinder, mug,
    wine glass, star prism), or ``mesh`` when the sorting box has a mesh hole and a round
    or box detection has that mesh's height and footprint (``MESH_MATCH``) but not its
    own kind's catalogue object's (the object of its hole, or of the default size)."""
    from handle_drake.geometry.objects import DEFAULT_SIZE, ObjectSpec, total_height
    from handle_drake.scene.config import footprint_radius, hole_spec

    kind = detection.shape or DETECTED_KIND[detection.kind]
    box = scenario.sorting_box
    meshes = [h for h in (box.holes if box is not None else []) if h.kind == "mesh"]
    if not meshes or kind == "sphere":
        return kind
    height, half = float(detection.extent[2]), float(detection.extent[0]) / 2

    def matches(spec):
        return (abs(total_height(spec) - height) < MESH_MATCH
                and abs(footprint_radius(spec) - half) < MESH_MATCH)

    sizes = [h.size for h in box.holes if h.kind == kind and h.size] or [DEFAULT_SIZE[kind]]
    if matches(hole_spec(meshes[0])) and not any(
            matches(ObjectSpec(kind=kind, size=s)) for s in sizes):
        return "mesh"
    return kind


def _upright(scenario, kind, detection, table):
    """The ObjectConfig of an upright ``kind`` seen as ``detection``: its shape's size
    (a mesh: the box's), resting on the table at the detected xy, turned by its shape's
    yaw (a mesh: the footprint's major axis)."""
    from pydrake.common.schema import Transform
    from pydrake.math import RigidTransform, RotationMatrix

    from handle_drake.geometry.objects import ObjectSpec, resting_height
    from handle_drake.scenario import ObjectConfig
    from handle_drake.scene.config import hole_spec

    if kind == "mesh":
        hole = next(h for h in scenario.sorting_box.holes if h.kind == "mesh")
        spec, size, yaw = hole_spec(hole), 0.05, float(detection.yaw)
        extra = dict(file=hole.file, scale=hole.scale)
    else:
        size, yaw = float(detection.shape_size), float(detection.shape_yaw)
        spec, extra = ObjectSpec(kind=kind, size=size), {}
    p = [float(detection.position[0]), float(detection.position[1]),
         table + resting_height(spec)]
    X = RigidTransform(RotationMatrix.MakeZRotation(yaw), p)
    return ObjectConfig(kind=kind, size=size, X_WO=Transform(X), on_table=False, fixed=True,
                        **extra)


def choose_target(objects, base_xy, index=None, kind=None, pickable=PICKABLE) -> int:
    """Index (into ``objects``) of the object to pick; see the module doc. ``pickable``:
    the kinds taken without ``--kind`` (those the sorting box has a hole for)."""
    order = sorted(range(len(objects)), key=lambda i: math.dist(
        np.asarray(objects[i].X_WO.translation[:2], dtype=float), base_xy))
    if index is not None:
        if not 0 <= index < len(order):
            raise ValueError(f"--object: {index} is not one of the {len(order)} objects "
                             f"(0 to {len(order) - 1})")
        return order[index]
    for i in order:
        if objects[i].kind == kind if kind else objects[i].kind in pickable:
            return i
    raise LookupError(f"no {kind or 'pickable'} object on the table (found "
                      f"{[objects[i].kind for i in order]})")


def exit_code(result: dict) -> int:
    """The command's exit status for a :func:`pick` result (:data:`EXIT_CODES`)."""
    return EXIT_CODES[result["status"]]


def pick(scenario, true_poses: bool = False, index=None, kind=None, html=None,
         grasp_db=None, execute: bool = True, close: str = "reactive",
         correct_release: bool = True, progress=None, monitor=None) -> dict:
    """Perceive (or read the truth), plan and execute one pick; returns the result.
    ``grasp_db``: a GraspDatabase (default: the shipped one); ``execute=False``
    stops after planning; ``close``: "reactive" or "scripted", ``correct_release``:
    measure the object in the hand after the lift and release it where it is
    (``execute_pick``); ``progress(line)``, if given, is called with a line as each
    phase ends; ``monitor``: ``execute_pick``'s. The result's ``status`` is one of
    :data:`EXIT_CODES` ("in_box", "failed": attempted and not in the box,
    "nothing_to_pick": nothing seen, nothing pickable, no reachable pick; a plan
    made with ``execute=False`` counts as "failed"), ``phases`` the list of
    ``{phase, wall_s[, sim_s], note}``."""
    phases = []
    report = _phase_reporter(phases, progress)
    # Loaded here, before any phase is timed (the plan and execute steps use them).
    import handle_drake.apps.pick.execute  # noqa: F401
    import handle_drake.apps.pick.plan  # noqa: F401
    from handle_drake.apps.pick.reach import ArmReach
    from handle_drake.scene.config import scene_objects

    base_xy = scenario.hand.mount.X_WB.GetDeterministicValue().translation()[:2]
    truth = scene_objects(scenario)
    seen, message = _perceive(scenario, true_poses, truth, report)
    result = {"perceived": not true_poses, "objects_seen": len(seen),
              "objects_true": len(truth), "message": message, "phases": phases}
    if not seen:
        result.update(status="nothing_to_pick",
                      outcome=f"not in the box: nothing to pick ({message})")
        return result
    try:
        holes = {h.kind for h in scenario.sorting_box.holes}
        i = choose_target(seen, base_xy, index, kind, [k for k in PICKABLE if k in holes])
    except LookupError as error:
        result.update(status="nothing_to_pick", outcome=f"not in the box: {error}")
        return result
    target = seen[i]
    p_seen = np.asarray(target.X_WO.translation, dtype=float)
    # The judge (not the plan) names the true object the detection stands for.
    true_name, true_object = min(truth, key=lambda t: math.dist(
        np.asarray(t[1].X_WO.translation[:2], dtype=float), p_seen[:2]))
    world = dc.replace(scenario, object=seen[0], objects=seen[1:])
    seen_name = "object" if i == 0 else f"object_{i}"
    start = time.perf_counter()
    reach = ArmReach(world, ignore=(seen_name,))
    result["reach_model_s"] = time.perf_counter() - start
    result.update(target=true_name, kind=target.kind, true_kind=true_object.kind,
                  planned_xy=p_seen[:2].round(4).tolist())
    plan = _plan(scenario, world, reach, target, seen_name, true_name, grasp_db, start,
                 report, result)
    if plan is None:
        return result
    if not execute:
        result.update(status="failed", outcome="planned (not executed)")
        return result
    _execute(scenario, dc.replace(plan, target=true_name), reach, html, close,
             correct_release, monitor, report, result)
    return result


def _phase_reporter(phases: list, progress):
    """``report(phase, wall, note, sim=None)``: appends the phase's entry to ``phases``
    and, if ``progress`` is given, calls it with the phase's line (:func:`pick`)."""

    def report(phase, wall, note, sim=None):
        entry = {"phase": phase, "wall_s": round(float(wall), 3), "note": note}
        timing = f"{wall:6.2f} s"
        if sim is not None:
            entry["sim_s"] = round(float(sim), 3)
            timing = f"{sim:5.2f} s simulated in {wall:6.2f} s"
        phases.append(entry)
        if progress is not None:
            progress(f"{phase:9s} {timing}  {note}")

    return report


def _perceive(scenario, true_poses: bool, truth, report):
    """The perceive phase: ``(seen, message)``, the objects as perceived (with
    ``true_poses``: the scenario's own ``truth``, fixed where they rest)."""
    start = time.perf_counter()
    if true_poses:
        from handle_drake.scene.config import initial_pose

        seen = [dc.replace(o, X_WO=_transform(initial_pose(o, scenario.table)), on_table=False,
                           fixed=True) for _, o in truth]
        message = ""
    else:
        seen, message = perceived_objects(scenario)
    report("perceive", time.perf_counter() - start,
           ("true poses: " if true_poses else "seen: ") + (", ".join(
               f"{o.kind} {100 * o.size:.1f} cm" for o in seen) or "nothing"))
    return seen, message


def _plan(scenario, world, reach, target, seen_name, true_name, grasp_db, start, report,
          result):
    """The plan phase (timed from ``start``, before the arm's reach model was built):
    :func:`plan_pick` of ``target`` (``seen_name`` in ``world``, the scene as
    perceived), its figures put in ``result``; None when no pick is reachable
    (``result`` then says why)."""
    from handle_drake.apps.pick.plan import PickPlanningError, plan_pick

    try:
        plan = plan_pick(world, reach, seen_name, target.kind, target.size,
                         target.X_WO.GetDeterministicValue(),
                         np.asarray(scenario.hand.mount.initial_position or np.zeros(6)),
                         grasp_db=grasp_db)
    except PickPlanningError as error:
        from handle_drake.apps.pick.checks import named_as_truth

        report("plan", time.perf_counter() - start, "no reachable pick")
        result.update(status="nothing_to_pick",
                      outcome=f"not in the box: {named_as_truth(error, seen_name, true_name)}")
        return None
    planning = time.perf_counter() - start
    result.update(grasp_class=plan.grasp_class, planning_s=dict(plan.seconds),
                  ik_solves=plan.ik_solves,
                  planned_size=plan.grasp.object_spec.size, grasp_stored=plan.grasp_stored,
                  grasp_source=plan.grasp_source,
                  grasp_log=[[c, src, round(t, 4)] for c, src, t in plan.grasp_log],
                  attempts=dict(plan.attempts))
    report("plan", planning, f"{target.kind} {100 * plan.grasp.object_spec.size:.1f} cm: "
           f"{plan.grasp_class} ({plan.grasp_source} grasp; grasp {plan.seconds['grasp']:.2f}"
           f" s, arm IK {plan.seconds['ik']:.2f} s, paths {plan.seconds['path']:.2f} s)")
    return plan


def _execute(scenario, plan, reach, html, close, correct_release, monitor, report, result):
    """The simulated phases (:func:`execute_pick` of ``plan``, named as the truth), their
    outcome put in ``result``."""
    from handle_drake.apps.pick.execute import execute_pick

    outcome = execute_pick(scenario, plan, html=html,
                           close=close, reach=reach if correct_release else None,
                           monitor=monitor,
                           progress=lambda phase, sim, wall, note: report(phase, wall, note,
                                                                          sim))
    result.update(close=close, release_corrected=outcome.release_corrected,
                  in_hand_offset_mm=outcome.in_hand_offset_mm,
                  in_hand_turn_deg=outcome.in_hand_turn_deg,
                  in_hand_contacts=outcome.in_hand_contacts,
                  in_hand_error_mm=outcome.in_hand_error_mm,
                  in_hand_error_deg=outcome.in_hand_error_deg,
                  release_offset_mm=outcome.release_offset_mm,
                  release_tilt_deg=outcome.release_tilt_deg,
                  release_height_mm=outcome.release_height_mm)
    if outcome.close_mode is not None:
        result.update(close_mode=outcome.close_mode, fingers_touched=outcome.fingers_touched,
                      closing_at_squeeze=outcome.closing_at_squeeze)
    result.update(status="in_box" if outcome.in_box else "failed",
                  outcome=outcome.reason, in_box=outcome.in_box,
                  final_position=outcome.p_WO_final.round(4).tolist(),
                  sim_s=outcome.sim_seconds, wall_s=outcome.wall_seconds)


def _transform(X):
    from pydrake.common.schema import Transform

    return Transform(X)


def _cmd_pick(args) -> int:
    from handle_drake.devices.arm.config import Arm
    from handle_drake.scenario import LoadScenario

    scenario = LoadScenario(filename=args.scenario, data=args.override)
    if not isinstance(scenario.hand.mount, Arm):
        raise ValueError("pick: the scenario's hand.mount must be an !Arm "
                         "(see diagrams/hamburg_setup.yaml)")
    if scenario.sorting_box is None:
        raise ValueError("--place box: the scenario has no sorting_box")
    if not args.true_poses and not scenario.cameras:
        raise ValueError("pick: the scenario has no camera to perceive with; add one or "
                         "give --true-poses")
    from handle_drake.apps.pick.checks import check_pick_arguments

    check_pick_arguments(args, scenario)  # every refusal before any work
    from handle_drake.apps.pick.plan import GRASP_DB, build_grasp_database
    from handle_drake.grasp.database import GraspDatabase

    if args.build_grasp_db:
        path = args.grasp_db or GRASP_DB
        database = build_grasp_database(scenario, path, rebuild=args.rebuild)
        print(f"grasp database: {len(database)} entries "
              f"({sum(g is not None for g in database.entries.values())} with a grasp) "
              f"written to {path}")
        return 0
    if args.rebuild:
        raise ValueError("--rebuild: only with --build-grasp-db")
    grasp_db = GraspDatabase.load(args.grasp_db) if args.grasp_db is not None else None
    if grasp_db is not None and grasp_db.stale:
        print(f"grasp database {args.grasp_db}: {len(grasp_db.stale)} entries of another "
              f"planner version ignored (searched afresh; rebuild with --build-grasp-db)")
    if args.scene_seed is not None:
        if args.scene_seed < 0:
            raise ValueError(f"--scene-seed: expected an integer >= 0, got {args.scene_seed}")
        from handle_drake.apps.pick.scenes import random_scene, scene_kinds

        scenario = random_scene(scenario, args.scene_seed, scene_kinds(args.scene_kinds))
    # One line per phase as it ends: on stdout, or on stderr under --json (whose stdout
    # is the JSON and the verdict).
    stream = sys.stderr if args.json else sys.stdout
    result = pick(scenario, args.true_poses, args.object, args.kind, args.html,
                  grasp_db=grasp_db, close="scripted" if args.scripted_close else "reactive",
                  correct_release=not args.no_release_correction,
                  progress=lambda line: print(line, file=stream, flush=True))
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for key in ("objects_seen", "target", "kind", "grasp_class"):
            if key in result:
                print(f"{key}: {result[key]}")
        if "sim_s" in result:
            print(f"simulated {result['sim_s']:.1f} s in {result['wall_s']:.1f} s "
                  f"({result['sim_s'] / result['wall_s']:.2f}x real time)")
        if args.html:
            print(f"replay written to {args.html}")
    print(result["outcome"])
    return exit_code(result)
