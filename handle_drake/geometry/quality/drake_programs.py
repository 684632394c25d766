"""The closure programs written as Drake ``MathematicalProgram`` s (report eqs. 15-21).

Two convex programs over the convex weights ``lambda`` of the m primitive
wrenches ``W`` (m, 6):

* **min-distance QP** (eq. 19/21): ``min |x|^2`` s.t. ``x = W^T lambda``,
  ``sum(lambda) = 1``, ``lambda >= 0``; the optimum ``|x|`` is the distance from
  the origin to ``conv(W)``.
* **closure LP**: ``max s`` s.t. ``W^T lambda = 0``, ``sum(lambda) = 1``,
  ``lambda_i >= s``. The origin is in the relative interior of ``conv(W)`` iff
  ``s* > 0``; with ``rank(W) = 6`` that is the interior, i.e. force closure
  (eq. 18).

Each program is built once per m and reused: only the coefficients of the
``W``-dependent equality constraint are replaced for a new grasp.
"""

from __future__ import annotations

import numpy as np
from pydrake.solvers import (
    ClarabelSolver,
    ClpSolver,
    MathematicalProgram,
    SolverOptions,
)

__all__ = ["ClosurePrograms", "wrench_rank"]

from .hull import _check_wrenches

DIM = 6


#: Most wrenches the Drake programs take: the closure LP's constraint matrix is a
#: dense m x (m + 1) (10,000 soft-finger contacts would be 160000 x 160000).
MAX_PROGRAM_WRENCHES = 4000


def _check_size(W) -> np.ndarray:
    W = _check_wrenches(W)
    if len(W) > MAX_PROGRAM_WRENCHES:
        raise ValueError(f"wrenches: method='drake' takes at most {MAX_PROGRAM_WRENCHES} "
                         f"wrenches (its LP is dense), got {len(W)}; use method='fast'")
    return W


def _span(W: np.ndarray) -> str:
    nonzero = np.abs(W[W != 0])
    if nonzero.size == 0:
        return "only zeros"
    return f"{nonzero.min():.3g}..{nonzero.max():.3g}"


def wrench_rank(W, tol: float = 1e-9) -> int:
    """Rank of the wrench set's linear span (closure needs 6)."""
    W = np.asarray(W, dtype=float)
    s = np.linalg.svd(W, compute_uv=False)
    return int(np.sum(s > tol * max(1.0, s[0] if len(s) else 0.0)))


class _Qp:
    def __init__(self, m: int):
        prog = MathematicalProgram()
        self.lam = prog.NewContinuousVariables(m, "lambda")
        self.x = prog.NewContinuousVariables(DIM, "x")
        prog.AddQuadraticCost(2.0 * np.eye(DIM), np.zeros(DIM), self.x, is_convex=True)
        self.A = np.hstack([np.eye(DIM), np.zeros((DIM, m))])
        self.eq = prog.AddLinearEqualityConstraint(
            self.A, np.zeros(DIM), np.concatenate([self.x, self.lam])
        )
        prog.AddLinearEqualityConstraint(np.ones((1, m)), [1.0], self.lam)
        prog.AddBoundingBoxConstraint(0.0, np.inf, self.lam)
        self.prog = prog


class _Lp:
    def __init__(self, m: int):
        prog = MathematicalProgram()
        self.lam = prog.NewContinuousVariables(m, "lambda")
        self.s = prog.NewContinuousVariables(1, "s")
        prog.AddLinearCost([-1.0], 0.0, self.s)
        self.A = np.zeros((DIM, m))
        self.eq = prog.AddLinearEqualityConstraint(self.A, np.zeros(DIM), self.lam)
        prog.AddLinearEqualityConstraint(np.ones((1, m)), [1.0], self.lam)
        prog.AddLinearConstraint(
            np.hstack([np.eye(m), -np.ones((m, 1))]),
            np.zeros(m),
            np.full(m, np.inf),
            np.concatenate([self.lam, self.s]),
        )
        prog.AddBoundingBoxConstraint(0.0, np.inf, self.lam)
        prog.AddBoundingBoxConstraint(-1.0, 1.0, self.s)
        self.prog = prog


class ClosurePrograms:
    """Cache of the closure QP and LP, one program per number of wrenches.

    The QP is solved with Clarabel (interior point; gap and feasibility
    tolerances set to 1e-12, it agrees with the exact NNLS distance to ~1e-10).
    OSQP was tried: at the 1e-10 tolerances needed to agree to 1e-6 near the
    closure boundary it hits its iteration limit, so it is not offered.

    Args:
        lp_solver: ``"clp"`` (simplex, default) or ``"clarabel"`` for the LP.
    """

    def __init__(self, lp_solver: str = "clp"):
        if lp_solver not in ("clp", "clarabel"):
            raise ValueError(f"lp_solver: expected 'clp' or 'clarabel', got {lp_solver!r}")
        self._qp_solver = ClarabelSolver()
        self._lp_solver = ClpSolver() if lp_solver == "clp" else ClarabelSolver()
        self._qp_options = SolverOptions()
        for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
            self._qp_options.SetOption(ClarabelSolver.id(), key, 1e-12)
        self._qps: dict[int, _Qp] = {}
        self._lps: dict[int, _Lp] = {}

    def min_distance(self, W) -> tuple[np.ndarray, float, np.ndarray]:
        """Solve the min-distance QP; returns ``(x, |x|, lambda)``.

        ValueError when Clarabel finds no solution (wrenches whose magnitudes span
        many orders; the exact NNLS path of method="fast" has no such limit).
        """
        W = _check_size(W)
        m = len(W)
        qp = self._qps.get(m)
        if qp is None:
            qp = self._qps[m] = _Qp(m)
        qp.A[:, DIM:] = -W.T
        qp.eq.evaluator().UpdateCoefficients(qp.A, np.zeros(DIM))
        result = self._qp_solver.Solve(qp.prog, None, self._qp_options)
        if not result.is_success():
            raise ValueError(f"wrenches: Drake's min-distance QP found no solution "
                             f"({result.get_solution_result()}); their magnitudes span "
                             f"{_span(W)}; method='fast' (exact NNLS) handles this set")
        lam = np.clip(result.GetSolution(qp.lam), 0.0, None)
        lam /= lam.sum()
        x = lam @ W  # recomputed from feasible weights: a point of the hull
        return x, float(np.linalg.norm(x)), lam

    def closure_lp(self, W) -> float:
        """Optimal ``s`` of the closure LP (``> 0``: origin in the relative interior)."""
        W = _check_size(W)
        m = len(W)
        lp = self._lps.get(m)
        if lp is None:
            lp = self._lps[m] = _Lp(m)
        lp.eq.evaluator().UpdateCoefficients(W.T.copy(), np.zeros(DIM))
        result = self._lp_solver.Solve(lp.prog)
        if not result.is_success():
            # Infeasible: the origin is not a convex combination of the wrenches.
            return -np.inf
        return float(result.GetSolution(lp.s)[0])

    def is_force_closure(self, W, tol: float = 1e-9) -> bool:
        """Force closure (eq. 18): full rank and the origin strictly inside."""
        W = _check_size(W)
        if wrench_rank(W) < DIM:
            return False
        return self.closure_lp(W) > tol
