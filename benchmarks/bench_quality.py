"""Per-grasp cost of the grasp quality metric, side by side with two references.

Run: ``python benchmarks/bench_quality.py [--quick]``. Prints a table and writes
``benchmarks/results/quality.json``.

Compared, on the same soft-finger grasps of a 5 cm sphere (2-6 contacts,
k = 4, 8, 16 cone edges, so 2k primitive wrenches per contact):

* ``ours``: ``grasp_quality`` (NNLS distance, EPA ball radius), from contacts.
* ``ours-drake``: the same metric through Drake's reused QP and closure LP.
* ``qhull (GraspIt)``: the epsilon as GraspIt computes it: a full qhull of the
  wrenches, epsilon = smallest facet offset (written here as a reference).
* ``facet QP (Dex-Net)``: Dex-Net's ``ferrari_canny_L1``: a full qhull, then a
  small QP per facet for the distance from the origin to that facet simplex
  (Dex-Net uses cvxopt; here Drake's Clarabel on one reused program). When a
  hull has more facets than the budget, a sample of facets is timed and the
  cost extrapolated (marked ``~``).

Times are CPU seconds of this process (``time.process_time``), so other jobs
on the shared machine inflate them less than wall time would. Closure and
non-closure grasps are timed separately (the metric has two
modes); a batch of 1000 mixed grasps is timed through ``bw_metric_batch``.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402
from pydrake.solvers import ClarabelSolver, MathematicalProgram  # noqa: E402
from scipy.spatial import ConvexHull, QhullError  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.geometry.quality import (  # noqa: E402
    ContactParams,
    bw_metric_batch,
    grasp_quality,
)

R = 0.05
GAMMA = 0.002


def params_for(k: int) -> ContactParams:
    return ContactParams(model="soft_finger", mu=0.5, gamma=GAMMA, num_edges=k,
                         characteristic_length=R)


def sample_grasps(rng, n, params, want_closure, count, max_tries=20000):
    """Random contacts on the sphere (normals tilted from radial) of the wanted mode."""
    out = []
    for _ in range(max_tries):
        d = rng.normal(size=(n, 3))
        if n == 2 and want_closure:  # nearly antipodal, else closure is too rare
            d[1] = -d[0] + 0.1 * rng.normal(size=3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = R * d
        nrm = -d + (0.15 if want_closure else 0.6) * rng.normal(size=(n, 3))
        if grasp_quality(p, nrm, params).force_closure == want_closure:
            out.append((p, nrm))
            if len(out) == count:
                break
    return out


# ------------------------------------------------------------------ references


def graspit_epsilon(p, n, params):
    """GraspIt-style epsilon: qhull of all wrenches, smallest facet offset."""
    W = params.wrenches(p, n).reshape(-1, 6)
    try:
        hull = ConvexHull(W)
    except QhullError:
        return 0.0, 0
    return float(np.min(-hull.equations[:, -1])), len(hull.simplices)


class FacetQp:
    """min |F^T a|^2 s.t. a >= 0, sum a = 1 for one facet F (6 x 6), reused."""

    def __init__(self):
        prog = MathematicalProgram()
        self.a = prog.NewContinuousVariables(6, "a")
        self.cost = prog.AddQuadraticCost(np.eye(6), np.zeros(6), self.a, is_convex=True)
        prog.AddLinearEqualityConstraint(np.ones((1, 6)), [1.0], self.a)
        prog.AddBoundingBoxConstraint(0.0, np.inf, self.a)
        self.prog = prog
        self.solver = ClarabelSolver()

    def __call__(self, F):
        Q = 2 * F @ F.T + 1e-10 * np.eye(6)  # Dex-Net's wrench regulariser
        self.cost.evaluator().UpdateCoefficients(Q, np.zeros(6))
        result = self.solver.Solve(self.prog)
        a = result.GetSolution(self.a)
        return float(np.linalg.norm(a @ F))


def dexnet_epsilon(p, n, params, facet_qp, budget):
    """Dex-Net-style: qhull, then one QP per facet; returns (epsilon, seconds, exact)."""
    t0 = clock()
    W = params.wrenches(p, n).reshape(-1, 6)
    try:
        hull = ConvexHull(W)
    except QhullError:
        return 0.0, clock() - t0, True
    t_hull = clock() - t0
    simplices = hull.simplices
    sample = simplices if len(simplices) <= budget else simplices[:budget]
    t1 = clock()
    dist = min(facet_qp(W[s]) for s in sample)
    t_qp = clock() - t1
    exact = len(sample) == len(simplices)
    seconds = t_hull + t_qp * len(simplices) / len(sample)
    return dist, seconds, exact


# ------------------------------------------------------------------ timing


# CPU time of this process: the machine is shared (2 cores), and wall time
# under other people's load says more about them than about the code.
clock = time.process_time


def per_call(fn, items, repeat=1):
    t0 = clock()
    for _ in range(repeat):
        for it in items:
            fn(*it)
    return (clock() - t0) / (repeat * len(items))


def fmt_time(s, approx=False):
    if s is None:
        return "-"
    tag = "~" if approx else ""
    if s < 1e-3:
        return f"{tag}{s * 1e6:.0f} us"
    if s < 1:
        return f"{tag}{s * 1e3:.2f} ms"
    return f"{tag}{s:.2f} s"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer grasps, smaller budgets")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "quality.json"))
    add_page_arguments(ap, "quality", published={"quick": False})
    args = ap.parse_args(argv)
    results_run = ResultsRun("Grasp quality: time per grasp against qhull, Drake and facet QP",
                             args)
    rng = np.random.default_rng(0)
    n_grasps = 5 if args.quick else 20
    n_ref = 2 if args.quick else 5
    facet_budget = 100 if args.quick else 400
    facet_qp = FacetQp()
    rows = []
    for k in (4, 8, 16):
        params = params_for(k)
        for n in (2, 3, 4, 5, 6):
            row = {"contacts": n, "edges": k, "wrenches": n * 2 * k}
            for mode, closure in (("closure", True), ("non_closure", False)):
                grasps = sample_grasps(rng, n, params, closure, n_grasps)
                if len(grasps) < 2:
                    row[mode] = None
                    continue
                ours = per_call(lambda p, q, c=params: grasp_quality(p, q, c), grasps, repeat=3)
                drake = per_call(lambda p, q, c=params: grasp_quality(p, q, c, method="drake"),
                                 grasps[:n_ref])
                refs = grasps[:n_ref]
                t0 = clock()
                g_out = [graspit_epsilon(p, q, params) for p, q in refs]
                t_graspit = (clock() - t0) / len(refs)
                facets = int(np.mean([f for _, f in g_out]))
                d_out = [dexnet_epsilon(p, q, params, facet_qp, facet_budget) for p, q in refs[:1]]
                t_dex, exact = d_out[0][1], d_out[0][2]
                # agreement of the closure radius with the references (closure mode)
                err = None
                if closure:
                    vals = [grasp_quality(p, q, params).value for p, q in refs]
                    err = float(max(abs(v - g) for v, (g, _) in zip(vals, g_out, strict=True)))
                    if exact:
                        err = max(err, abs(vals[0] - d_out[0][0]))
                row[mode] = {
                    "ours_s": ours, "ours_drake_s": drake, "graspit_qhull_s": t_graspit,
                    "dexnet_facet_qp_s": t_dex, "dexnet_exact": exact, "facets": facets,
                    "max_abs_diff_vs_refs": err,
                }
            rows.append(row)
            c, nc = row["closure"], row["non_closure"]

            def cell(d, key, approx=False):
                return fmt_time(d[key], approx) if d else "-"

            print(
                f"n={n} k={k:2d} m={row['wrenches']:3d} | closure: ours {cell(c, 'ours_s'):>9}"
                f"  drake {cell(c, 'ours_drake_s'):>9}  qhull {cell(c, 'graspit_qhull_s'):>9}"
                f"  facetQP {cell(c, 'dexnet_facet_qp_s', c and not c['dexnet_exact']):>10}"
                f" | non-closure: ours {cell(nc, 'ours_s'):>9}"
                f"  drake {cell(nc, 'ours_drake_s'):>9}  qhull {cell(nc, 'graspit_qhull_s'):>9}",
                flush=True,
            )
    # batch of 1000 mixed grasps, 4 contacts x 8 edges
    params = params_for(8)
    P = R * rng.normal(size=(1000, 4, 3))
    P = R * P / np.linalg.norm(P, axis=2, keepdims=True)
    N = -P / R + 0.3 * rng.normal(size=P.shape)
    t0 = clock()
    values = bw_metric_batch(P, N, params)
    t_batch = clock() - t0
    batch = {"grasps": 1000, "contacts": 4, "edges": 8, "seconds": t_batch,
             "per_grasp_s": t_batch / 1000, "closure_fraction": float(np.mean(values > 0))}
    print(f"batch of 1000 (4 contacts x 8 edges, {100 * batch['closure_fraction']:.0f}% closure): "
          f"{t_batch:.2f} s, {fmt_time(t_batch / 1000)} per grasp")
    result = {"machine": platform.platform(), "python": platform.python_version(),
              "quick": args.quick, "rows": rows, "batch": batch}
    printed = [{"contacts": row["contacts"], "edges": row["edges"], "mode": mode,
                **(row[mode] or {})} for row in rows for mode in ("closure", "non_closure")]
    printed.append({"contacts": 4, "edges": 8, "mode": "batch of 1000",
                    "ours_s": batch["per_grasp_s"]})
    results_run.finish(printed, result, Path(args.out))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
