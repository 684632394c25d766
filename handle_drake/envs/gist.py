"""Episode-level environments: one step is one trial of the existing trial objects.

``GistEnv`` wraps a trial objective (:class:`~handle_drake.apps.inhand.task.InHandTrial`,
:class:`~handle_drake.apps.inhand.screw_cap.ScrewCapTrial`,
:class:`~handle_drake.apps.inhand.jog_wheel.JogWheelTrial`,
:class:`~handle_drake.trial.grasp_trial.GraspTrial`): the action is the trial's parameter
vector (the action gist's eq. 45 parameters of an in-hand task; a grasp trial's offset,
standoff or synergy amplitudes), normalised to [-1, 1] over the trial's bounds; the step runs
``trial(x)`` (the same call the optimisers' loop makes) and ends the episode. Reward: the
trial's metric (the in-hand score of eqs. 47-49; the grasp's BW metric). Observation: a
summary of the last trial, ``[metric, progress, success]`` (progress: the turn over the
target, the grasp's force closure; success: target reached, force closure), zeros after
``reset`` (the task has no state before its trial: a contextual bandit).

:class:`TrialVectorEnv` runs ``num_envs`` trials per step through the trial executor of
:mod:`handle_drake.learning.executors` (a spawn process pool whose workers receive the trial
once and build its diagram there: diagrams do not pickle; or any ``concurrent.futures``
executor, e.g. :class:`~handle_drake.learning.executors.InlineExecutor` or a Dask client's).
Registered ids build it through ``gymnasium.make_vec(id, num_envs,
vectorization_mode="vector_entry_point")``.
"""

from __future__ import annotations

import json
import math
from concurrent.futures.process import BrokenProcessPool

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from handle_drake.apps.inhand.jog_wheel import JogWheelTask, JogWheelTrial
from handle_drake.envs.inhand import STEP_TASKS, checked_action, task_trial
from handle_drake.learning.executors import (
    TrialResult,
    _check_local_workers,
    _default_pool,
    _evaluate,
    _evaluate_in_worker,
)
from handle_drake.trial.grasp_trial import GraspTrial, GraspTrialConfig

__all__ = ["GistEnv", "TrialVectorEnv", "GIST_TASKS", "gist_trial"]

#: The episode-level tasks: the in-hand tasks (the jog wheel, turned by the floating wrist
#: and scored from its MIDI ticks, at this level only) and the grasp trial.
GIST_TASKS = (*STEP_TASKS, "jog_wheel", "grasp")
# [metric, progress, success], clipped to these bounds (the metrics lie well within)
_OBS = spaces.Box(np.array([-1e3, -100.0, 0.0], dtype=np.float32),
                  np.array([1e3, 100.0, 1.0], dtype=np.float32), dtype=np.float32)


def gist_trial(task: str, **options):
    """The trial objective of ``task`` (``options``: its settings' fields)."""
    if task == "grasp":
        return GraspTrial(GraspTrialConfig(**options))
    if task == "jog_wheel":
        return JogWheelTrial(JogWheelTask(**options))
    if task not in GIST_TASKS:
        raise ValueError(f"task: expected one of {GIST_TASKS}, got {task!r}")
    return task_trial(task, **options)


def _bounds(trial) -> np.ndarray:
    return np.asarray(trial.bounds, dtype=float)


def _summary(trial, metric: float, detail: dict) -> np.ndarray:
    """``[metric, progress, success]`` of one trial's details."""
    if isinstance(trial, GraspTrial):
        closure = float(bool(detail.get("force_closure")))
        values = [metric, closure, closure]
    else:
        turn = detail.get("turn_deg", detail.get("rotation_deg", 0.0))
        values = [metric, turn / trial.config.target_deg, float(bool(detail.get("reached_target")))]
    return np.clip(np.asarray(values, dtype=np.float32), _OBS.low, _OBS.high)


class _Parameters:
    """The normalised action <-> the trial's parameter vector."""

    def _setup(self, trial):
        self.trial = trial
        self.bounds = _bounds(trial)
        self.names = f"{len(self.bounds)} trial parameters"

    def check_action(self, action) -> np.ndarray:
        return checked_action(action, len(self.bounds), f"the {self.names}, normalised",
                              "parameters normalised over their bounds")

    def parameters(self, action) -> np.ndarray:
        """The trial's parameter vector of a normalised action."""
        a = self.check_action(action)
        low, high = self.bounds[:, 0], self.bounds[:, 1]
        return low + (a + 1.0) / 2.0 * (high - low)

    def action(self, parameters) -> np.ndarray:
        """The normalised action of a parameter vector within the bounds (inverse of
        :meth:`parameters`)."""
        x = np.asarray(parameters, dtype=float).reshape(-1)
        low, high = self.bounds[:, 0], self.bounds[:, 1]
        span = np.where(high > low, high - low, 1.0)
        return np.clip(2.0 * (x - low) / span - 1.0, -1.0, 1.0).astype(np.float32)


