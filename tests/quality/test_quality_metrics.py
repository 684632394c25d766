"""Force closure and the Bimodal Wrench Space metric against closed-form answers,
Drake's programs and an independent full qhull."""

import itertools

import numpy as np
import pytest

from handle_drake.base.testing import pick
from handle_drake.geometry.quality import (
    ClosurePrograms,
    ContactParams,
    bw_metric,
    bw_metric_batch,
    contact_wrenches,
    ferrari_canny,
    ferrari_canny_linf_qhull,
    grasp_quality,
    hull_volume,
    is_force_closure,
    largest_ball_radius,
    min_norm_point,
    qhull_ball_radius,
    quality_from_wrenches,
    transform_wrenches,
)
from handle_drake.geometry.quality import hull as hull_module
from handle_drake.geometry.quality.hull import EPA_STATS

R_SPHERE = 0.05


def sphere_contacts(directions):
    d = np.asarray(directions, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return R_SPHERE * d, -d


def equator(angles_deg):
    a = np.deg2rad(angles_deg)
    return sphere_contacts(np.stack([np.cos(a), np.sin(a), 0 * a], axis=1))


def random_grasps(rng, count, n_range=(2, 6), spread=0.5):
    """Contacts on a sphere with normals tilted from the radial direction."""
    out = []
    for _ in range(count):
        n = rng.integers(*n_range, endpoint=True)
        d = rng.normal(size=(n, 3))
        p, nrm = sphere_contacts(d)
        nrm = nrm + spread * rng.normal(size=(n, 3))
        out.append((p, nrm))
    return out


# ---------------------------------------------------------------- closed form

def test_antipodal_sphere_frictionless_not_closure():
    """Two collinear normal forces span one direction: rank 1, origin on the hull (BW = 0)."""
    p, n = sphere_contacts([[1, 0, 0], [-1, 0, 0]])
    q = grasp_quality(p, n, ContactParams(model="frictionless"))
    assert not q.force_closure
    assert q.value == pytest.approx(0.0, abs=1e-12)
    assert not is_force_closure(p, n, ContactParams(model="frictionless"))


def test_antipodal_sphere_point_friction_not_closure():
    """Point contacts with friction cannot resist a moment about the line through them:
    every moment is R x x f, orthogonal to x. Origin is in the hull: BW = 0."""
    p, n = sphere_contacts([[1, 0, 0], [-1, 0, 0]])
    params = ContactParams(model="point_friction", mu=0.8)
    W = contact_wrenches(p, n, "point_friction", mu=0.8).reshape(-1, 6)
    np.testing.assert_allclose(W[:, 3], 0.0, atol=1e-15)
    q = grasp_quality(p, n, params)
    assert not q.force_closure and q.value == pytest.approx(0.0, abs=1e-12)
    assert not is_force_closure(p, n, params)


@pytest.mark.parametrize("L", [1.0, 0.05])
def test_antipodal_sphere_soft_finger_closure_radius_is_gamma(L):
    """Torsion supplies the missing moment about x: closure. The hull's support in the
    pure-moment direction e_4 is gamma / L, and for |u| = 1 the support is at least
    |a_x| + mu cos(pi/k) (|a_yz| + R |b_yz|) / 2 + gamma |b_x| / L >= gamma / L when
    gamma / L <= min(1, mu cos(pi/k) / 2, mu cos(pi/k) R / (2 L)); so BW = gamma / L."""
    p, n = sphere_contacts([[1, 0, 0], [-1, 0, 0]])
    params = ContactParams(mu=0.5, gamma=0.002, num_edges=8, characteristic_length=L)
    q = grasp_quality(p, n, params)
    assert q.force_closure
    assert q.value == pytest.approx(0.002 / L, rel=1e-9)
    assert is_force_closure(p, n, params)


def test_single_contact_on_sphere_distance_is_one():
    """All primitive wrenches have unit normal force and no moment about the centre
    beyond tangential terms; their mean (n, 0) has norm 1 and every wrench has norm
    >= 1, so the distance is exactly 1 for every model."""
    p, n = sphere_contacts([[0.3, -0.2, 0.9]])
    for model in ("frictionless", "point_friction", "soft_finger"):
        q = grasp_quality(p, n, ContactParams(model=model, gamma=0.003))
        assert q.value == pytest.approx(-1.0, abs=1e-12)
        assert not q.force_closure


def test_single_frictionless_contact_off_centre_distance():
    p = np.array([[0.02, 0.0, 0.05]])
    n = np.array([[0.0, 0.6, -0.8]])
    q = grasp_quality(p, n, ContactParams(model="frictionless", characteristic_length=0.1))
    expected = np.sqrt(1 + np.sum(np.cross(p[0], n[0]) ** 2) / 0.1**2)
    assert q.value == pytest.approx(-expected, rel=1e-12)


def test_three_contacts_on_equator():
    """120 deg apart: frictionless forces are coplanar through the centre (rank 2, sum
    zero: BW = 0, not closure); with friction the cones add vertical forces and all
    moments: closure; the soft finger hull contains the point-friction hull."""
    p, n = equator([0, 120, 240])
    q0 = grasp_quality(p, n, ContactParams(model="frictionless"))
    assert not q0.force_closure and q0.value == pytest.approx(0.0, abs=1e-12)
    for L in (1.0, R_SPHERE):
        pf = ContactParams(model="point_friction", mu=0.5, characteristic_length=L)
        sf = ContactParams(model="soft_finger", mu=0.5, gamma=0.002, characteristic_length=L)
        q_pf, q_sf = grasp_quality(p, n, pf), grasp_quality(p, n, sf)
        assert q_pf.force_closure and q_sf.force_closure
        assert is_force_closure(p, n, pf)
        assert q_sf.value >= q_pf.value - 1e-12
        W = pf.wrenches(p, n).reshape(-1, 6)
        assert q_pf.value == pytest.approx(qhull_ball_radius(W), abs=1e-10)
    # fewer than 120 deg on one side (all within a half circle) with tiny friction: no
    p, n = equator([0, 40, 80])
    assert not grasp_quality(p, n, ContactParams(mu=0.05, gamma=0.0)).force_closure


# A minimal frictionless closure set on a cube of half-size 1 (7 contacts; 6 unit
# wrenches can never positively span R^6).
BOX_P = np.array([[-0.5, 0.5, -1.0], [0.5, -1.0, 0.5], [-0.5, -0.5, 1.0], [-1.0, 0.5, -0.5],
                  [1.0, -0.5, 0.5], [0.5, 0.5, 1.0], [-0.5, 1.0, -0.5]])
BOX_N = np.array([[0, 0, 1.0], [0, 1, 0], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 0, -1],
                  [0, -1, 0]])


