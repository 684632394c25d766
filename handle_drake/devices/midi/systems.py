"""LeafSystems of the MIDI controller: the device's encoder, a receiver that
counts what moved, and the hand-control interface.

MIDI travels between systems as an abstract :class:`MidiBatch` (the messages
of one update and a sequence number, so a reader takes each batch once) and
between processes or devices through a ``mido`` port (:mod:`handle_drake.devices.midi.ports`).

:class:`MidiControllerEncoder` (the simulated device; in the station)

==========================  =====  ==============  =======================================
port                        dir    size            units
==========================  =====  ==============  =======================================
``plant_state``             in     plant nq + nv   the plant's full state
``control_positions``       out    n controls      m (faders, buttons), rad (knobs, jog)
``midi``                    out    ``MidiBatch``   messages the device sent at its last scan
==========================  =====  ==============  =======================================

:class:`MidiReceiver` (the host: what the learner is told)

==========================  =====  ==============  =======================================
``midi_in``                 in     ``MidiBatch``   optional; and/or a mido ``port`` polled
``control_values``          out    n mapping       fader 7-bit value (-1 before any), net
                                                   ticks of knobs and jog, presses of buttons
``midi_counts``             out    2 + reasons     accepted, rejected, then rejected per
                                                   reason (``codec.REJECT_REASONS``)
==========================  =====  ==============  =======================================

:class:`MidiHandControl` (the hand-control interface)

==========================  =====  ==============  =======================================
``midi_in``                 in     ``MidiBatch``   optional; and/or a mido ``port`` polled
``position``                out    nu              rad, connect to ``hand.position``
``mode``                    out    1               0 joint mode, 1 synergy mode
``feedback``                out    ``MidiBatch``   fader feedback sent at start / the last switch
``midi_counts``             out    2 + reasons     as above
==========================  =====  ==============  =======================================
"""

from __future__ import annotations

import dataclasses as dc

import numpy as np
from pydrake.common.value import Value
from pydrake.systems.framework import LeafSystem

from handle_drake.base.hands import actuated_position_limits, get_hand_spec
from handle_drake.devices.midi.codec import (
    REJECT_REASONS,
    ControlCounts,
    ControlEncoder,
    MidiDecoder,
    control_message,
)
from handle_drake.devices.midi.device import check_mapping_on_device, control_layout
from handle_drake.devices.midi.mapping import MidiMapping

__all__ = [
    "MidiBatch",
    "MidiControllerEncoder",
    "MidiHandControl",
    "MidiReceiver",
    "JOINT_MODE",
    "SYNERGY_MODE",
    "DEFAULT_FADER_JOINTS",
    "DEFAULT_KNOB_JOINTS",
]

JOINT_MODE, SYNERGY_MODE = 0, 1

# Shadow hand, joint mode: the nine faders drive the flexion of each finger and
# the thumb's rotation; the knobs the abductions, the thumb's other joints and
# the wrist (relative, ``radians_per_tick`` per tick).
DEFAULT_FADER_JOINTS = ("FFJ3", "FFJ2", "MFJ3", "MFJ2", "RFJ3", "RFJ2", "LFJ3", "LFJ2", "THJ5")
DEFAULT_KNOB_JOINTS = ("FFJ4", "MFJ4", "RFJ4", "LFJ4", "LFJ5", "THJ4", "THJ2", "THJ1", "WRJ1")


@dc.dataclass(frozen=True)
class MidiBatch:
    """The MIDI messages of one update; ``seq`` grows by one per non-empty batch."""

    seq: int = 0
    messages: tuple = ()

    # Drake clones abstract state values at every unrestricted update (a
    # Python Value[object] clone is a deepcopy). A batch is never changed
    # after it is made, so a clone can be the batch itself.
    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self


def _batch_value() -> Value:
    return Value[object](MidiBatch())


