"""Checks of scenario text and values before anything reaches Drake.

Two layers, both raising :class:`ScenarioError` (re-exported by
:mod:`handle_drake.scenario`) with a message that names the field, what was
expected and what was got (shortened):

- :func:`check_yaml_text` walks the YAML *node graph* (PyYAML ``compose``, no
  construction) against the :class:`~handle_drake.scenario.Scenario` dataclass
  types before Drake's ``yaml_load_typed`` reads it. Drake's reader lets
  through what a user almost never means: a duplicate key (the last one wins),
  a scalar where a tagged variant belongs (``driver: 5`` becomes the first
  field of ``!SimHandDriver``), a document that is only an unknown tag
  (``!Foo {}`` runs the default scenario), a ``base_frame`` name that is
  ignored, and its own errors do not name the field (``could not convert
  string to float: 'big'``). Stochastic schema values (``!Uniform``,
  ``!Gaussian``...) are refused: a scenario is deterministic (Drake aborts the
  process on ``GetDeterministicValue`` of one).
- :func:`check_ranges` bounds every physical quantity to a range the station
  can simulate: values outside pass Drake's own checks and then crash deep in
  the plant (``RuntimeError`` or a ``Failure at ...`` that arrives as
  ``SystemExit``) or ask for absurd work.

Why by hand: no YAML library checks a node graph against Python dataclass
annotations, and the ranges are this project's physical envelope.
"""

import dataclasses as dc
import functools
import math
import os
import types
import typing
from pathlib import Path

import numpy as np
import yaml

__all__ = ["DEPRECATED_KEYS", "LIMITS", "ScenarioDeprecationWarning", "check_input_file",
           "check_yaml_text", "check_ranges", "read_text_file", "short", "short_path",
           "translate_deprecated_keys"]


class ScenarioError(ValueError):
    """A scenario that cannot be built; the message names the field."""


#: (low, high) accepted for each bounded quantity, SI units.
LIMITS = {
    "length": (1e-3, 2.0),  # m: object sizes and dimensions
    "mass": (1e-4, 1e3),  # kg
    "mu": (0.0, 10.0),
    "time_step": (1e-5, 0.01),  # s: SAP at point contact needs <= 10 ms
    "simulation_duration": (1e-3, 3600.0),  # s
    "steps": (1, 2_000_000),  # simulation_duration / plant_config.time_step
    "position": (-10.0, 10.0),  # m: any pose's translation, the wrist script
    "table_size": (1e-2, 100.0),  # m
    "gain": (1e-6, 1e8),  # wrist PD gains (N/m, N*s/m, N*m/rad, N*m*s/rad)
    "joint_velocity": (0.0, 1e3),  # rad/s (0 disables the limit)
    "control_period": (1e-4, 0.1),  # s
    "visualization_period": (1e-3, 10.0),  # s
    "angle": (-1e4, 1e4),  # rad or deg, any joint value or angle
    "wrist_angle": (-2 * math.pi, 2 * math.pi),  # rad: every orientation, no wind-up
    "wrist_speed": (0.0, 10.0),  # m/s between two keyframes of the wrist script
    "wrist_rate": (0.0, 100.0),  # rad/s likewise (1e4 rad in 0.2 s makes SAP diverge)
    "coupling_ratio": (0.5, 2.0),  # xFJ1 / xFJ2 (the C6 hand 1.0, the C5 1.1)
}
_MAX_NODES = 100_000  # alias chains ("billion laughs") expand to more than this
_SCALAR_TAGS = {"tag:yaml.org,2002:int", "tag:yaml.org,2002:float", "tag:yaml.org,2002:str",
                "tag:yaml.org,2002:bool", "tag:yaml.org,2002:null"}
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: ~10x faster composing
_MAP = "tag:yaml.org,2002:map"
_SEQ = "tag:yaml.org,2002:seq"