def test_box_minimal_frictionless_closure():
    params = ContactParams(model="frictionless")
    q = grasp_quality(BOX_P, BOX_N, params)
    assert q.force_closure and is_force_closure(BOX_P, BOX_N, params)
    # the hull is a 6-simplex: its radius is the smallest of its 7 facet distances
    W = params.wrenches(BOX_P, BOX_N).reshape(-1, 6)
    dists = []
    for j in range(7):
        F = np.delete(W, j, axis=0)
        a = np.linalg.solve(F, np.ones(6))  # facet plane a.x = 1
        dists.append(1.0 / np.linalg.norm(a))
    assert q.value == pytest.approx(min(dists), rel=1e-12)
    for drop in range(7):  # every 6-subset fails
        sub = np.delete(np.arange(7), drop)
        assert not grasp_quality(BOX_P[sub], BOX_N[sub], params).force_closure
        assert not is_force_closure(BOX_P[sub], BOX_N[sub], params)


def test_all_contacts_on_one_face_never_closure():
    """Every primitive wrench has f . n_face = 1, so |w| >= 1; with contacts symmetric
    about the face centre the mean wrench is (n_face, 0): distance exactly 1."""
    b = 0.3
    p = np.array([[b, b, 1.0], [-b, b, 1.0], [-b, -b, 1.0], [b, -b, 1.0]])
    n = np.tile([0, 0, -1.0], (4, 1))
    for model in ("frictionless", "point_friction", "soft_finger"):
        params = ContactParams(model=model, mu=2.0, gamma=0.05)
        q = grasp_quality(p, n, params)
        assert not q.force_closure and q.value == pytest.approx(-1.0, abs=1e-12)
        assert not is_force_closure(p, n, params)
    rng = np.random.default_rng(7)
    for _ in range(20):  # any contacts on the face: BW <= -1
        pr = np.c_[rng.uniform(-1, 1, (5, 2)), np.ones(5)]
        assert bw_metric(pr, np.tile([0, 0, -1.0], (5, 1)), ContactParams(mu=1.5)) <= -1 + 1e-12


# ---------------------------------------------------------------- agreement

