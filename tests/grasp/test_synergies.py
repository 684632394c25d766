"""PCA synergies against data of known rank and closed-form noise residuals."""

import numpy as np
import pytest

from handle_drake.base.hands import get_hand_spec
from handle_drake.grasp.synergies import (
    Coupling,
    SizeRegression,
    Synergies,
    choose_k,
    fit_synergies,
    reconstruction_error_vs_k,
)

SPEC = get_hand_spec("shadow")
NAMES = SPEC.joint_names
ACT = SPEC.actuated_joint_names
COUPLINGS = tuple(Coupling(f, l, 1.1) for f, l, _ in SPEC.couplings)
LO, HI = SPEC.joint_lower_limits, SPEC.joint_upper_limits


def _rank_data(rank, n=200, noise=0.0, seed=0):
    """Postures mean + A @ B (rank ``rank``) over the 20 actuated joints, J1 = 1.1 J2."""
    rng = np.random.default_rng(seed)
    mid = 0.5 * (LO + HI)
    basis = np.linalg.qr(rng.normal(size=(20, rank)))[0].T  # orthonormal rows
    amps = rng.normal(scale=0.15, size=(n, rank))
    act = mid[[NAMES.index(j) for j in ACT]] + amps @ basis + noise * rng.normal(size=(n, 20))
    q = np.zeros((n, 24))
    q[:, [NAMES.index(j) for j in ACT]] = act
    for c in COUPLINGS:
        q[:, NAMES.index(c.distal)] = 1.1 * q[:, NAMES.index(c.driver)]
    return q, basis


def _fit(q, **kw):
    return fit_synergies(q, NAMES, LO, HI, couplings=COUPLINGS, **kw)


def test_known_rank_round_trip():
    q, basis = _rank_data(rank=3)
    syn = _fit(q, variance=0.999)
    assert syn.synergy_joint_names == ACT  # the coupled J1s are not in the PCA
    assert syn.num_components == 3 and syn.k == 3
    np.testing.assert_allclose(np.cumsum(syn.explained_variance_ratio)[-1], 1.0)
    # The fitted subspace is the generating one: projecting B onto it keeps B.
    c = syn.components
    np.testing.assert_allclose(basis @ c.T @ c, basis, atol=1e-10)
    # amplitudes -> joints -> amplitudes, and joints -> amplitudes -> joints.
    a = syn.positions_to_amplitudes(q)
    np.testing.assert_allclose(syn.amplitudes_to_positions(a), q, atol=1e-10)
    np.testing.assert_allclose(syn.positions_to_amplitudes(syn.amplitudes_to_positions(a[:5])),
                               a[:5], atol=1e-10)


def test_reconstruction_error_vs_k_closed_form():
    sigma, m = 0.01, 20
    q, _ = _rank_data(rank=3, n=400, noise=sigma, seed=1)
    table = reconstruction_error_vs_k(q, NAMES, ACT, k_max=8)
    assert np.all(np.diff(table["train_rms"]) <= 1e-12)
    # Two synergies miss the third (amplitude std 0.15 spread over m joints).
    assert table["train_rms"][2] == pytest.approx(np.sqrt((0.15**2 + (m - 2) * sigma**2) / m),
                                                  rel=0.15)
    # Past the true rank only isotropic noise is left: per-joint RMS of the
    # residual of m-dim noise after removing k directions is sigma*sqrt((m-k)/m).
    for k in (3, 5, 8):
        expected = sigma * np.sqrt((m - k) / m)
        assert table["test_rms"][k] == pytest.approx(expected, rel=0.1)
    assert table["explained"][0] == 0.0 and table["explained"][3] > 0.95


def test_choose_k():
    ratio = [0.5, 0.3, 0.15, 0.05]
    assert choose_k(ratio, 0.8) == 2
    assert choose_k(ratio, 0.95) == 3
    assert choose_k(ratio, 1.0) == 4
    with pytest.raises(ValueError, match=r"threshold must be in \(0, 1\]"):
        choose_k(ratio, 1.5)


def test_limits_and_coupling_are_respected():
    q, _ = _rank_data(rank=4)
    syn = _fit(q, k=4)
    big = syn.amplitudes_to_positions(np.array([50.0, -50.0, 50.0, -50.0]))
    assert np.all(big >= LO - 1e-12) and np.all(big <= HI + 1e-12)
    for c in COUPLINGS:
        assert big[NAMES.index(c.distal)] == pytest.approx(1.1 * big[NAMES.index(c.driver)])
    # The J2 range is tightened so that J1 = 1.1 J2 never passes J1's upper limit.
    lo, hi = syn.synergy_limits()
    assert hi[ACT.index("FFJ2")] == pytest.approx(HI[NAMES.index("FFJ1")] / 1.1)
    cmd = syn.amplitudes_to_command(np.full(4, 50.0))
    assert cmd.shape == (20,) and np.all(cmd <= hi + 1e-12)


def test_bad_input():
    q, _ = _rank_data(rank=3)
    syn = _fit(q, k=2)
    with pytest.raises(ValueError, match=r"amplitudes: expected shape \(2,\)"):
        syn.amplitudes_to_positions(np.zeros(3))
    with pytest.raises(ValueError, match="expected last dimension 24 or 20"):
        syn.positions_to_amplitudes(np.zeros(7))
    with pytest.raises(ValueError, match=r"k must be in \[1, 3\]"):
        _fit(q, k=5)
    with pytest.raises(ValueError, match=r"k must be an int in \[1, 3\]"):
        syn.with_k(0)
    with pytest.raises(ValueError, match=r"q: expected shape \(N, 24\)"):
        _fit(q[:, :10])
    with pytest.raises(ValueError, match="do not vary"):
        _fit(np.tile(q[0], (5, 1)))
    with pytest.raises(ValueError, match="must be finite"):
        syn.amplitudes_to_positions(np.array([np.nan, 0.0]))


def test_save_load(tmp_path):
    q, _ = _rank_data(rank=3)
    syn = _fit(q)
    back = Synergies.load(syn.save(tmp_path / "s.npz"))
    a = np.array([0.1, -0.2, 0.05])[: syn.k]
    np.testing.assert_allclose(back.amplitudes_to_positions(a), syn.amplitudes_to_positions(a))
    assert back.couplings == syn.couplings
    with pytest.raises(FileNotFoundError):
        Synergies.load(tmp_path / "none.npz")


def test_size_regression_recovers_a_linear_preshape():
    # Postures that open linearly with object size along one synergy direction.
    sizes = np.linspace(0.02, 0.08, 30)
    q0, _ = _rank_data(rank=2, n=1)
    direction = np.zeros(24)
    direction[NAMES.index("FFJ3")] = -3.0
    direction[NAMES.index("THJ4")] = 2.0
    q = q0 + sizes[:, None] * direction
    syn = _fit(q, k=1)
    reg = SizeRegression.fit(syn, q, sizes)
    np.testing.assert_allclose(reg.positions(0.05), q0[0] + 0.05 * direction, atol=1e-10)
    with pytest.raises(ValueError, match="sizes must vary"):
        SizeRegression.fit(syn, q, np.full(30, 0.05))
