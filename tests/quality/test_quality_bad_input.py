"""Bad input: a clear error or the correct 'not in closure' answer, never a crash."""

import numpy as np
import pytest

from handle_drake.geometry.quality import (
    ClosurePrograms,
    ContactParams,
    bw_metric,
    bw_metric_batch,
    ferrari_canny,
    grasp_quality,
    hull_volume,
    is_force_closure,
    largest_ball_radius,
    min_norm_point,
    qhull_ball_radius,
    quality_from_wrenches,
)

P1 = np.array([[0.05, 0, 0]])
N1 = np.array([[-1.0, 0, 0]])


@pytest.mark.parametrize("fn", [bw_metric, grasp_quality, is_force_closure, hull_volume,
                                ferrari_canny])
def test_no_contacts(fn):
    with pytest.raises(ValueError, match="at least one contact"):
        fn(np.zeros((0, 3)), np.zeros((0, 3)))


def test_one_contact_is_not_closure_with_its_distance():
    q = grasp_quality(P1, N1)
    assert not q.force_closure and q.value == pytest.approx(-1.0)
    assert not is_force_closure(P1, N1)
    assert hull_volume(P1, N1) == 0.0
    assert ferrari_canny(P1, N1) == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_values(bad):
    p = np.array([[0.05, 0, 0], [-0.05, 0, bad]])
    n = np.array([[-1.0, 0, 0], [1.0, 0, 0]])
    with pytest.raises(ValueError, match="points: expected finite"):
        bw_metric(p, n)
    with pytest.raises(ValueError, match="normals: expected finite"):
        bw_metric(n, p)
    with pytest.raises(ValueError, match="finite"):
        quality_from_wrenches(np.full((8, 6), bad))
    with pytest.raises(ValueError, match="finite"):
        ClosurePrograms().min_distance(np.full((8, 6), bad))


def test_normals_zero_and_non_unit():
    p = np.array([[0.05, 0, 0], [-0.05, 0, 0]])
    with pytest.raises(ValueError, match="zero normal at \\[1\\]"):
        bw_metric(p, np.array([[-1.0, 0, 0], [0, 0, 0]]))
    # a normal is a direction: scaling it changes nothing
    a = bw_metric(p, np.array([[-1.0, 0, 0], [1.0, 0, 0]]))
    b = bw_metric(p, np.array([[-7.0, 0, 0], [0.2, 0, 0]]))
    assert a == pytest.approx(b, abs=1e-15)


