"""The CAN bus server: TCP clients on one side, the CAN-bus hand on the other.

Two jobs:

- the bus side receives frames, every waiting one per wake-up
  (:class:`~handle_drake.devices.can_hand.bus.FrameSource`), accepts only the
  hand's feedback ids (foreign ids and malformed frames are dropped and
  counted; our own setpoint frames echoed by a multicast bus are dropped,
  in the kernel where it can), assembles one
  snapshot per hand cycle, estimates joint velocities and sends the new
  hand state to every client at once;
- the I/O side (one ``selectors`` loop) accepts clients, reads their
  commands (:mod:`~handle_drake.devices.can_hand.protocol`), sends setpoints to the
  bus and writes what a slow client could not take at once.

When the bus can be waited on in that selector (a udp_multicast bus whose
socket :class:`~handle_drake.devices.can_hand.bus.FrameSource` reads itself),
one thread does both: a command and the hand's reply are handled by the
thread that is already awake, with no second thread to wake, no lock to wait
for and no hand-over of Python's GIL between the two (measured on the Barrett
classic chain: the two threads spent up to ~100 us per cycle waiting for each
other's lock and GIL). Any other bus (python-can's ``recv``) gets a bus
thread of its own. The clients' sockets and output buffers are shared under
``_io_lock`` (never held while waiting on the selector or sending on the bus).

Setpoint policy (what a command becomes on the bus):

1. clamp the command to the joint limits (counted as ``commands_clamped``);
2. at most ``max_setpoint_rate`` commits per second, on a schedule of one
   slot per ``1 / max_setpoint_rate`` s that tolerates ``rate_tolerance``
   slots of jitter (GCRA, the ATM cell-rate rule; one slot by default): any
   window of ``T`` seconds holds at most ``1 + rate_tolerance + rate * T``
   commits, yet a client sending at exactly the limit is not delayed when
   its commands arrive up to ``rate_tolerance`` slots late (a strict minimum
   interval lets every late command push all later ones back). A command
   arriving before its slot waits, and a newer command replaces it
   (``commands_coalesced``);
3. each commit moves every joint at most ``max_step`` towards the command
   (the first step starts from the measured position);
4. watchdog: without a command for ``watchdog`` seconds the target freezes at
   the last sent setpoint, so the hand holds there instead of finishing a
   stale motion (``watchdog_holds``); the next command resumes.

Holding at the last setpoint rather than at the measured position keeps a
grasp closed: a finger stopped by an object keeps pressing.
"""

from __future__ import annotations

import collections
import errno
import logging
import selectors
import socket
import threading
import time

import can
import numpy as np

from handle_drake.devices.can_hand import protocol as P
from handle_drake.devices.can_hand.bus import (
    ECHO,
    GARBAGE,
    ErrorLog,
    FrameSource,
    check_frame,
    open_bus,
    use_realtime_priority,
)
from handle_drake.devices.can_hand.config import CanServerConfig
from handle_drake.devices.can_hand.layout import HandLayout, hand_layout
from handle_drake.devices.can_hand.messages import (
    ForeignFrameError,
    FrameFormatError,
    MalformedFrameError,
    make_codec,
)

__all__ = ["CanBusServer", "CommitSchedule", "VelocityEstimator", "clamp_command",
           "limit_setpoint"]

log = logging.getLogger(__name__)

_READ_CHUNK = 4096  # bytes read from one client per round of the I/O loop
# Kernel send buffer per client: small enough that a client that stops reading
# shows up in its (capped) output backlog within ~0.1 s of STATE at 1 kHz, instead
# of hiding megabytes in an autotuned loopback buffer.
_CLIENT_SNDBUF = 64 * 1024
# s between two rounds of the I/O loop's housekeeping (client timeouts, paused polls),
# not after every event: the loop wakes twice per hand cycle.
_HOUSEKEEPING_PERIOD = 0.01


def clamp_command(q, lower, upper) -> tuple[np.ndarray, bool]:
    """``(clip(q, lower, upper), whether anything was clipped)``."""
    q = np.asarray(q, dtype=float)
    clamped = np.clip(q, lower, upper)
    return clamped, bool(np.any(clamped != q))


