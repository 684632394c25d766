"""Bayesian optimisation: per-iteration overhead and sample efficiency, side by side.

Part 1, overhead of one BO iteration (hyperparameter fit + DIRECT maximisation
of EI, the objective itself excluded) with n observations in d dimensions:

- ``ours, refit``: marginal-likelihood fit (scikit-learn, 3 starts) + DIRECT
  (500 d evaluations) on our fast point predictor;
- ``ours, cached``: the same iteration between two refits (the GP is only
  re-conditioned: one Cholesky factorisation) -- most iterations once
  n > 40 under the default schedule;
- ``ours, amortised``: the average under the default refit schedule;
- ``sklearn-only``: same fit, same DIRECT budget, but EI evaluated through
  ``GaussianProcessRegressor.predict`` + ``scipy.stats.norm`` (no fast path);
- ``gp_minimize``: scikit-optimize's marginal cost of one more iteration
  (its defaults: GP refit each step, gp_hedge, sampling + L-BFGS).

Part 2, sample efficiency on functions with known optima (maximisation form):
trials until the best value is within 20 %, 10 %, 5 %, 1 % of the optimum
(regret normalised by the function's range over the box), median over seeds;
BO with the report's xi = sigma_f^2/100 and with xi = 0, random search, and
gp_minimize (EI). BO runs ignore the EI stopping rule (``ei_threshold=0``) so
that every run has the same budget; the trial at which the default rule would
have stopped is reported separately.

Run: ``python benchmarks/bench_bayesopt.py [--quick]``; writes
``benchmarks/results/bayesopt.json``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402
from scipy.stats import norm, qmc  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.learning.acquisition import (  # noqa: E402
    default_xi,
    expected_improvement_point,
    maximize_acquisition,
)
from handle_drake.learning.gp import GaussianProcess  # noqa: E402
from handle_drake.learning.optim.bo import BayesianOptimizer, RandomSearch  # noqa: E402
from handle_drake.learning.test_functions import Branin, Hartmann3, Hartmann6  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "bayesopt.json")
THRESHOLDS = (0.20, 0.10, 0.05, 0.01)


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


# --------------------------------------------------------------------- part 1
def overhead_case(n, d, repeats):
    function = Branin() if d == 2 else Hartmann6()
    m = int(np.ceil(np.log2(n)))
    U = qmc.Sobol(d, scramble=True, rng=n).random_base2(m)[:n]
    y = function(function.bounds[:, 0] + U * (function.bounds[:, 1] - function.bounds[:, 0]))
    maxfun = 500 * d

    def fit():
        return GaussianProcess(seed=0, n_restarts=2).fit(U, y)

    gp = fit()
    best = float(y.max())
    xi = default_xi(gp.hyperparameters.signal_variance, gp.y_scale)

    def condition():
        return GaussianProcess().fit(U, y, hyperparameters=gp.hyperparameters)

    def direct_fast():
        predict_point = gp.point_predictor()

        def ei(u):
            mu, var = predict_point(u)
            return expected_improvement_point(mu, var, best, xi)

        return maximize_acquisition(ei, d, maxfun=maxfun)

    model = gp.sklearn_model
    mean0, scale, noise = float(np.mean(y)), gp.y_scale, gp.hyperparameters.noise_variance

    def direct_sklearn():
        def ei(u):
            m, s = model.predict(u[None, :], return_std=True)
            mu = mean0 + scale * m[0]
            sigma = np.sqrt(max((scale * s[0]) ** 2 - noise, 0.0))
            if sigma == 0:
                return max(mu - best - xi, 0.0)
            z = (mu - best - xi) / sigma
            return (mu - best - xi) * norm.cdf(z) + sigma * norm.pdf(z)

        return maximize_acquisition(ei, d, maxfun=maxfun)

    t_fit = best_of(fit, repeats)
    t_condition = best_of(condition, max(repeats, 3))
    t_direct = best_of(direct_fast, repeats)
    t_direct_sklearn = best_of(direct_sklearn, 1)
    # default schedule: refit every step up to 40, then each time n grows by 10 %
    refits_per_trial = 1.0 if n <= 40 else 1.0 / max(1, int(np.ceil(0.1 * n)))
    row = {
        "n": n,
        "d": d,
        "direct_maxfun": maxfun,
        "fit_ms": 1e3 * t_fit,
        "condition_ms": 1e3 * t_condition,
        "direct_fast_ms": 1e3 * t_direct,
        "direct_sklearn_ms": 1e3 * t_direct_sklearn,
        "ours_refit_ms": 1e3 * (t_fit + t_condition + t_direct),
        "ours_cached_ms": 1e3 * (t_condition + t_direct),
        "ours_amortised_ms": 1e3 * (t_condition + t_direct + refits_per_trial * t_fit),
        "sklearn_only_ms": 1e3 * (t_fit + t_direct_sklearn),
        "gp_minimize_ms": gp_minimize_overhead(function, U, y) * 1e3,
    }
    return row


def gp_minimize_overhead(function, U, y):
    """Marginal cost of one more gp_minimize iteration with n points given as x0/y0."""
    try:
        from skopt import gp_minimize
    except ImportError:
        return float("nan")
    X = function.bounds[:, 0] + U * (function.bounds[:, 1] - function.bounds[:, 0])
    dims = [tuple(map(float, b)) for b in function.bounds]

    def run(calls):
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gp_minimize(
                lambda x: float(-function(np.array(x))),
                dims,
                n_calls=calls,
                x0=X.tolist(),
                y0=(-y).tolist(),
                n_initial_points=0,
                random_state=0,
                acq_func="EI",
            )
        return time.perf_counter() - start

    return (run(3) - run(1)) / 2.0


# --------------------------------------------------------------------- part 2
def trials_to_reach(function, values):
    regret = function.normalized_regret(
        np.fmax.accumulate(np.where(np.isnan(values), -np.inf, values))
    )
    out = {}
    for threshold in THRESHOLDS:
        hit = np.flatnonzero(regret <= threshold)
        out[threshold] = int(hit[0]) + 1 if hit.size else None
    return out


def run_ours(function, strategy, budget, seed, xi="default"):
    if strategy == "random":
        optimizer = RandomSearch(function.bounds, seed)
    else:
        optimizer = BayesianOptimizer(function.bounds, seed, xi=None if xi == "default" else xi)
    values, stop_at = [], None
    for trial in range(budget):
        x = optimizer.ask()
        if strategy == "bo" and optimizer.converged and stop_at is None:
            stop_at = trial  # the default rule would have stopped here, before trial + 1
        value = function(x)
        optimizer.tell(x, value)
        values.append(value)
    return np.array(values), stop_at


def run_gp_minimize(function, budget, seed):
    from skopt import gp_minimize

    dims = [tuple(map(float, b)) for b in function.bounds]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = gp_minimize(
            lambda x: float(-function(np.array(x))),
            dims,
            n_calls=budget,
            random_state=seed,
            acq_func="EI",
        )
    return -np.array(result.func_vals), None


def median_trials(counts, budget):
    finite = [c if c is not None else np.inf for c in counts]
    m = float(np.median(finite))
    return None if not np.isfinite(m) else m


def efficiency(functions, seeds, have_skopt):
    rows = []
    for function, budget in functions:
        f, b = function, budget
        methods = [
            ("bo (xi=sf2/100)", lambda s, f=f, b=b: run_ours(f, "bo", b, s)),
            ("bo (xi=0)", lambda s, f=f, b=b: run_ours(f, "bo", b, s, xi=0.0)),
            ("random", lambda s, f=f, b=b: run_ours(f, "random", b, s)),
        ]
        if have_skopt:
            methods.append(("gp_minimize", lambda s, f=f, b=b: run_gp_minimize(f, b, s)))
        for name, method in methods:
            start = time.perf_counter()
            counts = {t: [] for t in THRESHOLDS}
            final_regret, stops = [], []
            for seed in seeds:
                values, stop_at = method(seed)
                reached = trials_to_reach(function, values)
                for t in THRESHOLDS:
                    counts[t].append(reached[t])
                final_regret.append(float(function.normalized_regret(np.nanmax(values))))
                stops.append(stop_at)
            row = {
                "function": function.name,
                "budget": budget,
                "method": name,
                "seeds": len(seeds),
                "median_trials": {
                    f"{int(t * 100)}%": median_trials(counts[t], budget) for t in THRESHOLDS
                },
                "reached": {
                    f"{int(t * 100)}%": sum(c is not None for c in counts[t]) for t in THRESHOLDS
                },
                "median_final_regret": float(np.median(final_regret)),
                "median_ei_stop": (
                    median_trials(stops, budget) if name.startswith("bo (xi=sf") else None
                ),
                "seconds": time.perf_counter() - start,
            }
            rows.append(row)
            print(format_efficiency_row(row), flush=True)
    return rows


# ---------------------------------------------------------------------- print
def format_efficiency_row(row):
    cells = []
    for key in ("20%", "10%", "5%", "1%"):
        m = row["median_trials"][key]
        cells.append(f">{row['budget']}" if m is None else f"{m:g}")
        cells[-1] += f" ({row['reached'][key]}/{row['seeds']})"
    stop = row["median_ei_stop"]
    return (
        f"{row['function']:10s} {row['method']:16s} "
        + " ".join(f"{c:>11s}" for c in cells)
        + f"  {row['median_final_regret']:9.2e}  "
        + ("-" if stop is None else f"{stop:g}").rjust(6)
        + f"  {row['seconds']:6.1f}"
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer seeds, smaller budgets")
    parser.add_argument("--skip-efficiency", action="store_true")
    add_page_arguments(parser, "bayesopt", published={"quick": False})
    args = parser.parse_args(argv)
    run = ResultsRun("Bayesian optimisation: per-iteration overhead and trials to target", args)
    try:
        import skopt  # noqa: F401

        have_skopt = True
    except ImportError:
        have_skopt = False

    sizes = [50, 100, 300]
    repeats = 1 if args.quick else 3
    print(f"Part 1: one BO iteration, objective excluded (ms; best of {repeats})")
    print(
        f"{'d':>2} {'n':>4} {'fit':>8} {'cond':>6} {'DIRECT':>7} | {'refit':>8} {'cached':>7} "
        f"{'amort.':>7} {'skl-only':>9} {'gp_min':>8} | {'skl/ours':>8} {'gpm/ours':>8}"
    )
    overhead = []
    for d in (2, 6):
        for n in sizes:
            row = overhead_case(n, d, repeats)
            overhead.append(row)
            print(
                f"{d:>2} {n:>4} {row['fit_ms']:8.1f} {row['condition_ms']:6.2f} "
                f"{row['direct_fast_ms']:7.1f} | {row['ours_refit_ms']:8.1f} "
                f"{row['ours_cached_ms']:7.1f} {row['ours_amortised_ms']:7.1f} "
                f"{row['sklearn_only_ms']:9.1f} {row['gp_minimize_ms']:8.1f} | "
                f"{row['sklearn_only_ms'] / row['ours_refit_ms']:8.2f} "
                f"{row['gp_minimize_ms'] / row['ours_amortised_ms']:8.2f}",
                flush=True,
            )

    rows = []
    if not args.skip_efficiency:
        if args.quick:
            seeds = list(range(3))
            functions = [(Branin(), 40), (Hartmann3(), 40), (Hartmann6(), 60)]
        else:
            seeds = list(range(10))
            functions = [(Branin(), 60), (Hartmann3(), 60), (Hartmann6(), 100)]
        print(
            "\nPart 2: trials to reach within x% of the optimum (median over seeds; "
            "(k/N) = seeds that reached it)"
        )
        print(
            f"{'function':10s} {'method':16s} {'20%':>11s} {'10%':>11s} {'5%':>11s} "
            f"{'1%':>11s}  {'regret':>9s}  {'EIstop':>6s}  {'s':>6s}"
        )
        rows = efficiency(functions, seeds, have_skopt)

    run.finish(
        [{"part": "overhead", **row} for row in overhead]
        + [{"part": "efficiency", **row} for row in rows],
        {
            "quick": args.quick,
            "python": sys.version.split()[0],
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "load_average": os.getloadavg(),
            "overhead": overhead,
            "efficiency": rows,
        },
        RESULTS,
    )
    print(f"\nwrote {RESULTS}")


if __name__ == "__main__":
    main()
