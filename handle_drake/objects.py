"""The object catalogue: grasp objects with one size parameter, and the table.

The grasp experiments of the method (report sections 3.1 and 4.3) use a sphere,
a cylinder, a cuboid, a rotated cuboid, a mug, a wine glass and a star prism,
each in several sizes. An :class:`ObjectSpec` names the kind and one
characteristic length ``size`` (metres); every other dimension follows from
fixed, documented proportions (``PROPORTIONS``) unless overridden through
``dimensions``.

Every object is a union of **convex pieces** (:class:`Piece`: a Drake
``Sphere``, ``Cylinder``, ``Box`` or ``Convex`` hull and its pose ``X_OP`` in
the object frame O). The pieces tile the object without overlapping (they
share faces), so

* point contact is correct for non-convex objects (a single ``Convex`` of a mug
  would fill its cavity),
* every piece supports compliant hydroelastic contact in Drake 1.51 (Sphere,
  Cylinder, Box and Convex all do),
* volume, mass and inertia are exact sums over pieces
  (``pydrake.multibody.tree.CalcSpatialInertia`` per piece).

Object frame O: origin at the geometric centre of the object's main body, on
its vertical axis at mid-height (mug: axis of the cup, the handle is not
counted; sphere: its centre); +z up when the object stands on a table;
the handle of the mug and the first arm of the star prism point along +x.
``resting_height(spec)`` is the height of O above a table the object stands
on.

Round walls (mug, wine-glass bowl) are regular ``segments``-gons
*circumscribed* about the documented circles: the middle of every flat face
lies on the circle, so the outer diameter and wall thickness are exact when
measured across faces and the axis-aligned bounds equal the documented
diameter (``segments`` is a multiple of 4 and faces are centred on the axes).

Drake 1.51 builds a ``Convex`` directly from in-memory points
(``Convex(points, label)``), so no files are needed to add an object to a
plant; only :func:`write_sdf` writes OBJ files, next to the SDFormat file.

Surface queries: :func:`surface_mesh` returns the concatenation of the piece
meshes (no boolean engine is installed: trimesh's needs ``manifold3d``), which
contains the faces the pieces share. Use :func:`sample_surface` for points on
the true outer surface (it rejects points on shared faces) and
:func:`ray_cast` for rays (the nearest entry point over all pieces is the true
surface seen from outside; trimesh's own ray casting needs ``rtree``, which is
not installed).

Mesh files (object kind ``mesh``, :class:`handle_drake.mesh_objects.MeshObjectSpec`)
are accepted by :func:`AddObject`, :func:`pieces`, :func:`mass_properties`,
:func:`spatial_inertia`, :func:`resting_height`, :func:`total_height`,
:func:`contact_feet`, :func:`surface_mesh`, :func:`sample_surface` and
:func:`ray_cast`, which hand them to that module.

Run ``python -m handle_drake.objects export models/objects`` to regenerate the
committed default-size SDFormat models and the table.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import trimesh
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    Convex,
    Cylinder,
    ProximityProperties,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import CoulombFriction
from pydrake.multibody.tree import CalcSpatialInertia, ModelInstanceIndex, SpatialInertia
from scipy.spatial import ConvexHull

__all__ = [
    "KINDS",
    "DEFAULT_SIZE",
    "DENSITY",
    "PROPORTIONS",
    "ROTATED_CUBOID_YAW",
    "BODY_NAME",
    "ObjectSpec",
    "Piece",
    "MassProperties",
    "RayHits",
    "dimensions",
    "pieces",
    "contact_feet",
    "total_height",
    "resting_height",
    "mass_properties",
    "spatial_inertia",
    "AddObject",
    "AddTable",
    "surface_mesh",
    "sample_surface",
    "ray_cast",
    "write_sdf",
    "write_table_sdf",
]

KINDS = ("sphere", "cylinder", "cuboid", "rotated_cuboid", "mug", "wine_glass", "star_prism")

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
}

_TABLE_COLOR = (0.55, 0.40, 0.25, 1.0)


def _check_positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    return value


def _mesh_module(spec):
    """``handle_drake.mesh_objects`` when ``spec`` is a mesh object (kind "mesh"), else None.

    The catalogue's functions hand mesh objects to that module.
    """
    if getattr(spec, "kind", None) == "mesh":
        from handle_drake import mesh_objects

        return mesh_objects
    return None


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
        allowed = names[1:]
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


# --------------------------------------------------------------------------- pieces


@dataclass(frozen=True, eq=False)
class Piece:
    """One convex piece of an object.

    ``shape`` is one of "sphere" (params: radius), "cylinder" (radius,
    length; axis z), "box" (x, y, z edge lengths) or "convex" (``vertices``,
    an (n, 3) array in the piece frame P, whose hull is the piece).
    ``X_OP`` is the pose of the piece frame in the object frame.
    """

    name: str
    shape: str
    params: tuple[float, ...]
    X_OP: RigidTransform
    vertices: np.ndarray | None = None

    def drake_shape(self):
        if self.shape == "sphere":
            return Sphere(self.params[0])
        if self.shape == "cylinder":
            return Cylinder(*self.params)
        if self.shape == "box":
            return Box(*self.params)
        return Convex(np.ascontiguousarray(self.vertices.T), self.name)

    def mesh(self) -> trimesh.Trimesh:
        """A triangle mesh of the piece in the object frame (round shapes faceted)."""
        if self.shape == "sphere":
            m = trimesh.creation.icosphere(subdivisions=3, radius=self.params[0])
        elif self.shape == "cylinder":
            m = trimesh.creation.cylinder(radius=self.params[0], height=self.params[1], sections=64)
        elif self.shape == "box":
            m = trimesh.creation.box(extents=self.params)
        else:
            m = trimesh.convex.convex_hull(self.vertices)
        m.apply_transform(self.X_OP.GetAsMatrix4())
        return m

    def round_resolution_hint(self) -> float:
        """Default hydroelastic tessellation length: 1/16 of a round piece's circumference."""
        if self.shape in ("sphere", "cylinder"):
            return 2 * math.pi * self.params[0] / 16
        return float(np.max(np.ptp(self.mesh().vertices, axis=0)))


