"""Per-frame cost of perception: rendering a frame against detecting in it.

Run: ``python benchmarks/bench_perception.py [--rounds N] [--repeats R]
[--scene-seed S] [--baseline OLD_DETECT.py]``. Prints a table and writes
``benchmarks/results/perception.json``.

The scenario is ``diagrams/tabletop_perception.yaml`` (a Kinect v1, 640 x 480,
1 m from a cuboid on the table); ``--scene-seed S`` renders instead a seeded
cluttered table (2-5 objects, :func:`handle_drake.apps.perception.scenes.random_scene`).
Per round, side by side in one process:

* ``render rgb``: the colour image (RenderEngineVtk).
* ``render depth + cloud``: the depth image, the Kinect noise model and the
  world-frame point cloud (Drake's DepthImageToPointCloud): what the detector
  consumes. This is the floor: the target is ``detect <= 1.0 x`` it.
* ``detect (plane per frame)``: :func:`detect_objects` on that cloud, the
  table plane fitted again in every frame.
* ``detect (plane per scene)``: :class:`TabletopDetector`: the plane fitted
  on the first frame and kept (checked on a sample of each frame).
* ``baseline detect`` (with ``--baseline FILE``): ``detect_objects`` of another
  version of ``detect.py`` (e.g. ``git show main:handle_drake/geometry/detect.py``),
  on the same cloud, for a before/after in one run.

Every round renders a new frame (the context's time moves, so the caches and
the noise are new). The garbage collector's runs are counted per step (a
``gc.callbacks`` hook; column ``gc``) and ``max@gc`` says whether the
slowest round of a step had a collection in it, so that a spike can be told
from a collection.
``--gc-freeze`` calls ``gc.freeze()`` once the diagram is built: a
collection then skips everything allocated so far (Drake's diagrams, the
modules), so a collection that lands in a frame no longer scans the heap.
``--repeats R`` runs the whole measurement R times (the machine is shared:
the spread across repeats shows the noise); medians and p90 are reported per
repeat, with the load average beside them.
"""

from __future__ import annotations

import argparse
import gc
import importlib.util
import os
import platform
import sys
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.base.models import diagrams_dir  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.geometry.detect import TabletopDetector, detect_objects  # noqa: E402


class _GcCounter:
    def __init__(self):
        self.runs = 0
        gc.callbacks.append(self)

    def __call__(self, phase, info):
        if phase == "start":
            self.runs += 1


