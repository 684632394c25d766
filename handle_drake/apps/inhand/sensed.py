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
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw

from handle_drake.devices.taxels.turn import ContactTurn, GravityTurn

__all__ = ["SensedTurn", "SENSED_OUTPUTS", "SCORES"]

#: ``ScrewCapTask.score``: the plant's joint / pose, or the sensed estimate.
SCORES = ("plant", "estimated")
#: The station outputs the estimate reads.
SENSED_OUTPUTS = ("hand.position_measured", "hand.taxels", "object.acceleration")
PERIOD = 0.01  # s: the taxels' sample period (profile pad4x4: 100 Hz)


class SensedTurn:
    """The turn (deg) of a station-built screw-cap trial from its sensed ports.

    ``scenario``: the trial's :class:`~handle_drake.apps.inhand.screw_cap.ScrewCapScenario`;
    ``X_WO``: the object's placed pose (its axis: z); ``sign``: +1 when the trial counts
    the turn about +z of the object (the cap's joint), -1 about -z (the free cylinder)."""

    def __init__(self, station, scenario, X_WO: RigidTransform, sign: float, **options):
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

    def reset(self, root_context) -> None:
        """The trial's start: turn 0, a first reading now."""
        self.contact.reset()
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
