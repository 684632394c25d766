"""``handle-drake report``: the grasp-babbling experiments of report section 4.3, as files.

:func:`make_report` writes into ``out_dir``:

- ``fig21_sphere_1d.png``, ``fig22_star_prism_1d.png``: 1-D scans along the
  approach axis (the standoff), four snapshots of a BO run each with the GP
  mean, +-2 standard deviations, the observations, EI and the dense scan.
  The seed is chosen as in the report: for the sphere the one whose first
  (random) sample is the worst on the dense scan, for the star prism the one
  whose first sample is the best.
- ``fig23_wine_glass_2d.png``, ``fig24_mug_2d.png``, ``fig25_star_prism_2d.png``
  and ``fig23_25_all_objects_2d.png``: the metric over the hand's (x, y)
  offset from a dense grid, and the GP mean of a BO run with its samples.
- ``table3.md`` / ``table3.csv``: per object, BO trials in total (EI stop
  rule, capped at ``trials``) and to come within 5 %, 10 %, 20 % of the grid
  maximum, median over ``seeds``, next to the report's Table 3.
- ``fig26_sphere_bo_vs_random.png``, ``fig27_mug_bo_vs_random.png``: best
  noiseless value so far over ``trials`` trials, median and quartiles over
  seeds, BO against random search.
- ``fig28_synergy_gp_mean.png``: Shadow hand babbling in the space of two
  anatomical synergy amplitudes (thumb abduction, index/middle abduction) on
  a cuboid, the GP mean map after ``trials`` trials next to a grid scan.
- ``summary.json``: every number above.
- with ``meshes`` (``handle-drake report --mesh FILE``): each mesh object is
  one more row of Table 3 (no report column) with its own 2-D figure
  ``fig_mesh_<name>_2d.png`` (grid ground truth and the GP mean of BO seed 0).

Every trial is logged in ``out_dir/babble.sqlite`` and every grid is cached in
``out_dir/grids/``: running the report again (or after an interruption)
re-uses them and only computes what is missing.

The 2-D runs observe the metric with Gaussian noise (``noise``, the report
"assumes that the observations are noisy"); ground truth, best-so-far curves
and the within-p counts use the noiseless metric of the trials' parameters.
"""

from __future__ import annotations

import csv
import dataclasses as dc
import json
import math
import time
from pathlib import Path

import numpy as np

from handle_drake.apps.babbling.babbling import (
    FRACTIONS,
    RunSpec,
    best_so_far,
    grid_values,
    replay_optimizer,
    run_batch,
    run_history,
    trials_to_within,
)
from handle_drake.apps.babbling.plots import figure, gp_mean_map, panel
from handle_drake.base.testing import reduced as reduced_mode
from handle_drake.geometry.objects import KINDS
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS
from handle_drake.learning.cluster import (
    CONNECT_TIMEOUT,
    ExecutorSpec,
    as_executor,
    trial_executor,
)
from handle_drake.learning.optim.bo import BayesianOptimizer
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

__all__ = ["make_report", "ReportSettings", "REPORT_TABLE3", "OBJECT_ORDER"]

# The report's Table 3 (BO, 2-D): total trials, trials to within 5 %, 10 %, 20 %.
REPORT_TABLE3 = {
    "sphere": (551, 14, 14, 14),
    "wine_glass": (306, 31, 19, 19),
    "cylinder": (485, 39, 20, 20),
    "mug": (331, 55, 55, 1),
    "cuboid": (564, 1, 1, 1),
    "rotated_cuboid": (388, 59, 59, 59),
    "star_prism": (402, 105, 105, 31),
}
OBJECT_ORDER = tuple(REPORT_TABLE3)
# Every grasp object of the catalogue (the instrumented devices are not in Table 3).
assert set(OBJECT_ORDER) == set(KINDS) - set(DEVICE_OBJECTS)

SYNERGY_OBJECT = "cuboid"  # the report's Figure 28 discusses the thumb on "the object facet"


