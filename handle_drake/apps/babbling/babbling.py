"""Grasp babbling experiments: dense-grid ground truth, batches of logged runs, sample efficiency.

The pieces the ``handle-drake report`` figures, the ``babble`` command and
``benchmarks/bench_babbling.py`` share (report section 4.3):

- :func:`grid_values`: the noiseless metric of a :class:`GraspTrial` on a
  dense grid of its parameter box, evaluated in a process pool and cached in
  an ``.npz`` file (the "global maximum" of Table 3 is the grid's maximum).
- :func:`run_batch`: many :func:`run_experiment` runs (objects x strategies x
  seeds) in one SQLite trial log, a whole run per worker process (a run is
  sequential; two runs in parallel use both cores). Re-running a batch
  resumes it: finished runs cost nothing.
- :func:`run_history`: a run's trials as arrays, with the *noiseless* metric
  the grasp trial logs next to the (noisy) observed one.
- :func:`trials_to_within`: the trial count of Table 3's 5 %, 10 %, 20 %
  columns.
- :func:`replay_optimizer`: a fresh optimiser told the first ``k`` trials of
  a logged run, i.e. exactly the GP and EI that proposed trial ``k + 1``
  (the optimiser's state is a function of its seed and the told data only).
- :class:`GridSurrogate`: a trial's metric read off its simulated grid (the
  nominal or the robust objective), for sample-efficiency studies that
  cannot afford a simulation per trial (``bench_babbling.py --surrogate``).

"Within p of the global maximum" (Table 3): the first trial whose noiseless
metric ``f(x_t)`` satisfies ``f(x_t) >= f* - p |f*|`` with ``f*`` the grid
maximum. Judging by the noiseless metric of the trial's parameters (not the
noisy observation) measures how good the grasp that was found really is; a
lucky noise draw does not count.
"""

from __future__ import annotations

import dataclasses as dc
import functools
import hashlib
import json
import math
import os
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from handle_drake.base.models import PACKAGE_DIR, models_dir
from handle_drake.learning import InlineExecutor, TrialLog, TrialRecord, replay, run_experiment
from handle_drake.learning.cluster import LocalPool, as_executor, executor_workers
from handle_drake.learning.log import code_digest, code_fingerprint  # noqa: F401 (code_digest: API)
from handle_drake.learning.optim.bo import BO_DEFAULTS_VERSION
from handle_drake.learning.optim.factory import make_optimizer
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig, placement_stencil

__all__ = [
    "CachedTrial",
    "RunSpec",
    "RunHistory",
    "grid_points",
    "grid_values",
    "run_batch",
    "run_history",
    "trials_to_within",
    "replay_optimizer",
    "best_so_far",
    "FRACTIONS",
    "GridSurrogate",
]

FRACTIONS = (0.05, 0.10, 0.20)  # Table 3's columns

# --------------------------------------------------------------- worker side
_TRIALS: dict = {}  # GraspTrialConfig -> GraspTrial, one diagram per worker process


def _trial(config: GraspTrialConfig) -> GraspTrial:
    trial = _TRIALS.get(config)
    if trial is None:
        trial = _TRIALS[config] = GraspTrial(config)
        # The built diagram does not depend on the metric noise (it is added
        # after scoring): share it between configs that differ only there.
        for other_config, other in _TRIALS.items():
            if other._built is not None and dc.replace(other_config, noise=0.0) == dc.replace(
                    config, noise=0.0):
                trial._built, trial._base = other._built, other._base
                break
    return trial


class CachedTrial:
    """A picklable objective that evaluates the process's cached :class:`GraspTrial` of ``config``.

    Shipping a ``GraspTrial`` to a process pool with every trial would rebuild
    its diagram each time; this handle holds only the config, and each worker
    builds the diagram once on its first trial.
    """

    def __init__(self, config: GraspTrialConfig):
        self.config = config
        self.name = GraspTrial(config).name

    def __call__(self, x, seed: int = 0):
        return _trial(self.config)(x, seed=seed)


def _pool(workers: int):
    """A spawn process pool with one BLAS thread per worker, or None to run inline."""
    if workers <= 1:
        return None
    return LocalPool(workers)


def _check_workers(workers) -> int:
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    return int(workers)


