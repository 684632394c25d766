"""One factory for every ask/tell optimiser, by name (:func:`make_optimizer`), and
:func:`maximize`, the in-process loop over any of them.

- ``bo``: :class:`~handle_drake.learning.optim.bo.BayesianOptimizer` (its options);
- ``random``: :class:`~handle_drake.learning.optim.base.RandomSearch`, or with a
  ``stop_score`` :class:`~handle_drake.learning.optim.population.StoppingRandomSearch`;
- ``ipso`` (Algorithm 2 as interpreted to work: :data:`IPSO_SETTINGS`, see
  ``docs/inhand.md``), ``ipso-report`` (Algorithm 2 with the report's literal
  settings: ``w = phi_p = phi_c = 0.4``, no clamping, no re-initialisation),
  ``ipso-restart`` (``ipso-report`` with the restarts of 5.5.4), ``pso``
  (standard, Clerc's constriction) and ``cmaes``: the swarms of
  :mod:`handle_drake.learning.optim.population` (``n_particles``, ``stop_score``,
  ``min_active``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from handle_drake.learning.optim.base import RandomSearch
from handle_drake.learning.optim.bo import BayesianOptimizer, OptimizationResult
from handle_drake.learning.optim.population import CMAES, IncrementalPSO, StoppingRandomSearch

__all__ = ["OPTIMIZERS", "SWARMS", "IPSO_SETTINGS", "GIST_SPREAD", "make_optimizer", "maximize"]

#: The swarms (population per iteration: ``n_particles``).
SWARMS = ("ipso", "ipso-gist", "ipso-report", "ipso-restart", "pso", "cmaes")

#: ``ipso``'s interpretation of Algorithm 2's open choices (docs/inhand.md, "Interpretations"):
#: the report's incremental activation and best-solution cluster, Clerc's constriction
#: coefficients instead of 0.4 (with 0.4 the swarm contracted around its first best: the
#: measurements in docs/results/inhand.md), velocities clamped to 0.3 of the box, and a
#: particle outside the best cluster drawn anew after 2 iterations without a better
#: personal best.
IPSO_SETTINGS = dict(w=0.7298, phi_p=1.49618, phi_c=1.49618, v_max=0.3, reinit_after=2)
#: ``ipso-gist``: ``ipso`` with the gist's start times seeding the swarm (``init_centre``,
#: given by the task: ``apps.inhand.experiment.gist_prior``) within +- this (population.py's
#: doc). Not the default: on the screw cap's evaluation seeds it reached 270 deg on 0 of 5
#: (docs/results/inhand.md), the uniform start on 1 of 5.
GIST_SPREAD = 0.1
OPTIMIZERS = ("bo", "random", *SWARMS)


def make_optimizer(strategy: str, bounds, seed: int = 0, **options):
    """The optimiser named ``strategy`` (module doc) over ``bounds``, seeded ``seed``.

    ``options`` go to the optimiser: BO's keyword arguments; ``stop_score`` for random
    search; ``n_particles``, ``stop_score`` and (the incremental swarms) ``min_active``
    for the swarms; ``init_centre`` (``ipso`` alone: the gist's timing that seeds the swarm,
    population.py's doc). The swarms' options are taken by every optimiser but BO and used
    where they mean something (random search has no population; PSO and CMA-ES have no
    activated dimensions), so every in-hand optimiser takes the same arguments.
    """
    if strategy == "bo":
        return BayesianOptimizer(bounds, seed, **options)
    if strategy == "random":
        stop_score = options.pop("stop_score", None)
        options.pop("n_particles", None)
        options.pop("min_active", None)
        options.pop("init_centre", None)
        if options:
            raise TypeError(f"RandomSearch takes no options, got {sorted(options)}")
        if stop_score is None:
            return RandomSearch(bounds, seed)
        return StoppingRandomSearch(bounds, seed, stop_score=stop_score)
    if strategy not in SWARMS:
        raise ValueError(f"strategy: expected one of {OPTIMIZERS}, got {strategy!r}")
    unknown = sorted(set(options) - {"n_particles", "stop_score", "min_active", "init_centre"})
    if unknown:
        raise TypeError(f"{strategy} takes n_particles, stop_score, min_active, init_centre, "
                        f"got {unknown}")
    n_particles = options.get("n_particles", 10)
    stop_score = options.get("stop_score")
    min_active = options.get("min_active", 1)
    if strategy == "ipso":
        return IncrementalPSO(bounds, seed, n_particles, min_active=min_active,
                              stop_score=stop_score, **IPSO_SETTINGS)
    if strategy == "ipso-gist":
        opt = IncrementalPSO(bounds, seed, n_particles, min_active=min_active,
                             stop_score=stop_score, init_centre=options.get("init_centre"),
                             init_spread=GIST_SPREAD, **IPSO_SETTINGS)
        opt.strategy = "ipso-gist"
        return opt
    if strategy == "ipso-report":  # the report's literal settings (5.5.4)
        opt = IncrementalPSO(bounds, seed, n_particles, min_active=min_active,
                             stop_score=stop_score)
        opt.strategy = "ipso-report"
        return opt
    if strategy == "ipso-restart":  # Algorithm 2 with the restarts of 5.5.4
        opt = IncrementalPSO(bounds, seed, n_particles, min_active=min_active,
                             stop_score=stop_score, restart_after=3)
        opt.strategy = "ipso-restart"
        return opt
    if strategy == "pso":
        opt = IncrementalPSO(bounds, seed, n_particles, w=0.7298, phi_p=1.49618,
                             phi_c=1.49618, incremental=False, cluster_size=1,
                             stop_score=stop_score)
        opt.strategy = "pso"
        return opt
    return CMAES(bounds, seed, n_particles, stop_score=stop_score)


def maximize(
    f: Callable[[np.ndarray], float],
    bounds,
    n_trials: int,
    seed: int = 0,
    strategy: str = "bo",
    stop_on_convergence: bool = True,
    **options,
) -> OptimizationResult:
    """Maximise ``f(x)`` over the box in at most ``n_trials`` evaluations, in this process.

    A non-finite value of ``f`` is told as a failure; exceptions propagate.
    For logged, resumable or parallel runs use
    :func:`handle_drake.learning.loop.run_experiment`.
    """
    if isinstance(n_trials, bool) or not isinstance(n_trials, int | np.integer) or n_trials < 1:
        raise ValueError(f"n_trials must be a positive integer, got {n_trials!r}")
    optimizer = make_optimizer(strategy, bounds, seed, **options)
    for _ in range(int(n_trials)):
        x = optimizer.ask()
        if stop_on_convergence and optimizer.converged:
            break
        value = float(f(x))
        if math.isfinite(value):
            optimizer.tell(x, value)
        else:
            optimizer.tell_failure(x, f"non-finite metric {value}")
    best = optimizer.best
    Y = optimizer.Y
    best_so_far = np.fmax.accumulate(np.where(np.isnan(Y), -np.inf, Y)) if Y.size else Y
    return OptimizationResult(
        x=None if best is None else best.x,
        y=math.nan if best is None else best.y,
        X=optimizer.X,
        Y=Y,
        strategy=strategy,
        converged=optimizer.converged,
        best_so_far=best_so_far,
    )
