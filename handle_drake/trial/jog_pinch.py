"""The palmar pinch on the MIDI controller's jog wheel, as a scenario builder.

Shared by Figure 9's ``midi jog`` experiment (``apps/figure9``) and the
jog-wheel learning task (``apps/inhand/jog_wheel``): the pinch planned by
:func:`handle_drake.grasp.planning.plan_grasp` on the wheel (an upright block
of the wheel's size on the panel, the panel top as the table), the wrist pose
turned about the wheel's axis, the grasp phase of the script (reach, close,
settle) and the floating-wrist Shadow scenario around the controller.
"""

from __future__ import annotations

import dataclasses as dc
import math

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from handle_drake.devices.midi.device import ControllerGeometry, control_layout
from handle_drake.geometry.objects import ObjectSpec
from handle_drake.grasp.planning import GraspPlan, plan_grasp
from handle_drake.grasp.taxonomy import GraspClass
from handle_drake.scenario import (
    FloatingWrist,
    HandConfig,
    Keyframe,
    MidiControllerConfig,
    Scenario,
    SimHandDriver,
    TableConfig,
    default_plant_config,
)

__all__ = ["GRASP_TIME", "TUCKED", "JogPinch", "controller_scenario", "plan_jog_pinch", "pose6",
           "unwrap_wrist"]

#: End of the grasp phase (s): reach 0.5, settle 0.1, close 0.4, settle 0.2.
GRASP_TIME = 1.2

#: The fingers the pinch (thumb and first finger) leaves free, curled into the palm (rad)
#: for the whole script. In the planner's pre-shape the ring and little fingers reach
#: down to the height of the neighbouring knobs' tops: turned about the wheel's axis, their
#: distal phalanges swept knob9 (+87 deg in the jog-wheel demonstration, -58 deg in
#: Figure 9's +60/-20 run, read from the plant's contact results).
TUCKED = {"RFJ3": 1.5, "RFJ2": 1.5, "LFJ3": 1.5, "LFJ2": 1.5}


def pose6(X: RigidTransform) -> list[float]:
    """``[x y z roll pitch yaw]`` of a pose (m, rad)."""
    return [float(v) for v in np.r_[X.translation(), RollPitchYaw(X.rotation()).vector()]]


@dc.dataclass(frozen=True)
class JogPinch:
    """The planned pinch and the wheel's axis (a vertical line through ``centre``)."""

    plan: GraspPlan
    centre: np.ndarray  # (3,) m, world: the wheel's axis at z = 0

    def turned(self, theta: float) -> list[float]:
        """The grasp's wrist pose turned by ``theta`` (rad, counter-clockwise seen from
        above: the jog joint's +) about the wheel's axis, as ``[x y z r p y]``."""
        R = RotationMatrix.MakeZRotation(theta)
        X = self.plan.X_WB
        p = self.centre + R.multiply(X.translation() - self.centre)
        return pose6(RigidTransform(R.multiply(X.rotation()), p))

    def open_command(self) -> dict[str, float]:
        """The planned pre-shape with the free fingers tucked (:data:`TUCKED`)."""
        return {**self.plan.command_dict(self.plan.preshape_command), **TUCKED}

    def grasp_script(self, grip: float | None = None) -> list[Keyframe]:
        """The grasp phase (0 to :data:`GRASP_TIME` s): open at the pre-grasp pose,
        reach the grasp pose, close (by ``grip`` when given: 0 the pre-shape, 1 the
        planned closure; None: the planned closure), settle. The free fingers stay
        tucked throughout."""
        plan = self.plan
        openc = self.open_command()
        close = {**plan.command_dict(plan.close_command), **TUCKED}
        if grip is not None:
            close = {n: float(openc.get(n, 0.0) + grip * (v - openc.get(n, 0.0)))
                     for n, v in close.items()}
        return [Keyframe(time=0.0, hand=openc, wrist=pose6(plan.X_WB_pregrasp)),
                Keyframe(time=0.5, wrist=pose6(plan.X_WB)),
                Keyframe(time=0.6),
                Keyframe(time=1.0, hand=close),
                Keyframe(time=GRASP_TIME)]


def plan_jog_pinch(reach_direction=(-1.0, 0.0)) -> JogPinch:
    """The palmar pinch on the jog wheel's rim, reaching along ``reach_direction``."""
    g = ControllerGeometry()
    jog = next(c for c in control_layout(g) if c.name == "jog")
    d = 2 * g.jog_radius
    block = ObjectSpec("cuboid", d, mu=g.mu, dimensions={"depth": d, "height": g.jog_height})
    # The pinch aims below the rim's mid-height: a fingertip pad planned at
    # mid-height touches the rim's top edge with the rounded tip first.
    p_target = np.array(jog.p_C) - [0.0, 0.0, 0.1 * g.jog_height]
    plan = plan_grasp(GraspClass.PALMAR_PINCH, block, RigidTransform(p_target),
                      table_height=g.panel_height - 0.1 * g.jog_height,
                      reach_direction=reach_direction)
    return JogPinch(plan, np.array([jog.p_C[0], jog.p_C[1], 0.0]))


def controller_scenario(X_WB: RigidTransform, initial: dict, script, duration: float,
                        X_WC=(0.0, 0.0), time_step: float = 0.002) -> Scenario:
    """The Shadow hand on a floating wrist (starting at ``X_WB``, joints at
    ``initial``) over the MIDI controller fixed on the table at ``X_WC`` (x, y),
    driven by ``script`` for ``duration`` s."""
    return Scenario(
        hand=HandConfig(kind="shadow", coupling_ratio=1.0,
                        mount=FloatingWrist(X_WB=Transform(X_WB)),
                        initial_position=dict(initial)),
        object=None,
        table=TableConfig(top_height=0.0),
        # 2 ms: the same wheel rotation and fader travel as at 1 ms (within
        # 1 degree / 0.1 mm) at twice the speed.
        plant_config=default_plant_config(time_step=time_step),
        driver=SimHandDriver(max_joint_velocity=4.0, control_period=time_step),
        simulation_duration=duration,
        script=script,
        midi_controller=MidiControllerConfig(
            X_WC=Transform(RigidTransform([X_WC[0], X_WC[1], 0.0]))),
    )


def unwrap_wrist(script):
    """``script`` with each keyframe's wrist roll, pitch and yaw moved by whole
    turns to lie within half a turn of the previous wrist keyframe's.

    The script interpolates ``[x y z roll pitch yaw]`` linearly, so a yaw that
    crosses +-180 degrees between two keyframes (RollPitchYaw wraps it) would
    send the wrist the long way round, nearly a full turn the other way.
    """
    out, previous = [], None
    for keyframe in script:
        if keyframe.wrist:
            wrist = np.array(keyframe.wrist, dtype=float)
            if previous is not None:
                turns = np.round((wrist[3:] - previous[3:]) / (2 * math.pi))
                wrist[3:] -= 2 * math.pi * turns
            previous = wrist
            keyframe = dc.replace(keyframe, wrist=[float(v) for v in wrist])
        out.append(keyframe)
    return out
