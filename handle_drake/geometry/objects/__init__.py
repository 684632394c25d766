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

Run ``python -m handle_drake.geometry.objects export models/objects`` to regenerate the
committed default-size SDFormat models and the table.

Mesh files (object kind ``mesh``, :class:`handle_drake.geometry.objects.mesh.MeshObjectSpec`)
are accepted by :func:`AddObject`, :func:`pieces`, :func:`mass_properties`,
:func:`spatial_inertia`, :func:`resting_height`, :func:`total_height`,
:func:`contact_feet`, :func:`surface_mesh`, :func:`sample_surface` and
:func:`ray_cast`, which hand them to :mod:`.mesh` (``mesh_examples`` generates
a torus, an L-bracket and a bowl).

Modules: :mod:`.catalogue` (kinds, proportions, :class:`ObjectSpec`),
:mod:`.pieces` (convex pieces, mass properties), :mod:`.plant` (``AddObject``,
``AddTable``), :mod:`.queries` (surface sampling, ray casts), :mod:`.sdf`
(SDFormat export). The names above are the public surface, importable from
``handle_drake.geometry.objects``.
"""

from handle_drake.geometry.objects.catalogue import (
    BODY_NAME,
    DEFAULT_SIZE,
    DENSITY,
    KINDS,
    PROPORTIONS,
    ROTATED_CUBOID_YAW,
    ObjectSpec,
    dimensions,
    resting_height,
    total_height,
)
from handle_drake.geometry.objects.pieces import (
    MassProperties,
    Piece,
    mass_properties,
    pieces,
    spatial_inertia,
)
from handle_drake.geometry.objects.plant import AddObject, AddTable, contact_feet
from handle_drake.geometry.objects.queries import RayHits, ray_cast, sample_surface, surface_mesh
from handle_drake.geometry.objects.sdf import export_models, write_sdf, write_table_sdf

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
    "export_models",
]
