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
import sys
from pathlib import Path

from handle_drake.apps.cli_support import check_hardware_server, run_command, start_meshcat
from handle_drake.base.blas import pin_blas

# Modules that add their own sub-commands with ``register(subparsers)``.
AREA_COMMANDS: tuple[str, ...] = (
    "handle_drake.apps.planning.cli",
    "handle_drake.apps.babbling.cli",
    "handle_drake.devices.can_hand.cli",
    "handle_drake.apps.figure8.cli",
    "handle_drake.apps.inhand.cli",
    "handle_drake.apps.perception.perceive",
    "handle_drake.apps.figure9.cli",
    "handle_drake.apps.pick.cli",
)


def _add_simulate(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="run a scenario file (see diagrams/) or a "
                                               "logged trial")
    p.add_argument("scenario", type=Path,
                   help="scenario YAML file, a shipped scenario's name (handle-drake "
                        "diagrams list), or a trial log (SQLite, of handle-drake babble or "
                        "inhand): its best trial's scenario (--run-id, --trial)")
    p.add_argument("--run-id", default=None,
                   help="with a trial log: the run (default: the log's only run)")
    p.add_argument("--trial", type=int, default=None, metavar="INDEX",
                   help="with a trial log: the trial's index (default: the best finished one)")
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


def _add_diagrams(subparsers) -> None:
    p = subparsers.add_parser(
        "diagrams", help="the shipped scenario files: list them, or copy them to edit",
        description="The scenarios of diagrams/ ship with the package (handle_drake/_diagrams "
                    "outside a checkout). Commands that take a scenario file also take a "
                    "shipped one by name: handle-drake simulate shadow_sphere_grasp.")
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    q = sub.add_parser("list", help="name each shipped scenario and its first comment line")
    q.add_argument("--paths", action="store_true", help="print the installed files' paths")
    q.set_defaults(func=_cmd_diagrams_list)
    q = sub.add_parser("copy", help="copy the shipped scenarios (and their meshes) to a folder")
    q.add_argument("dest", type=Path, help="folder to copy into (created; existing files are "
                                           "refused, not overwritten)")
    q.set_defaults(func=_cmd_diagrams_copy)


def _cmd_diagrams_list(args) -> int:
    from handle_drake.base.models import shipped_scenarios

    for path in shipped_scenarios():
        if args.paths:
            print(path)
            continue
        comments = [text for line in path.read_text().splitlines()
                    if line.startswith("#") and (text := line.lstrip("# ").strip())
                    and not text.startswith(("Planned by", "Written by"))]
        first = comments[0] if comments else ""
        print(f"{path.stem:44s} {first[:90]}")
    return 0


def _cmd_diagrams_copy(args) -> int:
    import shutil

    from handle_drake.base.models import diagrams_dir

    source = diagrams_dir()
    files = [p for p in sorted(source.rglob("*"))
             if p.is_file() and "__pycache__" not in p.parts and p.name != "__init__.py"]
    clashes = [str(args.dest / p.relative_to(source)) for p in files
               if (args.dest / p.relative_to(source)).exists()]
    if clashes:
        raise ValueError(f"DEST: {len(clashes)} file(s) already there, e.g. {clashes[0]}; "
                         "copy into a new folder")
    for path in files:
        target = args.dest / path.relative_to(source)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)
    print(f"copied {len(files)} files from {source} to {args.dest}")
    return 0


