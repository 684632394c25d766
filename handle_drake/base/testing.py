"""Shared switches for tests, notebooks and benchmarks.

``HANDLE_DRAKE_REDUCED=1`` shrinks loops (trial counts, durations, grid sizes)
so that notebooks and examples run in the test suite in seconds. Code that has
a long loop asks :func:`reduced` and picks its small size from it.
"""

from __future__ import annotations

import os

REDUCED_ENV = "HANDLE_DRAKE_REDUCED"


def reduced() -> bool:
    """True when the caller should run a shortened version of its work."""
    return os.environ.get(REDUCED_ENV, "0") not in ("", "0", "false", "False")


def pick(full, small):
    """``small`` in reduced mode, else ``full``."""
    return small if reduced() else full
