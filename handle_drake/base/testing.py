"""Shared switches for tests, notebooks and benchmarks.

``HANDLE_DRAKE_REDUCED=1`` shrinks loops (trial counts, durations, grid sizes)
so that notebooks and examples run in the test suite in seconds. Code that has
a long loop asks :func:`reduced` and picks its small size from it.
:func:`load_file_module` imports a script that is not in a package (a benchmark,
a model generator) for its tests.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

REDUCED_ENV = "HANDLE_DRAKE_REDUCED"


def reduced() -> bool:
    """True when the caller should run a shortened version of its work."""
    return os.environ.get(REDUCED_ENV, "0") not in ("", "0", "false", "False")


def pick(full, small):
    """``small`` in reduced mode, else ``full``."""
    return small if reduced() else full


def load_file_module(path, name: str):
    """The Python file ``path`` imported as module ``name`` (registered in
    ``sys.modules``, as dataclasses and pickling need)."""
    spec = importlib.util.spec_from_file_location(name, Path(path))
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
