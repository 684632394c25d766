"""Typed scenarios: what a station simulates (or drives), loaded from YAML.

This module must not use ``from __future__ import annotations``: Drake's
``yaml_load_typed`` reads the dataclass fields' types and needs real types, not
strings.

A scenario file names the hand and how it is mounted, the object, the table,
the plant's settings (Drake's ``MultibodyPlantConfig``: time step, contact
model, discrete contact approximation), the hand driver (a tagged variant: the
simulated hand, or a CAN hand behind the bus server) and the simulation
duration. :func:`LoadScenario` reads a file first and then an override string,
so a trial is "base scenario + parameters as an override":

.. code-block:: yaml

    hand:
      kind: shadow
      coupling_ratio: 1.0          # xFJ1 = ratio * xFJ2 (1.0 C6 hand, 1.1 C5)
      mount: !FloatingWrist
        X_WB: {translation: [0, 0, 0.3], rotation: !Rpy {deg: [180, 0, 0]}}
    object: {kind: sphere, size: 0.06, on_table: true}
    table: {top_height: 0.0}
    plant_config:                  # Drake's MultibodyPlantConfig; fields not given
      time_step: 0.001             # keep the defaults below
      contact_model: point         # point | hydroelastic_with_fallback
      discrete_contact_approximation: sap   # sap | similar | lagged
    driver: !SimHandDriver {}
    simulation_duration: 2.0
    random_seed: 0

``plant_config`` is Drake's own ``MultibodyPlantConfig`` (as in
RussTedrake/manipulation's scenarios), with this project's defaults: a 1 ms
step, point contact, the ``sap`` approximation and
``use_sampled_output_ports: false``; its other fields (``penetration_allowance``,
``stiction_tolerance``, ``sap_near_rigid_threshold``,
``contact_surface_representation``, ``adjacent_bodies_collision_filters``)
keep Drake's defaults. Drake's strict ``contact_model: hydroelastic`` is refused
with a hint: it throws at the first contact between two geometries without
compliant hydroelastic properties (the hands' links have none);
``hydroelastic_with_fallback`` gives the object compliant hydroelastic
properties (the table is rigid hydroelastic) and falls back to point contact
elsewhere. The old top-level keys
``contact_model`` (``hydroelastic`` meant ``hydroelastic_with_fallback``),
``time_step`` and ``contact_approximation`` are still read, moved into
``plant_config`` with a :class:`~handle_drake.base.checks.ScenarioDeprecationWarning`.

Units are SI (m, rad, kg, s). Poses are ``pydrake.common.schema.Transform``
(``translation`` in m, ``rotation`` as ``!Rpy {deg: [...]}`` or
``!AngleAxis``).
"""


import dataclasses as dc
import math
from pathlib import Path

import numpy as np
import yaml
from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.visualization import VisualizationConfig

from handle_drake.base.checks import (
    ScenarioError,
    check_pose,
    check_ranges,
    check_yaml_text,
    read_text_file,
    short,
    translate_deprecated_keys,
)
from handle_drake.base.hands import EFFORT_LIMITS, HAND_SPECS
from handle_drake.base.models import SHIPPED_HINT, shipped_path
from handle_drake.devices.accelerometer.config import AccelerometerConfig
from handle_drake.devices.accelerometer.sensor import check_sensor_pose
from handle_drake.devices.accelerometer.wiring import instrument_X_OS
from handle_drake.devices.arm.config import Arm, validate_arm
from handle_drake.devices.arm.model import ARM_SPECS
from handle_drake.devices.camera.config import (
    ARM_PARENT_PREFIX,
    CAMERA_PARENTS,
    CameraConfig,
    DepthCamera,
    resolve_camera_config,
)
from handle_drake.devices.camera.profiles import get_profile
from handle_drake.devices.can_hand.config import CanHandDriverConfig
from handle_drake.devices.midi.wiring import validate_midi_controller
from handle_drake.devices.taxels.config import TaxelConfig
from handle_drake.geometry.objects import KINDS, ObjectSpec
from handle_drake.geometry.objects.mesh import MeshObjectSpec, MeshObjectWarning
from handle_drake.scene.config import Hole, SortingBoxConfig, validate_scene
from handle_drake.scene.jointed import ObjectBase, ThreadJoint, validate_thread_joint

__all__ = [
    "AccelerometerConfig",
    "Arm",
    "Hole",
    "SortingBoxConfig",
    "CONTACT_MODELS",
    "CameraConfig",
    "DepthCamera",
    "CanHandDriver",
    "FixedMount",
    "FloatingWrist",
    "GraspMetric",
    "GuardedGraspController",
    "HandConfig",
    "Keyframe",
    "LoadScenario",
    "MidiControllerConfig",
    "MultibodyPlantConfig",
    "ObjectConfig",
    "ObjectBase",
    "ThreadJoint",
    "is_bare",
    "Scenario",
    "ScenarioError",
    "SimHandDriver",
    "default_plant_config",
    "default_visualization_config",
    "TableConfig",
    "DumpScenario",
    "object_spec",
    "mesh_object_spec",
]

