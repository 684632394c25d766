"""A simulated CAN-bus hand: joint position loops, noisy sensors, a virtual object.

It speaks the hand's side of the configured layout (``config.bus.frame_format``).
FD (``hand_fd.dbc``): it applies each ``<HAND>_SETPOINT`` frame on receipt.
Classic (``hand.dbc``): it applies SETPOINT frames on each SETPOINT_COMMIT.
The feedback (FD: one ``<HAND>_FEEDBACK`` frame; classic: POSITION, TACTILE,
then STATUS) acknowledges the last applied setpoint (``SEQ_ACK``). With the
bus server it lets the whole chain run without hardware
(``handle-drake can-sim``).

When the feedback goes out (``CanFirmwareConfig.feedback``):

- ``cycle`` (the Shadow's default): the firmware reads the bus once per
  control cycle (at the cycle's start, like a firmware reading its receive
  FIFO), steps the joint model and publishes one feedback, ``rate`` times a
  second. A setpoint waits for the next cycle to be acknowledged (0 to one
  period).
- ``on_request`` (the Barrett's default): the firmware blocks on the bus
  until a frame comes or a control cycle without a request ends, and answers
  an applied setpoint at once (when several frames were already waiting,
  after taking them all: one reply acknowledging the newest). That is how the
  real hand works: its pucks do not stream; the host drives the loop.
  libbarrett's ``Hand::update`` (src/products/hand.cpp;
  ``Hand::updatePosition`` in older versions) sends one group get-property
  request for ``P`` and then receives each puck's reply
  (``PuckGroup::sendGetPropertyRequest`` / ``receiveGetPropertyReply``,
  include/barrett/detail/puck_group-inl.h), right after its setpoints went
  out with ``Hand::setPositionCommand``. Here the setpoint frame is also the
  request. The reply carries the sample of the last joint-model step
  (positions and tactile with their noise, stamped with that step's time):
  a puck answers ``P`` with the encoder count its control loop last read,
  and a setpoint just received has not moved the motor yet. A cycle in
  which no setpoint came publishes its own feedback, so a host that sends
  nothing (the server before the first command, after its watchdog hold)
  still sees the hand. The joint model runs on a fixed grid of ``1 / rate``:
  the steps due while the firmware slept are taken when it wakes, before the
  new setpoint applies, so a cycle with a request costs one wake-up, not two
  (the simulated hand shares the host's cores; the real one does not).

Joint model (each actuated joint, see :class:`CanFirmwareConfig`): a
second-order position loop ``q'' = wn^2 (q_sp - q) - 2 zeta wn q'`` with
``wn = 2 pi natural_frequency``, velocity saturated at ``max_velocity``,
stopped at the command limits; coupled joints follow their leader
(``q_f = ratio * q_l``). A critically damped loop follows a ramp of slope
``s`` with a constant lag of ``2 zeta s / wn`` rad (``2 zeta / wn`` seconds),
which the tests check against.
"""

from __future__ import annotations

import collections
import logging
import threading
import time

import can
import numpy as np

from handle_drake.devices.can_hand.bus import (
    ECHO,
    GARBAGE,
    ErrorLog,
    FrameSource,
    check_frame,
    open_bus,
    use_realtime_priority,
)
from handle_drake.devices.can_hand.config import CanFirmwareConfig
from handle_drake.devices.can_hand.layout import HandLayout, hand_layout
from handle_drake.devices.can_hand.messages import (
    STATE_OK,
    ForeignFrameError,
    FrameFormatError,
    MalformedFrameError,
    make_codec,
)

__all__ = ["HandJointModel", "SimulatedHandFirmware"]

log = logging.getLogger(__name__)

_MAX_SUBSTEP = 0.001  # s; keeps the explicit integration stable for wn * dt << 1
_MAX_FRAMES_PER_CYCLE = 4096  # a flood of frames cannot stop the cycle from publishing
_MAX_WAIT = 0.05  # s, longest single wait on the bus (stop() stays prompt at low rates)
_FRAME, _TIMEOUT, _FAILED = "frame", "timeout", "failed"  # what one _receive got


