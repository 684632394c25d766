"""Ask/tell optimisers for the in-hand trials (scores are maximised).

- :class:`IncrementalPSO`: Algorithm 2 of the report (5.5). Particles start
  uniformly in the action-gist box (start times in [0, 1], one direction per
  joint variation, ``[0, A_lim]``), velocities in ``U(-|b_up - b_lo|, |b_up -
  b_lo|)``. Each iteration particle ``i`` updates only its first
  ``floor(f(p_i))`` dimensions (2*: the activated parameters, at least
  ``min_active``), with ``v <- w v + phi_p r_p (p - x) + phi_c r_c (c - x)``
  where ``c`` is the centre of the best-solution cluster (the mean of the
  ``cluster_size`` best personal bests); ``w = phi_p = phi_c = 0.4``. The
  report leaves the unproved dimensions' positions open; we freeze them
  ("we should not modify any unproved parameters", 5.5.2), or let them drift
  with their old velocity (``freeze_inactive=False``, the literal line 19).
  The report minimises a cost but its score grows with success: here every
  score is maximised. Particles of one iteration are evaluated as one batch
  (a synchronous swarm: the report updates ``g`` particle by particle), so the
  trials of an iteration run in parallel and a run depends only on its seed.
  Positions leaving the box are clipped to it and that velocity component is
  set to zero. ``init_centre`` (``ipso``: the action gist's start times, see
  :func:`handle_drake.apps.inhand.experiment.gist_prior`): the dimensions where it
  is finite start in ``centre +- init_spread`` instead of the whole box (at the
  start, a re-initialisation and a restart), the others uniformly. 5.4: "based on
  action gist, we have already had a rough view of when and how the fingers should
  move"; Figure 29: the particles are the meta motions' values whose "begin time
  and joint angle variation will be slightly changed". The gist's direction is the
  box already (1*); its timing seeds the swarm; how far each joint moves is left to
  the whole box ``[0, A_lim]``.
- standard PSO (``make_optimizer("pso")`` of :mod:`handle_drake.learning.optim.factory`):
  the same swarm with every dimension updated, global best (cluster of one) and Clerc's constriction
  coefficients ``w = 0.7298, phi_p = phi_c = 1.49618``, so the comparison
  isolates what Algorithm 2 changes. It is this class rather than a library
  PSO because a library's initialisation and bound handling would differ too.
- :class:`CMAES`: the ``cma`` package's CMA-ES in the unit cube (mean at the
  centre, sigma 0.3, population = particles), ask/tell per individual.
- random search: :class:`handle_drake.learning.RandomSearch`.
- ``ipso`` (``make_optimizer``) adds velocity clamping (``v_max``), re-drawn
  stagnant particles (``reinit_after``) and other coefficients
  (``factory.IPSO_SETTINGS``); ``ipso-report`` keeps the report's literal settings.
- ``ipso-restart``: Algorithm 2 with the report's restarts (5.5.4: "rather than
  increasing N_Iter, we prefer to restart the babbling learning process"): after
  3 iterations without a better personal best the swarm starts anew.

All stop once a told score reaches ``stop_score`` (the task's target score)
and are rebuilt exactly by replaying their tells (the trial log's resume).
"""

from __future__ import annotations

import math

import numpy as np

from handle_drake.learning.optim.base import Optimizer, RandomSearch, _derived_seed

__all__ = ["IncrementalPSO", "CMAES", "StoppingRandomSearch", "INHAND_OPTIMIZERS"]

# the optimisers the in-hand command offers (built by optim.factory.make_optimizer)
INHAND_OPTIMIZERS = ("ipso", "ipso-gist", "ipso-report", "ipso-restart", "pso", "cmaes",
                     "random")


