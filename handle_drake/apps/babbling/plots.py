"""Figures of logged babbling runs: one run (``handle-drake babble``) and the
shared panels of ``handle-drake report``.

Matplotlib's object API only (no pyplot), so the figures render under any
backend, in worker processes and in headless CI.
"""

from __future__ import annotations

import dataclasses as dc
from pathlib import Path

import numpy as np
from matplotlib.ticker import MaxNLocator

from handle_drake.apps.babbling.babbling import (
    RunHistory,
    RunSpec,
    best_so_far,
    grid_points,
    replay_optimizer,
)
from handle_drake.trial.grasp_trial import GraspTrial

__all__ = ["figure", "panel", "run_model", "gp_mean_map", "plot_run"]

MAP_POINTS = 61  # per dimension of a GP mean map


def figure(rows, cols, size):
    """A constrained-layout ``Figure`` and its (rows, cols) array of axes."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def panel(ax, axes, values, title, history=None, vmin=None, vmax=None, scale=1e3, unit="mm"):
    """A 2-D map ``values[i, j]`` over ``axes[0][i], axes[1][j]``; with ``history``,
    the trials as white dots and the best (noiseless) trial as a red star."""
    extent = [axes[0][0] * scale, axes[0][-1] * scale, axes[1][0] * scale, axes[1][-1] * scale]
    image = ax.imshow(values.T, origin="lower", extent=extent, aspect="auto", cmap="viridis",
                      vmin=vmin, vmax=vmax, interpolation="nearest")
    if history is not None and len(history.X):
        ax.plot(history.X[:, 0] * scale, history.X[:, 1] * scale, "w.", ms=3)
        if np.any(np.isfinite(history.noiseless)):
            i = int(np.nanargmax(history.noiseless))
            ax.plot(history.X[i, 0] * scale, history.X[i, 1] * scale, "r*", ms=10)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(f"x offset ({unit})" if unit else "")
    ax.set_ylabel(f"y offset ({unit})" if unit else "")
    return image


def run_model(spec: RunSpec, history: RunHistory):
    """The GP of a run told all its trials: a BO run's own optimiser replayed;
    for random search, a default BO model of the same box (what a user asks
    of a random run: where does the data say the good grasps are?)."""
    if spec.strategy != "bo":
        spec = dc.replace(spec, strategy="bo", options=())
    return replay_optimizer(spec, history)


def gp_mean_map(spec: RunSpec, history: RunHistory, axes) -> np.ndarray:
    """GP posterior mean of the run on the ``MAP_POINTS``-square grid spanning ``axes``."""
    model = run_model(spec, history)
    _, points = grid_points([[a[0], a[-1]] for a in axes], MAP_POINTS)
    return model.predict(points)[0].reshape(MAP_POINTS, MAP_POINTS)


def plot_run(spec: RunSpec, history: RunHistory, path, parameter_names) -> Path:
    """One run as a PNG: the metric per trial with the best so far, and the
    GP's picture of the parameter space (mean map in 2-D, mean +- 2 sd in 1-D)
    with the trials on it. Returns the path written."""
    path = Path(path)
    n = len(history.X)
    if n == 0:
        raise ValueError(f"run {history.run_id!r} has no trials to plot")
    names = list(parameter_names)
    bounds = GraspTrial(spec.config).bounds
    if len(names) != bounds.shape[0]:
        raise ValueError(f"parameter_names: expected {bounds.shape[0]} names, got {len(names)}")
    # Offsets and standoffs are in m: plot them in mm.
    in_metres = [name.endswith("_m") for name in names]
    scale = 1e3 if all(in_metres) else 1.0
    labels = [name[:-2].replace("_", " ") + " (mm)" if scale == 1e3 else name.replace("_", " ")
              for name in names]

    fig, axs = figure(1, 2, (11, 4.3))
    ax = axs[0, 0]
    trials = np.arange(1, n + 1)
    done = np.isfinite(history.observed)
    ax.plot(trials[done], history.observed[done], ".", color="0.4", label="metric (as observed)")
    if np.any(~done):
        floor = np.nanmin(history.observed) if np.any(done) else 0.0
        ax.plot(trials[~done], np.full(np.sum(~done), floor), "x", color="r",
                label="failed trial")
    ax.plot(trials, best_so_far(history.noiseless), "k-", label="best so far (noiseless)")
    ax.set_xlabel("trial")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("BW metric")
    ax.legend(fontsize=8)
    ax.set_title(f"{n} trials, {spec.strategy}, seed {spec.seed}", fontsize=9)

    ax = axs[0, 1]
    if np.sum(done) < 2:
        ax.text(0.5, 0.5, "fewer than 2 successful trials: no model", ha="center",
                va="center", transform=ax.transAxes)
        ax.set_axis_off()
    elif bounds.shape[0] == 2:
        axes = [np.linspace(lo, hi, MAP_POINTS) for lo, hi in bounds]
        image = panel(ax, axes, gp_mean_map(spec, history, axes),
                      "GP mean (dots: trials, star: best)", history, scale=scale, unit="")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        fig.colorbar(image, ax=ax, label="BW metric")
    else:
        model = run_model(spec, history)
        x = np.linspace(bounds[0, 0], bounds[0, 1], 4 * MAP_POINTS)
        mean, var = model.predict(x[:, None])
        sd = np.sqrt(np.maximum(var, 0.0))
        ax.plot(x * scale, mean, "r-", label="GP mean")
        ax.fill_between(x * scale, mean - 2 * sd, mean + 2 * sd, color="r", alpha=0.15, lw=0,
                        label="+- 2 sd")
        ax.plot(history.X[done, 0] * scale, history.observed[done], "k.", label="trials")
        ax.set_xlabel(labels[0])
        ax.set_ylabel("BW metric")
        ax.legend(fontsize=8)
    fig.suptitle(f"{history.run_id}", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path
