"""Where the demo station's time over the bare plant goes: four direct measurements.

1. The tactile sample's contact solve: at 100 sample instants of the demo grasp in contact
   (t = 1.00 ... 1.99 s, end of the step to t_k, as the logger samples), two copies of the
   station's context at t_k: on one the tactile port is evaluated (as the logger does) and
   then the step from t_k is taken; on the other only the step. Thread CPU of each part;
   the plant states after both steps are checked bit-identical. A step that is cheaper after
   the sample reuses the sample's contact solve (the same cache entry: same state, time and
   inputs).
2. What a leaf system costs the simulator: the bare plant driven by the demo script, as it
   is, with 25 Gains reading the plant state (no event, never evaluated), with 25 constant
   sources and 25 Gains, nested one diagram deeper, with 3 VectorLogSinks at 100 Hz.
3. The station's loggers: the demo station with no logger, each logger alone, the two
   vector loggers, all three (CPU, paired by round against "no logger").
4. Per step, in the running simulation: thread CPU between two calls of a Simulator
   monitor (one per 1 ms step; its own Python call costs every case alike) for the replay
   floor, the station with no logger and the station as users run it. Steps are split into
   those that end at a logger's sample instant (every 10th: the samples run at their end),
   the step after (it reuses the sample's contact solve) and the others, so the tactile
   sample's net cost and the per-step cost of the station's extra systems are read apart.

CPU seconds of this process, every case once per round (the machine is shared; compare
ratios). Usage: ``python benchmarks/bench_station_parts.py [--rounds N]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "support"))  # helpers, not benchmarks

from handle_drake.base.blas import pin_blas  # noqa: E402 - light: loads neither numpy nor Drake

pin_blas(force=False)

import numpy as np  # noqa: E402
from pydrake.multibody.plant import AddMultibodyPlant  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder, EventStatus  # noqa: E402
from pydrake.systems.primitives import (  # noqa: E402
    ConstantVectorSource,
    Gain,
    VectorLogSink,
)
from script_floor import connect_script  # noqa: E402

from handle_drake.apps.demo import DEMO_SCENARIO  # noqa: E402
from handle_drake.base.models import diagrams_dir  # noqa: E402
from handle_drake.base.results import ResultsRun, add_page_arguments  # noqa: E402
from handle_drake.scenario import LoadScenario  # noqa: E402
from handle_drake.station import AddPlantModels, GetPlant  # noqa: E402
from handle_drake.trial.simulate import ScenarioRunner  # noqa: E402


def _scenario():
    return LoadScenario(filename=diagrams_dir() / DEMO_SCENARIO)


def contact_solve_reuse() -> dict:
    """Part 1: thread CPU (ms) of the tactile sample, of the step after it and of the same
    step without a sample, and the solve / ContactResults / Python split of the sample."""
    runner = ScenarioRunner(_scenario(), log=())
    diagram, station = runner.diagram, runner.station
    plant = GetPlant(station)
    tactile = station.GetOutputPort("hand.tactile")
    contact_results = station.GetOutputPort("contact_results")
    # evaluates the contact solver's results without building ContactResults
    solve = plant.get_generalized_contact_forces_output_port(plant.GetModelInstanceByName("hand"))
    runner.reset()
    runner.simulator.Initialize()
    root = runner.simulator.get_context()
    contexts = {k: diagram.CreateDefaultContext() for k in ("sampled", "cold")}
    simulators = {k: Simulator(diagram, c) for k, c in contexts.items()}
    rows, identical = [], True
    for k in range(100, 200):
        t = k * 0.01
        runner.simulator.AdvanceTo(t)  # ends after the step to t: where the logger samples
        for name in contexts:
            contexts[name].SetTimeStateAndParametersFrom(root)
            simulators[name].Initialize()
        sampled = station.GetMyContextFromRoot(contexts["sampled"])
        c0 = time.thread_time()
        solve.Eval(plant.GetMyContextFromRoot(contexts["sampled"]))
        c1 = time.thread_time()
        contact_results.Eval(sampled)
        c2 = time.thread_time()
        tactile.Eval(sampled)
        c3 = time.thread_time()
        simulators["sampled"].AdvanceTo(t + 0.001)
        c4 = time.thread_time()
        simulators["cold"].AdvanceTo(t + 0.001)
        c5 = time.thread_time()
        rows.append((c1 - c0, c2 - c1, c3 - c2, c4 - c3, c5 - c4))
        x = [plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(c))
             for c in contexts.values()]
        identical &= bool(np.array_equal(x[0], x[1]))
    ms = 1e3 * np.array(rows)
    keys = ("solve", "contact_results", "tactile_python", "step_after_sample", "step_cold")
    out = {k: float(np.median(ms[:, i])) for i, k in enumerate(keys)}
    out["sample_net"] = float(np.median(ms[:, :4].sum(1) - ms[:, 4]))
    out["states_bit_identical"] = identical
    return out


def _bare_plant(extra_gains=0, extra_pairs=0, nested=False, loggers=0):
    """The bare plant driven by the demo script (bench_station's ``model`` floor), with
    extra leaf systems; returns a function that runs it 2 s and gives its CPU seconds."""
    scenario = _scenario()
    inner = DiagramBuilder()
    plant, _ = AddMultibodyPlant(scenario.plant_config, inner)
    hand = AddPlantModels(plant, scenario)
    plant.Finalize()
    connect_script(inner, plant, hand, scenario)
    nx = plant.num_positions() + plant.num_velocities()
    for _ in range(extra_gains):
        gain = inner.AddSystem(Gain(1.0, nx))
        inner.Connect(plant.get_state_output_port(), gain.get_input_port())
    for _ in range(extra_pairs):
        constant = inner.AddSystem(ConstantVectorSource(np.zeros(3)))
        gain = inner.AddSystem(Gain(1.0, 3))
        inner.Connect(constant.get_output_port(), gain.get_input_port())
    if nested:
        inner.ExportOutput(plant.get_state_output_port(), "state")
        builder = DiagramBuilder()
        port = builder.AddSystem(inner.Build()).GetOutputPort("state")
    else:
        builder, port = inner, plant.get_state_output_port()
    for _ in range(loggers):
        logger = builder.AddSystem(VectorLogSink(nx, 0.01))
        builder.Connect(port, logger.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    default = diagram.CreateDefaultContext()

    def run():
        simulator.get_mutable_context().SetTimeStateAndParametersFrom(default)
        simulator.Initialize()
        start = time.process_time()
        simulator.AdvanceTo(2.0)
        return time.process_time() - start

    return run


def _station(log):
    runner = ScenarioRunner(_scenario(), log=log)

    def run():
        runner.reset()
        runner.simulator.Initialize()
        start = time.process_time()
        runner.simulator.AdvanceTo(2.0)
        return time.process_time() - start

    return run


def per_step(rounds: int) -> dict:
    """Part 4: median thread CPU (ms) of the steps that end at a sample instant, of the
    step after each, and of the other steps, per case (median over rounds per step, then
    over the steps of each kind), and the whole run's."""
    import bench_station

    demo = bench_station.STATION_CASES[0]
    cases = {"replay": bench_station._replay_case()[0],
             "station, no logger": bench_station._station_case(*demo, log=()),
             "station as users run it": bench_station._station_case(*demo)}
    h = 0.001  # the demo's step
    every = round(0.01 / h)  # steps per logger sample (harness.LOG_PERIOD)

    def run(case):
        steps, last = [], [0.0]

        def monitor(context):
            now = time.thread_time()
            steps.append((context.get_time(), now - last[0]))
            last[0] = time.thread_time()
            return EventStatus.Succeeded()

        case.simulator.set_monitor(monitor)
        try:
            case._reset()
            steps.clear()  # Initialize calls the monitor too
            last[0] = time.thread_time()
            case.simulator.AdvanceTo(bench_station.TRIAL_SECONDS)
        finally:
            case.simulator.clear_monitor()
        return np.array(steps)

    for case in cases.values():  # warm-up
        run(case)
    runs = {name: [] for name in cases}
    for _ in range(rounds):
        for name, case in cases.items():
            runs[name].append(run(case))
    out = {}
    for name, recorded in runs.items():
        k = np.rint(recorded[0][:, 0] / h).astype(int)
        ms = 1e3 * np.median(np.array([r[:, 1] for r in recorded]), axis=0)
        sample = (k % every == 0) & (k > 0)
        after = (k % every == 1) & (k > 1)
        out[name] = {"sample_step_ms": float(np.median(ms[sample])),
                     "step_after_ms": float(np.median(ms[after])),
                     "other_step_ms": float(np.median(ms[~(sample | after)])),
                     "run_ms": float(np.median([1e3 * r[:, 1].sum() for r in recorded]))}
    return out


def _rounds(cases: dict, rounds: int, reference: str) -> dict:
    for run in cases.values():  # warm-up
        run()
    cpu = {k: [] for k in cases}
    for _ in range(rounds):
        for name, run in cases.items():
            cpu[name].append(run())
    out = {}
    for name in cases:
        ratios = [a / b for a, b in zip(cpu[name], cpu[reference], strict=True)]
        out[name] = {"cpu_s_median": statistics.median(cpu[name]),
                     "over_reference_median": statistics.median(ratios),
                     "rounds": ratios}
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--out", type=Path,
                        default=Path(__file__).parent / "results" / "station_parts.json")
    add_page_arguments(parser, "station", published={"rounds": 6})
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds: must be >= 1")
    results_run = ResultsRun("Station parts: the tactile sample's solve, leaf systems, loggers, "
                             "per step",
                             args)
    load = [os.getloadavg()[0]]
    reuse = contact_solve_reuse()
    print("1. the tactile sample at the end of the step to t_k, in contact (thread CPU, ms, "
          "median of 100 instants):")
    for key, label in (("solve", "contact solve (evaluated by the sample)"),
                       ("contact_results", "ContactResults from the solved step"),
                       ("tactile_python", "tactile sensor (Python)"),
                       ("step_after_sample", "the step from t_k after the sample"),
                       ("step_cold", "the same step without a sample"),
                       ("sample_net", "net cost of one sample")):
        print(f"   {label:<42}{reuse[key]:>7.3f}")
    print(f"   plant states after both steps bit-identical: {reuse['states_bit_identical']}")
    structure = _rounds({"bare plant": _bare_plant(),
                         "+25 Gains on the plant state": _bare_plant(extra_gains=25),
                         "+25 constant sources and 25 Gains": _bare_plant(extra_pairs=25),
                         "nested one diagram deeper": _bare_plant(nested=True),
                         "+3 VectorLogSinks at 100 Hz": _bare_plant(loggers=3)},
                        args.rounds, "bare plant")
    loggers = _rounds({"no logger": _station(()),
                       "hand.position_measured": _station(("hand.position_measured",)),
                       "object.position": _station(("object.position",)),
                       "both vector loggers": _station(("hand.position_measured",
                                                        "object.position")),
                       "all three (as users run it)": _station(("hand.position_measured",
                                                                "hand.tactile",
                                                                "object.position"))},
                      args.rounds, "no logger")
    steps = per_step(args.rounds)
    load.append(os.getloadavg()[0])
    print("4. per step in the running simulation (thread CPU, ms, medians; a sample ends "
          "every 10th step)")
    print(f"   {'case':<26}{'sample step':>12}{'step after':>12}{'other step':>12}{'run':>9}")
    for name, r in steps.items():
        print(f"   {name:<26}{r['sample_step_ms']:>12.3f}{r['step_after_ms']:>12.3f}"
              f"{r['other_step_ms']:>12.3f}{r['run_ms']:>9.0f}")
    for title, block in (("2. leaf systems (2 s of the demo script, CPU / bare plant)", structure),
                         ("3. the demo station's loggers (CPU / no logger)", loggers)):
        print(title)
        for name, r in block.items():
            print(f"   {name:<36}{r['cpu_s_median']:>7.3f} s  {r['over_reference_median']:.3f}x "
                  f"({' '.join(f'{v:.2f}' for v in r['rounds'])})")
    print(f"load average {load[0]:.2f} at the start, {load[1]:.2f} at the end "
          f"({os.cpu_count()} cpus)")
    rows = [{"measure": f"tactile sample: {key}", "median": reuse[key], "unit": "ms"}
            for key in ("solve", "contact_results", "tactile_python", "step_after_sample",
                        "step_cold", "sample_net")]
    rows += [{"measure": f"{part}: {name}", "median": r["over_reference_median"],
              "unit": f"x {reference}", "min": min(r["rounds"]), "max": max(r["rounds"])}
             for part, reference, block in (("leaf systems", "bare plant", structure),
                                            ("loggers", "no logger", loggers))
             for name, r in block.items()]
    rows += [{"measure": f"per step: {name}: {label}", "median": r[key], "unit": "ms"}
             for name, r in steps.items()
             for key, label in (("sample_step_ms", "step ending at a sample"),
                                ("step_after_ms", "step after it"),
                                ("other_step_ms", "other steps"))]
    results_run.finish(rows, {"contact_solve_reuse_ms": reuse, "leaf_systems": structure,
                              "loggers": loggers, "per_step": steps, "load_average": load,
                              "rounds": args.rounds}, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
