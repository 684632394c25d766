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

The diagram is built once per process and reset for each trial.
"""

from __future__ import annotations

import dataclasses as dc
import json
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handle_drake.hands import actuated_position_limits, get_hand_spec
from handle_drake.learning import TrialResult
from handle_drake.objects import KINDS, ObjectSpec, total_height
from handle_drake.quality import NO_CONTACT, ContactParams, score_contacts
from handle_drake.quality.object_contacts import ObjectContacts
from handle_drake.quality.surface import ObjectSurface
from handle_drake.scenario import DumpScenario, LoadScenario, Scenario
from handle_drake.station import GetPlant, MakeHandStation, object_body
from handle_drake.systems.guarded_grasp import GuardedGrasp

__all__ = [
    "GraspTrial",
    "GraspTrialConfig",
    "TrialOutcome",
    "NO_CONTACT",
    "DEFAULT_SIZES",
    "PARAMETER_SPACES",
]

PARAMETER_SPACES = ("standoff", "offset", "synergy")

# Object sizes (m) used by the babbling experiments, within the hands' reach.
DEFAULT_SIZES = {
    "sphere": 0.07, "cylinder": 0.06, "cuboid": 0.06, "rotated_cuboid": 0.06,
    "mug": 0.08, "wine_glass": 0.07, "star_prism": 0.09,
}


@dc.dataclass(frozen=True)
class GraspTrialConfig:
    hand: str = "barrett"
    object: str = "sphere"  # a catalogue kind, or "mesh" with object_file
    size: float | None = None  # m; None: DEFAULT_SIZES[object] (mesh: from the file)
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
        if self.space not in PARAMETER_SPACES:
            raise ValueError(f"space: expected one of {PARAMETER_SPACES}, got {self.space!r}")
        if self.space == "synergy" and self.hand != "shadow":
            raise ValueError("space 'synergy' needs the shadow hand")
        for name in ("noise", "standoff", "surface_radius"):
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
        return DEFAULT_SIZES[self.object] if self.size is None else float(self.size)

    def object_spec(self):
        """The trial's object: an ``ObjectSpec``, or a ``MeshObjectSpec`` for "mesh"."""
        if self.object == "mesh":
            from handle_drake.objects.mesh import MeshObjectSpec

            return MeshObjectSpec(self.object_file, scale=self.object_scale, mu=self.mu)
        return ObjectSpec(self.object, self.object_size, mu=self.mu)

    def object_yaml(self) -> str:
        """The object's fields of the trial scenario (flow-style YAML, no braces)."""
        if self.object == "mesh":
            return (f"kind: mesh, file: {json.dumps(str(self.object_spec().file))}, "
                    f"scale: {self.object_scale!r}")
        return f"kind: {self.object}, size: {self.object_size}"