def limit_setpoint(previous, target, max_step: float, lower, upper) -> np.ndarray:
    """The next setpoint: at most ``max_step`` per joint from ``previous`` towards ``target``."""
    previous = np.asarray(previous, dtype=float)
    step = np.clip(np.asarray(target, dtype=float) - previous, -max_step, max_step)
    return np.clip(previous + step, lower, upper)


def _backoff(failures: int) -> float:
    """s to wait after ``failures`` consecutive bus receive errors (1 ms doubling, <= 0.5 s)."""
    return min(0.5, 0.001 * 2 ** min(failures, 9))


class CommitSchedule:
    """GCRA rate limit: one slot per ``1 / rate`` s, ``tolerance`` slots of jitter allowed.

    :meth:`earliest` is when the next commit may go; :meth:`commit` books a
    slot. A commit that comes late does not push the schedule back beyond
    ``now``; one that comes early (within the tolerance) uses its slot ahead
    of time. Any window of ``T`` s therefore holds at most
    ``1 + tolerance + rate * T`` commits.
    """

    def __init__(self, rate: float, tolerance: float = 1.0):
        self.slot = 1.0 / rate
        self._tolerance = tolerance * self.slot
        self._next = -np.inf  # theoretical time of the next commit

    def earliest(self) -> float:
        return self._next - self._tolerance

    def commit(self, now: float) -> None:
        self._next = max(self._next, now) + self.slot


class VelocityEstimator:
    """Finite-difference joint velocity with a first-order low-pass (time constant ``tau``).

    Uses the hand's own clock (which wraps at ``wrap`` seconds: 2**32 us on
    the classic layout, 2**24 us on the FD one), so bus and scheduling jitter
    do not enter the difference quotient. ``tau = 0`` gives the raw difference.
    A repeated sample (same stamp, same positions) keeps the estimate.
    """

    def __init__(self, n: int, tau: float, wrap: float = float(1 << 32) * 1e-6):
        self._n, self._tau, self._wrap = n, float(tau), float(wrap)
        self._q = None
        self._t = None
        self.v = np.zeros(n)

    def update(self, q, t: float) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if self._q is not None:
            dt = (t - self._t) % self._wrap
            if dt == 0 and np.array_equal(q, self._q):
                # The same sample again (a hand that answers each request with its last
                # control step's reading, ``feedback: on_request``): nothing new to learn.
                return self.v.copy()
            if 0 < dt < 1.0:
                raw = (q - self._q) / dt
                alpha = dt / (self._tau + dt)
                self.v = self.v + alpha * (raw - self.v)
            else:  # a gap or a repeated stamp: restart the estimate
                self.v = np.zeros(self._n)
        self._q, self._t = q.copy(), t
        return self.v.copy()


class _Client:
    __slots__ = ("sock", "address", "reader", "out", "greeted", "closing", "writing", "since",
                 "stalled_since")

    def __init__(self, sock, address):
        self.sock, self.address = sock, address
        self.since = time.monotonic()
        self.stalled_since = None  # when its unread output first passed the cap
        self.reader = P.FrameReader()
        self.out = bytearray()
        self.greeted = False
        self.closing = False
        self.writing = False  # registered for EVENT_WRITE (output is pending)


