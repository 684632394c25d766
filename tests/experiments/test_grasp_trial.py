"""Simulated grasp trials score what physics and geometry say they should."""

import pickle
import re

import numpy as np
import pytest

from handle_drake.experiments.grasp_trial import (
    NO_CONTACT,
    GraspTrial,
    GraspTrialConfig,
    placement_stencil,
)
from handle_drake.objects import KINDS


@pytest.fixture(scope="module")
def barrett_sphere():
    return GraspTrial(hand="barrett", object="sphere", space="offset")


def test_centred_barrett_grasp_of_a_sphere_is_in_force_closure(barrett_sphere):
    outcome = barrett_sphere.evaluate([0.0, 0.0])
    assert outcome.force_closure and outcome.metric > 0
    # All three fingers wrap the sphere.
    fingers = {name[:2] for name in outcome.contacts}
    assert {"f1", "f2", "f3"} <= fingers
    # Every contact lies on the sphere's surface (radius 3.5 cm) within the
    # penetration allowance, and its normal points to the centre.
    for contact in outcome.contacts.values():
        p, n = np.array(contact["p_O"]), np.array(contact["n_O"])
        assert np.linalg.norm(p) == pytest.approx(0.035, abs=2e-3)
        assert np.dot(n, -p / np.linalg.norm(p)) > 0.99


def test_hand_beside_the_object_touches_nothing(barrett_sphere):
    # 20 cm to the side, the closing fingers cannot reach a 7 cm sphere.
    trial = GraspTrial(hand="barrett", object="sphere", space="offset", offset_range=0.3)
    outcome = trial.evaluate([0.2, 0.2])
    assert outcome.metric == NO_CONTACT and not outcome.contacts and not outcome.touched


def test_trials_are_deterministic_and_reset_fully(barrett_sphere):
    a = barrett_sphere.evaluate([0.01, -0.02]).metric
    barrett_sphere.evaluate([0.03, 0.03])
    b = barrett_sphere.evaluate([0.01, -0.02]).metric
    assert a == b


def test_noise_is_gaussian_with_the_configured_std_and_seeded():
    trial = GraspTrial(hand="barrett", object="sphere", space="offset", noise=0.05)
    outcomes = [trial.evaluate([0.0, 0.0], seed=s) for s in range(12)]
    clean = outcomes[0].metric_noiseless
    noise = np.array([o.metric - clean for o in outcomes])
    assert all(o.metric_noiseless == clean for o in outcomes)
    assert 0.02 < noise.std() < 0.09
    assert trial.evaluate([0.0, 0.0], seed=3).metric == outcomes[3].metric


def test_metric_is_the_mean_over_the_hold_and_ends_at_the_settle_time():
    """The hold samples are instants of one simulation: its last one is exactly
    the single-snapshot metric at settle time, and the metric is their mean."""
    x = [0.005, -0.009]
    held = GraspTrial(hand="barrett", object="cuboid", space="offset", hold_samples=5)
    snapshot = GraspTrial(hand="barrett", object="cuboid", space="offset", hold_samples=1)
    outcome = held.evaluate(x)
    assert len(outcome.metric_samples) == 5
    assert outcome.metric_noiseless == pytest.approx(np.mean(outcome.metric_samples), abs=1e-12)
    assert outcome.metric_samples[-1] == snapshot.evaluate(x).metric_noiseless
    # A settled cuboid grasp: every instant in closure, values within the
    # spread of a pad's point contact hopping between patch corners.
    assert min(outcome.metric_samples) > 0
    assert np.ptp(outcome.metric_samples) < 0.25


def test_standoff_too_large_loses_the_grasp():
    trial = GraspTrial(hand="barrett", object="sphere", space="standoff")
    near, far = trial.evaluate([0.0]), trial.evaluate([0.11])
    assert near.force_closure
    assert not far.force_closure and far.metric < near.metric


def test_trial_is_an_objective_for_the_trial_runner(tmp_path):
    from handle_drake.learning import InlineExecutor, TrialLog, run_experiment

    trial = GraspTrial(hand="barrett", object="sphere", space="offset")
    result = run_experiment(trial, trial.bounds, strategy="random", n_trials=3, seed=1,
                            db_path=tmp_path / "t.sqlite", executor=InlineExecutor(),
                            progress=False, objective_name=trial.name)
    assert result.n_done == 3
    with TrialLog(tmp_path / "t.sqlite") as log:
        rows = log.trials(result.run_id)
    assert len(rows) == 3
    for row in rows:
        # Every trial is stored with its full scenario and contacts, and its
        # metric replays from the stored parameters.
        assert "kind: sphere" in row.scenario and "fixed: true" in row.scenario
        assert isinstance(row.contacts["force_closure"], bool)
        assert trial.evaluate(row.parameters).metric == pytest.approx(row.metric, abs=1e-12)


