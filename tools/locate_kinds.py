"""Where each kind is in the hand after the pick's lift, located from touch (issue 49
item 5), against the plant's pose of the object read here by code of its own.

For each ``seed:kind`` the shape sorter's scene ``random_scene(diagrams/sorter_setup.yaml,
seed, SORTER_KINDS)`` is picked (true poses: the planner's prior is the planned grasp) to
the lift, where :func:`handle_drake.apps.pick.touch.locate_by_touch` locates the object;
the run stops there. Errors (``tests/pick/locate_errors.py``: position mm, angle deg up to
the object's symmetry) of the located and of the planned pose; one ``LOCATE {...}`` JSON
line per scene. Development seeds 600-619 by default; the held-out block
(``SORTER_SEEDS``, 700-711) only for the published table.

Run: ``python tools/locate_kinds.py [--pairs 600:cylinder,...] [--seeds 600-619]``
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "pick"))

from locate_errors import pose_errors  # noqa: E402

from handle_drake.apps.pick import cli, execute  # noqa: E402
from handle_drake.apps.pick.scenes import SORTER_KINDS, random_scene  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402

SORTER = ROOT / "diagrams" / "sorter_setup.yaml"


class _Located(Exception):
    """Stops the pick once the object is located."""


def truth_in_hand(station, root_context, target):
    """``X_BO`` of the object instance ``target`` in the hand base frame, from the plant."""
    from handle_drake.base.hands import get_hand_spec
    from handle_drake.station import GetPlant

    plant = GetPlant(station)
    context = plant.GetMyContextFromRoot(root_context)
    hand = plant.GetModelInstanceByName("hand")
    X_WB = plant.GetBodyByName(get_hand_spec("shadow").base_body, hand).EvalPoseInWorld(context)
    body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(target))[0])
    return X_WB.inverse() @ body.EvalPoseInWorld(context)


def locate_once(scenario, seed: int, kind: str, record=None) -> dict:
    """The pick of the nearest ``kind`` in scene ``seed`` run to the lift; the located,
    planned and true object poses in the hand compared."""
    scene = random_scene(scenario, seed, SORTER_KINDS)
    seen, runs = {}, []
    locate, run = execute.locate_by_touch, execute.execute_pick

    def spy(station, root_context, scenario, spec, X_OB_planned):
        start = time.perf_counter()
        found = locate(station, root_context, scenario, spec, X_OB_planned)
        seen.update(found=found, spec=spec, planned=X_OB_planned.inverse(),
                    truth=truth_in_hand(station, root_context, runs[0]),
                    seconds=time.perf_counter() - start)
        if record is not None:  # what the hand sensed, for replays of the fit
            record(station, root_context, scenario, spec, X_OB_planned, seen["truth"])
        raise _Located

    def watched(scenario, plan, **kwargs):
        runs.append(plan.target)
        return run(scenario, plan, **kwargs)

    execute.locate_by_touch, execute.execute_pick = spy, watched
    start = time.perf_counter()
    try:
        result = cli.pick(scene, true_poses=True, kind=kind)
    except _Located:
        result = None
    finally:
        execute.locate_by_touch, execute.execute_pick = locate, run
    out = dict(seed=seed, kind=kind, wall_s=round(time.perf_counter() - start, 1))
    if result is not None or "truth" not in seen:
        return dict(out, status="not located", outcome=(result or {}).get("outcome", "")[:200])
    truth, spec = seen["truth"], seen["spec"]

    def errors(X):
        mm, deg = pose_errors(spec, truth.rotation().matrix(), truth.translation(),
                              X.rotation().matrix(), X.translation())
        return round(1000 * mm, 1), round(deg, 1)

    if seen["found"] is None:
        return dict(out, status="no pad felt it", planned=errors(seen["planned"]))
    X_BO, pads = seen["found"][0].inverse(), seen["found"][1]
    # the object's axis z against the truth's (deg): its tilt error, whatever its yaw
    cos = truth.rotation().matrix()[:, 2] @ X_BO.rotation().matrix()[:, 2]
    return dict(out, status="located", pads=int(pads), located=errors(X_BO),
                tilt_deg=round(float(np.degrees(np.arccos(np.clip(cos, -1, 1)))), 1),
                planned=errors(seen["planned"]), locate_s=round(seen["seconds"], 2))


def _recorder(path: Path):
    """A ``record(...)`` writing the hand's sensed inputs and the truth to ``path``."""
    from handle_drake.apps.pick.touch import _hand_base_pose
    from handle_drake.devices.taxels.locate import sample_taxels

    def record(station, root_context, scenario, spec, X_OB_planned, truth):
        context = station.GetMyContextFromRoot(root_context)
        data = dict(taxels=sample_taxels(station, root_context),
                    q=station.GetOutputPort("hand.position_measured").Eval(context),
                    X_WB=_hand_base_pose(station, context, scenario).GetAsMatrix4(),
                    pads=station.GetSubsystemByName("taxels").pads, spec=spec,
                    hand=(scenario.hand.kind, scenario.hand.coupling_ratio),
                    X_OB_planned=X_OB_planned.GetAsMatrix4(), X_BO_true=truth.GetAsMatrix4())
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(data))

    return record


def _pairs(scenario, text, seeds):
    if text:
        return [(int(s), k) for s, k in (p.split(":") for p in text.split(","))]
    out = []
    for seed in seeds:
        scene = random_scene(scenario, seed, SORTER_KINDS)
        kinds = dict.fromkeys(o.kind for o in [scene.object, *scene.objects])
        out += [(seed, k) for k in kinds]
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", default="", help="SEED:KIND,... (default: every kind of "
                        "each --seeds scene)")
    parser.add_argument("--seeds", default="600-619", help="development scene seeds A-B")
    parser.add_argument("--kinds", default=",".join(SORTER_KINDS))
    parser.add_argument("--record", default=None, metavar="DIR",
                        help="also write each scene's sensed inputs (pickle) to DIR")
    args = parser.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = range(int(a), int(b or a) + 1)
    scenario = LoadScenario(filename=SORTER)
    kinds = set(args.kinds.split(","))
    # every kind located (the module's LOCATED_KINDS decides what the pick does)
    execute.LOCATED_KINDS = tuple(SORTER_KINDS)
    rows = []
    for seed, kind in _pairs(scenario, args.pairs, seeds):
        if kind not in kinds:
            continue
        row = locate_once(scenario, seed, kind, record=args.record and _recorder(
            Path(args.record) / f"{seed}_{kind}.pkl"))
        rows.append(row)
        print("LOCATE " + json.dumps(row), flush=True)
    ok = [r for r in rows if r["status"] == "located"]
    within = [r for r in ok if r["located"][0] <= 10 and r["located"][1] <= 10]
    print(f"located {len(ok)}/{len(rows)}, within 10 mm and 10 deg {len(within)}/{len(rows)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