@dc.dataclass(frozen=True)
class ReportSettings:
    seeds: int = 10
    trials: int = 100
    grid: int = 41  # points per dimension of the 2-D ground-truth grids
    scan: int = 121  # points of the 1-D dense scans
    trials_1d: int = 30
    synergy_grid: int = 21
    noise: float = 0.01  # std of the metric noise in the 2-D runs
    workers: int = 2
    ei_stop: float = 0.0  # EI stop threshold of the Table 3 runs (0: whole budget)
    mesh_scale: float = 1.0  # file units -> m of the mesh objects (``meshes``)

    def __post_init__(self):
        for name in ("seeds", "trials", "trials_1d", "workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
        for name in ("grid", "scan", "synergy_grid"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                raise ValueError(f"{name}: expected an integer >= 2, got {value!r}")
        if not (math.isfinite(self.noise) and self.noise >= 0):
            raise ValueError(f"noise: expected a finite value >= 0, got {self.noise}")
        if not (math.isfinite(self.ei_stop) and self.ei_stop >= 0):
            raise ValueError(f"ei_stop: expected a finite value >= 0, got {self.ei_stop}")
        if not (math.isfinite(self.mesh_scale) and self.mesh_scale > 0):
            raise ValueError(f"mesh_scale: expected a finite value > 0, got {self.mesh_scale}")

    @classmethod
    def small(cls, workers: int = 1) -> ReportSettings:
        """Reduced mode: tiny grids and few trials (the test suite's version)."""
        return cls(seeds=1, trials=5, grid=3, scan=5, trials_1d=4, synergy_grid=2,
                   workers=workers)


# ------------------------------------------------------------------- specs
def _offset_config(kind: str, noise: float, mesh_scale: float = 1.0) -> GraspTrialConfig:
    """The 2-D offset trial of a catalogue kind, or of a mesh object given by its file path
    (``mesh_scale``: its file units to metres)."""
    if kind not in KINDS:
        return GraspTrialConfig(hand="barrett", object="mesh", object_file=kind, space="offset",
                                noise=noise, object_scale=mesh_scale)
    return GraspTrialConfig(hand="barrett", object=kind, space="offset", noise=noise)


def _label(kind: str) -> str:
    """A table row's name: the kind, or ``mesh <file stem>`` for a mesh object."""
    return kind if kind in KINDS else f"mesh {Path(kind).stem}"


def _table3_spec(kind, seed, s: ReportSettings) -> RunSpec:
    options = (("ei_threshold", s.ei_stop),) if s.ei_stop else ()
    return RunSpec(_offset_config(kind, s.noise, s.mesh_scale), "bo", seed, s.trials,
                   options=options)


def _random_spec(kind, seed, s: ReportSettings) -> RunSpec:
    return RunSpec(_offset_config(kind, s.noise, s.mesh_scale), "random", seed, s.trials)


def _synergy_config(noise=0.0) -> GraspTrialConfig:
    return GraspTrialConfig(hand="shadow", object=SYNERGY_OBJECT, space="synergy", noise=noise)


# ------------------------------------------------------------------ report
def make_report(out_dir="out/report", seeds: int | None = None, trials: int | None = None,
                grid: int | None = None, reduced: bool | None = None, workers: int | None = None,
                noise: float | None = None, ei_stop: float | None = None,
                progress: bool = True, executor="local",
                connect_timeout: float = CONNECT_TIMEOUT, meshes=(),
                mesh_scale: float = 1.0) -> dict:
    """Run (or resume) every experiment and write the figures and tables; returns the summary.

    ``reduced`` (default: ``handle_drake.base.testing.reduced()``) starts from
    :meth:`ReportSettings.small`; explicit arguments override either default.
    ``executor``: ``"local"`` (pools of ``workers`` processes, a whole run
    per process), ``"dask"`` (a LocalCluster of ``workers`` processes),
    ``"dask://HOST:PORT"``, or an open executor (a ``distributed.Client``
    too): grids and trials run there, the runs are driven and logged here.
    The numbers do not depend on the choice.
    ``meshes``: mesh files added to Table 3 and the 2-D figures, their units
    times ``mesh_scale`` in metres (0.001: files in millimetres).
    """
    objects = OBJECT_ORDER + tuple(str(Path(m).expanduser().resolve()) for m in meshes)
    for kind in objects[len(OBJECT_ORDER):]:
        _offset_config(kind, 0.0, mesh_scale)  # a bad mesh fails here, before any trial runs
    if isinstance(executor, str | ExecutorSpec):
        spec = ExecutorSpec.parse(executor)
        if spec.kind != "local":
            workers_ = workers if workers is not None else ReportSettings.workers
            with trial_executor(spec, workers_, connect_timeout=connect_timeout) as opened:
                return make_report(out_dir, seeds, trials, grid, reduced, workers, noise,
                                   ei_stop, progress, opened, meshes=meshes,
                                   mesh_scale=mesh_scale)
        executor = None
    executor = None if executor is None else as_executor(executor)
    if reduced is None:
        reduced = reduced_mode()
    base = ReportSettings.small() if reduced else ReportSettings()
    overrides = {k: v for k, v in dict(seeds=seeds, trials=trials, grid=grid, workers=workers,
                                       noise=noise, ei_stop=ei_stop,
                                       mesh_scale=mesh_scale).items()
                 if v is not None}
    settings = dc.replace(base, **overrides)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    db = out / "babble.sqlite"
    grids = out / "grids"
    timings = {}
    summary = {"settings": dc.asdict(settings), "reduced": bool(reduced)}

    def step(name, fn):
        start = time.perf_counter()
        if progress:
            print(f"[report] {name} ...", flush=True)
        value = fn()
        timings[name] = round(time.perf_counter() - start, 1)
        return value

    summary["one_d"] = step("1-D scans (Figures 21-22)",
                            lambda: _one_d(out, db, grids, settings, progress, executor))
    truth = step("2-D grids", lambda: {
        kind: grid_values(_offset_config(kind, 0.0, settings.mesh_scale), settings.grid, grids,
                          settings.workers, progress, executor) for kind in objects})
    table3_specs = {kind: [_table3_spec(kind, s, settings) for s in range(settings.seeds)]
                    for kind in objects}
    random_specs = {kind: [_random_spec(kind, s, settings) for s in range(settings.seeds)]
                    for kind in ("sphere", "mug")}
    synergy_spec = RunSpec(_synergy_config(), "bo", 0, settings.trials)
    all_specs = [s for specs in table3_specs.values() for s in specs] + [
        s for specs in random_specs.values() for s in specs] + [synergy_spec]
    step("BO, random and synergy runs",
         lambda: run_batch(all_specs, db, settings.workers, progress, executor))
    summary["table3"] = step("Table 3 and Figures 23-25", lambda: _table3(
        out, db, truth, table3_specs, settings))
    summary["bo_vs_random"] = step("Figures 26-27", lambda: _bo_vs_random(
        out, db, truth, table3_specs, random_specs, settings))
    summary["synergy"] = step("Figure 28", lambda: _synergy(
        out, db, grids, synergy_spec, settings, progress, executor))
    summary["timings_s"] = timings
    (out / "summary.json").write_text(json.dumps(_jsonable(summary), indent=1))
    if progress:
        print(f"[report] written to {out}")
    return summary


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, float | np.floating):
        value = float(value)
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.integer):
        return int(value)
    return value