# Drake's contact models this station builds ("hydroelastic", Drake's strict
# mode, is refused: see the module docstring).
CONTACT_MODELS = ("point", "hydroelastic_with_fallback")
CONTACT_SURFACE_REPRESENTATIONS = ("triangle", "polygon")
# Drake's SAP-family discrete contact approximations. "sap" is ours by
# default: at 1 ms all three run within ~5% of each other on the demo grasp,
# and at 5 ms only "sap" and "similar" still hold the sphere through the lift
# ("lagged", Drake's own default, lets it slip). TAMSI is not offered: it
# ignores the PD actuators and coupler constraints the hands need (the joints
# silently never move).
CONTACT_APPROXIMATIONS = ("sap", "similar", "lagged")


@dc.dataclass
class FixedMount:
    """The hand base welded to the world at ``X_WB``."""

    X_WB: Transform = dc.field(default_factory=Transform)


@dc.dataclass
class FloatingWrist:
    """An actuated 6-DOF "floating wrist" carrying the hand base (no arm).

    Three prismatic joints (x, y, z) then three revolute joints (yaw about z,
    pitch about y, roll about x), so the commanded 6-vector
    ``[x, y, z, roll, pitch, yaw]`` is the base pose in world with
    ``R_WB = Rz(yaw) Ry(pitch) Rx(roll)``. ``X_WB`` is the initial pose. The
    arm that would carry the hand is taken as gravity compensated: gravity is
    off for the wrist and hand bodies (it still acts on the object).
    """

    X_WB: Transform = dc.field(default_factory=Transform)
    translation_kp: float = 2.0e4  # N/m
    translation_kd: float = 4.0e2  # N*s/m
    rotation_kp: float = 2.0e3  # N*m/rad
    rotation_kd: float = 4.0e1  # N*m*s/rad


@dc.dataclass
class HandConfig:
    kind: str = "shadow"
    # Shadow: xFJ1 = coupling_ratio * xFJ2 (1.0 for the C6 hand, 1.1 for the C5
    # hand). None takes the hand's default; the Barrett distal ratio is fixed.
    coupling_ratio: float | None = None
    # Or !Arm: the hand bolted to a robot arm's flange (handle_drake.devices.arm).
    mount: FixedMount | FloatingWrist | Arm = dc.field(default_factory=FixedMount)
    # Initial joint positions (rad) by actuated joint name; others start at 0.
    initial_position: dict[str, float] = dc.field(default_factory=dict)
    # Taxel arrays on the distal pads and the palm (handle_drake.devices.taxels): the
    # station then exports hand.taxels (and, with estimator: true, object.pose_estimated).
    taxels: TaxelConfig | None = None
    # The actuators' effort limits: "sheet" (the model file's) or "menagerie" (MuJoCo
    # Menagerie's Shadow hand: 1 N m on the finger joints; base.hands.effort_limit), each
    # times effort_scale in (0, 1] (perturbed physics).
    effort_limits: str = "sheet"
    effort_scale: float = 1.0


@dc.dataclass
class ObjectConfig:
    """The object to grasp; see ``handle_drake.geometry.objects`` for kinds and sizes."""

    kind: str = "sphere"  # a catalogue kind, or "mesh" (then file, scale, density)
    size: float = 0.06  # m, the kind's characteristic length (mesh: derived, ignored)
    # Optional overrides (m) of the kind's other dimensions, e.g. {depth: 0.01}
    # for a thin box; see handle_drake.geometry.objects.PROPORTIONS.
    dimensions: dict[str, float] = dc.field(default_factory=dict)
    mass: float | None = None  # kg; None derives it from the kind's density
    mu: float = 0.8  # Coulomb friction coefficient (static = dynamic)
    X_WO: Transform = dc.field(default_factory=Transform)
    # If true, X_WO's z is replaced so that the object rests on the table top.
    on_table: bool = True
    # If true, the object is welded to the world at X_WO (kinematic grasp
    # trials: the hand closes on an object that cannot move, as in the
    # report's OpenRAVE experiments).
    fixed: bool = False
    # kind "mesh": the mesh file (OBJ, STL, PLY, ...; relative paths are taken
    # from the scenario file's folder, else the working directory), the scale
    # from file units to m, and the density (kg/m^3) used when mass is None.
    # See handle_drake.geometry.objects.mesh.
    file: str = ""
    scale: float = 1.0
    density: float | None = None
    # An accelerometer on the object (see handle_drake.devices.accelerometer.config): the
    # station then exports object.acceleration, .roll_pitch, .free_fall, .slip, ...
    accelerometer: AccelerometerConfig | None = None
    # An object on a joint (handle_drake.scene.jointed): a revolute joint about the object's
    # own z axis at X_WO with thread friction, on an optional welded base (a cap on its
    # bottle); the station then exports object.joint_position. None: a free (or fixed) body.
    joint: ThreadJoint | None = None
    # false: the bare shape (a cylinder: one Drake Cylinder, the analytic solid-cylinder
    # inertia of ``mass``), without the rest-on-table contact feet; an object on a joint is
    # always bare. The in-hand tasks' objects.
    contact_feet: bool = True
    # N/m: the bare object's (and its base's) point-contact stiffness; 0: Drake's default
    point_stiffness: float = 0.0


@dc.dataclass
class TableConfig:
    top_height: float = 0.0  # m, world z of the table top
    size_x: float = 0.8
    size_y: float = 0.8


@dc.dataclass
class MidiControllerConfig:
    """The iControls Pro MIDI controller model (``handle_drake.devices.midi``) in the scene.

    ``X_WC`` places the controller frame C (bottom centre of its base, x along
    the channel strips, y away from the user); with ``on_table`` its z is the
    table top. ``fixed`` welds the base to the world, else it is a free body.
    ``mapping`` is a mapping file (empty: the shipped iControls Pro mapping);
    ``scan_period`` (s) how often the device reads its controls and sends MIDI.
    """

    X_WC: Transform = dc.field(default_factory=Transform)
    on_table: bool = True
    fixed: bool = True
    mapping: str = ""
    scan_period: float = 0.002