def short(value, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (with the full length)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def short_path(path, limit: int = 120) -> str:
    """A path for a message: its end (the file name) kept when it is long."""
    text = str(path)
    return text if len(text) <= limit else f"...{text[-limit:]}"


def check_input_file(filename, what: str, max_bytes: int | None = None) -> Path:
    """``filename`` as a Path if it names a readable regular file.

    FileNotFoundError only when nothing is there; a directory, a FIFO or
    device (reading it would block), an unreadable file or one larger than
    ``max_bytes`` is a ValueError saying which, ``what`` naming the field.
    """
    import stat

    if not isinstance(filename, (str, os.PathLike)) or not str(filename):
        raise TypeError(f"{what}: expected a file path, got {short(filename)}")
    path = Path(filename).expanduser()
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} not found: {short_path(path)}") from None
    except (OSError, ValueError) as error:  # name too long, NUL byte, a file as a folder, ...
        reason = getattr(error, "strerror", None) or str(error)
        raise ValueError(f"{what} {short_path(path)}: {reason}") from None
    if stat.S_ISDIR(info.st_mode):
        raise ValueError(f"{what}: expected a file, got the directory {short_path(path)}")
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{what}: expected a regular file, got a FIFO, socket or device "
                         f"{short_path(path)}")
    if max_bytes is not None and info.st_size > max_bytes:
        raise ValueError(f"{what} {short_path(path)}: expected at most {max_bytes} bytes, "
                         f"got {info.st_size}")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{what} {short_path(path)}: not readable (permission denied)")
    return path


def read_text_file(filename, what: str, max_bytes: int = 16 << 20) -> str:
    """The UTF-8 text of a regular file (see :func:`check_input_file`); a file
    that is not UTF-8 is a ValueError naming ``what`` and the offending byte."""
    path = check_input_file(filename, f"{what} file", max_bytes)
    try:
        return path.read_text(encoding="utf-8")
    except OSError as error:
        raise ValueError(f"{what} file {short_path(path)}: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{what} file {short_path(path)}: expected UTF-8 text, got a byte "
                         f"0x{error.object[error.start]:02x} at offset {error.start}") from None


def _error(path: str, expected: str, got) -> Exception:
    return ScenarioError(f"{path or 'scenario'}: expected {expected}, got {got}")


def _describe(node) -> str:
    if isinstance(node, yaml.ScalarNode):
        tag = "" if node.tag in _SCALAR_TAGS else f"{node.tag} "
        return f"{tag}{short(node.value)}"
    if isinstance(node, yaml.SequenceNode):
        return f"a list of {len(node.value)} items"
    tag = "" if node.tag == _MAP else f"{node.tag} "
    return f"{tag}a mapping".strip()


