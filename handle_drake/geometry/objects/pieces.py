"""Convex pieces of the catalogue objects and their exact mass properties.

Every object is a union of convex :class:`Piece` s (a Drake ``Sphere``,
``Cylinder``, ``Box`` or ``Convex`` hull and its pose ``X_OP`` in the object
frame O) that tile it without overlapping; volume, mass and inertia are exact
sums over pieces (``pydrake.multibody.tree.CalcSpatialInertia`` per piece).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from pydrake.geometry import (
    Box,
    Convex,
    Cylinder,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import CalcSpatialInertia, SpatialInertia

from handle_drake.geometry.objects.catalogue import (
    _BOWL_PROFILE,
    DENSITY,
    ROTATED_CUBOID_YAW,
    ObjectSpec,
    _mesh_module,
    dimensions,
    total_height,
)
from handle_drake.geometry.objects.instrumented import DEVICE_OBJECTS


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
    if kind in DEVICE_OBJECTS:
        return tuple(Piece(name, "box", edges, RigidTransform(list(centre)))
                     for name, centre, edges in DEVICE_OBJECTS[kind].box_list(spec.size))
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