@dc.dataclass
class SimHandDriver:
    """The simulated hand: Drake PD actuators tracking the position command.

    ``max_joint_velocity`` (rad/s) rate-limits the command before it reaches
    the PD loops, like a real hand's controller; 0 disables the limit.
    """

    max_joint_velocity: float = 4.0
    # Period (s) at which the hand and wrist commands are sampled and rate
    # limited (200 Hz, a hand controller's command rate); the PD loops
    # themselves run inside the plant at every time step.
    control_period: float = 0.005


@dc.dataclass
class Keyframe:
    """One point of a scripted command; commands are interpolated linearly.

    ``hand`` gives actuated joint positions (rad) by name; joints it does not
    name keep their value from the previous keyframe (or the initial
    position). ``wrist`` is ``[x y z roll pitch yaw]`` (m, rad) for a
    floating-wrist mount, or empty to keep the previous one.
    """

    time: float = 0.0  # s
    hand: dict[str, float] = dc.field(default_factory=dict)
    wrist: list[float] = dc.field(default_factory=list)


@dc.dataclass
class GuardedGraspController:
    """A guarded approach and close (``systems.guarded_grasp.GuardedGrasp``) drives the station.

    The hand base starts at ``start_pose`` (``[x y z roll pitch yaw]``, m and
    rad; the floating wrist is placed there) with the hand in ``preshape``,
    moves along ``direction`` at ``speed`` until a ``guard_bodies`` hand body
    touches the object (or ``max_travel`` is used up), backs off
    ``standoff`` and closes to ``closed``. Hand commands are actuated joint
    positions (rad) by name; joints not named are 0. ``guard_bodies`` names
    hand bodies; empty means every hand body. A scenario has either a
    controller or a ``script``, not both.
    """

    start_pose: list[float] = dc.field(default_factory=list)
    direction: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, -1.0])
    speed: float = 0.4  # m/s
    max_travel: float = 0.25  # m
    standoff: float = 0.0  # m
    preshape: dict[str, float] = dc.field(default_factory=dict)
    closed: dict[str, float] = dc.field(default_factory=dict)
    guard_bodies: list[str] = dc.field(default_factory=list)
    period: float = 0.004  # s


@dc.dataclass
class GraspMetric:
    """Score the grasp the run ends in: the Bimodal Wrench Space metric of the hand's
    contacts on the object (soft-finger contacts with the object's friction, the
    contact surface model of radius ``surface_radius``, moments scaled by half the
    object size), averaged over ``hold_samples`` instants spread over the last
    ``hold_window`` seconds of the run (its last one at ``simulation_duration``).

    ``placements`` (the robust objective of ``babble --placement-error``): sideways
    moves ``[dx, dy]`` (m) of the guarded grasp's ``start_pose``; the run is made once
    per placement and the metric is the mean of their metrics. Empty: one run, the
    scenario as it is.
    """

    hold_samples: int = 8
    hold_window: float = 0.1  # s
    surface_radius: float = 0.004  # m; 0: raw mean contacts
    gamma: float = 0.002  # m, torsional friction
    num_edges: int = 8  # friction-cone edges
    placements: list[list[float]] = dc.field(default_factory=list)  # [[dx, dy], ...] m


@dc.dataclass
class CanHandDriver(CanHandDriverConfig):
    """A real (or simulated-firmware) CAN hand behind the CAN bus server.

    Fields (host, port, timeouts, rates) are those of
    :class:`handle_drake.devices.can_hand.config.CanHandDriverConfig`.
    """


def default_plant_config(**fields) -> MultibodyPlantConfig:
    """Drake's ``MultibodyPlantConfig`` with this project's defaults, then
    ``fields`` (e.g. ``time_step=0.002``): a 1 ms discrete step, point contact,
    the ``sap`` approximation, and outputs computed from the current state on
    demand (``use_sampled_output_ports: false``: the contact results are then
    only built when a sensor asks, every control period, not stored in the
    state at every step; ~10% faster)."""
    defaults = dict(time_step=0.001, contact_model="point",
                    discrete_contact_approximation="sap", use_sampled_output_ports=False)
    return MultibodyPlantConfig(**(defaults | fields))


def default_visualization_config(**fields) -> VisualizationConfig:
    """Drake's ``VisualizationConfig`` with this project's defaults, then
    ``fields``: Meshcat at 32 Hz, the illustration geometry and the contact
    forces (no proximity or inertia layers), and no Meshcat of its own (the
    station draws only into a Meshcat it is given). Its ``lcm_bus`` is not
    used: the station's LCM messages go to an in-memory null bus."""
    defaults = dict(publish_period=1.0 / 32, publish_proximity=False, publish_inertia=False,
                    enable_meshcat_creation=False)
    return VisualizationConfig(**(defaults | fields))