def _ring_points(radius: float, z: float, n: int) -> np.ndarray:
    """Vertices of the regular n-gon whose faces touch the circle of ``radius``.

    Faces are centred on the angles 2*pi*k/n (so on +x, +y, -x, -y for n % 4 == 0).
    """
    angles = (np.arange(n) + 0.5) * 2 * math.pi / n
    r = radius / math.cos(math.pi / n)
    return np.column_stack([r * np.cos(angles), r * np.sin(angles), np.full(n, z)])


def _sector(ring_lo_out, ring_hi_out, ring_lo_in, ring_hi_in, k: int) -> np.ndarray:
    """The 8 corners of the wall piece between polygon vertices k-1 and k."""
    n = len(ring_lo_out)
    idx = [(k - 1) % n, k]
    return np.vstack([ring_lo_out[idx], ring_hi_out[idx], ring_lo_in[idx], ring_hi_in[idx]])


def _mug_pieces(spec: ObjectSpec, d: dict) -> list[Piece]:
    n = spec.segments
    ro, ri = d["diameter"] / 2, d["diameter"] / 2 - d["wall"]
    h = d["height"]
    z0, z1 = -h / 2, h / 2
    zb = z0 + d["bottom"]
    identity = RigidTransform()
    inner_lo = _ring_points(ri, zb, n)
    bottom = np.vstack([_ring_points(ri, z0, n), inner_lo])
    out = [Piece("bottom", "convex", (), identity, bottom)]
    # The wall stands on the ground from z0: the bottom is the inner prism only.
    rings = (_ring_points(ro, z0, n), _ring_points(ro, z1, n))
    inner = (_ring_points(ri, z0, n), _ring_points(ri, z1, n))
    # Wall pieces below the inner bottom touch the bottom prism along its side faces.
    for k in range(n):
        verts = _sector(rings[0], rings[1], inner[0], inner[1], k)
        out.append(Piece(f"wall_{k:02d}", "convex", (), identity, verts))
    # Handle: two horizontal arms from the flat outer face on +x, and a vertical bar.
    x_face = ro
    reach, t, span, w = (
        d["handle_reach"],
        d["handle_thickness"],
        d["handle_span"],
        d["handle_width"],
    )
    arm_len = reach - t
    for name, zc in (("handle_top", span / 2 - t / 2), ("handle_bottom", -span / 2 + t / 2)):
        out.append(
            Piece(name, "box", (arm_len, w, t), RigidTransform([x_face + arm_len / 2, 0.0, zc]))
        )
    out.append(
        Piece("handle_bar", "box", (t, w, span), RigidTransform([x_face + reach - t / 2, 0.0, 0.0]))
    )
    return out


