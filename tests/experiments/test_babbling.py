"""Babbling helpers: Table 3's counts, best-so-far curves, cached grids, replayed optimisers."""

import math

import numpy as np
import pytest

from handle_drake.apps.babbling.babbling import (
    RunSpec,
    best_so_far,
    grid_points,
    grid_values,
    replay_optimizer,
    run_batch,
    run_history,
    trials_to_within,
)
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig


def test_trials_to_within_counts_the_first_trial_in_each_band():
    # Maximum 1.0: 0.79 is 21 % short, 0.85 within 20 %, 0.91 within 10 %, 0.96 within 5 %.
    values = [0.5, 0.79, 0.85, 0.7, 0.91, 0.96]
    assert trials_to_within(values, 1.0) == [6.0, 5.0, 3.0]
    assert trials_to_within([0.1, 0.2], 1.0) == [math.inf] * 3
    # A negative maximum: "within 10 %" means at least -1.1.
    assert trials_to_within([-1.2, -1.08, -1.0], -1.0, (0.1,)) == [2.0]
    with pytest.raises(ValueError, match="global_max"):
        trials_to_within([1.0], math.nan)
    with pytest.raises(ValueError, match="fractions"):
        trials_to_within([1.0], 1.0, (1.5,))


def test_best_so_far_ignores_failures_and_holds_after_an_early_stop():
    np.testing.assert_array_equal(best_so_far([0.2, np.nan, 0.1, 0.5], 6),
                                  [0.2, 0.2, 0.2, 0.5, 0.5, 0.5])


def test_grid_points_span_the_box_in_ij_order():
    axes, points = grid_points([[0.0, 1.0], [-2.0, 2.0]], 3)
    assert points.shape == (9, 2)
    np.testing.assert_array_equal(points[:3], [[0, -2], [0, 0], [0, 2]])
    with pytest.raises(ValueError, match="expected an integer >= 2"):
        grid_points([[0.0, 1.0]], 1)


def test_grid_values_are_the_trials_noiseless_metric_and_cached(tmp_path, monkeypatch):
    config = GraspTrialConfig(hand="barrett", object="sphere", space="standoff", noise=0.3)
    (axis,), values = grid_values(config, 3, cache_dir=tmp_path)
    trial = GraspTrial(hand="barrett", object="sphere", space="standoff")
    np.testing.assert_array_equal(axis, [0.0, 0.06, 0.12])
    expected = [trial.evaluate([s]).metric for s in axis]  # noise is ignored for the grid
    np.testing.assert_allclose(values, expected, atol=1e-12)
    # The second call reads the cache and runs no simulation.
    monkeypatch.setattr(GraspTrial, "evaluate", lambda *a, **k: pytest.fail("not cached"))
    _, again = grid_values(config, 3, cache_dir=tmp_path)
    np.testing.assert_array_equal(again, values)


def test_replayed_optimizer_proposes_the_logged_next_trial(tmp_path):
    config = GraspTrialConfig(hand="barrett", object="mug", space="offset", noise=0.01)
    spec = RunSpec(config, "bo", seed=2, n_trials=6)
    db = tmp_path / "t.sqlite"
    run_batch([spec], db, workers=1, progress=False)
    history = run_history(db, spec)
    assert len(history.X) == 6
    # The optimiser rebuilt from the first 4 trials asks exactly for trial 5.
    optimizer = replay_optimizer(spec, history, 4)
    np.testing.assert_allclose(optimizer.ask(), history.X[4], rtol=0, atol=1e-12)
    # Noise is in the observed metric, not in the noiseless one.
    assert 0 < np.max(np.abs(history.observed - history.noiseless)) < 0.05
    with pytest.raises(ValueError, match="two runs have the same run_id"):
        run_batch([spec, spec], db)


def test_grid_cache_key_changes_with_the_simulation_code(monkeypatch):
    """A grid cached by other simulation code must not be read back as current."""
    from handle_drake.apps.babbling import babbling
    from handle_drake.trial.grasp_trial import GraspTrialConfig

    config = GraspTrialConfig(hand="barrett", object="sphere")
    key = babbling._config_key(config)
    assert babbling._config_key(config) == key  # stable for the same code
    monkeypatch.setattr(babbling, "simulation_fingerprint", lambda: "other-code")
    assert babbling._config_key(config) != key


