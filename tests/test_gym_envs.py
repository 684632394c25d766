"""The Gymnasium environments (handle_drake.envs): the checker, determinism, the reads
against the plant, the actions' checks and the vectorised trials against the trial objects."""

import os
import signal
import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pydrake.math import RollPitchYaw

import handle_drake.envs as envs
from handle_drake.apps.inhand.screw_cap import ONE_GAIT
from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.envs.gist import GistEnv, TrialVectorEnv, gist_trial
from handle_drake.learning.executors import InlineExecutor

NU = len(get_hand_spec("shadow").actuated_joint_names)


def _unwrapped(env_id, **kwargs):
    return gymnasium.make(env_id, **kwargs).unwrapped


def test_every_task_has_one_id_per_level_in_the_namespace():
    assert set(envs.STEP_IDS) == {"cylinder_rotation", "star_rotation", "screw_cap",
                                  "fingertip_cylinder"}
    assert set(envs.GIST_IDS) == set(envs.STEP_IDS) | {"jog_wheel", "grasp"}
    for env_id in envs.ENV_IDS:
        assert env_id.startswith("handle_drake/") and env_id in gymnasium.registry
    assert envs.STEP_IDS["screw_cap"] == "handle_drake/ScrewCap-v0"
    assert envs.GIST_IDS["grasp"] == "handle_drake/Grasp-v0"