class _Walker:
    def __init__(self):
        self.nodes = 0

    def visit(self, node, kind, path: str) -> None:
        self.nodes += 1
        if self.nodes > _MAX_NODES:
            raise _error(path, f"at most {_MAX_NODES} YAML nodes (aliases count each time)",
                         "more")
        origin = typing.get_origin(kind)
        args = typing.get_args(kind)
        if origin in (typing.Union, types.UnionType):
            options = [a for a in args if a is not type(None)]
            if type(None) in args and _is_null(node):
                return
            if len(options) == 1:
                return self.visit(node, options[0], path)
            return self._variant(node, options, path)
        if kind is float or kind is int:
            return self._number(node, kind, path)
        if kind is bool:
            if not (isinstance(node, yaml.ScalarNode) and node.tag.endswith(":bool")):
                raise _error(path, "true or false", _describe(node))
            return None
        if kind is str:
            if not isinstance(node, yaml.ScalarNode) or node.tag not in _SCALAR_TAGS:
                raise _error(path, "a string", _describe(node))
            if not node.tag.endswith(":str"):  # Drake's reader refuses a plain 5, true, null
                raise _error(path, "a string (quote a value YAML reads as a number, "
                             "boolean or null)", _describe(node))
            return None
        if origin is dict:
            self._mapping(node, path)
            seen = set()
            for key, value in node.value:
                name = self._key(key, path, seen)
                self.visit(value, args[1], f"{path}[{name}]")
            return None
        if origin is list:
            if not isinstance(node, yaml.SequenceNode) or node.tag != _SEQ:
                raise _error(path, "a list", _describe(node))
            for i, item in enumerate(node.value):
                self.visit(item, args[0], f"{path}[{i}]")
            return None
        if _is_transform(kind):
            return self._transform(node, path)
        if dc.is_dataclass(kind) or _is_drake_struct(kind):
            return self._dataclass(node, kind, path, tagged=False)
        return None  # a type this walker does not know: Drake's reader checks it

    def _number(self, node, kind, path):
        what = "an integer" if kind is int else "a number"
        if not isinstance(node, yaml.ScalarNode) or node.tag not in _SCALAR_TAGS:
            raise _error(path, what, _describe(node))
        if node.tag.endswith(":int") or (kind is float and node.tag.endswith(":float")):
            return
        # PyYAML resolves YAML 1.1 (``1e-3`` without a dot is a string there); Drake's
        # reader is YAML 1.2: a plain (unquoted) scalar that parses as a number is one.
        if node.tag.endswith(":str") and not node.style:  # plain: None (PyYAML), "" (libyaml)
            try:
                int(node.value) if kind is int else float(node.value)
                return
            except ValueError:
                pass
        raise _error(path, what, _describe(node))

    def _mapping(self, node, path):
        if not isinstance(node, yaml.MappingNode):
            raise _error(path, "a mapping", _describe(node))

    def _key(self, key, path, seen):
        if not isinstance(key, yaml.ScalarNode) or key.tag not in _SCALAR_TAGS:
            raise _error(path, "plain keys", _describe(key))
        if key.value in seen:
            raise _error(f"{path}.{key.value}".lstrip("."), "each key once",
                         "a duplicate key (YAML would keep only the last value)")
        seen.add(key.value)
        return key.value

    def _dataclass(self, node, kind, path, tagged):
        self._mapping(node, path)
        if not tagged and node.tag != _MAP:
            raise _error(path, f"a plain mapping of {kind.__name__} fields",
                         f"the tag {short(node.tag)}")
        fields, hints = _schema(kind)
        seen = set()
        for key, value in node.value:
            name = self._key(key, path, seen)
            where = f"{path}.{name}".lstrip(".")
            if name not in fields:
                raise _error(where, f"one of the {kind.__name__} fields {sorted(fields)}",
                             f"unknown field {short(name)}")
            self.visit(value, hints[name], where)

    def _variant(self, node, options, path):
        tags = {f"!{o.__name__}": o for o in options if dc.is_dataclass(o)}
        if not tags:
            return None
        if isinstance(node, yaml.MappingNode) and node.tag == _MAP:  # Drake: the first one
            return self._dataclass(node, options[0], path, tagged=True)
        if not isinstance(node, yaml.MappingNode) or node.tag not in tags:
            raise _error(path, f"one of {', '.join(f'{t} {{...}}' for t in tags)}",
                         _describe(node))
        return self._dataclass(node, tags[node.tag], path, tagged=True)

    def _vector(self, node, n, path):
        if not isinstance(node, yaml.SequenceNode) or node.tag != _SEQ or len(node.value) != n:
            raise _error(path, f"a list of {n} numbers (deterministic)", _describe(node))
        for i, item in enumerate(node.value):
            self._number(item, float, f"{path}[{i}]")

    def _transform(self, node, path):
        self._mapping(node, path)
        if node.tag != _MAP:
            raise _error(path, "a plain mapping {translation, rotation}", _describe(node))
        seen = set()
        for key, value in node.value:
            name = self._key(key, path, seen)
            where = f"{path}.{name}"
            if name == "base_frame":
                # A camera names its parent frame (world, wrist or arm::<link>; the
                # scenario's camera check names the allowed ones).
                camera = path.startswith("cameras[") and path.endswith("].config.X_PB")
                if camera and isinstance(value, yaml.ScalarNode) and value.tag == _STR:
                    continue
                if not (_is_null(value) or (isinstance(value, yaml.ScalarNode)
                                            and value.value == "world")):
                    raise _error(where, "'world' (poses are in the world frame)",
                                 _describe(value))
            elif name == "translation":
                self._vector(value, 3, where)
            elif name == "rotation":
                self._rotation(value, where)
            else:
                raise _error(where, "one of ['base_frame', 'rotation', 'translation']",
                             f"unknown field {short(name)}")

    def _rotation(self, node, path):
        expected = "!Rpy {deg: [r, p, y]}, !AngleAxis {angle_deg: a, axis: [x, y, z]} or " \
                   "!Identity {}"
        if not isinstance(node, yaml.MappingNode):
            raise _error(path, expected, _describe(node))
        fields = {"!Rpy": {"deg"}, "!AngleAxis": {"angle_deg", "axis"}, "!Identity": set(),
                  _MAP: set()}  # untagged: Drake's first variant, Identity (``{}``)
        if node.tag not in fields:
            if node.tag == "!Uniform":
                raise _error(path, expected + " (a scenario is deterministic)",
                             "a random !Uniform rotation")
            raise _error(path, expected, _describe(node))
        seen = set()
        for key, value in node.value:
            name = self._key(key, path, seen)
            if name not in fields[node.tag]:
                raise _error(f"{path}.{name}", f"one of {sorted(fields[node.tag])}",
                             f"unknown field {short(name)}")
            if name == "angle_deg":
                self._number(value, float, f"{path}.angle_deg")
            else:
                self._vector(value, 3, f"{path}.{name}")