def test_run_ids_follow_the_code_not_its_comments_or_docstrings():
    """Editing a docstring or a comment keeps a run resumable; changing code does not."""
    from handle_drake.apps.babbling.babbling import code_digest

    code = 'def f(x):\n    """Doubles x."""\n    return 2 * x\n'
    reworded = ('"""A module doc."""\n\n\ndef f(x):  # the factor is 2\n'
                '    """Twice x, reworded."""\n\n    return 2 * x\n')
    changed = 'def f(x):\n    """Doubles x."""\n    return 3 * x\n'
    only_doc = 'def f(x):\n    """Doubles x."""\n'
    assert code_digest(code) == code_digest(reworded)
    assert code_digest(code) != code_digest(changed)
    assert code_digest(only_doc) != code_digest(code)


# What a grasp trial loads that cannot change its metric: the learning engine, validation
# and port names, settings of drivers and sensors it does not use, where models live (the
# model files themselves are hashed).
# The station imports every device's systems at the top; a grasp trial's scenario adds none
# of them (no accelerometer, MIDI controller or camera), and the Meshcat framing and the
# reduced-mode switch change no metric.
_NOT_SIMULATION = ("base/blas", "learning/", "base/checks", "base/port_names", "base/models",
                   "can_hand/", "accelerometer/", "camera/", "devices/midi/", "base/viewing",
                   "base/testing", "base/extras", "base/orphans", "__init__")


