"""Grasp quality: wrenches, contact models, the contact surface model, force
closure, the Bimodal Wrench Space metric (report section 4.1), the classic
Ferrari-Canny and hull-volume references, and the ``ObjectContacts`` system
that turns a simulation's contact results into contacts on the object.

Typical use::

    from handle_drake.geometry.quality import ContactParams, grasp_quality
    q = grasp_quality(p_OC, n_O, ContactParams(mu=0.5, gamma=0.002, num_edges=8))
    q.value, q.force_closure
"""

from .contact import (
    ContactModel,
    GraspContacts,
    contact_frames,
    contact_wrenches,
    grasp_map,
    wrenches_per_contact,
)
from .drake_programs import ClosurePrograms, wrench_rank
from .hull import largest_ball_radius, min_norm_point, qhull_ball_radius
from .metrics import (
    ContactParams,
    GraspQuality,
    bw_metric,
    bw_metric_batch,
    ferrari_canny,
    ferrari_canny_linf_qhull,
    grasp_quality,
    hull_volume,
    is_force_closure,
    quality_from_wrenches,
)
from .object_contacts import NO_CONTACT, FingertipContacts, ObjectContacts, score_contacts
from .surface import (
    BoxSurface,
    CylinderSurface,
    MeshSurface,
    SphereSurface,
    contact_surface,
    disk_pattern,
    mean_contact,
)
from .wrench import skew, transform_wrenches, wrench_transform

__all__ = [
    # wrenches (eqs. 1-3)
    "skew",
    "wrench_transform",
    "transform_wrenches",
    # contact models and grasp map (eqs. 4-14)
    "ContactModel",
    "ContactParams",
    "GraspContacts",
    "contact_frames",
    "contact_wrenches",
    "grasp_map",
    "wrenches_per_contact",
    # contact surface model (4.1.3)
    "SphereSurface",
    "BoxSurface",
    "CylinderSurface",
    "MeshSurface",
    "contact_surface",
    "disk_pattern",
    "mean_contact",
    # closure and metrics (eqs. 15-21)
    "GraspQuality",
    "grasp_quality",
    "bw_metric",
    "bw_metric_batch",
    "quality_from_wrenches",
    "is_force_closure",
    "ClosurePrograms",
    "wrench_rank",
    "min_norm_point",
    "largest_ball_radius",
    "qhull_ball_radius",
    "ferrari_canny",
    "NO_CONTACT",
    "score_contacts",
    "ferrari_canny_linf_qhull",
    "hull_volume",
    # simulation
    "FingertipContacts",
    "ObjectContacts",
]