# ---------------------------------------------------------------------- grid
def grid_points(bounds, n: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Axes (one ``linspace`` of ``n`` points per dimension) and the (n^d, d) grid, 'ij' order."""
    bounds = np.asarray(bounds, dtype=float)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
        raise ValueError(f"grid: expected an integer >= 2 points per dimension, got {n!r}")
    axes = [np.linspace(lo, hi, int(n)) for lo, hi in bounds]
    return axes, _mesh(axes)


def _mesh(axes) -> np.ndarray:
    """The (prod len(axes), d) points of the grid on ``axes``, 'ij' order."""
    return np.column_stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")])


def _grid_chunk(config: GraspTrialConfig, points: np.ndarray) -> np.ndarray:
    trial = _trial(config)
    return np.array([trial.evaluate(x).metric_noiseless for x in points])


def simulation_sources() -> list[Path]:
    """The source files a grasp trial's metric depends on: the trial, harness, scenario
    runner, station, scenario, hands, objects (the instrumented devices' geometry
    included), the scene's further objects and the arm, the taxels (the station wires them
    when a scenario asks), drivers, controllers and grasp quality. What else a trial loads
    cannot change its metric: the learning engine, validation, port names, other
    drivers' settings (``tests/experiments/test_babbling.py`` keeps this true)."""
    root = PACKAGE_DIR
    return sorted([
        root / "trial" / "grasp_trial.py", root / "trial" / "harness.py",
        root / "trial" / "simulate.py",
        root / "station.py", root / "scenario.py", root / "base" / "hands.py",
        *(root / "geometry" / "objects").glob("*.py"), *(root / "systems").glob("*.py"),
        *(root / "geometry" / "quality").glob("*.py"),
        *(root / "scene").glob("*.py"), *(root / "devices" / "arm").glob("*.py"),
        *(root / "devices" / "taxels").glob("*.py"),
    ])


@functools.cache
def simulation_fingerprint() -> str:
    """Hash of everything a grasp trial's metric depends on besides its config:
    the code of :func:`simulation_sources` (:func:`code_digest`: not its
    comments or docstrings), the hand model files and Drake's version. A
    run or cached grid computed by other code is never resumed or read back
    as if it were current.

    Computed once per process (every run id and cache key needs it): the
    files as they were when first asked, i.e. the code this process runs."""
    return code_fingerprint(PACKAGE_DIR, simulation_sources(),
                            sorted(models_dir().glob("*/*.sdf")))


def _config_key(config: GraspTrialConfig) -> str:
    text = json.dumps(dc.asdict(config), sort_keys=True) + simulation_fingerprint()
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def grid_values(config: GraspTrialConfig, n: int, cache_dir=None, workers: int = 1,
                progress: bool = False, executor=None) -> tuple[list[np.ndarray], np.ndarray]:
    """Noiseless metric of the trial on an ``n``-per-dimension grid of its box.

    Returns ``(axes, values)`` with ``values`` shaped ``(n,) * d`` ('ij'
    indexing). With ``cache_dir`` the values are stored in
    ``<cache_dir>/<hand>-<object>-<space>-n<n>-<config hash>.npz`` and read
    back on the next call (the hash covers every field of the config, noise
    included, so a changed trial is never served stale values).

    ``executor`` (e.g. a :class:`~handle_drake.learning.cluster.DaskExecutor`
    or a ``distributed.Client``) evaluates the chunks instead of a pool of
    ``workers`` processes; it is not shut down.
    """
    workers = _check_workers(workers)
    if executor is not None:
        executor = as_executor(executor)
        workers = executor_workers(executor)
    config = dc.replace(config, noise=0.0)
    trial = GraspTrial(config)
    axes, points = grid_points(trial.bounds, n)
    cache = None
    if cache_dir is not None:
        cache = Path(cache_dir) / f"{trial.name}-n{n}-{_config_key(config)}.npz"
        if cache.exists():
            with np.load(cache) as data:
                if data["points"].shape == points.shape and np.array_equal(data["points"], points):
                    return axes, data["values"].reshape((n,) * len(axes))
    chunks = np.array_split(points, max(1, min(len(points), 8 * workers)))
    pool = _pool(workers) if executor is None else executor
    try:
        if pool is None:
            values = [_grid_chunk(config, chunk) for chunk in chunks]
        else:
            futures = {pool.submit(_grid_chunk, config, chunk): i for i, chunk in enumerate(chunks)}
            values = [None] * len(chunks)
            bar = _bar(len(chunks), f"grid {trial.name} {n}^{len(axes)}", progress)
            for future in as_completed(futures):
                values[futures[future]] = future.result()
                bar.update(1)
            bar.close()
    finally:
        if pool is not None and executor is None:
            pool.shutdown(wait=True, cancel_futures=True)
    flat = np.concatenate(values)
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(tmp, points=points, values=flat)
        os.replace(tmp, cache)  # a killed run never leaves a half-written cache
    return axes, flat.reshape((n,) * len(axes))


