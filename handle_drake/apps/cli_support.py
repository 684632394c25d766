"""What every ``handle-drake`` sub-command shares: running one with clean errors, Meshcat,
argument types that refuse bad numbers with "expected ..., got ...".

Here and not in :mod:`handle_drake.cli` so that the area modules that
register sub-commands (``grasp/cli.py``, ``experiments/cli.py``,
``can_hand/cli.py``) do not import the top-level command upwards.
"""

from __future__ import annotations

import argparse
import signal
import sys
import warnings

from handle_drake.base.arguments import (
    SEED_MAX,
    float_in,
    int_at_least,
    int_in,
    non_empty,
    non_negative_float,
    non_negative_int,
    positive_float,
    positive_int,
    seed_int,
)
from handle_drake.base.blas import pin_blas

__all__ = ["check_hardware_server", "run_command", "start_meshcat", "int_at_least", "positive_int",
           "non_negative_int", "positive_float", "non_negative_float", "add_mesh_arguments",
           "refuse_without_mesh", "non_empty", "SEED_MAX", "seed_int", "int_in", "float_in"]


def start_meshcat(wanted: bool):
    """A Meshcat (its address printed) when ``wanted``, else None."""
    if not wanted:
        return None
    from pydrake.geometry import StartMeshcat

    meshcat = StartMeshcat()
    print(f"Meshcat: {meshcat.web_url()}", flush=True)
    return meshcat


def check_hardware_server(scenario) -> None:
    """``--hardware`` needs a !CanHandDriver and its server answering, before anything runs."""
    import socket

    from handle_drake.scenario import CanHandDriver

    driver = scenario.driver
    if not isinstance(driver, CanHandDriver):
        raise ValueError(f"--hardware: expected a scenario with driver: !CanHandDriver, got "
                         f"!{type(driver).__name__}")
    try:
        with socket.create_connection((driver.host, driver.port),
                                      timeout=max(driver.connect_timeout, 1.0)):
            pass
    except OSError as error:
        raise ValueError(
            f"--hardware: expected a CAN bus server at {driver.host}:{driver.port} (driver.host, "
            f"driver.port), got {error.strerror or error}; start `handle-drake can-server`"
        ) from None


def add_mesh_arguments(parser: argparse.ArgumentParser, mesh_help: str, **mesh_options) -> None:
    """``--mesh FILE`` (your own object) and ``--mesh-scale S`` (default None: 1, and
    :func:`refuse_without_mesh` can tell it was given)."""
    from handle_drake.base.models import shipped_path

    parser.add_argument("--mesh", type=shipped_path, metavar="FILE", help=mesh_help,
                        **{"default": None, **mesh_options})
    parser.add_argument("--mesh-scale", type=positive_float, default=None, metavar="S",
                        help="mesh file units to metres (0.001 for millimetres; default 1)")


def refuse_without_mesh(args, *options: str) -> None:
    """Refuses mesh-only options (``"--mesh-scale"``, ``"--mass"``) given without ``--mesh``:
    they would be silently ignored."""
    if args.mesh:
        return
    for option in options:
        value = getattr(args, option.lstrip("-").replace("-", "_"))
        if value is not None:
            raise ValueError(f"{option}: only for a --mesh object, got {value} without --mesh")


def run_command(parser: argparse.ArgumentParser, argv: list[str] | None = None) -> int:
    """Parses ``argv`` and runs the chosen sub-command: bad input is a one-line
    error and exit code 2, Ctrl-C exit code 130 (runs that log trials resume)."""
    pin_blas(force=False)  # before the imports below load numpy
    from handle_drake.base.checks import ScenarioDeprecationWarning
    from handle_drake.base.extras import MissingExtraError
    from handle_drake.base.paths import check_outputs
    from handle_drake.learning import TrialLogError
    from handle_drake.learning.cluster import ExecutorError, check_executor_arguments

    args = parser.parse_args(argv)
    previous = _terminate_like_ctrl_c()
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(args.command)
            # Shown to CLI users too (Python hides DeprecationWarnings outside __main__).
            warnings.filterwarnings("always", category=ScenarioDeprecationWarning)
            check_outputs(args)  # before minutes of work, not after
            check_executor_arguments(args)
            return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, TypeError, TrialLogError, ExecutorError,
            MissingExtraError) as error:
        print(f"handle-drake {args.command}: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        from handle_drake.base.checks import short_path

        where = f": {short_path(error.filename)}" if error.filename else ""
        print(f"handle-drake {args.command}: error: {error.strerror or error}{where}",
              file=sys.stderr)
        return 2
    except SystemExit as error:
        if error.code is None or isinstance(error.code, int):
            raise
        # Last resort: a Drake ``Failure at ...`` (an input our checks let through).
        print(f"handle-drake {args.command}: error: Drake refused the input: "
              f"{str(error.code).strip()[:500]}", file=sys.stderr)
        return 2
    except (RuntimeError, MemoryError, RecursionError) as error:
        # Last resort too: Drake's RuntimeErrors on inputs our checks let through.
        print(f"handle-drake {args.command}: error: {type(error).__name__}: "
              f"{str(error).strip()[:500]}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = f"; run it again to resume from {args.db}" if getattr(args, "db", None) else ""
        print(f"handle-drake {args.command}: interrupted{resume}", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _one_line_warning(command: str):
    """A ``warnings.showwarning`` that prints ``handle-drake CMD: warning: ...`` on one
    line (not ``<string>:15: MeshObjectWarning: ...`` and the source line)."""

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        print(f"handle-drake {command}: warning: {text[:500]}", file=file or sys.stderr)

    return show


def _raise_keyboard_interrupt(signum, frame):
    raise KeyboardInterrupt


def _terminate_like_ctrl_c():
    """SIGTERM (``kill``, a job scheduler) takes the Ctrl-C path: the trial log
    marks the run resumable and worker pools are shut down, instead of the
    process vanishing and leaving its workers running. Only in the main
    thread (signal handlers cannot be set elsewhere); returns the previous
    handler, or None when nothing was changed. Commands with their own stop
    logic (can-server, can-sim) install their handlers over this one."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