@dc.dataclass
class Scenario:
    hand: HandConfig = dc.field(default_factory=HandConfig)
    object: ObjectConfig | None = dc.field(default_factory=ObjectConfig)
    # Further objects on the table (instances object_1, object_2, ...; see
    # handle_drake.scene.config); single-object commands act on ``object``.
    objects: list[ObjectConfig] = dc.field(default_factory=list)
    # The toy-sorting box, a fixed body with shaped holes (handle_drake.scene).
    sorting_box: SortingBoxConfig | None = None
    table: TableConfig | None = dc.field(default_factory=TableConfig)
    # The plant (Drake's own config; AddMultibodyPlant reads it).
    plant_config: MultibodyPlantConfig = dc.field(default_factory=default_plant_config)
    driver: SimHandDriver | CanHandDriver = dc.field(default_factory=SimHandDriver)
    simulation_duration: float = 2.0  # s
    random_seed: int = 0
    # An optional scripted command (hand joints and wrist pose over time), so a
    # scenario file alone describes a runnable experiment.
    script: list[Keyframe] = dc.field(default_factory=list)
    # Or a controller that drives the hand and wrist instead of the script.
    controller: GuardedGraspController | None = None
    # An optional score of the run (printed by ``handle-drake simulate``).
    metric: GraspMetric | None = None
    # What the station draws when a Meshcat is given (Drake's own config;
    # ApplyVisualizationConfig reads it).
    visualization: VisualizationConfig = dc.field(default_factory=default_visualization_config)
    # Depth cameras (simulation: Drake's RgbdSensor with RenderEngineVtk): Drake's
    # CameraConfig plus the device profile (handle_drake.devices.camera.config).
    cameras: list[DepthCamera] = dc.field(default_factory=list)
    # An optional MIDI controller on the table (an instrumented object).
    midi_controller: MidiControllerConfig | None = None


def LoadScenario(*, filename: str | Path | None = None, data: str | None = None,
                 text: str | None = None, source: str = "text") -> Scenario:
    """Loads a scenario from a YAML file (or its ``text``, named ``source`` in errors:
    e.g. a trial log's record), then applies an optional override string.

    A ``filename`` that names no file but a shipped scenario (``diagrams/NAME.yaml``
    outside a checkout, or ``NAME``) loads the installed one
    (:func:`~handle_drake.base.models.shipped_path`).

    Raises:
        FileNotFoundError: the file does not exist.
        ScenarioError: malformed YAML, an unknown field or tag, or an invalid
            value; the message names the file and the problem.
    """
    scenario = Scenario()
    if filename is not None and text is not None:
        raise ValueError("LoadScenario: give filename or text, not both")
    if text is not None:
        scenario = _load(text, scenario, source=source)
    if filename is not None:
        path = shipped_path(filename) if isinstance(filename, (str, Path)) else filename
        try:
            text = read_text_file(path, "scenario")
        except FileNotFoundError as error:
            raise FileNotFoundError(f"{error}; {SHIPPED_HINT}") from None
        scenario = _load(text, scenario, source=str(filename))
        _resolve_mesh_file(scenario, Path(path).parent)
    if data is not None:
        scenario = _load(data, scenario, source="override")
    validate_scenario(scenario)
    return scenario


def DumpScenario(scenario: Scenario) -> str:
    """The scenario as YAML text that :func:`LoadScenario` reads back.

    Drake's ``yaml_dump_typed`` leaves out fields that are None; a field whose
    default is not None (``object``, ``table``) is written as ``null`` so that
    the text loads back to the same scenario.
    """
    text = yaml_dump_typed(scenario)
    defaults = Scenario()
    for field in dc.fields(Scenario):
        if getattr(scenario, field.name) is None and getattr(defaults, field.name) is not None:
            text += f"{field.name}: null\n"
    return text


def _resolve_mesh_file(scenario: Scenario, folder: Path) -> None:
    # A relative mesh path in a scenario file names a file next to the scenario (the
    # objects' and the sorting box's mesh holes' too).
    items = [scenario.object, *scenario.objects]
    if scenario.sorting_box is not None:
        items += scenario.sorting_box.holes
    for o in items:
        if o is not None and o.file and not Path(o.file).expanduser().is_absolute():
            candidate = folder / o.file
            if candidate.is_file():
                o.file = str(candidate.resolve())


def _load(text: str, defaults: Scenario, source: str) -> Scenario:
    if not text.strip():
        return defaults
    text = translate_deprecated_keys(text, source)
    _refuse_renamed_keys(text, source)
    check_yaml_text(text, Scenario, source)
    if yaml.compose(text, Loader=yaml.SafeLoader) is None:  # comments only: as empty
        return defaults
    try:
        return yaml_load_typed(schema=Scenario, data=text, defaults=defaults)
    except Exception as error:  # yaml.YAMLError, RuntimeError, ValueError, TypeError
        message = str(error).strip().splitlines()
        raise ScenarioError(f"invalid scenario ({source}): {' '.join(message)[:500]}") from None


#: Keys that became fields of Drake's config types: old -> new (a camera's old
#: keys are per list item, ``cameras[i].<old>``).
RENAMED_KEYS = {"visualization_period": "visualization.publish_period (Drake's "
                                        "VisualizationConfig)"}
RENAMED_CAMERA_KEYS = {"name": "config.name", "X_PC": "config.X_PB",
                       "parent": "config.X_PB.base_frame (world | wrist)"}


