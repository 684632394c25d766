"""The sensing hand (issue 47): the pose estimate's accuracy per grasp, the taxel images,
and the station's cost with taxels against without, in the same run.

- Accuracy: each grasp scenario runs with ``hand.taxels: {estimator: true}``; the
  estimator's prior (its initial state) is the object's start pose moved by
  ``PRIOR_OFFSET`` (8 mm, 8 deg), so it must find the object from touch. Errors are the
  RMS over the holding phase (from ``HOLD_FROM`` to the end, sampled at 20 Hz) against
  the plant's ``object.pose`` (read only here); each grasp runs twice, touch alone and
  with the object's accelerometer (``object.accelerometer: {}``, the JoyWarrior at the
  object's origin). Reported std: the estimate's covariance along its largest axis (the
  least observed direction), median over the phase, and the share of samples whose
  errors lie within twice it. Angle errors: cuboid the smallest over
  its symmetry (180 deg about each axis); sphere none (its rotation is not observable).
- The pick's carry (``--picks``): each kind picked once (true poses; sphere and cuboid
  from diagrams/hamburg_setup.yaml's development scene 0, the others from the shape
  sorter) with taxels at 20 Hz; the estimator's inputs recorded every 0.05 s and replayed
  through an estimator built from those ports alone (prior: the start pose moved by
  ``PRIOR_OFFSET``); errors over the carry (the lift's end to the release). Angles: the
  smallest over the kind's symmetries (:func:`angle_error`).
- Images: the taxel readings at the end of the run, one PNG per grasp.
- Cost: the demo grasp (2 s) with taxels (and with taxels and the estimator) against
  without, CPU time of this process, ``--rounds`` rounds in alternating order; the median
  of the per-round ratios.

Usage: ``python benchmarks/bench_sensing.py [--rounds N] [--quick] [--picks K,K]``
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource

from handle_drake.base.models import diagrams_dir
from handle_drake.base.results import ResultsRun, add_page_arguments
from handle_drake.scenario import LoadScenario
from handle_drake.station import MakeHandStation, hand_initial_command
from handle_drake.trial.simulate import script_trajectories

ROOT = Path(__file__).resolve().parents[1]
GRASPS = ("shadow_sphere_grasp.yaml", "grasp_writing_tripod.yaml", "grasp_adduction_grip.yaml",
          "grasp_tripod.yaml", "grasp_lateral_tripod.yaml", "grasp_palmar_pinch.yaml",
          "grasp_tip_pinch.yaml", "grasp_parallel_extension.yaml", "grasp_lateral.yaml")
#: the shape sorter's kinds (diagrams/sorter_setup.yaml), each picked once for the carry
PICK_KINDS = ("sphere", "cuboid", "cylinder", "rotated_cuboid", "mug", "wine_glass",
              "star_prism", "mesh")
HOLD_FROM = 1.3  # s: the hands have closed in every grasp scenario by then
PRIOR_OFFSET = RigidTransform(RollPitchYaw(np.radians([5.0, -4.0, 4.6])), [0.005, -0.004, 0.0045])
SYMMETRY = [RotationMatrix(), RotationMatrix.MakeXRotation(np.pi),
            RotationMatrix.MakeYRotation(np.pi), RotationMatrix.MakeZRotation(np.pi)]


def _build(scenario):
    builder = DiagramBuilder()
    station = builder.AddSystem(MakeHandStation(scenario, finite_commands=True))
    hand, wrist = script_trajectories(scenario, hand_initial_command(scenario))
    builder.Connect(builder.AddSystem(TrajectorySource(hand)).get_output_port(),
                    station.GetInputPort("hand.position"))
    builder.Connect(builder.AddSystem(TrajectorySource(wrist)).get_output_port(),
                    station.GetInputPort("wrist.pose"))
    return station, Simulator(builder.Build())


def angle_error(kind: str, R_truth: RotationMatrix, R_estimate: RotationMatrix) -> float:
    """The angle (rad) between two orientations of an object of ``kind``, the smallest over
    its symmetries: none for a sphere (nan), the axis's tilt for a cylinder or a wine
    glass, a fifth of a turn about the axis for the star prism, half turns for a cuboid."""
    if kind == "sphere":
        return np.nan
    R = R_truth.inverse() @ R_estimate
    if kind in ("cylinder", "wine_glass"):
        tilt = abs(float(np.arccos(np.clip(R.matrix()[2, 2], -1.0, 1.0))))
        return min(tilt, np.pi - tilt) if kind == "cylinder" else tilt
    turns = [RotationMatrix()] if kind in ("mug", "mesh") else SYMMETRY + (
        [RotationMatrix.MakeZRotation(k * 2 * np.pi / 5) for k in range(1, 5)]
        if kind == "star_prism" else [])
    return min(abs((R @ S).ToAngleAxis().angle()) for S in turns)


def accuracy(name: str, duration: float | None = None, accelerometer: bool = False):
    data = "hand: {taxels: {estimator: true}}"
    if accelerometer:
        data += "\nobject: {accelerometer: {}}"
    scenario = LoadScenario(filename=diagrams_dir() / name, data=data)
    station, simulator = _build(scenario)
    context = simulator.get_mutable_context()
    estimator = station.GetSubsystemByName("object_pose_estimator")
    est_context = estimator.GetMyMutableContextFromRoot(context)
    x = est_context.get_discrete_state_vector().value().copy()
    start = RigidTransform(__import__("pydrake.common.eigen_geometry", fromlist=["Quaternion"])
                           .Quaternion(x[:4] / np.linalg.norm(x[:4])), x[4:7])
    prior = start @ PRIOR_OFFSET
    x[:4] = prior.rotation().ToQuaternion().wxyz()
    x[4:7] = prior.translation()
    est_context.SetDiscreteState(x)
    sc = station.GetMyContextFromRoot(context)
    kind = scenario.object.kind
    rows = []
    end = duration or scenario.simulation_duration
    for t in np.arange(HOLD_FROM, end + 1e-9, 0.05):
        simulator.AdvanceTo(t)
        truth = station.GetOutputPort("object.pose").Eval(sc)
        estimate = station.GetOutputPort("object.pose_estimated").Eval(sc)
        dp = np.linalg.norm(truth.translation() - estimate.translation())
        angle = angle_error(kind, truth.rotation(), estimate.rotation())
        quality = station.GetOutputPort("object.pose_quality").Eval(sc)
        cov = station.GetOutputPort("object.pose_covariance").Eval(sc).reshape(6, 6)
        # the reported spread along its largest axis (the least observed direction)
        std_a, std_p = (np.sqrt(max(np.linalg.eigvalsh(cov[k:k + 3, k:k + 3]).max(), 0.0))
                        for k in (0, 3))
        rows.append((t, dp, angle, quality[0], truth.translation()[2], std_p, std_a))
    rows = np.array(rows)
    taxels = station.GetOutputPort("hand.taxels").Eval(sc)
    pads = station.GetSubsystemByName("taxels").pads
    return kind, rows, taxels, pads


def _record_pick(kind: str) -> dict:
    """One pick of ``kind`` (true poses; a sphere or cuboid of diagrams/hamburg_setup.yaml's
    development scene 0, the other kinds from the shape sorter, diagrams/sorter_setup.yaml)
    with the hand's taxels at 20 Hz, recording every 0.05 s the estimator's inputs (the
    hand's measured joints, the taxels, the hand base by the arm's measured joints' forward
    kinematics) and the target's pose (the plant's, to score only); the phase marks, the
    target's spec and whether it ended in the box."""
    import dataclasses as dc

    from handle_drake.apps.pick import cli, execute, touch
    from handle_drake.apps.pick.scenes import random_scene
    from handle_drake.devices.taxels.config import TaxelConfig
    from handle_drake.scenario import object_spec
    from handle_drake.scene.config import scene_objects
    from handle_drake.station import GetPlant

    if kind in ("sphere", "cuboid"):
        scenario = random_scene(LoadScenario(filename=diagrams_dir() / "hamburg_setup.yaml"), 0)
    else:
        scenario = LoadScenario(filename=diagrams_dir() / "sorter_setup.yaml")
    scenario = dc.replace(scenario, hand=dc.replace(scenario.hand, taxels=TaxelConfig(
        rate_hz=20.0)))
    record = {"samples": []}
    original = execute._build_diagram

    def build(station, scenario, plan, close):
        out = original(station, scenario, plan, close)
        plant = GetPlant(station)
        body = plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(plan.target))[0])
        config = dict(scene_objects(scenario))[plan.target]
        record.update(scenario=scenario, marks=dict(out[1]), plant=plant, body=body,
                      pads=station.GetSubsystemByName("taxels").pads,
                      spec=object_spec(dc.replace(scenario, object=config, objects=[])))
        return out

    def monitor(station, context):
        t = context.get_time()
        if record["samples"] and t - record["samples"][-1][0] < 0.05 - 1e-9:
            return
        plant_context = station.GetSubsystemContext(record["plant"], context)
        record["samples"].append((
            t, station.GetOutputPort("hand.position_measured").Eval(context).copy(),
            station.GetOutputPort("hand.taxels").Eval(context).copy(),
            touch._hand_base_pose(station, context, record["scenario"]),
            record["body"].EvalPoseInWorld(plant_context)))

    execute._build_diagram = build
    try:
        result = cli.pick(scenario, true_poses=True, kind=kind, monitor=monitor)
    finally:
        execute._build_diagram = original
    record["in_box"] = result.get("status") == "in_box"
    return record


