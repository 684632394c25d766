"""The kinds the pick plans beyond the planner's own (upright cuboids and spheres): each
grasped through an upright cuboid stand-in (its *proxy*), and passed through its hole
standing as it stood on the table.

The grasp planner (:func:`handle_drake.grasp.planning.plan_grasp`) grasps a sphere and a
cuboid standing upright (and a cylinder lying down, which no hole takes). Every other kind
of the shape sorter stands upright on the table and goes through its hole upright, so its
grasp is planned on a cuboid that stands where the part of it the fingers close on stands
(:func:`grasp_proxy`), as the planner already plans a user's mesh on its bounding box:

==================  ==============================================================
kind                proxy (upright cuboid in the object's frame O)
==================  ==============================================================
cylinder            its bounding box (diameter x diameter x height)
rotated_cuboid      the cuboid itself, turned by ``ROTATED_CUBOID_YAW`` in O
mug                 the cup without its handle (diameter x diameter x height): the
                    fingers close across the cup, the handle (on +x) between the
                    finger row's ends, clear of the opposition
wine_glass          the bowl (diameter x diameter x bowl height, at the bowl's
                    centre): held by its bowl, foot down
star_prism          its bounding box, the fingers across its narrower edge
mesh (a user's)     its bounding box, the fingers across its narrower edge
==================  ==============================================================

The proxy's frame Q (its centre, ``X_OQ`` in O) carries the planner's grasp; the
:class:`~handle_drake.grasp.planning.GraspPlan` handed on is expressed for the object
itself (``X_WO`` and ``object_spec`` the real object's): the hand's poses are the
proxy's, so ``X_OB`` (object to hand base) is exact and the carry and release place
the object itself over its hole. The closing command squeezes 20 mm past the proxy's
faces (the planner's ``CLOSING_SQUEEZE``) and the reactive close stops each finger on
its touch, so the fingers end on the real surface (a cylinder's side lies within
2 mm of its box's faces across the finger row). The grasp database stores the
proxies' grasps under the cuboid's key (kind ``cuboid``, the proxy's dimensions).
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from handle_drake.geometry.objects import ObjectSpec, dimensions, surface_mesh, total_height
from handle_drake.geometry.objects.catalogue import ROTATED_CUBOID_YAW

__all__ = ["PROXY_KINDS", "grasp_proxy", "proxied_plan", "proxy_height"]

#: The kinds planned through a cuboid proxy (module doc).
PROXY_KINDS = ("cylinder", "rotated_cuboid", "mug", "wine_glass", "star_prism", "mesh")


def _box(width, depth, height, p_OQ=(0.0, 0.0, 0.0), yaw=0.0):
    """``(cuboid spec, X_OQ)``: the finger row along the proxy's x (its longer
    horizontal edge): a deeper than wide box is turned a quarter."""
    if depth > width:
        width, depth, yaw = depth, width, yaw + math.pi / 2
    spec = ObjectSpec(kind="cuboid", size=float(width),
                      dimensions={"depth": float(depth), "height": float(height)})
    return spec, RigidTransform(RotationMatrix.MakeZRotation(yaw), np.asarray(p_OQ, float))


def grasp_proxy(spec) -> tuple[ObjectSpec, RigidTransform]:
    """``(proxy, X_OQ)``: the upright cuboid the grasp of ``spec`` (one of
    :data:`PROXY_KINDS`) is planned on and its pose in the object's frame (module doc)."""
    kind = spec.kind
    if kind not in PROXY_KINDS:
        raise ValueError(f"grasp_proxy: no proxy for a {kind!r} (kinds: {PROXY_KINDS})")
    if kind == "mesh":
        low, high = np.asarray(surface_mesh(spec).bounds, dtype=float)
        extent = high - low
        return _box(*extent, p_OQ=(low + high) / 2)
    d = dimensions(spec)
    if kind == "rotated_cuboid":
        return _box(d["width"], d["depth"], d["height"], yaw=ROTATED_CUBOID_YAW)
    if kind in ("cylinder", "mug"):
        return _box(d["diameter"], d["diameter"], d["height"])
    if kind == "wine_glass":
        bowl_centre = d["foot_thickness"] + d["stem_height"] + d["bowl_height"] / 2
        return _box(d["diameter"], d["diameter"], d["bowl_height"],
                    p_OQ=(0.0, 0.0, bowl_centre - total_height(spec) / 2))
    low, high = np.asarray(surface_mesh(spec).bounds, dtype=float)  # the star prism
    extent = high - low
    return _box(*extent, p_OQ=[*(low + high)[:2] / 2, 0.0])


def proxy_height(spec, height: float) -> float:
    """The proxy's centre above the table when the object's is ``height`` above it."""
    return float(height + grasp_proxy(spec)[1].translation()[2])


def proxied_plan(plan_grasp, grasp_class, spec, X_WO: RigidTransform, **kwargs):
    """``plan_grasp(grasp_class, proxy, X_WO X_OQ, **kwargs)`` with the answer expressed
    for the object (``X_WO``, ``object_spec``: see the module doc)."""
    proxy, X_OQ = grasp_proxy(spec)
    plan = plan_grasp(grasp_class, proxy, X_WO @ X_OQ, **kwargs)
    return dc.replace(plan, X_WO=X_WO, object_spec=spec)