def _wine_glass_pieces(spec: ObjectSpec, d: dict) -> list[Piece]:
    n = spec.segments
    height = total_height(spec)
    z = -height / 2
    out = [
        Piece(
            "foot",
            "cylinder",
            (d["foot_diameter"] / 2, d["foot_thickness"]),
            RigidTransform([0, 0, z + d["foot_thickness"] / 2]),
        )
    ]
    z += d["foot_thickness"]
    out.append(
        Piece(
            "stem",
            "cylinder",
            (d["stem_diameter"] / 2, d["stem_height"]),
            RigidTransform([0, 0, z + d["stem_height"] / 2]),
        )
    )
    z += d["stem_height"]
    radius, hb, wall = d["diameter"] / 2, d["bowl_height"], d["wall"]
    profile = [(z + f * hb, r * radius) for f, r in _BOWL_PROFILE]
    identity = RigidTransform()
    (za, ra), (zc, rc) = profile[0], profile[1]
    base = np.vstack([_ring_points(ra, za, n), _ring_points(rc, zc, n)])
    out.append(Piece("bowl_base", "convex", (), identity, base))
    for band, ((zl, rl), (zh, rh)) in enumerate(zip(profile[1:-1], profile[2:], strict=True)):
        lo_out, hi_out = _ring_points(rl, zl, n), _ring_points(rh, zh, n)
        lo_in, hi_in = _ring_points(rl - wall, zl, n), _ring_points(rh - wall, zh, n)
        for k in range(n):
            verts = _sector(lo_out, hi_out, lo_in, hi_in, k)
            out.append(Piece(f"bowl_{band}_{k:02d}", "convex", (), identity, verts))
    return out


def _star_pieces(spec: ObjectSpec, d: dict) -> list[Piece]:
    r_out, r_in, h = d["diameter"] / 2, d["inner_diameter"] / 2, d["height"]
    tips = 2 * math.pi * np.arange(5) / 5  # first tip on +x
    notches = tips + math.pi / 5
    notch_xy = r_in * np.column_stack([np.cos(notches), np.sin(notches)])
    tip_xy = r_out * np.column_stack([np.cos(tips), np.sin(tips)])

    def prism(xy):
        return np.vstack([np.column_stack([xy, np.full(len(xy), s * h / 2)]) for s in (-1, 1)])

    identity = RigidTransform()
    out = [Piece("centre", "convex", (), identity, prism(notch_xy))]
    for k in range(5):
        tri = np.vstack([tip_xy[k], notch_xy[k], notch_xy[k - 1]])
        out.append(Piece(f"arm_{k}", "convex", (), identity, prism(tri)))
    return out


@lru_cache(maxsize=256)
def pieces(spec: ObjectSpec) -> tuple[Piece, ...]:
    """The convex pieces of ``spec`` in the object frame (they tile it, no overlaps)."""
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.pieces(spec)
    d = dimensions(spec)
    kind = spec.kind
    if kind == "sphere":
        return (Piece("sphere", "sphere", (d["diameter"] / 2,), RigidTransform()),)
    if kind == "cylinder":
        return (Piece("cylinder", "cylinder", (d["diameter"] / 2, d["height"]), RigidTransform()),)
    if kind in ("cuboid", "rotated_cuboid"):
        yaw = ROTATED_CUBOID_YAW if kind == "rotated_cuboid" else 0.0
        X = RigidTransform(RotationMatrix.MakeZRotation(yaw), [0, 0, 0])
        return (Piece("box", "box", (d["width"], d["depth"], d["height"]), X),)
    if kind == "mug":
        return tuple(_mug_pieces(spec, d))
    if kind == "wine_glass":
        return tuple(_wine_glass_pieces(spec, d))
    return tuple(_star_pieces(spec, d))


# --------------------------------------------------------------------------- mass


@dataclass(frozen=True)
class MassProperties:
    """Mass (kg), volume (m^3), centre of mass ``p_OScm`` (m, object frame) and the
    rotational inertia ``I_SScm_O`` (kg m^2) about the centre of mass, expressed in O."""

    mass: float
    volume: float
    p_OScm: np.ndarray
    I_SScm_O: np.ndarray


def _unit_density_inertia(spec: ObjectSpec) -> tuple[SpatialInertia, float]:
    """Spatial inertia about Oo for density 1 kg/m^3, and the volume."""
    M_OOo_O = SpatialInertia.Zero()
    volume = 0.0
    for piece in pieces(spec):
        shape = piece.drake_shape()
        M_PPo_P = CalcSpatialInertia(shape, 1.0)
        volume += M_PPo_P.get_mass()
        M_PPo_O = M_PPo_P.ReExpress(piece.X_OP.rotation())
        M_POo_O = M_PPo_O.Shift(-piece.X_OP.translation())
        M_OOo_O += M_POo_O
    return M_OOo_O, volume


def spatial_inertia(spec: ObjectSpec) -> SpatialInertia:
    """``M_OOo_O``: the object's spatial inertia about its origin, expressed in O."""
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.spatial_inertia(spec)
    M_unit, volume = _unit_density_inertia(spec)
    if spec.mass is not None:
        density = spec.mass / volume
    else:
        density = spec.density if spec.density is not None else DENSITY[spec.kind]
    mass = density * volume
    return SpatialInertia(
        mass, M_unit.get_com(), M_unit.get_unit_inertia(), skip_validity_check=False
    )


