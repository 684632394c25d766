"""Figure 9: the Shadow hand works the iControls Pro; MIDI reports what moved.

Two experiments, each a scenario (floating-wrist Shadow hand, the controller
fixed on the table, a keyframe script) run with a :class:`MidiReceiver` on
the station's ``midi_controller.midi`` output:

- :func:`jog_pinch_scenario`: a **palmar pinch** on the jog wheel's rim,
  planned by :func:`handle_drake.grasp.planning.plan_grasp` (the wheel stands
  in as an upright 45 mm block on the panel, the panel top as the table), then
  the wrist turns about the wheel's axis by ``turn_deg`` and back part of the
  way. The result compares the net ticks counted from MIDI with the wheel's
  true rotation: they must agree within one tick.
- :func:`fader_push_scenario`: the first finger's tip pushes a fader cap along
  its slot (the wrist moves, the finger is held stiff); the MIDI value must
  follow the cap's position (``round(127 s / travel)``, within one count).
"""

from __future__ import annotations

import dataclasses as dc
import math
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from handle_drake.base.hands import actuated_to_joint_positions, get_hand_spec
from handle_drake.devices.midi.codec import fader_value
from handle_drake.devices.midi.device import ControllerGeometry, control_layout
from handle_drake.devices.midi.mapping import LoadMidiMapping
from handle_drake.devices.midi.systems import MidiReceiver
from handle_drake.grasp.kinematics import GraspKinematics
from handle_drake.scenario import (
    Keyframe,
)
from handle_drake.trial.harness import DEFAULT_LOG
from handle_drake.trial.jog_pinch import (
    GRASP_TIME,
    controller_scenario,
    plan_jog_pinch,
    unwrap_wrist,
)
from handle_drake.trial.simulate import ScenarioRunner, script_trajectories

__all__ = [
    "MidiRunResult",
    "MidiScenarioRunner",
    "describe_midi",
    "fader_push_scenario",
    "jog_pinch_scenario",
    "run_midi_scenario",
    "unwrap_wrist",
    "commanded_wrist_turn_deg",
    "wheel_followed",
]

def _geometry() -> ControllerGeometry:
    return ControllerGeometry()


def _control(name: str):
    return next(c for c in control_layout(_geometry()) if c.name == name)


def jog_pinch_scenario(turn_deg: float = 60.0, back_deg: float = 20.0,
                       turn_time: float = 1.2, reach_direction=(-1.0, 0.0)):
    """The palmar-pinch jog-wheel experiment as a :class:`~handle_drake.scenario.Scenario`.

    The wrist turns the pinched wheel by ``turn_deg`` (positive: counter-
    clockwise seen from above, the jog joint's positive direction) over
    ``turn_time`` s, then back by ``back_deg``, then lets go and lifts.
    """

    for name, value in (("turn_deg", turn_deg), ("back_deg", back_deg)):
        if not (isinstance(value, int | float) and math.isfinite(value)
                and abs(value) <= 120):
            raise ValueError(f"{name}: expected a finite angle within +-120 degrees, got {value}")
    if not (math.isfinite(turn_time) and turn_time > 0):
        raise ValueError(f"turn_time: expected a positive duration (s), got {turn_time}")
    pinch = plan_jog_pinch(reach_direction)
    plan = pinch.plan
    openc = pinch.open_command()
    turned = pinch.turned
    script = pinch.grasp_script()
    t = GRASP_TIME
    steps = max(2, int(abs(turn_deg) / 5))
    for k in range(1, steps + 1):
        script.append(Keyframe(time=t + turn_time * k / steps,
                               wrist=turned(math.radians(turn_deg) * k / steps)))
    t += turn_time
    if back_deg != 0:  # no back-turn: no keyframes (they would share one time)
        back_steps = max(2, int(abs(back_deg) / 5))
        back_time = turn_time * abs(back_deg) / max(abs(turn_deg), 1e-9)
        for k in range(1, back_steps + 1):
            theta = math.radians(turn_deg - back_deg * k / back_steps)
            script.append(Keyframe(time=t + 0.2 + back_time * k / back_steps,
                                   wrist=turned(theta)))
        t += 0.2 + back_time
    final = math.radians(turn_deg - back_deg)
    script.append(Keyframe(time=t + 0.2))
    script.append(Keyframe(time=t + 0.6, hand=openc))
    lifted = turned(final)
    lifted[2] += 0.06
    script.append(Keyframe(time=t + 1.0, wrist=lifted))
    return controller_scenario(plan.X_WB_pregrasp, openc, unwrap_wrist(script),
                               duration=t + 1.2)


