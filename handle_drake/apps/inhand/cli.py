"""``handle-drake inhand``: in-hand manipulation by action-gist guided motor babbling.

Examples::

    handle-drake inhand --task cylinder_rotation --optimizer ipso --trials 1000 --seed 0
    handle-drake inhand --task star_rotation --optimizer cmaes --trials 100 --workers 2 \\
        --db out/inhand/star.sqlite
    handle-drake inhand --optimizer ipso --trials 1000 --executor dask://head:8786

Every trial goes to the SQLite log ``--db``; running the same command again
resumes the run. The particles of one iteration run in parallel on
``--executor`` (as for ``handle-drake babble``: ``local`` processes, a ``dask``
LocalCluster of ``--workers`` processes, or ``dask://HOST:PORT``, the workers
of a running ``dask scheduler``); a run depends only on its seed, not on where
its trials ran. The run stops when a trial reaches the target (held at the
end, rotated by ``--target-deg``) or after ``--trials``. It writes the learning
curve (best score per iteration, Figure 34) and an HTML replay of the best
trial next to the log. Scores are maximised. Bad arguments exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handle_drake.apps.cli_support import (
    float_in,
    int_in,
    non_empty,
    positive_int,
    run_command,
    seed_int,
)
from handle_drake.apps.inhand.experiment import MAX_PARTICLES
from handle_drake.apps.inhand.jog_wheel import JogWheelTask
from handle_drake.apps.inhand.screw_cap import DEFAULT_PLACEMENT, PLACEMENTS, TWO_STROKES
from handle_drake.apps.inhand.sensed import SCORES
from handle_drake.apps.inhand.task import EVALUATIONS, TASKS
from handle_drake.devices.accelerometer.profiles import PROFILES
from handle_drake.learning.cluster import add_executor_arguments
from handle_drake.learning.optim.population import INHAND_OPTIMIZERS

__all__ = ["register", "main", "MAX_GAITS", "MAX_TRIALS"]

#: --gaits: the regrasp placement turns 360 deg in 5 gaits; 12 is past two turns.
MAX_GAITS = 12
#: --trials: the report's longest runs are 1000 trials.
MAX_TRIALS = 100_000


def _add_robust_arguments(p) -> None:
    """Domain randomisation of the finger tasks (issue 45 item 3)."""
    p.add_argument("--robust", type=int_in(0, 64), default=0, metavar="K",
                   help="screw_cap / fingertip_cylinder: score each trial by its worst over K "
                        "perturbed physics drawn per trial (step, friction +-30 %%, mass +-20 "
                        "%%, thread 0.01-0.1 N m, effort limits down to half, placement +-2 mm; "
                        "ScrewCapTask.perturb_*); then print the best trial's success over "
                        "--fresh fresh perturbations. Default 0: the nominal physics only")
    p.add_argument("--fresh", type=int_in(1, 1000), default=20, metavar="N",
                   help="with --robust: fresh perturbations the best trial is tried on (20)")
    # checked by _task_options (a one-line error naming the flag, exit 2)
    p.add_argument("--score", default="plant", metavar="{" + ",".join(SCORES) + "}",
                   help="screw_cap / fingertip_cylinder: plant (default: the cap's joint, the "
                        "cylinder's pose) or estimated: the turn from what the hand senses "
                        "alone (taxels and joints; with --accelerometer the object's gravity "
                        "direction), apps/inhand/sensed.py; the plant's turn is logged beside")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "inhand", help="learn an in-hand rotation by action-gist guided babbling (PSO & co.)",
        description=__doc__.split("\n\n")[0])
    p.add_argument("--task", choices=sorted([*TASKS, "screw_cap", "fingertip_cylinder",
                                             "jog_wheel"]),
                   default="cylinder_rotation",
                   help="cylinder_rotation, star_rotation: palm up, the object lies across "
                        "the palm, which supports it; held only if it survives its weight "
                        "reversed for 0.5 s at the end (the palm's share of the weight "
                        "logged); screw_cap: the report's Fig. 32, a cap on a fixed bottle "
                        "turned by the fingers (score: the cap joint's encoder turn; "
                        "--target-deg default 90); "
                        "fingertip_cylinder: a free cylinder pinched by thumb and fingers, held "
                        "only if it survives its weight reversed at the end (default 100, in two "
                        "strokes: --strokes); "
                        "jog_wheel: the iControls Pro's jog wheel turned by a pinch, scored "
                        "from its MIDI ticks alone, the true wheel angle logged beside "
                        "(default 75, above the demonstration's 61.9)")
    p.add_argument("--gaits", type=int_in(1, MAX_GAITS), default=None,
                   help="screw_cap: repetitions of the gait (grip, turn, release, regrasp); "
                        "default 1 (the placement's)")
    p.add_argument("--placement", choices=sorted(PLACEMENTS), default=None,
                   help="screw_cap: the cap and grasp. Default clear (issue 45: the four "
                        "fingers on a 100 mm cap, no finger wedged against the welded bottle, "
                        "Menagerie's 1 N m finger limits, 1 ms: the one whose physics "
                        "converges). The earlier ones, whose turns come from a finger wedged "
                        "against the bottle: one-gait (first and ring finger on the cap), "
                        "four-finger-turn (thumb, first, middle and ring finger; the fingers "
                        "turn it), four-finger (FOUR_FINGER_GRIP: four digits, squeezed: they "
                        "jam), regrasp (5 gaits, 360 deg); clear-gaits: clear's cap, "
                        "one learned gait repeated 3 times, 360 deg")
    p.add_argument("--grip-digits", type=positive_int, default=None, metavar="N",
                   help="screw_cap: digits (thumb and fingers) that must each touch the cap "
                        "within the contact window at a check (default 1: any finger)")
    p.add_argument("--strokes", type=int, choices=(1, 2), default=None,
                   help="fingertip_cylinder: 2 (default) = the learning task (TWO_STROKES: the "
                        "gist twice in sequence, each stroke its own parameters, 100 deg held, "
                        "the turn counted only while held; base rate 0.34 %%); 1 = the 60 deg "
                        "pinch in one stroke (base rate 1.5-3.5 %%: random search reaches it "
                        "about as fast as any swarm)")
    _add_robust_arguments(p)
    p.add_argument("--optimizer", choices=INHAND_OPTIMIZERS, default="ipso",
                   help="ipso: Algorithm 2 (incremental PSO, docs/inhand.md's interpretation); "
                        "ipso-gist: ipso seeded by the gist's start times (5.4); "
                        "ipso-report: its literal settings (w = phi = 0.4); ipso-restart: "
                        "with the restarts of 5.5.4; pso: standard PSO; cmaes: CMA-ES; "
                        "random: random search")
    p.add_argument("--trials", type=int_in(1, MAX_TRIALS), default=200,
                   help="budget of trials (the run stops earlier at the target)")
    p.add_argument("--workers", type=int_in(1, 1024), default=1,
                   help="worker processes of 'local' and 'dask' (default 1: trials run in this "
                        "process); the particles of one iteration run in parallel. With "
                        "dask://, the cluster's workers")
    add_executor_arguments(p)
    p.add_argument("--seed", type=seed_int, default=0,
                   help="the run's seed (optimizer and trial noise; default 0)")
    p.add_argument("--particles", type=int_in(1, MAX_PARTICLES), default=10,
                   help="particles per iteration (CMA-ES: population)")
    p.add_argument("--target-deg", type=float_in(0, 360), default=None,
                   help="rotation the object must reach, held, at the end (deg; default 30, "
                        "the screw cap 90)")
    p.add_argument("--evaluation", choices=EVALUATIONS, default="incremental",
                   help="incremental: eqs. 47-49 with early stop; old: held time + rotation")
    p.add_argument("--accelerometer", choices=sorted(PROFILES), default=None, metavar="DEVICE",
                   help="make the object the report's instrumented object: this accelerometer "
                        f"({', '.join(sorted(PROFILES))}) at its origin also measures the "
                        "rotation (logged per trial; valid at rest)")
    p.add_argument("--db", type=Path, default=Path("out/inhand/inhand.sqlite"),
                   help="SQLite trial log (default out/inhand/inhand.sqlite); the same "
                        "command again resumes its run")
    p.add_argument("--run-id", type=non_empty, default=None,
                   help="name of the run in the log (default: task, optimizer, particles, "
                        "seed and a fingerprint of every other setting)")
    p.add_argument("--plot", type=Path, default=None, metavar="PNG",
                   help="learning curve (default <db folder>/<run id>.png)")
    p.add_argument("--html", type=Path, default=None,
                   help="HTML replay of the best trial (default <db folder>/<run id>.html)")
    _add_after_run_arguments(p)
    p.set_defaults(func=_cmd_inhand)


def _add_after_run_arguments(p) -> None:
    """What the command writes and does once the run is over."""
    p.add_argument("--no-plot", action="store_true", help="write no learning curve")
    p.add_argument("--no-html", action="store_true", help="write no replay of the best trial")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--hardware", type=_host_port, default=None, metavar="HOST:PORT",
                   help="after learning, replay the best trial's motion on the CAN hand behind "
                        "the CAN bus server at HOST:PORT, in real time (its logged scenario "
                        "with the driver !CanHandDriver; checked before any trial runs). The "
                        "same as: handle-drake simulate DB --hardware --override 'driver: "
                        "!CanHandDriver {host: HOST, port: PORT}'")


def _host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` of ``--hardware``."""
    host, _, port = str(text).rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (port 1-65535), got {text!r}")
    return host, int(port)