def mass_properties(spec: ObjectSpec) -> MassProperties:
    """Mass, volume, centre of mass and central inertia of ``spec``."""
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.mass_properties(spec)
    M = spatial_inertia(spec)
    _, volume = _unit_density_inertia(spec)
    p_OScm = np.array(M.get_com())
    I_SScm = M.Shift(p_OScm).CalcRotationalInertia().CopyToFullMatrix3()
    return MassProperties(float(M.get_mass()), float(volume), p_OScm, I_SScm)


# --------------------------------------------------------------------------- plant


def _object_proximity(spec: ObjectSpec, piece: Piece, hydroelastic: bool) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(spec.mu, spec.mu), properties=props)
    if hydroelastic:
        hint = spec.resolution_hint or piece.round_resolution_hint()
        AddCompliantHydroelasticProperties(hint, spec.hydroelastic_modulus, props)
    return props


def AddObject(plant, spec: ObjectSpec, name: str = "object", hydroelastic: bool = False):
    """Adds ``spec`` as a free rigid body to ``plant`` (before Finalize).

    The model instance is called ``name``; its body ``BODY_NAME`` has the
    object frame O as body frame. Every piece gets collision geometry
    (Coulomb friction ``mu``; compliant hydroelastic properties when
    ``hydroelastic`` is True, else point contact only) and visual geometry.
    Returns the ``ModelInstanceIndex``.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.AddMeshObject(plant, spec, name, hydroelastic)
    if not isinstance(spec, ObjectSpec):
        raise TypeError(f"spec must be an ObjectSpec, got {type(spec).__name__}")
    if plant.is_finalized():
        raise ValueError("AddObject must be called before plant.Finalize()")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty str, got {name!r}")
    instance: ModelInstanceIndex = plant.AddModelInstance(name)
    rgba = np.array(spec.rgba)
    body = plant.AddRigidBody(BODY_NAME, instance, spatial_inertia(spec))
    for piece in pieces(spec):
        shape = piece.drake_shape()
        plant.RegisterCollisionGeometry(
            body,
            piece.X_OP,
            shape,
            f"{piece.name}_collision",
            _object_proximity(spec, piece, hydroelastic),
        )
        plant.RegisterVisualGeometry(body, piece.X_OP, shape, f"{piece.name}_visual", rgba)
    if not hydroelastic:
        props = ProximityProperties()
        AddContactMaterial(friction=CoulombFriction(spec.mu, spec.mu), properties=props)
        for i, p_OF in enumerate(contact_feet(spec)):
            plant.RegisterCollisionGeometry(
                body, RigidTransform(p_OF), Sphere(_foot_radius(spec)), f"foot_{i}", props
            )
    return instance


def _foot_radius(spec: ObjectSpec) -> float:
    return 0.01 * spec.size


def contact_feet(spec: ObjectSpec) -> np.ndarray:
    """Centres (k, 3) in O of the small collision spheres added under flat bottoms.

    Drake's point contact yields one contact point per pair of geometries, so a
    box or a cylinder standing on the table box rocks on a single point forever.
    Under point contact, :func:`AddObject` therefore adds collision-only spheres
    of radius ``0.01 * size`` inside the bottom rim (4 corners of a cuboid, 8
    points on the rim of a cylinder or a wine-glass foot) whose lowest points lie
    on the bottom face; a star prism gets one near each tip. They have no mass
    and do not change the shape. The mug (16 wall pieces on the table) and the
    sphere get none.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.contact_feet(spec)
    r = _foot_radius(spec)
    d = dimensions(spec)
    z = -resting_height(spec) + r
    if spec.kind in ("cuboid", "rotated_cuboid"):
        hx, hy = d["width"] / 2 - r, d["depth"] / 2 - r
        local = np.array([[sx * hx, sy * hy, z] for sx in (-1, 1) for sy in (-1, 1)])
        yaw = ROTATED_CUBOID_YAW if spec.kind == "rotated_cuboid" else 0.0
        return local @ RotationMatrix.MakeZRotation(yaw).matrix().T
    if spec.kind in ("cylinder", "wine_glass"):
        radius = (d["diameter"] if spec.kind == "cylinder" else d["foot_diameter"]) / 2 - r
        angles = 2 * math.pi * np.arange(8) / 8
        return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(8, z)])
    if spec.kind == "star_prism":
        # Near the five tips (4 radii in from the tip, where the arm is wider than a foot).
        radius = d["diameter"] / 2 - 4 * r
        angles = 2 * math.pi * np.arange(5) / 5
        return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(5, z)])
    return np.zeros((0, 3))


def _table_proximity(mu: float, hydroelastic: str, resolution_hint: float, modulus: float):
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    if hydroelastic == "rigid":
        AddRigidHydroelasticProperties(resolution_hint, props)
    elif hydroelastic == "compliant":
        AddCompliantHydroelasticProperties(resolution_hint, modulus, props)
    return props


