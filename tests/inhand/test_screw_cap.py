"""The screw cap (report Fig. 32): physics of the task, the encoder score, the logged scenario."""

import numpy as np
import pytest

from handle_drake.apps.inhand.screw_cap import (
    FOUR_FINGER_GRIP,
    FOUR_FINGER_TURN,
    ONE_GAIT,
    REGRASP_GAITS,
    TWO_STROKES,
    GaitMotionSource,
    ScrewCapScenario,
    ScrewCapTask,
    ScrewCapTrial,
    contact_forces,
    contact_summary,
    four_finger_turn_motion,
    simulate_scenario,
)

ONE_COUNT_DEG = 360.0 / 4096


@pytest.fixture(scope="module")
def trial():
    return ScrewCapTrial(ScrewCapTask(**ONE_GAIT))


def _stroke(trial, j3=1.0, j2=0.9):
    """Hand-written: the three fingers' flex strokes at J3 j3, J2 j2 rad; no release, thumb
    still; the demonstration's start times."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        x[sl][1:] = [j3, j2] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    return x


def test_the_grasp_is_the_demonstrations_first_frame_with_rule_3(trial):
    q0 = dict(zip(trial.scenario().initial_position, trial.scenario().initial_position.values(),
                  strict=True))
    # rule 3: the thumb-index abduction drives both thumb abduction joints
    assert q0["THJ4"] == pytest.approx(0.61, abs=0.02)
    assert q0["THJ3"] == pytest.approx(0.21, abs=0.02)  # clipped to THJ3's range
    assert q0["FFJ3"] == pytest.approx(0.35, abs=0.03)
    # the gist: thumb, first, middle, ring flex then release (8 meta motions, eq. 45: 26)
    assert [m.finger for m in trial.gist.motions] == ["TH", "FF", "MF", "RF", "FF", "TH",
                                                      "MF", "RF"]
    assert trial.dimension == 26 and trial.target_score == 28


def test_the_four_finger_grip_touches_the_cap_with_thumb_and_three_fingers():
    # report 5.7: "the four fingers tightly grip the screwcap"; read from the plant's contact
    # results in the settled state (rule 3's thumb abductions kept)
    trial = ScrewCapTrial(ScrewCapTask(**FOUR_FINGER_GRIP))
    q0 = trial.scenario().initial_position
    assert q0["THJ4"] == pytest.approx(0.61, abs=0.02)
    assert q0["THJ3"] == pytest.approx(0.21, abs=0.02)
    built = trial._build()
    plant = built["plant"]
    summary = contact_summary(plant, plant.GetMyContextFromRoot(built["settled"]), built)
    assert {"thdistal", "ffdistal", "mfdistal", "rfdistal"} <= set(summary["touching"])
    assert summary["palm_force"] == 0.0
    # the closure matters: from the first frame alone the thumb does not reach this cap
    alone = ScrewCapTrial(ScrewCapTask(**{**FOUR_FINGER_GRIP, "grasp_closure": ()}))._build()
    assert "thdistal" not in alone["gripped"]


def test_a_known_stroke_turns_the_cap_90_deg_read_from_the_joint(trial):
    outcome = trial.evaluate(_stroke(trial))
    # settled grasp: the fingers (not the palm) touch the cap; the cap is on its joint
    assert len([b for b in outcome.gripped_at_start if b.endswith("distal")]) >= 2
    assert outcome.completed and outcome.turn_deg >= 90.0 and not outcome.palm_touched
    # issue 45: the turn is the ring finger's, wedged between the cap and the welded bottle
    # (> 100 N on the bottle at some step): not turned by the fingers, not reached
    assert outcome.leaned_on_welded and "rfdistal" in outcome.welded_bodies
    assert not outcome.reached_target
    assert outcome.score < trial.target_score
    # the encoder reads the joint within one count, at every sample
    assert abs(outcome.turn_deg - outcome.turn_deg_truth) <= ONE_COUNT_DEG / 2 + 1e-9
    # the logged scenario is whole: re-simulated alone (own build, reads the plant)
    result = trial(_stroke(trial))
    scenario = ScrewCapScenario.load(result.scenario)
    np.testing.assert_allclose(scenario.parameters, _stroke(trial))
    again = simulate_scenario(result.scenario)
    assert again["turn_deg"] == pytest.approx(outcome.turn_deg_truth, abs=0.5)
    assert again["palm_force_max"] == 0.0


def test_the_demonstrations_own_parameters_and_a_still_hand_do_not_reach_it(trial):
    still = _stroke(trial, 0.0, 0.0)
    rest = trial.evaluate(still, early_stop=False)
    assert abs(rest.turn_deg) < 3.0 and not rest.reached_target
    assert rest.score < trial.target_score
    demo = trial.evaluate(trial.gist.initial_parameters(), early_stop=False)
    assert demo.turn_deg < 90.0 and not demo.reached_target


def test_random_parameters_rarely_reach_the_target(trial):
    # the base rate (benchmarks/bench_screw_cap.py, 200 trials: docs/results/inhand.md);
    # here 8 uniformly random vectors: none may reach 90 deg
    rng = np.random.default_rng(35)
    b = trial.bounds
    reached = [trial.evaluate(b[:, 0] + rng.random(len(b)) * (b[:, 1] - b[:, 0])).reached_target
               for _ in range(8)]
    assert sum(reached) == 0


def test_the_fast_trial_scores_as_the_python_driver_with_contact_results_every_sample(
        trial, fingertip):
    # the trial plays the driver's rate-limited commands planned before it runs and reads
    # the touching bodies from the geometry query; the reference runs the Python driver
    # every step and reads the contact results every sample: the same trial, to 1e-9
    rng = np.random.default_rng(7)
    b = trial.bounds
    for t, x in [(trial, _stroke(trial)), (trial, trial.gist.initial_parameters()),
                 (trial, b[:, 0] + rng.random(len(b)) * (b[:, 1] - b[:, 0])),
                 (fingertip, _stroke(fingertip))]:
        fast = t.evaluate(x, early_stop=False).as_dict()
        ref = t.evaluate(x, early_stop=False, driver=True, contact_results=True).as_dict()
        assert fast["score"] == pytest.approx(ref["score"], abs=1e-9)
        np.testing.assert_allclose(fast["turn_deg_series"], ref["turn_deg_series"], atol=1e-9)
        assert fast["turn_deg_truth"] == pytest.approx(ref["turn_deg_truth"], abs=1e-9)
        assert fast["contacts"] == ref["contacts"]
        assert (fast["reached_target"], fast["palm_force_max"], fast["survived_reversal"]) == \
            (ref["reached_target"], ref["palm_force_max"], ref["survived_reversal"])
    # the trial runs on the station; the reference is the module's own diagram
    assert "trial" in trial._built and trial._reference_build["planned"] is None


def _gait(trial, release):
    """The stroke (J3 1.0, J2 0.9 on the three fingers) and, at the demonstrated release
    times, the release ``(J3, J2)`` magnitudes; thumb still. A gist parameter vector."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        x[sl][1:] = 0.0 if m.finger == "TH" else ([1.0, 0.9] if m.variation[0] > 0
                                                  else release)
    assert np.all((x >= trial.bounds[:, 0]) & (x <= trial.bounds[:, 1]))
    return x


