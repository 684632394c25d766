"""Simulated grasp trials: parameters -> scenario -> approach and close -> BW metric.

One trial (report section 4.3): the hand starts above a fixed object, moves
along the approach axis (world -z) until it touches it, backs off by the
standoff, closes, and the contacts on the object are scored with the Bimodal
Wrench Space metric (soft-finger contacts, contact surface model).

Parameter spaces (``GraspTrial.bounds``):

- ``"standoff"`` (1-D): the standoff s (m) the hand backs off after the first
  touch, before closing (the report's "initial position along the approach
  axis"); the hand is centred on the object.
- ``"offset"`` (2-D): the hand's (x, y) offset (m) from the object's axis in
  the plane normal to the approach axis; standoff fixed.
- ``"synergy"`` (2-D, Shadow only): amplitudes of two anatomical synergies,
  thumb abduction and index/middle abduction, in [-1, 1]; the wrist is fixed
  over the object and the hand closes from the pre-shape they define (report
  section 4.3.5).

Trials are deterministic for given parameters; ``noise`` adds Gaussian
measurement noise (seeded by the trial seed). A trial in which the hand does
not touch the object scores :data:`NO_CONTACT`.

Robust objective (``placement_error`` e > 0, ``placement_samples`` K): real
placement is noisy, so the metric of parameters x is the mean BW metric of K
trials whose wrist start is moved sideways (world x, y, normal to the
approach) by the points of :func:`placement_stencil`: a fixed sunflower
pattern that covers the disc of radius e evenly (the expected metric under a
placement error uniform on that disc). The same K points at every x (common
random numbers) keep the robust objective a deterministic function of x, so
its grid maximum is well defined and the optimiser's GP sees no extra noise;
one noisy draw per trial would only add variance. A maximum of this objective
is a region at least e wide, not one cell on a cliff edge.

The diagram is built once per process and reset for each trial.
"""

from __future__ import annotations

import dataclasses as dc
import time

import numpy as np
from pydrake.common.schema import Rotation, Transform

from handle_drake.hands import actuated_position_limits, get_hand_spec
from handle_drake.learning import TrialResult
from handle_drake.objects import DEFAULT_SIZE, KINDS, ObjectSpec, total_height
from handle_drake.quality import NO_CONTACT
from handle_drake.run import ScenarioRunner, placed
from handle_drake.scenario import (
    DumpScenario,
    FloatingWrist,
    GraspMetric,
    GuardedGraspController,
    HandConfig,
    ObjectConfig,
    Scenario,
    SimHandDriver,
    default_plant_config,
)

__all__ = [
    "GraspTrial",
    "GraspTrialConfig",
    "TrialOutcome",
    "NO_CONTACT",
    "BABBLING_SIZES",
    "PARAMETER_SPACES",
    "placement_stencil",
]

PARAMETER_SPACES = ("standoff", "offset", "synergy")

# The object sizes (m) of the babbling experiments (report section 4.3), chosen
# within both hands' reach. Not the catalogue's default sizes
# (``handle_drake.objects.DEFAULT_SIZE``, the one default size table): an
# experiment's setting, kept so that logged runs and Table 3 stay as they were.
BABBLING_SIZES = {
    "sphere": 0.07, "cylinder": 0.06, "cuboid": 0.06, "rotated_cuboid": 0.06,
    "mug": 0.08, "wine_glass": 0.07, "star_prism": 0.09,
}
#: m: the object sizes a grasp trial takes (a hand-held object; 1e300 m failed every trial).
SIZE_RANGE = (0.01, 0.5)


