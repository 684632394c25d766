"""The demo and the shipped grasp scenarios hold their object through a lift."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

from handle_drake.apps.demo import run_demo
from handle_drake.base.models import diagrams_dir
from handle_drake.scenario import LoadScenario
from handle_drake.trial.simulate import REQUIRED_LIFT, ScenarioRunner, held_through_lift


def test_demo_grasp_holds_the_sphere_through_a_10cm_lift(tmp_path):
    report = run_demo(plot=tmp_path / "height.png")
    assert report.held, report.summary()
    assert report.lift >= REQUIRED_LIFT
    # The held grasp is in force closure (BW metric > 0).
    assert report.force_closure and report.quality > 0
    # The hand, not a glitch, carried it: the fingertips press on it at the end.
    assert np.count_nonzero(report.result.tactile[-1] > 0.5) >= 2
    assert (tmp_path / "height.png").stat().st_size > 10_000
    # A clean pre-grasp: nothing presses on the sphere while the hand reaches
    # and pre-shapes (the fingers close from 0.5 s and meet it after 0.75 s),
    # and the sphere is not pushed into the table (it rests on point contact,
    # so pressing it sinks it: 17 N on the thumb sank it 2.7 mm).
    result = report.result
    reach = result.times < 0.75
    assert result.tactile[reach].max() < 1.0, result.tactile[reach].max(axis=0)
    z = result.object_position[:, 2]
    assert z[result.times < 1.2].min() > z[0] - 0.0005


def test_dropped_object_is_reported_as_not_held():
    scenario = LoadScenario(filename=diagrams_dir() / "shadow_sphere_grasp.yaml",
                            data="script: [{time: 0.0}]\nsimulation_duration: 0.5")
    runner = ScenarioRunner(scenario)
    result = runner.run()
    assert not held_through_lift(result)
    value, closure, _ = runner.grasp_quality()
    assert not closure and value < 0


def test_barrett_hand_holds_a_cylinder_through_a_lift():
    scenario = LoadScenario(filename=diagrams_dir() / "barrett_cylinder_grasp.yaml")
    result = ScenarioRunner(scenario).run()
    assert held_through_lift(result), result.object_position[::25, 2]


def test_cli_reports_bad_scenario_without_a_traceback(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("object: {kind: teapot}\n")
    completed = subprocess.run(
        [sys.executable, "-m", "handle_drake.cli", "simulate", str(bad)],
        capture_output=True, text=True, timeout=120,
    )
    assert completed.returncode == 2
    assert "teapot" in completed.stderr and "Traceback" not in completed.stderr


def test_cli_simulate_writes_a_self_contained_replay(tmp_path):
    html = tmp_path / "replay.html"
    completed = subprocess.run(
        [sys.executable, "-m", "handle_drake.cli", "simulate",
         str(diagrams_dir() / "shadow_sphere_grasp.yaml"), "--duration", "0.3",
         "--html", str(html)],
        capture_output=True, text=True, timeout=300,
    )
    assert completed.returncode == 0, completed.stderr
    text = html.read_text()
    assert "<html" in text.lower() and "animation" in text.lower()
    assert "http://localhost" not in text  # nothing left to fetch from the server


def _screenshot(html, png, profile):
    """``html`` as headless Chromium draws it at 640 x 480, as an RGB array."""
    from PIL import Image

    subprocess.run(
        ["chromium", "--headless", "--no-sandbox", "--disable-gpu",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--no-first-run", f"--user-data-dir={profile}", "--window-size=640,480",
         "--virtual-time-budget=5000", f"--screenshot={png}", html.as_uri()],
        capture_output=True, timeout=120, check=True,
    )
    return np.asarray(Image.open(png).convert("RGB"), dtype=float)


@pytest.mark.skipif(shutil.which("chromium") is None,
                    reason="Debian's chromium is not installed (.ci/run installs it)")
def test_replay_page_renders_the_scene_in_a_browser(tmp_path):
    """Look at the replay as a person would: the page must draw a scene, not a
    blank, and open framed on the hand, not on the whole world."""
    from pydrake.geometry import StartMeshcat

    meshcat = StartMeshcat()
    runner = ScenarioRunner(LoadScenario(filename=diagrams_dir() / "shadow_sphere_grasp.yaml"),
                            meshcat)
    html = tmp_path / "scene.html"
    runner.run(0.2, html=html)
    pixels = _screenshot(html, tmp_path / "scene.png", tmp_path / "chromium")
    # A drawn scene has the table, the hand and the object: many distinct colours
    # and real contrast; a blank or error page has almost none.
    assert pixels.std() > 20
    assert len(np.unique(pixels.reshape(-1, 3) // 16, axis=0)) > 50
    # The hand's share of the screen: the pixels that change when it is hidden.
    # Meshcat's default camera, metres away, showed it on 0.1 % of the pixels;
    # framed, it covers about 6 %.
    meshcat.SetProperty("/drake/illustration/hand", "visible", False)
    hidden = tmp_path / "no_hand.html"
    hidden.write_text(meshcat.StaticHtml())
    without = _screenshot(hidden, tmp_path / "no_hand.png", tmp_path / "chromium2")
    share = float(np.mean(np.abs(pixels - without).sum(axis=2) > 30))
    assert share > 0.03, share
