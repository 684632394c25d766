"""Simulated sensors of the station: fingertip tactile sensing and object pose.

The real hands carry pressure sensors (PST) or BioTacs in the fingertips; here
each fingertip reports the normal contact force on its distal link, summed
over all contacts (point and hydroelastic) the plant reports.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import BasicVector, LeafSystem

__all__ = ["FingertipTactile", "BodyPoseSelector", "HandJointsToPlantPositions",
           "fingertip_normal_forces"]


def fingertip_normal_forces(contact_results: ContactResults, fingertip_bodies,
                            geometry_to_body=None) -> np.ndarray:
    """Normal contact force magnitude (N) on each body of ``fingertip_bodies``.

    ``fingertip_bodies`` is a list of ``BodyIndex``; ``geometry_to_body`` maps
    the collision ``GeometryId`` of those bodies to their ``BodyIndex`` (needed
    for hydroelastic contacts, which name geometries, not bodies). A contact
    between two fingertips counts for both.
    """
    return _NormalForces(fingertip_bodies, geometry_to_body)(contact_results)


class _NormalForces:
    """:func:`fingertip_normal_forces` with its lookups built once (the tactile
    sensor calls it every sample): body and geometry -> output slot as plain
    ints and dicts, and a contact's force read only when one of its bodies is a
    fingertip (each pydrake accessor is a call into C++; a sample sees ~10
    contacts, half of them hand-hand, palm or table contacts)."""

    def __init__(self, fingertip_bodies, geometry_to_body=None):
        self._size = len(fingertip_bodies)
        self._slot = {int(index): i for i, index in enumerate(fingertip_bodies)}
        self._geometry_slot = {
            geometry: self._slot[int(body)] for geometry, body in (geometry_to_body or {}).items()
            if int(body) in self._slot}
        self._hydroelastic = bool(geometry_to_body)

    def __call__(self, contact_results: ContactResults) -> np.ndarray:
        forces = np.zeros(self._size)
        slot = self._slot.get
        for i in range(contact_results.num_point_pair_contacts()):
            info = contact_results.point_pair_contact_info(i)
            a, b = slot(int(info.bodyA_index())), slot(int(info.bodyB_index()))
            if a is None and b is None:
                continue
            magnitude = abs(float(np.dot(info.contact_force(), info.point_pair().nhat_BA_W)))
            if a is not None:
                forces[a] += magnitude
            if b is not None:
                forces[b] += magnitude
        if self._hydroelastic:
            slot = self._geometry_slot.get
            for i in range(contact_results.num_hydroelastic_contacts()):
                info = contact_results.hydroelastic_contact_info(i)
                surface = info.contact_surface()
                m, n = slot(surface.id_M()), slot(surface.id_N())
                if m is None and n is None:
                    continue
                magnitude = abs(float(np.dot(info.F_Ac_W().translational(),
                                             _mean_normal(surface))))
                if m is not None:
                    forces[m] += magnitude
                if n is not None:
                    forces[n] += magnitude
        return forces


def _mean_normal(surface) -> np.ndarray:
    """Area-weighted unit normal of a hydroelastic contact surface."""
    n = np.zeros(3)
    for face in range(surface.num_faces()):
        n += surface.area(face) * surface.face_normal(face)
    norm = np.linalg.norm(n)
    return n / norm if norm > 0 else n


class FingertipTactile(LeafSystem):
    """Normal contact force on each fingertip.

    Ports:

    - input ``contact_results`` (abstract ``ContactResults``).
    - output ``tactile`` (number of fingertips, N): normal force on each
      fingertip's distal link, fingertips in :class:`HandSpec` order.
    """

    def __init__(self, plant, fingertip_bodies):
        super().__init__()
        self._bodies = [body.index() for body in fingertip_bodies]
        self._geometry_to_body = {
            geometry: body.index()
            for body in fingertip_bodies
            for geometry in plant.GetCollisionGeometriesForBody(body)
        }
        self._forces = _NormalForces(self._bodies, self._geometry_to_body)
        self._contact_port = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self.DeclareVectorOutputPort("tactile", len(self._bodies), self._calc)

    def get_contact_results_input_port(self):
        return self._contact_port

    def _calc(self, context, out):
        out.SetFromVector(self._forces(self._contact_port.Eval(context)))


class BodyPoseSelector(LeafSystem):
    """Picks one body's pose and spatial velocity out of the plant's outputs.

    Ports:

    - input ``body_poses`` (abstract ``vector<RigidTransform>``), input
      ``body_spatial_velocities`` (abstract ``vector<SpatialVelocity>``).
    - output ``pose`` (abstract ``RigidTransform``, ``X_WB``).
    - output ``spatial_velocity`` (abstract ``SpatialVelocity``, ``V_WB`` in world).
    - output ``position`` (3, m): ``p_WB``, for loggers and plots.
    """

    def __init__(self, body):
        super().__init__()
        self._index = int(body.index())
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._velocities = self.DeclareAbstractInputPort(
            "body_spatial_velocities", AbstractValue.Make([SpatialVelocity()])
        )
        self.DeclareAbstractOutputPort(
            "pose", lambda: AbstractValue.Make(RigidTransform()),
            lambda context, out: out.set_value(self._poses.Eval(context)[self._index]),
        )
        self.DeclareAbstractOutputPort(
            "spatial_velocity", lambda: AbstractValue.Make(SpatialVelocity()),
            lambda context, out: out.set_value(self._velocities.Eval(context)[self._index]),
        )
        self.DeclareVectorOutputPort(
            "position", 3,
            lambda context, out: out.SetFromVector(
                self._poses.Eval(context)[self._index].translation()),
        )


class HandJointsToPlantPositions(LeafSystem):
    """Scatters hand joint positions into a plant's position vector (for drawing).

    Ports: input ``hand_positions`` (nq, rad, ``HandSpec.joint_names`` order);
    output ``plant_positions`` (plant nq, rad; other entries at their defaults).
    Holds the (non-owned by its consumer) plant so it lives as long as the diagram.
    """

    def __init__(self, plant, model_instance, joint_names):
        super().__init__()
        self._plant = plant
        self._index = np.array([plant.GetJointByName(n, model_instance).position_start()
                                for n in joint_names], dtype=int)
        self._default = plant.GetPositions(plant.CreateDefaultContext())
        self.DeclareVectorInputPort("hand_positions", len(joint_names))
        self.DeclareVectorOutputPort("plant_positions", plant.num_positions(), self._calc)

    def plant(self):
        return self._plant

    def _calc(self, context, output: BasicVector):
        q = self._default.copy()
        q[self._index] = self.get_input_port().Eval(context)
        output.SetFromVector(q)
