"""--accelerometer (issue 35 item 3): the cylinder's score from the instrumented object's
own roll estimate, the plant's rotation logged beside it."""

import numpy as np

from handle_drake.apps.inhand.task import InHandTask, InHandTrial
from handle_drake.devices.accelerometer.profiles import get_profile


def _stroke(trial):
    """The hand-written stroke of test_inhand_task: J3 1.0, J2 0.9 on the three fingers."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        x[sl][1:] = [1.0, 0.9] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    return x


# The device against the plant, measured at 2 ms (the palm-up cylinder's step before issue
# 45; its converged default is 0.5 ms, where the device was not re-examined)
STEP = 0.002


def test_the_score_reads_the_accelerometer_and_agrees_with_the_plant_at_rest():
    trial = InHandTrial(InHandTask(accelerometer="joywarrior24f14", time_step=STEP))
    c = trial.config
    outcome = trial.evaluate(_stroke(trial), early_stop=False)
    t = np.array(outcome.times)
    sensed = np.array(outcome.accelerometer_rotation_deg_series)
    truth = np.array(outcome.rotation_deg_series)
    benchmark = np.degrees(c.benchmark_at(t)) - c.tolerance_deg
    # eq. 48 recomputed from the sensor's series alone gives the score's S_a; from the
    # plant's it would not (the estimate lags and overshoots while the cylinder rolls)
    assert outcome.s_a == np.mean(sensed >= benchmark)
    assert np.mean(truth >= benchmark) != outcome.s_a
    assert outcome.reached_target and outcome.checks_passed == c.n_checks
    assert outcome.score == trial.dims_per_part.sum() + outcome.s_a + 2.0
    # at rest (after the motion) the two agree within the device's accuracy: a tilt
    # estimate off by at most asin(3 sigma of bias + 3 sigma of noise) (JoyWarrior:
    # 15 mg + 3.6 mg, 1.07 deg)
    p = get_profile("joywarrior24f14")
    accuracy = np.degrees(np.arcsin(3 * p.bias_std_g + 3 * p.noise_std_g))
    rest = t >= c.motion_duration - 0.15
    assert np.abs(sensed[rest] - truth[rest]).max() <= accuracy
    assert truth[-1] >= c.target_deg  # the plant agrees that the target was reached


def test_held_is_the_instrumented_objects_own_a_fall_flagged_by_its_accelerometer():
    # "held" in --accelerometer mode: the instrument never flagged a free fall (report 2.4);
    # the plant's held is logged beside it (held_truth)
    from pydrake.math import RigidTransform

    trial = InHandTrial(InHandTask(accelerometer="joywarrior24f14", time_step=STEP))
    held = trial.evaluate(_stroke(trial), early_stop=False)
    assert held.held and held.held_truth and held.reached_target
    # the same trial from the settled grasp with the object lifted 10 cm: it falls for
    # ~0.14 s (> the estimator's 24 ms below 0.3 g) before it lands in the hand
    built = trial._build()
    plant, settled = built["harness"].plant, built["settled"]
    lifted = settled.Clone()
    lifted_plant = plant.GetMyMutableContextFromRoot(lifted)
    X = plant.EvalBodyPoseInWorld(lifted_plant, built["body"])
    plant.SetFreeBodyPose(lifted_plant, built["body"],
                          RigidTransform(X.rotation(), X.translation() + [0, 0, 0.10]))
    built["settled"] = lifted
    try:
        dropped = trial.evaluate(_stroke(trial), early_stop=False)
    finally:
        built["settled"] = settled
    assert not dropped.held and not dropped.reached_target
    # the instrument knows at the first sample (50 ms: 24 ms below 0.3 g done), before the
    # object has fallen the plant's 15 mm (55 ms): never held, where the plant's held
    # would have lasted to that sample
    assert dropped.held_time == 0.0
    # the plant agrees: it fell more than the 15 mm the plant's held allows
    assert dropped.held_truth is False
    again = trial.evaluate(_stroke(trial), early_stop=False)  # the settled grasp restored
    assert again.held and again.score == held.score
