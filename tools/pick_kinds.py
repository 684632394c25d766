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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--perceived", action="store_true")
    parser.add_argument("--pairs", default=None, help="seed:kind,... (default: see doc)")
    args = parser.parse_args(argv)
    scenario = LoadScenario(filename=SORTER)
    pairs = default_pairs(scenario) if args.pairs is None else [
        (int(p.split(":")[0]), p.split(":")[1]) for p in args.pairs.split(",")]
    for seed, kind in pairs:
        print("RESULT", json.dumps(one_pick(scenario, seed, kind, args.perceived)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
