"""bench_babbling.py --surrogate: optimisers run on a grid surrogate as on simulated trials."""

import math
from pathlib import Path

import numpy as np
import pytest

from handle_drake.apps.babbling.babbling import GridSurrogate, trials_to_within
from handle_drake.base.testing import load_file_module
from handle_drake.learning.optim.bo import _derived_seed

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_babbling.py"


@pytest.fixture(scope="module")
def bench():
    return load_file_module(BENCH, "bench_babbling_under_test")


def _bump_grid(n=21, centre=(0.009, -0.006)):
    """A smooth bump of height 1 over a floor of 0.2 on a 60 mm box (known maximum)."""
    axes = [np.linspace(-0.03, 0.03, n)] * 2
    X, Y = np.meshgrid(*axes, indexing="ij")
    return axes, 0.2 + 0.8 * np.exp(-((X - centre[0]) ** 2 + (Y - centre[1]) ** 2) / 0.015 ** 2)


@pytest.mark.parametrize("method", ["bo", "random", "gp_minimize"])
def test_a_surrogate_run_sees_the_simulated_runs_noise_and_stops_within_5_percent(bench, method):
    surrogate = GridSurrogate(*_bump_grid(), noise=0.01)
    budget = 14 if method == "gp_minimize" else 40  # gp_minimize: ~0.3 s per trial
    run = bench.surrogate_run(surrogate, method, seed=3, n_trials=budget, target=1.0)
    X = np.array(run["X"])
    # Every trial's noiseless value is the surrogate's, and its noise is the one a
    # logged run would add to trial k (seed derived from the run seed and k).
    np.testing.assert_allclose(run["noiseless"], surrogate.noiseless(X), atol=1e-12)
    noise = [0.01 * np.random.default_rng(_derived_seed(3, k)).standard_normal()
             for k in range(len(X))]
    np.testing.assert_allclose(np.array(run["observed"]) - run["noiseless"], noise, atol=1e-12)
    # It stops at the first trial within 5 % of the target (or uses the budget).
    hits = trials_to_within(run["noiseless"], 1.0)
    assert len(X) == (hits[0] if math.isfinite(hits[0]) else budget)
    if method == "bo":  # a smooth bump is easy for BO in 40 trials
        assert math.isfinite(hits[0])


def test_surrogate_tables_judge_each_objective_against_its_own_optimum(bench, tmp_path,
                                                                      monkeypatch):
    grids = {"bump": _bump_grid(61)}  # 1 mm cells: the interpolant is within 1e-3
    settings = dict(seeds=[0, 1], n_trials=30, noise=0.01, placement_error=0.004,
                    placement_samples=5, methods=("bo", "random"), refine=2,
                    cache_dir=tmp_path)
    tables = bench.surrogate_tables(grids, **settings)
    # Every run is cached: the same table again runs nothing.
    monkeypatch.setattr(bench, "surrogate_run", lambda *a, **k: pytest.fail("not cached"))
    assert bench.surrogate_tables(grids, **settings) == tables
    nominal, robust = tables["nominal"]["bump"], tables["robust"]["bump"]
    # Nominal optimum: the bump's top (a grid node); robust: the same place,
    # lower by the bump's curvature over the 4 mm disc (mean r^2 = e^2 / 2).
    assert nominal["f_star"] == pytest.approx(1.0, abs=1e-3)
    np.testing.assert_allclose(nominal["x_star"], [0.01, -0.005], atol=1e-3)
    np.testing.assert_allclose(robust["x_star"], [0.01, -0.005], atol=1.5e-3)
    assert robust["f_star"] == pytest.approx(0.2 + 0.8 * np.exp(-0.004 ** 2 / 2 / 0.015 ** 2),
                                             abs=2e-3)
    assert robust["nominal_at_optimum"] == pytest.approx(1.0, abs=5e-3)
    assert 0 <= robust["nominal_loss"] < 5e-3
    for entry in (nominal, robust):
        assert len(entry["bo"]["per_seed"]) == 2
        assert entry["bo"]["reached"][0] == 2  # BO finds a smooth bump in 30 trials


