"""Success rate of planned grasps per class over a range of object sizes.

For each of the eight grasp classes and each object shape (cuboid grasped
across its depth, sphere), five grasp widths spread over the class's size
range (``taxonomy.GraspClassInfo.size_range_m``): plan (``plan_grasp``) once,
then execute the same plan twice, side by side:

- open loop: the plan's keyframe script (reach, close, hold, lift),
- reactive: :class:`~handle_drake.systems.reactive_grasp.ReactiveGrasp`
  (report section 3.3: approach slowed/shifted on contact, each finger closes
  until its own tactile contact, squeeze, lift; ``grasp.execution``),

on the floating-wrist station, and count a success when the object held
through the 13 cm lift (``demo.held_through_lift``: >= 10 cm higher and
steady at the end). A plan that raises (no IK solution) fails both.

Run: ``python benchmarks/bench_grasp_classes.py [--workers 2] [--executor dask://HOST:PORT]
[--reactive NAME=VALUE ...]``
(``--executor``: ``local`` process pool, default, ``dask`` LocalCluster or a running
Dask scheduler, ``handle_drake.learning.cluster``); prints a table and writes
``benchmarks/results/grasp_classes.json``. Under HANDLE_DRAKE_REDUCED=1 it runs
two sizes of two classes on cuboids only. ``--reactive NAME=VALUE`` overrides a
``ReactiveGraspParams`` field of the reactive runs (e.g. ``close_shift_speed=0.03``
switches the centring close on, ``cop_shift_gain=10 --reactive cop_hold_above=0.002``
the centring on the taxels' centres of pressure); the results file name then carries
it. Each reactive run also records the object's in-hand offset (from where the plan
put it in the hand, read from the plant after the lift) and the wrist's shift.

Perceived against true object (report sections 3.3 and 4: the object is not
where the plan thinks): ``--offset MM [--directions N]`` plans on the object
at the origin and executes on the true object moved by MM millimetres in N
directions evenly spread from a seeded start angle; ``--size-error F`` plans
on a size (1 + F) times the true one; ``--yaw-error DEG`` turns the true
cuboid (round objects have no yaw). Results go to
``grasp_classes_<error>.json``.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake
from handle_drake.base.results import ResultsRun, add_page_arguments, table_rows
from handle_drake.learning.cluster import add_executor_arguments, trial_executor
from handle_drake.trial.plans import plan_scenario

pin_blas(force=False)

RESULTS = Path(__file__).resolve().parent / "results" / "grasp_classes.json"


def trial(args):
    grasp_class, kind, width, error, *rest = args if len(args) >= 4 else (*args, None)
    overrides = rest[0] if rest else {}
    from pydrake.common.schema import Transform

    from handle_drake.apps.planning.execution import ReactiveGraspRunner, plan_params
    from handle_drake.grasp.planning import plan_grasp, resting_pose
    from handle_drake.scenario import ObjectConfig
    from handle_drake.trial.simulate import ScenarioRunner, held_through_lift

    size = width / 0.6 if kind == "cuboid" else width  # cuboid depth = 0.6 * size
    # The plan sees the object at the origin with the perceived size; the
    # world holds the true one (moved, resized, turned) when an error is given.
    dx, dy, size_factor, yaw = error if error is not None else (0.0, 0.0, 1.0, 0.0)
    perceived_size = size * size_factor
    world_object = None
    if error is not None:
        world_object = ObjectConfig(
            kind=kind, size=size, on_table=False,
            X_WO=Transform(resting_pose(kind, size, xy=(dx, dy), yaw=yaw)))
    start = time.perf_counter()
    try:
        plan = plan_grasp(grasp_class, (kind, perceived_size), resting_pose(kind, perceived_size))
    except ValueError as error:
        return dict(grasp_class=grasp_class, kind=kind, width=width, size=size,
                    planned=False, held=False, lift=0.0, held_reactive=False,
                    lift_reactive=0.0, error=str(error)[:120],
                    plan_time=time.perf_counter() - start)
    plan_time = time.perf_counter() - start
    open_loop = ScenarioRunner(plan_scenario(plan, world_object=world_object)).run()
    runner = ReactiveGraspRunner(plan, world_object=world_object,
                                 params=plan_params(plan, **overrides))
    reactive = runner.run()
    return dict(grasp_class=grasp_class, kind=kind, width=width, size=size, planned=True,
                offset=[dx, dy], size_factor=size_factor, yaw_error=yaw,
                held=held_through_lift(open_loop), lift=open_loop.object_lift(),
                held_reactive=held_through_lift(reactive), lift_reactive=reactive.object_lift(),
                reactive_final_mode=runner.final_mode().name,
                in_hand_offset_mm=runner.in_hand_offset() * 1e3,
                reactive_shift_mm=(runner.approach_shift() * 1e3).tolist(),
                centre_source=plan.centre_source, centre_offset_mm=plan.centre_offset * 1e3,
                plan_time=plan_time, sim_wall_time=open_loop.wall_time,
                sim_wall_time_reactive=reactive.wall_time)


def _offset_text(row) -> str:
    """The reactive run's in-hand offset (the object from where the plan put it in the
    hand, read from the plant after the run) for the progress line."""
    offset = row.get("in_hand_offset_mm")
    return "" if offset is None else f", in-hand offset {offset:.1f} mm"


def main(argv=None) -> int:
    from handle_drake.base.testing import reduced
    from handle_drake.grasp.taxonomy import GRASP_CLASSES

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--sizes", type=int, default=5)
    parser.add_argument("--offset", type=float, default=0.0,
                        help="lateral error of the perceived object (mm)")
    parser.add_argument("--directions", type=int, default=2,
                        help="directions of the lateral error (evenly spread)")
    parser.add_argument("--size-error", type=float, default=0.0,
                        help="perceived size = (1 + F) * true size")
    parser.add_argument("--yaw-error", type=float, default=0.0,
                        help="true cuboid turned by this much (deg)")
    parser.add_argument("--classes", default=None,
                        help="comma-separated grasp classes (default: all eight)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--reactive", action="append", default=[], metavar="NAME=VALUE",
                        help="override a ReactiveGraspParams field (repeatable), "
                             "e.g. close_shift_speed=0.03")
    add_executor_arguments(parser)
    add_page_arguments(parser, "grasp_classes", published={"sizes": 3, "directions": 2})
    args = parser.parse_args(argv)
    run = ResultsRun("Grasp classes: open-loop and reactive grasps held per class and object",
                     args)
    if args.directions < 1 or not 0 <= args.offset < 100 or not -0.5 < args.size_error < 0.5:
        raise SystemExit("need --directions >= 1, 0 <= --offset < 100 mm, |--size-error| < 0.5")
    import dataclasses

    from handle_drake.systems.reactive_grasp import ReactiveGraspParams

    fields = {f.name for f in dataclasses.fields(ReactiveGraspParams)}
    overrides = {}
    for item in args.reactive:
        name, _, value = item.partition("=")
        if name not in fields or not value:
            raise SystemExit(f"--reactive {item!r}: expected NAME=VALUE with NAME one of "
                             f"{sorted(fields)}")
        try:
            overrides[name] = float(value)
        except ValueError:
            raise SystemExit(f"--reactive {item!r}: {value!r} is not a number") from None
    small = reduced()
    classes = list(GRASP_CLASSES.values())[:2] if small else list(GRASP_CLASSES.values())
    if args.classes:
        wanted = args.classes.split(",")
        unknown = set(wanted) - {info.name for info in classes}
        if unknown:
            raise SystemExit(f"unknown grasp classes: {sorted(unknown)}")
        classes = [info for info in classes if info.name in wanted]
    errors = [None]
    label = ""
    if args.offset or args.size_error or args.yaw_error:
        start = np.random.default_rng(args.seed).uniform(0, 2 * np.pi)
        angles = start + 2 * np.pi * np.arange(args.directions) / args.directions
        offsets = ([(args.offset / 1000 * np.cos(a), args.offset / 1000 * np.sin(a))
                    for a in angles] if args.offset else [(0.0, 0.0)])
        errors = [(float(dx), float(dy), 1.0 + args.size_error, np.radians(args.yaw_error))
                  for dx, dy in offsets]
        label = (f"_offset{args.offset:g}mm_size{args.size_error:+g}_yaw{args.yaw_error:g}"
                 .replace("+", "p").replace("-", "m"))
    kinds = ("cuboid",) if small else ("cuboid", "sphere")
    n_sizes = 2 if small else args.sizes
    jobs = []
    for info in classes:
        lo, hi = info.size_range_m
        # Inset from the range ends, where the IK is least likely to succeed.
        widths = np.linspace(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo), n_sizes)
        jobs += [(info.name, kind, float(w), e, overrides) for kind in kinds for w in widths
                 for e in errors]
    start = time.perf_counter()
    rows = [None] * len(jobs)
    with trial_executor(args.executor, max(1, args.workers),
                        connect_timeout=args.connect_timeout) as pool:
        futures = {pool.submit(trial, job): i for i, job in enumerate(jobs)}
        for done, future in enumerate(as_completed(futures), 1):
            i = futures[future]
            rows[i] = r = future.result()
            e = jobs[i][3]
            error = ("" if e is None else f" (true object moved {e[0] * 1e3:+.1f}, "
                     f"{e[1] * 1e3:+.1f} mm, size x{e[2]:g}, yaw {np.degrees(e[3]):g} deg)")
            print(f"{done}/{len(jobs)} {r['grasp_class']} {r['kind']} {r['width'] * 1e3:.0f} mm"
                  f"{error}: open loop {'held' if r['held'] else 'dropped'}, "
                  f"reactive {'held' if r['held_reactive'] else 'dropped'}"
                  f"{_offset_text(r)}", flush=True)
    wall = time.perf_counter() - start

    print(f"{len(rows)} trials in {wall:.0f} s\n")
    print("| class | shape | planned | open loop held | reactive held | widths (mm): "
          "open loop / reactive | reactive in-hand offset (mm, held: mean, max) |")
    print("|---|---|---|---|---|---|---|")
    summary = {}
    for info in classes:
        for kind in kinds:
            sub = [r for r in rows if r["grasp_class"] == info.name and r["kind"] == kind]
            n = len(sub)
            planned = sum(r["planned"] for r in sub)
            held = sum(r["held"] for r in sub)
            held_r = sum(r["held_reactive"] for r in sub)

            def marks(key, sub=sub):
                return ", ".join(f"{r['width'] * 1e3:.0f}{'*' if r[key] else ''}" for r in sub)

            offsets = [r["in_hand_offset_mm"] for r in sub if r["held_reactive"]]
            summary[f"{info.name}/{kind}"] = dict(
                trials=n, planned=planned, held_open_loop=held, held_reactive=held_r,
                success_rate_open_loop=held / n, success_rate_reactive=held_r / n,
                in_hand_offset_mm_mean=float(np.mean(offsets)) if offsets else None)
            spread = (f"{np.mean(offsets):.1f}, {np.max(offsets):.1f}" if offsets else "-")
            print(f"| {info.name} | {kind} | {planned}/{n} | {held}/{n} ({held / n:.0%}) "
                  f"| {held_r}/{n} ({held_r / n:.0%}) | {marks('held')} / "
                  f"{marks('held_reactive')} | {spread} |")
    total = sum(r["held"] for r in rows)
    total_r = sum(r["held_reactive"] for r in rows)
    n = len(rows)
    print(f"\noverall: open loop {total}/{n} held ({total / n:.0%}), reactive {total_r}/{n} "
          f"({total_r / n:.0%}); ratio reactive/open loop {total_r / max(total, 1):.2f}; "
          "* = held")
    held_offsets = [r["in_hand_offset_mm"] for r in rows if r.get("held_reactive")]
    if held_offsets:
        print(f"reactive in-hand offset over the {len(held_offsets)} held: mean "
              f"{np.mean(held_offsets):.1f} mm, median {np.median(held_offsets):.1f} mm")
    label += "".join(f"_{name}{value:g}" for name, value in sorted(overrides.items()))
    out = RESULTS.with_name(f"grasp_classes{label}.json")
    run.finish(table_rows(summary, "class/object"), dict(
        reduced=small, wall_time_s=wall, summary=summary,
                                   held_open_loop=total, held_reactive=total_r,
                                   reactive_overrides=overrides,
                                   error=dict(offset_mm=args.offset, directions=args.directions,
                                              size_error=args.size_error,
                                              yaw_error_deg=args.yaw_error),
                                   trials=rows), out)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