def test_shapes_and_types():
    with pytest.raises(ValueError, match="expected shape \\(n, 3\\), got \\(2, 2\\)"):
        bw_metric(np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="shape of points"):
        bw_metric(np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(TypeError, match="array of numbers"):
        bw_metric([["a", "b", "c"]], N1)
    with pytest.raises(ValueError, match="\\(m, 6\\)"):
        quality_from_wrenches(np.zeros((4, 5)))
    with pytest.raises(ValueError, match="\\(m, 6\\)"):
        ClosurePrograms().closure_lp(np.zeros((4, 5)))
    with pytest.raises(ValueError, match="at least one wrench"):
        min_norm_point(np.zeros((0, 6)))
    with pytest.raises(ValueError, match="method"):
        quality_from_wrenches(np.eye(6), method="magic")
    with pytest.raises(ValueError, match="grasp 1"):
        bw_metric_batch([P1, P1], [N1, np.zeros((1, 3))])
    with pytest.raises(ValueError, match="expected 2 grasps"):
        bw_metric_batch([P1, P1], [N1])


@pytest.mark.parametrize("kwargs", [dict(mu=-0.5), dict(gamma=-0.01), dict(mu=np.inf)])
def test_negative_or_infinite_coefficients(kwargs):
    with pytest.raises(ValueError, match="expected a finite value >= 0"):
        ContactParams(**kwargs)


def test_rank_deficient_and_coplanar_wrench_sets():
    """qhull fails on flat sets; that must come out as 'not in closure', never an error."""
    planar = np.zeros((10, 6))
    planar[:, :2] = np.random.default_rng(0).normal(size=(10, 2))  # origin inside, flat
    assert quality_from_wrenches(planar).value == pytest.approx(0.0, abs=1e-12)
    assert not quality_from_wrenches(planar).force_closure
    assert quality_from_wrenches(planar, method="drake").force_closure is False
    assert qhull_ball_radius(planar) == 0.0
    assert largest_ball_radius(planar)[0] == 0.0
    zeros = np.zeros((7, 6))
    q = quality_from_wrenches(zeros)
    assert q.value == 0.0 and not q.force_closure
    dup = np.tile(np.eye(6)[0], (9, 1))
    assert quality_from_wrenches(dup).value == pytest.approx(-1.0)
    # contacts all on one line with normals along it: rank 1
    p = np.array([[0, 0, 0.05], [0, 0, -0.05], [0, 0, 0.05]])
    n = np.array([[0, 0, -1.0], [0, 0, 1.0], [0, 0, -1.0]])
    params = ContactParams(model="frictionless")
    assert grasp_quality(p, n, params).value == pytest.approx(0.0, abs=1e-12)
    assert hull_volume(p, n, params) == 0.0
    assert not is_force_closure(p, n, params)


def test_huge_and_tiny_scales_do_not_break():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(4, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for scale in (1e-6, 1e3):
        # the same grasp in other units: lengths (and gamma, a length) scale together
        params = ContactParams(gamma=0.02 * scale, characteristic_length=scale)
        q = grasp_quality(scale * d, -d, params)
        q_ref = grasp_quality(d, -d, ContactParams(gamma=0.02))
        assert q.value == pytest.approx(q_ref.value, rel=1e-6, abs=1e-12)


# --- extreme ranges (issue 15): computed correctly up to the limits, refused beyond ---

def _tetrahedron():
    P = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(3) * 0.05
    return P, -P / 0.05


def test_closure_grasp_stays_in_closure_up_to_the_largest_accepted_mu():
    """Four contacts of a regular tetrahedron are in closure for any mu > 0; for mu >> 1
    the cone edges (length mu) dominate the unit normal, so the largest ball grows in
    proportion to mu (mu = 1e9 used to read as not in closure, 1e6 raised LinAlgError)."""
    from handle_drake.geometry.quality import ContactParams, grasp_quality
    from handle_drake.geometry.quality.contact import MAX_MU

    P, N = _tetrahedron()
    values = {mu: grasp_quality(P, N, ContactParams(mu=mu, characteristic_length=0.05))
              for mu in (0.5, 100.0, MAX_MU)}
    assert all(q.force_closure for q in values.values())
    assert values[MAX_MU].value / MAX_MU == pytest.approx(values[100.0].value / 100.0, rel=1e-3)


@pytest.mark.parametrize("params,field", [
    (dict(mu=1e9), "mu"), (dict(num_edges=10000), "num_edges"), (dict(gamma=1e6), "gamma")])
def test_extreme_friction_parameters_are_refused_naming_the_field(params, field):
    from handle_drake.geometry.quality import ContactParams, grasp_quality

    P, N = _tetrahedron()
    with pytest.raises(ValueError, match=field):
        grasp_quality(P, N, ContactParams(characteristic_length=0.05, **params))


def test_points_far_beyond_the_characteristic_length_are_refused():
    from handle_drake.geometry.quality import ContactParams, grasp_quality

    P, N = _tetrahedron()
    with pytest.raises(ValueError, match="points: expected coordinates within"):
        grasp_quality(P * 1e302, N, ContactParams(characteristic_length=0.05))


def test_complex_input_is_refused_not_truncated():
    from handle_drake.geometry.quality import ContactParams, grasp_quality, quality_from_wrenches

    P, N = _tetrahedron()
    with pytest.raises(TypeError, match="points: expected real numbers, got complex"):
        grasp_quality(P * (1 + 1j), N, ContactParams(characteristic_length=0.05))
    with pytest.raises(TypeError, match="wrenches: expected real numbers"):
        quality_from_wrenches(np.ones((8, 6)) * 1j)
    with pytest.raises(TypeError, match="mu"):
        ContactParams(mu=0.5 + 0j)


def test_drake_method_refuses_more_wrenches_than_its_dense_lp_holds():
    from handle_drake.geometry.quality import quality_from_wrenches

    W = np.random.default_rng(0).normal(size=(160000, 6))
    with pytest.raises(ValueError, match="at most 4000 wrenches .* method='fast'"):
        quality_from_wrenches(W, method="drake")


@pytest.mark.parametrize("scale", [1e-3, 1e8, 1e100])
def test_the_metric_scales_with_the_wrenches(scale):
    """Scaling every wrench by s scales the BW value by s (a homogeneous geometric
    quantity); absolute tolerances used to call a closure set at s = 1e8 open, and a
    single wrench of 4.5e15 made NNLS return zero weights."""
    from handle_drake.geometry.quality import min_norm_point, quality_from_wrenches

    W = np.random.default_rng(1).normal(size=(40, 6))
    base = quality_from_wrenches(W)
    scaled = quality_from_wrenches(W * scale)
    assert base.force_closure and scaled.force_closure
    assert scaled.value == pytest.approx(base.value * scale, rel=1e-9)
    assert min_norm_point([[4503599627370496.0, 0, 0, 0, 0, 0]])[1] == 4503599627370496.0
