"""The contact surface model (section 4.1.3) on analytic and mesh surfaces."""

import numpy as np
import pytest
import trimesh
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.geometry import objects
from handle_drake.geometry.quality import (
    BoxSurface,
    ContactParams,
    CylinderSurface,
    MeshSurface,
    SphereSurface,
    contact_surface,
    disk_pattern,
    grasp_quality,
    mean_contact,
)
from handle_drake.geometry.quality.surface import ObjectSurface


def cloud_at(p, n, spread=0.002, count=5, seed=0):
    """A raw contact cloud scattered around p, with noisy normals around n."""
    rng = np.random.default_rng(seed)
    pts = p + spread * rng.normal(size=(count, 3)) * (1 - np.abs(n))
    pts -= pts.mean(axis=0) - p
    nrm = n + 0.05 * rng.normal(size=(count, 3))
    nrm -= nrm.mean(axis=0) - n
    return pts, nrm


def test_disk_pattern_covers_the_disk():
    d = disk_pattern(0.01, num_rings=2, points_per_ring=6)
    assert d.shape == (1 + 6 + 12, 2)
    assert np.max(np.linalg.norm(d, axis=1)) < 0.01
    np.testing.assert_allclose(d.mean(axis=0), 0.0, atol=1e-15)


def test_mean_contact_eq12():
    p, n = mean_contact([[0, 0, 1.0], [0, 0, 3.0]], [[1.0, 0, 0], [0, 1.0, 0]])
    np.testing.assert_allclose(p, [0, 0, 2])
    np.testing.assert_allclose(n, [np.sqrt(0.5), np.sqrt(0.5), 0])
    with pytest.raises(ValueError, match="mean normal is zero"):
        mean_contact([[0, 0, 0.0], [0, 0, 0.0]], [[1.0, 0, 0], [-1.0, 0, 0]])
    with pytest.raises(ValueError, match="at least one point"):
        mean_contact(np.zeros((0, 3)), np.zeros((0, 3)))


@pytest.mark.parametrize("depth", [0.0, 0.001])  # on the surface, or penetrating
def test_sphere_surface_points_and_normals(depth):
    R, r = 0.05, 0.01
    surf = SphereSurface(R)
    u = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    pts, nrm = contact_surface(*cloud_at((R - depth) * u, -u), surf, r)
    assert len(pts) == 19  # every segment hits
    np.testing.assert_allclose(np.linalg.norm(pts, axis=1), R, atol=1e-12)
    np.testing.assert_allclose(nrm, -pts / R, atol=1e-12)
    # each hit lies on its segment: offset from p_m orthogonal to n is the disk pattern
    p_m = (R - depth) * u
    lateral = (pts - p_m) - np.outer((pts - p_m) @ u, u)
    np.testing.assert_allclose(np.sort(np.linalg.norm(lateral, axis=1)),
                               np.sort(np.linalg.norm(disk_pattern(r), axis=1)), atol=1e-12)


def test_box_surface_face_and_edge():
    size = np.array([0.06, 0.04, 0.10])
    X = RigidTransform(RollPitchYaw(0.3, -0.2, 0.5), [0.01, 0.02, -0.03])
    surf = BoxSurface(size, X_OG=X)
    R, c = X.rotation().matrix(), X.translation()
    n_face = -R[:, 0]  # inward on the +x face
    p = c + R @ [0.03, 0.0, 0.0]
    pts, nrm = contact_surface(*cloud_at(p, n_face), surf, 0.01)
    assert len(pts) == 19
    local = (pts - c) @ R
    np.testing.assert_allclose(local[:, 0], 0.03, atol=1e-12)
    np.testing.assert_allclose(nrm, np.tile(n_face, (19, 1)), atol=1e-12)
    # at a corner region, segments beyond the face's edge miss and are dropped
    p_edge = c + R @ [0.03, 0.0, 0.05]
    pts, nrm = contact_surface(*cloud_at(p_edge, n_face), surf, 0.01)
    local = (pts - c) @ R
    assert 0 < len(pts) < 19
    assert np.all(local[:, 2] <= 0.05 + 1e-12)


def test_cylinder_surface_side_and_cap():
    R, L = 0.03, 0.12
    surf = CylinderSurface(R, L)
    a = 0.7
    u = np.array([np.cos(a), np.sin(a), 0.0])
    pts, nrm = contact_surface(*cloud_at(R * u + [0, 0, 0.01], -u), surf, 0.008)
    assert len(pts) == 19
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), R, atol=1e-12)
    expected = -np.c_[pts[:, :2] / R, np.zeros(len(pts))]
    np.testing.assert_allclose(nrm, expected, atol=1e-12)
    pts, nrm = contact_surface(*cloud_at([0.005, 0, L / 2], [0, 0, -1.0]), surf, 0.008)
    np.testing.assert_allclose(pts[:, 2], L / 2, atol=1e-12)
    np.testing.assert_allclose(nrm, np.tile([0, 0, -1.0], (len(pts), 1)))


