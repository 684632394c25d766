"""The grasp database: stored grasps equal fresh plans, stale ones are never used, and a
pick plans with stored grasps only (issue 33)."""

import json

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.apps.pick.plan import (
    CLASS_ORDER,
    GRASP_DB,
    catalogue_size,
    default_grasp_database,
    grasp_db_requests,
    plan_pick,
)
from handle_drake.apps.pick.reach import ArmReach
from handle_drake.base.models import diagrams_dir
from handle_drake.cli import main
from handle_drake.grasp import planning
from handle_drake.grasp.database import GraspDatabase, GraspDatabaseError, build_database
from handle_drake.grasp.planning import (
    PLANNER_VERSION,
    clear_solution_cache,
    grasp_key,
    plan_grasp,
    resting_pose,
)
from handle_drake.scene.config import initial_pose, scene_objects

PATH = diagrams_dir() / "hamburg_setup.yaml"  # the scenario of conftest's ``hamburg``


@pytest.fixture
def searches(monkeypatch):
    """The hand-IK searches run (``_solve_contacts`` calls), with an empty cache."""
    clear_solution_cache()
    calls = []
    solve = planning._solve_contacts

    def counting(*args, **kwargs):
        calls.append(args[0].grasp_class.value)
        return solve(*args, **kwargs)

    monkeypatch.setattr(planning, "_solve_contacts", counting)
    yield calls
    clear_solution_cache()


def _same_plan(a, b, atol=1e-9):
    for name in ("X_WB", "X_WB_pregrasp", "X_WP", "X_WG"):
        np.testing.assert_allclose(getattr(a, name).GetAsMatrix4(),
                                   getattr(b, name).GetAsMatrix4(), atol=atol, err_msg=name)
    for name in ("preshape_command", "grasp_command", "close_command", "q_grasp",
                 "grasp_amplitudes", "p_PC", "approach_W"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=atol,
                                   err_msg=name)
    assert a.centre_source == b.centre_source
    assert a.contact_error == pytest.approx(b.contact_error, abs=atol)


@pytest.mark.parametrize("grasp_class, kind", [("tripod", "sphere"),
                                               ("parallel_extension", "cuboid")])
def test_a_database_grasp_equals_the_freshly_planned_one(hamburg, searches, grasp_class,
                                                         kind):
    """The shipped database's grasp, placed on an object standing elsewhere and turned,
    is the plan a fresh search gives there (the classes the picks take)."""
    database = GraspDatabase.load(GRASP_DB)
    X0 = resting_pose(kind, 0.06, table_height=hamburg.table.top_height)
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.9), X0.translation() + [0.12, -0.2, 0.0])
    reach = (0.4, 1.0)
    stored = plan_grasp(grasp_class, (kind, 0.06), X_WO, table_height=hamburg.table.top_height,
                        reach_direction=reach, coupling_ratio=hamburg.hand.coupling_ratio,
                        cache=False, database=database)
    assert searches == []  # no hand-IK search: the grasp came from the file
    fresh = plan_grasp(grasp_class, (kind, 0.06), X_WO, table_height=hamburg.table.top_height,
                       reach_direction=reach, coupling_ratio=hamburg.hand.coupling_ratio,
                       cache=False)
    assert searches == [grasp_class]
    _same_plan(stored, fresh)


def test_the_shipped_database_answers_every_request_of_the_hamburg_catalogue(hamburg):
    database = default_grasp_database()
    assert database.stale == []
    ratio = hamburg.hand.coupling_ratio
    requests = grasp_db_requests(hamburg)
    # Every class of each hole's kind (the kinds beyond the sphere and the cuboid as their
    # cuboid proxies, apps/pick/kinds.py: stored in grasp_database_kinds.json).
    kinds = {h.kind for h in hamburg.sorting_box.holes}
    assert kinds <= set(CLASS_ORDER)
    assert len(requests) == sum(len(CLASS_ORDER[k]) for k in kinds)
    for grasp_class, obj, height in requests:
        key = grasp_key(grasp_class, obj, height, ratio)
        if key not in database:  # only the classes whose size range excludes the object
            with pytest.raises(ValueError, match="too large|too small"):
                planning.check_size(grasp_class, planning.grasp_dims(
                    planning._object_spec(obj))[1][0])


