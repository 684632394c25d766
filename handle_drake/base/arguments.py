"""Argument types every command shares: each refuses a bad value with "expected ...,
got ..." (argparse turns that into a one-line usage error, exit 2).

Here, in the lowest layer, so that any layer's command (the applications' sub-commands, a
device's own ``can-sim``/``can-server``) uses them without importing upwards;
:mod:`handle_drake.apps.cli_support` re-exports them.
"""

from __future__ import annotations

import argparse
import math

__all__ = ["int_at_least", "positive_int", "non_negative_int", "non_empty",
           "non_negative_float", "positive_float", "SEED_MAX", "seed_int", "int_in", "float_in"]


def int_at_least(minimum: int, expected: str, maximum: int | None = None):
    """An argparse type: an integer >= ``minimum`` (and <= ``maximum`` if given), else
    "expected <expected>, got ..."."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if value < minimum or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {value}")
        return value

    return parse


positive_int = int_at_least(1, "a positive integer")
non_negative_int = int_at_least(0, "an integer >= 0")
#: A seed: the trial log stores it as SQLite's 64-bit INTEGER.
SEED_MAX = 2**63 - 1
seed_int = int_at_least(0, "an integer in 0..2**63-1", SEED_MAX)


def int_in(low: int, high: int):
    """An argparse type: an integer in ``low..high``."""
    return int_at_least(low, f"an integer in {low}..{high}", high)


def float_in(low: float, high: float, low_open: bool = True):
    """An argparse type: a finite number in ``(low, high]`` (``[low, high]`` when not
    ``low_open``)."""
    expected = f"a number in {'(' if low_open else '['}{low:g}, {high:g}]"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not (math.isfinite(value) and (value > low if low_open else value >= low)
                and value <= high):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text}")
        return value

    return parse


def non_empty(text: str) -> str:
    """An argparse type: any text but the empty (or all-blank) one, which would
    silently mean "the default"."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a non-empty value, got {text!r}")
    return text


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text}")
    return value
