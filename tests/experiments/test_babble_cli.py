"""``handle-drake babble`` / ``report``: runs, resumes, refuses bad input, writes its files."""

import csv
import json
import sqlite3

import numpy as np
import pytest

from handle_drake.apps.babbling.cli import main
from handle_drake.learning import TrialLog
from handle_drake.trial import grasp_trial
from handle_drake.trial.grasp_trial import GraspTrial

ARGS = ["babble", "--object", "sphere", "--dims", "2", "--trials", "5", "--seed", "3",
        "--noise", "0.01", "--no-progress"]


def _rows(db):
    with TrialLog(db) as log:
        (run,) = log.runs()
        return log.trials(run.run_id)


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    """An uninterrupted 5-trial BO run, the truth the resumed run must match."""
    db = tmp_path_factory.mktemp("ref") / "ref.sqlite"
    assert main([*ARGS, "--db", str(db)]) == 0
    return db, _rows(db)


def test_babble_logs_every_trial_and_prints_the_best(reference_run, capsys, tmp_path):
    db, rows = reference_run
    assert [r.index for r in rows] == list(range(5))
    assert all(r.status == "done" for r in rows)
    bounds = GraspTrial(hand="barrett", object="sphere", space="offset").bounds
    X = np.array([r.parameters for r in rows])
    assert np.all((X >= bounds[:, 0]) & (X <= bounds[:, 1]))
    # Each logged noiseless metric is what the simulation gives at those
    # parameters, and the noise is the configured size.
    trial = GraspTrial(hand="barrett", object="sphere", space="offset")
    best = max(rows, key=lambda r: r.metric)
    clean = trial.evaluate(best.parameters).metric_noiseless
    assert best.contacts["metric_noiseless"] == pytest.approx(clean, abs=1e-9)
    assert all(abs(r.metric - r.contacts["metric_noiseless"]) < 0.06 for r in rows)
    assert all("hand:" in r.scenario and "barrett" in r.scenario for r in rows)
    # Same seed, new file: the same trials (determinism), and the best is printed.
    capsys.readouterr()
    assert main([*ARGS, "--db", str(tmp_path / "again.sqlite")]) == 0
    out = capsys.readouterr().out
    again = _rows(tmp_path / "again.sqlite")
    assert [r.parameters.tolist() for r in again] == [r.parameters.tolist() for r in rows]
    assert [r.metric for r in again] == [r.metric for r in rows]
    assert f"best metric {best.metric:.6g}" in out
    assert f"x_offset_m = {best.parameters[0]:.6g}" in out


def test_babble_resumes_an_interrupted_run_without_repeating_trials(
        reference_run, tmp_path, monkeypatch):
    _, reference = reference_run
    db = tmp_path / "resume.sqlite"
    evaluate = GraspTrial.evaluate
    calls = []

    def interrupted_on_third(self, x, seed=0):
        calls.append(np.array(x))
        if len(calls) == 3:
            raise KeyboardInterrupt  # Ctrl-C in the middle of trial 2
        return evaluate(self, x, seed=seed)

    monkeypatch.setattr(grasp_trial.GraspTrial, "evaluate", interrupted_on_third)
    assert main([*ARGS, "--db", str(db)]) == 130
    before = _rows(db)
    assert [r.status for r in before] == ["done", "done", "running"]

    calls.clear()
    monkeypatch.setattr(grasp_trial.GraspTrial, "evaluate", evaluate)
    counted = []

    def counting(self, x, seed=0):
        counted.append(np.array(x))
        return evaluate(self, x, seed=seed)

    monkeypatch.setattr(grasp_trial.GraspTrial, "evaluate", counting)
    assert main([*ARGS, "--db", str(db)]) == 0
    after = _rows(db)
    # Only the interrupted trial and the two never started ran again.
    assert len(counted) == 3
    np.testing.assert_array_equal(counted[0], before[2].parameters)
    # The finished trials were not touched.
    for old, new in zip(before[:2], after[:2], strict=True):
        assert (new.metric, new.finished_at) == (old.metric, old.finished_at)
    # The resumed run is the run that was never interrupted.
    assert [r.parameters.tolist() for r in after] == [r.parameters.tolist() for r in reference]
    assert [r.metric for r in after] == [r.metric for r in reference]
    # Asking for more trials later continues the same run.
    assert main([*ARGS[:-1], "--trials", "6", "--db", str(db), "--no-progress"]) == 0
    assert len(_rows(db)) == 6


