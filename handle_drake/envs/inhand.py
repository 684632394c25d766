"""Step-level in-hand environments: joint targets in, joints, touch and the object's sensor out.

One environment per in-hand task, each on the task's own diagram and physics, built by the
task's public builder from the task's settings (nothing here sets a physics constant):

- the palm-up rolling tasks (``cylinder_rotation``, ``star_rotation``):
  :func:`~handle_drake.apps.inhand.task.build_inhand` of
  :meth:`InHandTrial.scenario() <handle_drake.apps.inhand.task.InHandTrial.scenario>`: the
  station (:func:`~handle_drake.station.MakeHandStation`), its simulated hand driver (rate
  limit, PD gains) and the settled grasp; the env's command replaces the trial's frames on
  the station's ``hand.position`` input;
- the screw cap and the fingertip cylinder (``screw_cap``, ``fingertip_cylinder``):
  :func:`~handle_drake.apps.inhand.screw_cap.station_build` of
  :meth:`ScrewCapTrial.scenario() <handle_drake.apps.inhand.screw_cap.ScrewCapTrial.scenario>`:
  the trial's station (the cap on its thread joint, or the free cylinder), settled as the
  trial settles it; the env's targets replace the trial's frames on ``hand.position`` (the
  station's driver rate-limits and clips them).

A step holds one command (``action_mode="absolute"``: the action in [-1, 1] scaled onto the
actuated joints' limits; ``"delta"``: the action times ``max_delta`` rad added to the command
held so far) for ``control_period`` s of simulation. The observation (a ``Dict``):

========================  =====  ==================================================
``joint_position``        nq     rad, the hand's joints (``HandSpec.joint_names`` order)
``joint_velocity``        nq     rad/s
``tactile``               tips   N, normal force on each fingertip (the station's
                                 sensor: ``systems.tactile.fingertip_normal_forces``)
``command``               nu     the command held, normalised to [-1, 1] over the limits
``object_angle``          1      rad, the object's sensor: the cap's encoder (quantised as
                                 the trial reads it), else the object's turn about its own
                                 axis from its pose, unwrapped; positive = the task's way
``object_displacement``   3      m, the object's position less its settled one (world)
========================  =====  ==================================================

Each is clipped to finite bounds (100 rad/s, 1000 N, ten turns, 1 m) that the tasks'
motions do not reach, so that every observation lies in the space.

Reward: the turn gained in the step over the task's target (a whole target's turn sums to
1), +1 when the target is reached, -1 when the object is lost. Reached as the trial counts
it: the screw cap and the fingertip cylinder read the palm and the welded bottle at every
plant step (``screw_cap.step_contacts``): a turn made with the palm on the object or the
hand pushing the bottle with more than the task's ``lean_force`` (1 N) is not reached
(``info``: ``palm_touched``, ``welded_force_max``, ``leaned_on_welded``). Terminated when
the turn reaches the target or the object is lost (dropped more than the task's ``drop`` below its
start, or moved more than its ``max_travel``: the palm tasks; the fingertip cylinder:
``drop``; the cap sits on its thread and is never lost); truncated after ``max_steps``.
The simulation has no noise: ``reset`` restores the settled grasp exactly, so a seed only
seeds the spaces' sampling (``action_space.sample()``) and the same actions give the same
episode.
"""

from __future__ import annotations

import dataclasses as dc
import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from pydrake.systems.framework import EventStatus
from pydrake.trajectories import PiecewisePolynomial

from handle_drake.apps.inhand.screw_cap import (
    DEFAULT_PLACEMENT,
    PLACEMENTS,
    TWO_STROKES,
    ScrewCapTask,
    ScrewCapTrial,
    new_contact_record,
    station_build,
    step_contacts,
)
from handle_drake.apps.inhand.task import InHandTask, InHandTrial, build_inhand
from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.systems.tactile import fingertip_normal_forces

__all__ = ["InHandEnv", "STEP_TASKS", "task_trial", "ACTION_MODES"]