@dc.dataclass(frozen=True)
class GraspTrialConfig:
    hand: str = "barrett"
    object: str = "sphere"  # a catalogue kind, or "mesh" with object_file
    # m; None: BABBLING_SIZES[object], else DEFAULT_SIZE[object] (mesh: from the file)
    size: float | None = None
    space: str = "offset"
    noise: float = 0.0  # std of additive metric noise
    mu: float = 0.8  # object friction, also used by the metric
    time_step: float = 0.002  # s
    standoff: float = 0.01  # m, for the "offset" and "synergy" spaces
    offset_range: float | None = None  # m, half-width of the offset box; None: 0.6 * size
    surface_radius: float = 0.004  # m, contact surface model radius (0: raw mean contacts)
    # The metric is the mean over ``hold_samples`` instants spread over the
    # last ``hold_window`` seconds of the hold. One instant is not enough: a
    # flat pad on a flat face is a single point contact that hops between the
    # patch's corners from step to step, so a snapshot of a static cuboid
    # grasp reads 0.40, 0.47 or 0.55 depending on the step it falls on.
    hold_samples: int = 8
    hold_window: float = 0.1  # s
    # object "mesh": the mesh file and its scale to m (handle_drake.objects.mesh);
    # object_digest is the file's SHA-256, filled in so that cached trials of a
    # changed file are never read back.
    object_file: str | None = None
    object_scale: float = 1.0
    object_digest: str = ""
    # Robust objective: mean metric over ``placement_samples`` wrist placements
    # within ``placement_error`` (m) of the planned one (placement_stencil).
    placement_error: float = 0.0
    placement_samples: int = 1

    def __post_init__(self):
        get_hand_spec(self.hand)
        if self.object == "mesh":
            if not self.object_file:
                raise ValueError("object_file: object 'mesh' needs a mesh file")
            if self.size is not None:
                raise ValueError("size: a mesh's size comes from its file (use object_scale)")
            object.__setattr__(self, "object_digest", self.object_spec().digest)
        elif self.object not in KINDS:
            raise ValueError(f"object: unknown kind {self.object!r}; expected one of "
                             f"{KINDS + ('mesh',)}")
        elif self.object_file is not None:
            raise ValueError(f"object_file: only object 'mesh' reads a file, got {self.object!r}")
        if self.size is not None and not (isinstance(self.size, int | float)
                                          and not isinstance(self.size, bool)
                                          and SIZE_RANGE[0] <= self.size <= SIZE_RANGE[1]):
            raise ValueError(f"size: expected an object size in [{SIZE_RANGE[0]:g}, "
                             f"{SIZE_RANGE[1]:g}] m (held in one hand), got {self.size!r}")
        if self.space not in PARAMETER_SPACES:
            raise ValueError(f"space: expected one of {PARAMETER_SPACES}, got {self.space!r}")
        if self.space == "synergy" and self.hand != "shadow":
            raise ValueError("space 'synergy' needs the shadow hand")
        for name in ("noise", "standoff", "surface_radius", "placement_error"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: expected a finite value >= 0, got {value}")
        for name in ("mu", "time_step", "hold_window"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite value > 0, got {value}")
        if isinstance(self.hold_samples, bool) or not isinstance(self.hold_samples, int) \
                or self.hold_samples < 1:
            raise ValueError(f"hold_samples: expected an integer >= 1, got {self.hold_samples!r}")
        if isinstance(self.placement_samples, bool) or not isinstance(
                self.placement_samples, int) or not 1 <= self.placement_samples <= 64:
            raise ValueError("placement_samples: expected an integer in 1..64, got "
                             f"{self.placement_samples!r}")
        if self.placement_error > 0.05:
            raise ValueError(f"placement_error: expected at most 0.05 m (a placement error, "
                             f"not a search range), got {self.placement_error}")
        if (self.placement_error > 0) != (self.placement_samples > 1):
            raise ValueError("placement_error and placement_samples go together: a robust "
                             f"objective needs both > 0 and > 1, got {self.placement_error} "
                             f"and {self.placement_samples}")
        if self.hold_window >= self.settle_time - 0.3:
            raise ValueError(f"hold_window: expected < {self.settle_time - 0.3:.2f} s (the hold "
                             f"starts at the earliest 0.3 s), got {self.hold_window}")

    @property
    def settle_time(self) -> float:
        """s, when the trial ends: the approach has met the object and the hand has closed.

        Measured: Barrett offset trials settle by 0.75 s. The Shadow hand,
        opening fully and closing from the synergy pre-shape, settles between
        0.65 and 1.1 s (11 synergy points on the cuboid); at 0.7 s a grasp
        that ends at 0.23 still read 0.04.
        """
        return 0.9 if self.space != "synergy" else 1.2

    @property
    def object_size(self) -> float:
        if self.object == "mesh":
            return self.object_spec().size
        if self.size is not None:
            return float(self.size)
        # Kinds without a babbling size (the instrumented devices) keep their own size.
        return BABBLING_SIZES.get(self.object, DEFAULT_SIZE[self.object])

    def object_spec(self):
        """The trial's object: an ``ObjectSpec``, or a ``MeshObjectSpec`` for "mesh"."""
        if self.object == "mesh":
            from handle_drake.objects.mesh import MeshObjectSpec

            return MeshObjectSpec(self.object_file, scale=self.object_scale, mu=self.mu)
        return ObjectSpec(self.object, self.object_size, mu=self.mu)

    def object_config(self, **fields) -> ObjectConfig:
        """The trial scenario's object (a catalogue kind or the mesh file), with ``fields``."""
        if self.object == "mesh":
            return ObjectConfig(kind="mesh", file=self.object_spec().file,
                                scale=self.object_scale, mu=self.mu, **fields)
        return ObjectConfig(kind=self.object, size=self.object_size, mu=self.mu, **fields)


def placement_stencil(error: float, samples: int) -> np.ndarray:
    """(samples, 2) sideways placements (m) covering the disc of radius ``error`` evenly.

    Vogel's sunflower pattern: point k at radius ``error * sqrt((k + 0.5) / K)``
    and angle ``k`` golden angles, so each point stands for an equal area of
    the disc (for K >= 2 the mean is near 0 and the mean squared radius is
    ``error**2 / 2``, those of the uniform disc). Deterministic: the same
    points for every trial. ``samples == 1``: the planned placement alone.
    """
    if samples == 1:
        return np.zeros((1, 2))
    k = np.arange(samples)
    radius = error * np.sqrt((k + 0.5) / samples)
    angle = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])