def _can_override(address) -> str:
    return f"driver: !CanHandDriver {{host: '{address[0]}', port: {address[1]}}}"


def _check_hardware(args) -> None:
    """``--hardware``: a task whose hand is on a fixed mount, and the server answering."""
    if args.hardware is None:
        return
    if args.task == "jog_wheel":
        raise ValueError("--hardware: the jog wheel's hand is on a floating wrist; the CAN hand "
                         "has none (only the fixed-mount tasks)")
    from handle_drake.apps.cli_support import check_hardware_server
    from handle_drake.scenario import LoadScenario

    check_hardware_server(LoadScenario(data=_can_override(args.hardware)))


def _replay_on_hardware(args, run) -> None:
    """The run's best trial, from its logged scenario, on the CAN hand in real time (with
    ``--hardware``)."""
    if args.hardware is None:
        return
    from handle_drake.scenario import LoadScenario
    from handle_drake.trial.simulate import ScenarioRunner

    best = max((r for r in run.records if r.status == "done"), key=lambda r: r.metric)
    scenario = LoadScenario(text=best.scenario, data=_can_override(args.hardware),
                            source=f"{args.db}, trial {best.index}")
    result = ScenarioRunner(scenario, hardware=True).run()
    print(f"replayed trial {best.index} on the CAN hand at {args.hardware[0]}:"
          f"{args.hardware[1]}: {result.sim_time:.2f} s in {result.wall_time:.2f} s")


