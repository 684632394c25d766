"""Hostile input, fourth wave (issue 46): pick's targets, hands, scenes and grasp database,
the in-hand options and seeds, numba's cache, trial logs and the messages of a few refusals.

Every case was found by the issue's kit and is in ``tools/hostile_probe.py fourth``; each
test here fails on the code before the fix (a traceback, a hang, a silent accept, a file left
behind or a message that does not name the problem). The cases a user meets on the command
line run the CLI as a subprocess (tiny budgets; hangs bounded by the subprocess timeout);
the rest call the same ``main`` in-process.
"""

import json
import math
import os
import sqlite3
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from cli_runner import cli_exit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
HAMBURG = str(ROOT / "diagrams" / "hamburg_setup.yaml")
SHIPPED_DB = ROOT / "handle_drake" / "apps" / "pick" / "data" / "grasp_database.json"
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p),
           OPENBLAS_NUM_THREADS="1")


def _last_line(err: str) -> str:
    return err.strip().splitlines()[-1] if err.strip() else ""


def _run(argv, cwd, timeout=120):
    """``handle-drake argv`` as a user runs it: (exit code, stderr)."""
    done = subprocess.run([sys.executable, "-m", "handle_drake.cli", *argv], cwd=cwd,
                          env=ENV, capture_output=True, text=True, timeout=timeout)
    assert "Traceback" not in done.stderr, done.stderr[-2000:]
    return done.returncode, done.stderr


# ------------------------------------------------------------------ tracebacks
def test_pick_kind_without_a_hole_is_refused_naming_kind(tmp_path):
    code, err = _run(["pick", HAMBURG, "--true-poses", "--kind", "sphere", "--override",
                      "sorting_box: {holes: [{kind: cylinder, size: 0.05}]}"], tmp_path)
    assert code == 2 and "--kind sphere" in err and "no hole" in err, err  # was KeyError


def test_a_target_whose_kind_has_no_hole_is_a_planning_reason_not_a_key_error():
    from handle_drake.apps.pick.plan import PickPlanningError, plan_pick
    from handle_drake.scenario import LoadScenario

    scenario = LoadScenario(filename=HAMBURG,
                            data="sorting_box: {holes: [{kind: cylinder, size: 0.05}]}")
    with pytest.raises(PickPlanningError, match="no hole for a sphere"):
        plan_pick(scenario, None, "object_3", "sphere", 0.06, None, np.zeros(6))


@pytest.mark.parametrize("command", ["inhand", "babble"])
def test_a_seed_beyond_sqlite_integer_is_refused_before_the_log_exists(command, tmp_path):
    extra = ["--no-plot"] if command == "babble" else []
    code, err = _run([command, "--trials", "1", "--seed", str(2**70), "--db", "x.sqlite",
                      "--no-progress", *extra], tmp_path)
    assert code == 2 and "--seed" in _last_line(err), err  # was OverflowError
    assert not (tmp_path / "x.sqlite").exists()


def test_trial_log_create_run_names_a_seed_it_cannot_store(tmp_path):
    from handle_drake.learning.log import TrialLog

    with TrialLog(tmp_path / "log.sqlite") as log:
        with pytest.raises(ValueError, match="seed"):
            log.create_run("r", "random", [[0, 1]], 2**63, "objective")
        log.create_run("r", "random", [[0, 1]], 2**63 - 1, "objective")
        assert log.get_run("r").seed == 2**63 - 1


def test_numba_without_a_cache_place_falls_back_to_no_caching_with_a_warning(tmp_path):
    # as a user who can write neither the package's __pycache__ nor a home cache: numba's
    # locators all decline (root passes every permission check, so they are emptied)
    code = ("import numba.core.caching as c\n"
            "c.CacheImpl._locator_classes = []\n"
            "import numpy as np\n"
            "from handle_drake.geometry.quality import hull\n"
            "from handle_drake.geometry.quality import grasp_quality, ContactParams\n"
            "assert hull._compiled_epa_loop is not None\n"
            "P = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / 3**0.5 * 0.05\n"
            "q = grasp_quality(P, -P / 0.05, ContactParams(characteristic_length=0.05))\n"
            "print(q.force_closure, q.value)\n")
    done = subprocess.run([sys.executable, "-c", code], env=ENV, capture_output=True,
                          text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]  # was RuntimeError at import
    closure, value = done.stdout.split()
    # the regular tetrahedron's four contacts hold the sphere: force closure, q > 0
    assert closure == "True" and float(value) > 0
    assert done.stderr.count("numba cannot cache the compiled EPA") == 1, done.stderr