ACTION_MODES = ("absolute", "delta")
#: The step-level tasks and the trial (settings as ``handle-drake inhand --task ...`` uses by
#: default) each is built from.
STEP_TASKS = ("cylinder_rotation", "star_rotation", "screw_cap", "fingertip_cylinder")
_FAR = 1.0e6  # s: a held command's end (beyond any episode)
# The observation's bounds (values beyond are clipped to them, so that every observation is
# in the space; none is reached by the tasks' motions)
MAX_JOINT_VELOCITY = 100.0  # rad/s
MAX_TACTILE = 1000.0  # N
MAX_ANGLE = 20 * np.pi  # rad: ten turns
MAX_DISPLACEMENT = 1.0  # m


def task_trial(task: str, **options):
    """The trial object of ``task`` with the command line's default settings, ``options``
    overriding them (fields of :class:`InHandTask` or :class:`ScrewCapTask`)."""
    if task in ("cylinder_rotation", "star_rotation"):
        return InHandTrial(InHandTask(task=task, **options))
    if task == "screw_cap":  # the command line's default placement (its step and limits)
        return ScrewCapTrial(ScrewCapTask(**(PLACEMENTS[DEFAULT_PLACEMENT] | options)))
    if task == "fingertip_cylinder":  # the learning task: two strokes, 100 deg
        settings = {k: v for k, v in TWO_STROKES.items() if k != "free"} | options
        return ScrewCapTrial(ScrewCapTask(free=True, **settings))
    raise ValueError(f"task: expected one of {STEP_TASKS}, got {task!r}")


def checked_action(action, n: int, values: str, meaning: str, name=lambda i: "") -> np.ndarray:
    """``action`` as ``n`` finite floats in [-1, 1] (clipped to it within 1e-6); otherwise a
    one-line ValueError: the shape expected (``values``: what they are), or the first value
    out of range (``meaning``; ``name(i)``: what index ``i`` is)."""
    a = np.asarray(action, dtype=float)
    if a.shape != (n,):
        raise ValueError(f"action: expected {n} values ({values}), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("action: expected finite values")
    bad = np.flatnonzero(np.abs(a) > 1.0 + 1e-6)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"action: expected values in [-1, 1] ({meaning}), got {a[i]:g} at "
                         f"index {i}{name(i)}")
    return np.clip(a, -1.0, 1.0)


@dc.dataclass(eq=False)
class _Reading:
    """One read of the simulation (plain numbers)."""

    q: np.ndarray
    v: np.ndarray
    tactile: np.ndarray
    angle: float  # rad, the object's sensor
    angle_truth: float  # rad, the plant's (the cap's joint; else equal to angle)
    p: np.ndarray  # m, the object's position


class _Sim:
    """What both task families share: the plant's reads for one built diagram."""

    def _setup_reads(self, plant, hand_instance, body, joint=None, encoder_counts=None):
        spec = get_hand_spec("shadow")
        self.spec, self.plant, self.body, self.joint = spec, plant, body, joint
        self.encoder_counts = encoder_counts
        self._q_index = np.array([plant.GetJointByName(n, hand_instance).position_start()
                                  for n in spec.joint_names])
        self._v_index = np.array([plant.GetJointByName(n, hand_instance).velocity_start()
                                  for n in spec.joint_names])
        tips = [plant.GetFrameByName(n, hand_instance).body() for n in spec.fingertip_frames]
        self._tips = [b.index() for b in tips]
        self._tip_geometry = {g: b.index() for b in tips
                              for g in plant.GetCollisionGeometriesForBody(b)}

    def _start_reads(self):
        """The object's reference (its settled pose) for the turn and displacement."""
        X0 = self.plant.EvalBodyPoseInWorld(self.plant_context, self.body)
        self._R0_inv, self._p0 = X0.rotation().inverse(), X0.translation().copy()
        self._angle = self._previous = 0.0
        self._q_start = self.joint.get_angle(self.plant_context) if self.joint is not None \
            else 0.0

    def _advance(self, duration):
        """Simulates ``duration`` (a whole number of command periods) to the next time on the
        command grid (``ticks * command_period``, not a sum of steps: a sum drifts off the
        grid by rounding and moves the plant's steps against the commands' breaks)."""
        self.ticks += int(round(duration / self.command_period))
        self.simulator.AdvanceTo(self.ticks * self.command_period)

    def read(self) -> _Reading:
        plant, pc = self.plant, self.plant_context
        q, v = plant.GetPositions(pc), plant.GetVelocities(pc)
        tactile = fingertip_normal_forces(plant.get_contact_results_output_port().Eval(pc),
                                          self._tips, self._tip_geometry)
        X = plant.EvalBodyPoseInWorld(pc, self.body)
        if self.joint is not None:  # the cap's joint, read as its encoder counts it
            truth = self.joint.get_angle(pc) - self._q_start
            step = 2 * np.pi / self.encoder_counts
            angle = float(np.round(truth / step) * step)
        else:  # about the object's own axis, unwrapped (the trials' sign: the task's way > 0)
            R = (self._R0_inv @ X.rotation()).matrix()
            raw = -float(np.arctan2(R[1, 0], R[0, 0]))
            self._angle += (raw - self._previous + np.pi) % (2 * np.pi) - np.pi
            self._previous = raw
            angle = truth = self._angle
        return _Reading(q=q[self._q_index], v=v[self._v_index], tactile=tactile,
                        angle=float(angle), angle_truth=float(truth),
                        p=X.translation() - self._p0)


