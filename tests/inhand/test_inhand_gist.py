"""Action gist: segmentation, eq. 45, Algorithm 1 / eq. 46 frames, the motion source system."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import VectorLogSink

from handle_drake.apps.inhand.gist import (
    ActionGist,
    GistMotionSource,
    MetaMotion,
    extract_gist,
    frames,
    parameter_dimension,
    staged_gist,
)
from handle_drake.apps.inhand.task import task_gist
from handle_drake.base.hands import get_hand_spec

NAMES = list(get_hand_spec("shadow").actuated_joint_names)


def _gist():
    return ActionGist((
        MetaMotion("FF", 0.1, 0.5, (0.4, 0.2)),
        MetaMotion("TH", 0.2, 0.6, (0.3, -0.1, 0.2)),
        MetaMotion("FF", 0.6, 0.8, (-0.4, -0.2)),
    ))


def test_eq45_dimension():
    g = _gist()
    # (1 + 2) + (1 + 3) + (1 + 2)
    assert g.dimension == 10 == parameter_dimension(["FF", "TH", "FF"])
    assert g.initial_parameters().size == 10
    assert g.bounds().shape == (10, 2)
    assert parameter_dimension(["LF", "MF", "RF"]) == 9
    # the shipped screw-cap demonstration: 8 meta motions of TH, FF, MF, RF
    cap = task_gist("cylinder_rotation")
    fingers = [m.finger for m in cap.motions]
    assert sorted(set(fingers)) == ["FF", "MF", "RF", "TH"]
    assert cap.dimension == sum(1 + (3 if f == "TH" else 2) for f in fingers) == 26


def test_bounds_one_direction_per_variation():
    b = _gist().bounds()
    assert np.all(b[:, 0] == 0.0)
    assert b[0, 1] == 1.0 and b[3, 1] == 1.0  # start times in [0, 1]
    # FFJ3 command range is -0.2618..1.5708
    assert b[1, 1] == pytest.approx(1.5708 + 0.2618, abs=1e-4)
    assert np.all(_gist().bounds(limit=0.5)[[1, 2, 4, 5, 6, 8, 9], 1] == 0.5)


def test_eq46_frames_against_hand_computed_values():
    g = _gist()
    q0 = np.zeros(20)
    q0[NAMES.index("FFJ3")] = 0.3
    # c: FF starts 0.1 (ends where the next FF motion starts: 0.6), TH 0.2 (last TH motion:
    # demonstrated duration 0.4 -> ends 0.6), FF again at 0.6 (last: duration 0.2 -> 0.8)
    c = np.array([0.1, 0.5, 0.2, 0.2, 0.3, 0.1, 0.4, 0.6, 0.2, 0.1])
    F = frames(g, c, q0, 10)  # T = 0.1, 0.2, ..., 1.0
    ffj3, ffj2 = NAMES.index("FFJ3"), NAMES.index("FFJ2")
    thj5, thj2 = NAMES.index("THJ5"), NAMES.index("THJ2")
    # T = 0.3: FF ramp (0.3 - 0.1) / (0.6 - 0.1) = 0.4 of +0.5 on FFJ3
    assert F[2, ffj3] == pytest.approx(0.3 + 0.4 * 0.5)
    assert F[2, ffj2] == pytest.approx(0.4 * 0.2)
    # TH ramp at T = 0.3: (0.3 - 0.2) / 0.4 = 0.25; THJ2 goes negative (demo direction)
    assert F[2, thj5] == pytest.approx(0.25 * 0.3)
    assert F[2, thj2] == pytest.approx(-0.25 * 0.1)
    # T = 0.7: first FF motion complete (+0.5), second at (0.7 - 0.6) / 0.2 = 0.5 of -0.2
    assert F[6, ffj3] == pytest.approx(0.3 + 0.5 - 0.5 * 0.2)
    # T = 1.0: everything done
    assert F[9, ffj3] == pytest.approx(0.3 + 0.5 - 0.2)
    assert F[9, ffj2] == pytest.approx(0.2 - 0.1)
    # joints of no meta motion stay at q0
    assert np.all(F[:, NAMES.index("MFJ3")] == 0.0)
    # the next FF start before the first one: the first becomes a step at its start
    c2 = c.copy()
    c2[7] = 0.05
    F2 = frames(g, c2, q0, 10)
    assert F2[0, ffj3] == pytest.approx(0.3 + 0.5 - 0.2 * (0.1 - 0.05) / 0.2)


def test_extract_gist_finds_the_strokes_of_a_known_signal():
    t = np.linspace(0, 2, 201)
    q = np.zeros((t.size, 20))
    s = np.clip((t - 0.4) / 0.4, 0, 1) - np.clip((t - 1.2) / 0.4, 0, 1)  # up 0.4-0.8, down
    q[:, NAMES.index("MFJ3")] = 0.6 * s
    q[:, NAMES.index("MFJ2")] = 0.3 * s
    q[:, NAMES.index("RFJ3")] = 0.02 * np.sin(20 * t)  # tremor below the thresholds
    g = extract_gist(t, q)
    assert [m.finger for m in g.motions] == ["MF", "MF"]
    up, down = g.motions
    assert up.start == pytest.approx(0.2, abs=0.03) and up.end == pytest.approx(0.4, abs=0.03)
    assert down.start == pytest.approx(0.6, abs=0.03)
    np.testing.assert_allclose(up.variation, (0.6, 0.3), atol=0.05)
    np.testing.assert_allclose(down.variation, (-0.6, -0.3), atol=0.05)


def test_bad_gists_and_parameters():
    with pytest.raises(ValueError, match="meta motions of FF overlap"):
        ActionGist((MetaMotion("FF", 0.1, 0.5, (0.4, 0.2)),
                    MetaMotion("FF", 0.4, 0.8, (-0.4, -0.2))))
    with pytest.raises(ValueError, match="ordered by start time"):
        ActionGist((MetaMotion("FF", 0.5, 0.6, (0.4, 0.2)), MetaMotion("MF", 0.1, 0.2, (1, 1))))
    with pytest.raises(ValueError, match="expected 0 <= start < end <= 1"):
        MetaMotion("FF", 0.5, 0.5, (0.4, 0.2))
    with pytest.raises(ValueError, match="variation: expected 3 finite values"):
        MetaMotion("TH", 0.1, 0.5, (0.4, 0.2))
    with pytest.raises(ValueError, match="finger: expected one of"):
        MetaMotion("XX", 0.1, 0.5, (0.4, 0.2))
    with pytest.raises(ValueError, match="at least one meta motion"):
        ActionGist(())
    with pytest.raises(ValueError, match=r"expected 10 values \(eq. 45\), got 9"):
        frames(_gist(), np.zeros(9), np.zeros(20), 10)
    with pytest.raises(ValueError, match="n_frames"):
        frames(_gist(), np.zeros(10), np.zeros(20), 0)
    assert ActionGist.from_dict(_gist().as_dict()) == _gist()


def test_motion_source_sends_the_frames_as_a_zero_order_hold():
    g = _gist()
    q0 = np.full(20, 0.05)
    c = np.array([0.1, 0.5, 0.2, 0.2, 0.3, 0.1, 0.4, 0.6, 0.2, 0.1])
    builder = DiagramBuilder()
    source = builder.AddSystem(GistMotionSource(g, q0, duration=1.0, n_frames=10))
    log = builder.AddSystem(VectorLogSink(20, 0.05))
    builder.Connect(source.get_output_port(), log.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    source.set_parameters(source.GetMyMutableContextFromRoot(context), c)
    simulator.AdvanceTo(1.2)
    data = log.FindLog(context)
    F = frames(g, c, q0, 10)
    for t, value in zip(data.sample_times(), data.data().T, strict=True):
        j = min(10, int(np.floor(t / 0.1 + 1e-9)) + 1)
        np.testing.assert_allclose(value, F[j - 1])


def test_held_frames_give_a_sampling_driver_the_sources_commands():
    # what a driver sampling every period reads: the source's output at each sample time
    # (evaluated in its context) and the planned hold's value there, bit for bit, for the
    # in-hand task's gist (50 frames over 1 s, the station's 5 ms driver) and a gist whose
    # frame boundaries fall between samples (10 frames over 0.7 s, 2 ms)
    cases = [(task_gist("cylinder_rotation"), 1.0, 50, 0.005, 1.9),
             (_gist(), 0.7, 10, 0.002, 1.0)]
    rng = np.random.default_rng(3)
    for g, duration, n, period, end in cases:
        b = g.bounds()
        c = b[:, 0] + rng.random(len(b)) * (b[:, 1] - b[:, 0])
        source = GistMotionSource(g, np.full(20, 0.05), duration, n)
        context = source.CreateDefaultContext()
        source.set_parameters(context, c)
        held = source.held_frames(c, period, end)
        times = np.arange(int(round(end / period)) + 1) * period
        assert held.get_number_of_segments() < len(times) / 2  # one per frame, not per sample
        for t in times:
            context.SetTime(t)
            np.testing.assert_array_equal(held.value(t).ravel(),
                                          source.get_output_port().Eval(context))
        np.testing.assert_array_equal(source.frame_indices(times),
                                      [source.frame_index(t) for t in times])


def test_a_staged_gist_is_the_gist_performed_in_sequence_with_its_own_parameters():
    g = _gist()
    two = staged_gist(g, 2)
    assert staged_gist(g, 1) is g
    assert two.dimension == 2 * g.dimension and len(two) == 2 * len(g)
    # stage s: the gist's times mapped to [s / 2, (s + 1) / 2]
    assert [(m.start, m.end) for m in two.motions[:3]] == [(0.05, 0.25), (0.1, 0.3), (0.3, 0.4)]
    assert [(m.start, m.end) for m in two.motions[3:]] == [(0.55, 0.75), (0.6, 0.8),
                                                           (0.8, 0.9)]
    # eq. 46 sums over the stages: the second continues from where the first left the
    # fingers (a finger's last motion of stage 1 ends where its stage 2 starts, eq. 46's
    # rule), and stage 2's magnitudes do not move the frames before it starts (T = 0.55)
    q0 = np.zeros(20)
    c = two.initial_parameters()
    F = frames(two, c, q0, 100)
    one = frames(g, g.initial_parameters(), q0, 50)
    np.testing.assert_allclose(F[99], 2 * one[-1], atol=1e-12)  # twice the net variation
    c2 = c.copy()
    c2[g.dimension + 1: g.dimension + 3] = 0.0  # stage 2's first FF magnitudes
    F2 = frames(two, c2, q0, 100)
    np.testing.assert_allclose(F2[:55], F[:55])
    assert not np.allclose(F2[55:], F[55:])
    with pytest.raises(ValueError, match="stages"):
        staged_gist(g, 0)
