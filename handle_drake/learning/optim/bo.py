"""Bayesian optimisation and random search with an ask/tell interface (report section 4.2).

Both optimisers *maximise* (the grasp metric). A caller asks for parameters,
runs the trial (a simulation, or a person with a real hand), and tells the
metric back::

    opt = BayesianOptimizer(bounds=[(-0.05, 0.05), (0.0, 1.0)], seed=1)
    for _ in range(30):
        x = opt.ask()
        if opt.converged:          # only with ei_threshold > 0 (the report's stop rule)
            break
        opt.tell(x, run_trial(x))
    print(opt.best)

Determinism: the state of an optimiser is a function of ``seed`` and the
ordered list of told observations only. Proposal number ``k`` (counting told
and pending points) of the initial design is the ``k``-th point of a seeded
scrambled Sobol sequence; model-based proposals depend on the observations and
on ``seed`` (which seeds the restarts of the hyperparameter fit). Replaying the
same ``tell`` calls into a fresh optimiser therefore rebuilds it exactly; the
trial log relies on this to resume a run.

Initial design: ``n_initial`` (default ``max(10, d + 1)``, as scikit-optimize's
``gp_minimize``) points of a scrambled Sobol sequence in the box. The report
starts from one random point; space-filling points give the first
marginal-likelihood fit something to work with. On the grasp metrics (flat
plateaus with narrow tops) 10 points instead of ``d + 1 = 3`` halved the
trials to within 5-10 % of the maximum on the sphere (tuning seeds).

Stopping: by default the optimiser never declares convergence and a run uses
its whole budget. The report's rule (stop when the best EI is below
``ei_threshold`` times the RMS of the metric, after ``min_trials_to_stop``
trials) is kept as an option (``ei_threshold=1e-6``; ``handle-drake babble
--ei-stop``): on the grasp metrics it ended runs after 20-50 trials, often
before the narrow top was found.

Defaults history (:data:`BO_DEFAULTS_VERSION`): version 1 had ``n_initial =
d + 1`` and ``ei_threshold = 1e-6``; :func:`v1_options` gives them back for
side-by-side benchmarks. ``output_transform="rank"`` (the GP models normal
scores of the ranks, robust to the metric's steps such as the no-contact
value -1) is available and was measured; it is not the default (no
consistent gain on the tuning objects).

Hyperparameter schedule: the kernel hyperparameters are refitted by maximum
marginal likelihood after every observation up to ``refit_until``
observations, and afterwards each time the data set has grown by a fraction
``refit_growth`` (at n = 300, every ~30 trials); between refits the GP is only
re-conditioned on all data (one Cholesky factorisation). A refit at checkpoint
``c`` uses the first ``c`` observations and a restart seed derived from
``(seed, c)``, so it does not depend on the history of previous fits.

Failed trials: ``tell_failure(x)`` records a trial that produced no metric.
The GP sees it as the worst metric observed so far (otherwise the same point
would be proposed again); :attr:`best` never returns it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtri
from scipy.stats import qmc, rankdata

from handle_drake.learning.acquisition import (
    default_xi,
    expected_improvement,
    expected_improvement_point,
    maximize_acquisition,
)
from handle_drake.learning.gp import GaussianProcess, Hyperparameters
from handle_drake.learning.optim.base import (  # noqa: F401 - _derived_seed: used by the runner
    Best,
    Optimizer,
    RandomSearch,
    _check_seed,
    _derived_seed,
    check_bounds,
)

# Temporary alias for branches written before the base class became public (issue 18).
_AskTellBase = Optimizer

__all__ = [
    "BayesianOptimizer",
    "RandomSearch",
    "OptimizationResult",
    "Best",
    "check_bounds",
    "v1_options",
    "BO_DEFAULTS_VERSION",
    "OUTPUT_TRANSFORMS",
]


OUTPUT_TRANSFORMS = ("none", "rank")

# Bumped whenever a default of BayesianOptimizer changes what it proposes;
# logged runs (babbling.RunSpec.run_id) carry it so old runs are not mixed up
# with runs under the new defaults.
BO_DEFAULTS_VERSION = 2


@dataclass
class OptimizationResult:
    """Outcome of :func:`maximize`: the best point and the full history."""

    x: np.ndarray
    y: float
    X: np.ndarray  # (n, d) every evaluated point, in order
    Y: np.ndarray  # (n,) metric, nan for failed trials
    strategy: str
    converged: bool
    best_so_far: np.ndarray = field(repr=False, default=None)


def _check_options(dim, batch_size, output_transform, n_initial, xi, ei_threshold,
                   direct_maxfun, refit_until, refit_growth):
    """Validates :class:`BayesianOptimizer`'s options; returns ``n_initial`` and
    ``direct_maxfun`` with their defaults for ``dim`` dimensions filled in."""
    if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer) \
            or batch_size < 1:
        raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    if output_transform not in OUTPUT_TRANSFORMS:
        raise ValueError(
            f"output_transform must be one of {OUTPUT_TRANSFORMS}, got {output_transform!r}"
        )
    if n_initial is None:
        n_initial = max(10, dim + 1)
    if isinstance(n_initial, bool) or not isinstance(n_initial, int | np.integer):
        raise TypeError(f"n_initial must be an integer, got {n_initial!r}")
    if n_initial < 1:
        raise ValueError(f"n_initial must be >= 1, got {n_initial}")
    if xi is not None and not (math.isfinite(xi) and xi >= 0):
        raise ValueError(f"xi must be >= 0 or None, got {xi}")
    if not (math.isfinite(ei_threshold) and ei_threshold >= 0):
        raise ValueError(f"ei_threshold must be >= 0, got {ei_threshold}")
    if direct_maxfun is None:
        direct_maxfun = 500 * dim
    if direct_maxfun < 1:
        raise ValueError(f"direct_maxfun must be >= 1, got {direct_maxfun}")
    if refit_until < 1 or not refit_growth > 0:
        raise ValueError(
            f"refit_until must be >= 1 and refit_growth > 0, got {refit_until}, {refit_growth}"
        )
    return n_initial, direct_maxfun


class BayesianOptimizer(Optimizer):
    """Sequential Bayesian optimisation: GP (Matérn 3/2) + expected improvement + DIRECT.

    Args:
        bounds: (d, 2) box of ``[lower, upper]`` per parameter. The GP works in
            the unit cube this box maps to.
        seed: makes the run reproducible (initial design and fit restarts).
        n_initial: Sobol points before the first model-based proposal
            (default ``max(10, d + 1)``).
        xi: EI exploration parameter in metric units; ``None`` for the
            report's ``sigma_f^2 / 100`` (see :func:`default_xi`).
        ei_threshold: :attr:`converged` becomes True when the best EI found
            is below ``ei_threshold`` times the RMS of the metric about the
            prior mean; default 0: never (use the whole budget). The report's
            stop rule is e.g. ``1e-6``.
        min_trials_to_stop: the threshold is not checked before this many
            observations (default ``max(10 * d, n_initial + 3)``, the "10 d"
            rule of thumb of Jones et al. 1998 for a GP to be informative): a
            marginal-likelihood fit to a few points may explain them as pure
            noise, or a large ``xi`` may make EI ~0 while the model is still
            poor, and either would stop the search far from the optimum.
        mean: prior mean: ``"constant"``, ``"zero"``, a number, or a callable
            ``m(X) -> (n,)`` of parameters in the original units.
        n_restarts: extra starts of the marginal-likelihood fit.
        direct_maxfun: DIRECT's evaluation budget per proposal (default
            ``500 * d``, the per-dimension budget of Martinez-Cantin's BayesOpt
            library). Tests lower it.
        direct_locally_biased: use DIRECT-L instead of the original DIRECT.
        refit_until, refit_growth: hyperparameter refit schedule (module doc).
        length_scale_bounds: in unit-cube coordinates.
        signal_variance_bounds, noise_variance_bounds: relative to the mean
            square of the metric about the prior mean.
        output_transform: what the GP models: ``"none"`` the metric itself,
            ``"rank"`` the normal scores ``Phi^-1((rank - 1/2) / n)`` of the
            observations' mid-ranks (monotone, so the best observation is
            unchanged; steps and plateaus become evenly spaced). EI and its
            ``xi`` are then in those units; :meth:`predict` maps back.
        nu: smoothness of the Matérn kernel: 1.5 (the report's eq. 25,
            default) or 2.5.
        batch_size: how many proposals may be outstanding (trials run in
            parallel). 1 (default) is the report's sequential method. With
            ``q > 1``, a proposal asked while others are pending maximises EI
            under the "kriging believer" (Ginsbourger et al. 2010): the GP is
            conditioned on the pending points as if they had returned its own
            posterior mean there, with the hyperparameters unchanged, so the
            next proposal goes elsewhere. The first proposal of a batch is the
            sequential one.
    """

    strategy = "bo"
    synchronous = True  # batches are told in trial order (batch_size set per instance)

    def __init__(
        self,
        bounds,
        seed: int = 0,
        n_initial: int | None = None,
        xi: float | None = None,
        ei_threshold: float = 0.0,
        *,
        min_trials_to_stop: int | None = None,
        mean="constant",
        n_restarts: int = 2,
        direct_maxfun: int | None = None,
        direct_locally_biased: bool = False,
        refit_until: int = 40,
        refit_growth: float = 0.1,
        length_scale_bounds=(1e-2, 1e1),
        signal_variance_bounds=(1e-2, 1e2),
        noise_variance_bounds=(1e-6, 1.0),
        output_transform: str = "none",
        nu: float = 1.5,
        batch_size: int = 1,
    ):
        super().__init__(bounds, seed)
        n_initial, direct_maxfun = _check_options(
            self.dim, batch_size, output_transform, n_initial, xi, ei_threshold, direct_maxfun,
            refit_until, refit_growth)
        self.batch_size = int(batch_size)
        self.output_transform = output_transform
        self.n_initial = int(n_initial)
        if min_trials_to_stop is None:
            min_trials_to_stop = max(10 * self.dim, self.n_initial + 3)
        self.min_trials_to_stop = int(min_trials_to_stop)
        self.xi = xi
        self.ei_threshold = float(ei_threshold)
        self.direct_maxfun = int(direct_maxfun)
        self.direct_locally_biased = bool(direct_locally_biased)
        self.refit_until = int(refit_until)
        self.refit_growth = float(refit_growth)
        if callable(mean):
            user_mean = mean

            def mean_in_unit(U):
                return user_mean(self.from_unit(U))

            self._gp_mean = mean_in_unit
        else:
            self._gp_mean = mean
        self._gp_options = dict(
            n_restarts=n_restarts,
            length_scale_bounds=length_scale_bounds,
            signal_variance_bounds=signal_variance_bounds,
            noise_variance_bounds=noise_variance_bounds,
            nu=nu,
        )
        GaussianProcess(mean=self._gp_mean, **self._gp_options)  # validates the options now
        self._sobol = np.empty((0, self.dim))
        self._hyper: tuple[int, Hyperparameters] | None = None  # (checkpoint, fitted values)
        self._model: GaussianProcess | None = None
        self.last_ei = math.nan  # best EI found by the last model-based ask
        self.last_xi = math.nan

    # ---------------------------------------------------------- initial design
    def _sobol_point(self, k: int) -> np.ndarray:
        if k >= self._sobol.shape[0]:
            # Powers of two keep Sobol's balance (and scipy quiet); a fresh
            # engine with the same seed always starts with the same points.
            m = max(1, math.ceil(math.log2(k + 1)))
            self._sobol = qmc.Sobol(self.dim, scramble=True, rng=self.seed).random_base2(m)
        return self._sobol[k]

    # ------------------------------------------------------------- the model
    def _observations_changed(self):
        self._model = None

    def _checkpoint(self, n: int) -> int:
        """The number of observations the hyperparameters in use were fitted on."""
        if n <= self.refit_until:
            return n
        c = self.refit_until
        while True:
            nxt = max(c + 1, math.ceil(c * (1.0 + self.refit_growth)))
            if nxt > n:
                return c
            c = nxt

    def _training_data(self, n: int):
        """First ``n`` observations as (U, y) with failures imputed by the worst metric."""
        U = np.array(self._U[:n])
        y = np.array(self._y[:n])
        failed = np.isnan(y)
        if np.all(failed):
            return None
        y[failed] = np.min(y[~failed])
        return U, self._transform(y)

    def _transform(self, y: np.ndarray) -> np.ndarray:
        """The values the GP models (``output_transform``, see the class doc)."""
        if self.output_transform == "none":
            return y
        # "rank": normal scores of the mid-ranks; ties share a value.
        n = y.shape[0]
        return ndtri((rankdata(y, method="average") - 0.5) / n)

    def _new_gp(self, seed):
        return GaussianProcess(mean=self._gp_mean, seed=seed, **self._gp_options)

    @property
    def gp(self) -> GaussianProcess | None:
        """The GP on all observations (unit-cube inputs), or None before any metric."""
        if self._model is None:
            n = self.n_told
            data = self._training_data(n) if n else None
            if data is None:
                return None
            c = self._checkpoint(n)
            if self._hyper is None or self._hyper[0] != c:
                fit_data = self._training_data(c)
                if fit_data is None:  # only failures among the first c: fit on all data
                    fit_data = data
                gp = self._new_gp(_derived_seed(self.seed, c)).fit(*fit_data)
                self._hyper = (c, gp.hyperparameters)
            self._model = self._new_gp(None).fit(*data, hyperparameters=self._hyper[1])
        return self._model

    def _xi_and_best(self, gp):
        best = float(np.max(self._training_data(self.n_told)[1]))  # in the GP's units
        if self.xi is not None:
            return self.xi, best
        return default_xi(gp.hyperparameters.signal_variance, gp.y_scale), best

    def predict(self, X):
        """GP posterior mean and latent variance at parameters ``X`` (m, d), in metric units.

        With ``output_transform="rank"`` the GP models normal scores; the mean
        is mapped back to the metric through the (piecewise-linear, monotone)
        inverse of the transform of the observed data, and the variance by
        the slope of that map at the mean (delta method). Approximate, meant
        for plots.
        """
        gp = self.gp
        if gp is None:
            raise RuntimeError("no successful observation yet: nothing to predict")
        mean, var = gp.predict(self.to_unit(np.atleast_2d(X)))
        if self.output_transform == "none":
            return mean, var
        y = self._training_data(self.n_told)[1]
        metric = self.Y
        metric = np.where(np.isnan(metric), np.nanmin(metric), metric)
        z, first = np.unique(y, return_index=True)
        values = metric[first]
        if z.size == 1:
            return np.full_like(mean, values[0]), np.zeros_like(var)
        slopes = np.diff(values) / np.diff(z)
        # Linear beyond the observed range with the end slopes.
        index = np.clip(np.searchsorted(z, mean) - 1, 0, z.size - 2)
        back = values[index] + slopes[index] * (mean - z[index])
        return back, var * slopes[index] ** 2

    def acquisition(self, X) -> np.ndarray:
        """Expected improvement at parameters ``X`` (m, d), vectorised."""
        gp = self.gp
        if gp is None:
            raise RuntimeError("no successful observation yet: EI is undefined")
        mean, var = gp.predict(self.to_unit(np.atleast_2d(X)))
        xi, best = self._xi_and_best(gp)
        return expected_improvement(mean, var, best, xi)

    # ----------------------------------------------------------------- ask
    def ask(self) -> np.ndarray:
        """Parameters of the next trial (d,), in the units of ``bounds``.

        During the initial design any number of asks may be outstanding;
        afterwards at most ``batch_size`` (1: sequential), and asking for more
        raises. Sets :attr:`converged` when the best EI is below the threshold
        (the proposal is still returned).
        """
        k = self.n_told + self.n_pending
        gp = self.gp if k >= self.n_initial else None
        if gp is None:
            return self._register(self._sobol_point(k))
        if self.n_pending >= self.batch_size:
            raise RuntimeError(
                f"BayesianOptimizer with batch_size {self.batch_size}: {self.n_pending} "
                f"proposal(s) pending, e.g. {self.from_unit(self._pending[0])}; tell() their "
                "results (or tell_failure()) before asking again"
            )
        # xi comes from the real observations. The pending points enter as
        # data at the GP's own mean there, and as such also count for the
        # incumbent: near a pending point whose mean beats the best trial,
        # EI would otherwise stay high and the batch would crowd one spot.
        xi, best = self._xi_and_best(gp)
        model, believed = self._believer(gp)
        if believed.size:
            best = max(best, float(np.max(believed)))
        predict_point = model.point_predictor()

        def ei(u):
            mu, var = predict_point(u)
            return expected_improvement_point(mu, var, best, xi)

        u, value = maximize_acquisition(
            ei, self.dim, maxfun=self.direct_maxfun, locally_biased=self.direct_locally_biased
        )
        self.last_ei, self.last_xi = value, xi
        self.converged = (
            self.n_pending == 0 and self.n_told >= self.min_trials_to_stop
            and value < self.ei_threshold * gp.y_scale
        )
        return self._register(u)

    def _believer(self, gp: GaussianProcess) -> tuple[GaussianProcess, np.ndarray]:
        """``gp`` conditioned on the pending points at its own posterior mean,
        and those believed values (in the GP's units)."""
        if not self._pending:
            return gp, np.empty(0)
        pending = np.array(self._pending)
        U, y = self._training_data(self.n_told)
        believed = gp.predict(pending, return_variance=False)
        model = self._new_gp(None).fit(np.vstack([U, pending]), np.concatenate([y, believed]),
                                       hyperparameters=self._hyper[1])
        return model, believed


def v1_options(dim: int) -> dict:
    """The options that reproduce :class:`BayesianOptimizer`'s first defaults (version 1).

    ``d + 1`` Sobol points and the EI stop rule at ``1e-6`` (the rest is
    unchanged); for side-by-side benchmarks against the current defaults.
    """
    return dict(n_initial=int(dim) + 1, ei_threshold=1e-6)
