"""The screw cap's and the fingertip cylinder's turn from what the hand senses (issue 47).

``ScrewCapTask(score="estimated")`` (``handle-drake inhand --score estimated``) scores a
trial from :class:`SensedTurn` instead of the plant's joint or pose: the station then has
taxels (``hand.taxels``) and, with ``accelerometer``, an accelerometer on the object. At
every taxel sample (10 ms) it reads the station's ports alone -- ``hand.position_measured``,
``hand.taxels`` and ``object.acceleration`` -- and updates
:class:`~handle_drake.devices.taxels.turn.ContactTurn` (touch and joints) and
:class:`~handle_drake.devices.taxels.turn.GravityTurn` (the accelerometer: both objects
turn about a horizontal axis, world y). The estimate is the accelerometer's when the
object has one, else the touch's. What it knows beforehand is the task's setup (the hand's
mount, the object's size and its placed axis), never the plant's state.

The rule against leaning on the welded bottle reads the taxels too (:meth:`SensedTurn.
welded`): the bottle's cylinders (body and neck) and the cap's are the task's known scene;
a pressed taxel patch (its centre of pressure, from the measured joints' forward
kinematics) within ``WELDED_TOLERANCE`` of the bottle's surface and nearer to it than to
the cap's is force on the bottle. Read at every taxel sample (10 ms), not every step.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.devices.taxels.estimator import cylinder_signed_distance
from handle_drake.devices.taxels.turn import ContactTurn, GravityTurn

__all__ = ["SensedTurn", "SENSED_OUTPUTS", "SCORES", "WELDED_TOLERANCE", "cylinder_distance"]

#: ``ScrewCapTask.score``: the plant's joint / pose, or the sensed estimate.
SCORES = ("plant", "estimated")
#: The station outputs the estimate reads.
SENSED_OUTPUTS = ("hand.position_measured", "hand.taxels", "object.acceleration")
PERIOD = 0.01  # s: the taxels' sample period (profile pad4x4: 100 Hz)
#: m: a patch's centre of pressure within this of the bottle's surface presses the bottle
WELDED_TOLERANCE = 0.004


def cylinder_distance(points_W, X_WC: RigidTransform, radius: float, length: float):
    """The distance (m, unsigned) of each of ``points_W`` (k, 3) from the surface of a
    solid cylinder (axis: z of ``X_WC``, centred there, ``radius``, ``length``)."""
    p = X_WC.inverse().multiply(np.asarray(points_W, float).reshape(-1, 3).T).T
    return np.abs(cylinder_signed_distance(p, radius, length))


class SensedTurn:
    """The turn (deg) of a station-built screw-cap trial from its sensed ports.

    ``scenario``: the trial's :class:`~handle_drake.apps.inhand.screw_cap.ScrewCapScenario`;
    ``X_WO``: the object's placed pose (its axis: z); ``sign``: +1 when the trial counts
    the turn about +z of the object (the cap's joint), -1 about -z (the free cylinder);
    ``welded``: the welded bottle's cylinders ``[(X_WC, radius, length), ...]`` (the
    task's known scene; empty: none)."""

    def __init__(self, station, scenario, X_WO: RigidTransform, sign: float,
                 welded=(), **options):
        self._station = station
        ports = {station.get_output_port(i).get_name()
                 for i in range(station.num_output_ports())}
        self._q = station.GetOutputPort("hand.position_measured")
        self._taxels = station.GetOutputPort("hand.taxels")
        self._accel = station.GetOutputPort("object.acceleration") \
            if "object.acceleration" in ports else None
        X_WB = RigidTransform(RollPitchYaw(np.radians(scenario.hand_rpy_deg)),
                              np.asarray(scenario.hand_xyz, float))
        self._X_WB = X_WB
        X_BO = X_WB.inverse() @ X_WO
        axis_B = sign * X_BO.rotation().matrix()[:, 2]
        cap = scenario.cap
        self.contact = ContactTurn("shadow", 1.0, station.GetSubsystemByName("taxels").pads,
                                   X_BO.translation(), axis_B, cap.diameter / 2, cap.length,
                                   free=cap.free, R_BO=X_BO.rotation(),
                                   up_B=X_WB.rotation().inverse().multiply([0.0, 0.0, 1.0]),
                                   **options)
        # the sensor's axes are the object's (default_sensor_pose)
        self.gravity = GravityTurn((0.0, 0.0, sign)) if self._accel is not None else None
        self._next = 0.0
        self._fused = cap.free and self._accel is not None
        self._welded = [(RigidTransform(X), float(r), float(length))
                        for X, r, length in welded]
        self._cap = (X_WO, cap.diameter / 2, cap.length)
        self._reset_welded()

    def _reset_welded(self) -> None:
        self.welded_force = 0.0  # N: the last reading's force on the bottle
        self.welded_max = 0.0  # N: its largest since the reset
        self.welded_bodies: set[str] = set()

    def reset(self, root_context) -> None:
        """The trial's start: turn 0, a first reading now."""
        self.contact.reset()
        self._reset_welded()
        if self.gravity is not None:
            self.gravity.reset()
        self._next = root_context.get_time()
        self.step(root_context)

    def step(self, root_context) -> None:
        """After a simulator step: a reading when a taxel sample is due."""
        if root_context.get_time() < self._next - 1e-9:
            return
        self._next += PERIOD
        context = self._station.GetMyContextFromRoot(root_context)
        f_S = None if self._accel is None else self._accel.Eval(context)
        # a free object: its touch and its accelerometer fused (ContactTurn); a cap on its
        # thread (a fixed horizontal axis): each alone
        self.contact.update(self._q.Eval(context), self._taxels.Eval(context),
                            f_S if self._fused else None)
        if self.gravity is not None:
            self.gravity.update(f_S)
        if self._welded:
            self._read_welded()

    def _read_welded(self) -> None:
        """The taxels' force on the bottle at this reading (see the module doc)."""
        total = 0.0
        for pad, (_, points_B, forces) in zip(self.contact.pads, self.contact.contacts,
                                              strict=True):
            if not len(points_B):
                continue
            points_W = self._X_WB.multiply(points_B.T).T
            d_bottle = np.min([cylinder_distance(points_W, *c) for c in self._welded],
                              axis=0)
            on = (d_bottle <= WELDED_TOLERANCE) & (
                d_bottle < cylinder_distance(points_W, *self._cap))
            if on.any():
                total += float(forces[on].sum())
                self.welded_bodies.add(pad.body_name)
        self.welded_force = total
        self.welded_max = max(self.welded_max, total)

    @property
    def touch_deg(self) -> float:
        return float(np.degrees(self.contact.turn))

    @property
    def gravity_deg(self) -> float | None:
        return None if self.gravity is None else float(np.degrees(self.gravity.turn))

    @property
    def turn_deg(self) -> float:
        """The estimate: the accelerometer's when the object has one, else the touch's."""
        return self.touch_deg if self.gravity is None else self.gravity_deg

    def summary(self) -> dict:
        """What the taxels felt at the last reading, as the trial's contact summary: the
        hand bodies whose pads press the object's side (``touching``; ``"palm"`` for the
        palm pad) and the palm pad's force (N) on anything (``palm_force``)."""
        bodies = {p.name: p.body_name for p in self.contact.pads}
        palm = sum(self.contact.forces.get(n, 0.0) for n, b in bodies.items() if b == "palm")
        return {"touching": sorted({bodies[n] for n in self.contact.on_object}),
                "palm_force": float(palm)}

    def centre_W(self) -> np.ndarray:
        """The object's axis point (its centre as placed, or refitted for a free object),
        in world."""
        return self._X_WB.multiply(self.contact.centre)
