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
- Images: the taxel readings at the end of the run, one PNG per grasp.
- Cost: the demo grasp (2 s) with taxels (and with taxels and the estimator) against
  without, CPU time of this process, ``--rounds`` rounds in alternating order; the median
  of the per-round ratios.

Usage: ``python benchmarks/bench_sensing.py [--rounds N] [--quick]``
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
        R = truth.rotation().inverse() @ estimate.rotation()
        angle = min(abs((R @ S).ToAngleAxis().angle()) for S in SYMMETRY) \
            if kind != "sphere" else np.nan
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
    add_page_arguments(parser, "sensing", published={"rounds": 5, "quick": False})
    args = parser.parse_args(argv)
    run = ResultsRun("The sensing hand: the pose estimate per grasp and the station's cost",
                     args, section="quick" if args.quick else None)
    table = []
    grasps = GRASPS[:2] if args.quick else GRASPS
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
