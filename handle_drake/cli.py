"""The ``handle-drake`` command.

Sub-commands:

- ``demo``: the Shadow hand grasps a sphere, lifts it, reports whether it
  held and writes an HTML replay.
- ``simulate SCENARIO.yaml``: runs a scenario (live in Meshcat with
  ``--meshcat``, saved as a self-contained page with ``--html``).
- the sub-commands each area registers (``register(subparsers)``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from pathlib import Path

# Modules that add their own sub-commands with ``register(subparsers)``.
AREA_COMMANDS: tuple[str, ...] = (
    "handle_drake.grasp.cli",
    "handle_drake.experiments.cli",
    "handle_drake.can_hand.cli",
)


def _pin_blas() -> None:
    # Threaded BLAS on small machines makes small solves far slower.
    for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(variable, "1")


def _add_simulate(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="run a scenario file (see diagrams/)")
    p.add_argument("scenario", type=Path, help="scenario YAML file")
    p.add_argument("--override", default=None, help="YAML text applied on top of the file")
    p.add_argument("--duration", type=float, default=None, help="seconds (default: scenario's)")
    p.add_argument("--meshcat", action="store_true", help="show it live in Meshcat")
    p.add_argument("--html", type=Path, default=None, help="save a self-contained HTML replay")
    p.add_argument("--hardware", action="store_true",
                   help="drive the CAN hand of the scenario's !CanHandDriver in real time")
    p.add_argument("--quality", action="store_true",
                   help="score the final grasp: Bimodal Wrench Space metric of the contacts")
    p.set_defaults(func=_cmd_simulate)


def _add_demo(subparsers) -> None:
    p = subparsers.add_parser("demo", help="Shadow hand grasps and lifts a sphere")
    p.add_argument("--html", type=Path, default=Path("out/demo.html"),
                   help="HTML replay path (default out/demo.html)")
    p.add_argument("--meshcat", action="store_true", help="also show it live in Meshcat")
    p.add_argument("--no-html", action="store_true", help="do not write the HTML replay")
    p.set_defaults(func=_cmd_demo)


def _meshcat(wanted: bool):
    if not wanted:
        return None
    from pydrake.geometry import StartMeshcat

    meshcat = StartMeshcat()
    print(f"Meshcat: {meshcat.web_url()}", flush=True)
    return meshcat


def _cmd_simulate(args) -> int:
    from handle_drake.run import ScenarioRunner
    from handle_drake.scenario import LoadScenario

    scenario = LoadScenario(filename=args.scenario, data=args.override)
    meshcat = _meshcat(args.meshcat or args.html is not None)
    runner = ScenarioRunner(scenario, meshcat, hardware=args.hardware)
    result = runner.run(args.duration, html=args.html)
    print(f"simulated {result.sim_time:.2f} s in {result.wall_time:.2f} s "
          f"({result.realtime_factor:.1f}x real time)")
    if result.object_position is not None:
        print(f"object height: start {result.object_position[0, 2]:.3f} m, "
              f"end {result.object_position[-1, 2]:.3f} m")
    if result.score is not None:
        m, score = scenario.metric, result.score
        print(f"grasp metric (BW, soft finger, mean of {m.hold_samples} instants over the last "
              f"{m.hold_window:g} s): {score.value!r} "
              f"({'force closure' if score.force_closure else 'not in force closure'}); "
              f"touching: {', '.join(sorted(score.contacts)) or 'nothing'}")
    if args.quality:
        value, closure, contacts = runner.grasp_quality()
        print(f"grasp quality (BW metric, soft finger): {value:+.4f} "
              f"({'force closure' if closure else 'not in force closure'}); "
              f"touching: {', '.join(sorted(contacts)) or 'nothing'}")
    if args.html:
        print(f"replay written to {args.html}")
    return 0


def _cmd_demo(args) -> int:
    from handle_drake.demo import run_demo

    meshcat = _meshcat(args.meshcat or not args.no_html)
    report = run_demo(meshcat=meshcat, html=None if args.no_html else args.html)
    print(report.summary())
    return 0 if report.held else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handle-drake",
        description="Dexterous grasping with the Shadow and Barrett hands on Drake.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_demo(subparsers)
    _add_simulate(subparsers)
    for module_name in AREA_COMMANDS:
        importlib.import_module(module_name).register(subparsers)
    return parser


def run_command(parser: argparse.ArgumentParser, argv: list[str] | None = None) -> int:
    """Parses ``argv`` and runs the chosen sub-command: bad input is a one-line
    error and exit code 2, Ctrl-C exit code 130 (runs that log trials resume)."""
    from handle_drake.learning import TrialLogError

    _pin_blas()
    args = parser.parse_args(argv)
    previous = _terminate_like_ctrl_c()
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, TypeError, TrialLogError) as error:
        print(f"handle-drake {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        resume = f"; run it again to resume from {args.db}" if getattr(args, "db", None) else ""
        print(f"handle-drake {args.command}: interrupted{resume}", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


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


def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
