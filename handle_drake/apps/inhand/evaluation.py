"""The two evaluation functions of report 5.5.3; both are maximised.

**Old** (the one of Figure 34, one check at the end): how long the object is
kept in the hand and whether it rotated,
``f_old = t_held / t_total + clip(rotation / target, 0, 1)`` in ``[0, 2]``;
2 means held to the end and rotated by the target.

**Incremental** (eqs. 47-49): the motion is cut into ``K`` parts, each ending
with a check of the state (held, rotation at least the benchmark of that
check); a trial stops at the first failed check. Parameters are activated part
by part: those of the meta motions whose demonstrated start falls in part 1
are active from the start, passing check ``k`` activates those of part
``k + 1``.

- ``S_b`` (eq. 47) = number of activated parameters,
- ``S_a`` (eq. 48) = share of the ``L`` planned samples whose state matches
  the benchmark (samples after an early stop count as not matching); with
  partial credit (:func:`sample_credit`, the finger tasks' default) a sample
  below its benchmark counts the share of the benchmark it reached, so a trial
  that turns the object further scores higher even below the checks' thresholds
  (eq. 48 with ``q_i`` in ``[0, 1]``: our interpretation of ``s_i = t_i``),
- ``f = S_a + S_b`` (eq. 49), plus 2 when the target is reached: the final
  check passes *and* the state meets the target strictly (our addition:
  passing the last check activates nothing new, and without it a motion that
  reaches the target would not score above one that fails only the last
  check; the checks allow a tolerance below the benchmark, the bonus does not).

A trial that passes every check but misses the target scores at most
``d + S_a <= d + 1`` (``S_b = d``), one that reaches it at least ``d + 2``: so
``f >= d + 2`` exactly when the target state is reached and a run that stops
on that score stops only on the real target (issue 35: with a bonus of 1 the
target score ``d + 1`` was also reached by ``S_b = d, S_a = 1`` and by a last
check passed within its tolerance). ``floor(f)`` is the number of parameters
Algorithm 2 may update (capped at ``d``), and the maximum is ``d + 3``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["old_score", "incremental_score", "part_dimensions", "target_score", "BONUS",
           "sample_credit"]

#: Added to eq. 49 when the target is reached (> the largest S_a, so reached is f >= d + 2).
BONUS = 2.0


def old_score(held_time: float, total_time: float, rotation: float, target: float) -> float:
    """``t_held / t_total + clip(rotation / target, 0, 1)`` (rotation and target in rad)."""
    if not (total_time > 0 and target > 0):
        raise ValueError(f"total_time and target: expected > 0, got {total_time}, {target}")
    if not (0 <= held_time <= total_time + 1e-9):
        raise ValueError(f"held_time: expected in [0, {total_time}], got {held_time}")
    return float(held_time / total_time + np.clip(rotation / target, 0.0, 1.0))


def part_dimensions(starts, sizes, n_parts: int) -> np.ndarray:
    """Parameters per part: meta motion ``i`` (demonstrated start ``starts[i]``, ``sizes[i]``
    parameters) belongs to part ``floor(start * K) + 1``."""
    if isinstance(n_parts, bool) or not isinstance(n_parts, int) or n_parts < 1:
        raise ValueError(f"n_parts: expected an integer >= 1, got {n_parts!r}")
    starts = np.asarray(starts, dtype=float)
    sizes = np.asarray(sizes, dtype=int)
    if starts.shape != sizes.shape:
        raise ValueError(f"starts and sizes: expected equal lengths, got {starts.shape}, "
                         f"{sizes.shape}")
    if np.any(np.diff(starts) < 0):
        raise ValueError("starts: expected the gist's order (non-decreasing)")
    parts = np.minimum((starts * n_parts).astype(int), n_parts - 1)
    return np.bincount(parts, weights=sizes, minlength=n_parts).astype(int)


def sample_credit(held: bool, value: float, benchmark: float, tolerance: float = 0.0,
                  partial: bool = True) -> float:
    """Eq. 48's ``q_i`` of one sample: 1 when the object is held and ``value`` (its turn) is
    at least ``benchmark - tolerance``, 0 when it is not held; below the benchmark, with
    ``partial``, the share of it reached, ``clip(value / (benchmark - tolerance), 0, 1)``
    (a turn the wrong way: 0), without ``partial`` 0 (the literal ``s_i = t_i``).

    A benchmark within the tolerance of 0 asks only "held". The credit is 1 exactly where
    the binary match is, and below 1 elsewhere, so ``S_a <= 1`` still, the checks, the
    parameters they activate and the target are unchanged: only the ranking of trials
    below the thresholds gains a gradient.
    """
    if not (np.isfinite(value) and np.isfinite(benchmark) and tolerance >= 0):
        raise ValueError(f"sample_credit: expected finite value and benchmark and a tolerance "
                         f">= 0, got {value!r}, {benchmark!r}, {tolerance!r}")
    if not held:
        return 0.0
    need = benchmark - tolerance
    if value >= need:
        return 1.0
    if not partial or need <= 0:
        return 0.0
    return float(np.clip(value / need, 0.0, 1.0))


def incremental_score(dims_per_part, checks_passed: int, matches,
                      reached: bool | None = None) -> tuple[float, float, float]:
    """``(f, S_b, S_a)`` of eqs. 47-49 (see the module doc).

    ``dims_per_part`` (K,): parameters per part; ``checks_passed``: how many
    checks passed in a row (0..K); ``matches`` (L,): per planned sample, whether
    its state matched the benchmark (False for samples not reached), or its
    credit in ``[0, 1]`` (:func:`sample_credit`);
    ``reached``: whether the final state meets the target strictly (None: the
    last check decides alone). The bonus needs both the last check and it.
    """
    dims = np.asarray(dims_per_part, dtype=int)
    K = dims.size
    if not (0 <= checks_passed <= K):
        raise ValueError(f"checks_passed: expected 0..{K}, got {checks_passed}")
    matches = np.asarray(matches, dtype=float)
    if matches.size == 0:
        raise ValueError("matches: expected at least one planned sample")
    if not np.all((matches >= 0) & (matches <= 1)):
        raise ValueError("matches: expected values in [0, 1] (booleans or credits)")
    s_b = float(dims[: min(checks_passed + 1, K)].sum())
    s_a = float(matches.mean())
    bonus = checks_passed == K and (reached is None or bool(reached))
    return s_b + s_a + (BONUS if bonus else 0.0), s_b, s_a


def target_score(dimension: int, evaluation: str) -> float:
    """The score at and above which a trial reached the target (held, rotated by the target)."""
    if evaluation == "incremental":
        return float(dimension) + BONUS
    if evaluation == "old":
        return 2.0
    raise ValueError(f"evaluation: expected 'incremental' or 'old', got {evaluation!r}")