class _PalmSim(_Sim):
    """A palm-up rolling task on the station (:func:`build_inhand`)."""

    def __init__(self, trial: InHandTrial):
        c = trial.config
        scenario = trial.scenario()
        self.built = built = build_inhand(scenario)
        self.harness = harness = built["harness"]
        self.simulator, self.context = harness.simulator, harness.context
        self.coupling = scenario.station.hand.coupling_ratio
        self.q0 = scenario.initial_command()
        self.command_period = scenario.station.driver.control_period
        self.time_step = scenario.station.plant_config.time_step
        self.target = c.target
        self.drop, self.max_travel = c.drop, c.max_travel
        plant = harness.plant
        self._setup_reads(plant, plant.GetModelInstanceByName("hand"), built["body"])
        self.plant_context = harness.plant_context()

    def reset(self):
        self.context.SetTimeStateAndParametersFrom(self.built["settled"])
        self.ticks = 0
        self.command = self.q0.copy()
        self._hold(self.command)
        self.harness.initialize()
        self._start_reads()

    def _hold(self, command):
        t = self.ticks * self.command_period
        # from the driver's next sample on (the breaks half a sample before it, as the
        # trial's frames); the source's output cached at t is invalidated by SetTime
        self.built["player"].UpdateTrajectory(PiecewisePolynomial.ZeroOrderHold(
            [t - 0.5 * self.command_period, t + _FAR], np.column_stack([command, command])))
        self.context.SetTime(t)

    def advance(self, command, duration):
        self.command = command
        self._hold(command)
        self._advance(duration)

    def lost(self, reading: _Reading) -> bool:
        return bool(reading.p[2] < -self.drop or np.linalg.norm(reading.p) >= self.max_travel)

    def contacts(self) -> dict:
        """The episode's contacts that void a turn (the palm-up tasks: none)."""
        return {}