@dc.dataclass
class TrialOutcome:
    """What one trial produced (JSON-friendly through :meth:`as_dict`)."""

    metric: float  # BW value, noise included
    metric_noiseless: float  # mean of metric_samples
    metric_samples: list  # BW value at each hold instant (no noise)
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

    def __getstate__(self):
        return {"config": self.config}

    def __setstate__(self, state):
        self.config = state["config"]
        self._built = None

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
        if c.object == "mesh":
            import re

            stem = re.sub(r"[^A-Za-z0-9_]+", "_", self.config.object_spec().name)
            return f"{c.hand}-mesh_{stem}-{c.space}"
        return f"{c.hand}-{c.object}-{c.space}"

    def base_scenario(self) -> Scenario:
        c = self.config
        _, start, _, _ = _hand_setup(c)
        return LoadScenario(data=f"""
hand:
  kind: {c.hand}
  mount: !FloatingWrist
    X_WB: {{translation: [{start[0]}, {start[1]}, {start[2]}],
           rotation: !Rpy {{deg: [{np.degrees(start[3])}, {np.degrees(start[4])},
                                  {np.degrees(start[5])}]}}}}
object: {{{c.object_yaml()}, mu: {c.mu}, fixed: true, on_table: false}}
table: null
contact_model: point
time_step: {c.time_step}
driver: !SimHandDriver {{max_joint_velocity: 4.0}}
simulation_duration: 1.2
""")

    def _build(self):
        c = self.config
        spec, start, preshape, closed = _hand_setup(c)
        scenario = self.base_scenario()
        builder = DiagramBuilder()
        station = builder.AddNamedSystem("station", MakeHandStation(scenario))
        plant = GetPlant(station)
        hand = plant.GetModelInstanceByName("hand")
        hand_bodies = [plant.get_body(i) for i in plant.GetBodyIndices(hand)]
        obj = object_body(plant)
        # The approach stops when the palm touches (Shadow: the thumb, opposed
        # under the palm, must not stop it) or any link touches (Barrett).
        guard = [b for b in hand_bodies if c.hand == "barrett" or b.name() == "palm"]
        controller = builder.AddNamedSystem("controller", GuardedGrasp(
            start, [0, 0, -1], speed=0.4, max_travel=0.25, preshape=preshape, closed=closed,
            hand_bodies=[b.index() for b in guard], object_bodies=[obj.index()],
            standoff=c.standoff))
        builder.Connect(station.GetOutputPort("contact_results"),
                        controller.get_contact_results_input_port())
        builder.Connect(controller.GetOutputPort("wrist_pose"), station.GetInputPort("wrist.pose"))
        builder.Connect(controller.GetOutputPort("hand_position"),
                        station.GetInputPort("hand.position"))
        contacts = builder.AddNamedSystem("object_contacts", ObjectContacts(
            plant, obj, {b.name(): b for b in hand_bodies}))
        builder.Connect(station.GetOutputPort("contact_results"),
                        contacts.get_input_port(0))
        builder.Connect(station.GetOutputPort("body_poses"), contacts.get_input_port(1))
        diagram = builder.Build()
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        lower, upper = actuated_position_limits(spec, None)
        self._built = dict(
            diagram=diagram, simulator=simulator, context=context,
            default=diagram.CreateDefaultContext(), controller=controller,
            contacts=contacts, start=start, preshape=preshape, closed=closed,
            lower=lower, upper=upper, spec=spec,
            surface=ObjectSurface(c.object_spec()),
            params=ContactParams(model="soft_finger", mu=c.mu, gamma=0.002, num_edges=8,
                                 characteristic_length=c.object_size / 2),
        )
        return self._built

    def _check(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float).reshape(-1)
        bounds = self.bounds
        if x.shape != (len(bounds),):
            raise ValueError(f"parameters: expected {len(bounds)} values, got {x.shape[0]}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"parameters: expected finite values, got {x}")
        return x

    def scenario_for(self, x) -> str:
        """The trial's full scenario (YAML) with its parameters, for the trial log."""
        x = self._check(x)
        return DumpScenario(self.base_scenario()) + (
            f"# trial parameters ({self.config.space}): {x.tolist()}\n")

    def __call__(self, x, seed: int = 0) -> TrialResult:
        """The objective for ``run_experiment``: metric, contacts and scenario of one trial."""
        outcome = self.evaluate(x, seed=seed)
        return TrialResult(metric=outcome.metric, scenario=outcome.scenario, contacts={
            "force_closure": outcome.force_closure, "touched": outcome.touched,
            "metric_noiseless": outcome.metric_noiseless, "bodies": outcome.contacts,
        })

    def evaluate(self, x, seed: int = 0) -> TrialOutcome:
        x = self._check(x)
        built = self._built or self._build()
        c = self.config
        start_wall = time.perf_counter()
        start, preshape, closed = built["start"].copy(), built["preshape"], built["closed"].copy()
        standoff = c.standoff
        if c.space == "standoff":
            standoff = float(x[0])
        elif c.space == "offset":
            start[:2] += x
        else:
            preshape = preshape.copy()
            names = list(built["spec"].actuated_joint_names)
            for amplitude, synergy in zip(x, SHADOW_SYNERGIES.values(), strict=True):
                for joint, delta in synergy.items():
                    preshape[names.index(joint)] += amplitude * delta
                    closed[names.index(joint)] += amplitude * delta
            preshape = np.clip(preshape, built["lower"], built["upper"])
            closed = np.clip(closed, built["lower"], built["upper"])

        context, controller = built["context"], built["controller"]
        context.SetTimeStateAndParametersFrom(built["default"])
        controller.set_trial(controller.GetMyMutableContextFromRoot(context), start_pose6=start,
                             preshape=preshape, closed=closed, standoff=standoff)
        station = built["diagram"].GetSubsystemByName("station")
        plant = GetPlant(station)
        plant_context = plant.GetMyMutableContextFromRoot(context)
        _place_wrist(plant, plant_context, start)
        _place_hand(plant, plant_context, built["spec"], preshape)
        driver = station.GetSubsystemByName("hand_driver")
        driver.set_initial_command(driver.GetMyMutableContextFromRoot(context), preshape)
        simulator = built["simulator"]
        simulator.Initialize()
        # Approach until contact, let the hand close and settle, then score
        # the hold at hold_samples instants (the last one at settle_time).
        samples = []
        contacts_port = built["contacts"].get_output_port()
        contacts_context = built["contacts"].GetMyContextFromRoot(context)
        hold_times = (c.settle_time - c.hold_window * np.linspace(1.0, 0.0, c.hold_samples)
                      if c.hold_samples > 1 else [c.settle_time])
        for t in hold_times:
            simulator.AdvanceTo(float(t))
            value, closure, detail = self._score(contacts_port.Eval(contacts_context), built)
            samples.append(float(value))
        touched = np.isfinite(controller.GetOutputPort("contact_time").Eval(
            controller.GetMyContextFromRoot(context))[0])
        value = float(np.mean(samples))
        rng = np.random.default_rng(seed)
        noisy = value + (c.noise * rng.standard_normal() if c.noise > 0 else 0.0)
        return TrialOutcome(
            metric=float(noisy), metric_noiseless=value, metric_samples=samples,
            force_closure=bool(closure),
            contacts=detail, touched=bool(touched or detail),
            scenario=self.scenario_for(x), wall_time=time.perf_counter() - start_wall,
        )

    def _score(self, contacts, built):
        return score_contacts(contacts, built["params"], built["surface"],
                              self.config.surface_radius)


def _set_joint_positions(plant, plant_context, instance, names, values) -> None:
    q = plant.GetPositions(plant_context)
    for name, value in zip(names, values, strict=True):
        q[plant.GetJointByName(name, instance).position_start()] = value
    plant.SetPositions(plant_context, q)


def _place_wrist(plant, plant_context, pose6) -> None:
    from handle_drake.systems.hand_driver import WRIST_JOINTS, pose_to_wrist_joints

    _set_joint_positions(plant, plant_context, plant.GetModelInstanceByName("wrist"),
                         WRIST_JOINTS, pose_to_wrist_joints(pose6))


def _place_hand(plant, plant_context, spec, command) -> None:
    from handle_drake.hands import actuated_to_joint_positions

    _set_joint_positions(plant, plant_context, plant.GetModelInstanceByName("hand"),
                         spec.joint_names, actuated_to_joint_positions(spec, command))