def _load_baseline(path: Path):
    spec = importlib.util.spec_from_file_location("baseline_detect", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["baseline_detect"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module.detect_objects


def _ports(args):
    if args.scene_seed is None:
        from handle_drake.scenario import LoadScenario
        from handle_drake.station import MakeHandStation

        scenario = LoadScenario(
            filename=diagrams_dir() / "tabletop_perception.yaml",
            data="object: {kind: cuboid, size: 0.06, X_WO: {translation: [0.05, 0.02, 0], "
                 "rotation: !Rpy {deg: [0, 0, 25]}}}")
        diagram = MakeHandStation(scenario)
        expected = 1
    else:
        from handle_drake.apps.perception.scenes import TabletopScene, random_scene

        objects = random_scene(args.scene_seed)
        diagram = TabletopScene(objects, seed=args.scene_seed).diagram
        expected = len(objects)
    context = diagram.CreateDefaultContext()
    # The depth frame beside the cloud (what detect(frame) is given): the
    # detector joins the parts of one object seen apart around a nearer one
    # or around its surface nearer than the sensor's range.
    from types import SimpleNamespace

    from handle_drake.devices.camera.profiles import get_profile
    from handle_drake.devices.camera.sensors import camera_info

    depth_port = diagram.GetOutputPort("kinect.depth")
    X_WC = diagram.GetOutputPort("kinect.pose").Eval(context).GetAsMatrix4()
    K = camera_info(get_profile("kinect_v1")).intrinsic_matrix()

    def view():  # the depth image's array (no copy), K and X_WC
        return SimpleNamespace(depth=np.asarray(depth_port.Eval(context).data)[:, :, 0],
                               K=K, X_WC=X_WC)

    return (context, diagram.GetOutputPort("kinect.rgb"),
            diagram.GetOutputPort("kinect.point_cloud"), expected, view)


def measure(args, baseline) -> dict:
    context, rgb_port, cloud_port, expected, view_of = _ports(args)
    rgb_port.Eval(context)  # the renderer's first frame builds its pipeline
    steps = ["render rgb", "render depth + cloud", "detect (plane per frame)",
             "detect (plane per scene)"] + (["baseline detect"] if baseline else [])
    times = {k: [] for k in steps}
    gc_runs = {k: 0 for k in steps}
    gc_rounds = {k: [] for k in steps}  # per round: did a collection run in the step
    found = {k: [] for k in steps if k.endswith("detect") or k.startswith("detect")}
    detector = TabletopDetector()
    counter = _GcCounter()
    # One warm-up frame for every detector (imports, first-call caches).
    context.SetTime(0.001)
    cloud = cloud_port.Eval(context).xyzs().T
    detect_objects(cloud, view=view_of())
    if baseline:
        baseline(cloud)
    # What a full collection costs here (every object of Drake's diagrams and
    # the imported modules is scanned), then, with --gc-freeze, the same
    # after gc.freeze() (the heap built so far moved to a permanent
    # generation that collections skip: what a long-running loop should do
    # once its diagrams are built).
    start = time.perf_counter()
    gc.collect()
    full_gc_ms = 1000 * (time.perf_counter() - start)
    frozen_gc_ms = None
    if args.gc_freeze:
        gc.freeze()
        start = time.perf_counter()
        gc.collect()
        frozen_gc_ms = 1000 * (time.perf_counter() - start)
    load_before = os.getloadavg()[0]
    for i in range(args.rounds):
        context.SetTime(0.01 * (i + 1))
        results = {}
        for step in steps:
            before = counter.runs
            start = time.perf_counter()
            if step == "render rgb":
                rgb_port.Eval(context)
            elif step == "render depth + cloud":
                cloud = cloud_port.Eval(context).xyzs().T
                view = view_of()
            elif step == "detect (plane per frame)":
                results[step] = detect_objects(cloud, view=view)[1]
            elif step == "detect (plane per scene)":
                results[step] = detector.detect(cloud, view=view)
            else:
                results[step] = baseline(cloud)[1]
            times[step].append(time.perf_counter() - start)
            gc_runs[step] += counter.runs - before
            gc_rounds[step].append(counter.runs > before)
        for step, detections in results.items():
            found[step].append(len(detections))
    gc.callbacks.remove(counter)
    if args.gc_freeze:
        gc.unfreeze()
    floor = float(np.median(times["render depth + cloud"]))
    rows = {}
    for step, values in times.items():
        median = float(np.median(values))
        p90 = float(np.percentile(values, 90))
        rows[step] = {"median_ms": 1000 * median, "p90_ms": 1000 * p90,
                      "max_ms": 1000 * float(np.max(values)),
                      "over_depth_render": median / floor, "p90_over_median": p90 / median,
                      "gc_runs": gc_runs[step],
                      "slowest_round_had_gc": bool(gc_rounds[step][int(np.argmax(values))]),
                      "times_ms": [round(1000 * v, 3) for v in values],
                      "gc_in_round": gc_rounds[step]}
        if step in found:
            rows[step]["frames_all_found"] = sum(n == expected for n in found[step])
    return {"rows": rows, "rounds": args.rounds, "objects": expected,
            "gc_freeze": bool(args.gc_freeze), "full_gc_ms": full_gc_ms,
            "full_gc_after_freeze_ms": frozen_gc_ms,
            "plane_fits": detector.refits,
            "load_average": [load_before, os.getloadavg()[0]]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--scene-seed", type=int, default=None)
    parser.add_argument("--gc-freeze", action="store_true",
                        help="gc.freeze() once the diagram is built (collections then skip it)")
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another detect.py to time on the same clouds")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "perception.json")
    add_page_arguments(parser, "perception", published={"rounds": 40, "repeats": 3})
    args = parser.parse_args(argv)
    results_run = ResultsRun("Perception: detection time against the depth render", args)
    if args.rounds < 2 or args.repeats < 1:
        parser.error("--rounds must be >= 2 and --repeats >= 1")
    if args.baseline is not None and not args.baseline.is_file():
        parser.error(f"--baseline: no such file {args.baseline}")
    baseline = _load_baseline(args.baseline) if args.baseline else None
    runs = []
    for repeat in range(args.repeats):
        run = measure(args, baseline)
        runs.append(run)
        print(f"\nrepeat {repeat + 1}/{args.repeats}: {args.rounds} frames, "
              f"{run['objects']} object(s), load average {run['load_average'][0]:.1f} -> "
              f"{run['load_average'][1]:.1f}, table plane fitted {run['plane_fits']}x "
              f"by the per-scene detector; a full gc.collect() {run['full_gc_ms']:.0f} ms"
              + ("" if run["full_gc_after_freeze_ms"] is None else
                 f", after gc.freeze() {run['full_gc_after_freeze_ms']:.1f} ms"))
        print(f"{'step':26s} {'median ms':>9s} {'p90 ms':>7s} {'max ms':>7s} "
              f"{'x depth':>7s} {'p90/med':>7s} {'gc':>3s} {'max@gc':>6s} {'found':>6s}")
        for step, r in run["rows"].items():
            found = f"{r['frames_all_found']}/{args.rounds}" if "frames_all_found" in r else ""
            print(f"{step:26s} {r['median_ms']:9.1f} {r['p90_ms']:7.1f} {r['max_ms']:7.1f} "
                  f"{r['over_depth_render']:7.2f} {r['p90_over_median']:7.2f} "
                  f"{r['gc_runs']:3d} {'yes' if r['slowest_round_had_gc'] else 'no':>6s} "
                  f"{found:>6s}")
    ratios = [run["rows"]["detect (plane per scene)"]["over_depth_render"] for run in runs]
    print(f"\ndetect (plane per scene) / render (depth + cloud): "
          f"{', '.join(f'{r:.2f}' for r in ratios)} over {args.repeats} repeat(s) "
          f"(target <= 1.0)")
    results_run.finish(
        [{"repeat": i + 1, "step": step, **{k: v for k, v in r.items()
                                            if not isinstance(v, list | dict)}}
         for i, run in enumerate(runs) for step, r in run["rows"].items()],
        {"benchmark": "perception", "scene_seed": args.scene_seed,
         "baseline": str(args.baseline) if args.baseline else None, "runs": runs,
         "machine": platform.platform(), "cpus": os.cpu_count()}, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
