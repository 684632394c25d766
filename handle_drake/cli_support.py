"""What every ``handle-drake`` sub-command shares: running one with clean errors, Meshcat.

Here and not in :mod:`handle_drake.cli` so that the area modules that
register sub-commands (``grasp/cli.py``, ``experiments/cli.py``,
``can_hand/cli.py``) do not import the top-level command upwards.
"""

from __future__ import annotations

import argparse
import signal
import sys
import warnings

from handle_drake.blas import pin_blas

__all__ = ["run_command", "start_meshcat"]


def start_meshcat(wanted: bool):
    """A Meshcat (its address printed) when ``wanted``, else None."""
    if not wanted:
        return None
    from pydrake.geometry import StartMeshcat

    meshcat = StartMeshcat()
    print(f"Meshcat: {meshcat.web_url()}", flush=True)
    return meshcat


def run_command(parser: argparse.ArgumentParser, argv: list[str] | None = None) -> int:
    """Parses ``argv`` and runs the chosen sub-command: bad input is a one-line
    error and exit code 2, Ctrl-C exit code 130 (runs that log trials resume)."""
    from handle_drake.learning import TrialLogError
    from handle_drake.learning.cluster import ExecutorError
    from handle_drake.paths import check_outputs

    pin_blas(force=False)
    args = parser.parse_args(argv)
    previous = _terminate_like_ctrl_c()
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning(args.command)
            check_outputs(args)  # before minutes of work, not after
            return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, TypeError, TrialLogError, ExecutorError) as error:
        print(f"handle-drake {args.command}: error: {error}", file=sys.stderr)
        return 2
    except OSError as error:
        from handle_drake.scenario_checks import short_path

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