def test_sign_agrees_with_drake_closure_lp_on_random_grasps():
    rng = np.random.default_rng(8)
    progs = ClosurePrograms()
    grasps = random_grasps(rng, pick(400, 200))
    params = ContactParams(mu=0.4, gamma=0.002, num_edges=6, characteristic_length=R_SPHERE)
    n_closure = 0
    for p, n in grasps:
        W = params.wrenches(p, n).reshape(-1, 6)
        q = quality_from_wrenches(W)
        lp = progs.is_force_closure(W)
        assert abs(q.value) > 1e-7  # no grasp sits on the boundary
        assert q.force_closure == lp == (q.value > 0)
        n_closure += lp
    assert 0.2 * len(grasps) < n_closure < 0.8 * len(grasps)  # both modes exercised


def test_fast_path_agrees_with_drake_programs():
    rng = np.random.default_rng(9)
    params = ContactParams(mu=0.5, gamma=0.003, num_edges=8, characteristic_length=R_SPHERE)
    for p, n in random_grasps(rng, pick(80, 30)):
        W = params.wrenches(p, n).reshape(-1, 6)
        fast, drake = quality_from_wrenches(W), quality_from_wrenches(W, method="drake")
        assert fast.force_closure == drake.force_closure
        assert fast.value == pytest.approx(drake.value, abs=1e-6)


def test_min_norm_point_is_optimal():
    """KKT: x = W^T lambda and every wrench satisfies w . x >= |x|^2 (x is the projection)."""
    rng = np.random.default_rng(10)
    for _ in range(30):
        W = rng.normal(size=(40, 6)) + rng.normal(size=6) * 2
        x, d, lam = min_norm_point(W)
        np.testing.assert_allclose(lam @ W, x, atol=1e-12)
        assert np.all(lam >= 0) and lam.sum() == pytest.approx(1.0)
        assert np.min(W @ x) >= d**2 - 1e-10


def test_epa_radius_matches_full_qhull():
    rng = np.random.default_rng(11)
    params = ContactParams(mu=0.6, gamma=0.004, num_edges=8, characteristic_length=R_SPHERE)
    checked = 0
    for p, n in random_grasps(rng, pick(60, 25), n_range=(3, 5)):
        W = params.wrenches(p, n).reshape(-1, 6)
        if min_norm_point(W)[1] > 1e-9:
            continue
        r, u = largest_ball_radius(W)
        assert r == pytest.approx(qhull_ball_radius(W), abs=1e-10)
        assert np.max(W @ u) == pytest.approx(r, abs=1e-10)  # u supports the hull at r
        checked += 1
    assert checked >= 5


def _epa_compacting_reference(W):
    """The EPA as first written (facet lists compacted each step, horizon by np.unique on
    packed ridge keys, the same 6x6 solve per facet): the fast path must give its radius."""
    sup = W[np.argmax(np.vstack([np.eye(6), -np.eye(6)]) @ W.T, axis=1)]
    chosen, basis = [sup[0]], np.empty((0, 6))
    while len(chosen) < 7:
        rel = sup - chosen[0]
        resid = rel - (rel @ basis.T) @ basis
        dist = np.linalg.norm(resid, axis=1)
        j = int(np.argmax(dist))
        assert dist[j] > 1e-9, "reference: the 12 axis supports span no simplex"
        chosen.append(sup[j])
        basis = np.vstack([basis, resid[j] / dist[j]])
    V = list(chosen)
    center = np.mean(chosen, axis=0)

    def oriented(F):
        P = np.array(V)[F]
        A = np.empty_like(P)
        A[:, :5] = P[:, 1:] - P[:, :1]
        A[:, 5] = P[:, 0] - center
        rhs = np.zeros((len(P), 6, 1))
        rhs[:, 5] = 1.0
        N = np.linalg.solve(A, rhs)[..., 0]
        N /= np.sqrt(np.add.reduce(N * N, axis=1, keepdims=True))
        return N, np.einsum("ij,ij->i", N, P[:, 0])

    cols = np.array([[c for c in range(6) if c != j] for j in range(6)])
    F = np.array([[c for c in range(7) if c != j] for j in range(7)])
    N, b = oriented(F)
    scale = max(1.0, float(np.max(np.abs(W))))
    for _ in range(2000):
        j = int(np.argmin(b))
        s = W[np.argmax(W @ N[j])]
        if s @ N[j] - b[j] <= max(1e-12 * scale, 4e-11 * scale):
            return float(b[j])
        vis = N @ s - b > 1e-11 * scale
        V.append(s)
        ridges = F[vis][:, cols].reshape(-1, 5)
        uniq, count = np.unique(ridges, axis=0, return_counts=True)
        horizon = uniq[count == 1]
        F_new = np.hstack([horizon, np.full((len(horizon), 1), len(V) - 1)])
        N_new, b_new = oriented(F_new)
        F = np.concatenate([F[~vis], F_new])
        N = np.concatenate([N[~vis], N_new])
        b = np.concatenate([b[~vis], b_new])
    raise AssertionError("reference EPA did not converge")


