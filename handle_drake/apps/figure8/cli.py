"""``handle-drake instruments``: the Figure 8 experiments (report section 3.4).

``handle-drake instruments [--device joywarrior wiimote] [--quick] [--seed N]
[--plot F] [--json F] [--meshcat] [--html F] [--write-scenarios DIR]``: plans
the JoyWarrior tripod and Wiimote parallel-extension grasps, rotates each
device with the wrist, opens the hand, and prints the roll/pitch errors of the
device's own accelerometer against the plant's truth, the false alarms while
held and the free-fall detection delay (exit code 0 when every device was held
through the rotations, raised no false alarm and its fall was detected).
``--write-scenarios diagrams`` regenerates ``diagrams/instrumented_*.yaml``.

Register with ``register(subparsers)`` (``handle_drake.cli.AREA_COMMANDS``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

__all__ = ["register"]

QUICK_ROTATIONS = ((25.0, 0.0), (0.0, 0.0))


def register(subparsers) -> None:
    from handle_drake.apps.figure8.experiments import SETUPS

    p = subparsers.add_parser(
        "instruments", help="Figure 8: rotate instrumented objects in the hand, measure them")
    p.add_argument("--device", nargs="+", default=list(SETUPS), choices=list(SETUPS),
                   help="which experiments (default: all)")
    p.add_argument("--quick", action="store_true",
                   help="one rotation instead of four (a short run)")
    p.add_argument("--seed", type=int, default=0, help="accelerometer noise and bias seed")
    p.add_argument("--plot", type=Path, default=Path("out/instruments_figure8.png"),
                   help="figure: estimated vs true roll and pitch (default %(default)s)")
    p.add_argument("--json", type=Path, default=None, help="write the summaries as JSON")
    p.add_argument("--meshcat", action="store_true", help="show it live in Meshcat")
    p.add_argument("--html", type=Path, default=None,
                   help="save HTML replays (one per device: NAME_<device>.html)")
    p.add_argument("--write-scenarios", type=Path, default=None, metavar="DIR",
                   help="write the experiments' scenario files to DIR and stop")
    p.set_defaults(func=_cmd_instruments)


def _cmd_instruments(args) -> int:
    from handle_drake.apps.figure8.experiments import (
        ROTATIONS_DEG,
        plot_figure8,
        run_figure8,
        summary_table,
        write_scenarios,
    )

    if not 0 <= args.seed < 2 ** 32:
        raise ValueError(f"--seed: expected an integer in [0, 2**32), got {args.seed}")
    if args.write_scenarios is not None:
        args.write_scenarios.mkdir(parents=True, exist_ok=True)
        for path in write_scenarios(args.write_scenarios, seed=args.seed):
            print(f"wrote {path}")
        return 0
    from handle_drake.apps.cli_support import start_meshcat

    meshcat = start_meshcat(args.meshcat or args.html is not None)
    rotations = QUICK_ROTATIONS if args.quick else ROTATIONS_DEG
    results = []
    for device in args.device:
        html = None
        if args.html is not None:
            html = args.html.with_name(f"{args.html.stem}_{device}{args.html.suffix or '.html'}")
        results.append(run_figure8(device, rotations, seed=args.seed, meshcat=meshcat,
                                   html=html))
        if html is not None:
            print(f"replay written to {html}")
    print(summary_table(results))
    summaries = [r.summary() for r in results]
    for s in summaries:
        print(f"{s['device']}: at-rest flag on in {100 * s['at_rest_flag_at_rest']:.0f} % of the "
              f"rest phases, {100 * s['at_rest_flag_moving']:.0f} % while moving; free fall "
              f"from {s['release_time']:.3f} s flagged at {s['free_fall_detected']:.3f} s; "
              f"simulated {s['sim_time']:.1f} s in {s['wall_time']:.1f} s")
    print(f"plot: {plot_figure8(results, args.plot)}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summaries, indent=2))
        print(f"summaries: {args.json}")
    ok = all(s["held_through_rotations"] and not s["false_free_fall_held"]
             and not s["false_slip_held"] and math.isfinite(s["detection_delay_ms"])
             for s in summaries)
    return 0 if ok else 1