class _CapSim(_Sim):
    """The screw cap or the fingertip cylinder on the station (the trial's
    :func:`~handle_drake.apps.inhand.screw_cap.station_build`: a diagram of its own)."""

    def __init__(self, trial: ScrewCapTrial):
        c = trial.config
        scenario = trial.scenario()
        # the grasp settled as the trial settles it: the gist's frames with every variation 0
        gist = trial.gist
        still = gist.initial_parameters().copy()
        for sl in gist.slices():
            still[sl][1:] = 0.0
        self.built = built = station_build(scenario, still)
        self.simulator = built["simulator"]
        self.context = self.simulator.get_mutable_context()
        self.coupling = 1.0  # the trial's hand
        self.q0 = np.asarray(built["q0"], dtype=float).copy()
        self.command_period = built["trial"].scenario.driver.control_period
        self.time_step = scenario.time_step
        self.target = math.radians(c.target_deg)
        self.drop = c.drop
        plant = built["plant"]
        self._setup_reads(plant, plant.GetModelInstanceByName("hand"), built["cap"],
                          built["joint"], scenario.cap.encoder_counts)
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.settled = built["settled"]
        # the trial's reads at EVERY step: the palm and the hand on the welded bottle
        self.lean_force = c.lean_force
        self.record = new_contact_record()

        def monitor(root_context):
            step_contacts(plant, self.plant_context, built, self.record)
            return EventStatus.Succeeded()

        self.simulator.set_monitor(monitor)

    def reset(self):
        self.context.SetTimeStateAndParametersFrom(self.settled)
        self.ticks = 0
        self.record = new_contact_record()
        self.command = self.q0.copy()
        self._hold(np.tile(self.q0, (1, 1)))
        self.simulator.Initialize()
        self._start_reads()

    def _hold(self, targets):
        """Plays ``targets`` (one per driver period) from now to the station's driver (which
        rate-limits them itself), the last one held; breaks half a period before each of the
        driver's samples, as the trial's frames."""
        t = self.ticks * self.command_period
        breaks = t + (np.arange(len(targets)) - 0.5) * self.command_period
        self.built["trial"].player.UpdateTrajectory(PiecewisePolynomial.ZeroOrderHold(
            np.append(breaks, breaks[-1] + _FAR), np.vstack([targets, targets[-1]]).T))
        self.context.SetTime(t)

    def advance(self, command, duration):
        n = int(round(duration / self.command_period))
        self.command = command
        self._hold(np.tile(command, (n, 1)))
        self._advance(duration)

    def lost(self, reading: _Reading) -> bool:
        return bool(self.joint is None and reading.p[2] < -self.drop)

    def contacts(self) -> dict:
        """As the trial counts them (``ScrewCapTask.lean_force``): the palm touched the
        object or the bottle; the hand pushed the welded bottle with more than lean_force."""
        r = self.record
        return {"palm_touched": bool(r["palm"]), "welded_force_max": float(r["welded_max"]),
                "leaned_on_welded": bool(r["welded_max"] > self.lean_force)}