def test_epa_equals_the_compacting_reference_and_qhull_on_random_4x8_grasps():
    rng = np.random.default_rng(34)
    params = ContactParams(mu=0.5, gamma=0.002, num_edges=8, characteristic_length=R_SPHERE)
    stats0 = dict(EPA_STATS)
    checked = 0
    for p, n in random_grasps(rng, pick(80, 30), n_range=(4, 4), spread=0.15):
        W = params.wrenches(p, n).reshape(-1, 6)
        if min_norm_point(W)[1] > 1e-9:
            continue
        r, _ = largest_ball_radius(W)
        assert r > 0
        # the same EPA to the last few ulps (numpy's own matmul kernels may sum in another
        # order from one numpy release to the next: 2.4 moved results by 1 ulp)
        assert r == pytest.approx(_epa_compacting_reference(W), rel=1e-14, abs=0)
        assert r == pytest.approx(qhull_ball_radius(W), rel=1e-12)
        checked += 1
    assert checked >= 10
    assert EPA_STATS["fallbacks"] == stats0["fallbacks"]  # no grasp needed qhull


def test_epa_ridge_hash_collisions_fall_back_to_the_exact_answer(monkeypatch):
    """All vertex hashes equal: every ridge key collides, the horizon is lost; the
    exact ridge check must reject the polytope and the radius still be qhull's."""
    rng = np.random.default_rng(35)
    params = ContactParams(mu=0.5, gamma=0.002, num_edges=8, characteristic_length=R_SPHERE)
    monkeypatch.setattr(hull_module, "_VERTEX_HASH", np.zeros_like(hull_module._VERTEX_HASH))
    checked = 0
    for p, n in random_grasps(rng, 20, n_range=(4, 4), spread=0.15):
        W = params.wrenches(p, n).reshape(-1, 6)
        if min_norm_point(W)[1] > 1e-9:
            continue
        before = EPA_STATS["fallbacks"]
        r, _ = largest_ball_radius(W)
        assert EPA_STATS["fallbacks"] == before + 1
        assert r == pytest.approx(qhull_ball_radius(W), rel=1e-12)
        checked += 1
    assert checked >= 3


def test_permutation_invariance():
    rng = np.random.default_rng(12)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    for p, n in random_grasps(rng, 10, n_range=(3, 5)):
        perm = rng.permutation(len(p))
        assert bw_metric(p[perm], n[perm], params) == pytest.approx(bw_metric(p, n, params),
                                                                    abs=1e-12)


def test_continuous_across_the_closure_boundary():
    """Slide one contact of a 3-finger grasp until closure is lost: BW crosses 0 with no
    jump, and on both sides it tends to 0 linearly with the distance to the crossing."""
    params = ContactParams(model="point_friction", mu=0.3, num_edges=8,
                           characteristic_length=R_SPHERE)

    def bw(angle):
        return bw_metric(*equator([0, 120, angle]), params)

    assert bw(240) > 0 and bw(140) < 0
    lo, hi = 140.0, 240.0  # bisection on the sign
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if bw(mid) > 0 else (mid, hi)
    crossing = 0.5 * (lo + hi)
    for delta in (1e-2, 1e-4, 1e-6):
        assert abs(bw(crossing + delta)) < 10 * delta * np.pi / 180 + 1e-12
        assert abs(bw(crossing - delta)) < 10 * delta * np.pi / 180 + 1e-12
    grid = np.linspace(140, 240, 201)
    values = np.array([bw(a) for a in grid])
    assert np.max(np.abs(np.diff(values))) < 0.05  # no jump between neighbours


# ---------------------------------------------------------------- frame (in)dependence