class HandJointModel:
    """The hand's joint dynamics and sensors without any bus (pure, steppable).

    Attributes ``q``, ``v`` (nu, actuated order) and ``setpoint`` are public
    so tests can read the true state.
    """

    def __init__(self, layout: HandLayout, config: CanFirmwareConfig, initial_position=None):
        self.layout = layout
        self.config = config
        nu = layout.nu
        q0 = np.zeros(nu) if initial_position is None else np.asarray(initial_position, float)
        if q0.shape != (nu,):
            raise ValueError(f"initial_position: expected {nu} values, got shape {q0.shape}")
        self.lower, self.upper = layout.command_lower, layout.command_upper
        self.q = np.clip(q0, self.lower, self.upper)
        self.v = np.zeros(nu)
        self.setpoint = self.q.copy()
        self._wn = 2 * np.pi * config.natural_frequency
        self._rng = np.random.default_rng(config.seed)
        index = {n: i for i, n in enumerate(layout.actuated_joint_names)}
        self._pads = [np.array([index[n] for n in pad], dtype=int) for pad in layout.closing_joints]
        # Per-cycle work as matrix products: pad sums (nt x nu, 0/1) and the
        # coupling map of layout.joint_positions (nq x nu, linear: its columns).
        self._pad_matrix = np.zeros((len(self._pads), nu))
        for k, pad in enumerate(self._pads):
            self._pad_matrix[k, pad] = 1.0
        self._joint_map = np.stack([layout.joint_positions(e) for e in np.eye(nu)], axis=1)
        closing = self._pad_matrix.any(axis=0)
        if config.object_closure is None:
            self.stop = np.full(nu, np.inf)
        else:
            stop = self.lower + config.object_closure * (self.upper - self.lower)
            self.stop = np.where(closing, stop, np.inf)

    def apply(self, setpoint) -> None:
        """A new setpoint (the hand enforces its own limits too)."""
        self.setpoint = np.clip(np.asarray(setpoint, dtype=float), self.lower, self.upper)

    def step(self, dt: float) -> None:
        if not dt > 0:
            return
        n = max(1, int(np.ceil(dt / _MAX_SUBSTEP)))
        h = dt / n
        wn, zeta, vmax = self._wn, self.config.damping_ratio, self.config.max_velocity
        upper = np.minimum(self.upper, self.stop)
        for _ in range(n):
            a = wn * wn * (self.setpoint - self.q) - 2 * zeta * wn * self.v
            self.v = np.clip(self.v + h * a, -vmax, vmax)
            self.q = self.q + h * self.v
            low, high = self.q < self.lower, self.q > upper
            self.q = np.clip(self.q, self.lower, upper)
            self.v[low] = np.maximum(self.v[low], 0.0)
            self.v[high] = np.minimum(self.v[high], 0.0)

    def measured_positions(self) -> np.ndarray:
        """All joints (nq) with sensor noise."""
        q = self._joint_map @ self.q
        if self.config.position_noise > 0:
            q = q + self._rng.normal(0.0, self.config.position_noise, q.shape)
        return q

    def tactile(self) -> np.ndarray:
        """Normal force (N) on each fingertip: stiffness times setpoint past the object."""
        press = np.maximum(0.0, self.setpoint - self.stop)
        press[~np.isfinite(press)] = 0.0
        force = self.config.contact_stiffness * (self._pad_matrix @ press)
        if self.config.tactile_noise > 0:
            force = force + self._rng.normal(0.0, self.config.tactile_noise, force.shape)
        return np.maximum(force, 0.0)


