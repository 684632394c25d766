"""The pick's verdicts at the plant's step and at half of it, the same plan each time
(issue 49 item 3), judged from the plant's final state by separate code
(``tests/pick/pick_judge.py``: every collision point in the box's cavity, at rest).
A measurement tool (the tables of docs/results/pick.md, "Held-out scenes").

Run: ``python tools/pick_steps.py [--seeds eval|A-B|a,b,...] [--modes perceived,true]
[--time-steps 0.001,0.0005] [--kind cuboid]``: for each seed the scene
``random_scene(diagrams/hamburg_setup.yaml, seed)`` is perceived (or read true) and its
pick planned once (:func:`handle_drake.apps.pick.cli.pick`), then that plan is simulated
at each step (``execute_pick``, the release corrected as the command does); ``--kind``:
only the seeds whose picked object is of that kind. One JSON line per simulation
(``RESULT {...}``): the command's verdict, the plant judge's, where the object was as
the hand began to open (``release_offset_mm``, ``release_tilt_deg``) and its tilt as its
bottom came down to the lid's top (``tilt_at_lid_deg``: a 6 cm cube wedges across its
84 mm hole from 36.9 deg). A pick takes 20-50 s per step on a quiet machine.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses as dc
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "pick"))

from pick_judge import TiltAtTheLid, judge_in_box  # noqa: E402

from handle_drake.apps.pick import execute  # noqa: E402
from handle_drake.apps.pick.cli import pick  # noqa: E402
from handle_drake.apps.pick.scenes import EVALUATION_SEEDS, random_scene  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402
from handle_drake.scene.config import hole_centres  # noqa: E402

HAMBURG = ROOT / "diagrams" / "hamburg_setup.yaml"
MODES = ("perceived", "true")


def _with_step(scenario, step: float):
    config = copy.deepcopy(scenario.plant_config)
    config.time_step = float(step)
    return dc.replace(scenario, plant_config=config)


def one_seed(base, seed: int, mode: str, steps, kind=None) -> list[dict]:
    """The rows of one seed and mode: the plan made once, simulated at each step."""
    rows, run = [], execute.execute_pick

    def at_each_step(scenario, plan, **kwargs):
        if kind is not None and plan.kind != kind:
            return run(scenario, plan, **kwargs)
        first = None
        for step in steps:
            lid = hole_centres(scenario)[plan.kind][2]
            watch = TiltAtTheLid(plan.target, lid + plan.grasp.object_spec.size / 2)
            out = run(_with_step(scenario, step), plan, **dict(kwargs, monitor=watch))
            verdict = judge_in_box(scenario, plan.target, watch.x)
            rows.append(dict(seed=seed, mode=mode, time_step=step, kind=plan.kind,
                             grasp_class=plan.grasp_class, in_box=out.in_box,
                             plant_in_box=verdict["in_cavity"] and verdict["at_rest"],
                             release_offset_mm=out.release_offset_mm,
                             release_tilt_deg=out.release_tilt_deg,
                             release_height_mm=out.release_height_mm,
                             tilt_at_lid_deg=None if watch.tilt is None else round(watch.tilt, 1),
                             outcome=out.reason,
                             final_position=out.p_WO_final.round(3).tolist()))
            first = out if first is None else first
        return first

    execute.execute_pick = at_each_step
    try:
        pick(random_scene(base, seed), true_poses=(mode == "true"))
    finally:
        execute.execute_pick = run
    return rows


def _seeds(text: str) -> list[int]:
    try:
        if text == "eval":
            return list(EVALUATION_SEEDS)
        if "-" in text:
            a, b = (int(v) for v in text.split("-"))
            return list(range(a, b + 1))
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"--seeds: expected eval, A-B or a,b,..., got {text!r}") from None


def _steps(text: str) -> list[float]:
    try:
        steps = [float(v) for v in text.split(",")]
    except ValueError:
        steps = []
    if not steps or not all(math.isfinite(s) and 0 < s <= 0.01 for s in steps):
        raise ValueError(f"--time-steps: expected steps in (0, 0.01] s, got {text!r}")
    return steps


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="eval")
    parser.add_argument("--modes", default="perceived,true")
    parser.add_argument("--time-steps", default="0.001,0.0005")
    parser.add_argument("--kind", default=None, choices=("sphere", "cuboid"))
    args = parser.parse_args(argv)
    try:
        seeds, steps = _seeds(args.seeds), _steps(args.time_steps)
        modes = args.modes.split(",")
        if not set(modes) <= set(MODES):
            raise ValueError(f"--modes: expected some of {','.join(MODES)}, got {args.modes!r}")
    except ValueError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    base = LoadScenario(filename=HAMBURG)
    for seed in seeds:
        for mode in modes:
            for row in one_seed(base, seed, mode, steps, args.kind):
                print("RESULT", json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
