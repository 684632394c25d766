"""Grasp babbling sample efficiency per object: our BO, random search, gp_minimize, report Table 3.

For each of the seven objects (Barrett hand, 2-D offset space, metric noise
std 0.01): trials until a trial's noiseless BW metric is within 5 %, 10 %,
20 % of the maximum of a dense grid, median over seeds, for

- ``bo``: our BayesianOptimizer with its defaults (report's xi, 10 Sobol
  points, no stop rule: the whole ``--trials`` budget) -- the runs of
  ``handle-drake report``'s Table 3;
- ``bo_v1``: the optimiser's first defaults (``v1_options``: d + 1 Sobol
  points, EI stop rule at 1e-6), in the same run (``--no-v1`` leaves it out);
- ``random``: uniform random search, same budget;
- ``gp_minimize``: scikit-optimize's ``gp_minimize`` (its defaults: 10
  initial points, gp_hedge, Gaussian noise) minimising ``-metric`` on the
  same objective with the same per-trial noise seeds and budget;
- ``report``: Table 3 of the report (one run per object, OpenRave).

The target of issue 5: our BO needs at most half the report's trials-to-5 %
per object (median of 10 seeds).

Trials and grids are shared with ``handle-drake report`` (``--out``, default
``out/report``): whatever the report already ran is read back, not re-run.
gp_minimize runs are cached as JSON under ``<out>/gp_minimize/``.

Grids and BO/random runs go to ``--executor`` (``local``, ``dask``,
``dask://HOST:PORT``; the numbers do not depend on it).

Robust objective (issue 16): ``--placement-error M [--placement-samples K]``
runs every strategy on the robust objective (``GraspTrialConfig.placement_error``:
the mean metric over K wrist placements within M of the planned one), judges
them against the robust grid's maximum, and adds to the table how much the
robust optimum loses in nominal metric against the nominal grid's maximum
(``nominal loss``). Writes ``babbling_robust<M mm>mm<K>.json``.

Grid surrogate (``--surrogate``): every trial is read off the object's
simulated ``--grid`` instead of simulated (``babbling.GridSurrogate``: the
grid's interpolant; with ``--placement-error`` also the robust objective, the
mean of the interpolant over the same placement stencil), with the same metric
noise and per-trial noise seeds as simulated runs. A robust run of 100 trials
on one object costs 100 K simulations; the surrogate needs one grid of grid^2
simulations per object, shared by every optimiser, seed and objective. It
prints the nominal table and the robust one side by side (trials to within
5 / 10 / 20 % of the surrogate's maximum on the grid refined 12x, median of
``--seeds`` for BO, random search and gp_minimize alike) and how much the
robust optimum loses in nominal metric, and checks the surrogate against
simulated trials at the nominal and robust optima and ``--validate-points``
Sobol points per object (nominal and robust, the absolute error). Each run
stops at its first trial within 5 % (the counts are then known). Writes
``babbling_surrogate<grid>[_robust<M mm>mm<K>].json``.

Run: ``python benchmarks/bench_babbling.py [--quick]``; writes
``benchmarks/results/babbling.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses as dc
import hashlib
import json
import math
import multiprocessing
import os
import platform
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

from handle_drake.apps.babbling.babbling import (  # noqa: E402
    FRACTIONS,
    GridSurrogate,
    _config_key,
    _grid_chunk,
    _pool,
    _trial,
    grid_values,
    run_batch,
    run_history,
    trials_to_within,
)
from handle_drake.apps.babbling.report import (  # noqa: E402
    OBJECT_ORDER,
    REPORT_TABLE3,
    ReportSettings,
    _offset_config,
    _random_spec,
    _table3_spec,
)
from handle_drake.apps.cli_support import positive_int  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning.cluster import add_executor_arguments, trial_executor  # noqa: E402
from handle_drake.learning.optim.bo import (  # noqa: E402
    BO_DEFAULTS_VERSION,
    _derived_seed,
    v1_options,
)
from handle_drake.learning.optim.factory import make_optimizer  # noqa: E402
from handle_drake.trial.grasp_trial import GraspTrial  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "babbling.json"


def gp_minimize_run(config, seed: int, n_calls: int, cache: Path) -> dict:
    """One gp_minimize run on the grasp trial (in a worker); cached as JSON."""
    if cache.exists():
        data = json.loads(cache.read_text())
        if len(data["noiseless"]) >= n_calls:
            return data
    from skopt import gp_minimize

    trial = _trial(config)
    noiseless, observed, sim_time = [], [], []

    def objective(x):
        k = len(observed)  # the same per-trial noise seed as run_experiment's trial k
        start = time.perf_counter()
        outcome = trial.evaluate(np.asarray(x, dtype=float), seed=_derived_seed(seed, k))
        sim_time.append(time.perf_counter() - start)
        observed.append(outcome.metric)
        noiseless.append(outcome.metric_noiseless)
        return -outcome.metric

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # skopt warns about repeated points near the end
        result = gp_minimize(objective, [tuple(map(float, b)) for b in trial.bounds],
                             n_calls=n_calls, random_state=seed)
    total = time.perf_counter() - start
    data = dict(X=np.asarray(result.x_iters).tolist(), observed=observed, noiseless=noiseless,
                wall_time_s=total, sim_time_s=float(sum(sim_time)))
    _write_json(cache, data)
    return data


def _write_json(path: Path, data) -> None:
    """``data`` as JSON at ``path``, whole or not at all (a killed run leaves no half file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data))
    os.replace(tmp, path)


