"""The generic learning engine: GP regression, expected improvement, optimisers, trial logs.

Models (:mod:`.gp`), acquisition (:mod:`.acquisition`), optimisers
(:mod:`.optimizer`: the public ask/tell base class :class:`Optimizer`, which
declares its batching; :mod:`.bayesopt`: BO, random search), trial storage
(:mod:`.log`), where trials run (:mod:`.executors`), the resumable runner
(:mod:`.runner`) and synthetic test problems (:mod:`.test_functions`) are
separate modules; the names below are the public surface. Nothing here knows
about grasps: the grasp experiments are :mod:`handle_drake.apps.babbling`.

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
from handle_drake.learning.executors import InlineExecutor, TrialResult
from handle_drake.learning.gp import GaussianProcess, Hyperparameters, matern32
from handle_drake.learning.log import RunInfo, TrialLog, TrialLogError, TrialRecord
from handle_drake.learning.loop import ExperimentResult, TrialRunner, replay, run_experiment
from handle_drake.learning.optim.base import Optimizer
from handle_drake.learning.optim.bo import (
    BayesianOptimizer,
    Best,
    OptimizationResult,
    RandomSearch,
    check_bounds,
    v1_options,
)
from handle_drake.learning.optim.factory import OPTIMIZERS, make_optimizer, maximize

__all__ = [
    "BayesianOptimizer",
    "v1_options",
    "Best",
    "ExperimentResult",
    "GaussianProcess",
    "Hyperparameters",
    "InlineExecutor",
    "OPTIMIZERS",
    "OptimizationResult",
    "Optimizer",
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
    "replay",
    "run_experiment",
]
