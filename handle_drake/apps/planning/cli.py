"""``handle-drake grasp`` and ``handle-drake synergies``.

- ``grasp --class tripod --object cuboid --size 0.04 [--reactive | --open-loop]
  [--meshcat] [--html F]``: plans a grasp of the class on the object (resting
  on the table at the origin), simulates reach, close and lift on the
  floating-wrist station and prints whether the object held (exit code 0
  held, 1 dropped). ``--reactive`` executes the plan with the tactile
  :class:`~handle_drake.systems.reactive_grasp.ReactiveGrasp` controller
  (report section 3.3; see :mod:`handle_drake.apps.planning.execution`),
  ``--open-loop`` with the plan's keyframe script; the default is
  :data:`DEFAULT_REACTIVE`.
- ``synergies [FILE] [--k-max 8] [--plot F]``: fits PCA synergies to a
  ``handle_drake-grasps`` recording file (default: the shipped synthetic data),
  prints the reconstruction error against k and saves a plot.

Register with ``register(subparsers)`` (``handle_drake.cli.AREA_COMMANDS``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from handle_drake.apps.cli_support import add_mesh_arguments
from handle_drake.trial.plans import plan_scenario_yaml

__all__ = ["DEFAULT_REACTIVE", "register", "run_grasp", "write_class_scenarios"]

#: Execution used when neither --reactive nor --open-loop is given. Open loop:
#: on the nominal plans of benchmarks/bench_grasp_classes.py both held 41/80
#: (different cases), so the reactive controller is an option, not the default.
DEFAULT_REACTIVE = False

#: The object each class's scenario in ``diagrams/`` grasps: (kind, catalogue size m).
CLASS_OBJECTS = {
    "palmar_pinch": ("cuboid", 0.0667),  # grasp width (cuboid depth) 40 mm
    "tip_pinch": ("cuboid", 0.0367),  # 22 mm
    "tripod": ("cuboid", 0.075),  # 45 mm
    "writing_tripod": ("sphere", 0.024),
    "lateral": ("cuboid", 0.028),  # 16.8 mm, a thin box
    "lateral_tripod": ("cuboid", 0.0417),  # 25 mm
    "adduction_grip": ("cuboid", 0.025),  # 15 mm (a 10 mm sphere's plan does not lift)
    "parallel_extension": ("cuboid", 0.075),  # 45 mm
}


def register(subparsers) -> None:
    p = subparsers.add_parser("grasp", help="plan a grasp of one class, simulate, lift, report")
    p.add_argument("--class", dest="grasp_class", required=True,
                   help="grasp class (palmar_pinch tip_pinch tripod writing_tripod lateral "
                        "lateral_tripod adduction_grip parallel_extension)")
    p.add_argument("--object", default=None,
                   help="sphere, cylinder, cuboid (box, the default), or an instrumented device: "
                        "joywarrior, wiimote, nunchuk, sixaxis (planned on its bounding box, "
                        "lying flat)")
    p.add_argument("--size", type=float, default=None,
                   help="catalogue size (m): diameter, or the cuboid's width (required "
                        "unless --mesh; a device's default: its published size)")
    add_mesh_arguments(p, "grasp your own object, a mesh file (OBJ, STL, PLY, ...), instead of "
                          "--object; planned on its bounding box (see grasp.planning)")
    p.add_argument("--mass", type=float, default=None, help="mesh object mass (kg)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--reactive", dest="reactive", action="store_true", default=None,
                      help="tactile reactive approach and closing (ReactiveGrasp)")
    mode.add_argument("--open-loop", dest="reactive", action="store_false",
                      help="the plan's keyframe script, no feedback")
    p.add_argument("--meshcat", action="store_true", help="show it live in Meshcat")
    p.add_argument("--html", type=Path, default=None, help="save a self-contained HTML replay")
    p.add_argument("--save-scenario", type=Path, default=None,
                   help="write the planned scenario YAML here")
    p.add_argument("--xy", type=float, nargs=2, default=(0.0, 0.0), metavar=("X", "Y"),
                   help="where the object rests on the table (m, default 0 0)")
    p.add_argument("--yaw", type=float, default=0.0, help="object yaw on the table (deg)")
    p.add_argument("--perceived", action="store_true",
                   help="plan on what the tabletop Kinect sees (pose and size from "
                        "handle_drake.devices.camera), execute on the true object")
    p.add_argument("--pose-error", type=float, nargs=2, default=None, metavar=("DX", "DY"),
                   help="plan on the object at --xy, execute on it DX DY (m) further: a "
                        "position error the reactive controller has to cope with")
    p.add_argument("--recentre", action="store_true",
                   help="reactive close: the first touch locates the object and the hand "
                        "moves onto it (ReactiveGraspParams.max_recentres = 1; off by default; "
                        "implies --reactive)")
    p.set_defaults(func=_cmd_grasp)

    s = subparsers.add_parser("synergies", help="fit synergies to recorded grasps, error vs k")
    s.add_argument("file", nargs="?", default=None,
                   help="handle_drake-grasps CSV (default: the shipped synthetic data)")
    s.add_argument("--k-max", type=int, default=8,
                   help="largest number of synergies fitted (default 8)")
    s.add_argument("--plot", type=Path, default=Path("out/synergies_error_vs_k.png"),
                   help="figure of the error vs k (default out/synergies_error_vs_k.png)")
    s.set_defaults(func=_cmd_synergies)


def run_grasp(grasp_class: str, kind, size: float | None, meshcat=None, html=None,
              save_scenario=None, reactive: bool | None = None, xy=(0.0, 0.0),
              yaw: float = 0.0, perceived: bool = False, pose_error=None,
              recentre: bool = False):
    """Plan, simulate, lift; returns ``(plan, result, held)``.

    kind: a catalogue kind with its ``size`` (m), or a ``MeshObjectSpec``
    (``size`` None).
    reactive: execute with :class:`ReactiveGrasp` (True) or the plan's
    keyframes (False); None: :data:`DEFAULT_REACTIVE`. The object rests at
    ``xy`` (m) with ``yaw`` (rad). perceived: plan on the object's pose and
    size as the tabletop camera estimates them
    (:func:`handle_drake.apps.perception.grasping.perceive_object`), execute on the
    true object; the returned plan then carries ``plan.perception``.
    pose_error: ``(dx, dy)`` (m): the plan sees the object at ``xy``, the
    world holds it at ``xy + pose_error`` (a catalogue object). recentre: the
    reactive close re-centres on the object its first touch locates
    (``max_recentres=1``; reactive execution, which it implies when
    ``reactive`` is None).
    """
    import numpy as np

    from handle_drake.apps.planning.execution import run_plan
    from handle_drake.grasp.planning import plan_grasp, resting_pose
    from handle_drake.trial.simulate import held_through_lift

    if recentre and reactive is False:
        raise ValueError("--recentre: the re-centring is part of the reactive close; it does "
                         "not apply to --open-loop")
    if pose_error is not None:
        error = np.asarray(pose_error, dtype=float)
        if error.shape != (2,) or not np.isfinite(error).all() or np.abs(error).max() > 0.1:
            raise ValueError(f"--pose-error: expected two finite offsets of at most 0.1 m, got "
                             f"{pose_error}")
        if perceived:
            raise ValueError("--pose-error: with --perceived the error is the camera's own; "
                             "give one or the other")
        if getattr(kind, "kind", None) == "mesh":
            raise ValueError("--pose-error: moves a catalogue object (--object); a --mesh "
                             "object is not supported")
    world_object = perception = None
    if perceived:
        from pydrake.common.schema import Transform

        from handle_drake.apps.perception.grasping import perceive_object
        from handle_drake.scenario import ObjectConfig

        perception = perceive_object(kind, size, xy=xy, yaw=yaw)
        plan = plan_grasp(grasp_class, (kind, perception.size), perception.X_WO)
        world_object = ObjectConfig(kind=kind, size=size, X_WO=Transform(perception.true_X_WO),
                                    on_table=False)
    else:
        obj = kind if getattr(kind, "kind", None) == "mesh" else (kind, size)
        plan = plan_grasp(grasp_class, obj, resting_pose(kind, size, xy=xy, yaw=yaw))
        if pose_error is not None:
            from pydrake.common.schema import Transform

            from handle_drake.scenario import ObjectConfig

            true_xy = np.asarray(xy, dtype=float) + np.asarray(pose_error, dtype=float)
            world_object = ObjectConfig(
                kind=kind, size=size, on_table=False,
                X_WO=Transform(resting_pose(kind, size, xy=true_xy, yaw=yaw)))
    plan.perception = perception
    if save_scenario is not None:
        Path(save_scenario).parent.mkdir(parents=True, exist_ok=True)
        Path(save_scenario).write_text(plan_scenario_yaml(plan))
    if reactive is None:
        reactive = True if recentre else DEFAULT_REACTIVE
    reactive = bool(reactive)
    params = None
    if recentre:
        from handle_drake.apps.planning.execution import plan_params

        params = plan_params(plan, max_recentres=1)
    result = run_plan(plan, reactive=reactive, meshcat=meshcat,
                      html=html if meshcat is not None else None, world_object=world_object,
                      params=params)
    return plan, result, held_through_lift(result)


def _cmd_grasp(args) -> int:
    import math

    from handle_drake.apps.cli_support import refuse_without_mesh, start_meshcat
    from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS

    refuse_without_mesh(args, "--mesh-scale", "--mass")
    if args.mesh is None:
        args.object = args.object or "cuboid"
    if args.mesh is not None:
        from handle_drake.geometry.objects.mesh import MeshObjectSpec

        if args.object is not None:
            raise ValueError(f"--object {args.object}: give either --object or --mesh, not both")
        if args.perceived:
            raise ValueError("--perceived: the tabletop detector fits spheres, cylinders and "
                             "boxes; it cannot plan on a --mesh object")
        if args.size is not None:
            raise ValueError("--size: a mesh's size comes from its file; use --mesh-scale")
        obj = MeshObjectSpec(str(args.mesh), scale=args.mesh_scale or 1.0, mass=args.mass)
    elif args.object in DEVICE_OBJECTS and args.perceived:
        raise ValueError(f"--perceived: the tabletop detector fits spheres, cylinders and "
                         f"boxes; it cannot plan on a {args.object}")
    elif args.size is None and args.object not in DEVICE_OBJECTS:
        raise ValueError("--size: required for a catalogue object (or give --mesh FILE)")
    else:
        obj = args.object
        if args.size is None:  # an instrumented device: its published size
            args.size = DEVICE_OBJECTS[obj].default_size
    meshcat = start_meshcat(args.meshcat or args.html is not None)
    plan, result, held = run_grasp(args.grasp_class, obj, args.size, meshcat,
                                   args.html, args.save_scenario, args.reactive,
                                   xy=tuple(args.xy), yaw=math.radians(args.yaw),
                                   perceived=args.perceived, pose_error=args.pose_error,
                                   recentre=args.recentre)
    if plan.perception is not None:
        e = plan.perception.errors()
        yaw = "n/a (sphere)" if e["yaw_deg"] is None else f"{e['yaw_deg']:+.1f} deg"
        print(f"perceived by the tabletop Kinect: size {plan.perception.size * 100:.2f} cm "
              f"(true {args.size * 100:.2f}); error xy {e['xy_mm']:.1f} mm, "
              f"z {e['z_mm']:+.1f} mm, yaw {yaw}")
        print(f"perception: {plan.perception.selection}")
    print(plan.summary())
    reactive = (args.recentre or DEFAULT_REACTIVE) if args.reactive is None else args.reactive
    print(f"execution: {'reactive (tactile)' if reactive else 'open loop (keyframes)'}"
          + (", re-centring on the first touch" if args.recentre else ""))
    if args.pose_error is not None:
        print(f"the object is {args.pose_error[0] * 1e3:+.1f}, {args.pose_error[1] * 1e3:+.1f} mm "
              "from where the plan thinks")
    if plan.amplitudes is not None:
        print(f"synergy pre-shape amplitudes: {[round(float(a), 3) for a in plan.amplitudes]}")
    print(f"{'HELD' if held else 'DROPPED'}: object rose {result.object_lift() * 100:.1f} cm "
          f"(simulated {result.sim_time:.1f} s in {result.wall_time:.1f} s)")
    if args.html:
        print(f"replay written to {args.html}")
    return 0 if held else 1


def _cmd_synergies(args) -> int:
    from handle_drake.base.hands import get_hand_spec
    from handle_drake.grasp.analysis import fit_record_synergies, reconstruction_table
    from handle_drake.grasp.recordings import load_grasps
    from handle_drake.grasp.synergies import reconstruction_error_vs_k
    from handle_drake.grasp.synthetic import DATA_FILE

    spec = get_hand_spec("shadow")
    path = Path(args.file) if args.file else DATA_FILE
    records = load_grasps(path, (spec.joint_lower_limits, spec.joint_upper_limits))
    if not 1 <= args.k_max <= spec.num_actuated:
        raise ValueError(f"--k-max must be in [1, {spec.num_actuated}], got {args.k_max}")
    syn = fit_record_synergies(records)
    print(f"{len(records)} grasps from {path}; k for 95% variance: {syn.k}\n")
    print(reconstruction_table(records, k_max=args.k_max))
    res = reconstruction_error_vs_k(records.q, spec.joint_names, spec.actuated_joint_names,
                                    k_max=args.k_max)
    _plot_error(res, args.plot)
    print(f"\nplot: {args.plot}")
    return 0


def _plot_error(res, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
    ax[0].plot(res["k"], res["train_rms"], "o-", label="train")
    ax[0].plot(res["k"], res["test_rms"], "s-", label="5-fold test")
    ax[0].set_xlabel("k (synergies)")
    ax[0].set_ylabel("RMS joint error (rad)")
    ax[0].legend()
    ax[1].plot(res["k"], res["explained"], "o-")
    ax[1].set_xlabel("k")
    ax[1].set_ylabel("explained variance")
    ax[1].set_ylim(0, 1.02)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_class_scenarios(directory: Path) -> list[Path]:
    """Plan each class on its ``CLASS_OBJECTS`` object; write ``grasp_<class>.yaml``."""
    from handle_drake.grasp.planning import plan_grasp, resting_pose

    Path(directory).mkdir(parents=True, exist_ok=True)
    out = []
    for name, (kind, size) in CLASS_OBJECTS.items():
        plan = plan_grasp(name, (kind, size), resting_pose(kind, size))
        path = Path(directory) / f"grasp_{name}.yaml"
        header = ("# Planned by handle_drake.grasp.planning "
                  "(python -m handle_drake.apps.planning.cli "
                  f"--write-scenarios diagrams):\n# {plan.summary()}\n"
                  f"# Run: handle-drake simulate {path.name}\n")
        path.write_text(header + plan_scenario_yaml(plan))
        out.append(path)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="grasp scenarios")
    parser.add_argument("--write-scenarios", type=Path, required=True)
    args = parser.parse_args(argv)
    for path in write_class_scenarios(args.write_scenarios):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
