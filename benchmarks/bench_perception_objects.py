"""The seven grasp objects seen by the Kinect at seeded table poses: pose error
and the grasp planned from the camera against the grasp planned from the truth.

For each object of the babbling experiments (sphere, wine glass, cylinder, mug,
cuboid, rotated cuboid, star prism; report Table 3, at their babbling sizes)
at ``--poses`` seeded poses (anywhere within 15 cm of the table's centre, any
yaw), the tabletop Kinect (``diagrams/tabletop_perception.yaml``) perceives
it, and the babbling grasp trial (Barrett, guarded approach from above,
close, BW metric over the hold; the BW metric is signed) runs with the hand centred on the perceived
centre, turned with the perceived yaw where the footprint gives one
(:func:`handle_drake.apps.perception.grasping.perceived_grasp_trial`). From the
truth the same grasp is the trial at zero offset. Success = force closure.

Run: ``python benchmarks/bench_perception_objects.py [--poses 5] [--seed 0]``;
prints a table and writes ``benchmarks/results/perception_objects.json``.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "perception_objects.json"


def main(argv=None) -> int:
    from handle_drake.apps.babbling.report import OBJECT_ORDER
    from handle_drake.apps.perception.grasping import perceived_grasp_trial
    from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hand", default="barrett", choices=("barrett", "shadow"))
    parser.add_argument("--objects", nargs="+", default=list(OBJECT_ORDER))
    parser.add_argument("--out", type=Path, default=RESULTS)
    add_page_arguments(parser, "perception", published={"poses": 5, "objects": len(OBJECT_ORDER)})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Grasp trials on perceived objects, per object", args)
    if args.poses < 1:
        parser.error("--poses must be >= 1")
    rng = np.random.default_rng(args.seed)
    rows, start = [], time.perf_counter()
    for kind in args.objects:
        trial = GraspTrial(GraspTrialConfig(hand=args.hand, object=kind, space="offset"))
        truth = trial.evaluate([0.0, 0.0])
        cases = []
        for i in range(args.poses):
            r, phi = 0.15 * math.sqrt(rng.random()), rng.uniform(0, 2 * math.pi)
            xy, yaw = (r * math.cos(phi), r * math.sin(phi)), rng.uniform(-math.pi, math.pi)
            p = perceived_grasp_trial(kind, xy, yaw, hand=args.hand, seed=args.seed * 1000 + i,
                                      trial=trial)
            cases.append(p.as_dict())
            print(f"  {kind} pose {i}: xy {xy[0]:+.3f} {xy[1]:+.3f} yaw {math.degrees(yaw):+.0f}"
                  f" -> {p.error and p.error['xy_mm']} mm, metric {p.metric:.3f} "
                  f"(truth {truth.metric_noiseless:.3f})", flush=True)
        seen = [c for c in cases if c["error"] is not None]
        xy_err = [c["error"]["xy_mm"] for c in seen]
        yaw_err = [abs(c["error"]["yaw_deg"]) for c in seen if c["error"]["yaw_deg"] is not None]
        rows.append({
            "object": kind, "poses": len(cases), "seen": len(seen),
            "xy_mm_median": float(np.median(xy_err)) if xy_err else None,
            "xy_mm_max": float(np.max(xy_err)) if xy_err else None,
            "yaw_deg_median": float(np.median(yaw_err)) if yaw_err else None,
            "kind_ok": sum(bool(c["error"]["kind_ok"]) for c in seen),
            "truth_metric": truth.metric_noiseless, "truth_closure": truth.force_closure,
            "perceived_metric_mean": float(np.mean([c["metric"] if c["error"] else 0.0
                                                    for c in cases])),
            "truth_success": bool(truth.force_closure and truth.metric_noiseless > 0),
            "perceived_success": sum(bool(c["force_closure"] and c["metric"] > 0) for c in cases),
            "cases": cases,
        })
    wall = time.perf_counter() - start
    print(f"\n{args.hand} hand, {args.poses} seeded poses per object (seed {args.seed}), "
          f"{wall:.0f} s")
    print(f"{'object':15s} {'seen':>5s} {'xy mm med/max':>14s} {'|yaw| deg':>9s} {'kind':>5s}"
          f" {'BW truth':>9s} {'BW perc.':>9s} {'success truth':>14s} {'success perc.':>14s}")
    for r in rows:
        xy = "-" if r["xy_mm_median"] is None else f"{r['xy_mm_median']:.1f}/{r['xy_mm_max']:.1f}"
        yaw = "-" if r["yaw_deg_median"] is None else f"{r['yaw_deg_median']:.1f}"
        print(f"{r['object']:15s} {r['seen']:>2d}/{r['poses']:<2d} {xy:>14s} {yaw:>9s} "
              f"{r['kind_ok']:>5d} {r['truth_metric']:9.3f} {r['perceived_metric_mean']:9.3f} "
              f"{('yes' if r['truth_success'] else 'no'):>14s} "
              f"{r['perceived_success']:>11d}/{r['poses']:<2d}")
    results_run.finish(
        [{k: v for k, v in r.items() if k != "cases"} for r in rows],
        {"hand": args.hand, "poses": args.poses, "seed": args.seed, "wall_time_s": wall,
         "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                     "load_average": os.getloadavg()},
         "rows": rows}, args.out)
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
