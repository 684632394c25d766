"""What ``handle-drake pick`` refuses before any work (issue 46), in one place.

:func:`check_pick_arguments` runs after the scenario is loaded (its own checks:
finite, bounded numbers) and before perception, planning or a grasp search. Each
refusal is a ``ValueError`` naming the option or the scenario field: exit 2, nothing
written. A scene the planner cannot work in ends otherwise after seconds to minutes
in "no IK ..." (an arm base inside the table or metres below it, an object off the
table, a box that floats), in a ``KeyError`` (a target whose kind has no hole) or in
a size error of another hand's joints.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from handle_drake.apps.pick.plan import GRASP_DB
from handle_drake.apps.pick.scenes import scene_kinds
from handle_drake.base.paths import check_output
from handle_drake.devices.arm.model import ARM_SPECS
from handle_drake.scene.config import box_pose, scene_objects

__all__ = ["check_pick_arguments", "check_pick_scene", "named_as_truth", "PICK_HANDS"]

#: The hands the pick planner has grasps for (its grasp database and postures are the
#: Shadow hand's 24 joints).
PICK_HANDS = ("shadow",)
#: A box on the table (``on_table: false``) must stand this close to its top (m).
BOX_ON_TOP = 0.005


def check_pick_arguments(args, scenario) -> None:
    """Refuses what ``pick`` cannot do with ``args`` on ``scenario`` (module doc)."""
    if args.html is not None and Path(args.html).suffix.lower() != ".html":
        raise ValueError(f"--html: expected a .html file name, got {str(args.html)!r}")
    kind = scenario.hand.kind
    if kind not in PICK_HANDS:
        raise ValueError(f"hand.kind: pick plans grasps for the {' or '.join(PICK_HANDS)} "
                         f"hand only, got {kind!r}")
    if getattr(args, "scene_kinds", "sphere,cuboid") != "sphere,cuboid":
        if args.scene_seed is None:
            raise ValueError("--scene-kinds: only with --scene-seed (it names the kinds a "
                             "seeded scene draws)")
        scene_kinds(args.scene_kinds)
    box = scenario.sorting_box
    if args.kind is not None and box is not None:
        holes = [h.kind for h in box.holes if h.size or h.kind == "mesh"]
        if args.kind not in holes:
            raise ValueError(f"--kind {args.kind}: the sorting box has no hole for a "
                             f"{args.kind} (sorting_box.holes: {holes})")
    if args.build_grasp_db:
        check_output("--grasp-db" if args.grasp_db else "--build-grasp-db (the shipped "
                     "grasp database)", args.grasp_db or GRASP_DB)
    check_pick_scene(scenario)


def check_pick_scene(scenario) -> None:
    """The arm can reach the table from outside it, every object stands on the table,
    and the sorting box stands on it."""
    table = scenario.table
    if table is None:
        raise ValueError("table: pick needs the table the objects stand on")
    half = np.array([table.size_x, table.size_y]) / 2
    top = table.top_height
    mount = scenario.hand.mount
    p = np.asarray(mount.X_WB.GetDeterministicValue().translation(), dtype=float)
    if np.all(np.abs(p[:2]) < half) and p[2] < top:
        raise ValueError(f"hand.mount.X_WB: the arm's base at {p.round(3).tolist()} is inside "
                         f"the table ({table.size_x:g} x {table.size_y:g} m, top at {top:g} m)")
    reach = sum(ARM_SPECS[mount.kind].lengths) if ARM_SPECS[mount.kind].lengths else 1.5
    nearest = np.append(np.clip(p[:2], -half, half), top)
    if math.dist(p, nearest) > reach:
        raise ValueError(f"hand.mount.X_WB: the arm's base at {p.round(3).tolist()} is "
                         f"{math.dist(p, nearest):.2f} m from the table top, beyond the "
                         f"{mount.kind}'s reach of {reach:.2f} m")
    for name, o in scene_objects(scenario):
        xy = np.asarray(o.X_WO.GetDeterministicValue().translation()[:2], dtype=float)
        if not np.all(np.abs(xy) <= half):
            field = "object" if name == "object" else f"objects[{int(name.split('_')[1]) - 1}]"
            raise ValueError(f"{field}.X_WO: {name} at {xy.round(3).tolist()} is off the "
                             f"{table.size_x:g} x {table.size_y:g} m table")
    box = scenario.sorting_box
    if box is not None:
        q = box_pose(scenario).translation()
        if not np.all(np.abs(q[:2]) <= half):
            raise ValueError(f"sorting_box.X_WB: the box at {q[:2].round(3).tolist()} is off "
                             f"the {table.size_x:g} x {table.size_y:g} m table")
        if abs(q[2] - top) > BOX_ON_TOP:
            raise ValueError(f"sorting_box.X_WB: the box's bottom at z = {q[2]:g} m is not on "
                             f"the table top ({top:g} m); give on_table: true")


def named_as_truth(error, seen_name: str, true_name: str) -> str:
    """A planner's reason (it begins with the planning world's name of the target,
    ``seen_name``: the perceived objects' order) under the name the result reports,
    ``true_name`` (the true object the detection stands for), so that the target and the
    reason name the same object."""
    text = str(error)
    if seen_name != true_name and text.startswith(seen_name) \
            and text[len(seen_name):len(seen_name) + 1] in (":", " "):
        return f"{true_name} (perceived as {seen_name}){text[len(seen_name):]}"
    return text
