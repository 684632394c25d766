"""Where the demo station's time over the bare plant goes: three direct measurements.

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
from pydrake.systems.framework import DiagramBuilder  # noqa: E402
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
    add_page_arguments(parser, "station")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds: must be >= 1")
    results_run = ResultsRun("Station parts: the tactile sample's solve, leaf systems, loggers",
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
    load.append(os.getloadavg()[0])
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
    results_run.finish(rows, {"contact_solve_reuse_ms": reuse, "leaf_systems": structure,
                              "loggers": loggers, "load_average": load,
                              "rounds": args.rounds}, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