# ---------------------------------------------------------------------- hangs
def test_inhand_gaits_is_bounded(tmp_path):
    code, err = _run(["inhand", "--task", "screw_cap", "--gaits", "1000000", "--trials", "1",
                      "--db", "x.sqlite", "--no-progress"], tmp_path, timeout=60)
    assert code == 2 and "--gaits" in _last_line(err) and "1..12" in err, err
    assert not (tmp_path / "x.sqlite").exists()


@pytest.mark.parametrize("source", ["fifo", "/dev/zero", "directory"])
def test_grasp_db_that_is_no_regular_file_is_refused_at_once(source, tmp_path):
    # in a child with a deadline and 4 GiB of address space: a FIFO blocked the loader,
    # /dev/zero grew until MemoryError (39 s)
    path = {"fifo": tmp_path / "fifo", "/dev/zero": Path("/dev/zero"),
            "directory": tmp_path}[source]
    if source == "fifo":
        os.mkfifo(path)
    code = ("import resource, sys\n"
            "resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))\n"
            "from handle_drake.grasp.database import GraspDatabase, GraspDatabaseError\n"
            "try:\n"
            "    GraspDatabase.load(sys.argv[1])\n"
            "except GraspDatabaseError as error:\n"
            "    print(error)\n")
    done = subprocess.run([sys.executable, "-c", code, str(path)], env=ENV,
                          capture_output=True, text=True, timeout=90)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-1000:]
    message = done.stdout.strip()
    assert "grasp database" in message and str(path) in message and "\n" not in message


def test_pick_grasp_db_fifo_exits_2_as_a_user_meets_it(tmp_path):
    os.mkfifo(tmp_path / "fifo")
    code, err = _run(["pick", HAMBURG, "--true-poses", "--grasp-db", "fifo"], tmp_path,
                     timeout=90)
    assert code == 2 and "grasp database" in err and "fifo" in _last_line(err), err


# ------------------------------------------------- the grasp database's entries
def _database(tmp_path, change=None, name="db.json"):
    data = json.loads(SHIPPED_DB.read_text())
    if change is not None:
        change(data)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


def _grasped(data):
    return next(e for e in data["entries"] if e["grasp"] is not None)["grasp"]


def _set(field, value):
    return lambda data: _grasped(data).__setitem__(field, value)


NAN_POSE = np.eye(4).tolist()
NAN_POSE[1][3] = math.nan
MIRROR = np.diag([1.0, -1.0, 1.0, 1.0]).tolist()
SHEAR = np.eye(4).tolist()
SHEAR[0][1] = 0.5


@pytest.mark.parametrize("field,value,word", [
    ("X_PG", NAN_POSE, "finite"), ("X_BP", [[0.0] * 4] * 4, "last row"),
    ("X_PG", MIRROR, "rotation"), ("X_BP", SHEAR, "rotation"),
    ("contact_error", math.nan, "contact_error"),
])
def test_grasp_database_entries_must_be_finite_proper_transforms(field, value, word,
                                                                 tmp_path):
    from handle_drake.grasp.database import GraspDatabase, GraspDatabaseError

    path = _database(tmp_path, _set(field, value))
    with pytest.raises(GraspDatabaseError) as refused:
        GraspDatabase.load(path)  # was loaded: Drake failed later, or "no IK"
    text = str(refused.value)
    assert field in text and word in text and "db.json" in text and "entries[" in text


def test_the_shipped_grasp_database_still_loads_to_the_last_bit(tmp_path):
    from handle_drake.grasp.database import GraspDatabase

    database = GraspDatabase.load(SHIPPED_DB)
    data = json.loads(SHIPPED_DB.read_text())
    grasp = next(g for g in database.entries.values() if g is not None)
    stored = next(e["grasp"] for e in data["entries"] if e["grasp"] is not None)
    assert np.array_equal(grasp.X_PG.GetAsMatrix4(), np.array(stored["X_PG"]))
    assert len(database) == len(data["entries"])