def _bar(total, description, enabled):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=description, disable=not enabled, unit="job")


class GridSurrogate:
    """A grasp trial's objective read off its simulated grid instead of simulated.

    ``noiseless(x)``: the grid's multilinear interpolant (scipy's
    ``RegularGridInterpolator``) at ``x``, clamped to the box (the grid covers
    the whole search box; only the robust stencil reaches past its edges,
    where the hand is off the object). With ``placement_error`` e > 0 and
    ``placement_samples`` K > 1 it is the robust objective exactly as
    :class:`GraspTrialConfig` defines it, on the interpolant: the mean over
    ``x + placement_stencil(e, K)`` (the same sunflower points, only for the
    offset space, whose parameters are the wrist's sideways placement).
    ``surrogate(x, seed)`` adds the trial's metric noise as
    :meth:`GraspTrial.evaluate` does (``noise * N(0, 1)`` from
    ``default_rng(seed)``), so a run told these values sees what a run of
    simulated trials with the same seeds would see, up to the interpolation.

    Why: a simulated trial costs about a second on one core and a robust one
    K of them; 7 objects x 3 optimisers x 10 seeds x 100 trials do not fit a
    small machine, one grid per object does. The surrogate is only as fine as
    its grid (features narrower than a cell are smoothed away): check it
    against simulated trials (``bench_babbling.py --surrogate`` does) before
    trusting its figures.
    """

    def __init__(self, axes, values, *, placement_error: float = 0.0,
                 placement_samples: int = 1, noise: float = 0.0):
        from scipy.interpolate import RegularGridInterpolator

        axes = [np.asarray(a, dtype=float) for a in axes]
        values = np.asarray(values, dtype=float)
        if values.shape != tuple(len(a) for a in axes):
            raise ValueError(f"values: expected shape {tuple(len(a) for a in axes)} (one value "
                             f"per grid point), got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise ValueError("values: expected finite metric values on every grid point")
        if placement_error > 0 and len(axes) != 2:
            raise ValueError(f"placement_error: the robust objective moves the wrist sideways "
                             f"(the 2-D offset space), got a {len(axes)}-D grid")
        # The same checks (and messages) as the simulated trial's robust objective.
        GraspTrialConfig(noise=noise, placement_error=placement_error,
                         placement_samples=placement_samples)
        self.axes, self.values = axes, values
        self.bounds = np.array([[a[0], a[-1]] for a in axes])
        self.noise = float(noise)
        self.placement_error, self.placement_samples = float(placement_error), placement_samples
        self.stencil = (placement_stencil(placement_error, placement_samples) if len(axes) == 2
                        else np.zeros((1, len(axes))))
        self._interpolant = RegularGridInterpolator(axes, values, method="linear")

    def noiseless(self, X) -> np.ndarray | float:
        """The objective at ``x`` (d,) or at each row of ``X`` (n, d)."""
        X = np.asarray(X, dtype=float)
        points = np.atleast_2d(X)
        if points.shape[1] != len(self.axes):
            raise ValueError(f"parameters: expected {len(self.axes)} values, got "
                             f"{points.shape[1]}")
        moved = points[:, None, :] + self.stencil[None, :, :]
        moved = np.clip(moved, self.bounds[:, 0], self.bounds[:, 1])
        values = self._interpolant(moved.reshape(-1, len(self.axes))).reshape(moved.shape[:2])
        mean = values.mean(axis=1)
        return float(mean[0]) if X.ndim == 1 else mean

    def __call__(self, x, seed: int = 0) -> float:
        value = self.noiseless(np.asarray(x, dtype=float).reshape(-1))
        if self.noise > 0:
            value += self.noise * np.random.default_rng(seed).standard_normal()
        return float(value)

    def maximum(self, refine: int = 12) -> tuple[np.ndarray, float]:
        """The objective's maximum on the grid with each cell cut ``refine`` times: ``(x*, f*)``.

        The refined grid keeps every node (the nominal interpolant peaks on
        one); the robust mean may peak between them.
        """
        if isinstance(refine, bool) or not isinstance(refine, int | np.integer) or refine < 1:
            raise ValueError(f"refine: expected an integer >= 1, got {refine!r}")
        axes = [np.concatenate([np.linspace(a, b, refine + 1)[:-1] for a, b in zip(
            axis[:-1], axis[1:], strict=True)] + [axis[-1:]]) for axis in self.axes]
        points = _mesh(axes)
        values = self.noiseless(points)
        best = int(np.argmax(values))
        return points[best], float(values[best])


# ------------------------------------------------------------------- batches
@dc.dataclass(frozen=True)
class RunSpec:
    """One logged run: a grasp trial, an optimiser, a seed and a trial budget."""

    config: GraspTrialConfig
    strategy: str = "bo"
    seed: int = 0
    n_trials: int = 100
    options: tuple = ()  # optimiser options as sorted (name, value) pairs (hashable)

    @property
    def run_id(self) -> str:
        trial = GraspTrial(self.config)
        extra = "" if not self.options else "-" + _config_key_options(self.options)
        noise = f"-noise{self.config.noise:g}" if self.config.noise else ""
        # A BO run depends on the optimiser's defaults as well as on its
        # options: runs logged under earlier defaults keep their old ids and
        # are never read back as runs of the current ones.
        version = (f"-d{BO_DEFAULTS_VERSION}" if self.strategy == "bo" and BO_DEFAULTS_VERSION > 1
                   else "")
        # The trial's whole config and the simulation code it ran on: a run
        # logged by other code or settings (e.g. another hold_samples) starts
        # afresh under a new id instead of being resumed or read back.
        sim = _config_key(dc.replace(self.config, noise=0.0))
        return f"{trial.name}{noise}-{self.strategy}{version}{extra}-seed{self.seed}-sim{sim}"


def _config_key_options(options) -> str:
    return hashlib.sha1(json.dumps(list(options), sort_keys=True).encode()).hexdigest()[:8]


def _run_one(spec: RunSpec, db_path: str, executor=None):
    """One run: in this process, or with its trials on ``executor`` (driven from here)."""
    trial = _trial(spec.config)
    objective = trial if executor is None else CachedTrial(spec.config)
    result = run_experiment(
        objective, trial.bounds, spec.strategy, spec.n_trials, spec.seed, db_path,
        executor=executor or InlineExecutor(), progress=False, run_id=spec.run_id,
        objective_name=trial.name, optimizer_options=dict(spec.options),
    )
    return spec.run_id, result.n_done, result.best_y


def run_batch(specs, db_path, workers: int = 1, progress: bool = True, executor=None) -> None:
    """Run (or resume) every run of ``specs`` into one trial log, ``workers`` runs at a time.

    With ``executor`` (e.g. a :class:`~handle_drake.learning.cluster.DaskExecutor`)
    the runs' trials go to it instead, as many runs at once as it has
    workers: each run is driven by a thread of this process, which writes
    every row (workers on other machines never see the file).
    """
    workers = _check_workers(workers)
    specs = list(specs)
    ids = [s.run_id for s in specs]
    if len(set(ids)) != len(ids):
        raise ValueError("run_batch: two runs have the same run_id")
    db_path = str(db_path)
    Path(db_path).parent.mkdir(parents=True, exist_ok=True)
    TrialLog(db_path).close()  # create (or validate) the file before workers open it
    todo = [s for s in specs if not _complete(s, db_path)]
    if not todo:
        return
    bar = _bar(len(todo), f"runs -> {Path(db_path).name}", progress)
    if executor is not None:
        try:
            _run_threads(as_executor(executor), todo, db_path, bar)
        finally:
            bar.close()
        return
    pool = _pool(min(workers, len(todo)))
    try:
        if pool is None:
            for spec in todo:
                _run_one(spec, db_path)
                bar.update(1)
        else:
            futures = [pool.submit(_run_one, spec, db_path) for spec in todo]
            for future in as_completed(futures):
                run_id, n_done, best = future.result()
                bar.update(1)
                bar.set_postfix_str(f"{run_id}: best {best:.3g}")
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_threads(executor, specs, db_path, bar) -> None:
    threads = ThreadPoolExecutor(min(len(specs), executor_workers(executor)),
                                 thread_name_prefix="run")
    try:
        futures = [threads.submit(_run_one, spec, db_path, executor) for spec in specs]
        for future in as_completed(futures):
            run_id, n_done, best = future.result()
            bar.update(1)
            bar.set_postfix_str(f"{run_id}: best {best:.3g}")
    finally:
        # On an error or Ctrl-C the runs not started are dropped; running
        # ones end when their executor is closed (their rows stay resumable).
        threads.shutdown(wait=False, cancel_futures=True)


def _complete(spec: RunSpec, db_path) -> bool:
    """True when the log holds a finished run for ``spec`` (budget used or its optimiser
    converged)."""
    with TrialLog(db_path) as log:
        if log.get_run(spec.run_id) is None:
            return False
        records = log.trials(spec.run_id)
    if any(r.status in ("pending", "running") for r in records):
        return False
    if len(records) >= spec.n_trials:
        return True
    # A run that stopped early converged (BO's EI rule): replaying its trials says so.
    optimizer = replay_optimizer(spec, records)
    optimizer.ask()
    return bool(optimizer.converged)


@dc.dataclass
class RunHistory:
    """A logged run as arrays, in trial order (failed trials carry nan metrics)."""

    run_id: str
    X: np.ndarray  # (n, d) parameters
    observed: np.ndarray  # (n,) metric as the optimiser saw it (noise included)
    noiseless: np.ndarray  # (n,) the trial's noiseless metric
    wall_time: np.ndarray  # (n,) s per trial


def run_history(db_path, spec_or_run_id) -> RunHistory:
    """A run's trials as arrays; given a :class:`RunSpec`, at most its first ``n_trials``."""
    run_id = spec_or_run_id if isinstance(spec_or_run_id, str) else spec_or_run_id.run_id
    with TrialLog(db_path) as log:
        if log.get_run(run_id) is None:
            raise ValueError(f"run {run_id!r} is not in {db_path}")
        records = log.trials(run_id)
    if isinstance(spec_or_run_id, RunSpec):
        # The same run continued to a larger budget holds more trials.
        records = records[: spec_or_run_id.n_trials]
    X = np.array([r.parameters for r in records])
    observed = np.array([np.nan if r.metric is None else r.metric for r in records])
    noiseless = np.array([
        r.contacts.get("metric_noiseless", np.nan) if isinstance(r.contacts, dict) else np.nan
        for r in records])
    noiseless = np.where(np.isnan(noiseless), observed, noiseless)
    wall = np.array([np.nan if r.wall_time is None else r.wall_time for r in records])
    return RunHistory(run_id, X, observed, noiseless, wall)


def replay_optimizer(spec: RunSpec, records_or_history, k: int | None = None):
    """A fresh optimiser of ``spec`` told the first ``k`` logged trials (all when None);
    :func:`handle_drake.learning.replay` tells them."""
    optimizer = make_optimizer(spec.strategy, GraspTrial(spec.config).bounds, spec.seed,
                               **dict(spec.options))
    if isinstance(records_or_history, RunHistory):
        h = records_or_history
        records = [TrialRecord(h.run_id, i, x, "done" if math.isfinite(y) else "failed", 0,
                               metric=float(y) if math.isfinite(y) else None)
                   for i, (x, y) in enumerate(zip(h.X, h.observed, strict=True))]
    else:
        records = [r for r in records_or_history if r.status in ("done", "failed")]
    replay(optimizer, records[: len(records) if k is None else k])
    return optimizer


# ------------------------------------------------------------------ measures
def best_so_far(values, length: int | None = None) -> np.ndarray:
    """Running maximum of ``values`` (nan ignored), held flat up to ``length`` entries."""
    values = np.asarray(values, dtype=float)
    running = np.fmax.accumulate(np.where(np.isnan(values), -np.inf, values)) if values.size \
        else values
    if length is not None and length > running.size:
        fill = running[-1] if running.size else -np.inf
        running = np.concatenate([running, np.full(length - running.size, fill)])
    return running


def trials_to_within(values, global_max: float, fractions=FRACTIONS) -> list[float]:
    """Per fraction p: the 1-based index of the first value >= ``global_max - p |global_max|``.

    ``inf`` when no value gets there.
    """
    values = np.asarray(values, dtype=float)
    if not math.isfinite(global_max):
        raise ValueError(f"global_max: expected a finite value, got {global_max}")
    out = []
    for p in fractions:
        if not 0 <= p < 1:
            raise ValueError(f"fractions: expected values in [0, 1), got {p}")
        hit = np.flatnonzero(values >= global_max - p * abs(global_max))
        out.append(float(hit[0] + 1) if hit.size else math.inf)
    return out