class MidiControllerEncoder(LeafSystem):
    """The simulated device: reads its controls from the plant state every
    ``period`` s (the device's scan) and sends what changed (see ``codec``).

    Args:
        plant: the finalized plant holding the controller model instance.
        instance: the controller's model instance.
        mapping: the :class:`MidiMapping`; controls of the model that the
            mapping lacks are not sent.
        period: s, the scan period (> 0).
        geometry: the :class:`~handle_drake.devices.midi.device.ControllerGeometry` used.
    """

    def __init__(self, plant, instance, mapping: MidiMapping, period: float = 0.001,
                 geometry=None):
        super().__init__()
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be a finite number > 0 (s), got {period}")
        check_mapping_on_device(mapping, geometry)
        layout = control_layout(geometry)
        known = set(mapping.names())
        self._layout = [c for c in layout if c.name in known]
        names = [c.name for c in self._layout]
        self._q_index = np.array([plant.GetJointByName(n, instance).position_start()
                                  for n in names], dtype=int)
        self._encoder = ControlEncoder(mapping, names, [c.travel for c in self._layout])
        self._plant_state = self.DeclareVectorInputPort(
            "plant_state", plant.num_positions() + plant.num_velocities())
        q0 = plant.GetPositions(plant.CreateDefaultContext())[self._q_index]
        self._encoder.reset(q0)
        self._levels = self.DeclareDiscreteState(np.array(self._encoder.levels, dtype=float))
        self._batch = self.DeclareAbstractState(_batch_value())
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._scan)
        self.DeclareVectorOutputPort(
            "control_positions", len(names),
            lambda context, out: out.SetFromVector(
                self._plant_state.Eval(context)[self._q_index]))
        self.DeclareAbstractOutputPort(
            "midi", _batch_value,
            lambda context, out: out.set_value(
                context.get_abstract_state(int(self._batch)).get_value()),
            prerequisites_of_calc={self.abstract_state_ticket(self._batch)})

    @property
    def control_names(self) -> list[str]:
        return [c.name for c in self._layout]

    def get_plant_state_input_port(self):
        return self._plant_state

    def _scan(self, context, state):
        positions = self._plant_state.Eval(context)[self._q_index]
        previous = context.get_discrete_state(self._levels).value().astype(np.int64)
        levels, messages = self._encoder.encode(previous, positions)  # pure: no system member
        if not messages:
            return
        state.get_mutable_discrete_state(self._levels).SetFromVector(levels.astype(float))
        previous = context.get_abstract_state(int(self._batch)).get_value()
        state.get_mutable_abstract_state(int(self._batch)).set_value(
            MidiBatch(previous.seq + 1, tuple(messages)))