def test_repeated_gaits_with_a_release_that_clears_the_cap_turn_it_360_deg():
    trial = ScrewCapTrial(ScrewCapTask(**REGRASP_GAITS))
    n = trial.config.n_gaits
    # the release drops each finger 0.6 rad (J3) below its grasp, J2 still flexed: it
    # leaves the cap; the next gait's first frame closes it again (regrasp)
    cleared = trial.evaluate(_gait(trial, [1.6, 0.0]), early_stop=False)
    t, turn = np.array(cleared.times), np.array(cleared.turn_deg_series)
    assert cleared.turn_deg >= 360.0 and not cleared.palm_touched
    per_gait = np.diff([0.0] + [turn[np.argmin(abs(t - k))] for k in range(1, n + 1)])
    assert np.all(per_gait[1:] > 30.0)  # every regrasp turns it on, not only the first
    # between the release and the regrasp no finger touches the cap, and the thread's
    # friction holds it: no turn back
    window = (t % 1.0 > 0.86) & (t % 1.0 < 0.99) & (t < n)
    assert not any(cleared.contacts[i] for i in np.flatnonzero(window))
    assert np.all(np.diff(turn)[window[1:]] >= -1e-9)
    # the same stroke without a release stalls (the fingers regrasp over the cap), and a
    # release back along the stroke's path drags it back while touching
    assert trial.evaluate(_gait(trial, [0.0, 0.0]), early_stop=False).turn_deg < 250.0
    back = trial.evaluate(_gait(trial, [1.0, 0.9]), early_stop=False)
    assert back.turn_deg < 250.0
    assert any(back.contacts[i] for i in np.flatnonzero(window))


