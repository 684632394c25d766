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
  the benchmark (samples after an early stop count as not matching),
- ``f = S_a + S_b`` (eq. 49), plus 1 when the final check passes (our
  addition: passing the last check activates nothing new, and without it a
  motion that reaches the target would not score above one that fails only
  the last check).

So ``f >= d + 1`` exactly when the target state is reached, ``floor(f)`` is
the number of parameters Algorithm 2 may update (``d`` for a complete pass),
and the maximum is ``d + 2``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["old_score", "incremental_score", "part_dimensions", "target_score"]


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


def incremental_score(dims_per_part, checks_passed: int, matches) -> tuple[float, float, float]:
    """``(f, S_b, S_a)`` of eqs. 47-49 (see the module doc).

    ``dims_per_part`` (K,): parameters per part; ``checks_passed``: how many
    checks passed in a row (0..K); ``matches`` (L,): per planned sample, whether
    its state matched the benchmark (False for samples not reached).
    """
    dims = np.asarray(dims_per_part, dtype=int)
    K = dims.size
    if not (0 <= checks_passed <= K):
        raise ValueError(f"checks_passed: expected 0..{K}, got {checks_passed}")
    matches = np.asarray(matches, dtype=bool)
    if matches.size == 0:
        raise ValueError("matches: expected at least one planned sample")
    s_b = float(dims[: min(checks_passed + 1, K)].sum())
    s_a = float(matches.mean())
    return s_b + s_a + (1.0 if checks_passed == K else 0.0), s_b, s_a


def target_score(dimension: int, evaluation: str) -> float:
    """The score at and above which a trial reached the target (held, rotated by the target)."""
    if evaluation == "incremental":
        return float(dimension) + 1.0
    if evaluation == "old":
        return 2.0
    raise ValueError(f"evaluation: expected 'incremental' or 'old', got {evaluation!r}")