def _positive_int(name, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
    return int(value)


def _non_negative(name, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
            math.isfinite(value) and value >= 0):
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
    return float(value)


class _StopMixin:
    stop_score: float | None = None

    def _check_stop(self, y):
        if self.stop_score is not None and y >= self.stop_score:
            self.converged = True


class _Generational(_StopMixin, Optimizer):
    """A population asked as one batch and told in the order asked."""

    synchronous = True

    def __init__(self, bounds, seed, batch_size, stop_score):
        super().__init__(bounds, seed)
        self.batch_size = _positive_int("n_particles", batch_size)
        self.stop_score = None if stop_score is None else float(stop_score)
        self.generation = 0
        self._population = None  # (N, d) unit-cube points of this generation
        self._asked = 0
        self._scores: list[float] = []

    def _new_population(self) -> np.ndarray:
        raise NotImplementedError

    def _end_generation(self, scores: np.ndarray) -> None:
        raise NotImplementedError

    def _ensure_population(self):
        if self._population is None:
            self._population = self._new_population()
            self._asked = 0
            self._scores = []

    @property
    def batch_room(self) -> int:
        """Members of the current generation not asked yet (what a batch may hold now)."""
        return self.batch_size if self._population is None else self.batch_size - self._asked

    def ask(self) -> np.ndarray:
        self._ensure_population()
        if self._asked >= self.batch_size:
            raise RuntimeError(
                f"{type(self).__name__}: all {self.batch_size} members of generation "
                f"{self.generation} are asked; tell their results first")
        u = self._population[self._asked]
        self._asked += 1
        return self._register(u)

    def resume_pending(self, x) -> None:
        self._ensure_population()
        super().resume_pending(x)
        self._asked = max(self._asked, len(self._scores) + self.n_pending)

    def _record(self, x, y):
        self._ensure_population()
        k = len(self._scores)
        u = self.to_unit(np.asarray(x, dtype=float))
        if not np.allclose(u, self._population[k], rtol=0.0, atol=1e-9):
            raise ValueError(
                f"{type(self).__name__}: told x is not member {k} of generation "
                f"{self.generation} (members are told in the order they were asked)")
        self._scores.append(y)
        self._asked = max(self._asked, len(self._scores))
        if len(self._scores) == self.batch_size:
            scores = np.array(self._scores, dtype=float)
            self._end_generation(scores)
            self.generation += 1
            self._population = None

    def tell(self, x, y) -> None:
        super().tell(x, y)
        self._check_stop(float(y))
        self._record(x, float(y))

    def tell_failure(self, x, error: str = "") -> None:
        super().tell_failure(x, error)
        self._record(x, -math.inf)


class IncrementalPSO(_Generational):
    """Algorithm 2 (see the module doc). ``incremental=False`` updates every dimension."""

    strategy = "ipso"

    def __init__(self, bounds, seed: int = 0, n_particles: int = 10, w: float = 0.4,
                 phi_p: float = 0.4, phi_c: float = 0.4, incremental: bool = True,
                 min_active: int = 1, cluster_size: int | None = None,
                 freeze_inactive: bool = True, stop_score: float | None = None,
                 restart_after: int | None = None, v_max: float | None = None,
                 reinit_after: int | None = None, init_centre=None,
                 init_spread: float = 0.1):
        super().__init__(bounds, seed, n_particles, stop_score)
        self._init_prior(init_centre, init_spread)
        # velocity clamping: |v_d| <= v_max (a share of the box's width); None: unclamped
        if v_max is not None and not (isinstance(v_max, int | float)
                                      and not isinstance(v_max, bool) and 0 < v_max <= 1):
            raise ValueError(f"v_max: expected a number in (0, 1] (share of the box), got "
                             f"{v_max!r}")
        self.v_max = None if v_max is None else float(v_max)
        # re-initialisation of stagnant particles: a particle outside the best-solution
        # cluster whose personal best has not improved for this many iterations is drawn
        # anew (uniform position and velocity) and forgets its personal best; None: never
        self.reinit_after = None if reinit_after is None else _positive_int(
            "reinit_after", reinit_after)
        self.reinits = 0
        # 5.5.4: "rather than increasing N_Iter, we prefer to restart the babbling learning
        # process": after this many iterations without a better personal best, every
        # particle starts anew (uniform position and velocity, no memory); None: never
        self.restart_after = None if restart_after is None else _positive_int(
            "restart_after", restart_after)
        self._stale, self._best_seen, self.restarts = 0, -math.inf, 0
        self.w = _non_negative("w", w)
        self.phi_p = _non_negative("phi_p", phi_p)
        self.phi_c = _non_negative("phi_c", phi_c)
        self.incremental = bool(incremental)
        self.min_active = min(_positive_int("min_active", min_active), self.dim)
        self.cluster_size = max(1, math.ceil(self.batch_size / 5)) if cluster_size is None \
            else _positive_int("cluster_size", cluster_size)
        if self.cluster_size > self.batch_size:
            raise ValueError(f"cluster_size: expected <= n_particles ({self.batch_size}), got "
                             f"{self.cluster_size}")
        self.freeze_inactive = bool(freeze_inactive)
        rng = np.random.default_rng([self.seed, 0x15A0])  # own stream: not random search's
        self.x = self._seeded(rng.random((self.batch_size, self.dim)))  # U(b_lo, b_up)
        self.v = rng.uniform(-1.0, 1.0, (self.batch_size, self.dim))
        self.p = self.x.copy()
        self.f_p = np.full(self.batch_size, -math.inf)
        self.active = np.full(self.batch_size, self.dim if not incremental else self.min_active)
        self._stagnant = np.zeros(self.batch_size, dtype=int)  # iterations without a better p_i

    def _init_prior(self, init_centre, init_spread) -> None:
        """Checks and keeps the seeded dimensions' centre (unit cube; NaN: uniform)."""
        if isinstance(init_spread, bool) or not (isinstance(init_spread, int | float)
                                                 and 0 < init_spread <= 1):
            raise ValueError(f"init_spread: expected a number in (0, 1], got {init_spread!r}")
        self.init_spread = float(init_spread)
        if init_centre is None:
            self.init_centre = None
            return
        centre = np.asarray(init_centre, dtype=float)
        finite = np.isfinite(centre)
        if centre.shape != (self.dim,) or np.any((centre[finite] < 0) | (centre[finite] > 1)):
            raise ValueError(f"init_centre: expected {self.dim} values in [0, 1] (NaN: "
                             f"uniform), got shape {centre.shape}")
        self.init_centre = centre

    def _seeded(self, u: np.ndarray) -> np.ndarray:
        """Uniform draws ``u`` (unit cube) moved into ``init_centre +- init_spread`` where
        the centre is finite (clipped to the box); unchanged elsewhere."""
        if self.init_centre is None:
            return u
        finite = np.isfinite(self.init_centre)
        seeded = np.clip(self.init_centre + self.init_spread * (2.0 * u - 1.0), 0.0, 1.0)
        return np.where(finite, seeded, u)

    def _new_population(self) -> np.ndarray:
        return self.x.copy()

    def active_dimensions(self, score: float) -> int:
        """How many leading dimensions a particle with personal best ``score`` updates (2*)."""
        if not self.incremental:
            return self.dim
        if not math.isfinite(score):
            return self.min_active
        return int(min(self.dim, max(self.min_active, math.floor(score))))

    @property
    def cluster_centre(self) -> np.ndarray:
        order = np.argsort(-self.f_p, kind="stable")[: self.cluster_size]
        return self.p[order].mean(axis=0)

    def _end_generation(self, scores):
        better = scores > self.f_p
        self.p[better] = self.x[better]
        self.f_p[better] = scores[better]
        self._stagnant = np.where(better, 0, self._stagnant + 1)
        if self.restart_after is not None:
            best = float(np.max(self.f_p))
            self._stale = 0 if best > self._best_seen else self._stale + 1
            self._best_seen = max(self._best_seen, best)
            if self._stale >= self.restart_after:
                rng = np.random.default_rng([self.seed, 0x15A0, 0xF00D, self.generation])
                self.x = self._seeded(rng.random((self.batch_size, self.dim)))
                self.v = rng.uniform(-1.0, 1.0, (self.batch_size, self.dim))
                self.p = self.x.copy()
                self.f_p = np.full(self.batch_size, -math.inf)
                self.active[:] = self.min_active
                self._stale, self._best_seen = 0, -math.inf
                self._stagnant[:] = 0
                self.restarts += 1
                return
        c = self.cluster_centre
        elite = set(np.argsort(-self.f_p, kind="stable")[: self.cluster_size].tolist())
        for i in range(self.batch_size):
            rng = np.random.default_rng([self.seed, 0x15A0, self.generation + 1, i])
            if self.reinit_after is not None and i not in elite \
                    and self._stagnant[i] >= self.reinit_after:
                self._reinitialise(i, rng)
                continue
            m = self.active_dimensions(self.f_p[i])
            self.active[i] = m
            r_p, r_c = rng.random(m), rng.random(m)
            self.v[i, :m] = (self.w * self.v[i, :m] + self.phi_p * r_p * (self.p[i, :m]
                             - self.x[i, :m]) + self.phi_c * r_c * (c[:m] - self.x[i, :m]))
            if self.v_max is not None:
                self.v[i] = np.clip(self.v[i], -self.v_max, self.v_max)
            moving = slice(None) if not self.freeze_inactive else slice(0, m)
            new = self.x[i, moving] + self.v[i, moving]
            clipped = np.clip(new, 0.0, 1.0)
            self.v[i, moving] = np.where(clipped != new, 0.0, self.v[i, moving])
            self.x[i, moving] = clipped

    def _reinitialise(self, i: int, rng) -> None:
        """Particle ``i`` drawn anew (uniform in the box, velocity within ``v_max``); its
        personal best is forgotten, the others' (and so the cluster) are kept."""
        limit = 1.0 if self.v_max is None else self.v_max
        self.x[i] = self._seeded(rng.random(self.dim))
        self.v[i] = rng.uniform(-limit, limit, self.dim)
        self.p[i] = self.x[i]
        self.f_p[i] = -math.inf
        self.active[i] = self.dim if not self.incremental else self.min_active
        self._stagnant[i] = 0
        self.reinits += 1


class CMAES(_Generational):
    """CMA-ES from the ``cma`` package behind the same ask/tell (unit cube, maximising)."""

    strategy = "cmaes"

    def __init__(self, bounds, seed: int = 0, n_particles: int = 10, sigma0: float = 0.3,
                 stop_score: float | None = None):
        import cma

        super().__init__(bounds, seed, n_particles, stop_score)
        if not (isinstance(sigma0, int | float) and 0 < sigma0 <= 1):
            raise ValueError(f"sigma0: expected a number in (0, 1], got {sigma0!r}")
        self.sigma0 = float(sigma0)
        state = np.random.get_state()  # cma seeds numpy's global generator: restore it
        try:
            self._es = cma.CMAEvolutionStrategy(
                np.full(self.dim, 0.5), self.sigma0,
                {"bounds": [0.0, 1.0], "popsize": self.batch_size,
                 "seed": _derived_seed(seed, 1), "verbose": -9, "verb_log": 0, "verb_disp": 0})
        finally:
            np.random.set_state(state)
        self._raw = None

    def _new_population(self) -> np.ndarray:
        # cma samples from numpy's global generator: seed it per generation and
        # restore it, so a run depends only on its seed and tells.
        state = np.random.get_state()
        try:
            np.random.seed(_derived_seed(self.seed, 2, self.generation))
            self._raw = self._es.ask()
        finally:
            np.random.set_state(state)
        return np.clip(np.array(self._raw), 0.0, 1.0)

    def _end_generation(self, scores):
        ok = np.isfinite(scores)
        worst = scores[ok].min() - 1.0 if ok.any() else 0.0  # a failure: below every success
        state = np.random.get_state()
        try:
            self._es.tell(self._raw, list(-np.where(ok, scores, worst)))  # cma minimises
        finally:
            np.random.set_state(state)


class StoppingRandomSearch(_StopMixin, RandomSearch):
    """:class:`RandomSearch` that stops once a score reaches ``stop_score``."""

    def __init__(self, bounds, seed: int = 0, stop_score: float | None = None):
        super().__init__(bounds, seed)
        self.stop_score = None if stop_score is None else float(stop_score)

    def tell(self, x, y) -> None:
        super().tell(x, y)
        self._check_stop(float(y))