def _task_options(args) -> dict:
    """The task's settings from the command line (refusing flags of other tasks)."""
    if args.strokes is not None and args.task != "fingertip_cylinder":
        raise ValueError(f"--strokes: only with --task fingertip_cylinder, got --task "
                         f"{args.task}")
    if args.score not in SCORES:
        raise ValueError(f"--score: expected one of {', '.join(SCORES)}, got {args.score!r}")
    if args.score != "plant" and args.task not in ("screw_cap", "fingertip_cylinder"):
        raise ValueError(f"--score {args.score}: only with --task screw_cap or "
                         f"fingertip_cylinder")
    if args.placement is None:  # the screw cap's default: the one whose physics converges
        args.placement = DEFAULT_PLACEMENT if args.task == "screw_cap" else "one-gait"
    # the placement is the screw cap's alone (the fingertip cylinder has no bottle)
    preset = PLACEMENTS[args.placement] if args.task == "screw_cap" else {}
    if args.placement != "one-gait" and args.task != "screw_cap":
        raise ValueError(f"--placement {args.placement}: only with --task screw_cap")
    if args.robust and args.task not in ("screw_cap", "fingertip_cylinder"):
        raise ValueError(f"--robust {args.robust}: only with --task screw_cap or "
                         f"fingertip_cylinder")
    if args.grip_digits is not None and (args.task != "screw_cap" or args.grip_digits > 5):
        raise ValueError(f"--grip-digits {args.grip_digits}: 1..5, only with --task screw_cap")
    if args.task == "jog_wheel":
        if args.accelerometer or args.evaluation != "incremental" or args.gaits not in (None, 1):
            raise ValueError("--task jog_wheel: the incremental evaluation from MIDI only (no "
                             "--accelerometer, --evaluation old, --gaits)")
        options = dict(progress=not args.no_progress,
                       target_deg=JogWheelTask.target_deg if args.target_deg is None
                       else args.target_deg)
    elif args.task in ("screw_cap", "fingertip_cylinder"):
        if (args.accelerometer and args.score != "estimated") \
                or args.evaluation != "incremental":
            raise ValueError(f"--task {args.task}: the incremental evaluation only (no "
                             "--evaluation old; --accelerometer only with --score estimated)")
        default = preset.get("target_deg", 90.0) if args.task == "screw_cap" else 60.0
        options = dict(preset, progress=not args.no_progress,
                       n_gaits=preset.get("n_gaits", 1) if args.gaits is None else args.gaits)
        if args.task == "fingertip_cylinder" and args.strokes in (None, 2):
            options.update({k: v for k, v in TWO_STROKES.items() if k != "free"})
            default = TWO_STROKES["target_deg"]
        options["target_deg"] = default if args.target_deg is None else args.target_deg
        if args.grip_digits is not None:
            options["grip_digits"] = args.grip_digits
        if args.robust:
            options["robust_k"] = args.robust
        if args.score != "plant":
            options.update(score=args.score, accelerometer=args.accelerometer or "")
    else:
        if args.gaits is not None:
            raise ValueError(f"--gaits {args.gaits}: only with --task screw_cap or "
                             f"fingertip_cylinder")
        options = dict(progress=not args.no_progress, evaluation=args.evaluation,
                       target_deg=30.0 if args.target_deg is None else args.target_deg)
    return options


