"""Station speed: real-time factor of a 2 s Shadow grasp trial and reset cost.

Runs side by side in one process (ratios are what count on a noisy machine):

- the demo grasp (``diagrams/shadow_sphere_grasp.yaml``, first 2 s) with point
  and hydroelastic contact at 1 ms and 5 ms steps;
- a trial reset (``ScenarioRunner.reset``: default context copied back)
  against a full rebuild (``ScenarioRunner(scenario)``).

Targets (issue 2): >= 4x real time at 1 ms with point contact; reset <= 5 ms.

Usage: ``python benchmarks/bench_station.py [--repeats N] [--quick]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from handle_drake.demo import DEMO_SCENARIO, diagrams_dir  # noqa: E402
from handle_drake.run import ScenarioRunner  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402

TRIAL_SECONDS = 2.0


def _scenario(contact_model: str, time_step: float, approximation: str = "sap"):
    return LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO,
                        data=f"contact_model: {contact_model}\ntime_step: {time_step}\n"
                             f"contact_approximation: {approximation}")


def bench_realtime(repeats: int):
    rows = []
    cases = [(c, t, "sap") for c in ("point", "hydroelastic") for t in (0.001, 0.005)]
    cases += [("point", t, a) for a in ("similar", "lagged") for t in (0.001, 0.005)]
    for contact_model, time_step, approximation in cases:
        runner = ScenarioRunner(_scenario(contact_model, time_step, approximation))
        runs = [runner.run(TRIAL_SECONDS) for _ in range(repeats)]
        walls = [r.wall_time for r in runs]
        lift = runs[-1].object_position[-1, 2] - runs[-1].object_position[0, 2]
        rows.append({
            "contact_model": contact_model,
            "approximation": approximation,
            "time_step_ms": time_step * 1e3,
            "wall_s_median": statistics.median(walls),
            "realtime_factor": TRIAL_SECONDS / statistics.median(walls),
            "object_lift_cm_at_2s": 100 * lift,
        })
    return rows


def bench_plant_only(repeats: int):
    """The same models, contact and scripted motion with no Python systems: the
    keyframe trajectories drive the plant's PD targets through ``MatrixGain``
    (no rate limiting, no sensors, no loggers). The floor that the station's
    drivers, sensors and loggers add to."""
    import numpy as np
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import MatrixGain, TrajectorySource

    from handle_drake.hands import get_hand_spec
    from handle_drake.run import script_trajectories
    from handle_drake.station import AddPlantModels, hand_initial_command
    from handle_drake.systems.hand_driver import WRIST_JOINTS, actuated_order

    scenario = _scenario("point", 0.001)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=0.001, discrete_contact_approximation="sap", contact_model="point",
        use_sampled_output_ports=False), builder)
    hand = AddPlantModels(plant, scenario)
    plant.Finalize()
    wrist = plant.GetModelInstanceByName("wrist")
    hand_traj, wrist_traj = script_trajectories(scenario, hand_initial_command(scenario))
    spec = get_hand_spec(scenario.hand.kind)
    # Wrist command [x y z roll pitch yaw] -> joints [x y z yaw pitch roll].
    wrist_map = np.eye(6)[[0, 1, 2, 5, 4, 3]]
    for instance, trajectory, order, pre in (
            (hand, hand_traj, actuated_order(plant, hand, spec.actuated_joint_names), None),
            (wrist, wrist_traj, actuated_order(plant, wrist, WRIST_JOINTS), wrist_map)):
        n = len(order)
        gain = np.zeros((2 * n, n))
        gain[np.arange(n), order] = 1.0
        if pre is not None:
            gain[:n] = gain[:n] @ pre
        source = builder.AddSystem(TrajectorySource(trajectory))
        matrix = builder.AddSystem(MatrixGain(gain))
        builder.Connect(source.get_output_port(), matrix.get_input_port())
        builder.Connect(matrix.get_output_port(), plant.get_desired_state_input_port(instance))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    default = diagram.CreateDefaultContext()
    walls, lift = [], 0.0
    from handle_drake.station import object_body

    body = object_body(plant)
    for _ in range(repeats):
        simulator.get_mutable_context().SetTimeStateAndParametersFrom(default)
        simulator.Initialize()
        context = plant.GetMyContextFromRoot(simulator.get_context())
        z0 = body.EvalPoseInWorld(context).translation()[2]
        start = time.perf_counter()
        simulator.AdvanceTo(TRIAL_SECONDS)
        walls.append(time.perf_counter() - start)
        lift = body.EvalPoseInWorld(context).translation()[2] - z0
    return {"wall_s_median": statistics.median(walls),
            "realtime_factor": TRIAL_SECONDS / statistics.median(walls),
            "object_lift_cm_at_2s": 100 * lift}


def bench_reset(repeats: int):
    scenario = _scenario("point", 0.001)
    builds = []
    for _ in range(max(3, repeats)):
        start = time.perf_counter()
        runner = ScenarioRunner(scenario)
        builds.append(time.perf_counter() - start)
    resets = []
    for _ in range(50):
        start = time.perf_counter()
        runner.reset()
        resets.append(time.perf_counter() - start)
    return {
        "rebuild_ms_median": 1e3 * statistics.median(builds),
        "reset_ms_median": 1e3 * statistics.median(resets),
        "reset_ms_max": 1e3 * max(resets),
        "rebuild_over_reset": statistics.median(builds) / statistics.median(resets),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one repeat")
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "station.json")
    args = parser.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    rows = bench_realtime(repeats)
    floor = bench_plant_only(repeats)
    reset = bench_reset(repeats)
    print(f"Shadow grasp trial, {TRIAL_SECONDS:.0f} s simulated, median of {repeats}")
    print(f"{'contact':<13}{'approx.':<9}{'step':>5}{'wall (s)':>10}{'x real time':>13}"
          f"{'lift@2s (cm)':>14}")
    for r in rows:
        print(f"{r['contact_model']:<13}{r['approximation']:<9}{r['time_step_ms']:>3.0f}ms"
              f"{r['wall_s_median']:>10.2f}"
              f"{r['realtime_factor']:>13.2f}{r['object_lift_cm_at_2s']:>14.1f}")
    print(f"{'plant only':<13}{'sap':<9}{1:>3.0f}ms{floor['wall_s_median']:>10.2f}"
          f"{floor['realtime_factor']:>13.2f}{floor['object_lift_cm_at_2s']:>14.1f}"
          "   (same script, no Python systems)")
    print(f"station overhead at 1 ms, point: "
          f"{floor['realtime_factor'] / rows[0]['realtime_factor']:.2f}x slower than the plant")
    point_1ms = rows[0]["realtime_factor"]
    print(f"point/hydroelastic speed ratio at 1 ms: "
          f"{point_1ms / rows[2]['realtime_factor']:.1f}x")
    print(f"\nreset {reset['reset_ms_median']:.2f} ms (max {reset['reset_ms_max']:.2f}) vs "
          f"rebuild {reset['rebuild_ms_median']:.0f} ms: "
          f"{reset['rebuild_over_reset']:.0f}x faster")
    print(f"targets: >= 4x real time at 1 ms point contact: "
          f"{'met' if point_1ms >= 4 else 'NOT met'} ({point_1ms:.1f}x); reset <= 5 ms: "
          f"{'met' if reset['reset_ms_median'] <= 5 else 'NOT met'}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"realtime": rows, "plant_only": floor, "reset": reset,
                                    "cpu_count": os.cpu_count(),
                                    "load_average": os.getloadavg()}, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