def _refuse_renamed_keys(text: str, source: str) -> None:
    """A one-line :class:`ScenarioError` naming an old key and its new place."""
    if not any(key in text for key in ("visualization_period", "cameras")):
        return
    try:
        root = yaml.compose(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (yaml.YAMLError, RecursionError):
        return  # check_yaml_text names the problem
    if not isinstance(root, yaml.MappingNode):
        return
    for key, value in root.value:
        if key.value in RENAMED_KEYS:
            raise ScenarioError(f"{key.value}: renamed to {RENAMED_KEYS[key.value]} "
                                f"({source})")
        if key.value == "cameras" and isinstance(value, yaml.SequenceNode):
            for i, item in enumerate(value.value):
                if not isinstance(item, yaml.MappingNode):
                    continue
                for k, _ in item.value:
                    if getattr(k, "value", None) in RENAMED_CAMERA_KEYS:
                        raise ScenarioError(
                            f"cameras[{i}].{k.value}: moved into Drake's CameraConfig as "
                            f"cameras[{i}].{RENAMED_CAMERA_KEYS[k.value]} ({source})")


def _check_transform(name: str, transform: Transform) -> None:
    if not transform.IsDeterministic():  # GetDeterministicValue would abort the process
        raise ScenarioError(f"{name}: expected a deterministic pose, got a random one")
    check_pose(name, transform)  # names a NaN angle or axis (Drake: "NaN is detected ...")
    try:
        X = transform.GetDeterministicValue()
    except Exception as error:
        raise ScenarioError(f"{name}: {error}") from None
    if not np.all(np.isfinite(X.GetAsMatrix4())):
        raise ScenarioError(f"{name}: pose must be finite, got {X.GetAsMatrix4()[:3].tolist()}")


def _check_positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ScenarioError(f"{name} must be a finite number > 0, got {value!r}")


def _validate_catalogue_object(o: ObjectConfig) -> None:
    if o.kind not in KINDS:
        raise ScenarioError(
            f"object.kind: unknown object {short(o.kind)}; "
            f"expected one of {list(KINDS) + ['mesh']}"
        )
    _check_positive("object.size", o.size)
    try:
        ObjectSpec(kind=o.kind, size=o.size, dimensions=o.dimensions or None)
    except ValueError as error:
        raise ScenarioError(f"object: {error}") from None
    if o.file:
        raise ScenarioError(f"object.file: only kind 'mesh' reads a file, got kind "
                            f"{o.kind!r} with file {o.file!r}")
    if o.mass is not None:
        _check_positive("object.mass", o.mass)
    if not (math.isfinite(o.mu) and o.mu >= 0):
        raise ScenarioError(f"object.mu must be finite and >= 0, got {o.mu}")
    _check_transform("object.X_WO", o.X_WO)


def validate_scenario(scenario: Scenario) -> None:
    """Checks values the YAML schema cannot; raises :class:`ScenarioError`."""

    if scenario.hand.kind not in HAND_SPECS:
        raise ScenarioError(
            f"hand.kind: unknown hand {short(scenario.hand.kind)}; "
            f"expected one of {sorted(HAND_SPECS)}"
        )
    spec = HAND_SPECS[scenario.hand.kind]
    if scenario.hand.coupling_ratio is not None:
        _check_positive("hand.coupling_ratio", scenario.hand.coupling_ratio)
        try:
            spec.coupling_ratios(scenario.hand.coupling_ratio)
        except ValueError as error:
            raise ScenarioError(f"hand.coupling_ratio: {error}") from None
    _check_transform("hand.mount.X_WB", scenario.hand.mount.X_WB)
    if isinstance(scenario.hand.mount, Arm):
        validate_arm(scenario.hand.mount, ScenarioError)
    for name, value in scenario.hand.initial_position.items():
        if name not in spec.actuated_joint_names:
            raise ScenarioError(
                f"hand.initial_position: {short(name)} is not an actuated joint of the "
                f"{spec.name} hand; expected one of {list(spec.actuated_joint_names)}"
            )
        if not math.isfinite(value):
            raise ScenarioError(f"hand.initial_position[{name}] must be finite, got {value}")
    if scenario.hand.taxels is not None:
        _validate_taxels(scenario)
    if scenario.hand.effort_limits not in EFFORT_LIMITS:
        raise ScenarioError(f"hand.effort_limits: expected one of {list(EFFORT_LIMITS)}, got "
                            f"{short(scenario.hand.effort_limits)}")
    scale = scenario.hand.effort_scale
    if isinstance(scale, bool) or not (isinstance(scale, int | float) and 0 < scale <= 1):
        raise ScenarioError(f"hand.effort_scale: expected a value in (0, 1], got {short(scale)}")
    if scenario.object is not None and scenario.object.kind == "mesh":
        _validate_mesh_object(scenario.object)
    elif scenario.object is not None:
        _validate_catalogue_object(scenario.object)
    if scenario.object is not None and scenario.object.accelerometer is not None:
        _validate_accelerometer(scenario)  # mesh or catalogue object alike
    _validate_bare_objects(scenario)
    if scenario.table is not None:
        if not math.isfinite(scenario.table.top_height):
            raise ScenarioError("table.top_height must be finite")
        _check_positive("table.size_x", scenario.table.size_x)
        _check_positive("table.size_y", scenario.table.size_y)
    _validate_plant_config(scenario.plant_config)
    _check_positive("simulation_duration", scenario.simulation_duration)
    _check_positive("visualization.publish_period", scenario.visualization.publish_period)
    _validate_script(scenario, spec)
    _validate_cameras(scenario)
    if scenario.controller is not None:
        _validate_controller(scenario, spec)
    if scenario.metric is not None:
        _validate_metric(scenario)
    if scenario.midi_controller is not None:
        validate_midi_controller(scenario.midi_controller)
    if isinstance(scenario.driver, CanHandDriver):
        try:
            scenario.driver.validate()
        except ValueError as error:
            raise ScenarioError(f"driver: {error}") from None
    if isinstance(scenario.driver, SimHandDriver):
        if not (math.isfinite(scenario.driver.max_joint_velocity)
                and scenario.driver.max_joint_velocity >= 0):
            raise ScenarioError("driver.max_joint_velocity must be finite and >= 0")
        _check_positive("driver.control_period", scenario.driver.control_period)
    check_ranges(scenario)
    if scenario.objects or scenario.sorting_box is not None:
        validate_scene(scenario, validate_scenario, ScenarioError)


def _validate_taxels(scenario: Scenario) -> None:
    config = scenario.hand.taxels
    try:
        config.validate()
    except ValueError as error:
        raise ScenarioError(f"hand.taxels.{error}") from None
    if scenario.hand.kind != "shadow":
        raise ScenarioError(f"hand.taxels: only the Shadow hand carries tactile pads, got "
                            f"hand.kind {short(scenario.hand.kind)}")
    if config.estimator:
        if scenario.object is None or scenario.object.kind not in (
                "sphere", "cylinder", "cuboid", "rotated_cuboid"):
            raise ScenarioError("hand.taxels.estimator: expected an object of kind sphere, "
                                "cylinder or cuboid")
        if isinstance(scenario.hand.mount, Arm):
            raise ScenarioError("hand.taxels.estimator: expected a !FixedMount or "
                                "!FloatingWrist (the arm's forward kinematics is not wired)")


def is_bare(o: ObjectConfig) -> bool:
    """Whether the station builds ``o`` as a bare shape (``handle_drake.scene.jointed``)."""
    return o.joint is not None or not o.contact_feet


def _validate_bare_objects(scenario: Scenario) -> None:
    """An object on a joint or without contact feet: a cylinder of given mass, point contact
    (its only model), the main object only."""
    for i, o in enumerate(scenario.objects):
        if is_bare(o):
            raise ScenarioError(f"objects[{i}]: a joint or contact_feet: false is for the "
                                f"main object only")
    o = scenario.object
    if o is None:
        return
    if not (isinstance(o.point_stiffness, int | float) and math.isfinite(o.point_stiffness)
            and 0 <= o.point_stiffness <= 1e9):
        raise ScenarioError(f"object.point_stiffness: expected a value in [0, 1e9] N/m, got "
                            f"{short(o.point_stiffness)}")
    if not is_bare(o):
        if o.point_stiffness:
            raise ScenarioError("object.point_stiffness: only for a bare object (a joint or "
                                "contact_feet: false)")
        return
    what = "object.joint" if o.joint is not None else "object.contact_feet: false"
    if o.kind != "cylinder" or set(o.dimensions) - {"height"}:
        raise ScenarioError(f"{what}: expected kind cylinder (size: diameter, dimensions: "
                            f"{{height}}), got kind {short(o.kind)}")
    if o.mass is None:
        raise ScenarioError(f"{what}: needs object.mass (kg)")
    if scenario.plant_config.contact_model != "point":
        raise ScenarioError(f"{what}: point contact only (plant_config.contact_model: point), "
                            f"got {short(scenario.plant_config.contact_model)}")
    if o.fixed:  # an accelerometer may ride on it (issue 47: the in-hand turn's gravity)
        raise ScenarioError(f"{what}: not fixed")
    if o.joint is not None:
        if o.on_table:
            raise ScenarioError("object.joint: the joint is at X_WO: expected on_table: false")
        validate_thread_joint(o.joint, ScenarioError)
        if o.joint.base is not None:
            _check_transform("object.joint.base.X_WB", o.joint.base.X_WB)


def _validate_plant_config(config) -> None:
    """Every ``plant_config`` field Drake would otherwise refuse late (or abort on)."""
    if not isinstance(config, MultibodyPlantConfig):
        raise ScenarioError(f"plant_config: expected a pydrake MultibodyPlantConfig, got "
                            f"{type(config).__name__}")
    _check_positive("plant_config.time_step", config.time_step)
    if config.contact_model not in CONTACT_MODELS:
        hint = (" (Drake's strict hydroelastic needs compliant hydroelastic properties on "
                "every geometry, the hands' links have none: use hydroelastic_with_fallback)"
                if config.contact_model == "hydroelastic" else "")
        raise ScenarioError(f"plant_config.contact_model: expected one of "
                            f"{list(CONTACT_MODELS)}, got {short(config.contact_model)}{hint}")
    if config.discrete_contact_approximation not in CONTACT_APPROXIMATIONS:
        hint = (" (TAMSI ignores the hand's PD actuators and couplers)"
                if config.discrete_contact_approximation == "tamsi" else "")
        raise ScenarioError(
            f"plant_config.discrete_contact_approximation: expected one of "
            f"{list(CONTACT_APPROXIMATIONS)}, got "
            f"{short(config.discrete_contact_approximation)}{hint}")
    _check_positive("plant_config.penetration_allowance", config.penetration_allowance)
    _check_positive("plant_config.stiction_tolerance", config.stiction_tolerance)
    if not (math.isfinite(config.sap_near_rigid_threshold)
            and config.sap_near_rigid_threshold >= 0):
        raise ScenarioError(f"plant_config.sap_near_rigid_threshold must be finite and >= 0, "
                            f"got {config.sap_near_rigid_threshold!r}")
    if config.contact_surface_representation not in CONTACT_SURFACE_REPRESENTATIONS:
        raise ScenarioError(f"plant_config.contact_surface_representation: expected one of "
                            f"{list(CONTACT_SURFACE_REPRESENTATIONS)}, got "
                            f"{short(config.contact_surface_representation)}")


def _validate_accelerometer(scenario: Scenario) -> None:

    config = scenario.object.accelerometer
    try:
        config.validate(scenario.object.kind)
    except (ValueError, TypeError) as error:
        raise ScenarioError(f"object.accelerometer.{error}") from None
    if config.X_OS is not None:
        _check_transform("object.accelerometer.X_OS", config.X_OS)
        p = config.X_OS.GetDeterministicValue().translation()
        if not np.all(np.abs(p) <= 1.0):  # before the distance sums below overflow
            raise ScenarioError(f"object.accelerometer.X_OS.translation: expected values in "
                                f"[-1, 1] m (a point on the object), got {short(p.tolist())}")
    try:
        spec = object_spec(scenario)
        check_sensor_pose(spec, instrument_X_OS(scenario, spec))
    except ValueError as error:
        raise ScenarioError(f"object.accelerometer.{error}") from None


def _validate_mesh_object(o: ObjectConfig) -> None:
    if not o.file:
        raise ScenarioError("object.file: kind 'mesh' needs a mesh file (OBJ, STL, PLY, ...)")
    if o.dimensions:
        raise ScenarioError(f"object.dimensions: a mesh takes its dimensions from its file "
                            f"(use scale), got {dict(o.dimensions)}")
    if o.mass is not None and o.density is not None:
        raise ScenarioError("object: give mass or density for a mesh, not both")
    if o.size != ObjectConfig.size:
        import warnings


        warnings.warn(f"object.size: ignored for a mesh (its size comes from its file and "
                      f"scale), got {short(o.size)}", MeshObjectWarning, stacklevel=3)
    try:
        mesh_object_spec(o)
    except FileNotFoundError as error:
        raise ScenarioError(f"object.{error}") from None
    except (ValueError, TypeError) as error:
        raise ScenarioError(f"object.{error}") from None


def object_spec(scenario: Scenario):
    """The :class:`~handle_drake.geometry.objects.ObjectSpec` (or mesh spec) of the
    scenario's object: the one place a scenario's object becomes geometry."""
    o = scenario.object
    if o.kind == "mesh":
        return mesh_object_spec(o)
    return ObjectSpec(kind=o.kind, size=o.size, mass=o.mass, mu=o.mu,
                      dimensions=o.dimensions or None, density=o.density)


def mesh_object_spec(o: ObjectConfig):
    """The :class:`~handle_drake.geometry.objects.mesh.MeshObjectSpec` of a kind-"mesh" object."""

    return MeshObjectSpec(file=o.file, scale=o.scale, mass=o.mass, density=o.density, mu=o.mu)


def _validate_script(scenario: Scenario, spec) -> None:
    previous = -math.inf
    for i, keyframe in enumerate(scenario.script):
        where = f"script[{i}]"
        if not math.isfinite(keyframe.time) or keyframe.time < 0:
            raise ScenarioError(f"{where}.time must be finite and >= 0, got {keyframe.time}")
        if keyframe.time <= previous:
            raise ScenarioError(f"{where}.time must increase, got {keyframe.time} after {previous}")
        previous = keyframe.time
        for name, value in keyframe.hand.items():
            if name not in spec.actuated_joint_names:
                raise ScenarioError(
                    f"{where}.hand: {short(name)} is not an actuated joint of the {spec.name} hand"
                )
            if not math.isfinite(value):
                raise ScenarioError(f"{where}.hand[{name}] must be finite, got {value}")
        if keyframe.wrist:
            if not isinstance(scenario.hand.mount, FloatingWrist):
                raise ScenarioError(f"{where}.wrist needs a !FloatingWrist mount")
            if len(keyframe.wrist) != 6 or not all(math.isfinite(v) for v in keyframe.wrist):
                raise ScenarioError(
                    f"{where}.wrist: expected 6 finite values [x y z roll pitch yaw], "
                    f"got {short(keyframe.wrist)}"
                )


def _validate_cameras(scenario: Scenario) -> None:

    names = set()
    for i, camera in enumerate(scenario.cameras):
        where = f"cameras[{i}]"
        if not isinstance(camera.name, str) or not camera.name.strip() or any(
                c in camera.name for c in "./ \t\n"):
            raise ScenarioError(f"{where}.config.name must be a non-empty name without '.', "
                                f"'/' or spaces, got {short(camera.name)}")
        if camera.name in names:
            raise ScenarioError(f"{where}.config.name: duplicate camera name "
                                f"{short(camera.name)}")
        names.add(camera.name)
        try:
            get_profile(camera.profile)
        except ValueError as error:
            raise ScenarioError(f"{where}.profile: {error}") from None
        if camera.parent.startswith(ARM_PARENT_PREFIX):
            _check_arm_camera_parent(scenario, camera.parent, where)
        elif camera.parent not in CAMERA_PARENTS:
            raise ScenarioError(f"{where}.config.X_PB.base_frame: expected one of "
                                f"{list(CAMERA_PARENTS)} or arm::<link>, got "
                                f"{short(camera.parent)}")
        resolve_camera_config(camera, where, ScenarioError)
        _check_transform(f"{where}.config.X_PB", camera.config.X_PB)
        if camera.parent == "world" and scenario.table is not None:
            p = camera.config.X_PB.GetDeterministicValue().translation()
            table = scenario.table
            # The table top is a 5 cm slab below top_height (objects.AddTable).
            if (abs(p[0]) < table.size_x / 2 and abs(p[1]) < table.size_y / 2
                    and table.top_height - 0.05 <= p[2] <= table.top_height):
                raise ScenarioError(f"{where}.config.X_PB: the camera at "
                                    f"{p.round(4).tolist()} is inside the table top (z "
                                    f"{table.top_height - 0.05:g} to {table.top_height:g} m); "
                                    f"place it above the table")
        if camera.target:
            if camera.parent != "world":
                raise ScenarioError(f"{where}.target needs X_PB.base_frame: world (a camera on "
                                    f"the wrist moves; give its orientation in X_PB)")
            if len(camera.target) != 3 or not all(math.isfinite(v) for v in camera.target):
                raise ScenarioError(f"{where}.target: expected 3 finite values [x y z] (m), "
                                    f"got {camera.target}")
            eye = camera.config.X_PB.GetDeterministicValue().translation()
            if np.linalg.norm(np.asarray(camera.target) - eye) < 1e-6:
                raise ScenarioError(f"{where}.target: the camera cannot look at its own "
                                    f"position {eye.tolist()}")


def _check_arm_camera_parent(scenario: Scenario, parent: str, where: str) -> None:
    """``arm::<link>``: the hand is on an ``!Arm`` that has that link."""
    mount = scenario.hand.mount
    if not isinstance(mount, Arm):
        raise ScenarioError(f"{where}.config.X_PB.base_frame: {short(parent)} needs the hand on "
                            f"an !Arm mount (hand.mount)")
    links = ARM_SPECS[mount.kind].links
    link = parent[len(ARM_PARENT_PREFIX):]
    if link not in links:
        raise ScenarioError(f"{where}.config.X_PB.base_frame: the {mount.kind} arm has no link "
                            f"{short(link)}; expected one of "
                            f"{[ARM_PARENT_PREFIX + n for n in links]}")


def _finite_vector(name: str, values, size: int) -> None:
    if len(values) != size or not all(isinstance(v, int | float) and math.isfinite(v)
                                      for v in values):
        raise ScenarioError(f"{name}: expected {size} finite values, got {list(values)[:8]}")


def _validate_controller(scenario: Scenario, spec) -> None:
    c = scenario.controller
    if scenario.script:
        raise ScenarioError("controller: a scenario has a controller or a script, not both")
    if not isinstance(scenario.hand.mount, FloatingWrist):
        raise ScenarioError("controller: the guarded grasp moves the hand base: it needs a "
                            "!FloatingWrist mount")
    _finite_vector("controller.start_pose", c.start_pose, 6)
    _finite_vector("controller.direction", c.direction, 3)
    if not any(c.direction):
        raise ScenarioError("controller.direction must be non-zero")
    _check_positive("controller.speed", c.speed)
    _check_positive("controller.period", c.period)
    for name in ("max_travel", "standoff"):
        value = getattr(c, name)
        if not (math.isfinite(value) and value >= 0):
            raise ScenarioError(f"controller.{name} must be finite and >= 0, got {value}")
    for field in ("preshape", "closed"):
        for name, value in getattr(c, field).items():
            if name not in spec.actuated_joint_names:
                raise ScenarioError(
                    f"controller.{field}: {name!r} is not an actuated joint of the "
                    f"{spec.name} hand; expected one of {list(spec.actuated_joint_names)}")
            if not math.isfinite(value):
                raise ScenarioError(f"controller.{field}[{name}] must be finite, got {value}")


def _validate_metric(scenario: Scenario) -> None:
    m = scenario.metric
    if scenario.object is None:
        raise ScenarioError("metric: scoring a grasp needs an object")
    if isinstance(m.hold_samples, bool) or m.hold_samples < 1:
        raise ScenarioError(f"metric.hold_samples: expected an integer >= 1, got "
                            f"{m.hold_samples!r}")
    _check_positive("metric.hold_window", m.hold_window)
    if m.hold_window >= scenario.simulation_duration:
        raise ScenarioError(f"metric.hold_window: expected < simulation_duration "
                            f"({scenario.simulation_duration} s), got {m.hold_window}")
    for name in ("surface_radius", "gamma"):
        value = getattr(m, name)
        if not (math.isfinite(value) and value >= 0):
            raise ScenarioError(f"metric.{name} must be finite and >= 0, got {value}")
    if m.num_edges < 3:
        raise ScenarioError(f"metric.num_edges: expected >= 3, got {m.num_edges}")
    if m.placements:
        if not isinstance(scenario.controller, GuardedGraspController):
            raise ScenarioError("metric.placements: moving the start placement needs a "
                                "controller: !GuardedGraspController (its start_pose)")
        if len(m.placements) > 64:
            raise ScenarioError(f"metric.placements: expected at most 64 placements, got "
                                f"{len(m.placements)}")
        for i, placement in enumerate(m.placements):
            if len(placement) != 2 or not all(math.isfinite(v) and abs(v) <= 0.05
                                              for v in placement):
                raise ScenarioError(f"metric.placements[{i}]: expected [dx, dy] within "
                                    f"+-0.05 m, got {short(placement)}")
