"""``handle-drake babble`` and ``handle-drake report`` (report section 4.3).

Examples::

    handle-drake babble --hand barrett --object mug --dims 2 --strategy bo --trials 60 \\
        --seed 1 --noise 0.01 --db out/babble.sqlite
    handle-drake babble --hand shadow --object cuboid --space synergy --trials 100
    handle-drake babble --object sphere --strategy random --trials 200 --workers 2
    handle-drake babble --object mug --strategy random --trials 500 --executor dask://head:8786
    handle-drake babble --mesh my_part.stl --mesh-scale 0.001 --trials 40   # your own object
    handle-drake report --out out/report            # full: ~30 min on 2 cores
    handle-drake report --out /tmp/r --reduced      # seconds

``babble`` logs every trial to the SQLite file ``--db`` and resumes the run
(same hand, object, space, noise, strategy and seed) if it is already there:
an interrupted run continues where it stopped, with no trial repeated or lost.
It then draws the run (``--plot``, default ``<db folder>/<run id>.png``).
Bad arguments print an error and exit with status 2.

Also runnable as ``python -m handle_drake.apps.babbling.cli``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handle_drake.apps.cli_support import (
    add_mesh_arguments,
    non_empty,
    non_negative_float,
    positive_float,
    positive_int,
    refuse_without_mesh,
    seed_int,
)
from handle_drake.geometry.objects import KINDS
from handle_drake.learning.cluster import add_chunk_argument, add_executor_arguments

__all__ = ["register", "main", "build_parser", "SPACE_OF_DIMS"]

SPACE_OF_DIMS = {1: "standoff", 2: "offset"}
_PARAMETER_NAMES = {
    "standoff": ("standoff_m",),
    "offset": ("x_offset_m", "y_offset_m"),
    "synergy": ("thumb_abduction", "index_middle_abduction"),
}


def register(subparsers) -> None:
    """Adds ``babble`` and ``report`` to an argparse sub-parser collection."""
    p = subparsers.add_parser(
        "babble", help="learn a grasp by trial: BO or random search over grasp parameters",
        description="Runs (or resumes) grasp trials chosen by Bayesian optimisation or random "
                    "search and logs each one to an SQLite file.")
    p.add_argument("--hand", choices=("barrett", "shadow"), default="barrett",
                   help="the hand that grasps (default barrett)")
    p.add_argument("--object", choices=KINDS, default=None, help="the object (default sphere)")
    p.add_argument("--dims", type=int, choices=(1, 2), default=None,
                   help="1: standoff along the approach axis; 2: (x, y) offset (default 2)")
    p.add_argument("--space", choices=("standoff", "offset", "synergy"), default=None,
                   help="parameter space (synergy: Shadow anatomical synergies, 2-D)")
    p.add_argument("--strategy", choices=("bo", "random"), default="bo",
                   help="bo: Bayesian optimisation (GP + expected improvement); random: "
                        "random search (default bo)")
    p.add_argument("--trials", type=positive_int, default=50,
                   help="trials in the run (BO may stop earlier on its EI rule)")
    p.add_argument("--seed", type=seed_int, default=0,
                   help="the run's seed (first trials and trial noise; default 0)")
    p.add_argument("--ei-stop", type=non_negative_float, default=0.0, metavar="THRESHOLD",
                   help="BO only: stop when the best expected improvement falls below "
                        "THRESHOLD x the RMS of the metric (the report's stop rule, e.g. 1e-6; "
                        "default 0: use the whole --trials budget)")
    p.add_argument("--noise", type=non_negative_float, default=0.0,
                   help="std of Gaussian noise added to the metric (seeded per trial)")
    p.add_argument("--size", type=positive_float, default=None,
                   help="object size in m (default: the babbling catalogue's)")
    p.add_argument("--placement-error", type=non_negative_float, default=0.0, metavar="M",
                   help="robust objective: score each trial as the mean metric over "
                        "--placement-samples wrist placements within M metres of the "
                        "planned one (e.g. 0.002); default 0: the nominal metric")
    p.add_argument("--placement-samples", type=positive_int, default=None, metavar="K",
                   help="placements per trial of the robust objective (default 5 with "
                        "--placement-error)")
    add_mesh_arguments(p, "grasp your own object: a mesh file (OBJ, STL, PLY, ...) instead of "
                          "--object; decomposed into convex pieces once (cached)")
    p.add_argument("--db", type=Path, default=Path("out/babble.sqlite"),
                   help="SQLite trial log (default out/babble.sqlite); resumed if it exists")
    p.add_argument("--workers", type=positive_int, default=None,
                   help="trials run in parallel (worker processes of 'local' and 'dask'); BO "
                        "then proposes batches of this size (kriging believer), a run of its "
                        "own (default 1: the report's sequential BO). With dask://, BO "
                        "proposes batches of the cluster's worker count unless --workers says "
                        "otherwise, and random search runs as many trials at once as the "
                        "cluster has workers")
    add_executor_arguments(p)
    add_chunk_argument(p)
    p.add_argument("--run-id", type=non_empty, default=None, help="name of the run in the log")
    p.add_argument("--plot", type=Path, default=None, metavar="PNG",
                   help="figure of the run: metric per trial with the best so far, and the "
                        "GP's map of the parameter space (default: <db folder>/<run id>.png)")
    p.add_argument("--no-plot", action="store_true", help="write no figure")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_babble)

    p = subparsers.add_parser(
        "report", help="reproduce the babbling figures and Table 3 of report section 4.3",
        description="Runs every babbling experiment (cached: re-running is cheap) and writes "
                    "PNG figures, table3.md/csv and summary.json.")
    p.add_argument("--out", type=Path, default=Path("out/report"), help="output folder")
    p.add_argument("--seeds", type=positive_int, default=None, help="seeds per comparison")
    p.add_argument("--trials", type=positive_int, default=None, help="trials per 2-D run")
    p.add_argument("--grid", type=int, default=None,
                   help="points per dimension of the ground-truth grids (>= 2)")
    p.add_argument("--noise", type=non_negative_float, default=None,
                   help="metric noise std of the 2-D runs")
    p.add_argument("--ei-stop", type=non_negative_float, default=None, metavar="THRESHOLD",
                   help="stop the Table 3 BO runs on the EI rule with this threshold "
                        "(e.g. 1e-6; default 0: every run uses the whole --trials budget)")
    p.add_argument("--workers", type=positive_int, default=None,
                   help="worker processes of 'local' and 'dask' (default 2)")
    add_executor_arguments(p)
    add_mesh_arguments(p, "also run the Table 3 experiment on this mesh object (repeatable; "
                          "--mesh-scale applies to each)", action="append", default=[])
    p.add_argument("--reduced", action="store_true",
                   help="tiny grids and few trials (also HANDLE_DRAKE_REDUCED=1)")
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.set_defaults(func=_cmd_report)


def _resolve_space(args) -> str:
    if args.space is None:
        return SPACE_OF_DIMS[args.dims or 2]
    if args.dims is not None and SPACE_OF_DIMS.get(args.dims) != args.space and not (
            args.space == "synergy" and args.dims == 2):
        raise ValueError(f"--dims {args.dims} contradicts --space {args.space}")
    return args.space


def _trial_config(args, space):
    """The grasp trial's settings from the command line (object or mesh, robustness)."""
    from handle_drake.trial.grasp_trial import GraspTrialConfig

    samples = args.placement_samples
    if args.placement_error == 0 and samples not in (None, 1):
        raise ValueError(f"--placement-samples {samples}: needs --placement-error > 0")
    if args.placement_error > 0 and samples is None:
        samples = 5
    if args.placement_error > 0 and samples == 1:
        raise ValueError("--placement-samples 1: a robust objective needs at least 2")
    robust = dict(placement_error=args.placement_error, placement_samples=samples or 1)
    if args.mesh is not None:
        if args.size is not None:
            raise ValueError("--size: a mesh's size comes from its file; use --mesh-scale")
        if args.object is not None:
            raise ValueError(f"--object {args.object}: give either --object or --mesh, not both")
        config = GraspTrialConfig(hand=args.hand, object="mesh", space=space, noise=args.noise,
                                  object_file=str(args.mesh), object_scale=args.mesh_scale or 1.0,
                                  **robust)
    else:
        refuse_without_mesh(args, "--mesh-scale")
        config = GraspTrialConfig(hand=args.hand, object=args.object or "sphere", space=space,
                                  noise=args.noise, size=args.size, **robust)
    return config


