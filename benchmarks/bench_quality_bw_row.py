"""The issue-34 row of ``bench_quality.py`` alone: BW metric, closure, 4 x 8, against qhull.

Run: ``python benchmarks/bench_quality_bw_row.py [--rounds 6] [--baseline REV]``. Draws the
same 20 closure grasps as the full benchmark's n=4 k=8 row (its random stream walked through
the earlier rows), then times, interleaved in each round, qhull of the grasp's wrenches
(GraspIt's epsilon, the floor), ``grasp_quality`` on this tree and, with ``--baseline``,
``grasp_quality`` with ``hull.py`` as of git revision REV (before/after). Also checks that
both give bit-identical values. CPU seconds of the process. Also times the first call of
a fresh process (numba compiles the EPA loop, then caches it on disk): with an empty
numba cache and again with the cache written. Writes
``benchmarks/results/quality_bw_row.json``.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_quality as bq  # noqa: E402

from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.geometry.quality import grasp_quality, metrics  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def row_grasps():
    """The full benchmark's closure grasps for n=4, k=8 (same seed, same draw order)."""
    rng = np.random.default_rng(0)
    for k in (4, 8):
        params = bq.params_for(k)
        for n in (2, 3, 4, 5, 6):
            for closure in (True, False):
                grasps = bq.sample_grasps(rng, n, params, closure, 20)
                if k == 8 and n == 4:
                    return params, grasps
    raise AssertionError("unreachable")


def baseline_quality(revision: str):
    """``metrics._quality`` with the EPA of ``hull.py`` at ``revision``."""
    source = subprocess.run(["git", "show", f"{revision}:handle_drake/geometry/quality/hull.py"],
                            cwd=ROOT, capture_output=True, text=True, check=True).stdout
    path = Path(tempfile.mkdtemp()) / "hull_baseline.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("hull_baseline", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def quality(p, q, params):
        saved = metrics.largest_ball_radius
        metrics.largest_ball_radius = module.largest_ball_radius
        try:
            return grasp_quality(p, q, params)
        finally:
            metrics.largest_ball_radius = saved

    return quality


_FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from handle_drake.geometry.quality import ContactParams, grasp_quality
t1 = time.perf_counter()
p = 0.05 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0.0]])
grasp_quality(p, -p / 0.05, ContactParams(mu=0.5, num_edges=8, characteristic_length=0.05))
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)
"""


def first_call_seconds() -> dict:
    """Import and first ``grasp_quality`` call of a fresh process, cold and warm numba cache."""
    cache = tempfile.mkdtemp(prefix="numba_cache_")
    out = {}
    for name in ("empty_cache", "cache_written"):
        run = subprocess.run([sys.executable, "-c", _FIRST_CALL], capture_output=True, text=True,
                             check=True, env={**os.environ, "NUMBA_CACHE_DIR": cache})
        imp, first = map(float, run.stdout.split())
        out[name] = {"import_s": imp, "first_call_s": first}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--baseline", default=None, help="git revision of hull.py for 'before'")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "quality_bw_row.json"))
    add_page_arguments(ap, "quality", published={"rounds": 6})
    args = ap.parse_args(argv)
    results_run = ResultsRun("Grasp quality: one BW table row against qhull", args)
    if args.rounds < 1:
        ap.error(f"--rounds: expected >= 1, got {args.rounds}")
    params, grasps = row_grasps()
    fns = {"qhull": lambda p, q: bq.graspit_epsilon(p, q, params),
           "ours": lambda p, q: grasp_quality(p, q, params)}
    if args.baseline:
        before = baseline_quality(args.baseline)
        fns["before"] = lambda p, q: before(p, q, params)
        identical = all(before(p, q, params) == grasp_quality(p, q, params) for p, q in grasps)
    load = [os.getloadavg()[0]]
    rounds = []
    for r in range(args.rounds):
        times = {name: bq.per_call(fn, grasps, repeat=1 if name == "qhull" else 3)
                 for name, fn in (list(fns.items())[::-1] if r % 2 else fns.items())}
        load.append(os.getloadavg()[0])
        rounds.append(times)
        line = "  ".join(f"{k} {v * 1e3:.2f} ms" for k, v in times.items())
        ratios = "  ".join(f"qhull/{k} {times['qhull'] / times[k]:.1f}x" for k in times
                           if k != "qhull")
        print(f"round {r}: {line}  |  {ratios}", flush=True)
    med = {k: float(np.median([t[k] for t in rounds])) for k in fns}
    ratio = {k: float(np.median([t["qhull"] / t[k] for t in rounds])) for k in fns if k != "qhull"}
    print(f"median of {args.rounds} rounds: "
          + "  ".join(f"{k} {v * 1e3:.2f} ms" for k, v in med.items())
          + "  |  " + "  ".join(f"qhull/{k} {v:.1f}x" for k, v in ratio.items())
          + f"  (load average {min(load):.1f}-{max(load):.1f})")
    if args.baseline:
        print(f"values bit-identical to {args.baseline}: {identical}")
    result = {"machine": platform.platform(), "grasps": len(grasps), "contacts": 4, "edges": 8,
              "baseline": args.baseline, "rounds": rounds, "median_s": med,
              "median_ratio_qhull_over": ratio, "load_average": load,
              "bit_identical_to_baseline": identical if args.baseline else None}
    first = first_call_seconds()
    for name, t in first.items():
        print(f"fresh process, numba {name.replace('_', ' ')}: import {t['import_s']:.2f} s, "
              f"first grasp_quality call {t['first_call_s']:.2f} s")
    result["first_call"] = first
    results_run.finish([{"method": k, "median_ms": 1e3 * v,
                         "qhull_over_method": ratio.get(k, 1.0)} for k, v in med.items()],
                       result, Path(args.out))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