def test_the_run_id_covers_all_the_simulation_code_a_trial_runs():
    """Every module a grasp trial (on an instrumented device, the widest object) loads is
    hashed into the run id unless it cannot change a metric; a device's geometry can."""
    import subprocess
    import sys
    from pathlib import Path

    from handle_drake.apps.babbling.babbling import simulation_sources
    from handle_drake.base.models import PACKAGE_DIR

    code = ("import sys\nfrom handle_drake.trial.grasp_trial import GraspTrial, "
            "GraspTrialConfig\ntrial = GraspTrial(GraspTrialConfig(object='wiimote'))\n"
            "trial(trial.bounds.mean(axis=1))\n"
            "print('\\n'.join(m.__file__ for n, m in sys.modules.items() "
            "if n.startswith('handle_drake') and getattr(m, '__file__', None)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=600).stdout
    root = PACKAGE_DIR
    loaded = {Path(line).relative_to(root).as_posix() for line in out.split()}
    assert "geometry/objects/instrumented.py" in loaded and "systems/guarded_grasp.py" in loaded
    hashed = {p.relative_to(root).as_posix() for p in simulation_sources()}
    unhashed = sorted(f for f in loaded - hashed if not any(k in f for k in _NOT_SIMULATION))
    assert unhashed == []


def test_run_id_changes_with_the_trial_settings_and_simulation_code(monkeypatch):
    """A logged run is resumed or read back only by the same trial on the same code."""
    from handle_drake.apps.babbling import babbling

    config = GraspTrialConfig(hand="barrett", object="sphere", noise=0.01)
    spec = RunSpec(config, "bo", 3, 10)
    assert RunSpec(config, "bo", 3, 10).run_id == spec.run_id  # stable
    # The budget is not part of the run: a longer budget continues it.
    assert RunSpec(config, "bo", 3, 50).run_id == spec.run_id
    other_hold = GraspTrialConfig(hand="barrett", object="sphere", noise=0.01, hold_samples=1)
    assert RunSpec(other_hold, "bo", 3, 10).run_id != spec.run_id
    assert RunSpec(config, "bo", 4, 10).run_id != spec.run_id
    run_id = spec.run_id
    monkeypatch.setattr(babbling, "simulation_fingerprint", lambda: "other-code")
    assert RunSpec(config, "bo", 3, 10).run_id != run_id


# ------------------------------------------------------------- grid surrogate
def _sunflower(error, samples):
    """The placement stencil written out from its definition (Vogel's pattern)."""
    k = np.arange(samples)
    radius = error * np.sqrt((k + 0.5) / samples)
    angle = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


def test_grid_surrogate_interpolates_and_averages_over_the_placement_stencil():
    from handle_drake.apps.babbling.babbling import GridSurrogate

    axes = [np.linspace(-0.04, 0.04, 5), np.array([-0.03, -0.01, 0.0, 0.02, 0.03])]
    X, Y = np.meshgrid(*axes, indexing="ij")

    def f(x, y):  # bilinear: the grid's interpolant is exact everywhere in the box
        return 0.3 + 2.0 * x - 3.0 * y + 40.0 * x * y

    nominal = GridSurrogate(axes, f(X, Y))
    inside = np.random.default_rng(0).uniform([-0.04, -0.03], [0.04, 0.03], (20, 2))
    np.testing.assert_allclose(nominal.noiseless(inside), f(*inside.T), atol=1e-12)
    assert nominal.noiseless([0.01, 0.005]) == pytest.approx(f(0.01, 0.005), abs=1e-12)
    # Robust: E[f(x + s)] over the stencil = f(x) + 2 mean(sx) - 3 mean(sy)
    # + 40 (x mean(sy) + y mean(sx) + mean(sx sy)), away from the box's edges.
    e, k = 0.004, 7
    robust = GridSurrogate(axes, f(X, Y), placement_error=e, placement_samples=k)
    s = _sunflower(e, k)
    x, y = 0.012, -0.007
    expected = f(x, y) + 2.0 * s[:, 0].mean() - 3.0 * s[:, 1].mean() + 40.0 * (
        x * s[:, 1].mean() + y * s[:, 0].mean() + (s[:, 0] * s[:, 1]).mean())
    assert robust.noiseless([x, y]) == pytest.approx(expected, abs=1e-12)
    # On the box's edge the placements that fall outside read the edge's value.
    edge = robust.noiseless([0.04, 0.0])
    assert edge == pytest.approx(np.mean(f(np.minimum(0.04 + s[:, 0], 0.04), s[:, 1])),
                                 abs=1e-12)
    # Noise as the simulated trial adds it: noise * N(0, 1) from the trial's seed.
    noisy = GridSurrogate(axes, f(X, Y), noise=0.01)
    assert noisy([x, y], seed=5) == pytest.approx(
        f(x, y) + 0.01 * np.random.default_rng(5).standard_normal(), abs=1e-12)


def test_grid_surrogate_robust_optimum_leaves_a_spike_for_a_plateau():
    from handle_drake.apps.babbling.babbling import GridSurrogate

    # A one-cell spike of 1.0 at (-0.02, 0) and a plateau of 0.8 around (0.02, 0),
    # cells of 1 mm: the nominal maximum is the spike, the robust one (2 mm) the plateau.
    axes = [np.linspace(-0.03, 0.03, 61)] * 2
    X, Y = np.meshgrid(*axes, indexing="ij")
    values = np.where(np.hypot(X - 0.02, Y) <= 0.006, 0.8, 0.1)
    values[np.argmin(np.abs(axes[0] + 0.02)), 30] = 1.0
    x_nominal, f_nominal = GridSurrogate(axes, values).maximum(refine=1)
    np.testing.assert_allclose(x_nominal, [-0.02, 0.0], atol=1e-12)
    assert f_nominal == pytest.approx(1.0)
    x_robust, f_robust = GridSurrogate(axes, values, placement_error=0.002,
                                       placement_samples=8).maximum(refine=1)
    assert np.hypot(x_robust[0] - 0.02, x_robust[1]) <= 0.004
    assert f_robust == pytest.approx(0.8)


def test_grid_surrogate_refuses_bad_grids_and_settings():
    from handle_drake.apps.babbling.babbling import GridSurrogate

    axes = [np.linspace(0, 1, 3), np.linspace(0, 1, 4)]
    with pytest.raises(ValueError, match=r"values: expected shape \(3, 4\)"):
        GridSurrogate(axes, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="values: expected finite"):
        GridSurrogate(axes, np.full((3, 4), np.nan))
    with pytest.raises(ValueError, match="placement_error: the robust objective"):
        GridSurrogate([np.linspace(0, 1, 3)], np.zeros(3), placement_error=0.002,
                      placement_samples=5)
    with pytest.raises(ValueError, match="placement_error and placement_samples go together"):
        GridSurrogate(axes, np.zeros((3, 4)), placement_samples=5)
    with pytest.raises(ValueError, match="parameters: expected 2 values"):
        GridSurrogate(axes, np.zeros((3, 4))).noiseless([0.5])