def test_bo_verdicts_compare_medians_and_reached_seeds(bench):
    def summary(median, reached):
        return dict(median=[median, median, median], reached=[reached] * 3)

    entry = dict(bo=summary(12.0, 10), random=summary(40.0, 10), gp_minimize=summary(12.0, 10))
    assert bench.bo_verdicts(entry) == dict(vs_random="ahead", vs_gp_minimize="level")
    entry = dict(bo=summary(math.inf, 4), random=summary(math.inf, 2),
                 gp_minimize=summary(30.0, 8))
    assert bench.bo_verdicts(entry) == dict(vs_random="ahead", vs_gp_minimize="behind")


def test_validation_compares_simulated_trials_with_the_surrogate_and_caches_them(
        bench, tmp_path, monkeypatch):
    from handle_drake.trial.grasp_trial import GraspTrialConfig, placement_stencil

    def simulated(x, y):  # a "simulation" that is not bilinear: the interpolant errs
        return 0.5 + 40.0 * x * x + 10.0 * y

    def fake_trials(config, points):
        calls.append((config.placement_samples, len(points)))
        stencil = placement_stencil(config.placement_error, config.placement_samples)
        return np.array([np.mean([simulated(*(x + s)) for s in stencil]) for x in points])

    calls = []
    monkeypatch.setattr(bench, "_grid_chunk", fake_trials)
    axes = [np.linspace(-0.03, 0.03, 7)] * 2
    X, Y = np.meshgrid(*axes, indexing="ij")
    grids = {"sphere": (axes, simulated(X, Y))}
    configs = {"sphere": GraspTrialConfig(object="sphere")}
    points = {"sphere": np.array([[0.0, 0.0], [0.005, 0.001]])}
    result = bench.validate_surrogate(configs, grids, points, placement_error=0.002,
                                      placement_samples=5, cache_dir=tmp_path)["sphere"]
    # On a node the interpolant is exact; half-way between nodes 1 cm apart it
    # overestimates 40 x^2 by 40 * (0.005)^2 (the chord over the parabola).
    assert result["nominal"]["abs_error"] == pytest.approx([0.0, 40.0 * 0.005 ** 2], abs=1e-12)
    robust = GridSurrogate(axes, simulated(X, Y), placement_error=0.002, placement_samples=5)
    np.testing.assert_allclose(result["robust"]["surrogate"], robust.noiseless(points["sphere"]),
                               atol=1e-12)
    assert result["robust"]["max_abs_error"] > 0
    assert sorted(calls) == [(1, 1), (1, 1), (5, 1), (5, 1)]  # one point per simulation job
    calls.clear()
    again = bench.validate_surrogate(configs, grids, points, placement_error=0.002,
                                     placement_samples=5, cache_dir=tmp_path)["sphere"]
    assert calls == [] and again == result


@pytest.mark.parametrize("argv", [["--surrogate", "--trials", "5"], ["--trials", "9"]])
def test_a_budget_below_gp_minimizes_initial_points_is_refused_before_any_grid(
        bench, argv, tmp_path, capsys):
    """`--surrogate --trials 5` was a scikit-optimize traceback after the grids were computed:
    now one line and exit 2, and no grid was started (nothing written in --out)."""
    with pytest.raises(SystemExit) as exit_:
        bench.main([*argv, "--out", str(tmp_path / "out"), "--no-page"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "gp_minimize needs at least 10" in err and "--no-skopt" in err
    assert not (tmp_path / "out").exists()
    from skopt import gp_minimize  # the limit is scikit-optimize's own

    with pytest.raises(ValueError, match="Expected `n_calls` >= 10"):
        gp_minimize(lambda x: x[0] ** 2, [(-1.0, 1.0)], n_calls=bench.SKOPT_MIN_CALLS - 1,
                    random_state=0)
