"""Per-frame cost of perception: rendering a frame against detecting in it.

Run: ``python benchmarks/bench_perception.py [--rounds N]``. Prints a table and
writes ``benchmarks/results/perception.json``.

The scenario is ``diagrams/tabletop_perception.yaml`` (a Kinect v1, 640 x 480,
1 m from a cuboid on the table). Per round, side by side in one process:

* ``render rgb``: the colour image (RenderEngineVtk).
* ``render depth + cloud``: the depth image, the Kinect noise model and the
  world-frame point cloud (Drake's DepthImageToPointCloud): what the detector
  consumes.
* ``detect``: table plane, clusters and primitive fits on that cloud.

Every round renders a new frame (the context's time moves, so the caches and
the noise are new). Times are wall-clock medians over the rounds; the target
is ``detect / render (rgb + depth) <= 1``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from handle_drake.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.demo import diagrams_dir  # noqa: E402
from handle_drake.perception.detect import detect_objects  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402
from handle_drake.station import MakeHandStation  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "perception.json")
    args = parser.parse_args(argv)
    scenario = LoadScenario(
        filename=diagrams_dir() / "tabletop_perception.yaml",
        data="object: {kind: cuboid, size: 0.06, X_WO: {translation: [0.05, 0.02, 0], "
             "rotation: !Rpy {deg: [0, 0, 25]}}}")
    station = MakeHandStation(scenario)
    context = station.CreateDefaultContext()
    rgb_port = station.GetOutputPort("kinect.rgb")
    cloud_port = station.GetOutputPort("kinect.point_cloud")
    rgb_port.Eval(context)  # the renderer's first frame builds its pipeline
    times = {"render rgb": [], "render depth + cloud": [], "detect": []}
    found = []
    for i in range(args.rounds):
        context.SetTime(0.01 * (i + 1))
        start = time.perf_counter()
        rgb_port.Eval(context)
        times["render rgb"].append(time.perf_counter() - start)
        start = time.perf_counter()
        xyz = cloud_port.Eval(context).xyzs().T
        times["render depth + cloud"].append(time.perf_counter() - start)
        start = time.perf_counter()
        _, detections = detect_objects(xyz)
        times["detect"].append(time.perf_counter() - start)
        found.append(len(detections))
    median = {k: float(np.median(v)) for k, v in times.items()}
    render = median["render rgb"] + median["render depth + cloud"]
    ratio = median["detect"] / render
    print(f"{'step':24s} {'median ms':>10s} {'p90 ms':>8s}")
    for k, v in times.items():
        print(f"{k:24s} {median[k] * 1000:10.1f} {np.percentile(v, 90) * 1000:8.1f}")
    print(f"detect / render (rgb + depth) = {ratio:.2f}  (target <= 1); "
          f"one object found in {found.count(1)}/{len(found)} frames; "
          f"load average {os.getloadavg()[0]:.1f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({
        "benchmark": "perception", "rounds": args.rounds, "median_s": median,
        "detect_over_render": ratio, "frames_with_one_object": found.count(1),
        "load_average": os.getloadavg()[0], "machine": platform.platform(),
        "cpus": os.cpu_count()}, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