@functools.cache
def _schema(kind):
    if _is_drake_struct(kind):  # e.g. MultibodyPlantConfig: its fields are __fields__
        types_ = {f.name: f.type for f in kind.__fields__}
        return types_, types_
    return {f.name: f for f in dc.fields(kind)}, typing.get_type_hints(kind)


def _is_drake_struct(kind) -> bool:
    """A pydrake struct that Drake's YAML reader fills by its ``__fields__``."""
    return isinstance(kind, type) and kind.__module__.startswith("pydrake") and isinstance(
        getattr(kind, "__fields__", None), tuple)


def _is_null(node) -> bool:
    return isinstance(node, yaml.ScalarNode) and node.tag.endswith(":null")


def _is_transform(kind) -> bool:
    return getattr(kind, "__name__", "") == "Transform" and "schema" in getattr(
        kind, "__module__", "")


def check_yaml_text(text: str, schema, source: str, what: str = "scenario") -> None:
    """Refuses YAML (a scenario, or ``what`` of dataclass ``schema``) the typed
    reader would misread; see the module docstring."""
    try:
        documents = list(yaml.compose_all(text, Loader=_LOADER))
    except yaml.YAMLError as error:
        raise ScenarioError(f"invalid {what} ({source}): not YAML: "
                            f"{short(' '.join(str(error).split()), 300)}") from None
    except RecursionError:
        raise ScenarioError(f"invalid {what} ({source}): nested too deeply") from None
    if len(documents) > 1:
        raise ScenarioError(f"invalid {what} ({source}): expected one YAML document, got "
                            f"{len(documents)}")
    if not documents or documents[0] is None:
        return
    root = documents[0]
    try:
        _Walker()._dataclass(root, schema, "", tagged=False)
    except ScenarioError as error:
        message = str(error)
        if message.startswith("scenario:"):  # the root itself (see _error)
            message = what + message.removeprefix("scenario")
        raise ScenarioError(f"{message} ({source})") from None
    except RecursionError:
        raise ScenarioError(f"invalid {what} ({source}): nested too deeply") from None


#: Top-level scenario keys that moved into ``plant_config`` (Drake's
#: ``MultibodyPlantConfig``): old key -> its field there.
DEPRECATED_KEYS = {"contact_model": "contact_model", "time_step": "time_step",
                   "contact_approximation": "discrete_contact_approximation"}
_STR = "tag:yaml.org,2002:str"


class ScenarioDeprecationWarning(DeprecationWarning):
    """A scenario key that still works but has a new name (the CLI shows it)."""