@dc.dataclass
class TrialOutcome:
    """What one trial produced (JSON-friendly through :meth:`as_dict`)."""

    metric: float  # BW value, noise included
    metric_noiseless: float  # mean of metric_samples (robust: mean over the placements)
    metric_samples: list  # BW value at each hold instant (no noise; robust: placement 1)
    force_closure: bool
    contacts: dict  # body name -> {"p_O": [...], "n_O": [...], "f_O": [...]}
    touched: bool  # the approach met the object
    scenario: str  # the trial's full scenario, YAML
    wall_time: float  # s

    def as_dict(self) -> dict:
        return dc.asdict(self)


# Hand geometry for the approach from above (world -z, object at the origin).
_BARRETT_PALM_OFFSET = 0.08  # m, palm surface above the base frame origin
_SHADOW_PALM_SITE = np.array([0.0, -0.045, 0.337])  # m, grasp site in the base frame


def _hand_setup(config: GraspTrialConfig):
    """Start pose (at zero offset), pre-shape and closing commands by hand."""
    spec = get_hand_spec(config.hand)
    names = list(spec.actuated_joint_names)
    preshape, closed = np.zeros(len(names)), np.zeros(len(names))
    top = total_height(config.object_spec()) / 2
    if config.hand == "barrett":
        # Palm down, fingers raised to 0.8 rad (pointing down and out) and
        # closed towards 2.2 rad; spread 0 (F1, F2 against F3).
        for finger in ("f1_prox", "f2_prox", "f3_prox"):
            preshape[names.index(finger)] = 0.8
            closed[names.index(finger)] = 2.2
        height = top + _BARRETT_PALM_OFFSET + 0.12
        start = np.array([0.0, 0.0, height, np.pi, 0.0, 0.0])
    else:
        # Palm down with the fingers along world +x; thumb opposed under the palm.
        values_pre = {"THJ5": 0.5, "THJ4": 1.1}
        values_closed = {"THJ5": 0.5, "THJ4": 1.1, "THJ2": 0.5, "THJ1": 0.9}
        for finger in ("FF", "MF", "RF", "LF"):
            values_closed[f"{finger}J3"] = 1.4
            values_closed[f"{finger}J2"] = 1.4
        for name, value in values_pre.items():
            preshape[names.index(name)] = value
        for name, value in values_closed.items():
            closed[names.index(name)] = value
        # Base pose R_WB = RPY(90, 0, 90) deg maps the site (0, -y, z) to (z, 0, y).
        site_W = np.array([_SHADOW_PALM_SITE[2], 0.0, _SHADOW_PALM_SITE[1]])
        height = top - site_W[2] + 0.08
        start = np.array([-site_W[0], 0.0, height, np.pi / 2, 0.0, np.pi / 2])
    return spec, start, preshape, closed


