"""Wrench transforms (eqs. 2-3), contact models (eqs. 4-11) and the grasp map (eqs. 13-14)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.geometry.quality import (
    ContactParams,
    GraspContacts,
    contact_frames,
    contact_wrenches,
    grasp_map,
    skew,
    transform_wrenches,
    wrench_transform,
    wrenches_per_contact,
)


def test_skew_is_the_cross_product():
    rng = np.random.default_rng(0)
    p, v = rng.normal(size=(2, 3))
    np.testing.assert_allclose(skew(p) @ v, np.cross(p, v), atol=1e-15)
    np.testing.assert_allclose(skew(p), -skew(p).T)


def test_wrench_transform_matches_force_at_a_point_physics():
    """A force f applied at point q: its wrench about any origin is (f, r x f)."""
    rng = np.random.default_rng(1)
    X_CB = RigidTransform(RollPitchYaw(rng.normal(size=3)), rng.normal(size=3))
    f_B, q_B = rng.normal(size=(2, 3))  # force and its point of application, in B
    F_B = np.concatenate([f_B, np.cross(q_B, f_B)])
    R, p = X_CB.rotation().matrix(), X_CB.translation()
    f_C, q_C = R @ f_B, X_CB @ q_B
    expected = np.concatenate([f_C, np.cross(q_C, f_C)])
    np.testing.assert_allclose(wrench_transform(X_CB) @ F_B, expected, atol=1e-12)
    np.testing.assert_allclose(transform_wrenches(F_B, R_CB=R, p_CB=p), expected, atol=1e-12)
    np.testing.assert_allclose(transform_wrenches(F_B, X_CB.GetAsMatrix4()), expected, atol=1e-12)
    # the inverse pose maps back
    back = wrench_transform(X_CB.inverse()) @ wrench_transform(X_CB)
    np.testing.assert_allclose(back, np.eye(6), atol=1e-12)


def test_wrench_transform_rejects_bad_shapes():
    with pytest.raises(ValueError, match="R_CB"):
        wrench_transform(R_CB=np.eye(2))
    with pytest.raises(ValueError, match="4x4"):
        wrench_transform(np.eye(3))
    with pytest.raises(TypeError, match="either"):
        wrench_transform(np.eye(4), R_CB=np.eye(3))


def test_contact_frames_put_the_normal_on_z():
    rng = np.random.default_rng(2)
    n = rng.normal(size=(20, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    R = contact_frames(n)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R[:, :, 2], n, atol=1e-15)


@pytest.mark.parametrize("model,k,expected", [("frictionless", 8, 1), ("point_friction", 8, 8),
                                              ("soft_finger", 8, 16), ("soft_finger", 4, 8)])
def test_wrench_counts(model, k, expected):
    assert wrenches_per_contact(model, k) == expected
    w = contact_wrenches([[0, 0, 1.0]], [[0, 0, -1.0]], model, num_edges=k)
    assert w.shape == (1, expected, 6)


def test_frictionless_wrench_is_eq4():
    p = np.array([[0.1, 0.2, 0.3]])
    n = np.array([[0.0, 0.0, 2.0]])  # not unit: normalised
    w = contact_wrenches(p, n, "frictionless")
    np.testing.assert_allclose(w[0, 0], np.r_[0, 0, 1, np.cross(p[0], [0, 0, 1])])


def test_friction_edges_lie_on_the_coulomb_cone_eq7():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = rng.normal(size=(5, 3))
    mu = 0.7
    w = contact_wrenches(p, n, "point_friction", mu=mu, num_edges=8)
    f = w[..., :3]
    f_n = np.einsum("ckj,cj->ck", f, n)
    f_t = np.linalg.norm(f - f_n[..., None] * n[:, None, :], axis=-1)
    np.testing.assert_allclose(f_n, 1.0, atol=1e-12)  # eq. 10
    np.testing.assert_allclose(f_t, mu, atol=1e-12)  # on the cone's boundary
    np.testing.assert_allclose(f.mean(axis=1), n, atol=1e-12)  # edges equally spaced
    np.testing.assert_allclose(w[..., 3:], np.cross(p[:, None, :], f), atol=1e-12)


def test_soft_finger_adds_torsion_about_the_normal_eq11():
    p = np.array([[0.0, 0.0, 0.05]])
    n = np.array([[0.0, 0.0, -1.0]])
    w_pf = contact_wrenches(p, n, "point_friction", mu=0.5, num_edges=6)
    w_sf = contact_wrenches(p, n, "soft_finger", mu=0.5, gamma=0.01, num_edges=6)
    np.testing.assert_allclose(w_sf[0, :6, :3], w_pf[0, :, :3])
    np.testing.assert_allclose(w_sf[0, :6, 3:] - w_pf[0, :, 3:], np.tile([0, 0, -0.01], (6, 1)))
    np.testing.assert_allclose(w_sf[0, 6:, 3:] - w_pf[0, :, 3:], np.tile([0, 0, 0.01], (6, 1)))


def test_characteristic_length_scales_moments_only():
    rng = np.random.default_rng(4)
    p, n = rng.normal(size=(2, 3, 3))
    w1 = contact_wrenches(p, n, mu=0.4, gamma=0.01)
    w2 = contact_wrenches(p, n, mu=0.4, gamma=0.01, characteristic_length=0.05)
    np.testing.assert_allclose(w2[..., :3], w1[..., :3])
    np.testing.assert_allclose(w2[..., 3:], w1[..., 3:] / 0.05)


def test_grasp_map_columns_are_the_contact_wrenches_eq14():
    rng = np.random.default_rng(5)
    p, n = rng.normal(size=(2, 3, 3))
    G = grasp_map(p, n, "soft_finger", mu=0.3, gamma=0.002, num_edges=4)
    w = contact_wrenches(p, n, "soft_finger", mu=0.3, gamma=0.002, num_edges=4)
    assert G.shape == (6, 3 * 8)
    np.testing.assert_allclose(G[:, 8:16].T, w[1])
    # eq. 13: G_i = [R 0; [p]x R R] w_ci in the contact frame
    R = contact_frames(n / np.linalg.norm(n, axis=1, keepdims=True))[1]
    T = wrench_transform(R_CB=R, p_CB=p[1])
    w_c = np.array([0.3 * np.sin(np.pi / 2), 0.3 * np.cos(np.pi / 2), 1, 0, 0, 0.002])
    np.testing.assert_allclose(T @ w_c, G[:, 8 + 1], atol=1e-12)  # contact 1, edge 1


def test_batch_wrenches_equal_single():
    rng = np.random.default_rng(6)
    p, n = rng.normal(size=(2, 4, 3, 3))
    wb = contact_wrenches(p, n, batch=True)
    for b in range(4):
        np.testing.assert_allclose(wb[b], contact_wrenches(p[b], n[b]))


def test_grasp_contacts_dataclass_validates():
    g = GraspContacts(np.zeros((2, 3)), [[1, 0, 0], [0, 0, 3]], names=("a", "b"))
    np.testing.assert_allclose(g.normals[1], [0, 0, 1])
    assert len(g) == 2
    with pytest.raises(ValueError, match="names"):
        GraspContacts(np.zeros((2, 3)), np.ones((2, 3)), names=("a",))
    with pytest.raises(ValueError, match="forces"):
        GraspContacts(np.zeros((2, 3)), np.ones((2, 3)), forces=np.ones((3, 3)))


def test_contact_params_validation():
    with pytest.raises(ValueError, match="mu"):
        ContactParams(mu=-0.1)
    with pytest.raises(ValueError, match="gamma"):
        ContactParams(gamma=-1e-3)
    with pytest.raises(ValueError, match="num_edges"):
        ContactParams(num_edges=2)
    with pytest.raises(TypeError, match="num_edges"):
        ContactParams(num_edges=8.0)
    with pytest.raises(ValueError, match="characteristic_length"):
        ContactParams(characteristic_length=0.0)
    with pytest.raises(ValueError, match="contact model"):
        ContactParams(model="sticky")
    with pytest.raises(ValueError, match="mu"):
        ContactParams(mu=float("nan"))