@pytest.mark.parametrize("env_id", envs.ENV_IDS)
def test_check_env_is_clean(env_id):
    env = _unwrapped(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    assert [str(w.message) for w in caught] == []
    env.close()


def test_make_finds_the_ids_without_importing_the_package_first():
    code = ("import gymnasium; env = gymnasium.make('handle_drake.envs:handle_drake/ScrewCap-v0');"
            "print(env.unwrapped.action_space.shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, check=True).stdout
    assert out.strip() == f"({NU},)"


def _episode(env, seed, steps):
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    trace = [obs]
    rewards = []
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        trace.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return trace, rewards


@pytest.mark.parametrize("env_id", [envs.STEP_IDS["screw_cap"],
                                    envs.STEP_IDS["cylinder_rotation"]])
def test_same_seed_same_episode_also_in_a_fresh_build(env_id):
    first = _unwrapped(env_id)
    a, ra = _episode(first, 3, 6)
    b, rb = _episode(first, 3, 6)  # the same env, reset
    c, rc = _episode(_unwrapped(env_id), 3, 6)  # another build
    d, _ = _episode(first, 4, 6)  # another seed: other actions
    for other, rewards in ((b, rb), (c, rc)):
        assert rewards == ra
        for x, y in zip(a, other, strict=True):
            for key in x:
                np.testing.assert_array_equal(x[key], y[key])
    assert not np.array_equal(a[-1]["joint_position"], d[-1]["joint_position"])


def test_cap_angle_is_the_encoder_of_the_plants_joint():
    env = _unwrapped(envs.STEP_IDS["screw_cap"])
    obs, _ = env.reset(seed=0)
    plant, context = env.plant_and_context()
    joint = plant.GetJointByName("cap_thread")
    start = joint.get_angle(context)
    count = 2 * np.pi / 4096
    env.action_space.seed(1)
    moved = 0.0
    for _ in range(8):
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        turn = joint.get_angle(context) - start
        moved = max(moved, abs(turn))
        assert abs(obs["object_angle"][0] - turn) <= count / 2 + 1e-6
        assert info["turn_deg_truth"] == pytest.approx(np.degrees(turn), abs=1e-9)
        if terminated or truncated:
            break
    assert moved > np.radians(5)  # the random targets turned it: the test saw a turn


def test_screw_cap_env_has_the_default_tasks_physics():
    """The ScrewCap env is the command line's default screw cap (the clear placement, issue
    45): read from its built plant, a 1 ms step, Menagerie's 1 N m on the finger joints (the
    wrist 10 / 5), and nothing of the hand on the welded bottle in the settled grasp."""
    env = _unwrapped(envs.STEP_IDS["screw_cap"])
    env.reset(seed=0)
    plant, context = env.plant_and_context()
    assert plant.time_step() == pytest.approx(0.001)
    limits = {plant.get_joint_actuator(i).joint().name(): plant.get_joint_actuator(i)
              .effort_limit() for i in plant.GetJointActuatorIndices()}
    assert {n: limits[n] for n in ("FFJ3", "MFJ2", "RFJ3", "LFJ3", "WRJ2", "WRJ1")} == \
        pytest.approx({"FFJ3": 1, "MFJ2": 1, "RFJ3": 1, "LFJ3": 1, "WRJ2": 10, "WRJ1": 5})
    hand = plant.GetModelInstanceByName("hand")
    welded = {b.index() for b in plant.GetBodiesWeldedTo(plant.world_body())
              if b.model_instance() != hand}
    assert welded  # the bottle (and the world)
    on_welded = []
    results = plant.get_contact_results_output_port().Eval(context)
    for c in map(results.point_pair_contact_info, range(results.num_point_pair_contacts())):
        a, b = plant.get_body(c.bodyA_index()), plant.get_body(c.bodyB_index())
        if {a.model_instance() == hand, b.model_instance() == hand} == {True, False} and (
                a.index() in welded or b.index() in welded):
            on_welded.append((a.name(), b.name(), np.linalg.norm(c.contact_force())))
    assert not on_welded, f"the hand on a welded body in the settled grasp: {on_welded}"


def _hand_on_bottle(plant, context) -> float:
    """The hand's largest contact force on the welded bottle now, read from the plant."""
    hand, bottle = plant.GetModelInstanceByName("hand"), plant.GetBodyByName("bottle")
    results = plant.get_contact_results_output_port().Eval(context)
    forces = [0.0]
    for c in map(results.point_pair_contact_info, range(results.num_point_pair_contacts())):
        a, b = plant.get_body(c.bodyA_index()), plant.get_body(c.bodyB_index())
        if {a.index(), b.index()} & {bottle.index()} and hand in (a.model_instance(),
                                                                    b.model_instance()):
            forces.append(float(np.linalg.norm(c.contact_force())))
    return max(forces)


def test_a_turn_made_leaning_on_the_bottle_is_not_reached():
    """The old wedged placement (2 ms, the sheet's limits: a ring finger pressed against the
    welded bottle) with a 20 deg target: the hand-written stroke turns the cap past it, but
    the env, as the trial, does not count it (the bottle's force read from the plant); on the
    default placement holding the grasp leans on nothing."""
    wedged = {k: v for k, v in ONE_GAIT.items()
              if k in ("cap_position", "cap_length", "bottle_neck", "effort_limits",
                       "time_step")}
    assert wedged["time_step"] == 0.002 and wedged["effort_limits"] == "sheet"
    env = envs.InHandEnv("screw_cap", task_options=dict(wedged, target_deg=20.0))
    obs, _ = env.reset(seed=0)
    sim, trial = env.sim, env.trial
    plant, context = env.plant_and_context()
    x = _stroke(trial)
    source = sim.built["source"]
    n = int(round(trial.config.total_time / env.control_period))
    ticks = np.arange(n) * env.control_period
    targets = source.frames_for(x)[source.frame_indices(ticks) - 1]
    seen = 0.0
    for target in targets:
        _, _, terminated, _, info = env.step(2 * (target - sim.lower) / (sim.upper - sim.lower)
                                             - 1)
        seen = max(seen, _hand_on_bottle(plant, context))
        if info["turn_deg"] >= 20.0:
            break
    assert info["turn_deg"] >= 20.0  # the wedge turned it past the target
    assert seen > 1.0 and info["welded_force_max"] >= seen - 1e-9  # read at every step
    assert info["leaned_on_welded"] and not info["reached_target"] and not terminated
    env = _unwrapped(envs.STEP_IDS["screw_cap"])
    obs, _ = env.reset(seed=0)
    *_, info = env.step(obs["command"])
    assert info["welded_force_max"] == 0.0 and not info["leaned_on_welded"]


@pytest.mark.parametrize("task", ["cylinder_rotation", "fingertip_cylinder"])
def test_free_object_angle_is_its_turn_about_its_own_axis(task):
    env = _unwrapped(envs.STEP_IDS[task])
    env.reset(seed=0)
    plant, context = env.plant_and_context()
    body = env.sim.body
    R0 = plant.EvalBodyPoseInWorld(context, body).rotation()
    env.action_space.seed(2)
    yaws, angles = [0.0], [0.0]
    for _ in range(6):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        # independent read: Drake's roll-pitch-yaw of the rotation from the settled pose
        # (the turn about the object's own axis, its body z, is the yaw; the task counts the
        # turn about -z positive), unwrapped over the steps by numpy
        R = R0.inverse() @ plant.EvalBodyPoseInWorld(context, body).rotation()
        yaws.append(-RollPitchYaw(R).yaw_angle())
        angles.append(float(obs["object_angle"][0]))
        if terminated or truncated:
            break
    np.testing.assert_allclose(angles, np.unwrap(yaws), atol=1e-6)
    assert np.max(np.abs(angles)) > np.radians(2)  # the random targets turned it


def test_reset_restores_the_settled_grasp_exactly():
    env = _unwrapped(envs.STEP_IDS["fingertip_cylinder"])
    first, _ = env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    again, info = env.reset(seed=0)
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert info["time"] == 0.0 and info["turn_deg"] == 0.0


def test_a_target_reaches_the_joint_and_the_command_is_observed():
    env = _unwrapped(envs.STEP_IDS["cylinder_rotation"], control_period=0.04)
    obs, _ = env.reset(seed=0)
    spec = get_hand_spec("shadow")
    lower, upper = actuated_position_limits(spec, 1.0)
    i = spec.actuated_joint_names.index("LFJ3")  # the little finger: free of the object
    action = obs["command"].astype(float)
    action[i] = 0.5
    target = lower[i] + 0.75 * (upper[i] - lower[i])
    q_index = spec.joint_names.index("LFJ3")
    before = obs["joint_position"][q_index]
    for _ in range(10):
        obs, *_ = env.step(action)
    np.testing.assert_allclose(obs["command"], action, atol=1e-6)
    assert abs(obs["joint_position"][q_index] - target) < 0.05 < abs(before - target)


def test_delta_actions_add_to_the_command():
    env = _unwrapped(envs.STEP_IDS["screw_cap"], action_mode="delta", max_delta=0.1)
    obs, _ = env.reset(seed=0)
    spec = get_hand_spec("shadow")
    lower, upper = actuated_position_limits(spec, 1.0)
    i = spec.actuated_joint_names.index("LFJ3")
    start = lower[i] + (obs["command"][i] + 1) / 2 * (upper[i] - lower[i])
    action = np.zeros(NU)
    action[i] = 1.0
    for _ in range(3):
        obs, *_ = env.step(action)
    command = lower[i] + (obs["command"][i] + 1) / 2 * (upper[i] - lower[i])
    assert command == pytest.approx(min(start + 0.3, upper[i]), abs=1e-5)


def test_rewards_sum_to_the_turn_over_the_target():
    env = _unwrapped(envs.STEP_IDS["screw_cap"])
    env.reset(seed=0)
    env.action_space.seed(5)
    total, info = 0.0, {}
    for _ in range(10):
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        total += reward
        if terminated or truncated:
            break
    bonus = (1.0 if info["reached_target"] else 0.0) - (1.0 if info["lost"] else 0.0)
    turn = np.radians(info["turn_deg"])
    assert total == pytest.approx(turn / np.radians(env.trial.config.target_deg) + bonus)


def test_truncated_at_the_step_limit():
    env = _unwrapped(envs.STEP_IDS["screw_cap"], max_steps=2)
    obs, _ = env.reset(seed=0)
    hold = obs["command"]
    assert env.step(hold)[3] is False
    assert env.step(hold)[3] is True


@pytest.mark.parametrize("bad, words", [
    (np.full(NU, 1.5), ["action", "[-1, 1]", "index 0", "WRJ2"]),
    (np.r_[np.zeros(NU - 1), -2.0], ["action", "-2", f"index {NU - 1}", "THJ1"]),
    (np.zeros(NU + 1), ["action", f"expected {NU} values"]),
    (np.full(NU, np.nan), ["action", "finite"]),
])
def test_an_action_out_of_bounds_is_refused_by_name(bad, words):
    env = _unwrapped(envs.STEP_IDS["screw_cap"])
    env.reset(seed=0)
    t = env.sim.context.get_time()
    with pytest.raises(ValueError) as error:
        env.step(bad)
    for word in words:
        assert word in str(error.value)
    assert "\n" not in str(error.value)
    assert env.sim.context.get_time() == t  # refused before any simulation


def test_settings_are_checked_when_made():
    for kwargs, word in (({"action_mode": "joint"}, "action_mode"),
                         ({"control_period": 0.0}, "control_period"),
                         ({"max_steps": 0}, "max_steps"),
                         ({"task_options": {"target_deg": -1.0}}, "target_deg")):
        with pytest.raises(ValueError, match=word):
            gymnasium.make(envs.STEP_IDS["cylinder_rotation"], **kwargs)
    env = _unwrapped(envs.STEP_IDS["screw_cap"], control_period=0.003)
    with pytest.raises(ValueError, match="control_period: expected a multiple"):
        env.reset(seed=0)


def test_gist_env_is_one_trial_of_the_trial_object():
    env = GistEnv("screw_cap")
    env.reset(seed=0)
    trial = gist_trial("screw_cap")  # an independent trial object: its own diagram
    x = trial.gist.initial_parameters()
    action = env.action(x)
    np.testing.assert_allclose(env.parameters(action), x, atol=1e-5 * np.ptp(trial.bounds))
    obs, reward, terminated, truncated, info = env.step(action)
    expected = trial.evaluate(env.parameters(action))
    assert reward == expected.score and terminated and not truncated
    assert obs[0] == pytest.approx(expected.score, rel=1e-6)
    assert obs[1] == pytest.approx(expected.turn_deg / trial.config.target_deg, rel=1e-6)
    assert info["detail"]["turn_deg"] == expected.turn_deg
    with pytest.raises(ValueError, match=r"action: expected values in \[-1, 1\]"):
        env.step(np.full(trial.dimension, 3.0))


def test_vector_env_over_the_trial_executor_matches_the_single_env():
    single = GistEnv("cylinder_rotation")
    single.reset(seed=0)
    space = single.action_space
    space.seed(0)
    actions = np.stack([space.sample() for _ in range(3)])
    expected = [single.step(a)[1] for a in actions]
    inline = TrialVectorEnv("cylinder_rotation", num_envs=3, executor=InlineExecutor())
    inline.reset(seed=0)
    _, rewards, terminated, truncated, info = inline.step(actions)
    assert rewards.tolist() == expected
    assert terminated.all() and not truncated.any()
    assert [o[0] for o in info["final_obs"]] == pytest.approx(expected, rel=1e-6)
    with pytest.raises(ValueError, match="action"):  # checked before any trial
        inline.step(np.full_like(actions, 2.0))


def test_make_vec_runs_the_trials_in_a_process_pool():
    venv = gymnasium.make_vec(envs.GIST_IDS["screw_cap"], num_envs=2)
    try:
        assert isinstance(venv, TrialVectorEnv)
        venv.reset(seed=0)
        trial = gist_trial("screw_cap")
        x = trial.gist.initial_parameters()
        actions = np.stack([venv.action(x), venv.action(x)])
        _, rewards, *_ = venv.step(actions)
        assert venv._executor is not None  # the pool ran them
        score = trial.evaluate(venv.parameters(actions[0])).score
        assert rewards.tolist() == [score, score]
        # a worker that dies: the pool replaces itself and the step still gives the trials
        worker = next(iter(venv._executor._pool._processes.values()))
        os.kill(worker.pid, signal.SIGKILL)
        worker.join(timeout=30)
        _, again, *_ = venv.step(actions)
        assert again.tolist() == [score, score]
    finally:
        venv.close()


def test_step_envs_vectorise_in_processes_that_build_their_own_diagram():
    single = _unwrapped(envs.STEP_IDS["screw_cap"])
    obs, _ = single.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = np.clip(obs["command"] + 0.3 * rng.standard_normal((3, 2, NU)), -1, 1).astype(
        np.float32)
    venv = gymnasium.make_vec(envs.STEP_IDS["screw_cap"], num_envs=2,
                              vectorization_mode="async", vector_kwargs={"context": "spawn"})
    try:
        vobs, _ = venv.reset(seed=0)
        np.testing.assert_array_equal(vobs["joint_position"][1], obs["joint_position"])
        for step in actions:
            vobs, vrewards, *_ = venv.step(step)
        for i in range(2):
            single.reset(seed=0)
            for step in actions:
                sobs, reward, *_ = single.step(step[i])
            assert vrewards[i] == reward
            for key in sobs:
                np.testing.assert_array_equal(vobs[key][i], sobs[key])
    finally:
        venv.close()


def _stroke(trial, j3=1.0, j2=0.9):
    """The three fingers' flex strokes (J3 j3, J2 j2 rad), thumb still: a hand-written motion
    that turns the cap and rolls the cylinder (tests/inhand)."""
    g = trial.gist
    x = g.initial_parameters()
    for m, sl in zip(g.motions, g.slices(), strict=True):
        x[sl][1:] = [j3, j2] if (m.finger != "TH" and m.variation[0] > 0) else 0.0
    return x


@pytest.mark.parametrize("task", ["screw_cap", "cylinder_rotation"])
def test_the_trials_frames_as_targets_reproduce_the_trials_turn(task):
    """Same diagram, same physics, same command path: the env holding, per driver period, the
    frame the trial's motion source plans there ends where the trial ends, to the bit."""
    env = envs.InHandEnv(task, task_options={"target_deg": 359.0})  # no early termination
    env.reset(seed=0)
    sim, trial = env.sim, env.trial
    x = _stroke(trial)
    period = sim.command_period
    source = sim.built["source"] if task == "screw_cap" else sim.built["motion"]
    n = int(round(trial.config.total_time / period))
    targets = source.frames_for(x)[source.frame_indices(np.arange(n) * period) - 1]
    for target in targets:
        sim.advance(target, period)
    outcome = trial.evaluate(x, early_stop=False)
    expected = outcome.turn_deg_truth if task == "screw_cap" else outcome.rotation_deg
    assert np.degrees(sim.read().angle_truth) == pytest.approx(expected, abs=1e-9)
    assert expected > 30.0  # a real turn
    if task == "screw_cap":  # through the normalised actions: 2e-16 rad of rounding in the
        env = envs.InHandEnv(task, control_period=period,  # targets moves the cap's end
                             task_options={"target_deg": 359.0})  # by 0.02 deg (the rolling
        env.reset(seed=0)  # cylinder's by 0.9 deg: its contacts amplify it)
        for target in targets:
            action = 2 * (target - sim.lower) / (sim.upper - sim.lower) - 1
            *_, info = env.step(action)
        assert info["turn_deg_truth"] == pytest.approx(expected, abs=0.1)