def _cmd_babble(args) -> int:
    from handle_drake.apps.babbling.babbling import CachedTrial, RunSpec
    from handle_drake.learning import TrialLog, TrialLogError, run_experiment
    from handle_drake.learning.cluster import trial_executor
    from handle_drake.trial.grasp_trial import GraspTrial

    space = _resolve_space(args)
    config = _trial_config(args, space)
    trial = GraspTrial(config)
    if args.ei_stop and args.strategy != "bo":
        raise ValueError(f"--ei-stop {args.ei_stop}: only Bayesian optimisation has a stop rule")
    if args.plot is not None and args.no_plot:
        raise ValueError("--plot and --no-plot contradict each other")
    if args.plot is not None and args.plot.suffix.lower() != ".png":
        raise ValueError(f"--plot: expected a .png file name, got {str(args.plot)!r}")
    options = {"ei_threshold": args.ei_stop} if args.ei_stop else {}
    args.db.parent.mkdir(parents=True, exist_ok=True)
    try:
        TrialLog(args.db).close()  # refuses a corrupt or foreign file before any work
    except TrialLogError as error:  # the lead's CLI maps ValueError to exit status 2
        raise ValueError(f"--db: {error}") from None
    workers = args.workers or 1
    # One local worker runs trials in this process; elsewhere each worker
    # process builds the trial's diagram once (CachedTrial holds the config).
    in_process = args.executor.kind == "local" and workers == 1
    objective = trial if in_process else CachedTrial(config)
    with trial_executor(args.executor, workers, connect_timeout=args.connect_timeout,
                        chunk=args.chunk or 1) as executor:
        batch = bo_batch_size(args.strategy, args.executor, args.workers, executor)
        if batch > 1:
            options["batch_size"] = batch  # batches of parallel trials (kriging believer)
        spec = RunSpec(config, args.strategy, args.seed, n_trials=args.trials,
                       options=tuple(sorted(options.items())))
        run_id = args.run_id or spec.run_id
        print(f"babble: {trial.name}, {args.strategy}, seed {args.seed}, up to {args.trials} "
              f"trials, run {run_id!r} in {args.db} ({args.executor} executor)", flush=True)
        if args.strategy == "bo" and args.workers is None and args.executor.address:
            print(f"BO batches of {batch} trial(s): the cluster's worker threads now "
                  f"(--workers N fixes the batch size, and with it the run)", flush=True)
        result = run_experiment(
            objective, trial.bounds, args.strategy, args.trials, args.seed, args.db,
            executor=executor, progress=not args.no_progress, run_id=run_id,
            objective_name=trial.name, optimizer_options=options)
    print(f"trials: {result.n_done} done, {result.n_failed} failed"
          + (" (BO stopped: expected improvement below threshold)" if result.converged else ""))
    if result.best_x is None:
        failed = [r for r in result.trials if r.status == "failed" and r.error]
        reason = (f": trial {failed[0].index} failed: {' '.join(str(failed[0].error).split())}"
                  if failed else "")
        print(f"no successful trial{reason}"[:600])
        return 1
    names = _PARAMETER_NAMES[space]
    params = ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, result.best_x, strict=True))
    best = max((r for r in result.trials if r.status == "done"), key=lambda r: r.metric)
    clean = best.contacts.get("metric_noiseless") if isinstance(best.contacts, dict) else None
    print(f"best metric {result.best_y:.6g} (trial {best.index}"
          + (f", noiseless {clean:.6g}" if clean is not None and args.noise > 0 else "")
          + f"): {params}")
    if not args.no_plot:
        from handle_drake.apps.babbling.babbling import run_history
        from handle_drake.apps.babbling.plots import plot_run

        path = args.plot or args.db.parent / f"{run_id}.png"
        print(f"figure: {plot_run(spec, run_history(args.db, run_id), path, names)}")
    return 0


