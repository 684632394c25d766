"""Which floating-wrist grasp plans the PA10 can reach on the Hamburg table (issue 33, item 6).

For each grasp class and each plannable object of ``diagrams/hamburg_setup.yaml``
(the planner grasps a sphere anywhere and a cuboid upright; the upright
cylinder and the star prism it does not plan), at the object's own place and
at ``--places`` more places on the table (seeded), the floating-wrist planner
(``grasp.planning.plan_grasp``, reaching from the arm's base towards the
object) makes a plan; the arm then needs IK solutions
(``arm.reach.ArmReach``: joint limits, 3 mm clearance from table, box, other
objects and itself) for the pre-grasp, grasp and lift poses of the hand base,
chained (each seeded by the previous one), and collision-free straight
joint-space segments between them. Prints a table per class and writes JSON.

Run: python benchmarks/bench_arm_reachability.py [--places N] [--out out/bench]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from handle_drake.base.results import ResultsRun, add_page_arguments


def main(argv=None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--places", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="out/bench")
    add_page_arguments(parser, "arm_reachability", published={"places": 2})
    args = parser.parse_args(argv)
    run = ResultsRun("Arm reachability of planned grasps per grasp class", args)

    from pydrake.math import RigidTransform, RollPitchYaw

    from handle_drake.apps.pick.reach import ArmReach
    from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
    from handle_drake.base.models import diagrams_dir
    from handle_drake.grasp.planning import plan_grasp
    from handle_drake.grasp.taxonomy import GraspClass
    from handle_drake.scenario import LoadScenario
    from handle_drake.scene.config import initial_pose, scene_objects, spec_of

    scenario = LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml")
    ratio = scenario.hand.coupling_ratio
    hand = get_hand_spec(scenario.hand.kind)
    ready = np.array(scenario.hand.mount.initial_position)
    base = scenario.hand.mount.X_WB.GetDeterministicValue().translation()
    rng = np.random.default_rng(args.seed)
    cases = []
    for name, o in scene_objects(scenario):
        if o.kind not in ("sphere", "cuboid"):
            continue
        X0 = initial_pose(o, scenario.table)
        places = [X0]
        for _ in range(args.places):
            xy = rng.uniform([-0.15, -0.3], [0.2, 0.1])
            yaw = rng.uniform(-np.pi, np.pi)
            places.append(RigidTransform(RollPitchYaw(0, 0, yaw).ToRotationMatrix().multiply(
                X0.rotation()), [xy[0], xy[1], X0.translation()[2]]))
        cases.append((name, o, places))
    reaches = {name: ArmReach(scenario, ignore=(name,)) for name, _, _ in cases}
    rows = []
    for cls in GraspClass:
        for name, o, places in cases:
            for k, X_WO in enumerate(places):
                row = {"class": cls.value, "object": name, "kind": o.kind, "place": k,
                       "xy": X_WO.translation()[:2].round(3).tolist()}
                start = time.perf_counter()
                try:
                    plan = plan_grasp(cls, spec_of(o), X_WO, table_height=0.0,
                                      reach_direction=X_WO.translation()[:2] - base[:2],
                                      coupling_ratio=ratio)
                except ValueError as error:
                    row.update(planned=False, reason=str(error)[:120])
                    rows.append(row)
                    continue
                row.update(planned=True, plan_s=time.perf_counter() - start)
                reach = reaches[name]
                q_pre = actuated_to_joint_positions(hand, plan.preshape_command, ratio)
                seed, qs, ik_s, reason = ready, [], 0.0, ""
                for label, X in (("pregrasp", plan.X_WB_pregrasp), ("grasp", plan.X_WB),
                                 ("lift", plan.lifted())):
                    result = reach.solve_from_seeds(X, [seed, ready], q_pre)
                    ik_s += result.seconds
                    if not result.ok:
                        reason = f"no IK for the {label} pose"
                        break
                    qs.append(result.q)
                    seed = result.q
                if not reason:
                    for a, b in zip(qs, qs[1:], strict=False):
                        if not reach.path_is_free(a, b, q_pre):
                            reason = "straight joint path collides"
                row.update(reachable=not reason, reason=reason, ik_s=ik_s)
                rows.append(row)
                print(f"{cls.value:20s} {name:9s} place {k}: "
                      f"{'reachable' if not reason else reason} (IK {ik_s:.2f} s)", flush=True)

    print("\nclass                planned  reachable  median IK s (3 poses)")
    summary = {}
    for cls in GraspClass:
        mine = [r for r in rows if r["class"] == cls.value]
        planned = [r for r in mine if r["planned"]]
        ok = [r for r in planned if r.get("reachable")]
        ik = np.median([r["ik_s"] for r in planned]) if planned else float("nan")
        summary[cls.value] = {"cases": len(mine), "planned": len(planned), "reachable": len(ok),
                              "median_ik_s": float(ik)}
        print(f"{cls.value:20s} {len(planned):3d}/{len(mine):<3d}  {len(ok):3d}/{len(planned):<3d}"
              f"      {ik:.2f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "arm_reachability.json"
    run.finish([{"class": name, **row} for name, row in summary.items()],
               {"summary": summary, "rows": rows, "load_average": os.getloadavg()}, path)
    print(f"load average {os.getloadavg()[0]:.1f}; wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