def test_the_hand_written_regrasp_motion_reaches_its_target_score():
    # the cap sits on its thread joint (it cannot fall): over several gaits the final check
    # asks for a finger on the cap at the end of the last turn stroke, not after the last
    # release (which leaves the cap by design). Before: 3 of 4 checks, score below target.
    # (the welded bottle's rule switched off: this placement's fingers lean on it, issue 45,
    # tests/inhand/test_inhand_convergence.py; here the multi-gait touch rule alone)
    trial = ScrewCapTrial(ScrewCapTask(**REGRASP_GAITS, lean_force=1e6))
    x = _gait(trial, [1.6, 0.0])
    # the last gait's stroke ends where its last flexing finger (RF) starts its release
    rf_release = [m.start for m in trial.gist.motions if m.finger == "RF"][-1]
    assert trial.last_stroke_end(x) == pytest.approx(4.0 + rf_release)
    outcome = trial.evaluate(x)
    assert outcome.completed and outcome.checks_passed == trial.config.n_checks
    assert outcome.turn_deg >= 360.0 and not outcome.palm_touched
    assert outcome.reached_target and outcome.score >= trial.target_score
    # no finger touches the cap after the last release: the touch that counts is the stroke's
    assert not outcome.contacts[-1]
    # a still hand over the same gaits does not reach it
    still = trial.evaluate(trial.gist.initial_parameters() * _starts_only(trial))
    assert not still.reached_target and still.score < trial.target_score


def _starts_only(trial):
    """Mask keeping the start times of a gist vector (magnitudes 0): a still hand."""
    mask = np.zeros(trial.dimension)
    for sl in trial.gist.slices():
        mask[sl.start] = 1.0
    return mask


# pre-change scores (commit d84124f) of one-gait trials run to the end: the hand-written
# stroke, the demonstration's parameters, two uniformly random vectors (numpy seed 12)
_ONE_GAIT_SCORES = [28.99836993492961, 13.412228467987806, 26.551990386655937,
                    26.533315075516022]


def test_one_gait_scoring_is_unchanged_by_the_stroke_end_touch_rule():
    # the touch rule from the stroke's end applies to one gait too (issue 45: a turn past the
    # target is reached, tests/inhand/test_screw_cap_clear.py); these one-gait trials keep a
    # finger on the cap and score as before it
    trial = ScrewCapTrial(ScrewCapTask(**ONE_GAIT, lean_force=1e6))  # the welded bottle's rule off
    b = trial.bounds
    rng = np.random.default_rng(12)
    xs = [_stroke(trial), trial.gist.initial_parameters()] + [
        b[:, 0] + rng.random(len(b)) * (b[:, 1] - b[:, 0]) for _ in range(2)]
    scores = [trial.evaluate(x, early_stop=False).score for x in xs]
    np.testing.assert_allclose(scores, _ONE_GAIT_SCORES, rtol=0, atol=1e-12)


def test_gaits_repeat_the_frames(trial):
    source = GaitMotionSource(trial.gist, np.zeros(20), 1.0, 50, n_gaits=3)
    assert source.frame_index(0.0) == 1 and source.frame_index(0.99) == 50
    assert source.frame_index(1.0) == 1 and source.frame_index(2.5) == 26
    assert source.frame_index(3.2) == 50  # held after the last gait
    with pytest.raises(ValueError, match="n_gaits"):
        GaitMotionSource(trial.gist, np.zeros(20), 1.0, 50, n_gaits=0)


def test_frame_indices_are_frame_index_at_every_time(trial):
    # the planned commands' targets (one numpy pass) against the source's own per-time
    # index, at every 2 ms step and on every frame boundary (k duration / N, where the
    # 1e-9 guard decides), for one and several gaits
    for duration, n_gaits in ((1.0, 3), (0.6, 1), (1.2, 2)):
        source = GaitMotionSource(trial.gist, np.zeros(20), duration, 50, n_gaits=n_gaits)
        end = (n_gaits + 1) * duration
        times = np.r_[np.arange(int(end / 0.002) + 1) * 0.002,
                      np.arange(50 * (n_gaits + 1) + 1) * duration / 50]
        expected = [source.frame_index(float(t)) for t in times]
        np.testing.assert_array_equal(source.frame_indices(times), expected)


