"""Generated example meshes (no third-party files): a torus, an L-shaped bracket, a bowl.

Closed, outward-wound ``trimesh.Trimesh`` solids in metres with +z up, built
from closed-form profiles so that tests can check volumes and centres against
formulas. :func:`write_examples` writes them as OBJ, STL and PLY files for the
notebook, the benchmark and the tests (the project ships no mesh files).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["EXAMPLES", "torus", "l_bracket", "bowl", "prism", "write_examples"]


def torus(major_radius: float = 0.035, minor_radius: float = 0.011,
          sections: int = 32) -> trimesh.Trimesh:
    """A ring lying flat (axis z); volume ``2 pi^2 R r^2`` up to faceting."""
    return trimesh.creation.torus(major_radius, minor_radius, major_sections=sections,
                                  minor_sections=sections // 2)


def prism(polygon, depth: float) -> trimesh.Trimesh:
    """The polygon (n, 2) in the x-z plane (counter-clockwise seen from -y) extruded
    along y over ``[-depth/2, depth/2]``.

    Caps are fans from the polygon's first vertex, so the polygon must be
    star-shaped about it (every other vertex visible from it), as an L is
    about its inner corner.
    """
    xz = np.asarray(polygon, dtype=float)
    n = len(xz)
    front = np.column_stack([xz[:, 0], np.full(n, -depth / 2), xz[:, 1]])
    back = front + [0.0, depth, 0.0]
    vertices = np.vstack([front, back])
    faces = []
    for k in range(1, n - 1):
        faces.append([0, k, k + 1])  # front cap (y = -depth/2), normal -y
        faces.append([n, n + k + 1, n + k])  # back cap, normal +y
    for k in range(n):
        j = (k + 1) % n
        faces.append([k, n + k, n + j])
        faces.append([k, n + j, j])
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def l_bracket(length: float = 0.08, height: float = 0.06, thickness: float = 0.014,
              width: float = 0.035) -> trimesh.Trimesh:
    """An L lying on its long leg: a base ``length`` along x, an upright ``height`` at
    x = 0, both ``thickness`` thick and ``width`` deep along y. Volume
    ``width * thickness * (length + height - thickness)``."""
    t = thickness
    # Counter-clockwise seen from -y (x right, z up), starting at the inner corner.
    polygon = [(t, t), (t, height), (0.0, height), (0.0, 0.0), (length, 0.0), (length, t)]
    return prism(polygon, width)


def bowl(radius: float = 0.05, height: float = 0.04, wall: float = 0.006,
         foot_radius: float = 0.025, sections: int = 32) -> trimesh.Trimesh:
    """An open bowl standing on a flat foot: a conical wall ``wall`` thick (horizontal)
    from the foot (radius ``foot_radius`` at z = 0) to the rim (``radius`` at
    ``height``), with a bottom ``wall`` thick."""
    # (r, z) profile, counter-clockwise in the r-z plane, revolved about z.
    profile = np.array([
        [0.0, 0.0], [foot_radius, 0.0], [radius, height], [radius - wall, height],
        [foot_radius + (radius - foot_radius) * wall / height - wall, wall], [0.0, wall],
        [0.0, 0.0],
    ])
    mesh = trimesh.creation.revolve(profile, sections=sections)
    mesh.merge_vertices()
    mesh.remove_unreferenced_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    if mesh.volume < 0:
        mesh.invert()
    return mesh


#: name -> (generator, file extension written by write_examples)
EXAMPLES = {"torus": (torus, "obj"), "l_bracket": (l_bracket, "stl"), "bowl": (bowl, "ply")}


def write_examples(directory, sections: int = 32) -> dict[str, Path]:
    """Writes ``torus.obj``, ``l_bracket.stl`` and ``bowl.ply`` (metres) into ``directory``.

    ``sections``: facets around the torus and the bowl (fewer: coarser, faster to decompose).
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    out = {}
    for name, (make, ext) in EXAMPLES.items():
        path = directory / f"{name}.{ext}"
        (make() if make is l_bracket else make(sections=sections)).export(path)
        out[name] = path
    return out


def _check():  # pragma: no cover - a quick look from the command line
    for name, (make, _) in EXAMPLES.items():
        m = make()
        print(name, m.is_watertight, m.is_winding_consistent, m.volume, m.bounds.tolist())
    print("torus formula", 2 * math.pi**2 * 0.035 * 0.011**2)


if __name__ == "__main__":  # pragma: no cover
    _check()