def _cmd_simulate(args) -> int:
    from handle_drake.scenario import LoadScenario, object_spec
    from handle_drake.trial.harness import DEFAULT_LOG

    logged = _logged_trial(args)
    if logged is not None:
        print(f"trial {logged[1]} of run {logged[2]!r} in {args.scenario} (score "
              f"{logged[3]:.6g})")
        scenario = LoadScenario(text=logged[0], data=args.override,
                                source=f"{args.scenario}, trial {logged[1]}")
    else:
        scenario = LoadScenario(filename=args.scenario, data=args.override)
    if args.duration is not None:
        _check_duration(args.duration, scenario)
    if args.hardware:
        check_hardware_server(scenario)
    meshcat = start_meshcat(args.meshcat or args.html is not None)
    instrumented = scenario.object is not None and scenario.object.accelerometer is not None
    log = DEFAULT_LOG
    jointed = scenario.object is not None and scenario.object.joint is not None
    if jointed:
        log = log + ("object.joint_position",)
    if instrumented:
        from handle_drake.devices.accelerometer.wiring import INSTRUMENT_LOG

        log = DEFAULT_LOG + INSTRUMENT_LOG
    # A MIDI controller model on the table (simulation): a receiver counts what its MIDI
    # said, as a learner would be told (the experiments' runner; a script drives the hand).
    midi = (scenario.midi_controller is not None and not args.hardware
            and scenario.controller is None)
    reversal = _logged_reversal(logged, args, scenario)
    runner = _simulate_runner(scenario, args, meshcat, log, midi, reversal)
    result = runner.run(args.duration, html=args.html)
    print(f"simulated {result.sim_time:.2f} s in {result.wall_time:.2f} s "
          f"({result.realtime_factor:.1f}x real time)")
    if result.object_position is not None:
        print(f"object height: start {result.object_position[0, 2]:.3f} m, "
              f"end {result.object_position[-1, 2]:.3f} m")
        _warn_below_table(scenario, result.object_position[:, 2])
    if jointed and not args.hardware:
        print(_joint_turn(scenario, runner.harness.logs()["object.joint_position"]))
    if reversal is not None:
        print(_replayed_reversal(runner, reversal, logged[4]))
    if result.score is not None:
        m, score = scenario.metric, result.score
        over = (f"; the mean over {len(m.placements)} start placements (metric.placements), "
                f"each: {', '.join(f'{v:.6g}' for v in score.placement_values)}"
                if m.placements else "")
        print(f"grasp metric (BW, soft finger, mean of {m.hold_samples} instants over the last "
              f"{m.hold_window:g} s{over}): {score.value!r} "
              f"({'force closure' if score.force_closure else 'not in force closure'}); "
              f"touching: {', '.join(sorted(score.contacts)) or 'nothing'}")
    if instrumented:
        from handle_drake.devices.accelerometer.wiring import describe_instruments

        X_WO = None
        if runner.station.HasOutputPort("object.pose"):
            X_WO = runner.station.GetOutputPort("object.pose").Eval(
                runner.station.GetMyContextFromRoot(runner.context))
        print(describe_instruments(scenario, object_spec(scenario), runner.harness.logs(), X_WO))
    if midi:
        from handle_drake.apps.figure9.experiments import describe_midi

        print(describe_midi(runner.midi_result(result.wall_time), runner.mapping))
    if args.quality:
        value, closure, contacts = runner.grasp_quality()
        print(f"grasp quality (BW metric, soft finger): {value:+.4f} "
              f"({'force closure' if closure else 'not in force closure'}); "
              f"touching: {', '.join(sorted(contacts)) or 'nothing'}")
    if args.html:
        print(f"replay written to {args.html}")
    return 0


SQLITE_HEADER = b"SQLite format 3\x00"


def _logged_trial(args):
    """With a trial log as SCENARIO: ``(scenario text, trial index, run id, score, logged
    detail)`` of
    its best finished trial (or ``--trial``) of ``--run-id`` (or its only run); None for a
    scenario file. ``--run-id`` and ``--trial`` are refused without a log."""
    path = args.scenario
    is_log = False
    if path.is_file():
        with path.open("rb") as file:
            is_log = file.read(16) == SQLITE_HEADER
    if not is_log:
        for flag, value in (("--run-id", args.run_id), ("--trial", args.trial)):
            if value is not None:
                raise ValueError(f"{flag}: only with a trial log (SQLite) as SCENARIO, got "
                                 f"{str(path)!r}")
        return None
    from handle_drake.learning.log import TrialLog, TrialLogError

    try:
        with TrialLog(path) as log:
            runs = [r.run_id for r in log.runs()]
            run_id = args.run_id if args.run_id is not None else (runs[0] if len(runs) == 1
                                                                   else None)
            if run_id not in runs:
                raise ValueError(f"--run-id: expected one of the log's {len(runs)} runs "
                                 f"{runs[:4]}{' ...' if len(runs) > 4 else ''}, got "
                                 f"{args.run_id!r}")
            done = [r for r in log.trials(run_id) if r.status == "done" and r.scenario]
    except TrialLogError as error:
        raise ValueError(f"SCENARIO: {error}") from None
    if args.trial is not None:
        done = [r for r in done if r.index == args.trial]
        if not done:
            raise ValueError(f"--trial: run {run_id!r} has no finished trial {args.trial} "
                             f"with a scenario")
    if not done:
        raise ValueError(f"SCENARIO: run {run_id!r} in {path} has no finished trial with a "
                         f"scenario")
    best = max(done, key=lambda r: r.metric)
    return best.scenario, best.index, run_id, best.metric, best.contacts