# ------------------------------------------------------------------- 1-D
def _one_d(out, db, grids, s: ReportSettings, progress, executor=None) -> dict:
    result = {}
    for kind, figure_name, pick in (("sphere", "fig21_sphere_1d.png", np.argmin),
                                    ("star_prism", "fig22_star_prism_1d.png", np.argmax)):
        config = GraspTrialConfig(hand="barrett", object=kind, space="standoff")
        (axis,), scan = grid_values(config, s.scan, grids, s.workers, progress, executor)
        bounds = GraspTrial(config).bounds
        # The report starts from one random sample; pick the seed whose first
        # sample is the worst (sphere, Fig. 21) or best (star prism, Fig. 22).
        firsts = [float(BayesianOptimizer(bounds, seed, n_initial=1).ask()[0])
                  for seed in range(20)]
        first_values = np.interp(firsts, axis, scan)
        seed = int(pick(first_values))
        spec = RunSpec(config, "bo", seed, s.trials_1d, options=(("n_initial", 1),))
        run_batch([spec], db, 1, progress=False, executor=executor)
        history = run_history(db, spec)
        n = len(history.X)
        snapshots = sorted({1, min(n - 1, 3), min(n - 1, max(4, n // 2)), n})
        snapshots = [k for k in snapshots if 1 <= k <= n]
        fig, axes = figure(2, 2, (10, 6.5))
        dense = axis[:, None]
        for ax, k in zip(axes.ravel(), snapshots[:4], strict=False):
            optimizer = replay_optimizer(spec, history, k)
            mean, var = optimizer.predict(dense)
            ei = optimizer.acquisition(dense)
            sd = np.sqrt(var)
            ax.plot(axis * 1e3, scan, color="0.7", lw=1, label="dense scan")
            ax.plot(axis * 1e3, mean, "r", label="GP mean")
            ax.plot(axis * 1e3, mean + 2 * sd, "r--", lw=0.8, label="mean +- 2 sd")
            ax.plot(axis * 1e3, mean - 2 * sd, "r--", lw=0.8)
            ax.plot(history.X[:k, 0] * 1e3, history.observed[:k], "ro", ms=4, label="trials")
            if k < n:
                ax.axvline(history.X[k, 0] * 1e3, color="b", lw=0.8, ls=":",
                           label="next trial")
            twin = ax.twinx()
            twin.plot(axis * 1e3, ei, "b", lw=1)
            twin.set_ylabel("EI", color="b")
            ax.set_title(f"after {k} trial{'s' if k > 1 else ''}")
            ax.set_xlabel("standoff along the approach axis (mm)")
            ax.set_ylabel("BW metric")
        for ax in axes.ravel()[len(snapshots):]:
            ax.set_visible(False)
        axes[0, 0].legend(fontsize=7, loc="lower left")
        fig.suptitle(f"Barrett hand, {kind.replace('_', ' ')}: 1-D BO along the approach axis "
                     f"(seed {seed})")
        fig.savefig(out / figure_name, dpi=110)
        first_hit = trials_to_within(history.noiseless, float(np.max(scan)))
        result[kind] = dict(seed=seed, trials=n, scan_max=float(np.max(scan)),
                            scan_argmax_m=float(axis[np.argmax(scan)]),
                            best_found=float(np.nanmax(history.noiseless)),
                            first_value=float(history.noiseless[0]),
                            trials_to_within=dict(zip(map(str, FRACTIONS), first_hit, strict=True)),
                            figure=figure_name)
    return result


# ------------------------------------------------------------------- 2-D
def _median(values):
    values = np.asarray(values, dtype=float)
    return float(np.median(values)) if values.size else math.nan


def _fmt(value, reached=None):
    if not math.isfinite(value):
        return f">{reached}" if reached is not None else "-"
    return f"{value:g}"


def _table3(out, db, truth, specs, s: ReportSettings) -> dict:
    rows, result = [], {}
    for kind in specs:
        (ax_x, ax_y), values = truth[kind]
        report = REPORT_TABLE3.get(kind, ("-",) * 4)
        f_star = float(np.max(values))
        histories = [run_history(db, spec) for spec in specs[kind]]
        totals = [len(h.X) for h in histories]
        hits = np.array([trials_to_within(h.noiseless, f_star) for h in histories])
        medians = [_median(hits[:, j]) for j in range(len(FRACTIONS))]
        reached = [int(np.sum(np.isfinite(hits[:, j]))) for j in range(len(FRACTIONS))]
        best = [float(np.nanmax(h.noiseless)) for h in histories]
        result[_label(kind)] = dict(
            grid_max=f_star, grid_argmax=[float(ax_x[np.unravel_index(np.argmax(values),
                                                                        values.shape)[0]]),
                                          float(ax_y[np.unravel_index(np.argmax(values),
                                                                      values.shape)[1]])],
            total_median=_median(totals), totals=totals,
            converged=int(sum(t < s.trials for t in totals)),
            within_median=dict(zip(map(str, FRACTIONS), medians, strict=True)),
            within_reached=dict(zip(map(str, FRACTIONS), reached, strict=True)),
            within_per_seed=hits.tolist(), best_found_median=_median(best),
            report=dict(zip(("total", "5%", "10%", "20%"), report, strict=True)))
        rows.append([_label(kind), _fmt(_median(totals)), *[
            _fmt(m, s.trials) + ("" if r == len(histories) else f" ({r}/{len(histories)})")
            for m, r in zip(medians, reached, strict=True)],
            f"{f_star:.3f}", f"{_median(best):.3f}", *map(str, report)])
    header = ["object", "total", "5%", "10%", "20%", "grid max", "best found",
              "report total", "report 5%", "report 10%", "report 20%"]
    with open(out / "table3.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    lines = [
        "# Table 3: trials taken by Bayesian optimisation per object (Barrett hand, 2-D offset)",
        "",
        f"Ours: median over {s.seeds} seeds; total = trials until the EI stop rule "
        f"(threshold {s.ei_stop:g}; 0: never), capped at {s.trials}; "
        "5/10/20 % = trials until a trial's noiseless metric is within that "
        f"fraction of the maximum of a {s.grid}x{s.grid} grid (\"(k/n)\": only k of n seeds "
        f"got there; \">{s.trials}\": the median seed did not). Metric noise std {s.noise}. "
        "Report: OpenRave, one run per object, stopped by its own EI rule.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *["| " + " | ".join(row) + " |" for row in rows],
        "",
    ]
    (out / "table3.md").write_text("\n".join(lines))
    _figures_2d(out, db, truth, specs, s)
    return result


def _figures_2d(out, db, truth, specs, s):
    meshes = [(kind, f"fig_mesh_{Path(kind).stem}_2d.png") for kind in specs if kind not in KINDS]
    for kind, name in (("wine_glass", "fig23_wine_glass_2d.png"), ("mug", "fig24_mug_2d.png"),
                       ("star_prism", "fig25_star_prism_2d.png"), *meshes):
        axes_xy, values = truth[kind]
        spec = specs[kind][0]
        history = run_history(db, spec)
        fig, axs = figure(1, 2, (10, 4.2))
        vmin, vmax = float(np.min(values)), float(np.max(values))
        image = panel(axs[0, 0], axes_xy, values, f"dense grid {s.grid}x{s.grid} (noiseless)",
                       vmin=vmin, vmax=vmax)
        mean = gp_mean_map(spec, history, axes_xy)
        panel(axs[0, 1], axes_xy, mean, f"GP mean after {len(history.X)} BO trials "
               f"(seed {spec.seed}; dots: trials, star: best)", history, vmin, vmax)
        fig.colorbar(image, ax=axs[0, :].tolist(), label="BW metric")
        fig.suptitle(f"Barrett hand, {_label(kind).replace('_', ' ')}: metric over the hand's "
                     "offset")
        fig.savefig(out / name, dpi=110)
    fig, axs = figure(2, 4, (15, 7))
    for ax, kind in zip(axs.ravel(), OBJECT_ORDER, strict=False):
        axes_xy, values = truth[kind]
        panel(ax, axes_xy, values, kind.replace("_", " "), run_history(db, specs[kind][0]))
    axs[1, 3].set_visible(False)
    fig.suptitle(f"Grid ground truth of all objects with the trials of BO seed 0 "
                 f"({s.grid}x{s.grid} grid)")
    fig.savefig(out / "fig23_25_all_objects_2d.png", dpi=100)


# ------------------------------------------------------- BO against random
def _bo_vs_random(out, db, truth, bo_specs, random_specs, s) -> dict:
    result = {}
    for kind, name, number in (("sphere", "fig26_sphere_bo_vs_random.png", 26),
                               ("mug", "fig27_mug_bo_vs_random.png", 27)):
        f_star = float(np.max(truth[kind][1]))
        fig, axs = figure(1, 1, (7, 4.5))
        ax = axs[0, 0]
        entry = {"grid_max": f_star}
        trials = np.arange(1, s.trials + 1)
        for strategy, specs, color in (("bo", bo_specs[kind], "k"),
                                       ("random", random_specs[kind], "r")):
            curves = np.array([best_so_far(run_history(db, spec).noiseless, s.trials)
                               for spec in specs])
            q25, q50, q75 = np.percentile(curves, [25, 50, 75], axis=0)
            ax.plot(trials, q50, color=color, label=f"{strategy} (median of {len(specs)})")
            ax.fill_between(trials, q25, q75, color=color, alpha=0.2, lw=0)
            hits = np.array([trials_to_within(c, f_star) for c in curves])
            marks = [k for k in (5, 10, 25, 50, 100) if k <= s.trials]
            entry[strategy] = dict(
                median_best_at={k: float(q50[k - 1]) for k in marks},
                q25_best_at={k: float(q25[k - 1]) for k in marks},
                q75_best_at={k: float(q75[k - 1]) for k in marks},
                within_median={str(p): _median(hits[:, j]) for j, p in enumerate(FRACTIONS)},
                within_reached={str(p): int(np.sum(np.isfinite(hits[:, j])))
                                for j, p in enumerate(FRACTIONS)})
        ax.axhline(f_star, color="0.5", ls="--", lw=1, label="grid maximum")
        ax.set_xlabel("trial")
        ax.set_ylabel("best noiseless BW metric so far")
        ax.set_ylim(bottom=max(ax.get_ylim()[0], f_star - 1.0))
        ax.legend()
        ax.set_title(f"Figure {number}: {kind}, BO (black) vs random (red), "
                     "median and quartiles")
        fig.savefig(out / name, dpi=110)
        result[kind] = entry
    return result


# ------------------------------------------------------------ synergy babbling
def _synergy(out, db, grids, spec, s, progress, executor=None) -> dict:
    history = run_history(db, spec)
    axes_xy, truth = grid_values(_synergy_config(), s.synergy_grid, grids, s.workers, progress,
                                 executor)
    dense_axes = [np.linspace(-1, 1, 61)] * 2
    mean = gp_mean_map(spec, history, dense_axes)
    fig, axs = figure(1, 2, (10, 4.2))
    vmin, vmax = float(min(truth.min(), mean.min())), float(max(truth.max(), mean.max()))
    image = panel(axs[0, 0], dense_axes, mean,
                   f"GP mean after {len(history.X)} BO trials (dots: trials, star: best)",
                   history, vmin, vmax, scale=1.0, unit="")
    panel(axs[0, 1], axes_xy, truth, f"grid scan {s.synergy_grid}x{s.synergy_grid} (check)",
           vmin=vmin, vmax=vmax, scale=1.0, unit="")
    for ax in axs[0]:
        ax.set_xlabel("thumb abduction synergy amplitude")
        ax.set_ylabel("index/middle abduction amplitude")
    fig.colorbar(image, ax=axs[0, :].tolist(), label="BW metric")
    fig.suptitle(f"Shadow hand, {SYNERGY_OBJECT}: babbling in synergy space")
    fig.savefig(out / "fig28_synergy_gp_mean.png", dpi=110)
    # Report: the right half (more thumb abduction) is better on average.
    right, left = dense_axes[0] > 0, dense_axes[0] < 0
    grid_right, grid_left = axes_xy[0] > 0, axes_xy[0] < 0
    return dict(object=SYNERGY_OBJECT, trials=len(history.X),
                best_found=float(np.nanmax(history.noiseless)),
                best_x=history.X[int(np.nanargmax(history.noiseless))].tolist(),
                grid_max=float(truth.max()), gp_mean_right_half=float(mean[right].mean()),
                gp_mean_left_half=float(mean[left].mean()),
                grid_right_half=float(truth[grid_right].mean()),
                grid_left_half=float(truth[grid_left].mean()))