def test_a_logged_trial_replays_to_its_metric_through_simulate(tmp_path, capsys):
    """The logged scenario alone is the trial: ``handle-drake simulate`` on it (a fresh
    diagram built from the text) scores exactly the logged noiseless metric."""
    from handle_drake.cli import main
    from handle_drake.learning import InlineExecutor, TrialLog, run_experiment
    from handle_drake.run import ScenarioRunner
    from handle_drake.scenario import LoadScenario

    trial = GraspTrial(hand="barrett", object="cuboid", space="offset", noise=0.05)
    result = run_experiment(trial, trial.bounds, strategy="random", n_trials=2, seed=4,
                            db_path=tmp_path / "t.sqlite", executor=InlineExecutor(),
                            progress=False, objective_name=trial.name)
    with TrialLog(tmp_path / "t.sqlite") as log:
        rows = log.trials(result.run_id)
    for k, row in enumerate(rows):
        path = tmp_path / f"trial{k}.yaml"
        path.write_text(row.scenario)
        noiseless = row.contacts["metric_noiseless"]
        assert row.metric != noiseless  # the logged metric has the noise on top
        score = ScenarioRunner(LoadScenario(filename=path)).run().score
        assert score.value == noiseless
        assert score.force_closure == row.contacts["force_closure"]
        assert main(["simulate", str(path)]) == 0
        assert f"{noiseless!r}" in capsys.readouterr().out


def test_a_trial_logged_with_the_old_plant_keys_replays_to_the_same_metric(barrett_sphere):
    """Logs written before plant_config (top-level contact_model/time_step/
    contact_approximation) still replay, bit for bit, to what the trial scores now."""
    import re

    from handle_drake.run import ScenarioRunner
    from handle_drake.scenario import LoadScenario
    from handle_drake.scenario_checks import ScenarioDeprecationWarning

    x = [0.004, -0.012]
    text = barrett_sphere.scenario_for(x)
    old, n = re.subn(r"plant_config:\n(  .*\n)+", "contact_model: point\ntime_step: 0.002\n"
                     "contact_approximation: sap\n", text)
    assert n == 1 and "plant_config" not in old
    with pytest.warns(ScenarioDeprecationWarning, match="plant_config.time_step"):
        scenario = LoadScenario(data=old)
    assert repr(scenario) == repr(LoadScenario(data=text))
    score = ScenarioRunner(scenario).run().score
    assert score.value == barrett_sphere.evaluate(x).metric_noiseless


def test_a_runner_refuses_a_scenario_it_was_not_built_for(barrett_sphere):
    from handle_drake.run import ScenarioRunner

    runner = ScenarioRunner(barrett_sphere.base_scenario())
    other = GraspTrial(hand="barrett", object="mug", space="offset").scenario([0.0, 0.0])
    with pytest.raises(ValueError, match="built for another scenario"):
        runner.run(scenario=other)


def test_trial_pickles_without_its_diagram(barrett_sphere):
    barrett_sphere.evaluate([0.0, 0.0])
    clone = pickle.loads(pickle.dumps(barrett_sphere))
    assert clone.config == barrett_sphere.config
    assert clone.evaluate([0.0, 0.0]).metric == barrett_sphere.evaluate([0.0, 0.0]).metric


@pytest.mark.parametrize("kind", KINDS)
def test_every_object_gives_a_finite_metric(kind):
    outcome = GraspTrial(hand="barrett", object=kind, space="offset").evaluate([0.0, 0.0])
    assert np.isfinite(outcome.metric) and "object:" in outcome.scenario


def test_shadow_synergy_space_runs():
    trial = GraspTrial(hand="shadow", object="cuboid", space="synergy")
    assert trial.dims == 2
    assert np.isfinite(trial.evaluate([0.5, -0.5]).metric)


def test_shadow_synergy_trial_is_scored_after_the_hand_has_settled():
    """Full thumb and index/middle abduction is the slowest closing seen (the
    grasp completes at about 1.1 s): over the scored hold the metric only
    flickers (pad contacts on the cuboid's faces), and it is a force-closure
    grasp, not the half-closed hand a 0.7 s snapshot saw (0.04)."""
    trial = GraspTrial(hand="shadow", object="cuboid", space="synergy")
    outcome = trial.evaluate([1.0, 1.0])
    assert np.ptp(outcome.metric_samples) < 0.05
    assert outcome.force_closure and outcome.metric > 0.15