def translate_deprecated_keys(text: str, source: str, what: str = "scenario") -> str:
    """``text`` with the old top-level keys of :data:`DEPRECATED_KEYS` moved into
    ``plant_config`` (one :class:`ScenarioDeprecationWarning` naming the new keys).

    The old ``contact_model: hydroelastic`` meant Drake's
    ``hydroelastic_with_fallback`` and becomes that. Text without an old key
    is returned unchanged (not re-emitted); text that is not a YAML mapping is
    left for :func:`check_yaml_text` to report. Giving an old key and its new
    field both is refused (which one would win is a guess).
    """
    import warnings

    if not any(key in text for key in DEPRECATED_KEYS):
        return text
    try:
        root = yaml.compose(text, Loader=_LOADER)
    except (yaml.YAMLError, RecursionError):
        return text
    if not isinstance(root, yaml.MappingNode):
        return text

    def name(key):
        return key.value if isinstance(key, yaml.ScalarNode) else None

    old = [(key, value) for key, value in root.value if name(key) in DEPRECATED_KEYS]
    if not old:
        return text
    plant = [value for key, value in root.value if name(key) == "plant_config"]
    if plant and not isinstance(plant[-1], yaml.MappingNode):
        return text  # check_yaml_text names plant_config and the old keys
    if not plant:
        plant = [yaml.MappingNode(_MAP, [])]
        root.value.append((yaml.ScalarNode(_STR, "plant_config"), plant[0]))
    plant = plant[-1]
    given = {name(key) for key, _ in plant.value}
    moved = []
    for key, value in old:
        new = DEPRECATED_KEYS[key.value]
        if new in given:
            raise ScenarioError(f"{key.value}: deprecated, and plant_config.{new} is given too; "
                                f"keep only plant_config.{new} ({source})")
        if new == "contact_model" and isinstance(value, yaml.ScalarNode) and \
                value.value == "hydroelastic":
            value = yaml.ScalarNode(_STR, "hydroelastic_with_fallback")
        plant.value.append((yaml.ScalarNode(_STR, new), value))
        moved.append(f"{key.value} -> plant_config.{new}")
    root.value = [(key, value) for key, value in root.value if name(key) not in DEPRECATED_KEYS]
    warnings.warn(f"{what} ({source}): deprecated top-level keys, move them into plant_config "
                  f"(Drake's MultibodyPlantConfig): {', '.join(moved)}",
                  ScenarioDeprecationWarning, stacklevel=4)
    return yaml.serialize(root, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper))


def _in(path: str, value, key: str, unit: str = "") -> None:
    low, high = LIMITS[key]
    ok = isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(
        value, bool) and math.isfinite(value) and low <= value <= high
    if not ok:
        raise ScenarioError(f"{path}: expected a finite value in [{low:g}, {high:g}]{unit}, "
                            f"got {short(value)}")


def check_pose(path: str, transform) -> None:
    """Bounds a ``Transform``'s numbers (angles, axis, translation), naming the field:
    finite, and in :data:`LIMITS`, before Drake evaluates it."""
    _check_pose(path, transform)


def _check_pose(path: str, transform) -> None:
    if not transform.IsDeterministic():
        raise ScenarioError(f"{path}: expected a deterministic pose, got a random one")
    rotation = transform.rotation.value
    axis = getattr(rotation, "axis", None)
    if axis is not None:
        axis = np.asarray(axis, dtype=float)
        norm = float(np.linalg.norm(axis)) if np.all(np.isfinite(axis)) else math.nan
        if not (1e-6 <= norm < 1e150):
            raise ScenarioError(f"{path}.rotation.axis: expected a non-zero finite axis "
                                f"(norm >= 1e-6), got {short(axis.tolist())}")
    for name in ("deg", "angle_deg"):
        value = getattr(rotation, name, None)
        if value is not None:
            for v in np.atleast_1d(np.asarray(value, dtype=float)):
                _in(f"{path}.rotation.{name}", float(v), "angle", " deg")
    for i, v in enumerate(np.asarray(transform.translation, dtype=float).ravel()):
        _in(f"{path}.translation[{i}]", float(v), "position", " m")


