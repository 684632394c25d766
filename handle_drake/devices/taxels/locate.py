"""The held object's pose from one reading of the hand's senses (no plant state): the
taxels, the hand's measured joints and the hand base's pose, with a prior (where the
plan put the object in the hand, from the camera's detection at grasp time).

:func:`locate_in_hand` fits the object's signed distance to the pads' centres of pressure
(and its normals to theirs) with :meth:`InHandPoseEstimator.fit`, from several starts:
the prior, the object a half-size beyond the contacts along their normals, and for a
cuboid the prior turned by a quarter turn about each of its axes (a close that rolled
the box in the hand); the fit of least cost wins. :func:`sample_taxels` takes a fresh
reading of a station's simulated taxels now (a sensor sampled at the moment it is read).
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from handle_drake.devices.taxels.estimator import InHandPoseEstimator

__all__ = ["InHandLocation", "locate_in_hand", "sample_taxels", "PRIOR_POSITION_STD",
           "PRIOR_ANGLE_STD"]

#: The prior's spread: how far the close may have moved the object from the planned
#: grasp (2.4 cm was seen in a replay of a cuboid) and turned it.
PRIOR_POSITION_STD = 0.015  # m
PRIOR_ANGLE_STD = 0.2  # rad


@dc.dataclass
class InHandLocation:
    """``X_BO`` (the object in the hand base frame), its 6 x 6 covariance (rotation
    vector, position), the number of pads in contact and the RMS distance (m) of their
    centres of pressure to the fitted surface."""

    X_BO: RigidTransform
    covariance: np.ndarray
    contacts: int
    rms: float


def sample_taxels(station, root_context) -> np.ndarray:
    """A fresh reading (Pa) of ``station``'s simulated ``taxels`` system at the time of
    ``root_context`` (the whole diagram's: its forced sample), written into its state as
    the port's new value."""
    sensor = station.GetSubsystemByName("taxels")
    context = sensor.GetMyMutableContextFromRoot(root_context)
    state = sensor.AllocateDiscreteVariables()
    sensor.CalcForcedDiscreteVariableUpdate(context, state)
    context.SetDiscreteState(state)
    return np.array(sensor.GetOutputPort("taxels").Eval(context))


def _starts(estimator: InHandPoseEstimator, X_prior: RigidTransform, points, normals):
    starts = [X_prior]
    if len(points):
        guess = np.mean(points + estimator.half_size * normals, axis=0)
        starts.append(RigidTransform(X_prior.rotation(), guess))
    if estimator.shape_kind == "box":
        for axis in range(3):
            for angle in (np.pi / 2, -np.pi / 2):
                turn = np.zeros(3)
                turn[axis] = angle
                R = X_prior.rotation() @ RotationMatrix(_rotvec(turn))
                starts.append(RigidTransform(R, X_prior.translation()))
    return starts


def _rotvec(v):
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(v).as_matrix()


def locate_in_hand(estimator: InHandPoseEstimator, q: np.ndarray, taxels: np.ndarray,
                   X_BO_prior: RigidTransform, position_std: float = PRIOR_POSITION_STD,
                   angle_std: float = PRIOR_ANGLE_STD) -> InHandLocation | None:
    """The object's pose in the hand base frame from the hand's joints ``q`` and one
    ``taxels`` reading, near ``X_BO_prior`` (see the module doc); None when no pad
    feels the object."""
    points, normals, free, terms, touching = estimator.contacts(np.asarray(q, float),
                                                      np.asarray(taxels, float))
    if not len(points):
        return None
    hand = (estimator.hand_points(), estimator.hand_clearance)
    std = np.array([angle_std] * 3 + [position_std] * 3)
    best = None
    for start in _starts(estimator, X_BO_prior, points, normals):
        result = estimator.fit(points, normals, [(X_BO_prior, std)], None, free, hand,
                               start=start, terms=terms, touching=touching)
        if best is None or result[3] < best[3]:
            best = result
    X_BO, cov, rms, _ = best
    return InHandLocation(X_BO, cov, len(points), rms)