class CanBusServer:
    """Bridges TCP clients and the CAN-bus hand; see the module docstring.

    Use as a context manager or call :meth:`start` / :meth:`stop`. ``bus``
    may be given (e.g. a virtual bus shared with a test); otherwise it is
    opened from ``config.bus`` and closed on stop.
    """

    def __init__(self, config: CanServerConfig, bus: can.BusABC | None = None,
                 layout: HandLayout | None = None):
        if not isinstance(config, CanServerConfig):
            raise TypeError(f"config: expected a CanServerConfig, got {type(config).__name__}")
        config.validate()
        self.config = config
        self.layout = layout or hand_layout(config.hand_kind, config.coupling_ratio)
        if self.layout.kind != config.hand_kind:
            raise ValueError(f"layout: expected a {config.hand_kind} hand, got {self.layout.kind}")
        self.codec = make_codec(self.layout, config.bus.frame_format)
        self._info = P.HandInfo(self.layout.kind, self.layout.nq, self.layout.nu,
                                self.layout.num_tactile)
        self._bus = bus
        self._owns_bus = bus is None
        self._lock = threading.Lock()  # counters and the newest snapshot
        self._io_lock = threading.Lock()  # clients, their output, selector registrations
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._counters = collections.Counter()
        self._listen = None
        self._source = None  # the bus thread's FrameSource
        self._wake_r = self._wake_w = None
        self._selector = None
        self._clients: list[_Client] = []
        # Written by the bus thread under the lock.
        self._snapshot = None
        # Owned by the I/O thread (the bus thread reads them for STATE flags).
        self._target = None
        self._target_seq = 0
        self._setpoint = None
        self._unsent = False
        self._reached = False  # nothing left to commit: the setpoint is the target
        self._holding = False
        self._clamped = False
        self._last_command_time = 0.0
        self._schedule = CommitSchedule(config.max_setpoint_rate, config.rate_tolerance)
        self._commit_seq = 1
        self._commit_to_client = np.zeros(65536, dtype=np.int64)
        self._assembler = self.codec.feedback_receiver()
        self._velocities = VelocityEstimator(self.layout.nq, config.velocity_time_constant,
                                             self.codec.time_wrap)
        self._errors = ErrorLog(log)
        self._accept_paused_until = 0.0  # out of file descriptors: accept again then
        self._next_housekeeping = 0.0
        # One-thread mode's bus side (see _on_bus_ready): its counts, its back-off.
        self._pending = collections.Counter()
        self._bus_failures = 0
        self._bus_paused_until = 0.0  # a failing bus socket: poll it again then
        self.one_thread = False  # set by start(): see the module docstring

    # -- life cycle ----------------------------------------------------------
    def start(self) -> CanBusServer:
        if self._threads:
            raise RuntimeError("server already started")
        listen = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            listen.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listen.bind((self.config.host, self.config.port))
            listen.listen(64)
            listen.setblocking(False)
        except OSError as error:
            listen.close()
            raise OSError(error.errno, f"cannot listen on {self.config.host}:{self.config.port}: "
                                       f"{error.strerror}") from None
        if self._bus is None:
            try:
                self._bus = open_bus(self.config.bus)
            except BaseException:
                listen.close()
                raise
        self._listen = listen
        self._source = FrameSource(self._bus, echo_ids=self.codec.host_to_hand_ids)
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._selector = selectors.DefaultSelector()
        self._selector.register(listen, selectors.EVENT_READ, "listen")
        self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._threads = [threading.Thread(target=self._io_loop, name="can-server-io",
                                          daemon=True)]
        self.one_thread = self._source.direct  # the bus is waited on with the clients
        if self.one_thread:
            self._selector.register(self._source.fileno(), selectors.EVENT_READ, "bus")
        else:
            self._threads.append(threading.Thread(target=self._bus_loop, name="can-server-bus",
                                                  daemon=True))
        for thread in self._threads:
            thread.start()
        log.info("CAN bus server for the %s hand on %s:%d, bus %s %s", self.layout.kind,
                 *self.address, self.config.bus.interface, self.config.bus.channel)
        return self

    @property
    def address(self) -> tuple[str, int]:
        """The bound ``(host, port)`` (the real port when configured as 0)."""
        if self._listen is None:
            raise RuntimeError("server not started")
        return self._listen.getsockname()[:2]

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._wake()
        for thread in self._threads:
            thread.join(timeout)
        self._threads = []
        with self._io_lock:
            for client in list(self._clients):
                self._close_client(client)
        for sock in (self._listen, self._wake_r, self._wake_w):
            if sock is not None:
                sock.close()
        self._listen = self._wake_r = self._wake_w = None
        if self._selector is not None:
            self._selector.close()
            self._selector = None
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

    def stats(self) -> dict:
        """Counters: frames, rejected frames, commands, commits, holds, clients."""
        with self._lock:
            counters = dict(self._counters)
        counters["incomplete_cycles"] = self._assembler.incomplete
        counters["clients"] = sum(1 for c in list(self._clients) if c.greeted)
        return counters

    def _count(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._counters[name] += n

    def _wake(self) -> None:
        if self._wake_w is not None:
            try:
                self._wake_w.send(b"\0")
            except OSError:  # buffer full (already awake) or closed
                pass

    # -- bus side ----------------------------------------------------------------
    def _bus_loop(self) -> None:
        """The bus thread, for a bus the I/O selector cannot wait on."""
        use_realtime_priority(self.config.realtime_priority)
        source = self._source
        pending = collections.Counter()
        failures = 0  # consecutive bus errors: the back-off grows with them
        while not self._stop.is_set():
            batch = source.read(0.05, 64)
            if not batch:
                self._merge_counts(pending)
                continue
            if self._take_frames(batch, pending):
                failures = 0
            else:
                failures += 1
                self._stop.wait(_backoff(failures))

    def _on_bus_ready(self, now: float) -> None:
        """The bus socket is readable (one-thread mode): handles the frames waiting."""
        pending = self._pending
        if self._take_frames(self._source.read(0.0, 64), pending):
            self._bus_failures = 0
        else:  # a failing socket stays readable: stop polling it for a back-off
            self._bus_failures += 1
            self._selector.unregister(self._source.fileno())
            self._bus_paused_until = now + _backoff(self._bus_failures)
        self._merge_counts(pending)

    def _take_frames(self, batch, pending: collections.Counter) -> bool:
        """Handles one wake-up's frames; False when the bus failed (the caller backs off).

        Every waiting frame comes per wake-up (FrameSource); our own setpoint frames,
        which a multicast bus loops back, come as ECHO without being decoded. Frame
        counts are kept in ``pending`` and merged under the lock once per hand cycle,
        idle wait or 64 frames, not per frame.
        """
        for message, why in batch:
            if why == GARBAGE or why == ECHO:  # costs its decoding at most, no wait
                pending["frames_rx"] += 1
                pending[why] += 1
                if pending["frames_rx"] >= 64:
                    self._merge_counts(pending)
                continue
            if why is not None:
                pending[why] += 1
                self._merge_counts(pending)
                self._errors(why, RuntimeError("bus receive failed"))
                return False
            pending["frames_rx"] += 1
            try:
                self._on_frame(message, pending)
            except Exception as error:  # one frame never takes the bus side down
                pending["frame_errors"] += 1
                self._merge_counts(pending)
                self._errors("frame_errors", error)
        return True

    def _on_frame(self, message, pending: collections.Counter) -> None:
        try:
            arbitration_id, data, is_fd = check_frame(message)
        except MalformedFrameError:
            pending["malformed_frames"] += 1
            return
        snapshot = None
        if message.is_error_frame or message.is_remote_frame or message.is_extended_id:
            pending["foreign_frames"] += 1
        elif arbitration_id in self.codec.host_to_hand_ids:
            pending["echo_frames"] += 1
        else:
            try:
                snapshot = self._assembler.feed(arbitration_id, data, is_fd)
            except ForeignFrameError:
                pending["foreign_frames"] += 1
            except FrameFormatError:
                pending["wrong_format_frames"] += 1
            except MalformedFrameError:
                pending["malformed_frames"] += 1
        if snapshot is None:
            # Also while only rejected frames arrive: the counts must show.
            if pending["frames_rx"] >= 64:
                self._merge_counts(pending)
            return
        velocity = self._velocities.update(snapshot.q, snapshot.hand_time)
        pending["hand_cycles"] += 1
        with self._lock:
            self._snapshot = snapshot
            self._counters.update(pending)
        pending.clear()
        self._broadcast_state(snapshot, velocity)
        if self._setpoint is None and self._target is not None:
            self._wake()  # a first command waits for the measured position

    def _merge_counts(self, pending: collections.Counter) -> None:
        if pending:
            with self._lock:
                self._counters.update(pending)
            pending.clear()

    def _send_frames(self, frames) -> bool:
        fd = self.codec.is_fd
        # Built first, then sent back to back: the hand woken by the first frame finds the
        # commit already waiting (one wake-up per command, not one per frame).
        messages = [can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False,
                                is_fd=fd, bitrate_switch=fd) for arbitration_id, data in frames]
        try:
            for message in messages:
                self._bus.send(message, timeout=0.01)
        except (can.CanError, OSError) as error:
            self._count("bus_tx_errors")
            log.warning("bus send failed: %s", error)
            return False
        self._count("frames_tx", len(frames))
        return True

    # -- TCP side ------------------------------------------------------------------
    def _io_loop(self) -> None:
        use_realtime_priority(self.config.realtime_priority)
        failures = 0
        while not self._stop.is_set():
            try:
                events = self._selector.select(self._select_timeout(time.monotonic()))
            except (OSError, ValueError) as error:
                if self._stop.is_set():
                    return
                self._count("io_errors")
                self._errors("io_errors", error)
                self._stop.wait(0.01)
                continue
            try:
                # Each event takes the I/O lock only around what the bus thread shares
                # (the client list, output buffers, selector registrations): parsing and
                # applying a command run outside it, so a STATE the bus thread is sending
                # does not wait for them (nor for this thread's wake-up after a syscall).
                # Commands before the bus (one-thread mode): a commit sent first sets the
                # hand to work while this thread turns the bus's frames into STATE.
                bus_ready = False
                for key, mask in events:
                    if key.data == "bus":
                        bus_ready = True
                    else:
                        self._on_event(key, mask)
                now = time.monotonic()
                self._service_setpoint(now)
                if bus_ready:
                    self._on_bus_ready(now)
                if now >= self._next_housekeeping:  # its timeouts are 0.2 s and more
                    self._next_housekeeping = now + _HOUSEKEEPING_PERIOD
                    with self._io_lock:
                        self._housekeeping(now)
                failures = 0
            except Exception as error:  # the I/O thread outlives any bug a client triggers
                failures += 1
                self._count("io_errors")
                self._errors("io_errors", error)
                self._stop.wait(min(0.5, 0.001 * 2 ** min(failures, 9)))

    def _on_event(self, key, mask) -> None:
        if key.data == "listen":
            with self._io_lock:
                self._accept()
        elif key.data == "wake":
            try:
                while self._wake_r.recv(4096):
                    pass
            except OSError:
                pass
        else:
            client = key.data
            if client not in self._clients:  # closed by the bus thread meanwhile
                return
            try:
                if mask & selectors.EVENT_READ:
                    self._read(client)
                if mask & selectors.EVENT_WRITE:
                    with self._io_lock:
                        if not client.closing and client in self._clients:
                            self._flush(client)
            except Exception as error:  # one client's trouble is that client's alone
                self._count("client_errors")
                self._errors("client_errors", error)
                with self._io_lock:
                    if client in self._clients:
                        self._close_client(client)

    def _housekeeping(self, now: float) -> None:
        """Closes clients that never said HELLO or stopped reading; resumes accepting."""
        if self._accept_paused_until and now >= self._accept_paused_until:
            self._accept_paused_until = 0.0
            self._selector.register(self._listen, selectors.EVENT_READ, "listen")
        if self._bus_paused_until and now >= self._bus_paused_until:
            self._bus_paused_until = 0.0
            self._selector.register(self._source.fileno(), selectors.EVENT_READ, "bus")
        config = self.config
        for client in list(self._clients):
            if not client.greeted and now - client.since > config.hello_timeout:
                self._count("idle_clients_closed")
                self._close_client(client)
            elif client.stalled_since is not None and \
                    now - client.stalled_since > config.slow_client_timeout:
                self._count("slow_clients_closed")
                self._close_client(client)

    def _accept(self) -> None:
        for _ in range(16):  # a burst of connections waits for the next round
            try:
                sock, address = self._listen.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as error:
                self._count("accept_errors")
                self._errors("accept_errors", error)
                if error.errno in (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM):
                    # Out of descriptors: stop polling the listen socket (it would stay
                    # readable and spin) until the housekeeping has had a chance to free some.
                    self._selector.unregister(self._listen)
                    self._accept_paused_until = time.monotonic() + 0.2
                return
            if len(self._clients) >= self.config.max_clients:
                self._count("clients_refused")
                try:
                    sock.setblocking(False)
                    sock.send(P.pack(P.ERROR, f"server full: {self.config.max_clients} clients "
                                              f"connected (max_clients)".encode()))
                except OSError:
                    pass
                sock.close()
                continue
            try:
                sock.setblocking(False)
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, _CLIENT_SNDBUF)
                client = _Client(sock, address)
                self._selector.register(sock, selectors.EVENT_READ, client)
            except (OSError, ValueError) as error:
                self._count("accept_errors")
                self._errors("accept_errors", error)
                sock.close()
                continue
            self._clients.append(client)
            self._count("connections")

    def _close_client(self, client: _Client) -> None:
        if client in self._clients:
            self._clients.remove(client)
        try:
            self._selector.unregister(client.sock)
        except (KeyError, ValueError, AttributeError):
            pass
        client.sock.close()

    def _read(self, client: _Client) -> None:
        """Reads and handles one client's messages (I/O thread; takes the I/O lock itself)."""
        with self._io_lock:  # the socket is only closed under the lock
            if client.closing or client not in self._clients:
                return
            try:
                # A bounded read: a flooding client gets one slice of work per round.
                data = client.sock.recv(_READ_CHUNK)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._close_client(client)
                return
        try:
            messages = client.reader.feed(data)  # the reader is this thread's alone
        except P.ProtocolError as error:
            self._count("malformed_messages")
            self._reject(client, f"protocol error: {error}")
            return
        stats_wanted = False
        for message_type, payload in messages:
            if client.closing or client not in self._clients:
                return
            if message_type == P.STATS_REQ and client.greeted:
                stats_wanted = True  # one reply answers every request of this read
                continue
            self._handle(client, message_type, payload)
        if stats_wanted:
            stats = P.pack_stats(self.stats())
            with self._io_lock:
                if client in self._clients and not client.closing:
                    self._reply(client, stats)

    def _reply(self, client: _Client, data: bytes) -> None:
        """Queues a reply (under the I/O lock); a client whose unread output passed the cap
        is disconnected."""
        if len(client.out) + len(data) > self.config.max_client_backlog:
            self._count("slow_clients_closed")
            self._close_client(client)
            return
        client.out += data
        self._flush(client)

    def _reject(self, client: _Client, text: str) -> None:
        """Sends ERROR and closes once it is written (takes the I/O lock)."""
        with self._io_lock:
            client.out += P.pack(P.ERROR, text.encode()[:P.MAX_PAYLOAD])
            client.closing = True
            self._flush(client)
            if client in self._clients:
                self._close_client(client)

    def _reply_error(self, client: _Client, text: str) -> None:
        """Queues an ERROR and keeps the client (takes the I/O lock)."""
        with self._io_lock:
            self._reply(client, P.pack(P.ERROR, text.encode()[:1024]))

    def _handle(self, client: _Client, message_type: int, payload: bytes) -> None:
        """One message (I/O thread, without the I/O lock: replies take it)."""
        if message_type == P.HELLO:
            try:
                info = P.unpack_hello(payload)
            except P.PayloadError as error:
                self._count("malformed_messages")
                self._reject(client, str(error))
                return
            if info != self._info:
                self._count("rejected_clients")
                self._reject(client, f"this server drives a {self._info.kind} hand (nq "
                                     f"{self._info.nq}, nu {self._info.nu}, tactile "
                                     f"{self._info.nt}); client expected {info.kind} (nq "
                                     f"{info.nq}, nu {info.nu}, tactile {info.nt})")
                return
            with self._io_lock:  # WELCOME is queued before the bus thread's first STATE
                client.greeted = True
                self._reply(client, P.pack_hello(self._info, P.WELCOME))
        elif not client.greeted:
            self._count("malformed_messages")
            self._reject(client, "expected HELLO first")
        elif message_type == P.COMMAND:
            try:
                seq, q = P.unpack_command(payload, self.layout.nu)
            except P.PayloadError as error:
                self._count("commands_rejected")
                self._reply_error(client, str(error))
                return
            self._on_command(seq, q, time.monotonic())
        else:
            self._count("malformed_messages")
            self._reply_error(client, f"unexpected message type {message_type}")

    def _flush(self, client: _Client) -> None:
        """Writes what the socket takes now; the rest waits for EVENT_WRITE (under _io_lock)."""
        if client.out:
            try:
                sent = client.sock.send(client.out)
                del client.out[:sent]
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:
                self._close_client(client)
                return
        writing = bool(client.out)
        if writing != client.writing and client in self._clients:
            client.writing = writing
            events = selectors.EVENT_READ | (selectors.EVENT_WRITE if writing else 0)
            self._selector.modify(client.sock, events, client)

    def _select_timeout(self, now: float) -> float:
        timeout = 0.05
        if self._target is not None and not self._holding:
            timeout = min(timeout, max(0.0, self._last_command_time + self.config.watchdog - now))
            if self._unsent or not self._reached:
                next_commit = self._schedule.earliest()
                timeout = min(timeout, max(0.0, next_commit - now))
        return timeout

    # -- setpoints ---------------------------------------------------------------------
    def _on_command(self, seq: int, q: np.ndarray, now: float) -> None:
        q, clamped = clamp_command(q, self.layout.command_lower, self.layout.command_upper)
        self._count("commands_rx")
        if clamped:
            self._count("commands_clamped")
        if self._unsent:
            self._count("commands_coalesced")
        self._clamped = clamped
        self._target, self._target_seq = q, seq
        self._reached = self._setpoint is not None and np.array_equal(self._setpoint, q)
        self._unsent = True
        self._holding = False
        self._last_command_time = now

    def _measured_command(self):
        with self._lock:
            snapshot = self._snapshot
        return None if snapshot is None else self.layout.actuated_positions(snapshot.q)

    def _service_setpoint(self, now: float) -> None:
        if self._target is None or self._holding:
            return
        if now - self._last_command_time > self.config.watchdog:
            self._holding = True
            self._count("watchdog_holds")
            self._unsent = False
            if self._setpoint is None:
                self._target = None
            else:
                self._target = self._setpoint.copy()
            self._reached = self._setpoint is not None
            return
        base = self._setpoint if self._setpoint is not None else self._measured_command()
        if base is None:  # no hand state yet: the first step needs the measured position
            return
        if not self._unsent and self._reached:
            return
        if now < self._schedule.earliest():
            return  # too early for the next slot; the selector wakes us then
        setpoint = limit_setpoint(base, self._target, self.config.max_step,
                                  self.layout.command_lower, self.layout.command_upper)
        # Mapped before sending: the hand may acknowledge before send returns.
        self._commit_to_client[self._commit_seq] = self._target_seq
        if not self._send_frames(self.codec.encode_setpoints(setpoint, self._commit_seq)):
            return
        self._commit_seq = (self._commit_seq + 1) % 65536
        self._setpoint = setpoint
        self._reached = np.array_equal(setpoint, self._target)
        self._unsent = False
        self._schedule.commit(now)
        self._count("commits_tx")

    def _broadcast_state(self, snapshot, velocity) -> None:
        """Sends one hand cycle to every greeted client (bus thread)."""
        # The I/O thread replaces (never mutates) these arrays: read each once.
        setpoint, target = self._setpoint, self._target
        if setpoint is None:
            setpoint = self.layout.actuated_positions(snapshot.q)
            rate_limited = False
        else:
            rate_limited = target is not None and not np.array_equal(setpoint, target)
        flags = ((P.FLAG_HOLDING if self._holding else 0)
                 | (P.FLAG_CLAMPED if self._clamped else 0)
                 | (P.FLAG_RATE_LIMITED if rate_limited else 0))
        message = P.pack_state(P.StateMessage(
            seq_ack=int(self._commit_to_client[snapshot.seq_ack]), hand_state=snapshot.state,
            flags=flags, hand_time=snapshot.hand_time, q=snapshot.q, v=velocity,
            tactile=snapshot.tactile, setpoint=setpoint,
        ))
        sent = dropped = 0
        backlog = self.config.max_client_backlog
        with self._io_lock:
            for client in list(self._clients):
                if not client.greeted or client.closing:
                    continue
                if len(client.out) + len(message) > backlog:
                    dropped += 1  # the I/O thread closes it after slow_client_timeout
                    if client.stalled_since is None:
                        client.stalled_since = time.monotonic()
                    continue
                client.stalled_since = None
                client.out += message
                sent += 1
                self._flush(client)
        with self._lock:
            self._counters["states_sent"] += sent
            if dropped:
                self._counters["states_dropped"] += dropped

    def serve_until(self, stop_event: threading.Event) -> None:
        """Blocks until ``stop_event`` is set (the CLI's main loop)."""
        while not stop_event.wait(0.2):
            if not all(t.is_alive() for t in self._threads):
                raise RuntimeError("a server thread died; see the log")