def test_a_stale_entry_is_searched_again_never_used(tmp_path, searches):
    obj = ("sphere", 0.06)
    X_WO = resting_pose(*obj)
    database = build_database([("tripod", obj, X_WO.translation()[2])], log=lambda _: None)
    assert searches == ["tripod"] and len(database) == 1
    path = database.save(tmp_path / "db.json")
    searches.clear()
    clear_solution_cache()
    plan_grasp("tripod", obj, X_WO, cache=False, database=GraspDatabase.load(path))
    assert searches == []
    # The same file written by another planner version: read as stale, not used.
    data = json.loads(path.read_text())
    data["planner_version"] = PLANNER_VERSION + 1
    path.write_text(json.dumps(data))
    stale = GraspDatabase.load(path)
    assert len(stale) == 0 and len(stale.stale) == 1
    plan_grasp("tripod", obj, X_WO, cache=False, database=stale)
    assert searches == ["tripod"]
    # Another size is another key: not answered by the 6 cm ball's entry as it is, but
    # adapted from it (no search); a database of another version adapts nothing.
    searches.clear()
    other = plan_grasp("tripod", ("sphere", 0.055), resting_pose("sphere", 0.055),
                       cache=False, database=database)
    assert searches == [] and other.adapted_from == next(iter(database.entries))
    assert stale.nearest(grasp_key("tripod", ("sphere", 0.055), 0.0275)) is None


@pytest.mark.parametrize("text, field", [
    ("{", "not readable JSON"),
    ('{"format": "other"}', "format"),
    ('{"format": "handle_drake.grasp_database/1", "planner_version": "1"}', "planner_version"),
    ('{"format": "handle_drake.grasp_database/1", "planner_version": 1, '
     '"entries": [{"key": {"hand": "shadow"}}]}', r"entries\[0\]"),
])
def test_a_bad_database_file_is_refused_naming_the_field(tmp_path, text, field):
    path = tmp_path / "db.json"
    path.write_text(text)
    with pytest.raises(GraspDatabaseError, match=field):
        GraspDatabase.load(path)