def pick_carry(kind: str):
    """The estimator (built here from the recorded ports alone, its prior the target's
    start pose moved by ``PRIOR_OFFSET``) over one sorter pick of ``kind``: rows as
    :func:`accuracy`'s over the carry (the lift's end to the release), and whether the
    object ended in the box; None when the pick did not reach the carry."""
    from handle_drake.devices.taxels.estimator import InHandPoseEstimator

    record = _record_pick(kind)
    if "spec" not in record:
        return None
    samples = record["samples"]
    estimator = InHandPoseEstimator("shadow", record["scenario"].hand.coupling_ratio,
                                    record["pads"], record["spec"], samples[0][4] @ PRIOR_OFFSET)
    context = estimator.CreateDefaultContext()
    lift, release = record["marks"]["lift"], record["marks"]["release"]
    rows = []
    for t, q, taxels, X_WB, truth in samples:
        context.SetTime(t)
        hand_pose = np.concatenate([X_WB.translation(), RollPitchYaw(X_WB.rotation()).vector()])
        for port, value in (("hand_positions", q), ("taxels", taxels), ("hand_pose", hand_pose)):
            estimator.GetInputPort(port).FixValue(context, value)
        if lift <= t <= release:
            estimate = estimator.GetOutputPort("pose").Eval(context)
            cov = estimator.GetOutputPort("covariance").Eval(context).reshape(6, 6)
            std_a, std_p = (np.sqrt(max(np.linalg.eigvalsh(cov[k:k + 3, k:k + 3]).max(), 0.0))
                            for k in (0, 3))
            rows.append((t, np.linalg.norm(truth.translation() - estimate.translation()),
                         angle_error(kind, truth.rotation(), estimate.rotation()),
                         estimator.GetOutputPort("quality").Eval(context)[0],
                         truth.translation()[2], std_p, std_a))
        # the estimator's periodic update at this sample (as a simulator would run it)
        context.SetDiscreteState(
            estimator.EvalUniquePeriodicDiscreteUpdate(context).get_vector().value().copy())
    return (np.array(rows), record["in_box"]) if rows else None