#: How far (deg) the wheel's net turn may differ from the wrist's before ``midi jog``
#: says the pinch did not carry it: the larger of this and half the wrist's turn. The
#: planned pinches land within 11 deg (+60/-20: wheel +50.6; -75/+25: -90.8; +25: +31.8).
JOG_FOLLOW_TOL_DEG = 15.0


def commanded_wrist_turn_deg(scenario, t0: float, t1: float) -> float:
    """The wrist's yaw change (deg) from ``t0`` to ``t1`` as the scenario's script plays
    it (linear between keyframes, as :func:`~handle_drake.trial.simulate.script_trajectories`):
    for the jog pinch, the turn the pinched wheel should make."""

    spec = get_hand_spec(scenario.hand.kind)
    _, wrist = script_trajectories(scenario, np.zeros(len(spec.actuated_joint_names)))
    if wrist is None:
        return 0.0
    return math.degrees(float(wrist.value(t1)[5, 0] - wrist.value(t0)[5, 0]))


def wheel_followed(wheel_deg: float, wrist_deg: float) -> bool:
    """True when the wheel turned with the wrist: the same way, within
    :data:`JOG_FOLLOW_TOL_DEG` or half the wrist's turn."""
    tol = max(JOG_FOLLOW_TOL_DEG, 0.5 * abs(wrist_deg))
    return abs(wheel_deg - wrist_deg) <= tol and (
        abs(wrist_deg) <= JOG_FOLLOW_TOL_DEG or wheel_deg * wrist_deg > 0)


def fader_push_scenario(fader: str = "fader5", push: float = 0.040):
    """The fingertip fader push as a :class:`~handle_drake.scenario.Scenario`.

    The hand, palm down with the first finger stretched and the others
    curled, lowers the first finger's tip behind the cap of ``fader`` and
    moves the wrist ``push`` m along the slot (``+y_C``), then lifts.
    """

    g = _geometry()
    names = [c.name for c in control_layout(g) if c.kind == "fader"]
    if fader not in names:
        raise ValueError(f"fader: expected one of {names}, got {fader!r}")
    if not (math.isfinite(push) and 0 < push <= g.fader_travel):
        raise ValueError(f"push: expected a distance in (0, {g.fader_travel}] m, got {push}")
    cap = _control(fader)
    # Hand frame: fingers along world +y (the fader's "up"), palm down.
    # R_WB = Rz(yaw) Ry(pitch) Rx(roll) with roll = 90 deg, yaw = 180 deg puts the
    # fingers (+z of the hand base) along +y and the palm (-y of the hand) down.
    curled = {"MFJ3": 1.5, "MFJ2": 1.5, "RFJ3": 1.5, "RFJ2": 1.5, "LFJ3": 1.5, "LFJ2": 1.5,
              "THJ5": 0.0, "THJ4": 1.2, "THJ2": 0.5, "FFJ3": 0.5}
    fingertip = _fingertip_offset(curled)
    rpy = np.array([math.radians(90), 0.0, math.radians(180)])
    R_WB = RotationMatrix(RollPitchYaw(rpy))
    # The fingertip (tip frame) just behind the cap's back face, at cap mid-height.
    p_tip = np.array([cap.p_C[0], cap.p_C[1] - g.fader_cap[1] / 2 - 0.011, cap.p_C[2] + 0.002])
    p_WB = p_tip - R_WB.multiply(fingertip)
    above = p_WB + [0, 0, 0.04]
    script = [
        Keyframe(time=0.0, hand=curled, wrist=[*above, *rpy]),
        Keyframe(time=0.5, wrist=[*p_WB, *rpy]),
        Keyframe(time=0.6),
        Keyframe(time=1.6, wrist=[*(p_WB + [0, push, 0]), *rpy]),
        Keyframe(time=1.8),
        Keyframe(time=2.2, wrist=[*(p_WB + [0, push, 0.04]), *rpy]),
    ]
    return controller_scenario(RigidTransform(R_WB, above), curled, script, duration=2.4)


