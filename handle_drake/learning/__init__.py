"""Learning to grasp by trial: GP regression, expected improvement, DIRECT, BO, trial logs.

Models (:mod:`.gp`), acquisition (:mod:`.acquisition`), optimisers
(:mod:`.bayesopt`), trial storage and running (:mod:`.trials`) and synthetic
test problems (:mod:`.test_functions`) are separate modules; the names below
are the public surface.
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
)
from handle_drake.learning.gp import GaussianProcess, Hyperparameters, matern32
from handle_drake.learning.trials import (
    ExperimentResult,
    InlineExecutor,
    RunInfo,
    TrialLog,
    TrialLogError,
    TrialRecord,
    TrialResult,
    TrialRunner,
    run_experiment,
)

__all__ = [
    "BayesianOptimizer",
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
