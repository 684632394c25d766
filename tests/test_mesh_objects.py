"""Mesh files as grasp objects (handle_drake.geometry.objects.mesh).

Independent truths: catalogue objects written as mesh files behave like the
catalogue objects (mass properties within the facet error, resting height,
exact ray casts within the facet error, a grasp that holds one holds the
other); the L-bracket's mass properties in closed form (two boxes); a point
is inside a torus when its distance to the core circle is below the tube
radius. Generated meshes (torus, L-bracket, bowl) run through ``simulate``
and ``babble``. CoACD runs in reduced mode on coarse meshes, cached in a
temporary folder shared by the module.
"""

import math
import re
import warnings

import numpy as np
import pytest
import trimesh

from handle_drake.geometry import objects
from handle_drake.geometry.objects import mesh as mesh_objects
from handle_drake.geometry.objects import mesh_examples
from handle_drake.geometry.objects.mesh import MeshObjectSpec, MeshObjectWarning
from handle_drake.trial.plans import plan_scenario


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mesh_cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(mesh_objects.CACHE_ENV, str(folder))
        yield folder


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Catalogue objects exported as OBJ/STL, and coarse generated meshes."""
    d = tmp_path_factory.mktemp("meshes")
    out = {}
    for kind, size, ext in (("cuboid", 0.028, "obj"), ("cylinder", 0.05, "stl"),
                            ("sphere", 0.06, "ply")):
        out[kind] = mesh_objects.write_mesh(objects.ObjectSpec(kind, size), d / f"{kind}.{ext}")
    mesh_examples.torus(sections=16).export(d / "torus.obj")
    mesh_examples.l_bracket().export(d / "l_bracket.stl")
    mesh_examples.bowl(sections=16).export(d / "bowl.ply")
    out.update(torus=d / "torus.obj", l_bracket=d / "l_bracket.stl", bowl=d / "bowl.ply")
    return out


def _facet_error(spec: MeshObjectSpec, centre, radius) -> float:
    """Largest gap between a sphere/cylinder wall and the mesh faces: radius minus
    the smallest distance from the axis/centre to a face plane (faces are chords)."""
    mesh = mesh_objects.mesh_in_object_frame(spec)
    n = mesh.face_normals
    d = np.einsum("ij,ij->i", mesh.triangles[:, 0] - centre, n)
    side = np.abs(n[:, 2]) < 0.99  # for a cylinder, the caps are exact
    return float(radius - d[side].min())


# ------------------------------------------------------------------ as the catalogue


@pytest.mark.parametrize("kind, size, rel", [("cuboid", 0.028, 1e-6), ("cylinder", 0.05, 4e-3),
                                             ("sphere", 0.06, 2e-2)])
def test_exported_catalogue_object_has_the_catalogues_mass_properties(files, kind, size, rel):
    """Mass within the faceting's volume loss (64-gon cylinder: 0.16 %, 1280-face
    icosphere: 1.2 %), centre of mass at the origin, inertia within twice that."""
    cat = objects.ObjectSpec(kind, size)
    mesh = MeshObjectSpec(str(files[kind]), density=objects.DENSITY[kind])
    a, b = objects.mass_properties(cat), objects.mass_properties(mesh)
    assert b.mass == pytest.approx(a.mass, rel=rel)
    np.testing.assert_allclose(b.p_OScm, a.p_OScm, atol=1e-6 * size)
    np.testing.assert_allclose(b.I_SScm_O, a.I_SScm_O, rtol=2 * rel, atol=1e-12)
    # A given mass overrides the density, inertia scales with it.
    heavy = MeshObjectSpec(str(files[kind]), mass=2 * a.mass)
    assert objects.mass_properties(heavy).mass == pytest.approx(2 * a.mass)
    M = objects.spatial_inertia(heavy)
    assert M.get_mass() == pytest.approx(2 * a.mass)


def test_size_and_resting_height_are_the_catalogues(files):
    for kind, size in (("cuboid", 0.028), ("cylinder", 0.05), ("sphere", 0.06)):
        mesh = MeshObjectSpec(str(files[kind]))
        cat = objects.ObjectSpec(kind, size)
        assert mesh.size == pytest.approx(size, rel=1e-6), kind
        assert objects.resting_height(mesh) == pytest.approx(objects.resting_height(cat),
                                                             rel=1e-6), kind


def test_ray_casts_agree_with_the_exact_catalogue_ray_cast_within_the_facet_error(files):
    rng = np.random.default_rng(4)
    for kind, size in (("cylinder", 0.05), ("sphere", 0.06)):
        cat = objects.ObjectSpec(kind, size)
        mesh = MeshObjectSpec(str(files[kind]))
        radius = size / 2
        err = _facet_error(mesh, np.zeros(3), radius)
        assert 0 < err < 0.01 * radius
        # Rays from a sphere of radius 0.2 m towards points near the centre.
        u = rng.normal(size=(200, 3))
        o = 0.2 * u / np.linalg.norm(u, axis=1, keepdims=True)
        d = rng.uniform(-0.3, 0.3, size=(200, 3)) * radius - o
        exact, approx = objects.ray_cast(cat, o, d), objects.ray_cast(mesh, o, d)
        both = exact.hit & approx.hit
        assert both.sum() > 120
        # A facet lies inside the true surface by at most err; a ray at angle
        # theta to the normal travels at most err / cos(theta) further.
        cos = -np.einsum("ij,ij->i", exact.n_O, d / np.linalg.norm(d, axis=1, keepdims=True))
        gap = approx.distance[both] - exact.distance[both]
        assert np.all(gap >= -1e-9)
        assert np.all(gap <= err / np.maximum(cos[both], 0.2) + 1e-9)
        # Normals within the facet angle where the ray meets the round wall squarely.
        square = both & (cos > 0.5)
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", exact.n_O[square], approx.n_O[square]),
                                  -1, 1))
        assert np.degrees(angle).max() < 12.0
        # Misses agree away from grazing rays.
        assert np.mean(exact.hit == approx.hit) > 0.97


def test_contact_surface_model_on_the_mesh_matches_the_catalogue(files):
    from handle_drake.geometry.quality.surface import ObjectSurface, contact_surface

    cat = objects.ObjectSpec("cylinder", 0.05)
    mesh = MeshObjectSpec(str(files["cylinder"]))
    # A contact on the round wall, inward normal -x.
    p, n = np.array([[0.025, 0.0, 0.01]]), np.array([[-1.0, 0.0, 0.0]])
    pa, na = contact_surface(p, n, ObjectSurface(cat), 0.006)
    pb, nb = contact_surface(p, n, ObjectSurface(mesh), 0.006)
    assert len(pa) == len(pb) == 19  # every segment of the 2-ring pattern hits
    err = _facet_error(mesh, np.zeros(3), 0.025)
    assert np.abs(pa - pb).max() <= 1.5 * err
    assert np.degrees(np.arccos(np.clip(np.sum(na * nb, axis=1), -1, 1))).max() < 12.0


def test_resting_height_in_simulation_matches_the_catalogue_object(files, tmp_path):
    """The mesh dropped 1 cm onto the table settles where the catalogue cuboid does."""
    from handle_drake.scenario import LoadScenario
    from handle_drake.trial.simulate import ScenarioRunner

    ends = {}
    for name, obj in (("catalogue", "{kind: cuboid, size: 0.028}"),
                      ("mesh", f"{{kind: mesh, file: '{files['cuboid']}'}}")):
        scenario = LoadScenario(data=f"""