class _MidiInput:
    """What :class:`MidiReceiver` and :class:`MidiHandControl` share: the
    ``midi_in`` port and an optional mido port, decoded with bad input counted.

    Counters live in a discrete state group ``[last batch seq, accepted,
    rejected per reason...]`` so that a context reset resets them too.
    """

    def _declare_midi_input(self, mapping: MidiMapping, port, max_messages_per_update: int):
        if not isinstance(mapping, MidiMapping):
            raise TypeError(f"mapping must be a MidiMapping, got {type(mapping).__name__}")
        if port is not None and not hasattr(port, "iter_pending"):
            raise TypeError(f"port must be a mido input port, got {type(port).__name__}")
        if not (isinstance(max_messages_per_update, int) and max_messages_per_update > 0):
            raise ValueError("max_messages_per_update: expected an integer > 0, got "
                             f"{max_messages_per_update!r}")
        self._mapping = mapping
        self._port = port
        self._budget = max_messages_per_update
        self._midi_in = self.DeclareAbstractInputPort("midi_in", _batch_value())
        self._counts = self.DeclareDiscreteState(2 + len(REJECT_REASONS))
        self.DeclareVectorOutputPort(
            "midi_counts", 2 + len(REJECT_REASONS), self._calc_counts,
            prerequisites_of_calc={self.discrete_state_ticket(self._counts)})

    def get_midi_input_port(self):
        return self._midi_in

    def _calc_counts(self, context, out):
        counts = context.get_discrete_state(self._counts).value()
        out.SetFromVector(np.r_[counts[1], counts[2:].sum(), counts[2:]])

    def midi_counts(self, context) -> dict:
        """``{"accepted": n, "rejected": n, reason: n, ...}`` from a context."""
        counts = context.get_discrete_state(self._counts).value()
        out = {"accepted": int(counts[1]), "rejected": int(counts[2:].sum())}
        out.update({r: int(c) for r, c in zip(REJECT_REASONS, counts[2:], strict=True)})
        return out

    def _events(self, context, state) -> list:
        """Decoded events of this update (port first, then the ``midi_in`` batch)."""
        raw = list(self._port.iter_pending()) if self._port is not None else []
        seq = None
        if self._midi_in.HasValue(context):
            batch = self._midi_in.Eval(context)
            if (isinstance(batch, MidiBatch)
                    and batch.seq != context.get_discrete_state(self._counts).value()[0]):
                raw.extend(batch.messages)
                seq = batch.seq
        if not raw and seq is None:
            return []
        counts = context.get_discrete_state(self._counts).value().copy()
        if seq is not None:
            counts[0] = seq
        decoder = MidiDecoder(self._mapping)  # this update's counts only; the totals are state
        if len(raw) > self._budget:
            # A flood (a stuck controller, a feedback loop) cannot stall the
            # control loop: the oldest messages beyond the budget are dropped.
            decoder.reject("burst", len(raw) - self._budget)
            raw = raw[-self._budget:]
        events = [e for e in map(decoder.decode, raw) if e is not None]
        counts[1] += decoder.accepted
        for i, reason in enumerate(REJECT_REASONS):
            counts[2 + i] += decoder.rejected[reason]
        state.get_mutable_discrete_state(self._counts).SetFromVector(counts)
        return events


class MidiReceiver(LeafSystem, _MidiInput):
    """Counts what the controls did from their MIDI messages (a learner's sensor).

    Args:
        mapping: the :class:`MidiMapping`.
        port: an optional mido input port polled every update (a real device,
            an in-process port).
        period: s, update period.
        max_messages_per_update: messages beyond this in one update are
            dropped and counted as ``burst``.
    """

    def __init__(self, mapping: MidiMapping, port=None, period: float = 0.001,
                 max_messages_per_update: int = 256):
        LeafSystem.__init__(self)
        if not (np.isfinite(period) and period > 0):
            raise ValueError(f"period must be a finite number > 0 (s), got {period}")
        self._declare_midi_input(mapping, port, max_messages_per_update)
        self._names = mapping.names()
        self._values = self.DeclareDiscreteState(ControlCounts(mapping).values)
        self._pressed = self.DeclareDiscreteState(len(self._names))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "control_values", len(self._names),
            lambda context, out: out.SetFromVector(
                context.get_discrete_state(self._values).value()),
            prerequisites_of_calc={self.discrete_state_ticket(self._values)})

    @property
    def control_names(self) -> list[str]:
        return list(self._names)

    def control_values(self, context) -> dict[str, int]:
        values = context.get_discrete_state(self._values).value()
        return {n: int(v) for n, v in zip(self._names, values, strict=True)}

    def _update(self, context, state):
        events = self._events(context, state)
        if not events:
            return
        counts = ControlCounts(self._mapping, context.get_discrete_state(self._values).value(),
                               context.get_discrete_state(self._pressed).value())
        for event in events:
            counts.add(event)
        values, pressed = counts.values, counts.pressed
        state.get_mutable_discrete_state(self._values).SetFromVector(values)
        state.get_mutable_discrete_state(self._pressed).SetFromVector(pressed)