def AddTable(
    plant,
    top_height: float = 0.0,
    size: tuple[float, float] = (0.8, 0.8),
    name: str = "table",
    *,
    thickness: float = 0.05,
    mu: float = 0.8,
    hydroelastic: str = "rigid",
    hydroelastic_modulus: float = 1.0e7,
):
    """Adds a table top (a box welded to the world) whose top surface is at ``top_height``.

    The body ``top`` has its frame at the centre of the top surface, z up.
    ``hydroelastic`` is "rigid" (default), "compliant" or "none" (point contact
    only); with "rigid" the table meets compliant objects hydroelastically and
    point-contact objects through the fallback. Returns the ``ModelInstanceIndex``.
    """
    if plant.is_finalized():
        raise ValueError("AddTable must be called before plant.Finalize()")
    top_height = float(top_height)
    if not math.isfinite(top_height):
        raise ValueError(f"top_height must be finite, got {top_height}")
    size = tuple(size)
    if len(size) != 2:
        raise ValueError(f"table size must be (x, y), expected 2 numbers, got {len(size)}")
    sx, sy = (_check_positive("table size", s) for s in size)
    thickness = _check_positive("thickness", thickness)
    if hydroelastic not in ("rigid", "compliant", "none"):
        raise ValueError(
            f"hydroelastic must be 'rigid', 'compliant' or 'none', got {hydroelastic!r}"
        )
    mu = float(mu)
    if not math.isfinite(mu) or mu < 0:
        raise ValueError(f"mu must be a finite number >= 0, got {mu}")
    instance = plant.AddModelInstance(name)
    body = plant.AddRigidBody("top", instance, SpatialInertia.SolidBoxWithMass(10.0, sx, sy, 0.05))
    X_TG = RigidTransform([0, 0, -thickness / 2])
    shape = Box(sx, sy, thickness)
    props = _table_proximity(mu, hydroelastic, 0.1, hydroelastic_modulus)
    plant.RegisterCollisionGeometry(body, X_TG, shape, "top_collision", props)
    plant.RegisterVisualGeometry(body, X_TG, shape, "top_visual", np.array(_TABLE_COLOR))
    plant.WeldFrames(plant.world_frame(), body.body_frame(), RigidTransform([0, 0, top_height]))
    return instance


# --------------------------------------------------------------------------- surface