def check_ranges(scenario) -> None:
    """Bounds every physical quantity of ``scenario`` (see :data:`LIMITS`)."""
    hand = scenario.hand
    _check_pose("hand.mount.X_WB", hand.mount.X_WB)
    if hasattr(hand.mount, "X_FH"):  # an arm: the hand on its flange
        _check_pose("hand.mount.X_FH", hand.mount.X_FH)
    if hand.coupling_ratio is not None and isinstance(hand.coupling_ratio, int | float) \
            and not isinstance(hand.coupling_ratio, bool):
        _in("hand.coupling_ratio", hand.coupling_ratio, "coupling_ratio")
    box = getattr(scenario, "sorting_box", None)
    if box is not None:
        _check_pose("sorting_box.X_WB", box.X_WB)
    if hasattr(hand.mount, "translation_kp"):  # a floating wrist: its PD gains
        for name in ("translation_kp", "translation_kd", "rotation_kp", "rotation_kd"):
            _in(f"hand.mount.{name}", getattr(hand.mount, name), "gain")
    for name, value in hand.initial_position.items():
        _in(f"hand.initial_position[{name}]", value, "angle", " rad")
    obj = scenario.object
    if obj is not None:
        _in("object.size", obj.size, "length", " m")
        for name, value in obj.dimensions.items():
            _in(f"object.dimensions[{name}]", value, "length", " m")
        if obj.mass is not None:
            _in("object.mass", obj.mass, "mass", " kg")
        _in("object.mu", obj.mu, "mu")
        _check_pose("object.X_WO", obj.X_WO)
    if scenario.table is not None:
        _in("table.top_height", scenario.table.top_height, "position", " m")
        _in("table.size_x", scenario.table.size_x, "table_size", " m")
        _in("table.size_y", scenario.table.size_y, "table_size", " m")
    time_step = scenario.plant_config.time_step
    _in("plant_config.time_step", time_step, "time_step", " s")
    _in("simulation_duration", scenario.simulation_duration, "simulation_duration", " s")
    steps = scenario.simulation_duration / time_step
    low, high = LIMITS["steps"]
    if steps > high:
        raise ScenarioError(
            f"simulation_duration / plant_config.time_step: expected at most {high:,} steps, "
            f"got {steps:,.0f} ({scenario.simulation_duration:g} s / {time_step:g} s)")
    _in("visualization.publish_period", scenario.visualization.publish_period,
        "visualization_period", " s")
    if isinstance(scenario.random_seed, bool) or not isinstance(scenario.random_seed, int) or \
            not 0 <= scenario.random_seed < 2**32:
        raise ScenarioError(f"random_seed: expected an integer in [0, 2**32), got "
                            f"{short(scenario.random_seed)}")
    if hasattr(scenario.driver, "max_joint_velocity"):  # the simulated driver
        _in("driver.max_joint_velocity", scenario.driver.max_joint_velocity,
            "joint_velocity", " rad/s")
        _in("driver.control_period", scenario.driver.control_period, "control_period", " s")
    for i, keyframe in enumerate(scenario.script):
        longest = LIMITS["simulation_duration"][1]
        if keyframe.time > longest:
            raise ScenarioError(f"script[{i}].time: expected at most {longest:g} s, got "
                                f"{keyframe.time:g}")
        for name, value in keyframe.hand.items():
            _in(f"script[{i}].hand[{name}]", value, "angle", " rad")
        for k, value in enumerate(keyframe.wrist[:3]):
            _in(f"script[{i}].wrist[{k}]", value, "position", " m (the wrist's workspace)")
        for k, value in enumerate(keyframe.wrist[3:6]):
            _in(f"script[{i}].wrist[{k + 3}]", value, "wrist_angle", " rad")
    for i, camera in enumerate(getattr(scenario, "cameras", [])):
        _check_pose(f"cameras[{i}].config.X_PB", camera.config.X_PB)
        for k, value in enumerate(camera.target):
            _in(f"cameras[{i}].target[{k}]", value, "position", " m")
    wrist = [(k.time, k.wrist) for k in scenario.script if k.wrist]
    for (t0, w0), (t1, w1) in zip(wrist, wrist[1:], strict=False):
        dt = t1 - t0
        speed = float(np.linalg.norm(np.subtract(w1[:3], w0[:3]))) / dt
        rate = float(np.max(np.abs(np.subtract(w1[3:], w0[3:])))) / dt
        where = f"script (wrist from t = {t0:g} s to {t1:g} s)"
        _in(f"{where} speed", speed, "wrist_speed", " m/s")
        _in(f"{where} angular rate", rate, "wrist_rate", " rad/s")
