"""The proxy's TCP client: a background thread that keeps a connection to the server.

The simulator never waits on the network: :meth:`CanHandClient.send_command`
writes the command straight to the (non-blocking) socket when it takes the
whole message, and otherwise stores it as the newest command for the thread
(a newer one replaces it); :meth:`CanHandClient.latest` returns the newest
hand state. Both only take locks. Writing from the caller's thread saves a
thread wake-up per command on the latency path. The thread connects, says
HELLO, streams STATE messages in, writes what the socket could not take at
once, and on any error (or a server that stops reading for
``connect_timeout``) closes the socket and tries again every
``reconnect_interval`` seconds.
"""

from __future__ import annotations

import collections
import logging
import select
import socket
import threading
import time

import numpy as np

from handle_drake.devices.can_hand import protocol as P
from handle_drake.devices.can_hand.bus import use_realtime_priority
from handle_drake.devices.can_hand.layout import HandLayout

__all__ = ["DISCONNECTED", "CONNECTED", "STREAMING", "CanHandClient"]

log = logging.getLogger(__name__)

#: Connection states (the driver's ``connection_state`` output).
DISCONNECTED, CONNECTED, STREAMING = 0, 1, 2


class CanHandClient:
    """Keeps a TCP connection to a CAN bus server (see module docstring).

    Args:
        layout: the hand (its kind and sizes are checked in the handshake).
        host, port: the server.
        connect_timeout: s, one connect + handshake attempt.
        reconnect_interval: s, between attempts.
        status_timeout: s, without a STATE for this long the connection
            counts as CONNECTED (no hand data) rather than STREAMING.
        record_latency: keep round-trip times (command sent -> STATE with
            ``seq_ack`` >= its seq) in :attr:`latencies`.
        realtime_priority: 0 or 1..99: the I/O thread runs under SCHED_FIFO
            (:func:`~handle_drake.devices.can_hand.bus.use_realtime_priority`).
    """

    def __init__(self, layout: HandLayout, host: str = "127.0.0.1", port: int = 47800, *,
                 connect_timeout: float = 0.5, reconnect_interval: float = 0.2,
                 status_timeout: float = 0.1, record_latency: bool = False,
                 realtime_priority: int = 0):
        if not isinstance(layout, HandLayout):
            raise TypeError(f"layout: expected a HandLayout, got {type(layout).__name__}")
        self.layout = layout
        self.host, self.port = host, int(port)
        self.connect_timeout = float(connect_timeout)
        self.reconnect_interval = float(reconnect_interval)
        self.status_timeout = float(status_timeout)
        self._info = P.HandInfo(layout.kind, layout.nq, layout.nu, layout.num_tactile)
        self._lock = threading.Lock()
        # Socket writes (caller and thread): the session socket, its unsent bytes.
        self._send_lock = threading.Lock()
        self._session_sock = None
        self._out = bytearray()
        self._out_since = 0.0
        self._stats_pending = False
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._thread = None
        self._sock = None
        self._connected = False
        self._state: P.StateMessage | None = None
        self._state_time = -np.inf
        self._command = None  # (seq, q) not yet sent
        self._seq = 0
        self._stats_waiters: list = []
        self.counters = collections.Counter()
        self.last_error = ""
        self.record_latency = record_latency
        self.realtime_priority = int(realtime_priority)
        self._sent_times: collections.OrderedDict[int, float] = collections.OrderedDict()
        self.latencies: collections.deque[float] = collections.deque(maxlen=200_000)

    # -- life cycle ------------------------------------------------------------
    def start(self) -> CanHandClient:
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="can-hand-client", daemon=True)
            self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._wake()
        sock = self._sock
        if sock is not None:  # interrupts a handshake waiting on a silent server
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        for sock in (self._wake_r, self._wake_w):
            sock.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()

    # -- the simulator's side (non-blocking) -----------------------------------------
    def send_command(self, q) -> int:
        """Queues ``q`` (nu, rad) to be sent; a newer command replaces an unsent one.

        Returns the command's sequence number. Never blocks on the network.
        """
        q = np.asarray(q, dtype=float)
        if q.shape != (self.layout.nu,):
            raise ValueError(f"command: expected {self.layout.nu} values, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError(f"command: expected finite values, got {q.tolist()}")
        with self._lock:
            self._seq += 1
            self._command = (self._seq, q.copy())
            seq = self._seq
        if not self._send_now():
            self._wake()
        return seq

    def _send_now(self) -> bool:
        """Writes the pending command from the caller's thread; False: the thread must."""
        with self._send_lock:
            sock = self._session_sock
            if sock is None or self._out:
                return False
            with self._lock:
                command, self._command = self._command, None
            if command is None:
                return True
            data = P.pack_command(*command)
            try:
                sent = sock.send(data)  # non-blocking during a session
            except OSError:  # full (BlockingIOError) or broken: the thread deals with it
                sent = 0
            if sent == 0:
                with self._lock:
                    if self._command is None:  # unless a newer command replaced it
                        self._command = command
                return False
            if sent < len(data):
                self._out += data[sent:]
                self._out_since = time.monotonic()
            self._note_sent(command[0])
            return sent == len(data)

    def _note_sent(self, seq: int) -> None:
        """Counts a command written to the socket (called under _send_lock)."""
        self.counters["commands_sent"] += 1
        if self.record_latency:
            with self._lock:
                self._sent_times[seq] = time.perf_counter()
                while len(self._sent_times) > 10_000:
                    self._sent_times.popitem(last=False)

    def latest(self) -> tuple[P.StateMessage | None, float]:
        """The newest STATE (None before the first) and its receive time (monotonic s)."""
        with self._lock:
            return self._state, self._state_time

    @property
    def connection_state(self) -> int:
        """DISCONNECTED (0), CONNECTED without fresh hand data (1) or STREAMING (2)."""
        with self._lock:
            if not self._connected:
                return DISCONNECTED
            fresh = time.monotonic() - self._state_time <= self.status_timeout
            return STREAMING if fresh else CONNECTED

    def wait_for_state(self, timeout: float, state: int = STREAMING) -> bool:
        """Polls until :attr:`connection_state` reaches ``state`` (for tests and tools)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.connection_state >= state:
                return True
            time.sleep(0.005)
        return self.connection_state >= state

    def request_stats(self, timeout: float = 1.0) -> dict:
        """The server's counters (blocks up to ``timeout``; not for the control loop)."""
        waiter = {"event": threading.Event(), "value": None}
        with self._lock:
            self._stats_waiters.append(waiter)
        self._wake()
        if not waiter["event"].wait(timeout):
            with self._lock:
                if waiter in self._stats_waiters:
                    self._stats_waiters.remove(waiter)
            raise TimeoutError(f"no STATS from {self.host}:{self.port} within {timeout} s")
        return waiter["value"]

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"\0")
        except OSError:
            pass

    # -- the I/O thread --------------------------------------------------------------
    def _loop(self) -> None:

        use_realtime_priority(self.realtime_priority)
        while not self._stop.is_set():
            sock = None
            try:
                sock = self._connect()
                self._session(sock)
            except (OSError, P.ProtocolError, P.PayloadError, ConnectionError) as error:
                self.last_error = f"{type(error).__name__}: {error}"
            finally:
                self._sock = None
                if sock is not None:
                    sock.close()
                with self._lock:
                    was_connected = self._connected
                    self._connected = False
                if was_connected and not self._stop.is_set():
                    self.counters["disconnects"] += 1
                    log.warning("lost the CAN bus server at %s:%d (%s)", self.host, self.port,
                                self.last_error)
            self._stop.wait(self.reconnect_interval)

    def _connect(self) -> socket.socket:
        self.counters["connect_attempts"] += 1
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        self._sock = sock
        if self._stop.is_set():
            sock.close()
            raise ConnectionError("client closed")
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(P.pack_hello(self._info))
            reader = P.FrameReader()
            deadline = time.monotonic() + self.connect_timeout
            while True:
                sock.settimeout(max(1e-3, deadline - time.monotonic()))
                data = sock.recv(65536)
                if not data:
                    raise ConnectionError("server closed the connection during the handshake")
                messages = reader.feed(data)
                if messages:
                    break
            message_type, payload = messages[0]
            if message_type == P.ERROR:
                raise ConnectionError(f"server refused: {payload.decode(errors='replace')}")
            if message_type != P.WELCOME or P.unpack_hello(payload) != self._info:
                raise ConnectionError("unexpected handshake reply")
            sock.settimeout(self.connect_timeout)  # bounds sendall on a stuck peer
            self._reader = reader
            for message_type, payload in messages[1:]:
                self._on_message(message_type, payload)
        except BaseException:
            self._sock = None
            sock.close()
            raise
        with self._lock:
            self._connected = True
        self.counters["connects"] += 1
        return sock

    def _session(self, sock: socket.socket) -> None:
        sock.setblocking(False)
        with self._send_lock:
            self._out.clear()
            self._stats_pending = False
            self._session_sock = sock
        try:
            while not self._stop.is_set():
                writing = [sock] if self._out else []
                readable, _, _ = select.select([sock, self._wake_r], writing, [], 0.05)
                if self._wake_r in readable:
                    try:
                        while self._wake_r.recv(4096):
                            pass
                    except OSError:
                        pass
                if sock in readable:
                    try:
                        data = sock.recv(65536)
                    except (BlockingIOError, InterruptedError):
                        data = None
                    if data == b"":
                        raise ConnectionError("server closed the connection")
                    if data:
                        for message_type, payload in self._reader.feed(data):
                            self._on_message(message_type, payload)
                self._flush(sock)
        finally:
            with self._send_lock:
                self._session_sock = None
                self._out.clear()

    def _flush(self, sock: socket.socket) -> None:
        """Queues the pending command and a STATS request, writes what the socket takes."""
        with self._send_lock:
            if not self._out:
                with self._lock:
                    command, self._command = self._command, None
                    want_stats = bool(self._stats_waiters) and not self._stats_pending
                if command is not None:
                    self._out += P.pack_command(*command)
                    self._note_sent(command[0])
                if want_stats:
                    self._out += P.pack(P.STATS_REQ)
                    self._stats_pending = True
                self._out_since = time.monotonic()
            if self._out:
                try:
                    del self._out[:sock.send(self._out)]
                except (BlockingIOError, InterruptedError):
                    pass
            if self._out and time.monotonic() - self._out_since > self.connect_timeout:
                raise ConnectionError(
                    f"server stopped reading for {self.connect_timeout} s")

    def _on_message(self, message_type: int, payload: bytes) -> None:
        if message_type == P.STATE:
            state = P.unpack_state(payload, self._info)
            now = time.monotonic()
            with self._lock:
                self._state, self._state_time = state, now
            self.counters["states_received"] += 1
            if self.record_latency and self._sent_times:
                t = time.perf_counter()
                with self._lock:
                    while self._sent_times:
                        seq = next(iter(self._sent_times))
                        if seq > state.seq_ack:
                            break
                        self.latencies.append(t - self._sent_times.pop(seq))
        elif message_type == P.STATS:
            value = P.unpack_stats(payload)
            with self._lock:
                waiters, self._stats_waiters = self._stats_waiters, []
            self._stats_pending = False
            for waiter in waiters:
                waiter["value"] = value
                waiter["event"].set()
        elif message_type == P.ERROR:
            self.counters["server_errors"] += 1
            self.last_error = payload.decode(errors="replace")
            log.warning("CAN bus server: %s", self.last_error)
        else:
            self.counters["unexpected_messages"] += 1