# Anatomical synergies of the Shadow hand (report 4.3.5), joint deltas per unit amplitude.
SHADOW_SYNERGIES = {
    "thumb_abduction": {"THJ4": 0.35, "THJ5": 0.3},
    "index_middle_abduction": {"FFJ4": -0.3, "MFJ4": 0.15},
}


class GraspTrial:
    """A picklable objective: ``trial(x) -> metric``; ``trial.evaluate(x)`` gives details.

    The diagram is built lazily on first use in each process (so a
    ``ProcessPoolExecutor`` can ship the trial to its workers).
    """

    def __init__(self, config: GraspTrialConfig | None = None, **kwargs):
        self.config = config if config is not None else GraspTrialConfig(**kwargs)
        self._built = None
        self._base = None

    def __getstate__(self):
        return {"config": self.config}

    def __setstate__(self, state):
        self.config = state["config"]
        self._built = None
        self._base = None

    @property
    def bounds(self) -> np.ndarray:
        c = self.config
        if c.space == "standoff":
            return np.array([[0.0, 0.12]])
        if c.space == "offset":
            r = 0.6 * c.object_size if c.offset_range is None else c.offset_range
            return np.array([[-r, r], [-r, r]])
        return np.array([[-1.0, 1.0], [-1.0, 1.0]])

    @property
    def dims(self) -> int:
        return len(self.bounds)

    @property
    def name(self) -> str:
        c = self.config
        robust = (f"-robust{c.placement_error * 1e3:g}mm{c.placement_samples}"
                  if c.placement_samples > 1 else "")
        if c.object == "mesh":
            import re

            stem = re.sub(r"[^A-Za-z0-9_]+", "_", self.config.object_spec().name)
            return f"{c.hand}-mesh_{stem}-{c.space}{robust}"
        return f"{c.hand}-{c.object}-{c.space}{robust}"

    def base_scenario(self) -> Scenario:
        """The trial at zero parameters: the scenario every trial overrides."""
        c = self.config
        spec, start, preshape, closed = _hand_setup(c)
        names = spec.actuated_joint_names
        X_WB = Transform()
        X_WB.translation = start[:3].tolist()
        X_WB.rotation = Rotation()
        X_WB.rotation.value = Rotation.Rpy(deg=np.degrees(start[3:]).tolist())
        return Scenario(
            hand=HandConfig(kind=c.hand, mount=FloatingWrist(X_WB=X_WB)),
            object=c.object_config(fixed=True, on_table=False),
            table=None,
            plant_config=default_plant_config(time_step=c.time_step),
            driver=SimHandDriver(max_joint_velocity=4.0),
            simulation_duration=c.settle_time,
            # The approach stops when the palm touches (Shadow: the thumb,
            # opposed under the palm, must not stop it) or any link touches
            # (Barrett).
            controller=GuardedGraspController(
                start_pose=start.tolist(), direction=[0.0, 0.0, -1.0], speed=0.4,
                max_travel=0.25, standoff=c.standoff,
                preshape={n: float(v) for n, v in zip(names, preshape, strict=True)},
                closed={n: float(v) for n, v in zip(names, closed, strict=True)},
                guard_bodies=[] if c.hand == "barrett" else ["palm"]),
            metric=GraspMetric(hold_samples=c.hold_samples, hold_window=c.hold_window,
                               surface_radius=c.surface_radius, gamma=0.002, num_edges=8),
        )

    @property
    def runner(self) -> ScenarioRunner:
        """The runner of the base scenario, built on first use, once per process
        (per config); other scenarios of this trial run on it (``runner.run(scenario=...)``)."""
        if self._built is None:
            if self._base is None:
                self._base = self.base_scenario()
            self._built = ScenarioRunner(self._base)
        return self._built

    def _check(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float).reshape(-1)
        bounds = self.bounds
        if x.shape != (len(bounds),):
            raise ValueError(f"parameters: expected {len(bounds)} values, got {x.shape[0]}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"parameters: expected finite values, got {x}")
        return x

    def scenario(self, x, placement=(0.0, 0.0)) -> Scenario:
        """The trial of parameters ``x``: the base scenario with its controller overridden;
        ``placement``: the wrist start moved sideways by (dx, dy) m (the robust objective)."""
        x = self._check(x)
        if self._base is None:
            self._base = self.base_scenario()
        base = self._base
        c, ctrl = self.config, base.controller
        start = np.array(ctrl.start_pose)
        names = list(ctrl.preshape)
        preshape = np.array([ctrl.preshape[n] for n in names])
        closed = np.array([ctrl.closed[n] for n in names])
        standoff = c.standoff
        start[:2] += np.asarray(placement, dtype=float)
        if c.space == "standoff":
            standoff = float(x[0])
        elif c.space == "offset":
            start[:2] += x
        else:
            lower, upper = actuated_position_limits(get_hand_spec(c.hand), None)
            for amplitude, synergy in zip(x, SHADOW_SYNERGIES.values(), strict=True):
                for joint, delta in synergy.items():
                    preshape[names.index(joint)] += amplitude * delta
                    closed[names.index(joint)] += amplitude * delta
            preshape = np.clip(preshape, lower, upper)
            closed = np.clip(closed, lower, upper)
        return dc.replace(base, controller=dc.replace(
            ctrl, start_pose=start.tolist(), standoff=standoff,
            preshape={n: float(v) for n, v in zip(names, preshape, strict=True)},
            closed={n: float(v) for n, v in zip(names, closed, strict=True)}))

    def scenario_for(self, x) -> str:
        """The trial's full scenario (YAML): ``handle-drake simulate`` on it replays the trial
        (its metric is the trial's noiseless one)."""
        return self._scenario_text(self.scenario(x), x)

    def _scenario_text(self, scenario: Scenario, x) -> str:
        return DumpScenario(scenario) + (
            f"# trial parameters ({self.config.space}): {self._check(x).tolist()}\n")

    def __call__(self, x, seed: int = 0) -> TrialResult:
        """The objective for ``run_experiment``: metric, contacts and scenario of one trial."""
        outcome = self.evaluate(x, seed=seed)
        return TrialResult(metric=outcome.metric, scenario=outcome.scenario, contacts={
            "force_closure": outcome.force_closure, "touched": outcome.touched,
            "metric_noiseless": outcome.metric_noiseless, "bodies": outcome.contacts,
        })

    def evaluate(self, x, seed: int = 0) -> TrialOutcome:
        """One trial: parameters -> scenario -> simulate (the process's one diagram) -> metric.

        Approach until contact, let the hand close and settle, then score the
        hold at ``hold_samples`` instants (the last one at ``settle_time``).
        """
        start_wall = time.perf_counter()
        c = self.config
        runner = self.runner
        controller = runner.controller
        values, touched = [], False
        # The stencil's first placement (the planned one when K == 1) gives the
        # outcome's scenario, contacts and hold samples; the metric is the mean.
        stencil = placement_stencil(c.placement_error, c.placement_samples)
        trial_scenario = self.scenario(x)
        for k, placement in enumerate(stencil):
            # as ``handle-drake simulate`` runs the stored scenario's metric.placements
            run_scenario = placed(trial_scenario, placement) if c.placement_samples > 1 \
                else trial_scenario
            run_score = runner.run(scenario=run_scenario).score
            values.append(run_score.value)
            touched = touched or np.isfinite(controller.GetOutputPort("contact_time").Eval(
                controller.GetMyContextFromRoot(runner.context))[0])
            if k == 0:
                scenario, score = run_scenario, run_score
        value = float(np.mean(values))
        rng = np.random.default_rng(seed)
        noisy = value + (c.noise * rng.standard_normal() if c.noise > 0 else 0.0)
        return TrialOutcome(
            metric=float(noisy), metric_noiseless=value, metric_samples=score.samples,
            force_closure=score.force_closure, contacts=score.contacts,
            touched=bool(touched or score.contacts),
            scenario=self._scenario_text(scenario, x) if c.placement_samples == 1 else
            self._scenario_text(dc.replace(trial_scenario, metric=dc.replace(
                trial_scenario.metric, placements=stencil.tolist())), x) + (
                f"# robust objective: metric.placements holds the {c.placement_samples} "
                f"start placements within {c.placement_error} m; simulate runs each and "
                "reports their mean (the trial's noiseless metric)\n"),
            wall_time=time.perf_counter() - start_wall,
        )
