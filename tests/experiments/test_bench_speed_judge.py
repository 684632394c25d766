"""benchmarks/support/speed.py: a speed ratio's median comes with its 95 % interval, and a
target is judged met only when the whole interval is under it."""

from pathlib import Path

import numpy as np
import pytest

from handle_drake.base.testing import load_file_module

SPEED = Path(__file__).resolve().parents[2] / "benchmarks" / "support" / "speed.py"


@pytest.fixture(scope="module")
def speed():
    return load_file_module(SPEED, "bench_speed_under_test")


def test_the_interval_covers_the_true_median_about_95_percent_of_the_time(speed):
    # rounds drawn from a known distribution (median 1.09, +-2 % spread like the station's
    # rounds): over 200 simulated runs of 20 rounds the interval holds the true median
    # in ~95 % of them (percentile bootstrap of a median: 88-99 % at this size)
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(200):
        rounds = 1.09 + 0.015 * rng.standard_normal(20)
        low, high = speed.median_ci(rounds)
        assert low <= np.median(rounds) <= high
        hits += low <= 1.09 <= high
    assert 0.88 <= hits / 200 <= 0.99


def test_the_interval_narrows_with_more_rounds_and_is_repeatable(speed):
    rng = np.random.default_rng(1)
    few, many = 1.09 + 0.02 * rng.standard_normal(8), 1.09 + 0.02 * rng.standard_normal(80)
    width = [np.diff(speed.median_ci(x))[0] for x in (few, many)]
    assert width[1] < 0.6 * width[0]  # ~1/sqrt(10) in theory
    assert speed.median_ci(few) == speed.median_ci(few)  # seeded


def test_a_target_is_met_only_when_the_whole_interval_is_under_it(speed):
    under = {"median": 1.05, "ci95": [1.04, 1.06]}
    straddles = {"median": 1.095, "ci95": [1.088, 1.104]}
    over = {"median": 1.11, "ci95": [1.09, 1.12]}
    assert speed.judge(under, 1.10) == "met"
    assert speed.judge(straddles, 1.10).startswith("met by the median")
    assert "1.088-1.104" in speed.judge(straddles, 1.10)
    assert speed.judge(over, 1.10) == "NOT met"


def test_too_few_rounds_give_no_interval_and_no_full_met(speed):
    ci = speed.median_ci([1.05, 1.06, 1.04])
    assert ci == [None, None]  # null in a benchmark's JSON, not NaN
    assert speed.judge({"median": 1.05, "ci95": ci}, 1.10) == \
        "met by the median (too few rounds for an interval)"
    assert speed.judge({"median": 1.12, "ci95": ci}, 1.10) == "NOT met"
    assert speed.ci_text(ci) == "[95 %: too few rounds]"
    assert speed.ci_text([1.0876, 1.0952]) == "[95 % 1.088-1.095]"
