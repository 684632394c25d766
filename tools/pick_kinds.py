"""The shape sorter's block per kind (issue 49 item 1): picks of each kind on held-out
sorter scenes, each judged from the plant's final state by separate code
(``tests/pick/pick_judge.py``: every collision point in the box's cavity, at rest).
A measurement tool (the table of docs/results/pick.md, "Every kind through its own hole").

Run: ``python tools/pick_kinds.py [--perceived] [--pairs 700:cylinder,...]``: for each
``seed:kind`` the scene ``random_scene(diagrams/sorter_setup.yaml, seed, SORTER_KINDS)``
and a pick of the nearest object of that kind (``--perceived``: as the camera tells it;
a rotated cuboid is told as a cuboid, the same solid, and asked for as one); one JSON
line per pick (``RESULT {...}``) on stdout. The default pairs are, per kind, the first two
of the held-out ``SORTER_SEEDS`` (700-711) whose scene holds that kind. A pick takes
20-50 s on a quiet machine (70-220 s under load 7).

``--shapes 300-329``: the kinds perception tells instead (no pick): perception's seeded
tables (:func:`handle_drake.apps.perception.scenes.random_scene`, Kinect v1), each true
object's nearest detection (within 5 cm): the shape told, its size error (mm) and, for a
star prism or a mug, the yaw error (deg; a star's modulo 72 deg); one ``SHAPES {...}`` line.
The shape rules and the size biases were set on seeds 100-119.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "pick"))

from pick_judge import FinalState, judge_in_box  # noqa: E402

from handle_drake.apps.pick import execute  # noqa: E402
from handle_drake.apps.pick.cli import pick  # noqa: E402
from handle_drake.apps.pick.scenes import SORTER_KINDS, SORTER_SEEDS, random_scene  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402

SORTER = ROOT / "diagrams" / "sorter_setup.yaml"


def default_pairs(scenario) -> list[tuple[int, str]]:
    """Per kind, the first two held-out seeds whose scene holds it."""
    out = []
    for kind in SORTER_KINDS:
        seeds = [s for s in SORTER_SEEDS if kind in {
            o.kind for o in [random_scene(scenario, s, SORTER_KINDS).object,
                             *random_scene(scenario, s, SORTER_KINDS).objects]}]
        out += [(s, kind) for s in seeds[:2]]
    return out


def one_pick(scenario, seed: int, kind: str, perceived: bool) -> dict:
    """One pick of ``kind`` in scene ``seed``, its verdict and the plant judge's."""
    scene = random_scene(scenario, seed, SORTER_KINDS)
    final, runs = FinalState(), []
    run = execute.execute_pick

    def watched(scenario, plan, **kwargs):
        runs.append((scenario, plan.target))
        return run(scenario, plan, **dict(kwargs, monitor=final))

    execute.execute_pick = watched
    try:
        start = time.perf_counter()
        asked = "cuboid" if perceived and kind == "rotated_cuboid" else kind
        r = pick(scene, true_poses=not perceived, kind=asked)
    finally:
        execute.execute_pick = run
    verdict = judge_in_box(*runs[0], final.x) if runs else None
    return dict(seed=seed, kind=kind, perceived=perceived, status=r["status"],
                true_kind=r.get("true_kind"), seen_kind=r.get("kind"),
                grasp=r.get("grasp_class"), source=r.get("grasp_source"),
                outcome=r["outcome"], planning_s=r.get("planning_s"),
                judge=verdict and {k: verdict[k] for k in ("in_cavity", "at_rest", "outside")},
                wall_s=round(time.perf_counter() - start, 1))


def shapes(seeds) -> dict:
    """The confusion of true kind -> shape told, and the size and yaw errors per kind."""
    import collections
    import math

    import numpy as np

    from handle_drake.apps.perception.scenes import TabletopScene
    from handle_drake.apps.perception.scenes import random_scene as table_scene
    from handle_drake.geometry.detect import detect

    told, size, yaw = collections.Counter(), collections.defaultdict(list), \
        collections.defaultdict(list)
    for seed in seeds:
        objects = table_scene(seed)
        detections = detect(TabletopScene(objects, seed=seed).frame())
        for o in objects:
            near = min(detections, default=None,
                       key=lambda d: np.linalg.norm(d.position[:2] - o.xy))
            if near is None or np.linalg.norm(near.position[:2] - o.xy) > 0.05:
                told[f"{o.kind}->missed"] += 1
                continue
            told[f"{o.kind}->{near.shape}"] += 1
            if near.shape != o.kind:
                continue
            size[o.kind].append(round((near.shape_size - o.size) * 1000, 1))
            period = {"star_prism": 2 * math.pi / 5, "mug": 2 * math.pi}.get(o.kind)
            if period:
                e = (near.shape_yaw - o.yaw + period / 2) % period - period / 2
                yaw[o.kind].append(round(math.degrees(e), 1))
    return {"seeds": [min(seeds), max(seeds)], "told": dict(sorted(told.items())),
            "size_error_mm": dict(size), "yaw_error_deg": dict(yaw)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--perceived", action="store_true")
    parser.add_argument("--pairs", default=None, help="seed:kind,... (default: see doc)")
    parser.add_argument("--shapes", default=None, metavar="A-B",
                        help="perception's kinds on its seeded tables A..B (no pick)")
    args = parser.parse_args(argv)
    if args.shapes is not None:
        a, b = (int(v) for v in args.shapes.split("-"))
        print("SHAPES", json.dumps(shapes(range(a, b + 1))), flush=True)
        return 0
    scenario = LoadScenario(filename=SORTER)
    pairs = default_pairs(scenario) if args.pairs is None else [
        (int(p.split(":")[0]), p.split(":")[1]) for p in args.pairs.split(",")]
    for seed, kind in pairs:
        print("RESULT", json.dumps(one_pick(scenario, seed, kind, args.perceived)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
