"""Where the picked object is in the hand, located after the lift (issue 49 item 5, issue
47): from the hand's senses (``--locate taxels``: taxels, hand joints, arm joints; the
pick's default) or from the simulator's contact points (``--locate contacts``: the
points and normals the plant reports, the former method), against the plant's pose of
the object (read here only); and whether the release planned from it put the object in
the box.

Each ``--scenes`` entry ``SEED:KIND`` is a development scene (``random_scene``; never
the evaluation seeds) picked from the true poses (the planner's prior is the planned
grasp) through :func:`handle_drake.apps.pick.cli.pick`, the nearest object of ``KIND``.
Errors: position (mm) and angle (deg, a cuboid's smallest over its 180 degree
symmetries; a sphere's is not scored) of the located and of the planned pose in the
hand base frame. Prints the table, writes JSON and the page section (one per
``--locate``).

Run: python benchmarks/bench_pick_touch.py [--scenes 0:sphere,4:cuboid] [--locate taxels]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.math import RotationMatrix

from handle_drake.base.results import ResultsRun, add_page_arguments

ROOT = Path(__file__).resolve().parents[1]
SCENES = "0:sphere,2:sphere,0:cuboid,4:cuboid,5:cuboid,6:cuboid"
SYMMETRY = [RotationMatrix(), RotationMatrix.MakeXRotation(np.pi),
            RotationMatrix.MakeYRotation(np.pi), RotationMatrix.MakeZRotation(np.pi)]


def _scenes(text: str) -> list[tuple[int, str]]:
    from handle_drake.apps.pick.scenes import EVALUATION_SEEDS

    out = []
    for part in filter(None, text.split(",")):
        seed, _, kind = part.partition(":")
        if not seed.strip().isdigit() or kind not in ("sphere", "cuboid"):
            raise SystemExit(f"--scenes: expected SEED:KIND (sphere or cuboid), got {part!r}")
        if int(seed) in EVALUATION_SEEDS:
            raise SystemExit(f"--scenes: {seed} is an evaluation seed (nothing is measured "
                             "for tuning on them)")
        out.append((int(seed), kind))
    return out


def _errors(X_BO, truth, kind):
    position = float(np.linalg.norm(X_BO.translation() - truth.translation())) * 1e3
    if kind == "sphere":
        return round(position, 1), None
    R = truth.rotation().inverse() @ X_BO.rotation()
    angle = min(abs((R @ S).ToAngleAxis().angle()) for S in SYMMETRY)
    return round(position, 1), round(float(np.degrees(angle)), 1)


def _truth(plant, context, target_instance=None):
    """``X_BO`` of the object in the hand base frame from the plant (the target, or the
    object nearest the palm)."""
    from handle_drake.base.hands import get_hand_spec

    hand = plant.GetModelInstanceByName("hand")
    X_WB = plant.GetBodyByName(get_hand_spec("shadow").base_body, hand).EvalPoseInWorld(
        context)
    if target_instance is None:
        palm = plant.GetBodyByName("palm", hand).EvalPoseInWorld(context).translation()
        from pydrake.multibody.tree import ModelInstanceIndex

        instances = [ModelInstanceIndex(i) for i in range(plant.num_model_instances())
                     if plant.GetModelInstanceName(ModelInstanceIndex(i)).startswith("object")]
        target_instance = min(instances, key=lambda i: np.linalg.norm(
            plant.get_body(plant.GetBodyIndices(i)[0]).EvalPoseInWorld(context).translation()
            - palm))
    body = plant.get_body(plant.GetBodyIndices(target_instance)[0])
    return X_WB.inverse() @ body.EvalPoseInWorld(context)


def _spy(locate: str, record: dict):
    """Wraps the pick's locating step so that it also records the errors."""
    from handle_drake.apps.pick import execute
    from handle_drake.station import GetPlant

    if locate == "taxels":
        original = execute.locate_by_touch

        def by_touch(station, root_context, scenario, spec, X_OB_planned):
            found = original(station, root_context, scenario, spec, X_OB_planned)
            plant = GetPlant(station)
            truth = _truth(plant, plant.GetMyContextFromRoot(root_context))
            record.update(kind=spec.kind, contacts=found[1] if found else 0,
                          planned=_errors(X_OB_planned.inverse(), truth, spec.kind),
                          located=_errors(found[0].inverse(), truth, spec.kind)
                          if found else None)
            return found

        execute.locate_by_touch = by_touch
        return
    original = execute.measure_in_hand
    execute.with_taxels = lambda scenario: scenario  # the station without taxels

    def by_contacts(plant, context, contacts, target, hand, base_body, spec, X_OB_planned):
        found = original(plant, context, contacts, target, hand, base_body, spec, X_OB_planned)
        truth = _truth(plant, context, target)
        record.update(kind=spec.kind, contacts=found[1] if found else 0,
                      planned=_errors(X_OB_planned.inverse(), truth, spec.kind),
                      located=_errors(found[0].inverse(), truth, spec.kind) if found else None)
        return found

    execute.measure_in_hand = by_contacts


def _row(seed, kind, result, record):
    located = record.get("located")
    within = None if located is None else (
        located[0] <= 10 and (located[1] is None or located[1] <= 10))
    return {"scene": f"{seed}:{kind}", "grasp": result.get("grasp_class"),
            "contacts": record.get("contacts", 0),
            "planned (mm, deg)": record.get("planned"),
            "located (mm, deg)": located,
            "within 10 mm, 10 deg": {None: "n/a", True: "yes", False: "no"}[within],
            "release re-planned": bool(result.get("release_corrected")),
            "in the box": bool(result.get("in_box"))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=SCENES, help="SEED:KIND,... (development seeds)")
    parser.add_argument("--locate", default="taxels", choices=("taxels", "contacts"))
    add_page_arguments(parser, "sensing", published={"scenes": 6})
    args = parser.parse_args(argv)
    scenes = _scenes(args.scenes)
    from handle_drake.apps.pick import cli
    from handle_drake.apps.pick.scenes import random_scene
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    run = ResultsRun(f"The object in the hand after the pick's lift, located from "
                     f"{'touch' if args.locate == 'taxels' else 'the simulator contacts'}",
                     args, section=args.locate)
    record: dict = {}
    _spy(args.locate, record)
    base = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    rows = []
    for seed, kind in scenes:
        record.clear()
        start = time.perf_counter()
        result = cli.pick(random_scene(base, seed), true_poses=True, kind=kind)
        rows.append(_row(seed, kind, result, record))
        print(rows[-1], f"{time.perf_counter() - start:.0f} s", flush=True)
    located = [r for r in rows if r["within 10 mm, 10 deg"] != "n/a"]
    notes = [f"Within 10 mm and 10 deg: {sum(r['within 10 mm, 10 deg'] == 'yes' for r in located)}"
             f"/{len(located)} located; in the box {sum(r['in the box'] for r in rows)}"
             f"/{len(rows)}."]
    run.finish(rows, {"rows": rows, "locate": args.locate},
               json_path=ROOT / "benchmarks" / "results" / f"pick_touch_{args.locate}.json",
               notes=notes)
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