def _simulate_runner(scenario, args, meshcat, log, midi: bool, reversal):
    """simulate's runner: the MIDI experiments' (a MIDI controller model), one whose object's
    weight can be reversed (a logged fingertip-cylinder trial), else the scenario's."""
    if midi:
        from handle_drake.apps.figure9.experiments import MidiScenarioRunner

        return MidiScenarioRunner(scenario, meshcat, log=log)
    if reversal is not None:
        from handle_drake.apps.inhand.replay import ReversalRunner

        return ReversalRunner(scenario, reversal.margin, meshcat, log=log)
    from handle_drake.trial.simulate import ScenarioRunner

    return ScenarioRunner(scenario, meshcat, hardware=args.hardware, log=log)


def _logged_reversal(logged, args, scenario):
    """The logged in-hand trial's reversed weight (a free object's: held means it survives
    it), replayed after the scenario's duration; None without one, on hardware (no plant),
    with ``--duration`` (the reversal follows the trial's whole motion) or when
    ``--override`` left no free object."""
    if logged is None or args.hardware:
        return None
    from handle_drake.apps.inhand.replay import logged_reversal

    reversal = logged_reversal(logged[0])
    if reversal is None:
        return None
    o = scenario.object
    why = ("--duration: it follows the whole motion" if args.duration is not None else
           "--override: no free object" if o is None or o.joint is not None or o.fixed
           else "")
    if why:
        print(f"reversed weight: not replayed ({why})")
        return None
    return reversal


def _replayed_reversal(runner, reversal, contacts) -> str:
    """The replay's held verdict (read from its plant), then the logged trial's."""
    from handle_drake.apps.inhand.replay import replay_reversal

    out = replay_reversal(runner, reversal)
    logged = (contacts or {}).get("survived_reversal")
    where = "the largest over every step" if reversal.every_step else "at the end"
    said = ("the trial stopped before its reversal" if logged is None else
            f"{'held' if logged else 'not held'}, travel "
            f"{(contacts or {}).get('reversal_travel')!r} m")
    return (f"reversed weight (its weight reversed plus {reversal.margin:g} N, for "
            f"{reversal.time:g} s): {'held' if out['held'] else 'not held'}; travel "
            f"{out['travel']!r} m ({where}; held: < {reversal.travel:g} m and a finger "
            f"touching at the end); touching: {', '.join(out['touching']) or 'nothing'}; "
            f"logged: {said}")


def _joint_turn(scenario, log) -> str:
    """The object's turn on its joint (``object.joint_position``) over the run, counted from
    the script's first keyframe (the first sample at or after it; an in-hand trial's
    motion starts there, after the settle) or from the start."""
    import math

    import numpy as np

    times, q = log.sample_times(), log.data()[0]
    start = scenario.script[0].time if scenario.script else 0.0
    i = int(np.searchsorted(times, start - 1e-9))
    if i >= times.size:
        return "object joint: no sample after the script's first keyframe"
    turn = math.degrees(q[-1] - q[i])
    return (f"object joint (object.joint_position): turned {turn!r} deg from t = "
            f"{times[i]:g} s to {times[-1]:g} s")


def _warn_below_table(scenario, z) -> None:
    """A run whose object ends under the table top is not what happened on a real table:
    it fell off the edge, or a hand pressing down drove it through the top (point contact
    gives way under forces far beyond the object's weight). Said, not left to be read
    from a height."""
    import warnings

    if scenario.table is None or scenario.object is None or scenario.object.fixed:
        return
    top = scenario.table.top_height
    if z[0] >= top and z[-1] < top - 0.01:
        warnings.warn(f"object.position: the object ended at z = {z[-1]:.3f} m, below the "
                      f"table top ({top:.3f} m): it fell off the table or the hand pushed it "
                      f"through the top (check the script's wrist heights)", stacklevel=2)


def _check_duration(duration: float, scenario) -> None:
    import dataclasses

    from handle_drake.scenario import validate_scenario

    try:
        validate_scenario(dataclasses.replace(scenario, simulation_duration=duration))
    except ValueError as error:
        raise ValueError(f"--duration: {error}") from None


def _cmd_demo(args) -> int:
    from handle_drake.apps.demo import run_demo

    meshcat = start_meshcat(args.meshcat or not args.no_html)
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
    _add_diagrams(subparsers)
    for module_name in AREA_COMMANDS:
        importlib.import_module(module_name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    pin_blas(force=False)  # before the area modules load numpy (build_parser imports them)
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