def test_planned_commands_hold_one_segment_per_change(trial):
    # equal consecutive commands share one zero-order-hold segment: the same value as a
    # segment per step at every step time (bit for bit), with fewer segments
    planned = trial._build(build="planned")["planned"]
    x = _stroke(trial)
    source = trial._build(build="planned")["source"]
    n = 601
    targets = source.frames_for(x)[source.frame_indices(np.arange(n) * planned.period) - 1]
    cmd = planned.commands(targets)
    trajectory = planned.trajectory(cmd)
    held = (cmd[1:] == cmd[:-1]).all(axis=1).sum()
    assert held > 100 and trajectory.get_number_of_segments() == len(cmd) - held
    for k in range(len(cmd) + 3):
        expected = cmd[min(k, len(cmd) - 1)][planned._order]
        value = trajectory.value(k * planned.period).ravel()
        np.testing.assert_array_equal(value[:20], expected)
        assert not value[20:].any()


def test_bad_settings():
    with pytest.raises(ValueError, match="target_deg"):
        ScrewCapTask(target_deg=-1)
    with pytest.raises(ValueError, match="n_gaits"):
        ScrewCapTask(n_gaits=0)
    with pytest.raises(ValueError, match="parameters"):
        ScrewCapTrial().evaluate(np.zeros(3))


@pytest.fixture(scope="module")
def fingertip():
    return ScrewCapTrial(ScrewCapTask(free=True, target_deg=60.0))


def test_the_fingertip_cylinder_is_held_by_the_fingers_and_survives_palm_down(fingertip):
    # a free cylinder pinched by thumb and fingers from the demonstration's first frame:
    # the palm does not touch it, and a known stroke turns it and keeps it through 0.5 s
    # of reversed weight (the hand palm down, for it)
    outcome = fingertip.evaluate(_stroke(fingertip), early_stop=False)
    assert "thdistal" in outcome.gripped_at_start
    assert any(b.startswith(("ff", "mf")) for b in outcome.gripped_at_start)
    assert not outcome.palm_touched and outcome.palm_weight_share == 0.0
    assert outcome.turn_deg >= 60.0 and outcome.survived_reversal is True
    assert outcome.reached_target and outcome.score >= fingertip.target_score
    # the demonstration's own motion releases the grip at the end: the reversed weight
    # pulls the cylinder out of the hand, so that trial does not count as held
    demo = fingertip.evaluate(fingertip.gist.initial_parameters(), early_stop=False)
    assert demo.survived_reversal is False and not demo.reached_target
    assert demo.score < fingertip.target_score
    # the reversal's samples are eq. 48 samples: all 1 for the stroke that holds; for the
    # demonstration's, graded as the cylinder slides out (1 at first, then the share
    # reverse_travel / travel while a finger touches, 0 once none does; measured: it
    # slides about 43 mm and stays touched)
    n = fingertip.config.reversal_sample_times().size
    assert outcome.reversal_credits == [1.0] * n
    graded = np.array(demo.reversal_credits)
    assert graded.size == n and graded[0] == 1.0 and graded[-1] < 1.0
    assert np.any((graded > 0) & (graded < 1))  # slid further than 10 mm, still touched


def test_the_fingertip_scenario_re_simulates_alone_with_its_palm_down_check(fingertip):
    x = _stroke(fingertip)
    outcome = fingertip.evaluate(x, early_stop=False)
    again = simulate_scenario(fingertip(x).scenario)
    assert again["turn_deg"] == pytest.approx(outcome.turn_deg, abs=1.0)
    assert again["survived_reversal"] is True and again["palm_force_max"] == 0.0


def test_cli_refuses_settings_the_finger_tasks_do_not_have(tmp_path, capsys):
    from handle_drake.cli import main as cli_main

    for extra in (["--accelerometer", "joywarrior24f14"], ["--evaluation", "old"]):
        rc = cli_main(["inhand", "--task", "screw_cap", "--db", str(tmp_path / "x.sqlite"),
                       *extra])
        assert rc == 2
        err = capsys.readouterr().err
        assert "--task screw_cap" in err and "Traceback" not in err


