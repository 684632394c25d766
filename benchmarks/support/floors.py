"""Speed floors of the in-hand benchmarks: the bare plant on a trial's frames.

Shared by ``bench_inhand.py``, ``bench_screw_cap.py`` and ``trial_worker.py`` (which
times a trial or one of its floors in a worker process of its own, so that every case of a
speed table can run under the same conditions: one process per case, nothing else in it).
"""

from __future__ import annotations

import time

import numpy as np

from handle_drake.apps.inhand.gist import frames
from handle_drake.apps.inhand.task import InHandTrial


def _timed_run(simulator, plant, q, v, duration: float):
    """``run() -> wall s``: the plant from positions ``q`` and velocities ``v`` at time 0,
    simulated for ``duration`` (the timing starts after the reset)."""
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)

    def run():
        context.SetTime(0.0)
        plant.SetPositions(plant_context, q)
        plant.SetVelocities(plant_context, v)
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(duration)
        return time.perf_counter() - start

    return run


def bare_builder(trial):
    """A builder with the trial's plant alone (SAP, point contact, its time step) and
    its models: ``(builder, plant, hand instance)``."""
    from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
    from pydrake.systems.framework import DiagramBuilder

    from handle_drake.station import AddPlantModels

    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(
        time_step=trial.config.time_step, discrete_contact_approximation="sap",
        use_sampled_output_ports=False, contact_model="point"), builder)
    hand = AddPlantModels(plant, trial.scenario().station)
    plant.Finalize()
    return builder, plant, hand


def inhand_bare(trial: InHandTrial, x, duration: float):
    """Plant + SceneGraph of the trial's scenario, PD targets from a TrajectorySource,
    simulated for ``duration`` s (the trial's own simulated time, its reversed-weight
    test included)."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec

    c = trial.config
    builder, plant, hand = bare_builder(trial)
    spec = get_hand_spec("shadow")
    F = frames(trial.gist, x, trial.initial_command(), c.n_frames)
    times = np.arange(c.n_frames + 1) * c.motion_duration / c.n_frames
    F = np.vstack([F[0], F])
    # desired state of the actuated joints in actuator order: positions then zero velocities
    q_all = np.array([actuated_to_joint_positions(spec, f) for f in F])
    names = [plant.get_joint_actuator(i).joint().name()
             for i in plant.GetJointActuatorIndices(hand)]
    cols = [spec.joint_names.index(n) for n in names]
    desired = np.hstack([q_all[:, cols], np.zeros((len(times), len(cols)))])
    source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times,
                                                                                  desired.T)))
    builder.Connect(source.get_output_port(), plant.get_desired_state_input_port(hand))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    built = trial._build()
    plant_ref = built["harness"].plant  # the trial's plant; its settled state starts both
    q = plant_ref.GetPositions(plant_ref.GetMyContextFromRoot(built["settled"]))
    v = plant_ref.GetVelocities(plant_ref.GetMyContextFromRoot(built["settled"]))
    return _timed_run(simulator, plant, q, v, duration)


def inhand_replay(trial: InHandTrial, x, duration: float):
    """The bare plant (+ SceneGraph) on the trial's own plant inputs: the desired states
    its hand driver hands the plant at every step (recorded from one trial, held in a
    ``TrajectorySource`` zero-order hold) and, from the end of the hold, the reversed
    weight (a fixed value of the plant's force input), from the trial's settled state:
    the same physics (the object's final pose is checked equal to the trial's), no
    Python system, no samples, no checks. Returns ``(run, identical)``."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial


    c = trial.config
    built = trial._build()
    harness, reverse = built["harness"], built["reverse"]
    driver = harness.station.GetSubsystemByName("hand_driver")
    context = harness.context
    context.SetTimeStateAndParametersFrom(built["settled"])
    built["player"].UpdateTrajectory(built["motion"].held_frames(
        x, built["period"], c.total_time + c.reverse_time))
    plant_ref = harness.plant
    x0 = plant_ref.GetPositionsAndVelocities(plant_ref.GetMyContextFromRoot(context)).copy()
    forces = None
    harness.initialize()
    h, steps = c.time_step, int(round(duration / c.time_step))
    reversal_step = int(round(c.total_time / h))
    desired = []
    for j in range(steps + 1):
        if j:
            harness.simulator.AdvanceTo(j * h)  # stops before the events at j h
        if j == reversal_step:
            reverse.set_reversed(reverse.GetMyContextFromRoot(context), True)
            forces = reverse.get_output_port().Eval(reverse.GetMyContextFromRoot(context))
        desired.append(driver.GetOutputPort("desired_state").Eval(
            driver.GetMyContextFromRoot(context)).copy())
    final = built["body"].EvalPoseInWorld(plant_ref.GetMyContextFromRoot(context))

    builder, plant, hand = bare_builder(trial)
    breaks = np.concatenate([[0.0], (np.arange(1, steps + 1) - 0.5) * h, [duration + h]])
    values = np.array(desired).T
    source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(
        breaks, np.hstack([values, values[:, -1:]]))))
    builder.Connect(source.get_output_port(), plant.get_desired_state_input_port(hand))
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(root)
    force_port = plant.get_applied_spatial_force_input_port()
    body = plant.GetBodyByName(built["body"].name())

    def run():
        root.SetTime(0.0)
        plant.SetPositionsAndVelocities(plant_context, x0)
        force_port.FixValue(plant_context, [])
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(reversal_step * h)
        force_port.FixValue(plant_context, forces)
        simulator.AdvanceTo(duration)
        return time.perf_counter() - start

    run()
    mine = body.EvalPoseInWorld(plant_context)
    identical = bool(np.array_equal(mine.GetAsMatrix34(), final.GetAsMatrix34()))
    return run, identical


def screw_cap_bare(trial, x):
    """The screw cap's floor: its plant alone (``build_screw_cap(bare=True)``: the same
    frames as zero-order holds, no Python system) from the trial's settled state over the
    trial's simulated time (with the reversed weight's 0.5 s when the trial runs it).
    Returns ``(run, total, outcome)``: ``run() -> wall s``, the simulated time and the
    trial's outcome of ``x`` (run to its end)."""
    from pydrake.systems.analysis import Simulator

    from handle_drake.apps.inhand.screw_cap import build_screw_cap

    built = trial._build()
    trial._build(driver=True)  # settled before the timing
    bare = build_screw_cap(trial.scenario(x), bare=True)
    simulator = Simulator(bare["diagram"])
    ref = built["plant"].GetMyContextFromRoot(built["settled"])
    q, v = built["plant"].GetPositions(ref), built["plant"].GetVelocities(ref)
    outcome = trial.evaluate(x, early_stop=False)
    total = outcome.sim_time + (trial.config.reverse_time
                                if outcome.survived_reversal is not None else 0.0)
    return _timed_run(simulator, bare["plant"], q, v, total), total, outcome