@pytest.mark.parametrize("change,words", [
    (lambda d: d.update(entries=5), ["entries", "expected a list"]),
    (lambda d: d.update(entries=[5]), ["entries[0]", "mapping"]),
    (lambda d: d["entries"][0].pop("key"), ["entries[0]", "missing 'key'"]),
])
def test_grasp_database_structure_errors_name_the_field(change, words, tmp_path):
    from handle_drake.grasp.database import GraspDatabase, GraspDatabaseError

    with pytest.raises(GraspDatabaseError) as refused:
        GraspDatabase.load(_database(tmp_path, change))
    assert all(w in str(refused.value) for w in words), refused.value


def test_a_binary_grasp_database_is_refused_naming_the_file(tmp_path):
    from handle_drake.grasp.database import GraspDatabase, GraspDatabaseError

    path = tmp_path / "grasps.json"
    path.write_bytes(zlib.compress(SHIPPED_DB.read_bytes()))
    with pytest.raises(GraspDatabaseError, match="grasps.json.*UTF-8"):
        GraspDatabase.load(path)


_ENTRY = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.floats(-2, 2, allow_nan=False))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_ENTRY, min_size=16, max_size=16))
def test_fuzz_a_pose_either_is_a_rigid_transform_or_is_refused(values):
    from handle_drake.grasp.database import check_pose_matrix

    m = np.array(values).reshape(4, 4)
    try:
        checked = check_pose_matrix("X_PG", m)
    except ValueError as error:
        assert str(error).startswith("X_PG: expected")
        return
    # accepted: independent truth of a rigid transform
    R = checked[:3, :3]
    assert np.isfinite(checked).all() and np.allclose(R.T @ R, np.eye(3), atol=1e-5)
    assert np.linalg.det(R) > 0 and np.array_equal(checked[3], [0, 0, 0, 1])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(angle=st.floats(-10, 10), axis=st.lists(st.floats(-1, 1), min_size=3, max_size=3)
       .filter(lambda a: np.linalg.norm(a) > 1e-3), p=st.lists(st.floats(-1, 1), min_size=3,
                                                               max_size=3))
def test_fuzz_any_rigid_transform_stored_loads_back(angle, axis, p, tmp_path):
    from pydrake.common.eigen_geometry import AngleAxis
    from pydrake.math import RigidTransform, RotationMatrix

    from handle_drake.grasp.database import GraspDatabase

    X = RigidTransform(RotationMatrix(AngleAxis(angle, np.array(axis) / np.linalg.norm(axis))),
                       p)
    path = _database(tmp_path, _set("X_BP", X.GetAsMatrix4().tolist()), name="fuzz.json")
    loaded = GraspDatabase.load(path)
    grasp = next(g for g in loaded.entries.values() if g is not None)
    assert np.allclose(grasp.X_BP.GetAsMatrix4(), X.GetAsMatrix4(), atol=1e-12)