def _print_estimate(args, run) -> None:
    """``--score estimated``: the best trial's estimated turn beside the plant's (never in
    the score)."""
    if args.score != "estimated":
        return
    best = max((r for r in run.records if r.status == "done"), key=lambda r: r.metric)
    detail = best.contacts if isinstance(best.contacts, dict) else {}
    if "turn_deg_truth" in detail:
        print(f"best trial's turn: {detail['turn_deg']:.1f} deg estimated, "
              f"{detail['turn_deg_truth']:.1f} deg the plant's (not scored)")


def _cmd_inhand(args) -> int:
    from handle_drake.apps.inhand.experiment import plot_learning_curve, replay_best, run_inhand
    from handle_drake.learning.cluster import trial_executor
    from handle_drake.learning.log import TrialLog, TrialLogError

    for flag, path, suffix in (("--plot", args.plot, ".png"), ("--html", args.html, ".html")):
        if path is not None and path.suffix.lower() != suffix:
            raise ValueError(f"{flag}: expected a {suffix} file name, got {str(path)!r}")
    options = _task_options(args)  # every refusal before the log is created
    _check_hardware(args)
    if args.db.exists():
        try:
            TrialLog(args.db).close()  # refuses a corrupt or foreign file before any work
        except TrialLogError as error:
            raise ValueError(f"--db: {error}") from None
    args.db.parent.mkdir(parents=True, exist_ok=True)
    print(f"inhand: {args.task}, {args.optimizer}, seed {args.seed}, up to {args.trials} trials "
          f"in {args.db} ({args.executor} executor)", flush=True)
    if args.accelerometer:
        options["accelerometer"] = args.accelerometer
    if args.executor.kind == "local":  # run_inhand's own pool: workers build the trial first
        run = run_inhand(args.task, args.optimizer, args.trials, args.workers, args.seed,
                         args.db, args.particles, run_id=args.run_id, **options)
    else:  # dask: as many trials at once as the cluster has workers
        with trial_executor(args.executor, args.workers,
                            connect_timeout=args.connect_timeout) as executor:
            run = run_inhand(args.task, args.optimizer, args.trials, None, args.seed,
                             args.db, args.particles, executor=executor, run_id=args.run_id,
                             **options)
    s = run.summary()
    print(f"trials: {s['done']} done, {s['failed']} failed")
    if "best_score" not in s:
        print("no successful trial")
        return 1
    reached = (f"target reached at trial {s['trials_to_target']}" if s["trials_to_target"]
               else "target not reached")
    # a wheel on its axle or a cap on its thread: nothing to hold (best_held None); held
    # means held: the object survived its weight reversed plus the stated margin
    held = ("" if s.get("best_held") is None else
            f"{'held' if s['best_held'] else 'not held'} at the end (weight reversed + "
            f"margin); ")
    share = ("" if s.get("share_held") is None else
             f"; {100 * s['share_held']:.0f} % of trials held")
    leaned = ("" if "share_leaned" not in s else
              f"; best trial {'LEANED on' if s['best_leaned'] else 'did not lean on'} a welded "
              f"body, {100 * s['share_leaned']:.0f} % of trials leaned (> lean_force)")
    print(f"best score {s['best_score']:.4g} (target score {s['target_score']:g}), trial "
          f"{s['best_index']}: rotation {s['best_rotation_deg']:.1f} deg, {held}{reached}"
          + share + leaned)
    if s.get("best_digit_peak_normal"):
        print("best trial's peak normal force per digit (N, any step): " + ", ".join(
            f"{d} {v:.1f}" for d, v in s["best_digit_peak_normal"].items()))
    _print_estimate(args, run)
    if args.robust:
        from handle_drake.apps.inhand.screw_cap import fresh_success

        best = max((r for r in run.records if r.status == "done"), key=lambda r: r.metric)
        fresh = fresh_success(run.trial.config, best.parameters, args.fresh)
        print(f"best trial over {args.fresh} fresh perturbed physics (never used while "
              f"learning): reaches its target in {100 * fresh['success']:.0f} %; turns "
              f"{min(fresh['turns']):.1f}-{max(fresh['turns']):.1f} deg")
    _replay_on_hardware(args, run)
    if not args.no_plot:
        path = args.plot or args.db.parent / f"{run.run_id}.png"
        print(f"learning curve: {plot_learning_curve([run], path)}")
    if not args.no_html:
        html = args.html or args.db.parent / f"{run.run_id}.html"
        logged, outcome = replay_best(run, html)
        print(f"replay of the best trial: {html} (score {outcome.score:.4g}, logged "
              f"{logged:.4g})")
        if hasattr(outcome, "true_turn_deg"):
            print(f"its turn at the end: {outcome.turn_deg:.1f} deg (MIDI, "
                  f"{outcome.ticks:+d} ticks), {outcome.true_turn_deg:.1f} deg (plant)")
        if getattr(outcome, "accelerometer_rotation_deg_series", None):
            print(f"its rotation at the end: {outcome.rotation_deg:.1f} deg (plant), "
                  f"{outcome.accelerometer_rotation_deg_series[-1]:.1f} deg "
                  f"({args.accelerometer} accelerometer)")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="handle-drake")
    register(parser.add_subparsers(dest="command", required=True, metavar="COMMAND"))
    return run_command(parser, argv)


if __name__ == "__main__":
    sys.exit(main())