def _rms(rows, kind):
    """Position (mm) and angle (deg; None for a sphere) RMS of :func:`accuracy`'s rows."""
    pos = float(np.sqrt(np.mean(rows[:, 1] ** 2))) * 1e3
    return pos, float(np.degrees(np.sqrt(np.mean(rows[:, 2] ** 2)))) if kind != "sphere" \
        else None


def _deg(angle):
    return "n/a" if angle is None else round(angle, 1)


def save_image(path: Path, title: str, taxels, pads) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(pads), figsize=(2.0 * len(pads), 2.6))
    start = 0
    top = max(float(np.max(taxels)) / 1e3, 1.0)  # one scale (kPa) for every pad
    for ax, pad in zip(axes, pads, strict=True):
        image = taxels[start:start + pad.cells].reshape(pad.profile.rows, pad.profile.cols)
        start += pad.cells
        shown = ax.imshow(image / 1e3, origin="lower", cmap="inferno", vmin=0, vmax=top)
        ax.set_title(pad.name.replace("_pad", ""), fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(shown, ax=axes, shrink=0.8, label="kPa")
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def cost(rounds: int, duration: float):
    base = diagrams_dir() / "shadow_sphere_grasp.yaml"
    cases = {"without": "", "taxels": "hand: {taxels: {}}",
             "taxels at 50 Hz": "hand: {taxels: {rate_hz: 50}}",
             "taxels+estimator": "hand: {taxels: {estimator: true}}"}
    times = {k: [] for k in cases}
    for r in range(rounds):
        order = list(cases) if r % 2 == 0 else list(reversed(cases))
        for case in order:
            scenario = LoadScenario(filename=base, data=cases[case] or None)
            station, simulator = _build(scenario)
            start = time.process_time()
            simulator.AdvanceTo(duration)
            times[case].append(time.process_time() - start)
    ratios = {k: statistics.median(np.array(times[k]) / np.array(times["without"]))
              for k in cases if k != "without"}
    return times, ratios


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--picks", default=",".join(PICK_KINDS),
                        help="kinds picked from the shape sorter, carry scored (comma list)")
    add_page_arguments(parser, "sensing", published={"rounds": 5, "quick": False,
                                                     "picks": ",".join(PICK_KINDS)})
    args = parser.parse_args(argv)
    run = ResultsRun("The sensing hand: the pose estimate per grasp and the station's cost",
                     args, section="quick" if args.quick else None)
    table = []
    grasps = GRASPS[:2] if args.quick else GRASPS
    if args.quick and args.picks == ",".join(PICK_KINDS):
        args.picks = "sphere"
    lines = ["| scenario | kind | pads (median) | touch: mm, deg RMS | touch: reported std "
             "(mm, deg) | within 2 std | + accelerometer: mm, deg RMS | held | verdict "
             "(5 mm, 5 deg): touch, + acc. |", "|---|---|---|---|---|---|---|---|---|"]
    for name in grasps:
        kind, rows, taxels, pads = accuracy(name)
        _, rows_acc, _, _ = accuracy(name, accelerometer=True)
        (pos, ang), (pos_acc, ang_acc) = (_rms(r, kind) for r in (rows, rows_acc))
        held = rows[-1, 4] - rows[0, 4] > 0.05
        ok = [p <= 5 and (a is None or a <= 5) for p, a in ((pos, ang), (pos_acc, ang_acc))]
        std = (float(np.median(rows[:, 5])) * 1e3, float(np.degrees(np.median(rows[:, 6]))))
        # the share of samples whose errors lie within twice the reported std (honesty)
        within = float(np.mean((rows[:, 1] <= 2 * rows[:, 5])
                               & ((rows[:, 2] <= 2 * rows[:, 6]) | (kind == "sphere"))))
        table.append({"scenario": name, "kind": kind,
                      "pads in contact (median)": int(np.median(rows[:, 3])),
                      "touch: mm, deg RMS": f"{pos:.1f}, {_deg(ang)}",
                      "touch: reported std (mm, deg)": f"{std[0]:.1f}, {std[1]:.0f}",
                      "touch: within 2 std": round(within, 2),
                      "+ accelerometer: mm, deg RMS": f"{pos_acc:.1f}, {_deg(ang_acc)}",
                      "held (z rose > 5 cm)": bool(held),
                      "verdict (5 mm, 5 deg): touch, + acc.": ", ".join(
                          "met" if k else "not met" for k in ok)})
        lines.append(f"| {name} | {kind} | {np.median(rows[:, 3]):.0f} | {pos:.1f}, "
                     f"{_deg(ang)} | {std[0]:.1f}, {std[1]:.0f} | {within:.2f} | {pos_acc:.1f}, "
                     f"{_deg(ang_acc)} | {'yes' if held else 'no'} | "
                     f"{', '.join('met' if k else 'not met' for k in ok)} |")
        print(lines[-1], flush=True)
        save_image(ROOT / "docs" / "results" / f"taxels_{Path(name).stem}.png",
                   f"{name}: taxels at {rows[-1, 0]:.2f} s", taxels, pads)
    for kind in filter(None, args.picks.split(",")):
        carried = pick_carry(kind)
        if carried is None:  # the pick did not hold it to the carry
            table.append(dict.fromkeys(table[0], "n/a") | {
                "scenario": "pick, carry", "kind": kind,
                "verdict (5 mm, 5 deg): touch, + acc.": "not met (no carry)"})
            lines.append("| " + " | ".join(str(v) for v in table[-1].values()) + " |")
            continue
        rows, in_box = carried
        pos, ang = _rms(rows, kind)
        std = (float(np.median(rows[:, 5])) * 1e3, float(np.degrees(np.median(rows[:, 6]))))
        within = float(np.mean((rows[:, 1] <= 2 * rows[:, 5])
                               & ((rows[:, 2] <= 2 * rows[:, 6]) | np.isnan(rows[:, 2]))))
        ok = pos <= 5 and (ang is None or ang <= 5)
        table.append({"scenario": "pick, carry", "kind": kind,
                      "pads in contact (median)": int(np.median(rows[:, 3])),
                      "touch: mm, deg RMS": f"{pos:.1f}, {_deg(ang)}",
                      "touch: reported std (mm, deg)": f"{std[0]:.1f}, {std[1]:.0f}",
                      "touch: within 2 std": round(within, 2),
                      "+ accelerometer: mm, deg RMS": "",
                      "held (z rose > 5 cm)": f"in the box: {'yes' if in_box else 'no'}",
                      "verdict (5 mm, 5 deg): touch, + acc.": "met" if ok else "not met"})
        lines.append("| " + " | ".join(str(v) for v in table[-1].values()) + " |")
        print(lines[-1], flush=True)
    times, ratios = cost(args.rounds, 1.0 if args.quick else 2.0)
    lines += ["", "| station | CPU s per run (median) | ratio to without (median of rounds) |",
              "|---|---|---|"]
    for case, t in times.items():
        ratio = "1" if case == "without" else f"{ratios[case]:.3f}"
        lines.append(f"| {case} | {statistics.median(t):.2f} | {ratio} |")
    print("\n".join(lines[-6:]))
    cost_lines = [line for line in lines if line.startswith("| ") and (
        "station" in line or "without" in line or "taxels" in line)]
    run.finish(table, {"accuracy": table, "cost_s": times, "cost_ratio": ratios},
               json_path=ROOT / "benchmarks" / "results" / "sensing.json",
               notes=["Station cost, same run (CPU s of this process per 2 s demo grasp; "
                      f"{args.rounds} rounds, alternating order):", "",
                      cost_lines[0], "|---|---|---|", *cost_lines[1:]])
    return lines


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