def surface_mesh(spec: ObjectSpec) -> trimesh.Trimesh:
    """The pieces' meshes in the object frame, concatenated (round pieces faceted).

    Not a boolean union: faces shared by two pieces are included. Point
    sampling should use :func:`sample_surface`; ray casting :func:`ray_cast`
    (or the nearest hit from outside on this mesh, which is the true surface).
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.surface_mesh(spec)
    return trimesh.util.concatenate([p.mesh() for p in pieces(spec)])


@lru_cache(maxsize=256)
def _halfspaces(spec: ObjectSpec) -> tuple:
    """For each piece: ("planes", A, b) with the piece = {x: A x <= b} in O, or the
    analytic description ("sphere", centre, r) / ("cylinder", X_OP, r, half_length)."""
    out = []
    for piece in pieces(spec):
        X = piece.X_OP
        if piece.shape == "sphere":
            out.append(("sphere", np.array(X.translation()), piece.params[0]))
        elif piece.shape == "cylinder":
            out.append(("cylinder", X, piece.params[0], piece.params[1] / 2))
        else:
            if piece.shape == "box":
                half = np.array(piece.params) / 2
                verts = (
                    np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
                    * half
                )
            else:
                verts = piece.vertices
            eq = ConvexHull(verts).equations  # n . x + c <= 0 inside
            R, p = X.rotation().matrix(), np.array(X.translation())
            A = eq[:, :3] @ R.T
            b = -eq[:, 3] + A @ p
            out.append(("planes", A, b))
    return tuple(out)


def _inside(desc, points: np.ndarray, tol: float) -> np.ndarray:
    """True where points are inside the piece or within ``tol`` of its surface."""
    if desc[0] == "planes":
        _, A, b = desc
        return np.all(points @ A.T - b <= tol, axis=1)
    if desc[0] == "sphere":
        _, c, r = desc
        return np.linalg.norm(points - c, axis=1) <= r + tol
    _, X, r, half = desc
    q = (points - X.translation()) @ X.rotation().matrix()
    return (np.hypot(q[:, 0], q[:, 1]) <= r + tol) & (np.abs(q[:, 2]) <= half + tol)


def sample_surface(spec: ObjectSpec, n: int, rng=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniformly distributed (by area) on the object's outer surface.

    Returns ``(p_OS, n_O)``: points (n, 3) and outward unit normals (n, 3) in
    the object frame. Points on faces shared by two pieces are rejected, so
    every point lies on the true surface (round pieces are faceted: points on a
    sphere or cylinder lie on its 64-facet mesh, within 0.2 % of the radius).
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.sample_surface(spec, n, rng)
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise TypeError(f"n must be an int, got {type(n).__name__}")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(rng)
    piece_meshes = [p.mesh() for p in pieces(spec)]
    descs = _halfspaces(spec)
    tol = 1e-9 * spec.size
    # Sample on the concatenation by area, then drop points inside another piece;
    # repeat until enough points survive.
    mesh = trimesh.util.concatenate(piece_meshes)
    owner = np.concatenate([np.full(len(m.faces), i) for i, m in enumerate(piece_meshes)])
    areas = mesh.area_faces
    cdf = np.cumsum(areas) / areas.sum()
    tri = mesh.triangles
    normals = mesh.face_normals
    points, point_normals = [], []
    have = 0
    while have < n:
        m = max(2 * (n - have), 64)
        faces = np.minimum(np.searchsorted(cdf, rng.random(m)), len(cdf) - 1)
        u, v = rng.random(m), rng.random(m)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        t = tri[faces]
        p = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
        keep = np.ones(m, dtype=bool)
        for i, desc in enumerate(descs):
            others = owner[faces] != i
            keep[others] &= ~_inside(desc, p[others], tol)
        points.append(p[keep])
        point_normals.append(normals[faces[keep]])
        have += int(keep.sum())
    if n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.vstack(points)[:n], np.vstack(point_normals)[:n]


@dataclass(frozen=True)
class RayHits:
    """Result of :func:`ray_cast` for k rays: ``hit`` (k,) bool, ``distance`` (k,)
    along the ray (inf where no hit), ``p_OS`` (k, 3) hit points, ``n_O`` (k, 3)
    outward unit normals (NaN where no hit), ``piece`` (k,) index into
    ``pieces(spec)`` (-1 where no hit)."""

    hit: np.ndarray
    distance: np.ndarray
    p_OS: np.ndarray
    n_O: np.ndarray
    piece: np.ndarray


def _ray_planes(A, b, o, d):
    # Cyrus-Beck clipping of the rays against the piece's half-spaces.
    num = b[None, :] - o @ A.T  # >= 0 where the origin satisfies the plane
    den = d @ A.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    entering = den < 0
    exiting = den > 0
    t_in = np.where(entering, t, -np.inf).max(axis=1)
    t_out = np.where(exiting, t, np.inf).min(axis=1)
    parallel_out = np.any((den == 0) & (num < 0), axis=1)
    ok = (t_in <= t_out) & ~parallel_out & (t_in >= 0)
    face = np.where(entering, t, -np.inf).argmax(axis=1)
    normal = A[face] / np.linalg.norm(A[face], axis=1, keepdims=True)
    return np.where(ok, t_in, np.inf), normal


def _ray_sphere(c, r, o, d):
    oc = o - c
    bq = np.einsum("ij,ij->i", oc, d)
    disc = bq**2 - (np.einsum("ij,ij->i", oc, oc) - r * r)
    with np.errstate(invalid="ignore"):
        t = -bq - np.sqrt(disc)
    ok = (disc >= 0) & (t >= 0)
    t = np.where(ok, t, np.inf)
    with np.errstate(invalid="ignore"):
        normal = (o + np.where(ok, t, 0)[:, None] * d - c) / r
    return t, normal


def _ray_cylinder(X, r, half, o, d):
    R = X.rotation().matrix()
    q = (o - X.translation()) @ R
    e = d @ R
    best = np.full(len(o), np.inf)
    normal_local = np.zeros_like(q)
    # Side: entry through the round wall within the caps.
    a = e[:, 0] ** 2 + e[:, 1] ** 2
    bq = q[:, 0] * e[:, 0] + q[:, 1] * e[:, 1]
    c = q[:, 0] ** 2 + q[:, 1] ** 2 - r * r
    disc = bq**2 - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-bq - np.sqrt(disc)) / a
    z_side = q[:, 2] + t_side * e[:, 2]
    ok = (a > 0) & (disc >= 0) & (t_side >= 0) & (np.abs(z_side) <= half)
    best = np.where(ok, t_side, best)
    side_point = q + np.where(ok, t_side, 0)[:, None] * e
    normal_local[ok] = np.column_stack(
        [side_point[ok, 0], side_point[ok, 1], 0 * side_point[ok, 0]]
    )
    normal_local[ok] /= r
    # Caps: entry through the top (from above) or the bottom (from below).
    for sign in (1.0, -1.0):
        with np.errstate(divide="ignore", invalid="ignore"):
            t_cap = (sign * half - q[:, 2]) / e[:, 2]
        p = q + np.where(np.isfinite(t_cap), t_cap, 0)[:, None] * e
        ok = (sign * e[:, 2] < 0) & (t_cap >= 0) & (np.hypot(p[:, 0], p[:, 1]) <= r)
        ok &= t_cap < best
        best = np.where(ok, t_cap, best)
        normal_local[ok] = [0.0, 0.0, sign]
    return best, normal_local @ R.T


def _rays(p_OA, d_O) -> tuple[np.ndarray, np.ndarray]:
    """Checked ray origins (k, 3) and unit directions (k, 3) for a ray cast."""
    o = np.atleast_2d(np.asarray(p_OA, dtype=float))
    d = np.atleast_2d(np.asarray(d_O, dtype=float))
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"p_OA must have shape (k, 3), got {np.shape(p_OA)}")
    if d.shape != o.shape:
        raise ValueError(f"d_O must have shape {o.shape}, got {np.shape(d_O)}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("ray origins and directions must be finite")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0):
        raise ValueError("ray directions must be non-zero")
    return o, d / norm[:, None]


def ray_cast(spec: ObjectSpec, p_OA, d_O) -> RayHits:
    """First point where each ray ``p_OA + t d_O`` (t >= 0) enters the object.

    ``p_OA`` (k, 3) or (3,): ray origins in the object frame, outside the solid
    (a ray may start in the cavity of a mug); ``d_O`` same shape: directions
    (normalised here). Exact for the pieces' true shapes (spheres and cylinders
    are not faceted). Raises ValueError for an origin inside the solid.
    """
    if (mesh := _mesh_module(spec)) is not None:
        return mesh.ray_cast(spec, p_OA, d_O)
    o, d = _rays(p_OA, d_O)
    descs = _halfspaces(spec)
    inside = np.zeros(len(o), dtype=bool)
    for desc in descs:
        inside |= _inside(desc, o, -1e-12 * spec.size)
    if np.any(inside):
        raise ValueError(
            f"ray origins must lie outside the object; {int(inside.sum())} of {len(o)} are inside"
        )
    best = np.full(len(o), np.inf)
    normals = np.full((len(o), 3), np.nan)
    which = np.full(len(o), -1)
    for i, desc in enumerate(descs):
        if desc[0] == "planes":
            t, nrm = _ray_planes(desc[1], desc[2], o, d)
        elif desc[0] == "sphere":
            t, nrm = _ray_sphere(desc[1], desc[2], o, d)
        else:
            t, nrm = _ray_cylinder(desc[1], desc[2], desc[3], o, d)
        closer = t < best
        best[closer] = t[closer]
        normals[closer] = nrm[closer]
        which[closer] = i
    hit = np.isfinite(best)
    points = np.where(hit[:, None], o + np.where(hit, best, 0)[:, None] * d, np.nan)
    return RayHits(hit, best, points, normals, which)


# --------------------------------------------------------------------------- SDFormat


def _fmt(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values)


def _pose_text(X: RigidTransform) -> str:
    rpy = X.rotation().ToRollPitchYaw().vector()
    return f"<pose>{_fmt(X.translation())} {_fmt(rpy)}</pose>"


def _shape_sdf(piece: Piece, mesh_uri: str | None) -> str:
    if piece.shape == "sphere":
        return f"<sphere><radius>{piece.params[0]:.9g}</radius></sphere>"
    if piece.shape == "cylinder":
        r, length = piece.params
        return f"<cylinder><radius>{r:.9g}</radius><length>{length:.9g}</length></cylinder>"
    if piece.shape == "box":
        return f"<box><size>{_fmt(piece.params)}</size></box>"
    return f"<mesh><uri>{mesh_uri}</uri><drake:declare_convex/></mesh>"


def write_sdf(
    spec: ObjectSpec, directory, name: str | None = None, hydroelastic: bool = True
) -> Path:
    """Writes a standalone SDFormat model of ``spec`` into ``directory``.

    Files: ``<name>.sdf`` and one ``<name>_<piece>.obj`` per convex-hull piece,
    referenced by relative URIs. With ``hydroelastic`` the collision geometry
    declares compliant hydroelastic properties (used only when the plant's
    contact model is hydroelastic). The link is ``BODY_NAME``. Returns the
    path of the ``.sdf`` file.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    name = name or spec.kind
    M = spatial_inertia(spec)
    mp = mass_properties(spec)
    I = mp.I_SScm_O
    rgba = _fmt(spec.rgba)
    lines = [
        '<?xml version="1.0"?>',
        "<!-- Generated by handle_drake.objects.write_sdf; do not edit. -->",
        f"<!-- {spec!r} -->",
        '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">',
        f'  <model name="{name}">',
        f'    <link name="{BODY_NAME}">',
        "      <inertial>",
        f"        <pose>{_fmt(M.get_com())} 0 0 0</pose>",
        f"        <mass>{M.get_mass():.9g}</mass>",
        "        <inertia>",
        f"          <ixx>{I[0, 0]:.9g}</ixx><ixy>{I[0, 1]:.9g}</ixy><ixz>{I[0, 2]:.9g}</ixz>",
        f"          <iyy>{I[1, 1]:.9g}</iyy><iyz>{I[1, 2]:.9g}</iyz><izz>{I[2, 2]:.9g}</izz>",
        "        </inertia>",
        "      </inertial>",
    ]
    for piece in pieces(spec):
        uri = None
        if piece.shape == "convex":
            uri = f"{name}_{piece.name}.obj"
            _write_obj(trimesh.convex.convex_hull(piece.vertices), directory / uri)
        geometry = _shape_sdf(piece, uri)
        hydro = ""
        if hydroelastic:
            hint = spec.resolution_hint or piece.round_resolution_hint()
            hydro = (
                "<drake:compliant_hydroelastic/>"
                f"<drake:hydroelastic_modulus>{spec.hydroelastic_modulus:.9g}"
                "</drake:hydroelastic_modulus>"
                f"<drake:mesh_resolution_hint>{hint:.9g}</drake:mesh_resolution_hint>"
            )
        lines += [
            f'      <collision name="{piece.name}_collision">',
            f"        {_pose_text(piece.X_OP)}",
            f"        <geometry>{geometry}</geometry>",
            "        <drake:proximity_properties>",
            f"          <drake:mu_dynamic>{spec.mu:.9g}</drake:mu_dynamic>"
            f"<drake:mu_static>{spec.mu:.9g}</drake:mu_static>{hydro}",
            "        </drake:proximity_properties>",
            "      </collision>",
            f'      <visual name="{piece.name}_visual">',
            f"        {_pose_text(piece.X_OP)}",
            f"        <geometry>{geometry}</geometry>",
            f"        <material><diffuse>{rgba}</diffuse></material>",
            "      </visual>",
        ]
    lines += ["    </link>", "  </model>", "</sdf>", ""]
    path = directory / f"{name}.sdf"
    _write_text(path, "\n".join(lines))
    return path