def test_the_pick_command_refuses_a_bad_database_in_one_line(tmp_path, capsys):
    path = tmp_path / "db.json"
    path.write_text("{")
    assert main(["pick", str(PATH), "--true-poses", "--grasp-db", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "grasp database" in err[0] and "Traceback" not in err[0]


def test_a_pick_plans_with_stored_grasps_only_even_on_a_perceived_size(hamburg, searches):
    """A perceived ball 2 mm small is the catalogue's 6 cm ball: planned with its size and
    the stored grasp, no hand-IK search, the grasp resting on the table."""
    assert catalogue_size(hamburg, "sphere", 0.058) == pytest.approx(0.06)
    assert catalogue_size(hamburg, "sphere", 0.05) == pytest.approx(0.05)  # not the ball
    name, sphere = next((n, o) for n, o in scene_objects(hamburg) if o.kind == "sphere")
    reach = ArmReach(hamburg, ignore=(name,))
    X_true = initial_pose(sphere, hamburg.table)
    X_seen = RigidTransform(X_true.rotation(), X_true.translation() - [0, 0, 0.001])
    plan = plan_pick(hamburg, reach, name, "sphere", 0.058, X_seen,
                     hamburg.hand.mount.initial_position)
    assert searches == []
    assert plan.grasp_stored and plan.grasp.object_spec.size == pytest.approx(0.06)
    assert plan.X_WO.translation()[2] == pytest.approx(X_true.translation()[2], abs=1e-9)


@pytest.fixture
def ik_solves(monkeypatch):
    """The hand-IK solves run (``GraspKinematics.solve_grasp`` calls)."""
    from handle_drake.grasp.kinematics import GraspKinematics

    calls = []
    solve = GraspKinematics.solve_grasp

    def counting(self, *args, **kwargs):
        calls.append(args[0])
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(GraspKinematics, "solve_grasp", counting)
    return calls


@pytest.mark.parametrize("kind, grasp_class, sizes", [
    # Across the old cliff at 6.5 cm (SIZE_TOLERANCE around the 6 cm catalogue cuboid).
    ("cuboid", "parallel_extension", (0.0640, 0.0649, 0.0651, 0.0657, 0.0680)),
    ("sphere", "tripod", (0.0520, 0.0549, 0.0551, 0.0651, 0.0700)),
])
def test_every_size_gets_a_stored_grasp_adapted_without_a_search(hamburg, searches, ik_solves,
                                                                 kind, grasp_class, sizes):
    """Sizes the database does not hold get its nearest grasp adapted (one seeded IK
    solve), never a hand-IK search; the adapted contacts lie on the new object's
    surface (checked by forward kinematics of the returned posture, not by the
    adaptation's own test) and the posture is the stored grasp's, moved a little."""
    from handle_drake.geometry.objects import ObjectSpec
    from handle_drake.grasp.kinematics import GraspKinematics
    from handle_drake.grasp.taxonomy import grasp_info

    database = default_grasp_database()
    ratio = hamburg.hand.coupling_ratio
    stored = database.get(grasp_key(grasp_class, (kind, 0.06), resting_pose(kind, 0.06)
                                    .translation()[2], ratio))
    kin = GraspKinematics(ratio)
    for size in sizes:
        ik_solves.clear()
        X_WO = resting_pose(kind, size, xy=(0.1, -0.2), yaw=0.7,
                            table_height=hamburg.table.top_height)
        plan = plan_grasp(grasp_class, (kind, size), X_WO,
                          table_height=hamburg.table.top_height, reach_direction=(1.0, -0.2),
                          coupling_ratio=ratio, cache=False, database=database,
                          time_budget=60.0)
        assert searches == [], size
        assert len(ik_solves) == 1, size  # the stored grasp's layout, solved once
        assert plan.adapted_from == stored.key
        shape, dims = planning.grasp_dims(ObjectSpec(kind, size))
        X_PO = plan.X_WP.inverse() @ plan.X_WG
        # Surface error of the class's contacts on the new object (the layout the
        # adaptation solved is the stored grasp's: a row of fingers may be left out).
        error = kin.surface_error(plan.q_grasp, grasp_info(grasp_class).grasp_class, shape,
                                  dims, X_PO)
        assert error <= planning.MAX_CONTACT_ERROR + 1e-4, (size, error)
        assert np.max(np.abs(plan.q_grasp - stored.q_grasp)) < 0.5


def test_a_pick_of_a_perceived_size_past_the_tolerance_adapts_every_class_it_tries(
        hamburg, searches):
    """The held-out cuboids read 6.51-6.57 cm: past SIZE_TOLERANCE they were searched
    (3-32 s); now the stored grasp is adapted and nothing is searched."""
    name, cuboid = next((n, o) for n, o in scene_objects(hamburg) if o.kind == "cuboid")
    reach = ArmReach(hamburg, ignore=(name,))
    X_true = initial_pose(cuboid, hamburg.table)
    size = 0.0655
    assert catalogue_size(hamburg, "cuboid", size) == size
    X_seen = RigidTransform(X_true.rotation(), [*X_true.translation()[:2],
                                                resting_pose("cuboid", size).translation()[2]])
    plan = plan_pick(hamburg, reach, name, "cuboid", size, X_seen,
                     hamburg.hand.mount.initial_position)
    assert searches == []
    assert plan.grasp_source == "adapted"
    assert plan.grasp.object_spec.size == pytest.approx(size)
    assert all(source in ("adapted", "unreachable") for _, source, _ in plan.grasp_log)