hand: {{kind: barrett, mount: !FixedMount {{X_WB: {{translation: [0.3, 0, 0.4]}}}}}}
object: {obj}
simulation_duration: 0.5
""")
        scenario.object.on_table = False
        scenario.object.X_WO.translation = [0.0, 0.0, 0.021 + 0.01]
        ends[name] = ScenarioRunner(scenario).run().object_position[-1]
    assert ends["mesh"][2] == pytest.approx(0.021, abs=1.5e-3)
    np.testing.assert_allclose(ends["mesh"], ends["catalogue"], atol=1e-3)


def test_a_grasp_that_holds_the_catalogue_cuboid_holds_the_mesh(files):
    from handle_drake.grasp.planning import grasp_dims, plan_grasp, resting_pose
    from handle_drake.scenario import ObjectConfig
    from handle_drake.trial.simulate import ScenarioRunner, held_through_lift

    mesh = MeshObjectSpec(str(files["cuboid"]))
    cat = objects.ObjectSpec("cuboid", 0.028)
    # The planner's input for the mesh is the catalogue cuboid's (bounding box proxy).
    assert grasp_dims(mesh)[0] == "box"
    np.testing.assert_allclose(grasp_dims(mesh)[1], grasp_dims(cat)[1], rtol=1e-6)
    assert resting_pose(mesh).IsNearlyEqualTo(resting_pose("cuboid", 0.028), 1e-9)
    plan = plan_grasp("lateral", ("cuboid", 0.028), resting_pose("cuboid", 0.028))
    assert held_through_lift(ScenarioRunner(plan_scenario(plan)).run())  # the catalogue object
    # The planner, given the mesh, plans the same grasp; its scenario names the file.
    mesh_plan = plan_grasp("lateral", mesh, resting_pose(mesh))
    assert mesh_plan.grasp_size == pytest.approx(plan.grasp_size, rel=1e-6)
    assert mesh_plan.X_WB.IsNearlyEqualTo(plan.X_WB, 1e-4)
    scenario = plan_scenario(mesh_plan)
    assert scenario.object == ObjectConfig(kind="mesh", file=mesh.file, mu=mesh.mu,
                                           X_WO=scenario.object.X_WO, on_table=False)
    result = ScenarioRunner(scenario).run()
    assert held_through_lift(result), result.object_position[::25, 2]


# ------------------------------------------------------------------ generated meshes


def test_l_bracket_mass_properties_in_closed_form(files):
    """Two boxes: base 80 x 35 x 14 mm, upright 14 x 35 x (60 - 14) mm on it."""
    spec = MeshObjectSpec(str(files["l_bracket"]), origin="file", density=1000.0)
    mp = objects.mass_properties(spec)
    boxes = [((0.08, 0.035, 0.014), (0.04, 0.0, 0.007)),
             ((0.014, 0.035, 0.046), (0.007, 0.0, 0.014 + 0.023))]
    masses = [1000.0 * math.prod(e) for e, _ in boxes]
    com = sum(m * np.array(c) for m, (_, c) in zip(masses, boxes, strict=True)) / sum(masses)
    inertia = np.zeros((3, 3))
    for m, (e, c) in zip(masses, boxes, strict=True):
        ex, ey, ez = e
        r = np.array(c) - com
        inertia += np.diag([ey**2 + ez**2, ex**2 + ez**2, ex**2 + ey**2]) * m / 12
        inertia += m * (r @ r * np.eye(3) - np.outer(r, r))
    # STL stores float32 vertices: agreement to ~1e-7 relative.
    assert mp.mass == pytest.approx(sum(masses), rel=1e-6)
    np.testing.assert_allclose(mp.p_OScm, com, atol=1e-8)
    np.testing.assert_allclose(mp.I_SScm_O, inertia, rtol=1e-5, atol=1e-12)
    # The plant's spatial inertia (about O) says the same (its product Ixz is not 0).
    M = objects.spatial_inertia(spec)
    assert M.get_mass() == pytest.approx(sum(masses), rel=1e-6)
    np.testing.assert_allclose(M.get_com(), com, atol=1e-8)
    I_Scm = M.Shift(M.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
    assert abs(inertia[0, 2]) > 1e-3 * inertia[0, 0]
    np.testing.assert_allclose(I_Scm, inertia, rtol=1e-5, atol=1e-12)
    # Frame: origin="file" keeps the file's origin; "bbox" centres the bounding box.
    assert objects.resting_height(spec) == pytest.approx(0.0)
    centred = MeshObjectSpec(str(files["l_bracket"]))
    assert objects.resting_height(centred) == pytest.approx(0.03)
    np.testing.assert_allclose(objects.mass_properties(centred).p_OScm,
                               com - [0.04, 0.0, 0.03], atol=1e-8)


def test_torus_pieces_cover_the_solid_and_contains_matches_the_formula(files):
    spec = MeshObjectSpec(str(files["torus"]))
    R, r = 0.035, 0.011
    rng = np.random.default_rng(2)
    p = rng.uniform(-0.05, 0.05, size=(3000, 3)) * [1, 1, 0.25]
    q = np.hypot(np.hypot(p[:, 0], p[:, 1]) - R, p[:, 2])
    # Away from the faceted wall: 16 x 8 facets cut in by at most
    # r (1 - cos(pi/8)) + (R + r) (1 - cos(pi/16)) = 0.15 r.
    clear = np.abs(q - r) > r * (1 - math.cos(math.pi / 8)) + (R + r) * (
        1 - math.cos(math.pi / 16)) + 1e-9
    inside = mesh_objects.contains(spec, p)
    assert np.array_equal(inside[clear], (q < r)[clear])
    # The convex pieces: several (the hole stays open), together close to the solid.
    parts = objects.pieces(spec)
    assert 4 <= len(parts) <= spec.max_pieces
    from scipy.spatial import Delaunay

    in_pieces = np.zeros(len(p), dtype=bool)
    for piece in parts:
        in_pieces |= Delaunay(piece.vertices).find_simplex(p) >= 0
    assert not in_pieces[np.hypot(p[:, 0], p[:, 1]) < R - 1.3 * r].any()  # the hole
    solid = inside & clear
    assert in_pieces[solid].mean() > 0.97


@pytest.mark.parametrize("name", ["torus", "l_bracket", "bowl"])
def test_generated_mesh_rests_on_the_table_through_simulate(files, tmp_path, capsys, name):
    from handle_drake.cli import main

    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(f"""