def test_rotating_the_reference_frame_leaves_bw_unchanged():
    """A rotation acts on wrenches by the orthogonal block diag(R, R): norms, hull
    distances and ball radii are invariant (with the contact frames rotated too)."""
    rng = np.random.default_rng(13)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    from pydrake.math import RotationMatrix
    for p, n in random_grasps(rng, 15, n_range=(2, 5)):
        R = RotationMatrix.MakeFromOneVector(rng.normal(size=3), 2).matrix()
        t = np.tile([1.0, 0.0, 0.0], (len(p), 1)) + 0.1  # fixed tangent hints
        q = grasp_quality(p, n, params, tangents=t)
        q_rot = grasp_quality(p @ R.T, n @ R.T, params, tangents=t @ R.T)
        assert q_rot.value == pytest.approx(q.value, abs=1e-12)


def test_moving_the_reference_point_keeps_closure_but_changes_the_value():
    """Moving the moment origin maps wrench space by an invertible, non-orthogonal map:
    closure (origin interior) is preserved, the metric value is not."""
    rng = np.random.default_rng(14)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    changed = 0
    for p, n in random_grasps(rng, 40, n_range=(2, 5)):
        shift = np.array([0.03, -0.02, 0.01])
        q, q_s = grasp_quality(p, n, params), grasp_quality(p - shift, n, params)
        assert q.force_closure == q_s.force_closure
        # same as applying eq. 2 with R = I, p = -shift (scaled) to every wrench
        W = params.wrenches(p, n).reshape(-1, 6)
        Ws = transform_wrenches(W, p_CB=-shift / R_SPHERE)
        np.testing.assert_allclose(Ws, params.wrenches(p - shift, n).reshape(-1, 6), atol=1e-12)
        changed += abs(q.value - q_s.value) > 1e-4
    assert changed > 10


# ---------------------------------------------------------------- references and batch

def test_ferrari_canny_l1_equals_bw_in_closure_and_linf_matches_enumeration():
    p, n = equator([0, 120, 240])
    params = ContactParams(mu=0.5, gamma=0.002, num_edges=4, characteristic_length=R_SPHERE)
    q = grasp_quality(p, n, params)
    assert ferrari_canny(p, n, params, norm="L1") == pytest.approx(q.value, abs=1e-12)
    e_inf = ferrari_canny(p, n, params, norm="Linf")
    assert e_inf == pytest.approx(ferrari_canny_linf_qhull(p, n, params), abs=1e-9)
    assert e_inf >= q.value  # the L-inf set contains the L1 set
    p1, n1 = equator([0, 40])
    assert ferrari_canny(p1, n1, params) == 0.0
    assert ferrari_canny(p1, n1, params, norm="Linf") == 0.0


def test_hull_volume():
    # frictionless 7-contact box: a 6-simplex, volume |det(W[1:] - W[0])| / 6!
    params = ContactParams(model="frictionless")
    W = params.wrenches(BOX_P, BOX_N).reshape(-1, 6)
    expected = abs(np.linalg.det(W[1:] - W[0])) / 720
    assert hull_volume(BOX_P, BOX_N, params) == pytest.approx(expected, rel=1e-9)
    p, n = sphere_contacts([[1, 0, 0], [-1, 0, 0]])
    assert hull_volume(p, n, ContactParams(model="point_friction")) == 0.0  # flat


def test_batch_equals_single_and_accepts_ragged():
    rng = np.random.default_rng(15)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    P = np.stack([sphere_contacts(rng.normal(size=(4, 3)))[0] for _ in range(12)])
    N = -P / R_SPHERE + 0.4 * rng.normal(size=P.shape)
    values = bw_metric_batch(P, N, params)
    single = [bw_metric(p, n, params) for p, n in zip(P, N, strict=True)]
    np.testing.assert_allclose(values, single, atol=1e-14)
    assert bw_metric_batch(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), params).shape == (0,)
    ragged = [P[0], P[1][:2]]
    v2, details = bw_metric_batch(ragged, [N[0], N[1][:2]], params, details=True)
    assert v2[0] == pytest.approx(values[0]) and details[1].value == v2[1]


def test_all_subsets_of_a_closure_grasp_are_monotone():
    """Adding contacts can only enlarge the hull: BW never decreases."""
    rng = np.random.default_rng(16)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    p, n = random_grasps(rng, 1, n_range=(5, 5))[0]
    for k in (2, 3, 4):
        for sub in itertools.combinations(range(5), k):
            sub = list(sub)
            assert bw_metric(p, n, params) >= bw_metric(p[sub], n[sub], params) - 1e-12


