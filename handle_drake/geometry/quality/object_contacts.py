"""Contacts on the object from a simulation: ``ContactResults`` -> per-fingertip contacts in O.

A simulated grasp is scored by turning the plant's contact results into, for
every fingertip, a contact point, an inward normal and the force it applies on
the object, all expressed in the object frame O (the report's reference frame
R_r at the object's body origin); the raw per-fingertip point clouds are kept
for the contact surface model (``surface.contact_surface``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import LeafSystem

from .contact import GraspContacts
from .metrics import grasp_quality
from .surface import contact_surface

__all__ = ["FingertipContacts", "ObjectContacts", "NO_CONTACT", "score_contacts"]


@dataclass
class FingertipContacts:
    """Per-fingertip contacts on the object, in the object frame O.

    Attributes:
        names: fingertip names (k,).
        in_contact: (k,) bool, the fingertip touches the object.
        p_OC: (k, 3) m, contact point (force-weighted mean of the fingertip's
            contact points; zeros when not in contact).
        n_O: (k, 3) inward unit normal on the object (force-weighted mean).
        f_O: (k, 3) N, total force the fingertip applies on the object.
        clouds: name -> ``(points (N, 3), inward normals (N, 3))`` raw, in O.
    """

    names: tuple[str, ...]
    in_contact: np.ndarray
    p_OC: np.ndarray
    n_O: np.ndarray
    f_O: np.ndarray
    clouds: dict = field(default_factory=dict)

    @classmethod
    def empty(cls, names) -> FingertipContacts:
        k = len(names)
        return cls(tuple(names), np.zeros(k, bool), np.zeros((k, 3)), np.zeros((k, 3)),
                   np.zeros((k, 3)), {})

    def grasp_contacts(self) -> GraspContacts:
        """The touching fingertips as :class:`GraspContacts` (raises if none touch)."""
        idx = np.flatnonzero(self.in_contact)
        if len(idx) == 0:
            raise ValueError("grasp_contacts: expected at least one fingertip in contact, got 0")
        return GraspContacts(self.p_OC[idx], self.n_O[idx], self.f_O[idx],
                             tuple(self.names[i] for i in idx))


def _body_indices(plant, spec, what: str) -> list[BodyIndex]:
    items = spec if isinstance(spec, Iterable) and not isinstance(spec, str) else [spec]
    out = []
    for item in items:
        if isinstance(item, BodyIndex):
            out.append(item)
        elif isinstance(item, str):
            out.append(plant.GetBodyByName(item).index())
        elif hasattr(item, "index") and hasattr(item, "body_frame"):
            out.append(item.index())
        else:
            raise TypeError(f"{what}: expected a Body, BodyIndex or body name, got {item!r}")
    if not out:
        raise ValueError(f"{what}: expected at least one body, got none")
    return out


class ObjectContacts(LeafSystem):
    """Per-fingertip contacts on the object, expressed in the object frame.

    .. pydrake_system::

        name: ObjectContacts
        input_ports:
        - contact_results
        - body_poses (or object_pose)
        output_ports:
        - object_contacts

    Ports:
        ``contact_results`` (in, abstract ``ContactResults``): the plant's (or
        station's) contact results, point-pair and hydroelastic contacts.
        ``body_poses`` (in, abstract ``list[RigidTransform]``): ``X_WB`` of every
        body, the plant's ``body_poses`` port; or, with ``pose_input="object_pose"``,
        ``object_pose`` (in, abstract ``RigidTransform``): ``X_WO`` (the station's
        ``object.pose``).
        ``object_contacts`` (out, abstract :class:`FingertipContacts`): per fingertip
        point (m), inward normal and force on the object (N), all in O.

    Args:
        plant: the MultibodyPlant (finalized) that produces the contact results.
        object_body: the object's Body (or its name); O is its body frame.
        fingertips: fingertip name -> Body, BodyIndex, body name, or a list of
            them (a fingertip may be several bodies, e.g. a distal link and a pad).
        pose_input: ``"body_poses"`` (default) or ``"object_pose"``.
    """

    def __init__(self, plant, object_body, fingertips: Mapping, pose_input: str = "body_poses"):
        super().__init__()
        if not plant.is_finalized():
            raise ValueError("plant: expected a finalized MultibodyPlant")
        if not isinstance(fingertips, Mapping) or not fingertips:
            raise ValueError("fingertips: expected a non-empty mapping name -> body")
        if pose_input not in ("body_poses", "object_pose"):
            raise ValueError(
                f"pose_input: expected 'body_poses' or 'object_pose', got {pose_input!r}"
            )
        (self._object,) = _body_indices(plant, object_body, "object_body")
        self._names = tuple(str(k) for k in fingertips)
        self._tip_of_body: dict[BodyIndex, int] = {}
        for i, spec in enumerate(fingertips.values()):
            for b in _body_indices(plant, spec, f"fingertips[{self._names[i]!r}]"):
                if b == self._object:
                    raise ValueError(f"fingertips[{self._names[i]!r}]: is the object body")
                if b in self._tip_of_body:
                    raise ValueError(f"fingertips: body {int(b)} is given twice")
                self._tip_of_body[b] = i
        # geometry -> body, for hydroelastic contact surfaces (keyed by GeometryId)
        self._body_of_geometry = {}
        for b in [self._object, *self._tip_of_body]:
            for g in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
                self._body_of_geometry[g] = b
        self._contact_port = self.DeclareAbstractInputPort(
            "contact_results", plant.get_contact_results_output_port().Allocate()
        )
        self._pose_input = pose_input
        if pose_input == "body_poses":
            self._pose_port = self.DeclareAbstractInputPort(
                "body_poses", plant.get_body_poses_output_port().Allocate()
            )
        else:
            self._pose_port = self.DeclareAbstractInputPort(
                "object_pose", AbstractValue.Make(RigidTransform())
            )
        self._output = self.DeclareAbstractOutputPort(
            "object_contacts",
            lambda: AbstractValue.Make(FingertipContacts.empty(self._names)),
            self._calc,
        )

    def get_contact_results_input_port(self):
        return self._contact_port

    def get_pose_input_port(self):
        return self._pose_port

    def get_object_contacts_output_port(self):
        return self._output

    @property
    def fingertip_names(self) -> tuple[str, ...]:
        return self._names

    def _pairs(self, results):
        """Yield (tip, p_W, inward n_W, force on object f_W) for each relevant contact."""
        obj = self._object
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            a, b = info.bodyA_index(), info.bodyB_index()
            if obj == a and b in self._tip_of_body:
                tip, sign = self._tip_of_body[b], 1.0  # nhat_BA points into A = object
            elif obj == b and a in self._tip_of_body:
                tip, sign = self._tip_of_body[a], -1.0
            else:
                continue
            n_W = sign * info.point_pair().nhat_BA_W
            # contact_force() acts on B; the object gets it if it is B.
            f_W = -sign * info.contact_force()
            yield tip, info.contact_point(), n_W, f_W
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            s = info.contact_surface()
            bm = self._body_of_geometry.get(s.id_M())
            bn = self._body_of_geometry.get(s.id_N())
            if bm == obj and bn in self._tip_of_body:
                tip, sign = self._tip_of_body[bn], 1.0  # normals point out of N into M
            elif bn == obj and bm in self._tip_of_body:
                tip, sign = self._tip_of_body[bm], -1.0
            else:
                continue
            # F_Ac_W acts on M's body at the centroid
            f_W = sign * info.F_Ac_W().translational()
            normals = np.array([s.face_normal(f) for f in range(s.num_faces())])
            areas = np.array([s.area(f) for f in range(s.num_faces())])
            n_W = sign * (areas @ normals)
            n_W /= max(np.linalg.norm(n_W), 1e-300)
            yield tip, s.centroid(), n_W, f_W

    def _calc(self, context, output):
        results = self._contact_port.Eval(context)
        if self._pose_input == "body_poses":
            X_WO = self._pose_port.Eval(context)[int(self._object)]
        else:
            X_WO = self._pose_port.Eval(context)
        X_OW = X_WO.inverse()
        R_OW = X_OW.rotation().matrix()
        k = len(self._names)
        pts = [[] for _ in range(k)]
        nrm = [[] for _ in range(k)]
        frc = [[] for _ in range(k)]
        for tip, p_W, n_W, f_W in self._pairs(results):
            pts[tip].append(X_OW @ np.asarray(p_W))
            nrm[tip].append(R_OW @ np.asarray(n_W))
            frc[tip].append(R_OW @ np.asarray(f_W))
        value = FingertipContacts.empty(self._names)
        for i in range(k):
            if not pts[i]:
                continue
            P, N, F = np.array(pts[i]), np.array(nrm[i]), np.array(frc[i])
            w = np.maximum(np.einsum("ij,ij->i", F, N), 0.0)  # normal force magnitudes
            w = w / w.sum() if w.sum() > 0 else np.full(len(P), 1.0 / len(P))
            n = w @ N
            nn = np.linalg.norm(n)
            if nn < 1e-12:
                continue  # normals cancel: no meaningful single contact
            value.in_contact[i] = True
            value.p_OC[i] = w @ P
            value.n_O[i] = n / nn
            value.f_O[i] = F.sum(axis=0)
            value.clouds[self._names[i]] = (P, N)
        output.set_value(value)


#: BW value reported when nothing touches the object: that of a single
#: frictionless unit contact, worse than any grasp with contact on a sphere.
NO_CONTACT = -1.0


def score_contacts(contacts: FingertipContacts, params, surface=None,
                   surface_radius: float = 0.0, num_rings: int = 1, points_per_ring: int = 4):
    """BW metric of simulated contacts: ``(value, force_closure, detail)``.

    Each touching body's raw contact cloud goes through the contact surface
    model (report 4.1.3) on ``surface`` when ``surface_radius > 0``; where no
    segment hits the surface, the body's force-weighted mean contact is used.
    ``detail`` maps body name -> ``{"p_O", "n_O", "f_O"}`` lists (JSON-ready).
    Nothing touching scores :data:`NO_CONTACT`.
    """
    idx = np.flatnonzero(contacts.in_contact)
    if len(idx) == 0:
        return NO_CONTACT, False, {}
    points, normals, detail = [], [], {}
    for i in idx:
        name = contacts.names[i]
        detail[name] = {"p_O": contacts.p_OC[i].tolist(), "n_O": contacts.n_O[i].tolist(),
                        "f_O": contacts.f_O[i].tolist()}
        cloud = contacts.clouds.get(name)
        modelled = None
        if surface is not None and surface_radius > 0 and cloud is not None:
            try:
                modelled = contact_surface(cloud[0], cloud[1], surface, surface_radius,
                                           num_rings=num_rings, points_per_ring=points_per_ring)
            except ValueError:
                modelled = None  # no segment hit the surface: keep the raw contact
        if modelled is None or len(modelled[0]) == 0:
            points.append(contacts.p_OC[i][None])
            normals.append(contacts.n_O[i][None])
        else:
            points.append(modelled[0])
            normals.append(modelled[1])
    quality = grasp_quality(np.vstack(points), np.vstack(normals), params)
    return float(quality.value), bool(quality.force_closure), detail
