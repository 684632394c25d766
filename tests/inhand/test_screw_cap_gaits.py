"""Issue 45 item 5: the screw cap's several-gait task (``clear-gaits``): one gait whose
parameters are learned, repeated ``n_gaits`` times (a task setting), so the search space
stays one gait's."""

import argparse

import numpy as np
import pytest

from handle_drake.apps.inhand.screw_cap import (
    CLEAR,
    CLEAR_GAITS,
    PLACEMENTS,
    ScrewCapTask,
    ScrewCapTrial,
    build_screw_cap,
)


def test_the_several_gait_task_is_clear_repeated_and_searches_one_gait():
    assert PLACEMENTS["clear-gaits"] is CLEAR_GAITS
    task = ScrewCapTask(**CLEAR_GAITS)
    assert task.n_gaits == 3 and task.target_deg == 360.0
    for name, value in CLEAR.items():  # the same cap, hand and physics as the one gait
        if name != "target_deg":
            assert getattr(task, name) == value, name
    one, several = ScrewCapTrial(ScrewCapTask(**CLEAR)), ScrewCapTrial(task)
    assert several.dimension == one.dimension == 26
    np.testing.assert_array_equal(several.bounds, one.bounds)
    assert task.total_time == pytest.approx(3 * task.gait_duration + task.hold)
    # its checks at the end of each gait (the last after the hold): a quarter, half, all
    np.testing.assert_allclose(task.check_times(), [1.0, 2.0, 3.2])
    np.testing.assert_allclose(task.benchmark_at(task.check_times()), [90.0, 180.0, 360.0])


def test_the_command_line_takes_the_several_gait_task_by_name():
    from handle_drake.apps.inhand.cli import _task_options, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    options = _task_options(parser.parse_args(["inhand", "--task", "screw_cap", "--placement",
                                               "clear-gaits"]))
    assert options["n_gaits"] == 3 and options["target_deg"] == 360.0
    assert {k: options[k] for k in CLEAR if k != "target_deg"} == {
        k: v for k, v in CLEAR.items() if k != "target_deg"}
    # the repetitions stay a setting: --gaits overrides the preset's 3
    options = _task_options(parser.parse_args(["inhand", "--task", "screw_cap", "--placement",
                                               "clear-gaits", "--gaits", "4"]))
    assert options["n_gaits"] == 4


def _motion_at(built, times) -> np.ndarray:
    """The diagram's gait source output (the hand's commanded positions) at ``times``."""
    source = built["source"]
    context = built["diagram"].CreateDefaultContext()
    out = []
    for t in times:
        context.SetTime(float(t))
        out.append(source.get_output_port().Eval(
            source.GetMyContextFromRoot(context)).copy())
    return np.array(out)


def test_the_commanded_motion_is_the_one_gait_tiled_with_the_regrasp_between():
    # read from the two built diagrams (one gait, three gaits) with the same parameters:
    # at every time in gait k the three-gait command is the one gait's at t - k d; at each
    # gait's end the command returns from the gait's last frame to its first (the regrasp),
    # and after the last gait it holds the last frame
    one = ScrewCapTrial(ScrewCapTask(**CLEAR))
    several = ScrewCapTrial(ScrewCapTask(**CLEAR_GAITS))
    b = one.bounds
    x = b[:, 0] + np.random.default_rng(5).random(len(b)) * (b[:, 1] - b[:, 0])
    built_one = build_screw_cap(one.scenario(x), driver=False)
    built_several = build_screw_cap(several.scenario(x), driver=False)
    d = several.config.gait_duration
    t = np.linspace(0.0, d, 97, endpoint=False)
    single = _motion_at(built_one, t)
    assert np.ptp(single, axis=0).max() > 0.3  # the gait moves the fingers
    for k in range(3):
        np.testing.assert_array_equal(_motion_at(built_several, t + k * d), single)
    last, first = _motion_at(built_one, [d - 1e-6, 0.0])
    assert np.abs(last - first).max() > 0.1  # so the regrasp is a real return
    for k in (1, 2):
        before, after = _motion_at(built_several, [k * d - 1e-6, k * d + 1e-6])
        np.testing.assert_array_equal(before, last)
        np.testing.assert_array_equal(after, first)
    held = _motion_at(built_several, [3 * d + 1e-6, 3 * d + 0.15])
    np.testing.assert_array_equal(held, [last, last])


def test_the_learned_gait_turns_the_cap_360_deg_over_three_gaits_read_from_the_plant():
    # the learned gait (pso, a development seed) re-simulated by convergence.resimulate, which
    # reads the cap's thread joint from the plant at every step: past 360 deg at the task's
    # 1 ms (398.4 measured), no force on the welded bottle, the palm off the cap
    from handle_drake.apps.inhand.convergence import LEARNED_GAIT_360, resimulate

    trial = ScrewCapTrial(ScrewCapTask(**CLEAR_GAITS))
    r = resimulate(trial.scenario(np.array(LEARNED_GAIT_360)), target_deg=360.0)
    assert r.time_step == pytest.approx(0.001)
    assert r.reached and r.turn_deg >= 360.0
    assert r.welded_peak <= 1.0 and r.palm_peak <= 1.0