def _fingertip_offset(command: dict) -> np.ndarray:
    """p_BT: the first finger's tip frame in the hand base frame for a command."""

    spec = get_hand_spec("shadow")
    kin = GraspKinematics(1.0)
    u = np.array([command.get(n, 0.0) for n in spec.actuated_joint_names])
    kin._set(actuated_to_joint_positions(spec, u, 1.0))
    base = kin.plant.GetBodyByName(spec.base_body, kin.hand).body_frame()
    tip = kin.plant.GetFrameByName("fftip", kin.hand)
    return tip.CalcPose(kin.context, base).translation()


@dc.dataclass
class MidiRunResult:
    """What a MIDI experiment recorded (sampled every ``harness.LOG_PERIOD`` s)."""

    times: np.ndarray  # (T,) s
    control_positions: np.ndarray  # (T, n) m / rad, the true control positions
    control_names: list[str]
    midi_values: np.ndarray  # (T, m) MidiReceiver.control_values
    midi_names: list[str]
    counts: dict  # accepted / rejected messages
    ticks_per_turn: int
    wall_time: float

    def position(self, name: str) -> np.ndarray:
        return self.control_positions[:, self.control_names.index(name)]

    def midi(self, name: str) -> np.ndarray:
        return self.midi_values[:, self.midi_names.index(name)]

    def jog_summary(self) -> dict:
        """True rotation (rad, ticks) and the net ticks counted from MIDI."""
        theta = self.position("jog")
        true_ticks = (theta[-1] - theta[0]) * self.ticks_per_turn / (2 * math.pi)
        counted = int(self.midi("jog")[-1])
        peak = int(np.abs(self.midi("jog")).max())
        return {"rotation_deg": math.degrees(theta[-1] - theta[0]),
                "max_rotation_deg": math.degrees(np.abs(theta - theta[0]).max()),
                "true_ticks": float(true_ticks), "midi_ticks": counted, "peak_midi_ticks": peak,
                "error_ticks": float(counted - true_ticks)}

    def fader_summary(self, fader: str, travel: float) -> dict:
        s = self.position(fader)
        midi = self.midi(fader)
        expected = np.array([fader_value(v, travel) for v in s])
        sent = midi >= 0
        return {"travel_m": float(s.max() - s.min()), "final_value": int(midi[-1]),
                "expected_value": int(expected[-1]),
                "max_error_counts": int(np.abs(midi[sent] - expected[sent]).max())
                if sent.any() else None}