# ----------------------------------------------------------- pick's scenes
@pytest.mark.parametrize("override,words", [
    ("hand: {mount: !Arm {kind: pa10, X_WB: {translation: [-1.0, 0, 0]}, "
     "X_FH: {rotation: !Rpy {deg: [.nan, 0, 0]}}}}", ["hand.mount.X_FH"]),
    ("sorting_box: {X_WB: {translation: [.nan, 0.3, 0]}}", ["sorting_box.X_WB"]),
    ("hand: {mount: !Arm {kind: pa10, X_WB: {translation: [0, 0, -0.2]}}}",
     ["hand.mount.X_WB", "inside the table"]),
    ("hand: {mount: !Arm {kind: pa10, X_WB: {translation: [-1.0, 0, -5]}}}",
     ["hand.mount.X_WB", "reach"]),
    ("object: {kind: sphere, size: 0.06, X_WO: {translation: [3, 3, 0]}}",
     ["object.X_WO", "off the"]),
    ("objects: [{kind: sphere, size: 0.06, X_WO: {translation: [0.1, 2, 0]}}]",
     ["objects[0].X_WO", "off the"]),
    ("sorting_box: {on_table: false, X_WB: {translation: [0.0, 0.3, 0.5]}}",
     ["sorting_box.X_WB", "table top"]),
    ("sorting_box: {X_WB: {translation: [0.0, 1.5, 0]}}", ["sorting_box.X_WB", "off the"]),
    ("hand: {coupling_ratio: 100}", ["hand.coupling_ratio"]),
    ("hand: {kind: barrett, coupling_ratio: null}", ["hand.kind", "shadow"]),
])
def test_pick_refuses_a_scene_it_cannot_work_in_before_any_work(override, words, capsys,
                                                                monkeypatch, tmp_path):
    import handle_drake.apps.pick.cli as pick_cli

    def no_work(*args, **kwargs):  # planning would be the work: it must not start
        raise AssertionError("pick started")

    monkeypatch.setattr(pick_cli, "pick", no_work)
    monkeypatch.chdir(tmp_path)
    code, err = cli_exit(["pick", HAMBURG, "--true-poses", "--override", override], capsys)
    assert code == 2 and all(w in err for w in words), err
    assert len(err.strip().splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_the_shipped_hamburg_scene_passes_pick_checks():
    import argparse

    from handle_drake.apps.pick.checks import check_pick_arguments
    from handle_drake.scenario import LoadScenario

    args = argparse.Namespace(html=None, kind="sphere", build_grasp_db=False, grasp_db=None)
    check_pick_arguments(args, LoadScenario(filename=HAMBURG))  # no exception


def test_pick_html_png_is_refused_before_any_work(capsys, monkeypatch, tmp_path):
    import handle_drake.apps.pick.cli as pick_cli

    monkeypatch.setattr(pick_cli, "pick", lambda *a, **k: (_ for _ in ()).throw(
        AssertionError("pick started")))
    code, err = cli_exit(["pick", HAMBURG, "--true-poses", "--html", str(tmp_path / "out.png")],
                         capsys)
    assert code == 2 and "--html" in err and ".html" in err and not (tmp_path / "out.png")\
        .exists()


def test_build_grasp_db_to_an_unwritable_place_is_refused_before_any_search(capsys,
                                                                            monkeypatch):
    import handle_drake.apps.pick.plan as plan

    monkeypatch.setattr(plan, "build_grasp_database", lambda *a, **k: (_ for _ in ()).throw(
        AssertionError("searched")))
    code, err = cli_exit(["pick", HAMBURG, "--true-poses", "--build-grasp-db", "--grasp-db",
                      "/proc/grasps.json"], capsys)
    assert code == 2 and "--grasp-db" in err, err  # was refused after 45 s of searches


def test_a_planning_reason_names_the_target_the_result_names():
    from handle_drake.apps.pick.checks import named_as_truth

    reason = "object_40 (sphere): no reachable pick; tripod: no IK"
    assert named_as_truth(reason, "object_40", "object_41").startswith(
        "object_41 (perceived as object_40) (sphere)")
    assert named_as_truth(reason, "object_40", "object_40") == reason
    assert named_as_truth("object_4: x", "object_40", "object_41") == "object_4: x"


# ------------------------------------------- inhand: refusals before the log
@pytest.mark.parametrize("argv,word", [
    (["--placement", "regrasp"], "--placement"),
    (["--task", "screw_cap", "--grip-digits", "6"], "--grip-digits"),
    (["--task", "jog_wheel", "--gaits", "2"], "--gaits"),
    (["--target-deg", "1e308"], "--target-deg"),
    (["--particles", "1000000000"], "--particles"),
    (["--trials", "1000000000000"], "--trials"),
    (["--workers", "1000000"], "--workers"),
    (["--gaits", "3"], "--gaits"),  # a task without gaits: was silently ignored
    (["--strokes", "1"], "--strokes"),
])
def test_inhand_refusals_leave_no_trial_log_behind(argv, word, capsys, tmp_path):
    db = tmp_path / "sub" / "x.sqlite"
    code, err = cli_exit(["inhand", "--trials", "1", "--no-progress", "--db", str(db), *argv],
                         capsys)
    assert code == 2 and word in _last_line(err), err
    assert not db.exists() and not db.parent.exists()  # was: a new sqlite file


def test_target_deg_minus_90_names_the_accepted_range(capsys, tmp_path):
    code, err = cli_exit(["inhand", "--target-deg", "-90", "--db", str(tmp_path / "x.sqlite")],
                         capsys)
    assert code == 2 and "(0, 360]" in err and ">= 0" not in err, err


def test_chunk_superscript_two_is_named(capsys):
    code, err = cli_exit(["babble", "--chunk", "²", "--trials", "1"], capsys)
    assert code == 2 and "--chunk" in err and "'²'" in err and "_chunk_type" not in err, err


# ----------------------------------------------------------------- trial logs
def _babble(db, trials, cwd):
    return subprocess.Popen([sys.executable, "-m", "handle_drake.cli", "babble", "--strategy",
                             "random", "--trials", str(trials), "--db", str(db), "--no-plot",
                             "--no-progress"], cwd=cwd, env=ENV, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def test_a_trial_log_with_a_scenario_that_is_not_utf8_is_refused_in_one_line(tmp_path):
    from handle_drake.learning.log import TrialLog, TrialLogError

    db = tmp_path / "log.sqlite"
    with TrialLog(db) as log:
        log.create_run("r", "random", [[0, 1]], 0, "objective")
        log.add_pending("r", 0, [0.5], 0, scenario="hand: {kind: shadow}\n")
    conn = sqlite3.connect(db)
    conn.execute("UPDATE trials SET scenario = CAST(? AS TEXT)",
                 (b"\xff\xfe hand:\n  kind: barrett\n" * 20,))
    conn.commit()
    conn.close()
    with pytest.raises(TrialLogError) as refused:
        TrialLog(db)
    text = str(refused.value)
    assert "scenario" in text and "UTF-8" in text and "0xff" in text
    assert "\n" not in text and "barrett" not in text and len(text) < 300


def test_the_same_run_twice_at_once_on_one_log_is_refused_naming_the_other_process(tmp_path):
    from handle_drake.learning.log import TrialLog, TrialLogError

    db = tmp_path / "log.sqlite"
    code = ("import sys, time\n"
            "from handle_drake.learning.log import TrialLog\n"
            "log = TrialLog(sys.argv[1])\n"
            "log.open_run('r', 'random', [[0, 1]], 0, 'objective')\n"
            "print('open', flush=True)\n"
            "sys.stdin.read()\n")
    other = subprocess.Popen([sys.executable, "-c", code, str(db)], env=ENV, text=True,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        assert other.stdout.readline().strip() == "open"
        with TrialLog(db) as log:
            with pytest.raises(TrialLogError, match="another process"):
                log.open_run("r", "random", [[0, 1]], 0, "objective")
            log.open_run("s", "random", [[0, 1]], 0, "objective")  # another run: fine
    finally:
        other.stdin.close()
        other.wait(60)
    with TrialLog(db) as log:  # the other process has ended: the run is free again
        log.open_run("r", "random", [[0, 1]], 0, "objective")
        with TrialLog(db) as same_process:  # and this process may open it twice
            same_process.open_run("r", "random", [[0, 1]], 0, "objective")


def test_a_run_killed_with_kill_9_is_free_at_once_and_resumes(tmp_path):
    from handle_drake.learning.log import TrialLog

    db = tmp_path / "log.sqlite"
    code = ("import os, sys\n"
            "from handle_drake.learning.log import TrialLog\n"
            "log = TrialLog(sys.argv[1])\n"
            "log.open_run('r', 'random', [[0, 1]], 0, 'objective')\n"
            "log.add_pending('r', 0, [0.5], 0)\n"
            "log.mark_running('r', 0)\n"
            "log.commit()\n"
            "os.kill(os.getpid(), 9)\n")
    done = subprocess.run([sys.executable, "-c", code, str(db)], env=ENV, timeout=120)
    assert done.returncode == -9
    with TrialLog(db) as log:  # no stale claim: the kernel freed it with the process
        log.open_run("r", "random", [[0, 1]], 0, "objective")
        assert [t.status for t in log.trials("r")] == ["running"]
