"""Postural synergies: PCA of recorded grasp postures (report section 3.1).

A :class:`Synergies` object maps a few amplitudes ``a`` (k,) to hand joint
angles and back::

    q_act = mean + a @ components[:k]        (actuated joints, rad)
    a     = (q_act - mean) @ components[:k].T

The PCA runs on the *actuated* joints only (for the Shadow hand the 20
command joints): a coupled distal joint ``J1 = ratio * J2`` carries no
information of its own and would double the weight of ``J2``. Mapping
amplitudes to joints clips to the joint limits (tightening a driver's limit so
that its coupled joint stays inside its own) and then re-imposes the coupling.

The PCA itself is scikit-learn's; this module adds what the method needs on
top: the joint bookkeeping, the limits and couplings, the choice of k and the
reconstruction error against k.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from sklearn.decomposition import PCA
from sklearn.model_selection import KFold

from handle_drake.base.hands import get_hand_spec
from handle_drake.grasp.recordings import GraspRecords, load_grasps
from handle_drake.grasp.synthetic import DATA_FILE
from handle_drake.grasp.taxonomy import GraspClass, grasp_info

__all__ = [
    "ClassSynergies",
    "Coupling",
    "Synergies",
    "SizeRegression",
    "choose_k",
    "default_synergies",
    "fit_synergies",
    "reconstruction_error_vs_k",
]


@dataclass(frozen=True)
class Coupling:
    """``q[distal] = ratio * q[driver]`` (the Shadow J1/J2 coupling)."""

    distal: str
    driver: str
    ratio: float


def choose_k(explained_variance_ratio, threshold: float = 0.95) -> int:
    """Smallest k whose first k components explain at least ``threshold``."""
    ratio = np.asarray(explained_variance_ratio, dtype=float)
    if ratio.ndim != 1 or ratio.size == 0:
        raise ValueError(
            f"explained_variance_ratio: expected a non-empty 1-D array, got {ratio.shape}"
        )
    if not 0.0 < threshold <= 1.0:
        raise ValueError(f"threshold must be in (0, 1], got {threshold}")
    cumulative = np.cumsum(ratio)
    # Round-off can leave the total a hair under 1.
    hits = np.nonzero(cumulative >= threshold - 1e-12)[0]
    return int(hits[0] + 1) if hits.size else int(ratio.size)


@dataclass
class Synergies:
    """A PCA synergy basis over ``synergy_joint_names`` of a hand.

    joint_names: all joints of the hand (positions returned in this order).
    synergy_joint_names: the joints the PCA ran on (the actuated ones).
    mean: (m,) rad.  components: (r, m) orthonormal rows, by decreasing variance.
    explained_variance: (r,) rad^2; explained_variance_ratio: (r,).
    lower, upper: (n,) rad, limits of ``joint_names``.
    couplings: distal = ratio * driver relations (distal not in the PCA).
    k: the number of synergies in use (amplitude vectors have k entries).
    amplitude_min, amplitude_max: (r,) range of the training data's amplitudes.
    """

    joint_names: tuple[str, ...]
    synergy_joint_names: tuple[str, ...]
    mean: np.ndarray
    components: np.ndarray
    explained_variance: np.ndarray
    explained_variance_ratio: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    couplings: tuple[Coupling, ...] = ()
    k: int = 2
    amplitude_min: np.ndarray | None = None
    amplitude_max: np.ndarray | None = None
    _sel: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.joint_names = tuple(self.joint_names)
        self.synergy_joint_names = tuple(self.synergy_joint_names)
        n, m = len(self.joint_names), len(self.synergy_joint_names)
        self.mean = np.asarray(self.mean, dtype=float)
        self.components = np.atleast_2d(np.asarray(self.components, dtype=float))
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        if self.mean.shape != (m,):
            raise ValueError(f"mean: expected shape ({m},), got {self.mean.shape}")
        if self.components.ndim != 2 or self.components.shape[1] != m:
            raise ValueError(f"components: expected shape (r, {m}), got {self.components.shape}")
        if self.lower.shape != (n,) or self.upper.shape != (n,):
            raise ValueError(
                f"lower/upper: expected shape ({n},), got {self.lower.shape}, {self.upper.shape}"
            )
        if np.any(self.lower > self.upper):
            raise ValueError("lower must not exceed upper for any joint")
        missing = [j for j in self.synergy_joint_names if j not in self.joint_names]
        if missing:
            raise ValueError(f"synergy joints {missing} are not in joint_names")
        self._sel = np.array([self.joint_names.index(j) for j in self.synergy_joint_names])
        for c in self.couplings:
            if c.distal not in self.joint_names or c.driver not in self.joint_names:
                raise ValueError(f"coupling {c} names a joint not in joint_names")
            if c.driver not in self.synergy_joint_names:
                raise ValueError(f"coupling driver {c.driver} must be a synergy joint")
        self.k = self._check_k(self.k)

    # ---- sizes ---------------------------------------------------------------
    @property
    def num_components(self) -> int:
        return self.components.shape[0]

    def _check_k(self, k) -> int:
        if not isinstance(k, int | np.integer) or not 1 <= k <= self.num_components:
            raise ValueError(f"k must be an int in [1, {self.num_components}], got {k!r}")
        return int(k)

    def with_k(self, k: int) -> Synergies:
        """A copy that uses the first ``k`` synergies."""
        return Synergies(
            self.joint_names, self.synergy_joint_names, self.mean, self.components,
            self.explained_variance, self.explained_variance_ratio, self.lower, self.upper,
            self.couplings, k, self.amplitude_min, self.amplitude_max,
        )  # fmt: skip

    # ---- limits --------------------------------------------------------------
    def synergy_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Limits of the synergy joints, tightened so every coupled joint stays in its own."""
        lo, hi = self.lower[self._sel].copy(), self.upper[self._sel].copy()
        for c in self.couplings:
            d = self.synergy_joint_names.index(c.driver)
            j = self.joint_names.index(c.distal)
            if c.ratio > 0:
                lo[d] = max(lo[d], self.lower[j] / c.ratio)
                hi[d] = min(hi[d], self.upper[j] / c.ratio)
            elif c.ratio < 0:
                lo[d] = max(lo[d], self.upper[j] / c.ratio)
                hi[d] = min(hi[d], self.lower[j] / c.ratio)
        return lo, hi

    # ---- maps ----------------------------------------------------------------
    def _amplitudes(self, a) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.shape[-1:] != (self.k,) or a.ndim > 2:
            raise ValueError(
                f"amplitudes: expected shape ({self.k},) or (N, {self.k}), got {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise ValueError("amplitudes must be finite")
        return a

    def amplitudes_to_command(self, a) -> np.ndarray:
        """Amplitudes (k,) or (N, k) -> synergy-joint angles (m,) or (N, m), within limits."""
        a = self._amplitudes(a)
        q = self.mean + a @ self.components[: self.k]
        lo, hi = self.synergy_limits()
        return np.clip(q, lo, hi)

    def command_to_positions(self, q_syn) -> np.ndarray:
        """Synergy-joint angles -> all joints; non-synergy joints from ``fill`` rules.

        Coupled distal joints get ``ratio * driver``; any other joint that is not
        a synergy joint is held at the middle of its range clipped to [0, upper]
        (for the Shadow hand there are none).
        """
        q_syn = np.asarray(q_syn, dtype=float)
        m = len(self.synergy_joint_names)
        if q_syn.shape[-1:] != (m,) or q_syn.ndim > 2:
            raise ValueError(f"expected shape ({m},) or (N, {m}), got {q_syn.shape}")
        batch = q_syn.reshape(-1, m)
        out = np.tile(np.clip(0.0, self.lower, self.upper), (batch.shape[0], 1))
        out[:, self._sel] = batch
        for c in self.couplings:
            d = self.joint_names.index(c.driver)
            j = self.joint_names.index(c.distal)
            out[:, j] = c.ratio * out[:, d]
        out = np.clip(out, self.lower, self.upper)
        return out.reshape(q_syn.shape[:-1] + (len(self.joint_names),))

    def amplitudes_to_positions(self, a) -> np.ndarray:
        """Amplitudes -> all joint angles (rad), within limits and coupling."""
        return self.command_to_positions(self.amplitudes_to_command(a))

    def positions_to_amplitudes(self, q) -> np.ndarray:
        """All joint angles (n,)/(N, n), or synergy-joint angles (m,)/(N, m) -> amplitudes."""
        q = np.asarray(q, dtype=float)
        n, m = len(self.joint_names), len(self.synergy_joint_names)
        if q.shape[-1:] == (n,) and q.ndim <= 2:
            q = q[..., self._sel]
        elif not (q.shape[-1:] == (m,) and q.ndim <= 2):
            raise ValueError(f"positions: expected last dimension {n} or {m}, got shape {q.shape}")
        return (q - self.mean) @ self.components[: self.k].T

    def reconstruct(self, q) -> np.ndarray:
        """Project all-joint angles onto the first k synergies and back (unclipped)."""
        q = np.asarray(q, dtype=float)
        a = self.positions_to_amplitudes(q)
        q_syn = self.mean + a @ self.components[: self.k]
        return self.command_to_positions(q_syn) if q.shape[-1] == len(self.joint_names) else q_syn

    def amplitude_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(k,) min and max amplitudes seen in the training data (search box for optimisers)."""
        if self.amplitude_min is None or self.amplitude_max is None:
            raise ValueError("these synergies carry no amplitude range (not fitted from data)")
        return self.amplitude_min[: self.k].copy(), self.amplitude_max[: self.k].copy()

    # ---- files ---------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write an ``.npz`` file (no pickles)."""
        path = Path(path)
        np.savez(
            path,
            joint_names=np.array(self.joint_names),
            synergy_joint_names=np.array(self.synergy_joint_names),
            mean=self.mean, components=self.components,
            explained_variance=self.explained_variance,
            explained_variance_ratio=self.explained_variance_ratio,
            lower=self.lower, upper=self.upper,
            coupling_distal=np.array([c.distal for c in self.couplings], dtype=str),
            coupling_driver=np.array([c.driver for c in self.couplings], dtype=str),
            coupling_ratio=np.array([c.ratio for c in self.couplings], dtype=float),
            k=self.k,
            amplitude_min=self.amplitude_min if self.amplitude_min is not None else np.array([]),
            amplitude_max=self.amplitude_max if self.amplitude_max is not None else np.array([]),
        )  # fmt: skip
        return path

    @classmethod
    def load(cls, path: str | Path) -> Synergies:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no synergy file {path}")
        with np.load(path, allow_pickle=False) as f:
            couplings = tuple(
                Coupling(str(d), str(r), float(x))
                for d, r, x in zip(f["coupling_distal"], f["coupling_driver"],
                                   f["coupling_ratio"], strict=True)
            )  # fmt: skip
            amin, amax = f["amplitude_min"], f["amplitude_max"]
            return cls(
                tuple(str(s) for s in f["joint_names"]),
                tuple(str(s) for s in f["synergy_joint_names"]),
                f["mean"], f["components"], f["explained_variance"],
                f["explained_variance_ratio"], f["lower"], f["upper"], couplings,
                int(f["k"]), amin if amin.size else None, amax if amax.size else None,
            )  # fmt: skip


def _select(q, joint_names, synergy_joint_names) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != len(joint_names):
        raise ValueError(f"q: expected shape (N, {len(joint_names)}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q: joint angles must be finite")
    idx = [list(joint_names).index(j) for j in synergy_joint_names]
    return q[:, idx]


def fit_synergies(
    q,
    joint_names: Sequence[str],
    lower,
    upper,
    synergy_joint_names: Sequence[str] | None = None,
    couplings: Sequence[Coupling] = (),
    k: int | None = None,
    variance: float = 0.95,
) -> Synergies:
    """PCA synergies from postures ``q`` (N, n) rad.

    synergy_joint_names: the joints to run PCA on (default: every joint that is
      not the distal side of a coupling).
    k: synergies in use; default the smallest k explaining ``variance``.
    """
    joint_names = tuple(joint_names)
    if synergy_joint_names is None:
        distal = {c.distal for c in couplings}
        synergy_joint_names = tuple(j for j in joint_names if j not in distal)
    synergy_joint_names = tuple(synergy_joint_names)
    x = _select(q, joint_names, synergy_joint_names)
    if x.shape[0] < 2:
        raise ValueError(f"need at least 2 postures to fit synergies, got {x.shape[0]}")
    pca = PCA(svd_solver="full").fit(x)
    # Components with (numerically) zero variance carry no synergy; dropping
    # them keeps the basis to the data's rank.
    # Variance below 1e-18 rad^2 (1e-9 rad spread) is round-off of constant data.
    ev = pca.explained_variance_
    keep = (ev > 1e-12 * ev[0]) & (ev > 1e-18)
    components = pca.components_[keep]
    ratio = pca.explained_variance_ratio_[keep]
    if components.shape[0] == 0:
        raise ValueError("the postures do not vary: no synergy can be fitted")
    amplitudes = (x - pca.mean_) @ components.T
    if k is None:
        k = choose_k(ratio, variance)
    elif not 1 <= int(k) <= components.shape[0]:
        raise ValueError(
            f"k must be in [1, {components.shape[0]}] (the rank of the data), got {k}"
        )
    return Synergies(
        joint_names, synergy_joint_names, pca.mean_, components,
        pca.explained_variance_[keep], ratio, lower, upper, tuple(couplings),
        int(k),
        amplitudes.min(axis=0), amplitudes.max(axis=0),
    )  # fmt: skip


def reconstruction_error_vs_k(
    q,
    joint_names: Sequence[str],
    synergy_joint_names: Sequence[str],
    k_max: int | None = None,
    folds: int = 5,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """RMS joint-angle error (rad) of reconstructing postures from k synergies.

    Returns ``{"k": 0..k_max, "train_rms": ..., "test_rms": ..., "max_abs": ...,
    "explained": cumulative explained variance ratio}``; ``test_rms`` is the
    ``folds``-fold cross-validated error (fit on the other folds), so it does
    not fall to zero just because k reaches the number of joints. k = 0 is the
    mean posture alone. Errors are over the synergy joints, unclipped.
    """
    x = _select(q, joint_names, synergy_joint_names)
    n, m = x.shape
    if n < max(2, folds):
        raise ValueError(f"need at least {max(2, folds)} postures, got {n}")
    k_max = m if k_max is None else int(k_max)
    if not 1 <= k_max <= m:
        raise ValueError(f"k_max must be in [1, {m}], got {k_max}")
    ks = np.arange(k_max + 1)

    def errors(train, test):
        pca = PCA(svd_solver="full").fit(train)
        d = test - pca.mean_
        rms, mx = [], []
        for k in ks:
            c = pca.components_[:k]
            r = d - (d @ c.T) @ c
            rms.append(np.mean(r**2))
            mx.append(np.max(np.abs(r)))
        return np.array(rms), np.array(mx), np.cumsum(np.r_[0.0, pca.explained_variance_ratio_])

    train_ms, max_abs, explained = errors(x, x)
    test_ms = np.zeros_like(train_ms)
    for tr, te in KFold(folds, shuffle=True, random_state=seed).split(x):
        ms, _, _ = errors(x[tr], x[te])
        test_ms += ms * len(te)
    test_ms /= n
    return {
        "k": ks,
        "train_rms": np.sqrt(train_ms),
        "test_rms": np.sqrt(test_ms),
        "max_abs": max_abs,
        "explained": explained[: k_max + 1],
    }


@dataclass
class SizeRegression:
    """Linear model of synergy amplitudes against object size: ``a(s) = a0 + a1 s``.

    Fitted per grasp class; gives the pre-shape of a class for a new size.
    """

    synergies: Synergies
    intercept: np.ndarray
    slope: np.ndarray
    size_min: float
    size_max: float

    @classmethod
    def fit(cls, synergies: Synergies, q, sizes) -> SizeRegression:
        q = np.asarray(q, dtype=float)
        sizes = np.asarray(sizes, dtype=float)
        if q.ndim != 2 or sizes.shape != (q.shape[0],):
            raise ValueError(f"expected q (N, n) and sizes (N,), got {q.shape} and {sizes.shape}")
        if np.ptp(sizes) <= 0:
            raise ValueError("sizes must vary to fit a size regression")
        a = synergies.positions_to_amplitudes(q)
        design = np.column_stack([np.ones_like(sizes), sizes])
        coef, *_ = np.linalg.lstsq(design, a, rcond=None)
        return cls(synergies, coef[0], coef[1], float(sizes.min()), float(sizes.max()))

    def amplitudes(self, size: float) -> np.ndarray:
        size = float(size)
        if not np.isfinite(size) or size <= 0:
            raise ValueError(f"size must be positive and finite, got {size}")
        return self.intercept + self.slope * size

    def positions(self, size: float) -> np.ndarray:
        return self.synergies.amplitudes_to_positions(self.amplitudes(size))


# ---------------------------------------------------------------- per grasp class


def fit_record_synergies(records: GraspRecords, k: int | None = None, variance: float = 0.95,
                         grasp_class=None, coupling_ratio: float | None = None) -> Synergies:
    """PCA synergies of recorded Shadow postures over the 20 command joints.

    grasp_class: fit only that class's grasps (per-class synergies).
    coupling_ratio: J1/J2 ratio used when mapping back (default 1.0, C6 hand).
    """
    spec = get_hand_spec("shadow")
    if grasp_class is not None:
        records = records.of_class(grasp_class)
    ratio = 1.0 if coupling_ratio is None else float(coupling_ratio)
    couplings = tuple(Coupling(f, l, ratio) for f, l, _ in spec.couplings)
    return fit_synergies(
        records.q, spec.joint_names, spec.joint_lower_limits, spec.joint_upper_limits,
        synergy_joint_names=spec.actuated_joint_names, couplings=couplings, k=k,
        variance=variance,
    )  # fmt: skip


@dataclass
class ClassSynergies:
    """Global synergies plus, per class, the amplitude-vs-size regression."""

    synergies: Synergies
    regressions: dict[GraspClass, SizeRegression]

    def amplitudes(self, grasp_class, size: float) -> np.ndarray | None:
        """Amplitudes (k,) of the class's pre-shape at ``size`` (m), or None without data."""
        reg = self.regressions.get(grasp_info(grasp_class).grasp_class)
        return None if reg is None else reg.amplitudes(size)

    def posture(self, grasp_class, size: float) -> np.ndarray | None:
        """All 24 joints (rad) of the class's synergy pre-shape at ``size``, or None."""
        a = self.amplitudes(grasp_class, size)
        return None if a is None else self.synergies.amplitudes_to_positions(a)

    @classmethod
    def fit(cls, records, k: int | None = None, variance: float = 0.95) -> ClassSynergies:
        """Fit from :class:`~handle_drake.grasp.recordings.GraspRecords`."""
        syn = fit_record_synergies(records, k=k, variance=variance)
        regs = {}
        for gc in GraspClass:
            sub = records.of_class(gc)
            if len(sub) >= 2 and np.ptp(sub.sizes) > 0:
                regs[gc] = SizeRegression.fit(syn, sub.q, sub.sizes)
        return cls(syn, regs)


@lru_cache(maxsize=1)
def default_synergies() -> ClassSynergies:
    """Synergies and size regressions fitted on the shipped grasp data set."""
    return ClassSynergies.fit(load_grasps(DATA_FILE))
