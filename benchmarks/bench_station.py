"""Station speed: real-time factor of a 2 s Shadow grasp trial and reset cost.

Runs side by side in one process (ratios are what count on a noisy machine):

- the demo grasp (``diagrams/shadow_sphere_grasp.yaml``, first 2 s) with point
  and hydroelastic contact at 1 ms and 5 ms steps;
- the plant alone under the same script (no drivers, sensors or loggers), as
  modelled, without hand self-collision, and without any contact: the floors
  that bound what the station can reach on this machine;
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

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

from handle_drake.apps.demo import DEMO_SCENARIO  # noqa: E402
from handle_drake.base.models import diagrams_dir  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402
from handle_drake.trial.simulate import ScenarioRunner  # noqa: E402

TRIAL_SECONDS = 2.0


def _scenario(contact_model: str, time_step: float, approximation: str = "sap"):
    return LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO,
                        data=f"plant_config: {{contact_model: {contact_model}, "
                             f"time_step: {time_step}, "
                             f"discrete_contact_approximation: {approximation}}}")


class _Case:
    """One simulation to time: a simulator, how to reset it, and the object's height."""

    def __init__(self, simulator, reset, lift):
        self.simulator, self._reset, self._lift = simulator, reset, lift
        self.walls: list[float] = []
        self.lift_cm = float("nan")

    def run_once(self) -> None:
        self._reset()
        z0 = self._lift()
        start = time.perf_counter()
        self.simulator.AdvanceTo(TRIAL_SECONDS)
        self.walls.append(time.perf_counter() - start)
        self.lift_cm = 100 * (self._lift() - z0)

    def row(self, **labels) -> dict:
        wall = statistics.median(self.walls)
        return {**labels, "wall_s_median": wall, "realtime_factor": TRIAL_SECONDS / wall,
                "realtime_factor_range": [TRIAL_SECONDS / max(self.walls),
                                          TRIAL_SECONDS / min(self.walls)],
                "object_lift_cm_at_2s": self.lift_cm}


def _station_case(contact_model, time_step, approximation) -> _Case:
    from handle_drake.station import GetPlant, object_body

    runner = ScenarioRunner(_scenario(contact_model, time_step, approximation))
    plant = GetPlant(runner.station)
    body = object_body(plant)
    return _Case(runner.simulator, runner.reset,  # what ScenarioRunner.run does first
                 lambda: body.EvalPoseInWorld(plant.GetMyContextFromRoot(
                     runner.simulator.get_context())).translation()[2])


def _plant_case(variant: str) -> _Case:
    """The same models, contact and scripted motion with no Python systems: the
    keyframe trajectories drive the plant's PD targets through ``MatrixGain``
    (no rate limiting, no sensors, no loggers). ``variant``:

    - ``"model"``: the station's plant as it is (the floor that the station's
      drivers, sensors and loggers add to);
    - ``"no_self_collision"``: every hand-hand collision pair filtered;
    - ``"no_contact"``: no object and no table (the hand moves in free space).
    """
    import numpy as np
    from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
    from pydrake.multibody.plant import AddMultibodyPlant
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import MatrixGain, TrajectorySource

    from handle_drake.base.hands import get_hand_spec
    from handle_drake.station import AddPlantModels, hand_initial_command, object_body
    from handle_drake.systems.hand_driver import WRIST_JOINTS, actuated_order
    from handle_drake.trial.simulate import script_trajectories

    scenario = _scenario("point", 0.001)
    if variant == "no_contact":
        scenario.object, scenario.table = None, None
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)  # as the station
    hand = AddPlantModels(plant, scenario)
    if variant == "no_self_collision":
        geometries = [g for i in plant.GetBodyIndices(hand)
                      for g in plant.GetCollisionGeometriesForBody(plant.get_body(i))]
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeWithin(GeometrySet(geometries)))
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

    def reset():
        simulator.get_mutable_context().SetTimeStateAndParametersFrom(default)
        simulator.Initialize()

    if scenario.object is None:
        return _Case(simulator, reset, lambda: 0.0)
    body = object_body(plant)
    return _Case(simulator, reset,
                 lambda: body.EvalPoseInWorld(plant.GetMyContextFromRoot(
                     simulator.get_context())).translation()[2])


STATION_CASES = [(c, t, "sap") for c in ("point", "hydroelastic_with_fallback")
                 for t in (0.001, 0.005)]
STATION_CASES += [("point", t, a) for a in ("similar", "lagged") for t in (0.001, 0.005)]
PLANT_VARIANTS = ("model", "no_self_collision", "no_contact")


def bench_realtime(repeats: int):
    """Every case once per round, ``repeats`` rounds: the cases see the same
    machine conditions, so their ratios hold even when the machine's speed
    drifts (it does here, by up to 40 % over minutes)."""
    station = {case: _station_case(*case) for case in STATION_CASES}
    plant = {variant: _plant_case(variant) for variant in PLANT_VARIANTS}
    for _ in range(repeats):
        for case in [*station.values(), *plant.values()]:
            case.run_once()
    rows = [station[(c, t, a)].row(contact_model=c, approximation=a, time_step_ms=t * 1e3)
            for c, t, a in STATION_CASES]
    floors = [plant[v].row(variant=v) for v in PLANT_VARIANTS]
    return rows, floors


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
    rows, floors = bench_realtime(repeats)
    reset = bench_reset(repeats)
    print(f"Shadow grasp trial, {TRIAL_SECONDS:.0f} s simulated, median of {repeats}")
    print(f"{'contact':<28}{'approx.':<9}{'step':>5}{'wall (s)':>10}{'x real time':>13}"
          f"{'lift@2s (cm)':>14}")
    for r in rows:
        print(f"{r['contact_model']:<28}{r['approximation']:<9}{r['time_step_ms']:>3.0f}ms"
              f"{r['wall_s_median']:>10.2f}"
              f"{r['realtime_factor']:>13.2f}{r['object_lift_cm_at_2s']:>14.1f}")
    print("\nthe plant alone (same script, no Python systems, no loggers), 1 ms, point, sap:")
    for f in floors:
        print(f"  {f['variant']:<20}{f['wall_s_median']:>8.2f} s{f['realtime_factor']:>8.2f}x"
              f"  (range {f['realtime_factor_range'][0]:.2f}-{f['realtime_factor_range'][1]:.2f})"
              f"  lift {f['object_lift_cm_at_2s']:.1f} cm")
    floor = floors[0]
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
    args.out.write_text(json.dumps({"realtime": rows, "plant_only": floors, "reset": reset,
                                    "cpu_count": os.cpu_count(),
                                    "load_average": os.getloadavg()}, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