def test_new_settings_at_their_defaults_keep_logged_run_ids():
    # the run id hashes the task's settings: the grip's settings, added later, leave them
    # at their defaults, so logs written before still resume; set, they tell runs apart
    from handle_drake.apps.inhand.experiment import _config

    task = _config(ScrewCapTrial(ScrewCapTask()), "ipso", 10)["task"]
    assert not {"cap_diameter", "cap_axis_yaw_deg", "cap_length", "cap_axis_reversed",
                "grasp_closure", "grip_digits"} & set(task)
    grip = _config(ScrewCapTrial(ScrewCapTask(**FOUR_FINGER_GRIP)), "ipso", 10)["task"]
    assert grip["cap_diameter"] == 0.04 and len(grip["grasp_closure"]) == 4


def _run_to(trial, x, t):
    """The plant's context after ``t`` s of the trial with parameters ``x``."""
    built = trial._build()
    plant_context = trial._reset(built, x)
    built["simulator"].Initialize()
    built["simulator"].AdvanceTo(t)
    return built, plant_context


def test_contact_torques_balance_the_thread_while_the_cap_turns(trial):
    # the cap's balance about its axis (its inertia is 2e-6 kg m^2): while it turns steadily,
    # the hand's contact torques (contact_forces, from the plant's contact results) sum to
    # the thread's friction, Coulomb 0.01 N m + viscous 1e-3 N m s/rad * speed
    built, plant_context = _run_to(trial, _stroke(trial), 0.8)
    speed = built["joint"].get_angular_rate(plant_context)
    assert speed > 0.5  # turning the demonstrated way
    forces = contact_forces(built["plant"], plant_context, built)
    total = sum(torque for _, _, torque in forces.values())
    assert total == pytest.approx(0.01 + 1e-3 * speed, abs=2e-3)
    for normal, tangential, _ in forces.values():
        assert normal >= 0 and 0 <= tangential <= 1.0 * normal + 1e-6  # mu = 1


def test_a_reversed_axis_reads_the_same_motion_as_the_opposite_turn(trial):
    # the cap is a cylinder: turning its joint axis over changes nothing but the sign
    reversed_ = ScrewCapTrial(ScrewCapTask(**ONE_GAIT, cap_axis_reversed=True))
    forward = trial.evaluate(_stroke(trial), early_stop=False)
    backward = reversed_.evaluate(_stroke(reversed_), early_stop=False)
    assert backward.turn_deg_truth == pytest.approx(-forward.turn_deg_truth, abs=0.5)
    assert not backward.reached_target
    with pytest.raises(ValueError, match="cap_axis_reversed"):
        ScrewCapTask(cap_axis_reversed=1)
    with pytest.raises(ValueError, match="cap_length"):
        ScrewCapTask(cap_length=0.5)


@pytest.fixture(scope="module")
def four_finger():
    return ScrewCapTrial(ScrewCapTask(**FOUR_FINGER_TURN))


_DIGITS = ("thdistal", "ffdistal", "mfdistal", "rfdistal")


def test_the_four_finger_turn_grasp_holds_the_cap_with_thumb_and_three_fingers(four_finger):
    # settled from the demonstration's first frame (rule 3's thumb abductions kept) plus the
    # grasp closure; read from the plant's contact results
    q0 = four_finger.scenario().initial_position
    assert q0["THJ4"] == pytest.approx(0.61, abs=0.02)
    assert q0["THJ3"] == pytest.approx(0.21, abs=0.02)
    built = four_finger._build()
    plant = built["plant"]
    context = plant.GetMyContextFromRoot(built["settled"])
    forces = contact_forces(plant, context, built)
    assert set(forces) == set(_DIGITS)  # the distal phalanges, nothing else
    assert all(forces[b][0] > 1.0 for b in _DIGITS)  # each presses with more than 1 N
    assert contact_summary(plant, context, built)["palm_force"] == 0.0