class MidiHandControl(LeafSystem, _MidiInput):
    """MIDI faders, knobs and a mode button -> the hand's position command.

    **Joint mode** (0): fader ``i`` sets joint ``fader_joints[i]`` absolutely,
    ``value / 127`` across the joint's command range; knob ``i`` moves joint
    ``knob_joints[i]`` by ``radians_per_tick`` per tick.
    **Synergy mode** (1): fader ``i < k`` sets synergy amplitude ``i`` across
    the amplitude range of the synergies' training data; the target is
    ``synergies.amplitudes_to_command(a)``; knobs are not used.

    A press of ``mode_button`` toggles the mode. On a switch the target
    becomes the current command (nothing jumps) and the faders are sent to
    the values that command has in the new mode (``control_change`` messages
    to ``feedback_port`` and on the ``feedback`` output): motorised faders
    move there, so the next touch starts from where the hand is. At the
    simulator's initialization the faders are sent to the initial command the
    same way.

    The command moves towards the target by at most ``max_joint_velocity *
    period`` per update (the rate limit) and stays within the hand's command
    limits. It drives the station's ``hand.position``, in simulation or on
    the CAN hand (``hardware=True``) alike.

    Args:
        hand: ``"shadow"`` or ``"barrett"``.
        mapping: the :class:`MidiMapping` (faders, knobs, the mode button).
        synergies: optional :class:`~handle_drake.grasp.synergies.Synergies`
            over the hand's command joints (synergy mode needs them).
        fader_joints / knob_joints: command joint names per fader / knob, in
            the mapping's fader / knob order (``None`` entries or a shorter
            list leave controls unused). Defaults for the Shadow hand:
            :data:`DEFAULT_FADER_JOINTS`, :data:`DEFAULT_KNOB_JOINTS`; for the
            Barrett hand: spread and the three fingers on faders 1-4.
        initial_command: (nu,) rad; default zeros within limits.
        port / feedback_port: optional mido input / output ports.
        mode: the initial mode (0 joint, 1 synergy).
        max_joint_velocity: rad/s (> 0). period: s (> 0).
        radians_per_tick: rad per knob tick (> 0).
        coupling_ratio: the hand's J1/J2 ratio (command limits).
    """

    def __init__(self, hand: str, mapping: MidiMapping, synergies=None,
                 fader_joints=None, knob_joints=None, initial_command=None,
                 port=None, feedback_port=None, mode: int = JOINT_MODE,
                 max_joint_velocity: float = 2.0, period: float = 0.005,
                 radians_per_tick: float = np.pi / 48, mode_button: str = "mode",
                 coupling_ratio: float | None = None, max_messages_per_update: int = 256):
        LeafSystem.__init__(self)

        spec = get_hand_spec(hand)
        self._spec = spec
        for name, value in (("max_joint_velocity", max_joint_velocity), ("period", period),
                            ("radians_per_tick", radians_per_tick)):
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if mode not in (JOINT_MODE, SYNERGY_MODE):
            raise ValueError(f"mode: expected 0 (joint) or 1 (synergy), got {mode!r}")
        self._declare_midi_input(mapping, port, max_messages_per_update)
        if feedback_port is not None and not hasattr(feedback_port, "send"):
            raise TypeError("feedback_port must be a mido output port, got "
                            f"{type(feedback_port).__name__}")
        self._feedback_port = feedback_port
        names = list(spec.actuated_joint_names)
        nu = len(names)
        self._lower, self._upper = actuated_position_limits(spec, coupling_ratio)
        self._faders = mapping.names("fader")
        self._knobs = mapping.names("knob")
        if fader_joints is None:
            fader_joints = DEFAULT_FADER_JOINTS if hand == "shadow" else tuple(names)
        if knob_joints is None:
            knob_joints = DEFAULT_KNOB_JOINTS if hand == "shadow" else ()
        self._fader_joint = self._joint_indices("fader_joints", fader_joints, self._faders, names)
        self._knob_joint = self._joint_indices("knob_joints", knob_joints, self._knobs, names)
        mapping.control(mode_button)
        self._mode_button = mode_button
        self._synergies = None
        if synergies is not None:
            if tuple(synergies.synergy_joint_names) != tuple(names):
                raise ValueError(
                    f"synergies must be fitted over the {nu} command joints of the "
                    f"{spec.name} hand in command order, got {synergies.synergy_joint_names}")
            lo, hi = synergies.amplitude_bounds()
            k = min(synergies.k, len(self._faders))
            self._synergies, self._amp_lo, self._amp_hi = synergies, lo[:k], hi[:k]
        if mode == SYNERGY_MODE and self._synergies is None:
            raise ValueError("synergy mode needs synergies")
        self._max_step = float(max_joint_velocity) * float(period)
        self._radians_per_tick = float(radians_per_tick)
        if initial_command is None:
            initial_command = np.zeros(nu)
        initial = np.asarray(initial_command, dtype=float)
        if initial.shape != (nu,) or not np.isfinite(initial).all():
            raise ValueError(f"initial_command: expected {nu} finite values, got {initial.shape}")
        initial = np.clip(initial, self._lower, self._upper)

        self._command = self.DeclareDiscreteState(initial)
        self._target = self.DeclareDiscreteState(initial)
        self._fader_values = self.DeclareDiscreteState(self._fader_levels(initial, mode))
        self._mode = self.DeclareDiscreteState([float(mode)])
        self._feedback = self.DeclareAbstractState(_batch_value())
        self.DeclareInitializationUnrestrictedUpdateEvent(self._initialize)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self._position = self.DeclareVectorOutputPort(
            "position", nu,
            lambda context, out: out.SetFromVector(
                context.get_discrete_state(self._command).value()),
            prerequisites_of_calc={self.discrete_state_ticket(self._command)})
        self.DeclareVectorOutputPort(
            "mode", 1,
            lambda context, out: out.SetFromVector(context.get_discrete_state(self._mode).value()),
            prerequisites_of_calc={self.discrete_state_ticket(self._mode)})
        self.DeclareAbstractOutputPort(
            "feedback", _batch_value,
            lambda context, out: out.set_value(
                context.get_abstract_state(int(self._feedback)).get_value()),
            prerequisites_of_calc={self.abstract_state_ticket(self._feedback)})

    @staticmethod
    def _joint_indices(field, joints, controls, names):
        joints = list(joints)
        if len(joints) > len(controls):
            raise ValueError(f"{field}: expected at most {len(controls)} joints (one per "
                             f"control), got {len(joints)}")
        out = []
        for joint in joints:
            if joint is None:
                out.append(-1)
            elif joint not in names:
                raise ValueError(f"{field}: {joint!r} is not a command joint; expected one of "
                                 f"{names}")
            else:
                out.append(names.index(joint))
        return out + [-1] * (len(controls) - len(out))

    # ---- accessors --------------------------------------------------------------
    def get_position_output_port(self):
        return self._position

    def get_mode(self, context) -> int:
        return int(context.get_discrete_state(self._mode).value()[0])

    def set_command(self, context, command) -> None:
        """Sets command and target (e.g. to the measured position at start-up)."""
        command = np.asarray(command, dtype=float)
        if command.shape != (self._spec.num_actuated,) or not np.isfinite(command).all():
            raise ValueError(f"command: expected {self._spec.num_actuated} finite values, "
                             f"got {command.shape}")
        command = np.clip(command, self._lower, self._upper)
        context.get_mutable_discrete_state(self._command).SetFromVector(command)
        context.get_mutable_discrete_state(self._target).SetFromVector(command)
        context.get_mutable_discrete_state(self._fader_values).SetFromVector(
            self._fader_levels(command, self.get_mode(context)))

    def fader_targets(self, fader_values) -> np.ndarray:
        """The joint-mode target of fader values (nan where a joint has no fader)."""
        out = np.full(self._spec.num_actuated, np.nan)
        for i, j in enumerate(self._fader_joint):
            if j >= 0:
                span = self._upper[j] - self._lower[j]
                out[j] = self._lower[j] + fader_values[i] / 127.0 * span
        return out

    # ---- the maps ----------------------------------------------------------------
    def _fader_levels(self, command, mode) -> np.ndarray:
        """7-bit fader values that represent ``command`` in ``mode`` (the feedback)."""
        values = np.zeros(len(self._faders))
        if mode == JOINT_MODE:
            for i, j in enumerate(self._fader_joint):
                if j >= 0:
                    span = self._upper[j] - self._lower[j]
                    values[i] = (command[j] - self._lower[j]) / span * 127.0
        elif self._synergies is not None:
            a = self._synergies.positions_to_amplitudes(command)[: len(self._amp_lo)]
            values[: len(a)] = (a - self._amp_lo) / (self._amp_hi - self._amp_lo) * 127.0
        return np.clip(np.round(values), 0, 127)

    def _synergy_target(self, fader_values) -> np.ndarray:
        k = len(self._amp_lo)
        a = np.zeros(self._synergies.k)
        a[:k] = self._amp_lo + fader_values[:k] / 127.0 * (self._amp_hi - self._amp_lo)
        return self._synergies.amplitudes_to_command(a)

    # ---- update --------------------------------------------------------------------
    def _send_feedback(self, context, state, fader_values) -> None:
        """Sends the faders to ``fader_values`` (feedback port and ``feedback`` output)."""
        feedback = [control_message(self._mapping.control(name), int(v))
                    for name, v in zip(self._faders, fader_values, strict=True)]
        if self._feedback_port is not None:
            for message in feedback:
                self._feedback_port.send(message)
        previous = context.get_abstract_state(int(self._feedback)).get_value()
        state.get_mutable_abstract_state(int(self._feedback)).set_value(
            MidiBatch(previous.seq + 1, tuple(feedback)))

    def _initialize(self, context, state):
        # Motorised faders (or Meshcat sliders) start where the command is, so
        # the first touch of a fader moves its joint from there, not from
        # wherever the fader was left.
        self._send_feedback(context, state,
                            context.get_discrete_state(self._fader_values).value())

    def _update(self, context, state):
        events = self._events(context, state)
        command = context.get_discrete_state(self._command).value()
        target = context.get_discrete_state(self._target).value()
        if not events and np.array_equal(command, target):
            return  # nothing to do: the state stays as it is
        command, target = command.copy(), target.copy()
        faders = context.get_discrete_state(self._fader_values).value().copy()
        mode = self.get_mode(context)
        switched = False
        for event in events:
            if event.kind == "fader":
                i = self._faders.index(event.name)
                faders[i] = event.value
                if mode == JOINT_MODE:
                    j = self._fader_joint[i]
                    if j >= 0:
                        target[j] = self.fader_targets(faders)[j]
                else:
                    target = self._synergy_target(faders)
            elif event.kind == "knob" and mode == JOINT_MODE:
                j = self._knob_joint[self._knobs.index(event.name)]
                if j >= 0:
                    target[j] += event.value * self._radians_per_tick
            elif event.name == self._mode_button and event.value:
                new_mode = SYNERGY_MODE if mode == JOINT_MODE else JOINT_MODE
                if new_mode == SYNERGY_MODE and self._synergies is None:
                    continue  # no synergies: the button does nothing
                mode = new_mode
                target = command.copy()
                faders = self._fader_levels(command, mode)
                switched = True
        target = np.clip(target, self._lower, self._upper)
        step = np.clip(target - command, -self._max_step, self._max_step)
        state.get_mutable_discrete_state(self._command).SetFromVector(command + step)
        state.get_mutable_discrete_state(self._target).SetFromVector(target)
        state.get_mutable_discrete_state(self._fader_values).SetFromVector(faders)
        state.get_mutable_discrete_state(self._mode).SetFromVector([float(mode)])
        if switched:
            self._send_feedback(context, state, faders)
