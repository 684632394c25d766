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
           "non_negative_float", "positive_float"]


def int_at_least(minimum: int, expected: str):
    """An argparse type: an integer >= ``minimum``, else "expected <expected>, got ..."."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {value}")
        return value

    return parse


positive_int = int_at_least(1, "a positive integer")
non_negative_int = int_at_least(0, "an integer >= 0")


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
    value = non_negative_float(text)
    if value == 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text}")
    return value
