"""Figures of one babbling run (``handle-drake babble``): the map they draw is
the run's own GP, fitted to the run's trials, and it finds a known maximum."""

import numpy as np
import pytest
from matplotlib.image import imread

from handle_drake.apps.babbling.babbling import RunHistory, RunSpec, grid_points
from handle_drake.apps.babbling.plots import MAP_POINTS, gp_mean_map, plot_run, run_model
from handle_drake.learning.optim.factory import make_optimizer
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

CONFIG = GraspTrialConfig(hand="barrett", object="sphere", space="offset")
BOUNDS = GraspTrial(CONFIG).bounds
PEAK = np.array([0.6, 0.3]) * BOUNDS[:, 1]  # inside the box, off centre
NAMES = ("x_offset_m", "y_offset_m")


def _bump(x):
    """A smooth landscape with its maximum 1.0 at PEAK (no simulation)."""
    width = 0.5 * BOUNDS[0, 1]
    return float(np.exp(-np.sum((np.asarray(x) - PEAK) ** 2) / width**2))


def _history(strategy, n, seed=0):
    spec = RunSpec(CONFIG, strategy, seed, n)
    optimizer = make_optimizer(strategy, BOUNDS, seed)
    X, Y = [], []
    for _ in range(n):
        x = optimizer.ask()
        y = _bump(x)
        optimizer.tell(x, y)
        X.append(x)
        Y.append(y)
    Y = np.array(Y)
    return spec, RunHistory(spec.run_id, np.array(X), Y, Y, np.zeros(n))


@pytest.mark.parametrize("strategy", ["random", "bo"])
def test_the_map_is_a_model_of_the_trials_that_finds_the_known_maximum(strategy):
    spec, history = _history(strategy, 30)
    model = run_model(spec, history)
    mean_at_trials, _ = model.predict(history.X)
    np.testing.assert_allclose(mean_at_trials, history.observed, atol=0.05)
    axes = [np.linspace(lo, hi, MAP_POINTS) for lo, hi in BOUNDS]
    mean = gp_mean_map(spec, history, axes)
    assert mean.shape == (MAP_POINTS, MAP_POINTS)
    _, points = grid_points(BOUNDS, MAP_POINTS)
    best = points[np.argmax(mean.ravel())]
    assert np.linalg.norm(best - PEAK) < 0.1 * BOUNDS[0, 1] * 2
    assert mean.max() == pytest.approx(1.0, abs=0.08)
    # The map's layout: mean[i, j] is at (axes[0][i], axes[1][j]).
    i, j = np.unravel_index(np.argmax(mean), mean.shape)
    np.testing.assert_allclose([axes[0][i], axes[1][j]], best)


def test_a_failed_trial_is_drawn_and_kept_out_of_the_fit(tmp_path):
    spec, history = _history("random", 12)
    history.observed[4] = np.nan
    history.noiseless[4] = np.nan
    path = plot_run(spec, history, tmp_path / "run.png", NAMES)
    image = imread(path)
    assert image.shape[0] > 300 and image.shape[1] > 800
    # Not a blank page: the map and the curves put many colours on it.
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 200


def test_one_dimensional_runs_get_a_mean_and_band(tmp_path):
    config = GraspTrialConfig(hand="barrett", object="sphere", space="standoff")
    (lo, hi), = GraspTrial(config).bounds
    spec = RunSpec(config, "random", 0, 6)
    X = np.linspace(lo, hi, 6)[:, None]
    Y = np.sin(X[:, 0] / hi * 3)
    path = plot_run(spec, RunHistory(spec.run_id, X, Y, Y, np.zeros(6)), tmp_path / "a.png",
                    ["standoff_m"])
    assert path.stat().st_size > 10_000


def test_bad_input_is_refused_with_a_reason(tmp_path):
    spec, history = _history("random", 3)
    empty = RunHistory("empty-run", np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0))
    with pytest.raises(ValueError, match="empty-run.*no trials"):
        plot_run(spec, empty, tmp_path / "x.png", NAMES)
    with pytest.raises(ValueError, match="expected 2 names, got 1"):
        plot_run(spec, history, tmp_path / "x.png", NAMES[:1])
    assert not (tmp_path / "x.png").exists()