@pytest.mark.parametrize("bad, message", [
    (["--trials", "0"], "positive integer"),
    (["--trials", "ten"], "positive integer"),
    (["--seed", "-1"], "integer in 0..2**63-1"),
    (["--noise", "nan"], "finite number"),
    (["--ei-stop", "-1"], "finite number"),
    (["--object", "teapot"], "invalid choice"),
    (["--dims", "3"], "invalid choice"),
])
def test_babble_bad_arguments_exit_2_with_a_message(bad, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["babble", *bad, "--db", str(tmp_path / "x.sqlite")])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.sqlite").exists()


@pytest.mark.parametrize("bad, message", [
    (["--space", "synergy"], "needs the shadow hand"),
    (["--dims", "1", "--space", "offset"], "contradicts"),
    (["--strategy", "random", "--ei-stop", "1e-6"], "only Bayesian optimisation"),
    (["--plot", "run.jpg"], "expected a .png file name"),
    (["--plot", "run.png", "--no-plot"], "contradict"),
    (["--placement-samples", "3"], "needs --placement-error"),
    (["--placement-error", "0.002", "--placement-samples", "1"], "at least 2"),
    (["--placement-error", "0.5"], "placement_error: expected at most 0.05 m"),
])
def test_babble_inconsistent_arguments_exit_2(bad, message, tmp_path, capsys):
    assert main(["babble", *bad, "--db", str(tmp_path / "x.sqlite")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.sqlite").exists()


def test_babble_writes_its_figure_next_to_the_log_unless_told_not_to(
        reference_run, tmp_path, capsys):
    db, _ = reference_run
    with TrialLog(db) as log:
        (run,) = log.runs()
    assert (db.parent / f"{run.run_id}.png").stat().st_size > 10_000
    capsys.readouterr()
    # Resuming a finished run still draws it, where asked; --no-plot draws nothing.
    assert main([*ARGS, "--db", str(db), "--plot", str(tmp_path / "fig" / "a.png")]) == 0
    assert f"figure: {tmp_path / 'fig' / 'a.png'}" in capsys.readouterr().out
    assert (tmp_path / "fig" / "a.png").stat().st_size > 10_000
    other = tmp_path / "other.sqlite"
    assert main([*ARGS[:-3], "--trials", "2", "--db", str(other), "--no-plot",
                 "--no-progress"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig", "other.sqlite"]


def test_babble_refuses_a_corrupt_database_and_leaves_it_alone(tmp_path, capsys):
    db = tmp_path / "broken.sqlite"
    garbage = b"not a database at all\x00" * 50
    db.write_bytes(garbage)
    assert main(["babble", "--trials", "2", "--db", str(db), "--no-progress"]) == 2
    assert "not an SQLite database" in capsys.readouterr().err
    assert db.read_bytes() == garbage
    # An SQLite file of something else is not touched either.
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as conn:
        conn.execute("CREATE TABLE notes (text TEXT)")
    size = other.stat().st_size
    assert main(["babble", "--trials", "2", "--db", str(other), "--no-progress"]) == 2
    assert "not a handle_drake trial log" in capsys.readouterr().err
    assert other.stat().st_size == size


def test_report_in_reduced_mode_writes_figures_and_table(tmp_path, capsys):
    from handle_drake.geometry.objects.mesh_examples import l_bracket

    out = tmp_path / "report"
    # a mesh object in millimetres, as CAD exports it: one more row
    l_bracket().apply_scale(1000.0).export(tmp_path / "bracket.stl")
    mesh = ["--mesh", str(tmp_path / "bracket.stl"), "--mesh-scale", "0.001"]
    assert main(["report", "--out", str(out), "--reduced", "--no-progress", *mesh]) == 0
    for name in ("fig21_sphere_1d.png", "fig22_star_prism_1d.png", "fig23_wine_glass_2d.png",
                 "fig24_mug_2d.png", "fig25_star_prism_2d.png", "fig23_25_all_objects_2d.png",
                 "fig26_sphere_bo_vs_random.png", "fig27_mug_bo_vs_random.png",
                 "fig28_synergy_gp_mean.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000, name
    with open(out / "table3.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["object"] for r in rows] == ["sphere", "wine_glass", "cylinder", "mug", "cuboid",
                                           "rotated_cuboid", "star_prism", "mesh bracket"]
    assert rows[7]["report total"] == "-" and float(rows[7]["grid max"]) > -1.0
    assert (out / "fig_mesh_bracket_2d.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert rows[3]["report total"] == "331" and rows[6]["report 5%"] == "105"
    summary = json.loads((out / "summary.json").read_text())
    # The grid is 3x3, so its centre is the centred grasp: the grid maximum
    # can be no lower than an independent trial there.
    centre = GraspTrial(hand="barrett", object="sphere", space="offset").evaluate([0.0, 0.0])
    assert summary["table3"]["sphere"]["grid_max"] >= centre.metric_noiseless - 1e-12
    assert "| sphere |" in (out / "table3.md").read_text()
    # Everything is cached: a second report runs no trial.
    with TrialLog(out / "babble.sqlite") as log:
        count = sum(len(log.trials(r.run_id)) for r in log.runs())
    assert main(["report", "--out", str(out), "--reduced", "--no-progress", *mesh]) == 0
    with TrialLog(out / "babble.sqlite") as log:
        assert sum(len(log.trials(r.run_id)) for r in log.runs()) == count


def test_sigterm_stops_a_parallel_run_like_ctrl_c_and_leaves_no_workers(tmp_path):
    """``kill`` (SIGTERM) on a run with worker processes: exit code 130, the
    log is resumable (nothing lost: every row done, running or pending), and
    no worker process outlives the command."""
    import os
    import signal
    import subprocess
    import sys
    import time

    db = tmp_path / "killed.sqlite"
    log_path = tmp_path / "stderr.txt"
    children = []
    with open(log_path, "w") as stderr:
        process = subprocess.Popen(
            [sys.executable, "-m", "handle_drake.cli", "babble", "--object", "sphere", "--dims",
             "2", "--strategy", "random", "--trials", "400", "--workers", "2", "--seed", "1",
             "--db", str(db), "--no-progress"],
            stdout=subprocess.DEVNULL, stderr=stderr,
            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    try:
        deadline = time.monotonic() + 120
        done = 0
        while time.monotonic() < deadline and process.poll() is None and done < 4:
            time.sleep(0.5)
            if db.exists():
                try:
                    with sqlite3.connect(db) as connection:
                        done = connection.execute(
                            "SELECT COUNT(*) FROM trials WHERE status = 'done'").fetchone()[0]
                except sqlite3.OperationalError:  # tables not created yet
                    pass
        assert done >= 4, "the run did not get going"
        children = [int(pid) for pid in subprocess.run(
            ["pgrep", "-P", str(process.pid)], capture_output=True, text=True).stdout.split()]
        assert children, "expected worker processes"
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=60)
        time.sleep(1.0)
        alive = [pid for pid in children if os.path.exists(f"/proc/{pid}")
                 and "zombie" not in open(f"/proc/{pid}/status").read()]
    finally:
        for pid in [process.pid, *children]:
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
    assert process.returncode == 130
    err = log_path.read_text()
    assert "interrupted" in err and "resume" in err
    assert not alive, f"worker processes still running after the command ended: {alive}"
    with TrialLog(db) as log:
        (run,) = log.runs()
        statuses = {r.status for r in log.trials(run.run_id)}
    assert statuses <= {"done", "running", "pending"} and "done" in statuses


def test_babble_bo_on_two_workers_runs_batches_as_a_run_of_its_own(reference_run, tmp_path):
    """``--workers 2`` with BO: trials in pairs on two processes, logged under
    their own run id (a batch run is not the sequential run)."""
    db, rows = reference_run
    batch_db = tmp_path / "batch.sqlite"
    assert main([*ARGS, "--workers", "2", "--db", str(batch_db)]) == 0
    with TrialLog(batch_db) as log:
        (run,) = log.runs()
        trials = log.trials(run.run_id)
    with TrialLog(db) as log:
        (sequential,) = log.runs()
    assert run.run_id != sequential.run_id and run.config == {"batch_size": 2}
    assert [t.status for t in trials] == ["done"] * 5
    # The initial design does not depend on the batch size.
    np.testing.assert_array_equal([t.parameters for t in trials], [r.parameters for r in rows])


@pytest.mark.parametrize("parse, text, value, error", [
    ("positive_int", "3", 3, None), ("positive_int", "0", None, "a positive integer, got 0"),
    ("positive_int", "2.5", None, "a positive integer, got '2.5'"),
    ("non_negative_int", "0", 0, None), ("non_negative_int", "-1", None, "integer >= 0, got -1"),
    ("non_negative_float", "0", 0.0, None),
    ("non_negative_float", "nan", None, "finite number >= 0, got nan"),
    ("non_negative_float", "inf", None, "finite number >= 0, got inf"),
    ("positive_float", "1e-3", 1e-3, None), ("positive_float", "0", None, "number > 0, got 0"),
    ("positive_float", "x", None, "number > 0, got 'x'"),  # not ">= 0": 0 is refused
    ("positive_float", "-90", None, "finite number > 0, got -90"),
])
def test_the_shared_argument_types(parse, text, value, error):
    """One set of argparse types for every sub-command (babble, report, inhand)."""
    import argparse

    from handle_drake.apps import cli_support

    function = getattr(cli_support, parse)
    if error is None:
        assert function(text) == value
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=f"expected .*{error}"):
            function(text)