def test_epa_on_degenerate_symmetric_box_grasps():
    """Contacts on a grid of a cube's faces give many coplanar and repeated wrenches (the
    hard case for incremental hulls): EPA still matches a full qhull, both modes."""
    rng = np.random.default_rng(17)
    grid = np.array([-0.5, 0.0, 0.5])
    n_closure = 0
    for _ in range(pick(200, 60)):
        model = ("frictionless", "point_friction", "soft_finger")[rng.integers(3)]
        m = int(rng.integers(3, 9))
        axes, signs = rng.integers(3, size=m), rng.choice([-1.0, 1.0], size=m)
        P = rng.choice(grid, size=(m, 3))
        P[np.arange(m), axes] = signs
        N = np.zeros((m, 3))
        N[np.arange(m), axes] = -signs
        params = ContactParams(model=model, mu=0.5, gamma=0.1, num_edges=int(rng.choice([4, 8])))
        W = params.wrenches(P, N).reshape(-1, 6)
        q, r_ref = quality_from_wrenches(W), qhull_ball_radius(W)
        if q.force_closure:
            n_closure += 1
            assert q.value == pytest.approx(r_ref, abs=1e-10)
        else:
            assert r_ref <= 1e-9
            assert q.value == pytest.approx(-min_norm_point(W)[1], abs=1e-12)
    assert n_closure >= 10


def test_moving_the_reference_point_can_reorder_grasps():
    """The report's advice (compare grasps in one reference frame) is needed: some pair
    of closure grasps swaps order when moments are taken about another point."""
    rng = np.random.default_rng(18)
    params = ContactParams(mu=0.5, gamma=0.002, characteristic_length=R_SPHERE)
    grasps = [g for g in random_grasps(rng, 40, n_range=(3, 4), spread=0.3)
              if grasp_quality(*g, params).force_closure][:12]
    shift = np.array([0.04, 0.0, 0.0])
    a = np.array([bw_metric(p, n, params) for p, n in grasps])
    b = np.array([bw_metric(p - shift, n, params) for p, n in grasps])
    swapped = np.sign(a[:, None] - a[None, :]) * np.sign(b[:, None] - b[None, :]) < 0
    assert len(grasps) >= 6 and swapped.any()


def test_the_compiled_epa_equals_the_numpy_epa_to_a_few_ulps(monkeypatch):
    """epa_compiled.epa_loop (numba) against hull._Epa's numpy loop: the same radius and
    normal, to a few ulps, on random 3-5 contact grasps with 4 and 8 friction-cone edges."""
    rng = np.random.default_rng(3434)
    stats0 = dict(EPA_STATS)
    checked = 0
    for k in (4, 8):
        params = ContactParams(mu=0.5, gamma=0.002, num_edges=k, characteristic_length=R_SPHERE)
        for p, n in random_grasps(rng, pick(60, 25), n_range=(3, 5), spread=0.15):
            W = params.wrenches(p, n).reshape(-1, 6)
            if min_norm_point(W)[1] > 1e-9:
                continue
            monkeypatch.setitem(hull_module.COMPILED_EPA, "enabled", True)
            r, u = largest_ball_radius(W)
            monkeypatch.setitem(hull_module.COMPILED_EPA, "enabled", False)
            r_numpy, u_numpy = largest_ball_radius(W)
            assert r > 0
            # to a few ulps: numba's loop and numpy's kernels may sum in another order
            assert r == pytest.approx(r_numpy, rel=1e-14, abs=0)
            np.testing.assert_allclose(u, u_numpy, rtol=0, atol=1e-13)
            checked += 1
    assert checked >= 10
    assert EPA_STATS["fallbacks"] == stats0["fallbacks"]


def test_the_compiled_epa_asks_for_more_points_when_the_axes_support_a_flat(monkeypatch):
    """Two far points (+-10 (1, .., 1)) are the support point of every axis: the axes give
    a 1-D flat, the compiled initial simplex reports it and the numpy one asks the support
    oracle in the orthogonal directions; the radius is still the numpy EPA's, bit for bit,
    and qhull's."""
    W = np.vstack([10 * np.ones(6), -10 * np.ones(6), np.eye(6), -np.eye(6)])
    calls = []
    compiled = hull_module._compiled_init_simplex
    monkeypatch.setattr(hull_module, "_compiled_init_simplex",
                        lambda *a: calls.append(compiled(*a)[0]) or compiled(*a))
    r, _ = largest_ball_radius(W)
    assert calls == [False]
    monkeypatch.setitem(hull_module.COMPILED_EPA, "enabled", False)
    assert r == largest_ball_radius(W)[0]
    assert r == pytest.approx(qhull_ball_radius(W), rel=1e-12)
    assert r > 0.1