hand: {{kind: barrett, mount: !FixedMount {{X_WB: {{translation: [0.3, 0, 0.4]}}}}}}
object: {{kind: mesh, file: {files[name].name}, mass: 0.05}}
simulation_duration: 0.4
""")
    (tmp_path / files[name].name).write_bytes(files[name].read_bytes())  # relative to the file
    assert main(["simulate", str(scenario), "--quality"]) == 0
    out = capsys.readouterr().out
    start, end = map(float, re.search(r"object height: start (\S+) m, end (\S+) m", out).groups())
    spec = MeshObjectSpec(str(files[name]))
    assert start == pytest.approx(objects.resting_height(spec), abs=1e-6)
    assert end == pytest.approx(start, abs=2e-3)  # it stays on the table, no sinking or jump


def test_hydroelastic_contact_uses_the_same_pieces(files):
    from handle_drake.scenario import LoadScenario
    from handle_drake.station import GetPlant
    from handle_drake.trial.simulate import ScenarioRunner

    scenario = LoadScenario(data=f"""
hand: {{kind: barrett, mount: !FixedMount {{X_WB: {{translation: [0.3, 0, 0.4]}}}}}}
object: {{kind: mesh, file: '{files["torus"]}', mass: 0.05}}
plant_config: {{contact_model: hydroelastic_with_fallback}}
simulation_duration: 0.3
""")
    runner = ScenarioRunner(scenario)
    plant = GetPlant(runner.station)
    body = plant.GetBodyByName(objects.BODY_NAME, plant.GetModelInstanceByName("object"))
    # One collision geometry per convex piece, no point-contact feet.
    ids = plant.GetCollisionGeometriesForBody(body)
    assert len(ids) == len(objects.pieces(MeshObjectSpec(str(files["torus"]))))
    result = runner.run()
    assert result.object_position[-1, 2] == pytest.approx(0.011, abs=2.5e-3)


@pytest.mark.parametrize("name", ["torus", "l_bracket", "bowl"])
def test_short_babble_on_generated_meshes(files, tmp_path, capsys, name):
    from handle_drake.apps.babbling.cli import main
    from handle_drake.learning import TrialLog

    db = tmp_path / "b.sqlite"
    assert main(["babble", "--mesh", str(files[name]), "--strategy", "random", "--trials", "2",
                 "--db", str(db), "--no-plot", "--no-progress"]) == 0
    assert f"barrett-mesh_{name}-offset" in capsys.readouterr().out
    with TrialLog(db) as log:
        (run,) = log.runs()
        trials = log.trials(run.run_id)
    assert [t.status for t in trials] == ["done", "done"]
    # The trial log keeps the scenario: it names the mesh file.
    assert str(files[name]) in trials[0].scenario


# ------------------------------------------------------------------ cache


def test_decomposition_is_cached_by_content(files, cache, monkeypatch, tmp_path):
    mesh = trimesh.load(files["l_bracket"], force="mesh")
    first = mesh_objects.convex_decomposition(mesh.vertices, mesh.faces)
    assert len(first) >= 2 and len(list((cache / "convex").glob("*.npz"))) >= 1

    def fail(*args, **kwargs):
        raise AssertionError("CoACD ran although the decomposition is cached")

    monkeypatch.setattr(mesh_objects, "_isolated", fail)  # where CoACD runs (a child process)
    again = mesh_objects.convex_decomposition(mesh.vertices, mesh.faces)
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    # Another mesh (other content) is not served from the cache.
    with pytest.raises(AssertionError, match="CoACD ran"):
        mesh_objects.convex_decomposition(mesh.vertices * 1.01, mesh.faces)
    # A convex mesh needs no CoACD at all: one piece, its hull.
    box = trimesh.creation.box((0.03, 0.02, 0.01))
    (piece,) = mesh_objects.convex_decomposition(box.vertices, box.faces, directory=tmp_path)
    assert len(piece) == 8
    # A damaged cache file is recomputed, not trusted.
    for path in (tmp_path / "convex").glob("*.npz"):
        path.write_bytes(b"not an npz")
    (piece,) = mesh_objects.convex_decomposition(box.vertices, box.faces, directory=tmp_path)
    assert len(piece) == 8


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(mesh_objects.CACHE_ENV, str(tmp_path / "c"))
    assert mesh_objects.cache_dir() == tmp_path / "c"
    monkeypatch.delenv(mesh_objects.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert mesh_objects.cache_dir() == tmp_path / "x" / "handle_drake"


# ------------------------------------------------------------------ bad input


def test_bad_files_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="file: mesh file not found"):
        MeshObjectSpec(str(tmp_path / "missing.obj"))
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"\x00\x01 this is not a mesh" * 3)
    with pytest.raises(ValueError, match="file: "):
        MeshObjectSpec(str(garbage))
    unknown = tmp_path / "part.xyz123"
    unknown.write_text("v 0 0 0\n")
    with pytest.raises(ValueError, match="file: cannot read mesh"):
        MeshObjectSpec(str(unknown))
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\nv 0 0 0\nv 1 0 0\n")
    with pytest.raises(ValueError, match="file: .*no triangles"):
        MeshObjectSpec(str(empty))
    flat = tmp_path / "flat.obj"
    flat.write_text("v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="encloses no volume"), warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshObjectWarning)
        MeshObjectSpec(str(flat))


def test_absurd_scale_mass_and_size(files):
    path = str(files["cuboid"])
    with pytest.raises(ValueError, match=r"scale: .*far larger than a hand.*millimetres"):
        MeshObjectSpec(path, scale=1000.0)
    with pytest.raises(ValueError, match="scale: .*smaller than"):
        MeshObjectSpec(path, scale=0.01)
    with pytest.raises(ValueError, match="scale: expected a finite number > 0"):
        MeshObjectSpec(path, scale=-1.0)
    with pytest.raises(ValueError, match=r"mass: 500 kg .* density"):
        MeshObjectSpec(path, mass=500.0)
    with pytest.raises(ValueError, match="density: expected a value in"):
        MeshObjectSpec(path, density=1e6)
    with pytest.warns(MeshObjectWarning, match="larger than the hands can enclose"):
        spec = MeshObjectSpec(path, scale=12.0)  # 0.5 m across
    assert spec.size == pytest.approx(0.336)


def test_open_meshes_warn_and_take_a_stated_fallback(tmp_path):
    box = trimesh.creation.box((0.04, 0.03, 0.02))
    holed = trimesh.Trimesh(box.vertices, box.faces[:-1])  # one triangle missing
    holed.export(tmp_path / "holed.obj")
    with pytest.warns(MeshObjectWarning, match="holes were filled"):
        spec = MeshObjectSpec(str(tmp_path / "holed.obj"))
    assert objects.mass_properties(spec).volume == pytest.approx(0.04 * 0.03 * 0.02, rel=1e-9)
    # A hemispherical shell (a surface, no thickness) cannot be closed: hull fallback.
    shell = trimesh.creation.icosphere(2, radius=0.03)
    shell.update_faces(shell.triangles_center[:, 2] > 0.003)
    shell.remove_unreferenced_vertices()
    shell.export(tmp_path / "shell.stl")
    with pytest.warns(MeshObjectWarning, match="convex hull"):
        spec = MeshObjectSpec(str(tmp_path / "shell.stl"))
    hull = shell.convex_hull
    assert objects.mass_properties(spec).volume == pytest.approx(hull.volume, rel=1e-6)  # float32
    # Surface queries still use the real (open) surface: a ray into the
    # shell's opening from below passes through and meets it from inside.
    hits = objects.ray_cast(spec, [[0.0, 0.0, -0.1]], [[0.0, 0.0, 1.0]])
    assert hits.hit[0] and hits.p_OS[0, 2] > 0.01


def test_scenario_and_cli_errors_name_the_field(files, tmp_path, capsys):
    from handle_drake.cli import main
    from handle_drake.scenario import LoadScenario, ScenarioError

    with pytest.raises(ScenarioError, match="object.file: kind 'mesh' needs a mesh file"):
        LoadScenario(data="object: {kind: mesh}")
    with pytest.raises(ScenarioError, match="object.file: mesh file not found"):
        LoadScenario(data="object: {kind: mesh, file: /no/such/file.obj}")
    with pytest.raises(ScenarioError, match="object.scale"):
        LoadScenario(data=f"object: {{kind: mesh, file: '{files['cuboid']}', scale: 1000}}")
    with pytest.raises(ScenarioError, match="mass or density"):
        LoadScenario(data=f"object: {{kind: mesh, file: '{files['cuboid']}', mass: 0.1, "
                          "density: 500}")
    with pytest.raises(ScenarioError, match="object.file: only kind 'mesh'"):
        LoadScenario(data=f"object: {{kind: sphere, file: '{files['cuboid']}'}}")
    scenario = tmp_path / "s.yaml"
    scenario.write_text("object: {kind: mesh, file: nowhere.stl}\n")
    assert main(["simulate", str(scenario)]) == 2
    assert "object.file: mesh file not found" in capsys.readouterr().err
    from handle_drake.apps.babbling.cli import main as learning_main

    assert learning_main(["babble", "--mesh", str(tmp_path / "none.obj"), "--trials", "1",
                          "--db", str(tmp_path / "b.sqlite"), "--no-progress"]) == 2
    assert "mesh file not found" in capsys.readouterr().err
    assert main(["grasp", "--class", "lateral", "--mesh", str(tmp_path / "none.obj")]) == 2
    assert "mesh file not found" in capsys.readouterr().err
    assert main(["grasp", "--class", "lateral", "--mesh", str(files["cuboid"]), "--size",
                 "0.03"]) == 2
    assert "--size: a mesh's size comes from its file" in capsys.readouterr().err
    assert main(["grasp", "--class", "lateral"]) == 2
    assert "--size: required" in capsys.readouterr().err


def test_an_open_shell_collides_as_its_hull_without_a_decomposition(tmp_path, monkeypatch):
    # An open hemispherical shell: CoACD would first remesh it into a thin
    # shell (measured: > 5 min, 32 slivers). Its collision geometry is its
    # hull, as its mass properties are, and CoACD never runs.
    shell = trimesh.creation.icosphere(2, radius=0.03)
    shell.update_faces(shell.triangles_center[:, 2] < 0.02)
    shell.remove_unreferenced_vertices()
    shell.export(tmp_path / "open.obj")

    def no_coacd(*args):
        raise AssertionError("CoACD ran on an open shell")

    monkeypatch.setattr(mesh_objects, "_run_coacd", no_coacd)
    with pytest.warns(MeshObjectWarning, match="collision geometry are those of its convex hull"):
        spec = MeshObjectSpec(str(tmp_path / "open.obj"))
    (piece,) = objects.pieces(spec)
    hull = trimesh.Trimesh(piece.vertices).convex_hull
    assert hull.volume == pytest.approx(objects.mass_properties(spec).volume, rel=1e-6)
    assert hull.volume == pytest.approx(shell.convex_hull.volume, rel=1e-6)


def test_closed_parts_are_decomposed_one_by_one(tmp_path, monkeypatch):
    # Two disjoint closed boxes in one file: each part is convex, so each is
    # its own hull and CoACD never runs; together they hold both volumes.
    a = trimesh.creation.box((0.02, 0.02, 0.02))
    b = a.copy()
    b.apply_translation((0.04, 0.0, 0.0))
    both = trimesh.util.concatenate([a, b])
    both.export(tmp_path / "two.obj")
    monkeypatch.setattr(mesh_objects, "_run_coacd", lambda *a: pytest.fail("CoACD ran"))
    spec = MeshObjectSpec(str(tmp_path / "two.obj"))
    parts = objects.pieces(spec)
    assert len(parts) == 2
    volumes = sorted(trimesh.Trimesh(p.vertices).convex_hull.volume for p in parts)
    assert volumes == pytest.approx([0.02**3, 0.02**3], rel=1e-9)
    assert objects.mass_properties(spec).volume == pytest.approx(2 * 0.02**3, rel=1e-9)


def test_a_crash_of_the_decomposition_costs_a_child_process_not_the_session(
        files, tmp_path, monkeypatch):
    import faulthandler
    import os

    # A real segfault and a hard exit in the child: None, and this process lives on.
    assert mesh_objects._isolated(faulthandler._sigsegv) is None
    assert mesh_objects._isolated(os._exit, 3) is None
    assert mesh_objects._isolated(max, 2, 5) == 5
    # When CoACD fails with its remeshing off and on, the piece is the hull, with a warning.
    monkeypatch.setattr(mesh_objects, "_isolated", lambda *args: None)
    torus = trimesh.load(files["torus"], force="mesh")
    with pytest.warns(MeshObjectWarning, match="CoACD failed on mesh torus"):
        (hull,) = mesh_objects.convex_decomposition(torus.vertices, torus.faces,
                                                    directory=tmp_path, name="torus")
    assert trimesh.Trimesh(hull).convex_hull.volume == pytest.approx(torus.convex_hull.volume)
    assert not list((tmp_path / "convex").glob("*.npz"))  # not cached: the next run retries


def test_a_mesh_object_renders_for_the_cameras_and_is_detected_as_its_catalogue_twin(files):
    # Drake's renderer refuses an OBJ without normals; the mesh's visual has
    # them. The exported cuboid (28 x 16.8 x 42 mm, objects.PROPORTIONS) is
    # found where it stands, with its catalogue dimensions; a mesh is no
    # primitive, so its detected kind is not judged.
    from handle_drake.apps.perception.perceive import detection_error, render_views
    from handle_drake.base.models import diagrams_dir
    from handle_drake.scenario import LoadScenario

    data = (f"object: {{kind: mesh, file: '{files['cuboid']}', X_WO: {{translation: "
            "[0.05, -0.03, 0], rotation: !Rpy {deg: [0, 0, 30]}}}\n"
            "cameras: [{profile: ideal, target: [0, 0, 0], config: {name: kinect, "
            "X_PB: {translation: [-0.707, 0, 0.707]}}}]\n")
    scenario = LoadScenario(filename=diagrams_dir() / "tabletop_perception.yaml", data=data)
    (view,) = render_views(scenario)
    (box,) = view.detections
    assert box.kind == "box"
    np.testing.assert_allclose(sorted(box.extent), [0.0168, 0.028, 0.042], atol=0.004)
    error = detection_error(box, scenario)
    assert error["xy_mm"] < 5.0 and error["kind_ok"] is None and error["kind_expected"] is None


def test_an_accelerometer_on_a_mesh_object_reads_gravity_and_off_it_is_refused(files):
    from pydrake.math import RollPitchYaw
    from pydrake.systems.analysis import Simulator

    from handle_drake.devices.accelerometer.profiles import get_profile
    from handle_drake.scenario import LoadScenario, ScenarioError
    from handle_drake.station import MakeHandStation

    hand_away = "hand: {mount: !FixedMount {X_WB: {translation: [0, 0, 1.5]}}}\n"
    rpy = (20.0, -35.0, 60.0)
    scenario = LoadScenario(data=hand_away + (
        f"object: {{kind: mesh, file: '{files['cuboid']}', fixed: true, on_table: false, "
        f"X_WO: {{translation: [0.3, 0.3, 0.4], rotation: !Rpy {{deg: {list(rpy)}}}}}, "
        "accelerometer: {noise: false, X_OS: {translation: [0, 0, 0.01]}}}"))
    station = MakeHandStation(scenario)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    station.GetInputPort("hand.position").FixValue(context, np.zeros(20))
    simulator.AdvanceTo(0.05)
    # At rest, the sensor (axes of O) feels +g up: R_WO^T [0, 0, 9.81], in counts.
    R_WO = RollPitchYaw(np.radians(rpy)).ToRotationMatrix()
    lsb = get_profile("joywarrior24f14").lsb
    expected = np.rint((R_WO.inverse() @ np.array([0.0, 0.0, 9.81])) / lsb)
    counts = station.GetOutputPort("object.acceleration_counts").Eval(context)
    np.testing.assert_array_equal(counts, expected)
    with pytest.raises(ScenarioError, match="object.accelerometer.X_OS"):
        LoadScenario(data=f"object: {{kind: mesh, file: '{files['cuboid']}', accelerometer: "
                          "{X_OS: {translation: [0.05, 0, 0]}}}")