def _overhead_per_trial(db, spec) -> float:
    """Mean optimiser time between two trials of a logged run (s), from the log's timestamps."""
    from handle_drake.learning import TrialLog

    with TrialLog(db) as log:
        records = log.trials(spec.run_id)[: spec.n_trials]
    gaps = [b.started_at - a.finished_at for a, b in zip(records, records[1:], strict=False)
            if a.finished_at and b.started_at]
    return float(np.mean(gaps)) if gaps else math.nan


def _summary(hits):
    hits = np.asarray(hits, dtype=float)
    return dict(median=[float(np.median(hits[:, j])) for j in range(len(FRACTIONS))],
                reached=[int(np.sum(np.isfinite(hits[:, j]))) for j in range(len(FRACTIONS))],
                per_seed=hits.tolist())


def _fmt(value, budget):
    return f">{budget}" if not math.isfinite(value) else f"{value:g}"


def _cells(summary, budget) -> list[str]:
    """A :func:`_summary`'s medians per fraction, "(k)" when only k seeds got there."""
    return [_fmt(m, budget) + ("" if r == len(summary["per_seed"]) or not math.isfinite(m)
                               else f"({r})")
            for m, r in zip(summary["median"], summary["reached"], strict=True)]


def _print_table(header, rows) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    print("  ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for row in rows:
        print("  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)))


# ------------------------------------------------------------------ surrogate
SURROGATE_METHODS = ("bo", "random", "gp_minimize")
#: gp_minimize's default n_initial_points: it refuses fewer calls.
SKOPT_MIN_CALLS = 10


def surrogate_run(surrogate: GridSurrogate, method: str, seed: int, n_trials: int,
                  target: float | None = None) -> dict:
    """One run of ``method`` (``SURROGATE_METHODS``) on a grid surrogate, in this process.

    Trial ``k`` observes ``surrogate(x, seed=_derived_seed(seed, k))``: the
    noise a logged run (``run_experiment``) or ``gp_minimize_run`` of simulated
    trials with this seed would add. BO and random search are the engine's
    optimisers with their defaults; gp_minimize is scikit-optimize's with
    its defaults, minimising ``-metric``. With ``target`` the run stops after
    its first trial whose noiseless value is within ``min(FRACTIONS)`` of it:
    every count of the table is known by then.
    """
    if method not in SURROGATE_METHODS:
        raise ValueError(f"method: expected one of {SURROGATE_METHODS}, got {method!r}")
    X, observed, noiseless = [], [], []
    goal = math.inf if target is None else target - min(FRACTIONS) * abs(target)

    def trial(x) -> float:
        x = np.asarray(x, dtype=float)
        y = surrogate(x, seed=_derived_seed(seed, len(observed)))
        X.append(x.tolist())
        observed.append(y)
        noiseless.append(surrogate.noiseless(x))
        return y

    start = time.perf_counter()
    if method == "gp_minimize":
        from skopt import gp_minimize

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # skopt warns about repeated points near the end
            gp_minimize(lambda x: -trial(x), [tuple(map(float, b)) for b in surrogate.bounds],
                        n_calls=n_trials, random_state=seed,
                        callback=lambda _: noiseless[-1] >= goal)
    else:
        optimizer = make_optimizer(method, surrogate.bounds, seed)
        while len(observed) < n_trials and not (noiseless and noiseless[-1] >= goal):
            x = optimizer.ask()
            optimizer.tell(x, trial(x))
    return dict(X=X, observed=observed, noiseless=noiseless,
                wall_time_s=time.perf_counter() - start)


def _run_jobs(fn, jobs: dict, workers: int, progress: str | None = None) -> dict:
    """``{key: fn(*args)}`` for ``jobs`` (key -> args): in this process with one worker,
    else on ``babbling._pool``'s spawn pool of ``workers`` (printing ``progress`` counts)."""
    pool = _pool(workers) if jobs else None
    if pool is None:
        return {key: fn(*args) for key, args in jobs.items()}
    try:
        futures = {pool.submit(fn, *args): key for key, args in jobs.items()}
        results = {}
        for i, future in enumerate(as_completed(futures), 1):
            results[futures[future]] = future.result()
            if progress and (i % 20 == 0 or i == len(jobs)):
                print(f"{progress} {i}/{len(jobs)}", flush=True)
        return results
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _surrogate_job(surrogate, method, seed, n_trials, target, cache=None):
    """One surrogate run, read back from ``cache`` (JSON) when it holds it."""
    if cache is not None and cache.exists():
        return json.loads(cache.read_text())
    run = surrogate_run(surrogate, method, seed, n_trials, target)
    if cache is not None:
        _write_json(cache, run)
    return run


def _surrogate_key(surrogate: GridSurrogate, *settings) -> str:
    """What a surrogate run depends on: the grid, noise, stencil and the run's settings."""
    digest = hashlib.sha1(json.dumps([surrogate.noise, surrogate.stencil.tolist(),
                                      *settings]).encode())
    for axis in surrogate.axes:
        digest.update(axis.tobytes())
    digest.update(surrogate.values.tobytes())
    return digest.hexdigest()[:12]


def surrogate_tables(grids: dict, *, seeds, n_trials: int, noise: float,
                     placement_error: float = 0.0, placement_samples: int = 5,
                     methods=SURROGATE_METHODS, workers: int = 1, refine: int = 12,
                     objectives=("nominal", "robust"), cache_dir=None) -> dict:
    """Trials to within 5 / 10 / 20 % of the optimum per object, method and objective.

    ``grids``: object -> ``(axes, values)`` of its simulated nominal grid.
    Objectives: ``"nominal"`` (the grid's interpolant) and, with
    ``placement_error`` > 0, ``"robust"`` (its mean over the placement
    stencil). ``f*`` is each objective's maximum on the grid with every cell
    cut ``refine`` times (``GridSurrogate.maximum``); the robust entry also gives the nominal
    value at the robust optimum and the nominal loss ``1 - that / nominal f*``.
    The optimisers run on the ``objectives`` named (the other's optimum is
    still given). Runs go to a spawn pool of ``workers`` processes (the
    numbers do not depend on it); with ``cache_dir`` each run is kept there
    as JSON and read back on the next call (an interrupted table resumes).
    """
    stencils = {"nominal": {}}
    if placement_error > 0:
        stencils["robust"] = dict(placement_error=placement_error,
                                  placement_samples=placement_samples)
    surrogates = {(name, kind): GridSurrogate(*grids[kind], noise=noise, **robust)
                  for name, robust in stencils.items() for kind in grids}
    optima = {key: s.maximum(refine) for key, s in surrogates.items()}
    jobs = [(key, method, seed) for key in surrogates if key[0] in objectives
            for method in methods for seed in seeds]

    def cache(key, method, seed):
        if cache_dir is None:
            return None
        tag = _surrogate_key(surrogates[key], method, seed, n_trials, optima[key][1],
                             min(FRACTIONS), BO_DEFAULTS_VERSION)
        return Path(cache_dir) / f"{key[1]}-{key[0]}-{method}-seed{seed}-{tag}.json"

    runs = _run_jobs(_surrogate_job, {job: (surrogates[job[0]], *job[1:], n_trials,
                                            optima[job[0]][1], cache(*job)) for job in jobs},
                     workers, progress="surrogate runs")
    tables = {}
    for name, kind in surrogates:
        x_star, f_star = optima[name, kind]
        entry = dict(f_star=f_star, x_star=x_star.tolist())
        if name == "robust":
            nominal = surrogates["nominal", kind]
            entry["nominal_at_optimum"] = nominal.noiseless(x_star)
            f_nominal = optima["nominal", kind][1]
            entry["nominal_loss"] = (1.0 - entry["nominal_at_optimum"] / f_nominal
                                     if f_nominal > 0 else math.nan)
        for method in methods if name in objectives else ():
            histories = [runs[(name, kind), method, seed] for seed in seeds]
            entry[method] = _summary([trials_to_within(h["noiseless"], f_star)
                                      for h in histories])
            entry[method]["overhead_per_trial_s"] = float(np.mean(
                [h["wall_time_s"] / len(h["noiseless"]) for h in histories]))
        tables.setdefault(name, {})[kind] = entry
    return tables


def bo_verdicts(entry: dict) -> dict:
    """BO against random search and gp_minimize on one object: trials to within 5 %.

    "ahead": a smaller median; with both medians past the budget, more
    seeds that got there. "level": the same median (or, past the budget, as
    many seeds). Returns ``{"vs_random": ..., "vs_gp_minimize": ...}`` with
    values ``"ahead"``, ``"level"`` or ``"behind"``.
    """
    def compare(ours, theirs):
        a, b = ours["median"][0], theirs["median"][0]
        if a == b == math.inf:
            a, b = -ours["reached"][0], -theirs["reached"][0]
        return "ahead" if a < b else "level" if a == b else "behind"

    return {f"vs_{m}": compare(entry["bo"], entry[m]) for m in ("random", "gp_minimize")
            if m in entry}


def validate_surrogate(configs: dict, grids: dict, points: dict, *, placement_error: float,
                       placement_samples: int, workers: int = 1, cache_dir=None) -> dict:
    """Simulated trials against the surrogate at ``points[kind]`` (n, 2) per object.

    Nominal: one trial per point against the interpolant; robust (with
    ``placement_error`` > 0): the robust trial (``placement_samples``
    simulations) against the surrogate's stencil mean. Returns per object the
    points, both values and the absolute errors. With ``cache_dir`` each
    simulated value is kept (keyed by the trial's config, simulation code
    included, and the point) and read back.
    """
    jobs = {}
    for kind, X in points.items():
        jobs[kind, "nominal"] = (configs[kind], np.asarray(X, dtype=float))
        if placement_error > 0:
            jobs[kind, "robust"] = (dc.replace(configs[kind], placement_error=placement_error,
                                               placement_samples=placement_samples),
                                    np.asarray(X, dtype=float))

    def cache(config, x):
        if cache_dir is None:
            return None
        tag = hashlib.sha1((_config_key(config) + x.tobytes().hex()).encode()).hexdigest()[:12]
        return Path(cache_dir) / f"{GraspTrial(config).name}-{tag}.json"

    simulated = {key: np.full(len(X), np.nan) for key, (_, X) in jobs.items()}
    todo = {}  # (key, i) -> its cache file (or None)
    for key, (config, X) in jobs.items():
        for i, x in enumerate(X):
            path = cache(config, x)
            if path is not None and path.exists():
                simulated[key][i] = json.loads(path.read_text())["metric"]
            else:
                todo[key, i] = path
    # One point per job: the robust ones are K times dearer.
    done = _run_jobs(_grid_chunk, {(key, i): (jobs[key][0], jobs[key][1][i:i + 1])
                                   for key, i in todo}, workers)
    for (key, i), values in done.items():
        simulated[key][i] = values[0]
        if todo[key, i] is not None:
            _write_json(todo[key, i], dict(metric=float(values[0])))
    out = {}
    for (kind, name), values in simulated.items():
        robust = (dict(placement_error=placement_error, placement_samples=placement_samples)
                  if name == "robust" else {})
        predicted = GridSurrogate(*grids[kind], **robust).noiseless(points[kind])
        error = np.abs(np.asarray(values) - predicted)
        out.setdefault(kind, dict(points=np.asarray(points[kind]).tolist()))[name] = dict(
            simulated=np.asarray(values).tolist(), surrogate=predicted.tolist(),
            abs_error=error.tolist(), max_abs_error=float(error.max()),
            mean_abs_error=float(error.mean()))
    return out


def surrogate_main(args, settings, objects, out: Path) -> int:
    """``--surrogate``: the nominal and robust tables on the simulated grids' surrogates."""
    from scipy.stats import qmc

    if not args.no_v1:
        print("(--surrogate runs bo with its current defaults only; bo_v1 is left out)")
    if args.skopt_seeds and args.skopt_seeds != settings.seeds:
        raise SystemExit("--skopt-seeds: --surrogate runs every method on the same --seeds")
    methods = tuple(m for m in SURROGATE_METHODS if not (args.no_skopt and m == "gp_minimize"))
    robust = dict(placement_error=args.placement_error,
                  placement_samples=args.placement_samples)
    seeds = list(range(args.seed_offset, args.seed_offset + settings.seeds))
    configs = {kind: _offset_config(kind, 0.0) for kind in objects}
    timings = {}
    start = time.perf_counter()
    grids = {kind: grid_values(configs[kind], settings.grid, out / "grids", settings.workers,
                               progress=True) for kind in objects}
    timings["grids_s"] = time.perf_counter() - start
    start = time.perf_counter()
    tables = surrogate_tables(grids, seeds=seeds, n_trials=settings.trials, noise=settings.noise,
                              methods=methods, workers=settings.workers, **robust,
                              objectives=("robust",) if args.robust_only else ("nominal", "robust"),
                              cache_dir=out / "surrogate_runs")
    timings["surrogate_runs_s"] = time.perf_counter() - start
    # Simulated check points: both optima and a few Sobol points of the box.
    points = {}
    for kind in objects:
        X = [tables[name][kind]["x_star"] for name in tables]
        if args.validate_points:
            bounds = GridSurrogate(*grids[kind]).bounds
            sobol = qmc.Sobol(2, seed=7).random(args.validate_points)
            X += qmc.scale(sobol, bounds[:, 0], bounds[:, 1]).tolist()
        points[kind] = np.array(X)
    start = time.perf_counter()
    validation = validate_surrogate(configs, grids, points, workers=settings.workers, **robust,
                                    cache_dir=out / "validation")
    timings["validation_s"] = time.perf_counter() - start

    budget = settings.trials
    printed = []
    for name, table in tables.items():
        if args.robust_only and name == "nominal":
            continue
        print(f"\n{name} objective on the {settings.grid}x{settings.grid} grid surrogate"
              + (f" (mean over {args.placement_samples} placements within "
                 f"{args.placement_error * 1e3:g} mm)" if name == "robust" else "")
              + f": trials to within 5 / 10 % of f* (the surrogate's maximum, cells cut 12x), "
              f"median "
              f"of {len(seeds)} seeds from {args.seed_offset}, budget {budget}, noise std "
              f"{settings.noise}; \"(k)\": only k seeds got there")
        header = ["object", "f*"] + [f"{m} {p}" for m in methods for p in ("5%", "10%")]
        header += ["BO vs random", "BO vs gp_min"] + (
            ["nominal at x*", "nominal loss"] if name == "robust" else [])
        header += ["|sim - surr| max"]
        rows = []
        for kind, entry in table.items():
            verdict = bo_verdicts(entry)
            entry["verdict"] = verdict
            row = [kind, f"{entry['f_star']:.3f}"]
            for method in methods:
                row += _cells(entry[method], budget)[:2]
            row += [verdict.get("vs_random", "-"), verdict.get("vs_gp_minimize", "-")]
            if name == "robust":
                row += [f"{entry['nominal_at_optimum']:.3f}", f"{entry['nominal_loss']:.1%}"]
            row += [f"{validation[kind][name]['max_abs_error']:.3f}"]
            rows.append(row)
        _print_table(header, rows)
        printed += [{"objective": name, **dict(zip(header, row, strict=True))} for row in rows]
        ahead_random = sum(e["verdict"]["vs_random"] == "ahead" for e in table.values())
        level_gp = sum(e["verdict"].get("vs_gp_minimize") in ("ahead", "level")
                       for e in table.values())
        print(f"BO ahead of random on {ahead_random} of {len(table)}; ahead of or level with "
              f"gp_minimize on {level_gp} of {len(table)}")
    print("\nsurrogate against simulated trials (absolute error, per object: mean / max over "
          f"{len(next(iter(points.values())))} points): " + "; ".join(
              f"{kind} " + ", ".join(f"{name} {v['mean_abs_error']:.3f}/{v['max_abs_error']:.3f}"
                                     for name, v in entry.items() if name != "points")
              for kind, entry in validation.items()))
    results = RESULTS.with_name(
        f"babbling_surrogate{settings.grid}"
        + (f"_robust{args.placement_error * 1e3:g}mm{args.placement_samples}"
           if args.placement_error else "")
        # A subset of the objects does not overwrite the whole table.
        + ("" if tuple(objects) == OBJECT_ORDER else "_" + "+".join(objects)) + ".json")
    results = args.results_run.output(results)  # out/results/ below the published budget
    results.parent.mkdir(parents=True, exist_ok=True)
    results.write_text(json.dumps(dict(
        surrogate=True, robust=robust, settings=dc.asdict(settings), seeds=seeds,
        methods=methods, fractions=FRACTIONS, tables=tables, validation=validation,
        timings=timings, python=sys.version.split()[0], machine=platform.machine(),
        cpu_count=os.cpu_count(), load_average=os.getloadavg()), indent=1,
        default=lambda v: str(v)).replace("Infinity", '"inf"'))
    print(f"\nwritten {results}")
    args.results_run.finish(printed, json_path=results, write_json=False)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="3 objects, 2 seeds, 15 trials, 9x9 grid (own folder)")
    parser.add_argument("--out", type=Path, default=None,
                        help="trial log and grid cache folder (default out/report)")
    parser.add_argument("--seeds", type=positive_int, default=None,
                        help="seeds for BO and random (10)")
    parser.add_argument("--skopt-seeds", type=positive_int, default=None,
                        help="seeds for gp_minimize (default 5: ~0.3 s overhead per iteration)")
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument("--no-v1", action="store_true",
                        help="leave out the BO runs with the first defaults (bo_v1)")
    parser.add_argument("--seed-offset", type=int, default=0,
                        help="first seed (tuning used seeds 100-109 on three objects)")
    parser.add_argument("--objects", default=None,
                        help="comma-separated subset of the seven objects")
    parser.add_argument("--no-skopt", action="store_true", help="leave out gp_minimize")
    parser.add_argument("--placement-error", type=float, default=0.0, metavar="M",
                        help="robust objective: mean metric over placements within M metres")
    parser.add_argument("--placement-samples", type=int, default=5, metavar="K",
                        help="placements per trial of the robust objective (default 5)")
    parser.add_argument("--trials", type=positive_int, default=None, help="trials per run (100)")
    parser.add_argument("--grid", type=positive_int, default=None,
                        help="grid points per dimension (41)")
    parser.add_argument("--surrogate", action="store_true",
                        help="run the optimisers on the simulated grid's surrogate (nominal and, "
                             "with --placement-error, robust tables side by side)")
    parser.add_argument("--robust-only", action="store_true",
                        help="--surrogate: run the optimisers on the robust objective only")
    parser.add_argument("--validate-points", type=int, default=2, metavar="V",
                        help="--surrogate: Sobol points per object simulated to check the "
                             "surrogate, besides both optima (default 2)")
    add_executor_arguments(parser)  # grids and BO/random runs; gp_minimize stays local
    add_page_arguments(parser, "babbling", published={"quick": False, "seeds": 10, "trials": 100,
                                                  "grid": 41, "skopt_seeds": 5, "objects": False})
    args = parser.parse_args(argv)
    run = args.results_run = ResultsRun(
        "Motor babbling: trials to within 5 / 10 / 20 % of the optimum per object", args)

    if args.quick:
        settings = ReportSettings(seeds=2, trials=15, grid=9, workers=args.workers)
        objects = ("sphere", "mug", "star_prism")
        out = args.out or Path("out/bench_babbling_quick")
        skopt_seeds = args.skopt_seeds or 2
    else:
        settings = ReportSettings(workers=args.workers)
        objects = OBJECT_ORDER
        out = args.out or Path("out/report")
        skopt_seeds = args.skopt_seeds or 5
    if args.objects:
        objects = tuple(args.objects.split(","))
        unknown = sorted(set(objects) - set(OBJECT_ORDER))
        if unknown:
            parser.error(f"--objects: unknown {unknown}, expected some of {OBJECT_ORDER}")
    if args.seeds:
        settings = dc.replace(settings, seeds=args.seeds)
    if args.trials:
        settings = dc.replace(settings, trials=args.trials)
    if args.grid:
        settings = dc.replace(settings, grid=args.grid)
    if not args.no_skopt and settings.trials < SKOPT_MIN_CALLS:  # before any grid is computed
        parser.error(f"--trials {settings.trials}: gp_minimize needs at least "
                     f"{SKOPT_MIN_CALLS} (its initial random points); give --trials >= "
                     f"{SKOPT_MIN_CALLS} or --no-skopt")
    if args.validate_points < 0:
        parser.error(f"--validate-points: expected an integer >= 0, got {args.validate_points}")
    if args.robust_only and not (args.surrogate and args.placement_error):
        parser.error("--robust-only: needs --surrogate and --placement-error")
    if args.surrogate and args.executor.kind != "local":
        parser.error(f"--surrogate: runs on this machine only (--executor local), got "
                     f"--executor {args.executor.kind}")
    if args.surrogate:
        return surrogate_main(args, settings, objects, out)
    robust = dict(placement_error=args.placement_error,
                  placement_samples=args.placement_samples if args.placement_error else 1)

    def config_of(kind, noise):
        """The object's 2-D offset trial, on the robust objective when asked."""
        return dc.replace(_offset_config(kind, noise), **robust)

    def robust_spec(spec):
        return dc.replace(spec, config=dc.replace(spec.config, **robust))
    db = out / "babble.sqlite"
    timings = {}
    seeds = range(args.seed_offset, args.seed_offset + settings.seeds)
    bo = {k: [robust_spec(_table3_spec(k, s, settings)) for s in seeds] for k in objects}
    rnd = {k: [robust_spec(_random_spec(k, s, settings)) for s in seeds] for k in objects}
    v1 = {} if args.no_v1 else {k: [dc.replace(spec, options=tuple(sorted(
        v1_options(2).items()))) for spec in bo[k]] for k in objects}

    # `local` keeps its pools of `workers` processes (a whole run per process).
    cluster, executor = contextlib.ExitStack(), None
    if args.executor.kind == "dask":
        executor = cluster.enter_context(trial_executor(
            args.executor, settings.workers, connect_timeout=args.connect_timeout))
    with cluster:
        start = time.perf_counter()
        truth = {kind: grid_values(config_of(kind, 0.0), settings.grid, out / "grids",
                                   settings.workers, progress=True, executor=executor)
                 for kind in objects}
        # The robust optimum's nominal metric against the nominal optimum (same grid).
        nominal = ({kind: grid_values(_offset_config(kind, 0.0), settings.grid, out / "grids",
                                      settings.workers, progress=True, executor=executor)
                    for kind in objects} if args.placement_error else truth)
        timings["grids_s"] = time.perf_counter() - start
        start = time.perf_counter()
        # Old defaults first (they stop early, so are cheap), then the new ones.
        run_batch([s for k in objects for s in v1.get(k, []) + bo[k] + rnd[k]], db,
                  settings.workers, executor=executor)
        timings["bo_and_random_runs_s"] = time.perf_counter() - start

    start = time.perf_counter()
    jobs = [] if args.no_skopt else [(k, s) for k in objects
                                     for s in range(args.seed_offset,
                                                    args.seed_offset + skopt_seeds)]
    skopt = {k: [] for k in objects}
    pool = ProcessPoolExecutor(settings.workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=pin_blas)
    with pool:
        futures = {pool.submit(gp_minimize_run, config_of(k, settings.noise), s,
                               settings.trials,
                               out / "gp_minimize" / (f"{k}-noise{settings.noise:g}-seed{s}"
                                                        f"-sim{_config_key(config_of(k, 0.0))}"
                                                        ".json")):
                   (k, s) for k, s in jobs}
        for i, future in enumerate(as_completed(futures), 1):
            k, s = futures[future]
            skopt[k].append(future.result())
            print(f"gp_minimize {i}/{len(jobs)}: {k} seed {s}", flush=True)
    timings["gp_minimize_runs_s"] = time.perf_counter() - start

    budget = settings.trials

    methods = [("bo", bo)] + ([("bo_v1", v1)] if v1 else [])
    rows, per_object = [], {}
    for kind in objects:
        f_star = float(np.max(truth[kind][1]))
        nominal_max = float(np.max(nominal[kind][1]))
        at_robust = float(nominal[kind][1].flat[int(np.argmax(truth[kind][1]))])
        entry = dict(grid_max=f_star, report=list(REPORT_TABLE3[kind]),
                     nominal_grid_max=nominal_max, nominal_at_robust_optimum=at_robust,
                     nominal_loss=1.0 - at_robust / nominal_max if nominal_max > 0 else math.nan)
        for name, specs in methods:
            hist = [run_history(db, spec) for spec in specs[kind]]
            entry[name] = _summary([trials_to_within(h.noiseless, f_star) for h in hist])
            entry[name]["total_median"] = float(np.median([len(h.X) for h in hist]))
            entry[name]["best_median"] = float(np.median([np.nanmax(h.noiseless)
                                                          for h in hist]))
            entry[name]["overhead_per_trial_s"] = float(np.nanmean(
                [_overhead_per_trial(db, spec) for spec in specs[kind]]))
            entry[name]["sim_per_trial_s"] = float(np.nanmean(
                np.concatenate([h.wall_time for h in hist])))
        rnd_hist = [run_history(db, spec) for spec in rnd[kind]]
        entry["random"] = _summary([trials_to_within(h.noiseless, f_star) for h in rnd_hist])
        entry["random"]["best_median"] = float(np.median([np.max(h.noiseless)
                                                          for h in rnd_hist]))
        if skopt[kind]:
            entry["gp_minimize"] = _summary([trials_to_within(r["noiseless"], f_star)
                                             for r in skopt[kind]])
            entry["gp_minimize"]["best_median"] = float(np.median([np.max(r["noiseless"])
                                                                   for r in skopt[kind]]))
            entry["gp_minimize"]["overhead_per_trial_s"] = float(np.mean(
                [(r["wall_time_s"] - r["sim_time_s"]) / len(r["noiseless"])
                 for r in skopt[kind]]))
        report_5 = REPORT_TABLE3[kind][1]
        ours_5 = entry["bo"]["median"][0]
        entry["bo_5pct_over_report"] = ours_5 / report_5
        entry["target_met"] = bool(ours_5 <= report_5 / 2)
        per_object[kind] = entry
        row = [kind, f"{f_star:.3f}", *_cells(entry["bo"], budget)]
        if v1:
            row += _cells(entry["bo_v1"], budget)
        row += _cells(entry["random"], budget)
        if "gp_minimize" in entry:
            row += _cells(entry["gp_minimize"], budget)
        row += [*map(str, REPORT_TABLE3[kind][1:]), f"{entry['bo_5pct_over_report']:.2f}",
                "yes" if entry["target_met"] else "NO"]
        if args.placement_error:
            row += [f"{nominal_max:.3f}", f"{entry['nominal_loss']:.1%}"]
        rows.append(row)

    header = ["object", "f*", "BO 5%", "10%", "20%"]
    if v1:
        header += ["BOv1 5%", "10%", "20%"]
    header += ["rand 5%", "10%", "20%"]
    if any(skopt.values()):
        header += ["gp_min 5%", "10%", "20%"]
    header += ["rep 5%", "10%", "20%", "BO/rep 5%", "<=1/2"]
    if args.placement_error:
        header += ["nominal f*", "nominal loss"]
    print(f"\nTrials to within 5/10/20 % of the grid maximum ({settings.grid}x{settings.grid}), "
          f"median of {settings.seeds} seeds from {args.seed_offset} (gp_minimize: "
          f"{0 if args.no_skopt else skopt_seeds}), budget {settings.trials}, noise std "
          f"{settings.noise}; \"(k)\": only k seeds got there"
          + (f"; robust objective: mean over {robust['placement_samples']} placements within "
             f"{args.placement_error * 1e3:g} mm (f* is the robust grid's maximum; nominal "
             "loss: 1 - nominal metric at the robust optimum / nominal f*)"
             if args.placement_error else ""))
    _print_table(header, rows)
    print("\nbest noiseless metric found (median): " + ", ".join(
        f"{k}: " + " / ".join(f"{m} {e[m]['best_median']:.3f}"
                             for m in ("bo", "bo_v1", "random", "gp_minimize") if m in e)
        + f" (f* {e['grid_max']:.3f})" for k, e in per_object.items()))
    print("trials per run (median): " + ", ".join(
        f"{k}: " + " / ".join(f"{m} {e[m]['total_median']:g}" for m, _ in methods)
        for k, e in per_object.items()))
    print("optimiser overhead per trial (s): " + ", ".join(
        f"{k}: BO {e['bo']['overhead_per_trial_s']:.3f}"
        + (f", gp_minimize {e['gp_minimize']['overhead_per_trial_s']:.3f}"
           if "gp_minimize" in e else "") for k, e in per_object.items()))
    print(f"simulated trial wall time (s, BO runs): "
          f"{np.mean([e['bo']['sim_per_trial_s'] for e in per_object.values()]):.3f}")

    results = (RESULTS.with_name(f"babbling_robust{args.placement_error * 1e3:g}mm"
                                 f"{robust['placement_samples']}.json")
               if args.placement_error else RESULTS)
    results = run.output(results)  # out/results/ below the published budget
    results.parent.mkdir(parents=True, exist_ok=True)
    results.write_text(json.dumps(dict(robust=robust,
        quick=args.quick, settings=dc.asdict(settings), skopt_seeds=skopt_seeds,
        seed_offset=args.seed_offset, bo_v1_options=v1_options(2) if v1 else None,
        fractions=FRACTIONS, objects=per_object, timings=timings,
        python=sys.version.split()[0], machine=platform.machine(), cpu_count=os.cpu_count(),
        load_average=os.getloadavg()), indent=1,
        default=lambda v: str(v)).replace("Infinity", '"inf"'))
    print(f"\nwritten {results}")
    run.finish([dict(zip(header, row, strict=True)) for row in rows], json_path=results,
               write_json=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
