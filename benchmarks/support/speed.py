"""The speed tables of the in-hand benchmarks: cases timed in rounds, ratios to a floor.

Every case runs once per round (ratios hold while the machine's speed drifts). A case
whose name ends in ``(own worker, CPU)`` ran in a worker process of its own
(``trial_worker.py``: nothing else in that process; a new one every round), is timed in
that process's CPU seconds (a worker is single-threaded; CPU time does not count the
waits for a core on a loaded machine) and is divided by the floor that ran in its own
worker too, round by round; the other cases by the floor timed in the benchmark's
process. Both are printed: the benchmark's process interleaves every case (other
diagrams, other allocations between two runs of one), a worker runs one case only, as a
learning loop's worker runs only trials.
"""

from __future__ import annotations

import os

import numpy as np

OWN = " (own worker, CPU)"


def rounds(cases: dict, n: int, workers=(), seed: int = 0) -> dict:
    """``{name: [s per round]}``: every case once per round, in a shuffled order (no case
    keeps one place in the round); the ``workers`` (``BaselineTrial``) are restarted
    before every round but the first (no case keeps one process). Measured, two workers of
    identical code still read 1.007-1.055x (three 7-round runs; 1.045-1.067x without
    either): a ratio within +-5 % of another is not resolved by one run."""
    times = {k: [] for k in cases}
    rng = np.random.default_rng(seed)
    names = list(cases)
    for i in range(n):
        for worker in workers if i else ():
            worker.restart()
        for j in rng.permutation(len(names)):
            times[names[j]].append(cases[names[j]]())
    return times


def ratios(times: dict, floor_name: str, sim_time: float) -> dict:
    """Each case's median and its ratio to its floor (``floor_name``, or ``floor_name``
    + ``OWN`` for a case in its own worker), median of the per-round ratios and their
    range; printed, and returned with the rows for the results page."""
    med = {k: float(np.median(t)) for k, t in times.items()}
    load = os.getloadavg()[0]
    table, ratio = [], {}
    for k, t in med.items():
        floor = floor_name + OWN if k.endswith(OWN) and floor_name + OWN in times else floor_name
        per_round = np.array(times[k]) / np.array(times[floor])
        ratio[k] = t / med[floor]
        print(f"{k:48s} {t:8.3f} s  x{ratio[k]:5.2f} of {floor} (per round: median "
              f"{np.median(per_round):.2f}, {per_round.min():.2f}-{per_round.max():.2f})",
              flush=True)
        table.append({"case": k, "floor": floor, "sim_time": sim_time,
                      "median_wall_s": round(t, 4), "ratio_to_floor": round(ratio[k], 3),
                      "ratio_per_round_median": round(float(np.median(per_round)), 3),
                      "rounds_range": f"{per_round.min():.2f}-{per_round.max():.2f}"})
    print(f"load average now {load:.2f}", flush=True)
    return {"sim_time": sim_time, "median_wall": med, "rounds": times, "table": table,
            "ratio_to_floor": ratio, "load_end": load}


def median_ci(values, confidence: float = 0.95) -> list[float]:
    """Percentile-bootstrap confidence interval of the median of ``values`` (a run's
    per-round ratios), seeded (the same rounds give the same interval): how far the run's
    median may lie from the ratio it estimates, given its rounds' spread (rounds of the same
    builds: the differences between builds are not in it). A run of fewer than 5 rounds
    gives ``[None, None]`` (too few to resolve; null in the JSON)."""
    from scipy.stats import bootstrap

    x = np.asarray(values, dtype=float)
    if x.size < 5:
        return [None, None]
    low, high = bootstrap((x,), np.median, confidence_level=confidence, method="percentile",
                          rng=np.random.default_rng(0)).confidence_interval
    return [float(low), float(high)]


def ci_text(ci) -> str:
    """``median_ci``'s interval as printed: ``[95 % 1.088-1.095]``."""
    if ci[0] is None:
        return "[95 %: too few rounds]"
    return f"[95 % {ci[0]:.3f}-{ci[1]:.3f}]"


def judge(ratio: dict, target: float) -> str:
    """A per-round ratio (``median``, ``ci95``) against ``target`` (at most): "met" when
    the whole interval is at or under it, "met by the median" when the interval straddles
    it, "NOT met" when the median is over it."""
    low, high = ratio["ci95"]
    if ratio["median"] > target:
        return "NOT met"
    if high is None:
        return "met by the median (too few rounds for an interval)"
    if high <= target:
        return "met"
    return f"met by the median (its 95 % interval {low:.3f}-{high:.3f} reaches over {target:.2f})"


def paired(times: dict, a: str, b: str, label: str) -> dict:
    """``a / b`` round by round: its median, the median's 95 % interval and the rounds,
    printed."""
    r = np.array(times[a]) / np.array(times[b])
    ci = median_ci(r)
    print(f"{label}, paired by round: median {np.median(r):.3f} {ci_text(ci)}"
          f" ({' '.join(f'{v:.2f}' for v in r)})", flush=True)
    return {"median": float(np.median(r)), "ci95": ci, "rounds": r.tolist()}


def speed_table(cases: dict, workers: dict, n: int, *, trial: str, floor: str,
                sim_time: float, kind: str, options: dict, baseline: str | None,
                outcome: dict) -> tuple[dict, dict]:
    """Times ``cases`` (in this process) and ``workers`` (``{name: BaselineTrial}``, each
    its own process, CPU s, named ``... + OWN``) in ``n`` rounds; with ``baseline`` also
    the trial ``kind`` of that git revision in a worker, its outcome checked equal to
    ``outcome``. Returns the :func:`ratios` table (plus the trial / floor ratio of the
    workers and, with a baseline, after / before) and the per-round times."""
    from trial_worker import BaselineTrial  # same folder

    workers = dict(workers)
    same = None
    try:
        if baseline:
            before = workers[f"trial at {baseline} (before)" + OWN] = BaselineTrial(
                baseline, kind, options)
            same = before.run()[2] == outcome
            print(f"trial at {baseline}: outcome identical to this tree's: {same}", flush=True)
        timed = {**cases, **{k: (lambda w=w: w.run()[1]) for k, w in workers.items()}}
        times = rounds(timed, n, workers.values())
    finally:
        for worker in workers.values():
            worker.close()
    out = ratios(times, floor, sim_time)
    out["own_worker_trial_over_bare"] = paired(times, trial + OWN, floor + OWN,
                                               "trial / bare plant, each in its own worker")
    if baseline:
        out.update(baseline=baseline, baseline_outcome_identical=same,
                   after_over_before=paired(times, trial + OWN,
                                            f"trial at {baseline} (before)" + OWN,
                                            "after / before (both in workers)"))
    return out, times