def bo_batch_size(strategy: str, executor_spec, workers: int | None, executor) -> int:
    """Trials per BO batch: ``--workers`` when given; on a running cluster
    (``dask://``) without it, the cluster's worker threads when the run starts (so
    that no worker idles); else 1 (the report's sequential BO). 1 for random search
    (it keeps the workers busy on its own)."""
    from handle_drake.learning.cluster import executor_workers

    if strategy != "bo":
        return 1
    if workers is not None:
        return workers
    if executor_spec.address is not None:
        return executor_workers(executor)
    return 1


def _cmd_report(args) -> int:
    from handle_drake.apps.babbling.report import make_report

    if args.grid is not None and args.grid < 2:
        raise ValueError(f"--grid: expected an integer >= 2, got {args.grid}")
    reduced = True if args.reduced else None
    refuse_without_mesh(args, "--mesh-scale")
    summary = make_report(args.out, seeds=args.seeds, trials=args.trials, grid=args.grid,
                          reduced=reduced, workers=args.workers, noise=args.noise,
                          ei_stop=args.ei_stop, meshes=args.mesh, mesh_scale=args.mesh_scale or 1.0,
                          progress=not args.no_progress,
                          executor=args.executor, connect_timeout=args.connect_timeout)
    print((Path(args.out) / "table3.md").read_text())
    for kind, entry in summary["bo_vs_random"].items():
        marks = entry["bo"]["median_best_at"]
        last = max(marks)
        print(f"{kind}: median best after {last} trials: BO {marks[last]:.3f}, random "
              f"{entry['random']['median_best_at'][last]:.3f} (grid max {entry['grid_max']:.3f})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="handle-drake", description="Grasp babbling.")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The two sub-commands on their own (``handle_drake.cli`` registers them too)."""
    from handle_drake.apps.cli_support import run_command

    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