@pytest.mark.parametrize("kwargs, word", [
    (dict(hand="allegro"), "allegro"),
    (dict(object="teapot"), "teapot"),
    (dict(space="joint"), "space"),
    (dict(space="synergy", hand="barrett"), "shadow"),
    (dict(noise=-1.0), "noise"),
    (dict(mu=float("nan")), "mu"),
    (dict(hold_samples=0), "hold_samples"),
    (dict(hold_samples=2.5), "hold_samples"),
    (dict(hold_window=0.0), "hold_window"),
    (dict(hold_window=0.7), "hold_window"),
    (dict(placement_error=-0.002, placement_samples=5), "placement_error"),
    (dict(placement_error=0.2, placement_samples=5), "placement_error"),
    (dict(placement_error=0.002), "placement_samples"),
    (dict(placement_error=0.002, placement_samples=0), "placement_samples"),
    (dict(placement_samples=5), "placement_error"),
])
def test_bad_configuration_is_named(kwargs, word):
    with pytest.raises(ValueError, match=word):
        GraspTrialConfig(**kwargs)


def test_bad_parameters_are_named(barrett_sphere):
    with pytest.raises(ValueError, match="expected 2 values"):
        barrett_sphere.evaluate([0.0])
    with pytest.raises(ValueError, match="finite"):
        barrett_sphere.evaluate([np.nan, 0.0])


@pytest.mark.parametrize("samples", [2, 5, 16])
def test_placement_stencil_has_the_moments_of_the_uniform_disc(samples):
    e = 0.002
    points = placement_stencil(e, samples)
    r = np.linalg.norm(points, axis=1)
    assert points.shape == (samples, 2) and np.all(r <= e)
    # Uniform on the disc of radius e: E[r^2] = e^2 / 2 (exact for the sunflower radii).
    assert np.mean(r ** 2) == pytest.approx(e ** 2 / 2, rel=1e-12)
    assert len({tuple(p) for p in np.round(points, 12)}) == samples
    assert np.array_equal(placement_stencil(0.0, 1), np.zeros((1, 2)))


def test_robust_metric_is_the_mean_over_placed_trials(barrett_sphere):
    """In the offset space a placement error is an offset: the robust metric at x
    equals the mean of nominal trials at x + each stencil point."""
    e, k = 0.004, 3
    robust = GraspTrial(hand="barrett", object="sphere", space="offset", placement_error=e,
                        placement_samples=k)
    x = np.array([0.012, -0.006])
    nominal = [barrett_sphere.evaluate(x + d).metric_noiseless for d in placement_stencil(e, k)]
    outcome = robust.evaluate(x)
    assert outcome.metric_noiseless == pytest.approx(np.mean(nominal), abs=1e-9)
    assert "metric.placements holds the 3 start placements" in outcome.scenario
    assert robust.name == "barrett-sphere-offset-robust4mm3"


def test_a_robust_trials_stored_scenario_replays_its_logged_metric(tmp_path, capsys):
    """The trial's stored scenario holds all its placements (metric.placements): ``handle-drake
    simulate`` on it runs each and reports their mean, the trial's noiseless metric (it
    held placement 1 of K, whose metric alone was off the logged one)."""
    from handle_drake.cli import main
    from handle_drake.scenario import LoadScenario

    e, k = 0.004, 3
    robust = GraspTrial(hand="barrett", object="sphere", space="offset", placement_error=e,
                        placement_samples=k, noise=0.01)
    x = np.array([0.012, -0.006])
    result = robust(x, seed=5)  # what run_experiment logs: metric (noisy), scenario
    logged = result.contacts["metric_noiseless"]
    assert result.metric != logged  # the log's metric carries the noise; the replay has none
    scenario = LoadScenario(data=result.scenario)
    np.testing.assert_array_equal(scenario.metric.placements, placement_stencil(e, k))
    path = tmp_path / "trial.yaml"
    path.write_text(result.scenario)
    assert main(["simulate", str(path)]) == 0
    out = capsys.readouterr().out
    replayed = float(re.search(r"grasp metric \(.*each: ([^)]*)\): ([^ ]+)", out)[2])
    assert replayed == logged, out
    each = [float(v) for v in re.search(r"each: ([^)]*)\)", out)[1].split(", ")]
    assert len(each) == k and np.mean(each) == pytest.approx(logged, abs=1e-6)
    # the placements differ: one of them alone is not the trial's metric
    assert max(each) - min(each) > 1e-4


def test_bad_placements_are_named(barrett_sphere, tmp_path):
    from handle_drake.scenario import LoadScenario, ScenarioError

    path = tmp_path / "trial.yaml"
    path.write_text(barrett_sphere.scenario_for([0.0, 0.0]))
    assert LoadScenario(filename=path, data="metric: {placements: [[0.001, 0.0]]}")
    for bad in ("[[0.1, 0.0]]", "[[0.001]]", "[[.nan, 0.0]]"):
        with pytest.raises(ScenarioError, match=r"metric.placements\[0\]"):
            LoadScenario(filename=path, data=f"metric: {{placements: {bad}}}")
    with pytest.raises(ScenarioError, match="GuardedGraspController"):
        LoadScenario(filename=path, data="controller: null\nmetric: {placements: [[0, 0]]}")