class MidiScenarioRunner(ScenarioRunner):
    """A :class:`~handle_drake.trial.simulate.ScenarioRunner` (the trial harness: built once,
    reset per run) whose scenario has a MIDI controller, with a
    :class:`MidiReceiver` on the station's ``midi_controller.midi`` and the
    controls' true positions and the receiver's counts logged."""

    LOG = DEFAULT_LOG + ("midi_controller.control_positions", "control_values")

    def __init__(self, scenario, meshcat=None, log=()):
        if scenario.midi_controller is None:
            raise ValueError("scenario.midi_controller: this experiment needs a MIDI controller")
        if scenario.controller is not None:
            raise ValueError("scenario.controller: a MIDI experiment runs the scenario's script "
                             "(its receiver takes the controller's place); remove the controller")
        self.mapping = LoadMidiMapping(scenario.midi_controller.mapping or None)
        super().__init__(scenario, meshcat, log=tuple(dict.fromkeys(self.LOG + tuple(log))))

    def add_driver(self, builder, station):

        super().add_driver(builder, station)
        receiver = builder.AddNamedSystem("midi_receiver", MidiReceiver(
            self.mapping, period=self.scenario.midi_controller.scan_period))
        builder.Connect(station.GetOutputPort("midi_controller.midi"),
                        receiver.get_midi_input_port())
        return receiver

    def run_midi(self, html: str | Path | None = None) -> MidiRunResult:
        """Resets, simulates the scenario's duration and returns what MIDI reported."""
        duration = self.scenario.simulation_duration
        self.reset()
        return self.midi_result(self.harness.advance(duration, html))

    def midi_result(self, wall_time: float) -> MidiRunResult:
        """What MIDI reported over the last run (after :meth:`run_midi` or ``run``)."""
        logs = self.harness.logs()
        positions = logs["midi_controller.control_positions"]
        midi = logs["control_values"]
        if not np.all(np.isfinite(positions.data())):
            raise FloatingPointError("simulation diverged: non-finite control positions")
        receiver = self.controller
        return MidiRunResult(
            times=positions.sample_times().copy(),
            control_positions=positions.data().T.copy(),
            control_names=self.station.GetSubsystemByName("midi_controller").control_names,
            midi_values=midi.data().T.copy(),
            midi_names=receiver.control_names,
            counts=receiver.midi_counts(self.harness.controller_context()),
            ticks_per_turn=self.mapping.jog_ticks_per_turn,
            wall_time=wall_time,
        )


def describe_midi(result: MidiRunResult, mapping=None) -> str:
    """What the controller's MIDI said over a run against what its controls did, for
    ``handle-drake simulate``: per control that moved or sent anything, its true
    change (a fader's position and the value it gives; a knob's or the jog's turn in
    degrees and ticks) and what MIDI reported (the last fader value, the net ticks,
    the presses of a button). ``mapping``: the run's (default: the shipped one)."""
    layout = {c.name: c for c in control_layout(_geometry())}
    knob_ticks = (mapping or LoadMidiMapping()).knob_ticks_per_turn
    counts = result.counts
    lines = [f"MIDI controller: {counts['accepted']} messages accepted, "
             f"{counts['rejected']} ignored"]
    for name in result.midi_names:
        if name not in result.control_names:
            continue
        control, s, midi = layout[name], result.position(name), result.midi(name)
        change = float(s[-1] - s[0])
        if control.kind in ("knob", "jog"):
            n = result.ticks_per_turn if control.kind == "jog" else knob_ticks
            ticks = change * n / (2 * math.pi)
            if abs(ticks) < 0.5 and midi[-1] == 0:
                continue
            lines.append(f"  {name:8s} turned {math.degrees(change):+7.1f} deg "
                         f"({ticks:+.2f} ticks at {n}/turn); MIDI net ticks {int(midi[-1]):+d}")
        elif control.kind == "fader":
            if midi[-1] < 0 and abs(change) < 1e-4:
                continue
            sent = str(int(midi[-1])) if midi[-1] >= 0 else "none sent"
            lines.append(f"  {name:8s} at {s[-1] * 1e3:5.1f} of {control.travel * 1e3:.0f} mm "
                         f"(value {fader_value(float(s[-1]), control.travel)}); MIDI value "
                         f"{sent}")
        elif midi[-1] > 0:
            lines.append(f"  {name:8s} pressed {int(midi[-1])} time(s) (MIDI)")
    if len(lines) == 1:
        lines.append("  no control moved")
    return "\n".join(lines)


def run_midi_scenario(scenario, meshcat=None, html: str | Path | None = None) -> MidiRunResult:
    """Builds a :class:`MidiScenarioRunner` for ``scenario`` and runs it once."""
    return MidiScenarioRunner(scenario, meshcat).run_midi(html)
