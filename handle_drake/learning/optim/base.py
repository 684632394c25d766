"""The public ask/tell base class of the learning engine, and the checks optimisers share."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Optimizer", "Best", "RandomSearch", "check_bounds"]


def check_bounds(bounds) -> np.ndarray:
    """``bounds`` as a float array (d, 2) of ``[lower, upper]`` rows, validated."""
    try:
        array = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError) as error:
        raise TypeError(f"bounds must be a sequence of (lower, upper) pairs: {error}") from None
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(
            f"bounds must have shape (d, 2) with one (lower, upper) row per dimension, "
            f"got shape {array.shape}"
        )
    if array.shape[0] == 0:
        raise ValueError("bounds must have at least one dimension, got 0")
    if not np.all(np.isfinite(array)):
        raise ValueError("bounds must be finite")
    bad = np.flatnonzero(array[:, 0] >= array[:, 1])
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"bounds[{i}]: lower must be < upper, got lower={array[i, 0]}, upper={array[i, 1]}"
        )
    return array


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise TypeError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _derived_seed(*entropy: int) -> int:
    """A 32-bit seed that depends only on ``entropy`` (for per-step random streams)."""
    return int(np.random.SeedSequence(list(entropy)).generate_state(1)[0])


@dataclass(frozen=True)
class Best:
    """The best observation so far: parameters ``x`` (d,) and metric ``y``."""

    x: np.ndarray
    y: float


class Optimizer:
    """The ask/tell interface every optimiser of the engine implements (it *maximises*).

    A subclass implements :meth:`ask` (register the proposal with
    :meth:`_register`) and may react to new data in
    :meth:`_observations_changed`; the base keeps the bounds, the told
    observations (failures as nan) and the outstanding asks. Its state must be
    a function of its seed and of the ordered told observations only: a trial
    log resumes a run by replaying them into a fresh optimiser
    (:func:`handle_drake.learning.loop.replay`).

    Batching is declared by the class, and the runner follows it:

    - ``batch_size``: how many proposals may be outstanding at once (None:
      any number, e.g. random search).
    - ``synchronous``: True when the optimiser proposes a batch, waits for all
      of it and must be told it in trial order before proposing the next
      (BO with the kriging believer, a particle swarm's generation), so that a
      run depends only on its seed and options, never on which worker
      finished first. False: ask again as soon as a worker is free.
    """

    strategy = ""
    batch_size: int | None = None
    synchronous: bool = False

    def __init__(self, bounds, seed):
        self.bounds = check_bounds(bounds)
        self.seed = _check_seed(seed)
        self.dim = self.bounds.shape[0]
        self._lower = self.bounds[:, 0]
        self._width = self.bounds[:, 1] - self.bounds[:, 0]
        self._U: list[np.ndarray] = []  # observed points in the unit cube
        self._y: list[float] = []  # metric, nan for a failure
        self._errors: list[str] = []
        self._pending: list[np.ndarray] = []
        self.converged = False

    def ask(self) -> np.ndarray:
        """The next parameters to try, (d,) in the original units."""
        raise NotImplementedError

    # ----------------------------------------------------------- coordinates
    def to_unit(self, x) -> np.ndarray:
        return (np.asarray(x, dtype=float) - self._lower) / self._width

    def from_unit(self, u) -> np.ndarray:
        return self._lower + np.asarray(u, dtype=float) * self._width

    def _check_point(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape != (self.dim,):
            raise ValueError(f"x must have shape ({self.dim},), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"x must be finite, got {x}")
        u = self.to_unit(x)
        tolerance = 1e-9
        outside = np.flatnonzero((u < -tolerance) | (u > 1 + tolerance))
        if outside.size:
            i = int(outside[0])
            raise ValueError(
                f"x[{i}] = {x[i]} is outside the bounds [{self.bounds[i, 0]}, {self.bounds[i, 1]}]"
            )
        return np.clip(u, 0.0, 1.0)

    # ---------------------------------------------------------------- tell
    def _take_pending(self, u):
        for i, p in enumerate(self._pending):
            # |p - u| <= 1e-12 everywhere (np.allclose with rtol 0, at a tenth of its cost)
            if float(np.max(np.abs(p - u))) <= 1e-12:
                del self._pending[i]
                return

    def tell(self, x, y) -> None:
        """Record that the trial at ``x`` (d,) gave metric ``y`` (finite).

        ``x`` need not come from :meth:`ask` (a person may add a trial of
        their own choice). A missing metric is a failure: use
        :meth:`tell_failure`.
        """
        u = self._check_point(x)
        try:
            y = float(y)
        except (TypeError, ValueError):
            raise TypeError(f"y must be a real number, got {y!r}") from None
        if not math.isfinite(y):
            raise ValueError(
                f"y must be finite, got {y}; report a trial without a metric with tell_failure(x)"
            )
        self._take_pending(u)
        self._U.append(u)
        self._y.append(y)
        self._errors.append("")
        self._observations_changed()

    def tell_failure(self, x, error: str = "") -> None:
        """Record that the trial at ``x`` produced no metric (crash, NaN, lost object...)."""
        u = self._check_point(x)
        self._take_pending(u)
        self._U.append(u)
        self._y.append(math.nan)
        self._errors.append(str(error))
        self._observations_changed()

    def resume_pending(self, x) -> None:
        """Declare ``x`` as asked and not yet told (a trial log's unfinished trial on resume).

        Keeps the proposal counter where it was when the trial was asked, so
        the next :meth:`ask` returns what it would have returned then.
        """
        self._pending.append(self._check_point(x))

    def _observations_changed(self):
        pass

    @property
    def batch_room(self) -> int | None:
        """How many proposals the next batch of a synchronous optimiser holds:
        ``batch_size``, or fewer when a generation was resumed part-way (a
        swarm asks only for its remaining members)."""
        return self.batch_size

    # ------------------------------------------------------------- queries
    @property
    def n_told(self) -> int:
        return len(self._y)

    @property
    def n_pending(self) -> int:
        return len(self._pending)

    @property
    def X(self) -> np.ndarray:
        """(n, d) told points in order (failures included)."""
        if not self._U:
            return np.empty((0, self.dim))
        return self.from_unit(np.array(self._U))

    @property
    def Y(self) -> np.ndarray:
        """(n,) told metrics in order, nan for failures."""
        return np.array(self._y, dtype=float)

    @property
    def best(self) -> Best | None:
        """The best successful observation, or None before the first one."""
        y = self.Y
        if y.size == 0 or np.all(np.isnan(y)):
            return None
        i = int(np.nanargmax(y))
        return Best(self.from_unit(self._U[i]), float(y[i]))

    def _register(self, u) -> np.ndarray:
        self._pending.append(np.asarray(u, dtype=float))
        return self.from_unit(u)


class RandomSearch(Optimizer):
    """Uniform random search with the ask/tell interface of :class:`BayesianOptimizer`.

    Point ``k`` (counting told and pending points) is drawn from a generator
    seeded with ``(seed, k)``, so any number of asks may be outstanding
    (parallel trials) and a replayed run proposes the same points.
    """

    strategy = "random"
    batch_size = None  # any number of asks may be outstanding
    synchronous = False

    def __init__(self, bounds, seed: int = 0):
        super().__init__(bounds, seed)

    def ask(self) -> np.ndarray:
        k = self.n_told + self.n_pending
        u = np.random.default_rng([self.seed, k]).random(self.dim)
        return self._register(u)
