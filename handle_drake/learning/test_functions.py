"""Synthetic functions with known optima, in maximisation form.

Our optimisers maximise (a grasp metric), so each function here is the
negative of its usual minimisation form: ``value = -f(x)``, ``maximum =
-f_min``. Optima are from the literature (Dixon & Szegő 1978 for Branin and
Hartmann; problem 02 of Gavana's global-optimisation suite for the 1-D
function); the tests check them against the formulas independently.

Instances are picklable callables, so they can run in worker processes.
Each accepts one point (d,) -> float or many (m, d) -> (m,).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SyntheticFunction", "SineSum1D", "Branin", "Hartmann3", "Hartmann6", "FUNCTIONS"]


class SyntheticFunction:
    """Base: ``name``, ``bounds`` (d, 2), ``maximum``, ``argmax`` (k, d), ``worst`` (min value)."""

    name = ""
    bounds: np.ndarray
    maximum: float
    argmax: np.ndarray
    worst: float  # the minimum over the box (for range-normalised regret)

    @property
    def dim(self) -> int:
        return self.bounds.shape[0]

    def __call__(self, x):
        x = np.asarray(x, dtype=float)
        single = x.ndim == 1
        X = np.atleast_2d(x)
        if X.shape[1] != self.dim:
            raise ValueError(
                f"{self.name}: expected points with {self.dim} entries, got {X.shape[1]}"
            )
        value = self._evaluate(X)
        return float(value[0]) if single else value

    def normalized_regret(self, y):
        """``(maximum - y) / (maximum - worst)``: 0 at the optimum, 1 at the worst point."""
        return (self.maximum - np.asarray(y, dtype=float)) / (self.maximum - self.worst)

    def __repr__(self):
        return f"{type(self).__name__}()"


class SineSum1D(SyntheticFunction):
    """``-(sin x + sin(10 x / 3))`` on [2.7, 7.5]; global max 1.899599 at x = 5.145735.

    Three local maxima of different heights: a small multi-modal 1-D test.
    """

    name = "sine_sum_1d"
    bounds = np.array([[2.7, 7.5]])
    maximum = 1.8995993491521
    argmax = np.array([[5.1457352908]])
    worst = -0.88831478  # at x = 6.21731

    def _evaluate(self, X):
        x = X[:, 0]
        return -(np.sin(x) + np.sin(10.0 * x / 3.0))


class Branin(SyntheticFunction):
    """Negative Branin-Hoo on [-5, 10] x [0, 15]; max -0.397887 at three points."""

    name = "branin"
    bounds = np.array([[-5.0, 10.0], [0.0, 15.0]])
    maximum = -0.39788735772973816
    argmax = np.array([[-np.pi, 12.275], [np.pi, 2.275], [9.42478, 2.475]])
    worst = -308.12909601160663  # at (-5, 0)

    def _evaluate(self, X):
        x1, x2 = X[:, 0], X[:, 1]
        a, b, c = 1.0, 5.1 / (4 * np.pi**2), 5.0 / np.pi
        r, s, t = 6.0, 10.0, 1.0 / (8 * np.pi)
        return -(a * (x2 - b * x1**2 + c * x1 - r) ** 2 + s * (1 - t) * np.cos(x1) + s)


_HARTMANN_ALPHA = np.array([1.0, 1.2, 3.0, 3.2])


class Hartmann3(SyntheticFunction):
    """Negative Hartmann 3-D on [0, 1]^3; max 3.86278 at (0.114614, 0.555649, 0.852547)."""

    name = "hartmann3"
    bounds = np.array([[0.0, 1.0]] * 3)
    maximum = 3.8627797869493365
    argmax = np.array([[0.114614, 0.555649, 0.852547]])
    worst = 0.0  # the sum of exponentials is positive and tends to 0: a lower bound
    A = np.array([[3.0, 10, 30], [0.1, 10, 35], [3.0, 10, 30], [0.1, 10, 35]])
    P = 1e-4 * np.array(
        [[3689, 1170, 2673], [4699, 4387, 7470], [1091, 8732, 5547], [381, 5743, 8828]]
    )

    def _evaluate(self, X):
        inner = np.einsum("kj,mkj->mk", self.A, (X[:, None, :] - self.P[None]) ** 2)
        return np.exp(-inner) @ _HARTMANN_ALPHA


class Hartmann6(SyntheticFunction):
    """Negative Hartmann 6-D on [0, 1]^6; max 3.32237 at (0.20169, 0.150011, ...)."""

    name = "hartmann6"
    bounds = np.array([[0.0, 1.0]] * 6)
    maximum = 3.3223680114155147
    argmax = np.array([[0.20169, 0.150011, 0.476874, 0.275332, 0.311652, 0.6573]])
    worst = 0.0
    A = np.array(
        [
            [10, 3, 17, 3.5, 1.7, 8],
            [0.05, 10, 17, 0.1, 8, 14],
            [3, 3.5, 1.7, 10, 17, 8],
            [17, 8, 0.05, 10, 0.1, 14],
        ]
    )
    P = 1e-4 * np.array(
        [
            [1312, 1696, 5569, 124, 8283, 5886],
            [2329, 4135, 8307, 3736, 1004, 9991],
            [2348, 1451, 3522, 2883, 3047, 6650],
            [4047, 8828, 8732, 5743, 1091, 381],
        ]
    )

    def _evaluate(self, X):
        inner = np.einsum("kj,mkj->mk", self.A, (X[:, None, :] - self.P[None]) ** 2)
        return np.exp(-inner) @ _HARTMANN_ALPHA


FUNCTIONS = {f.name: f for f in (SineSum1D, Branin, Hartmann3, Hartmann6)}