def test_the_hand_written_motion_turns_the_cap_90_deg_with_four_digits_on_it(four_finger):
    x = four_finger_turn_motion(four_finger.gist)
    b = four_finger.bounds
    assert np.all((x >= b[:, 0]) & (x <= b[:, 1]))  # inside the gist's box
    outcome = four_finger.evaluate(x)
    # issue 45: this placement's fingers lean on the welded bottle (> 1 N): not reached
    assert outcome.leaned_on_welded and not outcome.reached_target
    assert outcome.completed and outcome.checks_passed == 4
    assert outcome.turn_deg >= 90.0 and not outcome.palm_touched
    assert abs(outcome.turn_deg - outcome.turn_deg_truth) <= ONE_COUNT_DEG / 2 + 1e-9
    # the part of the turn made while all four digits touched the cap (25 ms samples)
    step = np.diff(np.r_[0.0, outcome.turn_deg_series])
    four = np.array([set(_DIGITS) <= set(c) for c in outcome.contacts])
    assert step[four].sum() >= 60.0
    # the logged scenario re-simulates alone (own build, reads the plant's joint)
    again = simulate_scenario(four_finger(x).scenario)
    assert again["turn_deg"] == pytest.approx(outcome.turn_deg_truth, abs=0.5)
    assert again["palm_force_max"] == 0.0


def test_in_the_four_finger_turn_first_and_middle_finger_drive_and_the_ring_brakes(
        four_finger):
    # contact torques about the cap's axis over the stroke (0.3-0.9 s, every 50 ms): the
    # first and middle fingers' J2 flexion drags the cap round (torque of the turn's sign),
    # the ring finger holds against it; the thumb stays on the cap (at >= 80 % of the
    # samples; its torque changes sign: measured + to 0.6 s, - after); no contact beyond
    # friction's mu = 1
    built = four_finger._build()
    plant_context = four_finger._reset(built, four_finger_turn_motion(four_finger.gist))
    simulator = built["simulator"]
    simulator.Initialize()
    torque, thumb_on, times = dict.fromkeys(_DIGITS, 0.0), 0, np.arange(0.3, 0.91, 0.05)
    for t in times:
        simulator.AdvanceTo(t)
        forces = contact_forces(built["plant"], plant_context, built)
        thumb_on += "thdistal" in forces
        for body, (normal, tangential, tau) in forces.items():
            assert tangential <= normal + 1e-6
            if body in torque:
                torque[body] += tau
    assert torque["ffdistal"] > 0 and torque["mfdistal"] > 0 and torque["rfdistal"] < 0
    assert thumb_on >= 0.8 * times.size


def test_from_the_four_finger_grasp_the_demonstration_and_a_still_hand_do_not_turn_it(
        four_finger):
    still = four_finger.evaluate(four_finger.gist.initial_parameters() * _starts_only(
        four_finger), early_stop=False)
    # measured 5.2 deg: the squeezed grasp still creeps after the 0.5 s settling
    assert abs(still.turn_deg) < 10.0 and not still.reached_target
    demo = four_finger.evaluate(four_finger.gist.initial_parameters(), early_stop=False)
    assert demo.turn_deg < 90.0 and not demo.reached_target
    assert demo.score < four_finger.target_score


