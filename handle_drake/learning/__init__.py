"""Learning to grasp by trial: GP regression, expected improvement, DIRECT, BO, trial logs.

Models (:mod:`.gp`), acquisition (:mod:`.acquisition`), optimisers
(:mod:`.bayesopt`), trial storage (:mod:`.log`), where trials run (:mod:`.executors`), the
resumable runner (:mod:`.runner`) and synthetic
test problems (:mod:`.test_functions`) are separate modules; the names below
are the public surface.

Defaults of :class:`BayesianOptimizer` (version 2, ``BO_DEFAULTS_VERSION``):
10 scrambled Sobol points before the first GP proposal (``max(10, d + 1)``),
EI with the report's ``xi = sigma_f^2 / 100`` (eq. 40), and no stop rule (a
run uses its whole budget; the report's EI rule is ``ei_threshold=1e-6``,
``handle-drake babble --ei-stop``). ``v1_options(d)`` restores the first
defaults (``d + 1`` points, EI stop at 1e-6) for comparisons;
``benchmarks/bench_babbling.py`` runs both side by side.
"""

from handle_drake.learning.acquisition import (
    default_xi,
    expected_improvement,
    expected_improvement_point,
    maximize_acquisition,
)
from handle_drake.learning.bayesopt import (
    BayesianOptimizer,
    Best,
    OptimizationResult,
    RandomSearch,
    check_bounds,
    make_optimizer,
    maximize,
    v1_options,
)
from handle_drake.learning.executors import InlineExecutor, TrialResult
from handle_drake.learning.gp import GaussianProcess, Hyperparameters, matern32
from handle_drake.learning.log import RunInfo, TrialLog, TrialLogError, TrialRecord
from handle_drake.learning.runner import ExperimentResult, TrialRunner, run_experiment

__all__ = [
    "BayesianOptimizer",
    "v1_options",
    "Best",
    "ExperimentResult",
    "GaussianProcess",
    "Hyperparameters",
    "InlineExecutor",
    "OptimizationResult",
    "RandomSearch",
    "RunInfo",
    "TrialLog",
    "TrialLogError",
    "TrialRecord",
    "TrialResult",
    "TrialRunner",
    "check_bounds",
    "default_xi",
    "expected_improvement",
    "expected_improvement_point",
    "make_optimizer",
    "matern32",
    "maximize",
    "maximize_acquisition",
    "run_experiment",
]