class InHandEnv(gym.Env):
    """A step-level in-hand task (module doc): ``gymnasium.make("handle_drake/ScrewCap-v0")``.

    Args:
        task: one of :data:`STEP_TASKS`.
        control_period: s of simulation per step (a whole number of the hand driver's
            command periods).
        max_steps: steps before truncation (default: the task's trial length, motion and
            hold, in control periods).
        action_mode: ``"absolute"`` (joint targets over the limits) or ``"delta"``.
        max_delta: rad per step at a delta action of 1.
        task_options: settings of the task (``InHandTask`` / ``ScrewCapTask`` fields).
    """

    metadata = {"render_modes": []}

    def __init__(self, task: str = "screw_cap", control_period: float = 0.04,
                 max_steps: int | None = None, action_mode: str = "absolute",
                 max_delta: float = 0.1, task_options: dict | None = None):
        self.trial = task_trial(task, **(task_options or {}))
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode: expected one of {ACTION_MODES}, got {action_mode!r}")
        if not (isinstance(control_period, int | float) and not isinstance(control_period, bool)
                and 0.001 <= control_period <= 1.0):
            raise ValueError(f"control_period: expected a value in [0.001, 1] s, got "
                             f"{control_period!r}")
        if not (isinstance(max_delta, int | float) and 0 < max_delta <= 1.0):
            raise ValueError(f"max_delta: expected a value in (0, 1] rad, got {max_delta!r}")
        if max_steps is not None and (isinstance(max_steps, bool) or not isinstance(
                max_steps, int) or max_steps < 1):
            raise ValueError(f"max_steps: expected an integer >= 1, got {max_steps!r}")
        self.task, self.control_period, self.action_mode = task, float(control_period), \
            action_mode
        self.max_delta = float(max_delta)
        total = self.trial.config.total_time
        self.max_steps = max_steps or int(math.ceil(total / self.control_period - 1e-9))
        spec = get_hand_spec("shadow")
        self.joint_names, self.actuated_names = spec.joint_names, spec.actuated_joint_names
        nq, nu, tips = len(spec.joint_names), len(spec.actuated_joint_names), \
            len(spec.fingertip_frames)
        f32 = np.float32
        self.action_space = spaces.Box(-1.0, 1.0, (nu,), dtype=f32)
        self.observation_space = spaces.Dict({
            name: spaces.Box(-bound, bound, (size,), dtype=f32) if name != "tactile"
            else spaces.Box(0.0, bound, (size,), dtype=f32)
            for name, size, bound in (
                ("joint_position", nq, np.pi), ("joint_velocity", nq, MAX_JOINT_VELOCITY),
                ("tactile", tips, MAX_TACTILE), ("command", nu, 1.0),
                ("object_angle", 1, MAX_ANGLE), ("object_displacement", 3, MAX_DISPLACEMENT))})
        self._sim = None
        self._steps = 0
        self._last = None

    # -------------------------------------------------------------- the simulation
    @property
    def sim(self):
        """The task's diagram, built and settled on first use (once per env)."""
        if self._sim is None:
            sim = _PalmSim(self.trial) if isinstance(self.trial, InHandTrial) \
                else _CapSim(self.trial)
            ratio = self.control_period / sim.command_period
            if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
                raise ValueError(f"control_period: expected a multiple of the hand driver's "
                                 f"{sim.command_period:g} s, got {self.control_period:g}")
            sim.lower, sim.upper = actuated_position_limits(get_hand_spec("shadow"),
                                                            sim.coupling)
            self._sim = sim
        return self._sim

    def plant_and_context(self):
        """The plant and its context (for reading the simulation from outside)."""
        return self.sim.plant, self.sim.plant_context

    # -------------------------------------------------------------- actions
    def check_action(self, action) -> np.ndarray:
        """``action`` as nu floats in [-1, 1]; a ValueError naming what is wrong otherwise."""
        names = self.actuated_names
        return checked_action(action, len(names),
                              f"one per actuated joint, {names[0]}..{names[-1]}",
                              "normalised joint targets", lambda i: f" ({names[i]})")

    def target(self, action) -> np.ndarray:
        """The joint command (rad) of a checked action."""
        sim = self.sim
        if self.action_mode == "absolute":
            return sim.lower + (action + 1.0) / 2.0 * (sim.upper - sim.lower)
        return np.clip(sim.command + self.max_delta * action, sim.lower, sim.upper)

    def normalised(self, command) -> np.ndarray:
        sim = self.sim
        span = np.where(sim.upper > sim.lower, sim.upper - sim.lower, 1.0)
        return np.clip(2.0 * (command - sim.lower) / span - 1.0, -1.0, 1.0)

    # -------------------------------------------------------------- the API
    def _observation(self, r: _Reading) -> dict:
        values = {"joint_position": r.q, "joint_velocity": r.v, "tactile": r.tactile,
                  "command": self.normalised(self.sim.command), "object_angle": [r.angle],
                  "object_displacement": r.p}
        return {name: np.clip(np.asarray(values[name], dtype=np.float32), space.low, space.high)
                for name, space in self.observation_space.spaces.items()}

    def _info(self, r: _Reading) -> dict:
        return {"turn_deg": math.degrees(r.angle), "turn_deg_truth": math.degrees(r.angle_truth),
                "time": self.sim.context.get_time(), "steps": self._steps}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        sim = self.sim
        sim.reset()
        self._steps = 0
        self._last = sim.read()
        return self._observation(self._last), self._info(self._last)

    def step(self, action):
        if self._last is None:
            raise RuntimeError("step: call reset() first")
        a = self.check_action(action)
        sim = self.sim
        before = self._last.angle
        sim.advance(self.target(a), self.control_period)
        self._steps += 1
        r = self._last = sim.read()
        reward = (r.angle - before) / sim.target
        # reached as the trial counts it: not with the palm, nor leaning on a welded body
        voided = sim.contacts()
        lost = sim.lost(r)
        reached = r.angle >= sim.target and not (voided.get("palm_touched")
                                                 or voided.get("leaned_on_welded"))
        if lost:
            reward -= 1.0
        elif reached:
            reward += 1.0
        terminated = bool(lost or reached)
        truncated = bool(not terminated and self._steps >= self.max_steps)
        info = self._info(r) | {"lost": lost, "reached_target": bool(reached)} | voided
        return self._observation(r), float(reward), terminated, truncated, info
