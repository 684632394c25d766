"""The catalogue: object kinds, their proportions, sizes and densities, and :class:`ObjectSpec`.

An :class:`ObjectSpec` names the kind and one characteristic length ``size``
(metres); every other dimension follows from fixed, documented proportions
(``PROPORTIONS``) unless overridden through ``dimensions``. Object frame O: see
:mod:`handle_drake.geometry.objects`.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS

KINDS = ("sphere", "cylinder", "cuboid", "rotated_cuboid", "mug", "wine_glass", "star_prism",
         *DEVICE_OBJECTS)  # + the instrumented objects (handle_drake.geometry.objects.instrumented)

#: Name of the object's rigid body inside its model instance (AddObject and write_sdf).
BODY_NAME = "base_link"

#: A size typical of the demonstration objects (m), used by ``ObjectSpec.default``.
DEFAULT_SIZE = {
    "sphere": 0.06,
    "cylinder": 0.05,
    "cuboid": 0.06,
    "rotated_cuboid": 0.06,
    "mug": 0.08,
    "wine_glass": 0.08,
    "star_prism": 0.08,
    **{kind: device.default_size for kind, device in DEVICE_OBJECTS.items()},
}

#: Default density (kg/m^3): wood/plastic for the primitives, ceramic mug, glass.
DENSITY = {
    "sphere": 500.0,
    "cylinder": 500.0,
    "cuboid": 500.0,
    "rotated_cuboid": 500.0,
    "mug": 2000.0,
    "wine_glass": 2500.0,
    "star_prism": 500.0,
    **{kind: device.density for kind, device in DEVICE_OBJECTS.items()},
}

#: Every dimension of a kind as a multiple of ``size``. The first entry is
#: ``size`` itself (ratio 1); the others may be overridden in metres through
#: ``ObjectSpec(dimensions={...})``.
PROPORTIONS: dict[str, dict[str, float]] = {
    "sphere": {"diameter": 1.0},
    "cylinder": {"diameter": 1.0, "height": 2.0},
    # Three distinct edges so that the box's orientation is observable.
    "cuboid": {"width": 1.0, "depth": 0.6, "height": 1.5},
    "rotated_cuboid": {"width": 1.0, "depth": 0.6, "height": 1.5},
    "mug": {
        "diameter": 1.0,  # outer diameter of the cup
        "height": 1.1,
        "wall": 0.07,  # wall thickness
        "bottom": 0.08,  # bottom thickness
        "handle_reach": 0.3,  # handle's outward extent from the outer wall
        "handle_span": 0.7,  # handle's vertical extent
        "handle_thickness": 0.09,  # cross-section of the handle bars in the x-z plane
        "handle_width": 0.12,  # handle's extent along y
    },
    "wine_glass": {
        "diameter": 1.0,  # outer diameter of the bowl at its widest
        "foot_diameter": 0.8,
        "foot_thickness": 0.05,
        "stem_diameter": 0.1,
        "stem_height": 0.8,
        "bowl_height": 1.1,
        "wall": 0.04,  # horizontal wall thickness of the bowl
    },
    "star_prism": {
        "diameter": 1.0,  # tip-to-tip circle
        "inner_diameter": 0.45,  # circle through the notches between arms
        "height": 0.5,  # extrusion along z
    },
    **{kind: dict(device.proportions) for kind, device in DEVICE_OBJECTS.items()},
}

#: The rotated cuboid is the cuboid turned by this angle (rad) about the object z axis,
#: so that an approach along x meets an edge instead of a face.
ROTATED_CUBOID_YAW = math.pi / 4

# Outer radius of the wine-glass bowl as a fraction of the bowl radius, at heights given
# as fractions of the bowl height (tulip shape: widest at half height, narrower rim).
# The bowl is solid up to the second point, a wall of constant horizontal thickness above.
_BOWL_PROFILE = ((0.0, 0.25), (0.12, 0.7), (0.3, 0.93), (0.5, 1.0), (0.75, 0.96), (1.0, 0.86))

_COLORS = {
    "sphere": (0.85, 0.33, 0.10, 1.0),
    "cylinder": (0.10, 0.45, 0.80, 1.0),
    "cuboid": (0.20, 0.65, 0.30, 1.0),
    "rotated_cuboid": (0.55, 0.75, 0.25, 1.0),
    "mug": (0.90, 0.88, 0.82, 1.0),
    "wine_glass": (0.70, 0.85, 0.95, 0.6),
    "star_prism": (0.95, 0.75, 0.10, 1.0),
    **{kind: device.color for kind, device in DEVICE_OBJECTS.items()},
}

_TABLE_COLOR = (0.55, 0.40, 0.25, 1.0)

def _mesh_module(spec):
    """The module of a mesh object's spec (kind "mesh"), else None.

    The catalogue's functions hand mesh objects (``MeshObjectSpec``, defined in
    :mod:`handle_drake.geometry.objects.mesh`) to the module that defines their type,
    so the catalogue needs no import of it (a mesh spec exists only once that module is
    imported).
    """
    if getattr(spec, "kind", None) == "mesh":
        return sys.modules[type(spec).__module__]
    return None


def _check_positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    return value


@dataclass(frozen=True)
class ObjectSpec:
    """One grasp object: its kind, its size and its contact parameters.

    Attributes:
        kind: one of ``KINDS``.
        size: the characteristic length (m): sphere, cylinder, mug and star
            prism diameter; cuboid width (its longest horizontal edge); wine
            glass bowl diameter. See ``PROPORTIONS`` for the other dimensions.
        mass: total mass (kg); default ``DENSITY[kind] * volume``.
        mu: Coulomb friction coefficient (static = dynamic).
        dimensions: optional overrides, in metres, of the dimensions named in
            ``PROPORTIONS[kind]`` other than the first (e.g.
            ``{"height": 0.2}`` for a cylinder). Stored as sorted pairs.
        density: kg/m^3, used when ``mass`` is None; default ``DENSITY[kind]``.
        hydroelastic_modulus: Pa, for compliant hydroelastic contact.
        resolution_hint: m, tessellation length of compliant Sphere/Cylinder
            pieces; default: 1/16 of each round piece's circumference.
        segments: number of flat faces around the round walls of the mug and
            the wine glass (multiple of 4, >= 8).
        color: RGBA illustration colour; default per kind.
    """

    kind: str
    size: float
    mass: float | None = None
    mu: float = 0.8
    dimensions: Mapping[str, float] | tuple | None = None
    density: float | None = None
    hydroelastic_modulus: float = 1.0e7
    resolution_hint: float | None = None
    segments: int = 16
    color: tuple[float, float, float, float] | None = field(default=None)

    def __post_init__(self):
        if not isinstance(self.kind, str):
            raise TypeError(f"kind must be a str, got {type(self.kind).__name__}")
        if self.kind not in KINDS:
            raise ValueError(f"unknown object kind {self.kind!r}; valid kinds: {', '.join(KINDS)}")
        object.__setattr__(self, "size", _check_positive("size", self.size))
        if self.mass is not None:
            object.__setattr__(self, "mass", _check_positive("mass", self.mass))
        if self.density is not None:
            object.__setattr__(self, "density", _check_positive("density", self.density))
        mu = self.mu
        if isinstance(mu, bool) or not isinstance(mu, int | float | np.floating | np.integer):
            raise TypeError(f"mu must be a number, got {type(mu).__name__}")
        if not math.isfinite(float(mu)) or mu < 0:
            raise ValueError(f"mu must be a finite number >= 0, got {mu}")
        object.__setattr__(self, "mu", float(mu))
        object.__setattr__(
            self,
            "hydroelastic_modulus",
            _check_positive("hydroelastic_modulus", self.hydroelastic_modulus),
        )
        if self.resolution_hint is not None:
            object.__setattr__(
                self, "resolution_hint", _check_positive("resolution_hint", self.resolution_hint)
            )
        if isinstance(self.segments, bool) or not isinstance(self.segments, int | np.integer):
            raise TypeError(f"segments must be an int, got {type(self.segments).__name__}")
        if self.segments < 8 or self.segments % 4:
            raise ValueError(f"segments must be a multiple of 4 and >= 8, got {self.segments}")
        if self.color is not None:
            rgba = tuple(float(c) for c in self.color)
            if len(rgba) != 4 or not all(0.0 <= c <= 1.0 for c in rgba):
                raise ValueError(f"color must be 4 numbers in [0, 1] (RGBA), got {self.color}")
            object.__setattr__(self, "color", rgba)
        object.__setattr__(self, "dimensions", self._normalised_dimensions())
        dimensions(self)  # checks that the dimensions make a valid solid

    def _normalised_dimensions(self) -> tuple:
        given = self.dimensions
        if given is None:
            return ()
        items = given.items() if isinstance(given, Mapping) else given
        try:
            pairs = [(str(k), v) for k, v in items]
        except (TypeError, ValueError) as error:
            raise TypeError(
                f"dimensions must be a mapping name -> metres, got {type(given).__name__}"
            ) from error
        names = list(PROPORTIONS[self.kind])
        allowed = names[1:] if self.kind not in DEVICE_OBJECTS else []
        out = {}
        for name, value in pairs:
            if name not in allowed:
                raise ValueError(
                    f"dimension {name!r} is not known for {self.kind}; "
                    f"overridable: {', '.join(allowed) or 'none'} ({names[0]} is `size`)"
                )
            out[name] = _check_positive(f"dimensions[{name!r}]", value)
        return tuple(sorted(out.items()))

    @staticmethod
    def default(kind: str, **kwargs) -> ObjectSpec:
        """The object of ``kind`` at its ``DEFAULT_SIZE``."""
        if kind not in DEFAULT_SIZE:
            raise ValueError(f"unknown object kind {kind!r}; valid kinds: {', '.join(KINDS)}")
        return ObjectSpec(kind, DEFAULT_SIZE[kind], **kwargs)

    @property
    def rgba(self) -> tuple[float, float, float, float]:
        return self.color if self.color is not None else _COLORS[self.kind]


def dimensions(spec: ObjectSpec) -> dict[str, float]:
    """All named dimensions of ``spec`` in metres (``PROPORTIONS`` times size, then overrides).

    Raises ValueError when overrides make an impossible solid (e.g. a wall
    thicker than the radius).
    """
    d = {name: ratio * spec.size for name, ratio in PROPORTIONS[spec.kind].items()}
    d.update(dict(spec.dimensions or ()))
    kind = spec.kind
    if kind == "mug":
        radius = d["diameter"] / 2
        if d["wall"] >= radius:
            raise ValueError(f"mug wall {d['wall']} m must be < outer radius {radius} m")
        if d["bottom"] >= d["height"]:
            raise ValueError(f"mug bottom {d['bottom']} m must be < height {d['height']} m")
        if d["handle_span"] > d["height"]:
            raise ValueError(
                f"mug handle_span {d['handle_span']} m must be <= height {d['height']} m"
            )
        if d["handle_span"] <= 2 * d["handle_thickness"]:
            raise ValueError("mug handle_span must exceed 2 * handle_thickness")
        if d["handle_reach"] <= d["handle_thickness"]:
            raise ValueError("mug handle_reach must exceed handle_thickness")
        # The handle arms end on the flat outer face centred on +x.
        face = 2 * radius * math.tan(math.pi / spec.segments)
        if d["handle_width"] > face:
            raise ValueError(
                f"mug handle_width {d['handle_width']} m must be <= the outer face width "
                f"{face:.4g} m (raise segments or narrow the handle)"
            )
    elif kind == "wine_glass":
        radius = d["diameter"] / 2
        stem_r = d["stem_diameter"] / 2
        narrowest = min(r for _, r in _BOWL_PROFILE[1:]) * radius
        if d["wall"] >= narrowest:
            raise ValueError(f"wine_glass wall {d['wall']} m must be < {narrowest:.4g} m")
        if stem_r > _BOWL_PROFILE[0][1] * radius:
            raise ValueError("wine_glass stem_diameter must be <= half the bowl diameter")
        if stem_r > d["foot_diameter"] / 2:
            raise ValueError("wine_glass stem_diameter must be <= foot_diameter")
    elif kind == "star_prism":
        if d["inner_diameter"] >= d["diameter"]:
            raise ValueError(
                f"star_prism inner_diameter {d['inner_diameter']} m must be < "
                f"diameter {d['diameter']} m"
            )
    return d


def total_height(spec: ObjectSpec) -> float:
    """Vertical extent (m) of the object standing on a table."""
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.total_height(spec)
    d = dimensions(spec)
    if spec.kind == "sphere":
        return d["diameter"]
    if spec.kind == "wine_glass":
        return d["foot_thickness"] + d["stem_height"] + d["bowl_height"]
    return d["height"]


def resting_height(spec: ObjectSpec) -> float:
    """Height (m) of the object origin above a table top the object stands on."""
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.resting_height(spec)
    return total_height(spec) / 2