def test_cli_runs_the_four_finger_turn_placement_and_refuses_it_elsewhere(tmp_path, capsys):
    from handle_drake.cli import main as cli_main
    from handle_drake.learning.log import TrialLog

    rc = cli_main(["inhand", "--task", "cylinder_rotation", "--placement", "four-finger-turn",
                   "--db", str(tmp_path / "x.sqlite")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--placement four-finger-turn" in err and "Traceback" not in err
    for bad in (["--task", "cylinder_rotation", "--grip-digits", "4"],
                ["--task", "screw_cap", "--grip-digits", "6"]):
        assert cli_main(["inhand", *bad, "--db", str(tmp_path / "x.sqlite")]) == 2
        err = capsys.readouterr().err
        assert "--grip-digits" in err and "Traceback" not in err
    db = tmp_path / "cap.sqlite"
    rc = cli_main(["inhand", "--task", "screw_cap", "--placement", "four-finger-turn",
                   "--optimizer", "random", "--trials", "1", "--particles", "1", "--no-plot",
                   "--no-html", "--no-progress", "--db", str(db)])
    assert rc == 0
    with TrialLog(db) as log:
        (info,) = log.runs()
        task = info.config["task"]
        (record,) = [r for r in log.trials(info.run_id) if r.status == "done"]
    # (settings at their defaults, as the 35 mm diameter, are left out of the run's config)
    assert list(task["cap_position"]) == [0.365, -0.02, 0.058] and task["cap_length"] == 0.07
    assert [list(c) for c in task["grasp_closure"]] == [list(c) for c in
                                                        FOUR_FINGER_TURN["grasp_closure"]]
    assert set(_DIGITS) <= set(record.contacts["gripped_at_start"])


# draw 44 (index 43) of the four-finger-turn base rate (seed 1000): it reaches the target as
# first scored, turning the cap 138 deg, but only 1 deg of it with all four digits on the cap
_DRAW_43 = [0.6498555341862423, 0.35181051050634626, 0.3685449687555527, 0.16518461721030175,
            0.9410103707691737, 1.7790256167322065, 1.2511512087574406, 0.5219775479466948,
            0.04016449611999835, 0.7083958933826481, 0.7317347402487742, 0.29232415171433623,
            1.5289507485412044, 0.0691399762180609, 1.215894490858605, 1.178916155005173,
            0.5869131111523996, 1.9047745259991646, 0.76672785201425, 0.339317458465269,
            0.9130855186580884, 0.8285882156964999, 0.5887929333215602, 0.003571537752446563,
            0.9168033987160289, 0.35974235056626386]


def test_grip_digits_refuses_a_turn_made_after_the_grip_was_given_up():
    # the welded bottle's rule off (this placement leans on it, issue 45): grip_digits alone
    four_finger = ScrewCapTrial(ScrewCapTask(**FOUR_FINGER_TURN, lean_force=1e6))
    loose = four_finger.evaluate(_DRAW_43)  # grip_digits 1: any finger within 0.3 s
    assert loose.reached_target and loose.turn_deg >= 90.0
    strict = ScrewCapTrial(ScrewCapTask(**FOUR_FINGER_TURN, grip_digits=4, lean_force=1e6))
    refused = strict.evaluate(_DRAW_43)
    assert not refused.reached_target and refused.score < strict.target_score
    # the hand-written motion keeps all four digits on the cap at every check
    assert strict.evaluate(four_finger_turn_motion(strict.gist)).reached_target
    with pytest.raises(ValueError, match="grip_digits"):
        ScrewCapTask(grip_digits=0)


@pytest.fixture(scope="module")
def two_strokes():
    return ScrewCapTrial(ScrewCapTask(**TWO_STROKES))


def _strokes(trial, first=(0.6, 0.6), second=(0.6, 0.6)):
    """Hand-written: per stroke the three fingers' flex at (J3, J2) rad; no release, thumb
    still; the demonstration's start times."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        flex = m.finger != "TH" and m.variation[0] > 0
        x[sl][1:] = (first if m.start < 0.5 else second) if flex else 0.0
    return x


def test_two_strokes_each_its_own_parameters_checked_while_held(two_strokes):
    # the demonstration's gist twice in sequence, each stroke its own 26 parameters, its
    # start times bounded to its own half; 4 parts of 13 (a stroke's flex, its release)
    t = two_strokes
    assert t.dimension == 52 and t.target_score == 54
    np.testing.assert_array_equal(t.dims_per_part, [13, 13, 13, 13])
    starts = np.array([sl.start for sl in t.gist.slices()])
    first = np.array([m.start < 0.5 for m in t.gist.motions])
    assert np.all(t.bounds[starts[first]] == [0.0, 0.5])
    assert np.all(t.bounds[starts[~first]] == [0.5, 1.0])
    assert np.all((t.bounds[:, 0] <= t.gist.initial_parameters())
                  & (t.gist.initial_parameters() <= t.bounds[:, 1]))


def test_two_hand_written_strokes_turn_it_held_by_the_fingers(two_strokes):
    # issue 45: on the converged physics (TWO_STROKES: Menagerie's limits, a 3 kN/m pad, no
    # near-rigid softening) the hand-written strokes turn it 65.6 deg at 2 ms (64.2, 62.7
    # at 1, 0.5 ms): short of the 100 deg target (before: 118.1, on a contact whose
    # compliance the 2 ms step set)
    t = two_strokes
    assert t.config.effort_limits == "menagerie" and t.config.free_near_rigid_threshold == 0
    both = t.evaluate(_strokes(t), early_stop=False)
    # held by the fingers: the palm never touches it, carries none of its weight, and it
    # stays in the hand through 0.5 s of reversed weight
    assert {"thdistal", "ffdistal"} <= set(both.gripped_at_start)
    assert not both.palm_touched and both.palm_force_max == 0.0
    assert both.palm_weight_share == 0.0 and both.survived_reversal is True
    assert 55.0 <= both.turn_deg < 80.0 and not both.reached_target
    # the turn needs both strokes: the first alone turns it about 21 deg, held
    one = t.evaluate(_strokes(t, second=(0.0, 0.0)), early_stop=False)
    assert 10.0 <= one.turn_deg < 30.0 and one.survived_reversal is True
    assert both.turn_deg > 2 * one.turn_deg
    # re-simulated from its logged scenario alone (its own build; reads the plant)
    again = simulate_scenario(t(_strokes(t)).scenario)
    assert again["turn_deg"] == pytest.approx(both.turn_deg, abs=1.0)
    assert again["survived_reversal"] is True and again["palm_force_max"] == 0.0


def _stroke_release(trial, j3, j2, thumb_release=0.0):
    """:func:`_stroke`, with the thumb's release at ``thumb_release`` x the demonstration's."""
    x = _stroke(trial, j3, j2)
    for m, sl in zip(trial.gist.motions, trial.gist.slices(), strict=True):
        if m.finger == "TH" and m.variation[0] < 0:
            x[sl][1:] = np.abs(m.variation) * thumb_release
    return x


def test_held_turn_ranks_a_cylinder_lost_below_a_smaller_turn_held():
    # both from the physics (the 60 deg task, early stop on, as a run scores them): a
    # far flex turns the cylinder 139 deg and passes all four checks, then the thumb's half
    # release lets the reversed weight pull it out; a smaller flex turns it 56 deg and holds
    lost_x, held_x = _stroke_release(ScrewCapTrial(), 1.4, 1.3, 0.5), _stroke(
        ScrewCapTrial(), 0.6, 0.54)
    scores = {}
    for held_turn in (False, True):
        t = ScrewCapTrial(ScrewCapTask(free=True, target_deg=60.0, held_turn=held_turn))
        lost, held = t.evaluate(lost_x), t.evaluate(held_x)
        assert lost.turn_deg > 2 * held.turn_deg > 100.0
        assert not lost.reached_target and not held.reached_target
        scores[held_turn] = lost, held
    lost, held = scores[True]
    assert lost.survived_reversal is False and held.survived_reversal is True
    assert lost.score < held.score
    # the turn counts only while held: none of the lost one's motion samples match; the
    # reversal's samples keep their graded credit, and its last check fails
    n = ScrewCapTask().sample_times().size
    assert lost.checks_passed == 3 and lost.s_a == pytest.approx(
        sum(lost.reversal_credits) / (n + len(lost.reversal_credits)))
    # the published score (held_turn off) ranked them the other way round: the defect
    old_lost, old_held = scores[False]
    assert old_lost.checks_passed == 4 and old_lost.score > old_held.score
    # held_turn asks for the free cylinder (a cap on its joint cannot be lost)
    with pytest.raises(ValueError, match="held_turn"):
        ScrewCapTask(held_turn=True)


def test_cli_runs_the_two_strokes_target_and_refuses_strokes_elsewhere(tmp_path, capsys):
    from handle_drake.cli import main as cli_main

    db = tmp_path / "t.sqlite"
    # the default: the two strokes (the learning task), as with --strokes 2 (the same run)
    for strokes in ([], ["--strokes", "2"]):
        rc = cli_main(["inhand", "--task", "fingertip_cylinder", *strokes, "--trials", "1",
                       "--optimizer", "random", "--db", str(db), "--no-plot", "--no-html",
                       "--no-progress"])
        assert rc == 0
    from handle_drake.learning.log import TrialLog

    with TrialLog(db) as log:
        (info,) = log.runs()
        assert "100deg" in info.run_id and "2strokes" in info.run_id
        assert len(info.bounds) == 52
    # --strokes 1: the 60 deg pinch in one stroke, another run
    rc = cli_main(["inhand", "--task", "fingertip_cylinder", "--strokes", "1", "--trials", "1",
                   "--optimizer", "random", "--db", str(db), "--no-plot", "--no-html",
                   "--no-progress"])
    assert rc == 0
    with TrialLog(db) as log:
        pinch = [r for r in log.runs() if r.run_id != info.run_id]
        assert len(pinch) == 1 and "60deg" in pinch[0].run_id and len(pinch[0].bounds) == 26
    capsys.readouterr()
    rc = cli_main(["inhand", "--task", "screw_cap", "--strokes", "2", "--db", str(db)])
    err = capsys.readouterr().err
    assert rc == 2 and "--strokes" in err and "Traceback" not in err