class GistEnv(_Parameters, gym.Env):
    """One trial per episode (module doc): ``gymnasium.make("handle_drake/ScrewCapGist-v0")``.

    Args:
        task: one of :data:`GIST_TASKS`.
        task_options: the trial's settings (``InHandTask``, ``ScrewCapTask`` or
            ``GraspTrialConfig`` fields).
    """

    metadata = {"render_modes": []}

    def __init__(self, task: str = "screw_cap", task_options: dict | None = None):
        self.task = task
        self._setup(gist_trial(task, **(task_options or {})))
        self.action_space = spaces.Box(-1.0, 1.0, (len(self.bounds),), dtype=np.float32)
        self.observation_space = _OBS
        self._seed = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        # the trial's seed (the grasp trial's metric noise; the in-hand trials have none)
        self._seed = int(self.np_random.integers(2**31))
        return np.zeros(3, dtype=np.float32), {}

    def step(self, action):
        x = self.parameters(action)
        value = self.trial(x, seed=self._seed)
        result = value if isinstance(value, TrialResult) else TrialResult(value)
        detail = dict(result.contacts or {})
        detail.pop("wall_time", None)  # the rest is a function of the action and seed
        metric = float(result.metric)
        obs = _summary(self.trial, metric, detail)
        info = {"parameters": x, "detail": detail, "scenario": result.scenario}
        return obs, metric, True, False, info


class TrialVectorEnv(_Parameters, VectorEnv):
    """``num_envs`` one-trial episodes per step, run through the trial executor.

    Args:
        task, task_options: as :class:`GistEnv`.
        num_envs: trials per step.
        executor: None (a spawn process pool of ``workers`` processes, each building the
            trial's diagram once) or any ``concurrent.futures.Executor`` (the trial is
            pickled with each call: its settings only).
        workers: the pool's processes (default: ``min(num_envs, 2)``).

    Autoreset is ``SAME_STEP``: every step ends all episodes; the observations returned are
    the reset ones and ``info["final_obs"]`` holds each trial's summary.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, task: str = "screw_cap", num_envs: int = 2, executor=None,
                 workers: int | None = None, task_options: dict | None = None):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs: expected an integer >= 1, got {num_envs!r}")
        self.task = task
        self._setup(gist_trial(task, **(task_options or {})))
        self.num_envs = num_envs
        self.single_action_space = spaces.Box(-1.0, 1.0, (len(self.bounds),), dtype=np.float32)
        self.single_observation_space = _OBS
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        if executor is None:
            workers = min(num_envs, 2) if workers is None else workers
            _check_local_workers(workers)
        self._executor, self._workers, self._owns = executor, workers, executor is None
        self._seeds = np.zeros(num_envs, dtype=np.int64)

    def _submit(self, x, seed):
        if self._executor is None:
            self._executor = _default_pool(self.trial, self._workers)
        if self._owns:  # the pool's workers hold the trial (received once, built once)
            return self._executor.submit(_evaluate_in_worker, x, seed, True)
        return self._executor.submit(_evaluate, self.trial, x, seed, True)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._seeds = self.np_random.integers(2**31, size=self.num_envs)
        return np.zeros((self.num_envs, 3), dtype=np.float32), {}

    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions: expected {self.num_envs} rows (one per env), got shape "
                             f"{actions.shape}")
        xs = [self.parameters(a) for a in actions]  # every action checked before any trial
        futures = [self._submit(x, int(s)) for x, s in zip(xs, self._seeds, strict=True)]
        rewards = np.zeros(self.num_envs)
        final = np.zeros((self.num_envs, 3), dtype=np.float32)
        infos: dict = {}
        for i, future in enumerate(futures):
            try:
                outcome = future.result()
            except BrokenProcessPool:  # a worker died: the pool replaces itself; once more
                outcome = self._submit(xs[i], int(self._seeds[i])).result()
            detail = json.loads(outcome["contacts"]) if outcome.get("contacts") else {}
            rewards[i] = outcome["metric"] if outcome["status"] == "done" else 0.0
            final[i] = _summary(self.trial, rewards[i], detail)
            env_info = {"parameters": xs[i], "status": outcome["status"],
                        "wall_time": outcome.get("wall_time", math.nan)}
            if outcome["status"] != "done":
                env_info["error"] = outcome.get("error", "")
            infos = self._add_info(infos, {"final_obs": final[i], "final_info": env_info}, i)
        self._seeds = self.np_random.integers(2**31, size=self.num_envs)
        done = np.ones(self.num_envs, dtype=bool)
        return (np.zeros((self.num_envs, 3), dtype=np.float32), rewards, done,
                np.zeros(self.num_envs, dtype=bool), infos)

    def close_extras(self, **kwargs):
        if self._owns and self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