def test_mesh_box_matches_analytic_box():
    size = np.array([0.06, 0.04, 0.10])
    mesh = trimesh.creation.box(extents=size)
    cloud = cloud_at([0.01, 0.02, 0.05], [0, 0, -1.0])
    pa, na = contact_surface(*cloud, BoxSurface(size), 0.012)
    pm, nm = contact_surface(*cloud, MeshSurface(mesh), 0.012)
    np.testing.assert_allclose(pm, pa, atol=1e-12)
    np.testing.assert_allclose(nm, na, atol=1e-12)


def test_mesh_sphere_approximates_analytic_sphere():
    R = 0.05
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=R)
    u = np.array([0.2, 0.9, -0.3]) / np.linalg.norm([0.2, 0.9, -0.3])
    cloud = cloud_at(R * u, -u)
    pa, na = contact_surface(*cloud, SphereSurface(R), 0.01)
    pm, nm = contact_surface(*cloud, MeshSurface(mesh), 0.01)
    assert len(pm) == len(pa)
    np.testing.assert_allclose(pm, pa, atol=R * 2e-3)  # facet sagitta of the icosphere
    assert np.min(np.sum(nm * na, axis=1)) > np.cos(np.deg2rad(5))


@pytest.mark.parametrize("kind", ["sphere", "cylinder", "cuboid"])
def test_catalogue_objects_match_the_analytic_surfaces(kind):
    spec = objects.ObjectSpec(kind, 0.06)
    d = objects.dimensions(spec)
    analytic = {"sphere": lambda: SphereSurface(d["diameter"] / 2),
                "cylinder": lambda: CylinderSurface(d["diameter"] / 2, d["height"]),
                "cuboid": lambda: BoxSurface([d["width"], d["depth"], d["height"]])}[kind]()
    (piece,) = objects.pieces(spec)
    X_OP = piece.X_OP
    # a contact on the side facing -x of the object: push along +x
    half_x = (d["width"] if "width" in d else d["diameter"]) / 2
    cloud = cloud_at(X_OP.translation() - [half_x, 0, 0],
                     [1.0, 0, 0])
    shifted = type(analytic).__new__(type(analytic))
    shifted.__dict__.update(analytic.__dict__)
    shifted.R_OG, shifted.p_OG = X_OP.rotation().matrix(), X_OP.translation()
    pa, na = contact_surface(*cloud, shifted, 0.01)
    po, no = contact_surface(*cloud, ObjectSurface(spec), 0.01)
    np.testing.assert_allclose(po, pa, atol=1e-10)
    np.testing.assert_allclose(no, na, atol=1e-10)
    pm, nm = contact_surface(*cloud, MeshSurface(objects.surface_mesh(spec)), 0.01, pick="first")
    assert len(pm) == len(pa)
    np.testing.assert_allclose(pm, pa, atol=2e-3 * spec.size)


def test_surface_contacts_feed_the_metric():
    """Two opposite fingers on a sphere, each a patch of point contacts: a patch can
    resist torsion, so point-friction patches reach closure where single points cannot."""
    R = 0.05
    surf = SphereSurface(R)
    params = ContactParams(model="point_friction", mu=0.5, characteristic_length=R)
    single = grasp_quality([[R, 0, 0], [-R, 0, 0]], [[-1.0, 0, 0], [1.0, 0, 0]], params)
    assert not single.force_closure
    p1, n1 = contact_surface(*cloud_at([R, 0, 0], [-1.0, 0, 0]), surf, 0.01)
    p2, n2 = contact_surface(*cloud_at([-R, 0, 0], [1.0, 0, 0]), surf, 0.01)
    patch = grasp_quality(np.vstack([p1, p2]), np.vstack([n1, n2]), params)
    assert patch.force_closure


def test_contact_surface_bad_input():
    surf = SphereSurface(0.05)
    with pytest.raises(ValueError, match="radius"):
        contact_surface([[0.05, 0, 0]], [[-1.0, 0, 0]], surf, -0.01)
    with pytest.raises(ValueError, match="finite"):
        contact_surface([[np.nan, 0, 0]], [[-1.0, 0, 0]], surf, 0.01)
    with pytest.raises(ValueError, match="pick"):
        contact_surface([[0.05, 0, 0]], [[-1.0, 0, 0]], surf, 0.01, pick="last")
    with pytest.raises(ValueError, match="radius"):
        SphereSurface(0.0)
    with pytest.raises(TypeError, match="Trimesh"):
        MeshSurface("box.obj")
    # a cloud far from the object: no segment hits -> empty arrays, not an error
    pts, nrm = contact_surface([[1.0, 0, 0]], [[-1.0, 0, 0]], surf, 0.01)
    assert pts.shape == (0, 3) and nrm.shape == (0, 3)