def _write_text(path: Path, text: str) -> None:
    # Write to a temporary name and rename, so concurrent readers never see half a file.
    tmp = path.with_name(f".{path.name}.{id(text):x}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def _write_obj(mesh: trimesh.Trimesh, path: Path) -> None:
    lines = ["# convex piece generated by handle_drake.objects"]
    lines += [f"v {_fmt(v)}" for v in mesh.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    _write_text(path, "\n".join(lines) + "\n")


def write_table_sdf(
    directory, size: tuple[float, float] = (0.8, 0.8), thickness: float = 0.05, mu: float = 0.8
) -> Path:
    """Writes ``table.sdf``: a static table top whose top surface is at z = 0 of its model frame.

    Weld the link ``top`` to where the top-surface centre belongs. Rigid
    hydroelastic, friction ``mu``.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    sx, sy = (_check_positive("table size", s) for s in size)
    thickness = _check_positive("thickness", thickness)
    box = f"<box><size>{_fmt((sx, sy, thickness))}</size></box>"
    pose = f"<pose>0 0 {-thickness / 2:.9g} 0 0 0</pose>"
    text = "\n".join(
        [
            '<?xml version="1.0"?>',
            "<!-- Generated by handle_drake.objects.write_table_sdf; do not edit. -->",
            '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">',
            '  <model name="table">',
            '    <link name="top">',
            "      <inertial><mass>10</mass><inertia><ixx>0.5</ixx><iyy>0.5</iyy><izz>1</izz>"
            "<ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>",
            '      <collision name="top_collision">',
            f"        {pose}",
            f"        <geometry>{box}</geometry>",
            "        <drake:proximity_properties>",
            f"          <drake:mu_dynamic>{mu:.9g}</drake:mu_dynamic>"
            f"<drake:mu_static>{mu:.9g}</drake:mu_static>",
            "          <drake:rigid_hydroelastic/>"
            "<drake:mesh_resolution_hint>0.1</drake:mesh_resolution_hint>",
            "        </drake:proximity_properties>",
            "      </collision>",
            '      <visual name="top_visual">',
            f"        {pose}",
            f"        <geometry>{box}</geometry>",
            f"        <material><diffuse>{_fmt(_TABLE_COLOR)}</diffuse></material>",
            "      </visual>",
            "    </link>",
            "  </model>",
            "</sdf>",
            "",
        ]
    )
    path = directory / "table.sdf"
    _write_text(path, text)
    return path


def export_models(directory) -> list[Path]:
    """Writes table.sdf and every kind at its default size (``<kind>/<kind>.sdf``)."""
    directory = Path(directory)
    paths = [write_table_sdf(directory)]
    for kind in KINDS:
        paths.append(write_sdf(ObjectSpec.default(kind), directory / kind))
    return paths


def _main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != "export":
        print("usage: python -m handle_drake.objects export <directory>", file=sys.stderr)
        return 2
    for path in export_models(argv[1]):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