class SimulatedHandFirmware:
    """Runs a :class:`HandJointModel` on a CAN bus in a background thread."""

    def __init__(self, config: CanFirmwareConfig, bus: can.BusABC | None = None,
                 layout: HandLayout | None = None, initial_position=None):
        if not isinstance(config, CanFirmwareConfig):
            raise TypeError(f"config: expected a CanFirmwareConfig, got {type(config).__name__}")
        config.validate()
        self.config = config
        self.layout = layout or hand_layout(config.hand_kind, config.coupling_ratio)
        self.codec = make_codec(self.layout, config.bus.frame_format)
        self.model = HandJointModel(self.layout, config, initial_position)
        self._assembler = self.codec.setpoint_receiver()
        self._bus = bus
        self._owns_bus = bus is None
        self._stop = threading.Event()
        self._thread = None
        self._source = None  # FrameSource, from start()
        self._lock = threading.Lock()
        self.counters = collections.Counter()
        self._seq_ack = 0
        self._counter = 0
        self._t0 = time.monotonic()
        self.silent = threading.Event()  # set: stop publishing (a test's "hand unplugged")
        self._errors = ErrorLog(log)
        self.feedback = config.feedback_mode(self.layout.kind)
        self._on_request = self.feedback == "on_request"
        self._unanswered = False  # a setpoint was applied since the last feedback
        self._period = 1.0 / config.rate  # s, the control cycle
        self._grid_start = self._t0  # on_request: the joint model's step k is at
        self._grid_index = 0  # _grid_start + k period; the last step taken
        self._last_sample = None  # (q, tactile, hand_time) of the last joint-model step

    def start(self) -> SimulatedHandFirmware:
        if self._thread is not None:
            raise RuntimeError("firmware already started")
        if self._bus is None:
            self._bus = open_bus(self.config.bus)
        self._source = FrameSource(self._bus, echo_ids=self.codec.hand_to_host_ids)
        self._thread = threading.Thread(target=self._loop, name="can-sim", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        if self._source is not None:
            self._source.close()
            self._source = None
        if self._owns_bus and self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def is_alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _handle(self, message: can.Message) -> bool:
        """Processes one received frame; True when it applied a setpoint."""
        self.counters["frames_rx"] += 1
        try:
            arbitration_id, data, is_fd = check_frame(message)
        except MalformedFrameError:
            self.counters["malformed_frames"] += 1
            return False
        if arbitration_id in self.codec.hand_to_host_ids:
            self.counters["echo_frames"] += 1  # our own feedback looped back
            return False
        if message.is_error_frame or message.is_remote_frame or message.is_extended_id:
            self.counters["foreign_frames"] += 1
            return False
        try:
            applied = self._assembler.feed(arbitration_id, data, is_fd)
        except ForeignFrameError:
            self.counters["foreign_frames"] += 1
            return False
        except FrameFormatError:
            self.counters["wrong_format_frames"] += 1
            return False
        except MalformedFrameError:
            self.counters["malformed_frames"] += 1
            return False
        self.counters["rejected_commits"] = self._assembler.rejected_commits
        if applied is None:
            return False
        seq, setpoint = applied
        with self._lock:
            self.model.apply(setpoint)
            self._seq_ack = seq
        self.counters["commits_applied"] += 1
        return True

    def _receive(self, timeout: float, limit: int) -> tuple[str, int]:
        """Handles one wake-up's frames: waits up to ``timeout`` s for the first, then takes
        every frame already waiting behind it (at most ``limit``).

        Returns ``(outcome, frames)``: ``_FRAME`` (frames or garbage datagrams came),
        ``_TIMEOUT`` or ``_FAILED`` (the bus failed: the caller must not retry at once).
        """
        batch = self._source.read(timeout, max(1, limit))
        if not batch:
            return _TIMEOUT, 0
        if self._on_request:  # the steps due before these frames' setpoints apply
            self._catch_up(time.monotonic())
        counters, n = self.counters, 0
        for message, why in batch:
            if why == ECHO or why == GARBAGE:  # our own feedback looped back; undecodable
                counters["frames_rx"] += 1
                counters[why] += 1
                n += 1
                continue
            if why is not None:
                counters[why] += 1
                self._errors(why, RuntimeError("firmware bus receive failed"))
                return _FAILED, n
            n += 1
            try:
                if self._handle(message):
                    self._unanswered = True
            except Exception as error:  # one frame never stops the hand
                counters["frame_errors"] += 1
                self._errors("frame_errors", error)
        return _FRAME, n

    def _drain(self, limit: int) -> int:
        """Handles the frames already waiting (at most ``limit``); returns how many."""
        n = 0
        while n < limit:
            got, k = self._receive(0.0, limit - n)
            n += k
            if got != _FRAME:
                break
        return n

    def _sample(self, now: float) -> None:
        """Reads the sensors after a joint-model step (the feedback's values until the next)."""
        with self._lock:
            self._last_sample = (self.model.measured_positions(), self.model.tactile(),
                                 now - self._t0)

    def _publish(self, reply: bool = False) -> None:
        """Sends one feedback: the last step's sample and the last applied setpoint's seq
        (``reply``: answering a request, counted apart on request)."""
        self._unanswered = False
        if self.silent.is_set():
            return
        q, tactile, hand_time = self._last_sample
        frames = self.codec.encode_feedback(q, tactile, self._seq_ack, self._counter, STATE_OK,
                                            hand_time)
        self._counter = (self._counter + 1) % 256
        fd = self.codec.is_fd
        # Every frame built first, then sent back to back: a receiver woken by the first
        # finds the rest already waiting (one wake-up for the cycle, not one per frame).
        messages = [can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False,
                                is_fd=fd, bitrate_switch=fd) for arbitration_id, data in frames]
        try:
            for message in messages:
                self._bus.send(message, timeout=0.01)
            self.counters["cycles"] += 1
            if self._on_request:
                self.counters["feedback_replies" if reply else "feedback_idle"] += 1
        except (can.CanError, OSError) as error:
            self.counters["bus_tx_errors"] += 1
            log.warning("firmware bus send failed: %s", error)

    def _loop(self) -> None:
        use_realtime_priority(self.config.realtime_priority)
        if self._on_request:
            self._loop_on_request()
        else:
            self._loop_cycle()

    def _loop_cycle(self) -> None:
        """``feedback: cycle``: one wake-up per control cycle, like a firmware that reads
        its CAN receive FIFO at the start of each cycle: sleep to the deadline, take every
        frame that arrived meanwhile, step, publish. (Waking for each frame as well would
        double the context switches per cycle and gain nothing: the acknowledgement goes
        out with this cycle's feedback either way.)"""
        period = self._period
        last = time.monotonic()
        deadline = last + period
        self._sample(last)
        while not self._stop.is_set():
            remaining = deadline - time.monotonic()
            if remaining > 0 and self._stop.wait(remaining):
                break
            self._drain(_MAX_FRAMES_PER_CYCLE)
            if self._stop.is_set():
                break
            now = time.monotonic()
            with self._lock:
                self.model.step(min(now - last, 0.05))
            self._sample(now)
            last = now
            deadline += period
            if deadline < now - 10 * period:  # fell far behind (a stall): do not burst
                deadline = now + period
            self._publish()

    def _loop_on_request(self) -> None:
        """``feedback: on_request``: the joint model runs on a grid of ``period`` (step k at
        ``t0 + k period``), and the firmware sleeps until a frame comes or a cycle without
        a request ends. Woken by frames, it first brings the model to the last grid time
        (``_catch_up``), then applies the setpoints and answers the newest once with that
        step's sample; a cycle that ends without a request publishes its own feedback.
        Cycles with a request cost one wake-up, not two: the steps they skip are taken
        at the next wake-up, on the same grid, so the model's trajectory is the one a
        step at every deadline gives (the steps skipped are integrated in one call,
        with the same ``<= 1 ms`` substeps)."""
        period = self._period
        start = self._grid_start = time.monotonic()
        self._grid_index = 0
        self._sample(start)
        answered = -1  # the last cycle in which a setpoint was answered
        frames = 0  # frames handled in the current cycle (a flood cannot stop publishing)
        cycle_of_frames = 0
        while not self._stop.is_set():
            now = time.monotonic()
            cycle = int((now - start) // period)
            if cycle != cycle_of_frames:
                cycle_of_frames, frames = cycle, 0
            # Due without a request: the end of the first cycle not yet answered.
            due = start + ((cycle if answered < cycle else cycle + 1) + 1) * period
            if frames >= _MAX_FRAMES_PER_CYCLE:  # flooded: publish at the due time anyway
                self._stop.wait(max(0.0, due - now))
                got, n = _TIMEOUT, 0
            else:
                got, n = self._receive(min(max(0.0, due - now), _MAX_WAIT),
                                       _MAX_FRAMES_PER_CYCLE - frames)
                frames += n
            if got == _FAILED:  # no busy retry: wait out this cycle
                self._stop.wait(max(0.0, due - time.monotonic()))
            self.counters["wakeups"] += 1
            now = time.monotonic()
            if got == _FRAME and self._unanswered:
                self._publish(reply=True)  # the last grid step's sample, the newest seq
                answered = self._grid_index  # the cycle whose step the reply carries
                if not self._source.kernel_filter:  # take our looped-back reply now
                    frames += self._drain(_MAX_FRAMES_PER_CYCLE - frames)
            elif now >= due and not self._stop.is_set():
                self._catch_up(now)  # the cycle ended without a request: its own feedback
                self._publish()

    def _catch_up(self, now: float) -> None:
        """On-request mode: steps the joint model to the last grid time at or before ``now``
        (one call for the steps skipped; at most 50 ms after a stall) and samples it."""
        period = self._period
        index = int((now - self._grid_start) // period)
        steps = index - self._grid_index
        if steps <= 0:
            return
        with self._lock:
            self.model.step(min(steps * period, 0.05))
        self._grid_index = index
        self._sample(self._grid_start + index * period)
