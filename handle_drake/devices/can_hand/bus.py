"""Opening a python-can bus from a :class:`BusConfig` (the thin transport).

- ``virtual``: python-can's in-process bus (all ends in one process).
- ``udp_multicast``: frames as UDP multicast datagrams, across processes on
  one host (loopback, TTL 1). A socket also receives its own frames, so every
  node ignores the ids it sends itself (:class:`FrameSource` drops them in the
  kernel, or before decoding them). python-can (4.x) offers only the
  group, port and hop limit: its socket is bound to ``("", port)`` (every
  interface, so also unicast datagrams sent to any local address at that
  port, and, with Linux's default ``IP_MULTICAST_ALL``, other groups'
  traffic on that port) and joins the group on ``INADDR_ANY``. For an IPv4
  group we therefore replace that socket with one bound to ``(group, port)``
  (only datagrams addressed to the group), joined and sending on
  ``BusConfig.multicast_interface`` (127.0.0.1 by default: the bus never
  leaves the host), TTL 1 and ``IP_MULTICAST_ALL`` off. ``multicast_interface
  = ""`` keeps python-can's socket (any interface); IPv6 groups keep it too
  (with a warning).
- ``socketcan``: a Linux CAN interface (``can0``, or ``vcan0`` for a virtual
  kernel bus); needs the interface to exist, and for the fd frame format an
  FD-capable one (MTU 72).

The bus is opened able to receive CAN FD frames whenever the interface can,
also for the classic layout: a frame of the wrong format then reaches the
node and is rejected and counted instead of vanishing inside python-can.
"""

from __future__ import annotations

import ctypes
import logging
import os
import select
import socket
import struct
import time

import can
import msgpack

from handle_drake.devices.can_hand.config import BusConfig
from handle_drake.devices.can_hand.messages import MalformedFrameError

__all__ = ["open_bus", "receive", "FrameSource", "check_frame", "ErrorLog",
           "socketcan_available", "socketcan_fd_capable", "use_realtime_priority"]

log = logging.getLogger(__name__)

_CANFD_MTU = 72  # struct canfd_frame; a CAN 2.0 interface has MTU 16
_IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)  # Linux only
_SO_TIMESTAMPNS = 35  # what python-can's udp_multicast recv expects when it asked for it


def socketcan_available(channel: str) -> bool:
    """True when the Linux network interface ``channel`` exists (e.g. ``vcan0``)."""
    return os.path.exists(f"/sys/class/net/{channel}")


def socketcan_fd_capable(channel: str) -> bool:
    """True when the SocketCAN interface ``channel`` carries CAN FD frames (MTU 72)."""
    try:
        with open(f"/sys/class/net/{channel}/mtu") as f:
            return int(f.read()) >= _CANFD_MTU
    except (OSError, ValueError):
        return False


def use_realtime_priority(priority: int) -> bool:
    """Runs the calling thread under ``SCHED_FIFO`` at ``priority`` (1..99); 0 does nothing.

    A 1 kHz loop on a shared machine waits for the CPU behind every runnable
    normal-priority process; a real-time thread preempts them (the kernel's
    RT throttling still leaves them 5 % of each second). Needs CAP_SYS_NICE
    or an ``rtprio`` limit (``ulimit -r``); returns False with a warning when
    the OS refuses, and the thread carries on at normal priority.
    """
    if priority == 0:
        return False
    try:
        # On Linux, pid 0 is the calling thread, not the whole process.
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as error:
        log.warning("cannot use real-time priority %d (%s); running at normal priority",
                    priority, error)
        return False
    return True


def open_bus(config: BusConfig) -> can.BusABC:
    """A python-can bus for ``config``; ValueError naming the problem otherwise."""
    config.validate()
    if config.interface == "virtual":
        # The virtual bus carries any frame; ``protocol`` only labels it.
        protocol = can.CanProtocol.CAN_FD if config.frame_format == "fd" else can.CanProtocol.CAN_20
        return can.Bus(interface="virtual", channel=config.channel, receive_own_messages=False,
                       protocol=protocol)
    if config.interface == "udp_multicast":
        bus = can.Bus(interface="udp_multicast", channel=config.channel, port=config.port,
                      hop_limit=1, fd=True)
        if config.multicast_interface:
            try:
                _scope_multicast(bus, config)
            except BaseException:
                bus.shutdown()
                raise
        return bus
    if not socketcan_available(config.channel):
        raise ValueError(
            f"socketcan: no network interface {config.channel!r}; create it first "
            f"(e.g. `ip link add dev {config.channel} type vcan && "
            f"ip link set {config.channel} mtu 72 && ip link set up {config.channel}`)"
        )
    fd = socketcan_fd_capable(config.channel)
    if config.frame_format == "fd" and not fd:
        raise ValueError(
            f"socketcan: {config.channel!r} is not CAN FD capable (MTU < 72); use "
            f"--frame-format classic, or `ip link set {config.channel} mtu 72` (vcan) / "
            f"`ip link set {config.channel} type can bitrate 1000000 dbitrate 5000000 fd on`")
    return can.Bus(interface="socketcan", channel=config.channel, fd=fd)


def _scope_multicast(bus: can.BusABC, config: BusConfig) -> None:
    """Replaces python-can's any-interface socket by one scoped to the group and interface.

    See the module docstring. Uses python-can's private ``_multicast._socket``
    (checked; with another python-can the bus stays unscoped, with a warning).
    """
    multicast = getattr(bus, "_multicast", None)
    old = getattr(multicast, "_socket", None)
    if not isinstance(old, socket.socket) or old.family != socket.AF_INET:
        log.warning("udp_multicast: cannot scope the bus socket to %s (IPv6 group or another "
                    "python-can); it listens on every interface", config.multicast_interface)
        return
    group = socket.inet_aton(config.channel)
    interface = socket.inet_aton(config.multicast_interface)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 1))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, interface)
        if getattr(multicast, "timestamp_nanosecond", False):
            sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
        try:
            sock.setsockopt(socket.IPPROTO_IP, _IP_MULTICAST_ALL, 0)
        except OSError:  # not Linux: binding to the group already filters
            pass
        sock.bind((config.channel, config.port))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group + interface)
    except OSError as error:
        sock.close()
        raise ValueError(f"multicast_interface: cannot join {config.channel} on "
                         f"{config.multicast_interface}: {error.strerror}") from None
    multicast._socket = sock
    multicast._last_send_timeout = None
    bus._handle_drake_scoped = True  # FrameSource may read this socket directly
    old.close()


#: ``receive`` outcomes other than a frame or a timeout (the counter names);
#: :class:`FrameSource` adds ``ECHO``: a frame with one of the reader's own ids.
GARBAGE, BUS_ERROR, ECHO = "garbage_frames", "bus_rx_errors", "echo_frames"


def receive(bus: can.BusABC, timeout: float) -> tuple[can.Message | None, str | None]:
    """One ``bus.recv``: ``(message, None)``, ``(None, None)`` on timeout, or ``(None, why)``.

    ``why`` is :data:`GARBAGE` for a datagram python-can could not decode
    (udp_multicast raises ``CanOperationError("could not unpack ...")`` for
    it; any other exception python-can lets out while decoding counts the
    same) and :data:`BUS_ERROR` for a failing socket or interface. Garbage
    costs only its decoding: callers go on at once, and wait (back off) only
    on bus errors.
    """
    try:
        return bus.recv(timeout), None
    except can.CanOperationError as error:
        if isinstance(error.__cause__, OSError) or "unpack" not in str(error):
            return None, BUS_ERROR
        return None, GARBAGE
    except (can.CanError, OSError):
        return None, BUS_ERROR
    except Exception:  # python-can decoding a hostile datagram  # noqa: BLE001
        return None, GARBAGE


class FrameSource:
    """Reads a bus a wake-up at a time: every frame already waiting, in one call.

    ``read(timeout, limit)`` waits up to ``timeout`` s for the first frame and
    returns it with every frame that is already waiting behind it (at most
    ``limit``), as :func:`receive` pairs ``(message, None)`` / ``(None, why)``;
    ``[]`` on timeout. A bus failure ends the batch with ``(None, BUS_ERROR)``.

    On a udp_multicast bus whose socket :func:`open_bus` scoped (the default),
    it reads that socket itself, one wait per wake-up and one ``recvmsg`` per
    datagram (python-can's ``recv`` costs a ``select`` per frame, and, for the
    frames already waiting, ~18 us against ~5 us here), and decodes each
    datagram as python-can's ``unpack_message`` does (msgpack, then a checked
    ``can.Message`` with the kernel receive stamp). A frame whose id is in
    ``echo_ids`` (a standard, non-remote, non-error frame: what this node
    sends itself, which a multicast bus loops back to it) is returned as
    ``(None, ECHO)`` before any ``can.Message`` is built; on Linux a socket
    filter (``kernel_filter``, see :func:`_attach_echo_filter`) drops such
    datagrams in the kernel already, so they do not even wake the reader
    (and are not counted). Any other bus is
    read through :func:`receive` (``bus.recv``), waiting once and then
    taking the waiting frames with a zero timeout; it has no echoes.
    """

    def __init__(self, bus: can.BusABC, echo_ids=frozenset(), kernel_filter: bool = True):
        self._bus = bus
        self._echo_ids = frozenset(echo_ids)
        self._socket = None
        self.kernel_filter = False
        sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
        if getattr(bus, "_handle_drake_scoped", False) and isinstance(sock, socket.socket):
            # A second handle on the bus socket with its own (zero) timeout: python-can's
            # send() sets a timeout on the original, which would make a Python recv poll.
            self._socket = sock.dup()
            self._socket.setblocking(False)
            self._ancillary = socket.CMSG_SPACE(struct.calcsize("@ll"))
            self._max_buffer = int(getattr(bus._multicast, "max_buffer", 4096))
            if kernel_filter and self._echo_ids:
                self.kernel_filter = _attach_echo_filter(self._socket, self._echo_ids)

    @property
    def direct(self) -> bool:
        """True when it reads the udp_multicast socket itself (echoes dropped undecoded)."""
        return self._socket is not None

    def fileno(self) -> int | None:
        """The socket :meth:`read` waits on when :attr:`direct` (to wait on it with other
        sockets, then ``read(0.0)``); None otherwise."""
        return None if self._socket is None else self._socket.fileno()

    def close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def read(self, timeout: float, limit: int = 64) -> list:
        if self._socket is None:
            return self._read_bus(timeout, limit)
        return self._read_socket(timeout, limit)

    def _read_bus(self, timeout: float, limit: int) -> list:
        out = []
        wait = timeout
        while len(out) < limit:
            message, why = receive(self._bus, wait)
            if message is None and why is None:
                break
            out.append((message, why))
            if why == BUS_ERROR:
                break
            wait = 0.0
        return out

    def _read_socket(self, timeout: float, limit: int) -> list:
        sock, out = self._socket, []
        waited = False
        while len(out) < limit:
            try:
                data, ancillary, _, _ = sock.recvmsg(self._max_buffer, self._ancillary,
                                                     socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                if out or waited or timeout <= 0:
                    break
                try:  # nothing was waiting: one wait for the first frame
                    ready, _, _ = select.select([sock], [], [], timeout)
                except (OSError, ValueError):
                    out.append((None, BUS_ERROR))
                    break
                if not ready:
                    break
                waited = True
                continue
            except OSError:
                out.append((None, BUS_ERROR))
                break
            out.append(self._decode(data, ancillary))
        return out

    def _decode(self, data: bytes, ancillary) -> tuple:
        try:
            fields = msgpack.unpackb(data, raw=False)
            if (type(fields) is dict and fields.get("arbitration_id") in self._echo_ids
                    and type(fields["arbitration_id"]) is int
                    and fields.get("is_extended_id") is False
                    and fields.get("is_remote_frame") is False
                    and fields.get("is_error_frame") is False):
                return None, ECHO
            fields["timestamp"] = _stamp(ancillary)
            return can.Message(check=True, **fields), None
        except Exception:  # what python-can's recv reports as "could not unpack"  # noqa: BLE001
            return None, GARBAGE


# Classic BPF (linux/filter.h): opcodes and the socket option.
_BPF_LDB, _BPF_LDH, _BPF_LDW = 0x30, 0x28, 0x20  # BPF_LD | B/H/W | BPF_ABS
_BPF_LEN = 0x80  # BPF_LD | BPF_W | BPF_LEN: the packet's length
_BPF_JEQ, _BPF_JGE, _BPF_RET = 0x15, 0x35, 0x06  # BPF_JMP | JEQ/JGE | BPF_K, BPF_RET | BPF_K
_SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
_UDP_HEADER = 8  # a UDP socket's filter sees the datagram from its UDP header on


def _echo_filter_program(echo_ids) -> list[tuple[int, int, int, int]]:
    """A socket filter that drops python-can udp_multicast frames with one of ``echo_ids``.

    python-can packs a frame as a msgpack map in a fixed key order (``pack_message``):
    ``timestamp`` (a float64), ``arbitration_id``, ``is_extended_id``,
    ``is_remote_frame``, ``is_error_frame``, ... For a frame stamped with a float, an
    id in 0x100..0x7FF (a uint16) and the three flags False, every byte the program
    reads sits at a fixed offset; it checks the keys' first letters there too, and
    passes any datagram that does not match that shape in full (decoded in Python,
    where an own id is still caught as ECHO).
    """
    p = _UDP_HEADER
    # (offset, width, value): the map header, each key's header and first letters, the
    # id's uint16 marker and the three flags False.
    checks = [(p + 0, 1, 0x8B), (p + 1, 1, 0xA9), (p + 2, 4, int.from_bytes(b"time", "big")),
              (p + 11, 1, 0xCB), (p + 20, 1, 0xAE), (p + 21, 4, int.from_bytes(b"arbi", "big")),
              (p + 35, 1, 0xCD),
              (p + 38, 1, 0xAE), (p + 39, 4, int.from_bytes(b"is_e", "big")), (p + 53, 1, 0xC2),
              (p + 54, 1, 0xAF), (p + 55, 4, int.from_bytes(b"is_r", "big")), (p + 70, 1, 0xC2),
              (p + 71, 1, 0xAE), (p + 72, 4, int.from_bytes(b"is_e", "big")), (p + 86, 1, 0xC2)]
    ids = sorted(i for i in echo_ids if 0x100 <= i < 0x800)
    load = {1: _BPF_LDB, 2: _BPF_LDH, 4: _BPF_LDW}
    accept = 2 + 2 * len(checks) + 1 + len(ids)  # index of "ret accept"; "ret drop" follows
    program = []  # (code, jt, jf, k); a jump goes to (its index + 1 + offset)
    # Shorter datagrams pass untouched (a load past the end would end the program: drop).
    program.append((_BPF_LEN, 0, 0, 0))
    program.append((_BPF_JGE, 0, accept - len(program) - 1, p + 87))
    for offset, width, value in checks:
        program.append((load[width], 0, 0, offset))
        program.append((_BPF_JEQ, 0, accept - len(program) - 1, value))
    program.append((_BPF_LDH, 0, 0, p + 36))  # the id, big-endian
    for frame_id in ids:
        program.append((_BPF_JEQ, accept - len(program), 0, frame_id))
    program.append((_BPF_RET, 0, 0, 0xFFFFFFFF))  # accept: the whole datagram
    program.append((_BPF_RET, 0, 0, 0))  # drop
    return program


def _attach_echo_filter(sock: socket.socket, echo_ids) -> bool:
    """Attaches :func:`_echo_filter_program` to ``sock``; False where the OS has no BPF."""
    if not any(0x100 <= i < 0x800 for i in echo_ids) or os.uname().sysname != "Linux":
        return False
    program = _echo_filter_program(echo_ids)
    code = b"".join(struct.pack("HBBI", *instruction) for instruction in program)
    buffer = ctypes.create_string_buffer(code, len(code))
    fprog = struct.pack("HL", len(program), ctypes.addressof(buffer))  # struct sock_fprog
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_ATTACH_FILTER, fprog)
    except OSError as error:
        log.info("udp_multicast: no socket filter for the echoes (%s); dropped in Python", error)
        return False
    return True


def _stamp(ancillary) -> float:
    """The kernel receive time (SO_TIMESTAMPNS) of a datagram, else the time now."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= 16:
            seconds, nanoseconds = struct.unpack_from("@ll", data)
            return seconds + nanoseconds * 1e-9
    return time.time()


def check_frame(message) -> tuple[int, bytes, bool]:
    """``(arbitration_id, data, is_fd)`` of a received frame with checked types.

    A frame from udp_multicast is whatever the sender packed (python-can checks
    ranges, not types: an id ``300.5`` or a flag ``"yes"`` pass it). Raises
    :class:`~handle_drake.devices.can_hand.messages.MalformedFrameError` unless the id is
    an ``int`` of the frame's id range, the flags are ``bool`` and the data
    are at most 64 bytes.
    """

    arbitration_id = getattr(message, "arbitration_id", None)
    flags = [getattr(message, name, None) for name in
             ("is_extended_id", "is_fd", "is_error_frame", "is_remote_frame")]
    if type(arbitration_id) is not int or not 0 <= arbitration_id < (1 << 29):
        raise MalformedFrameError(
            f"arbitration_id: expected an integer in 0..2**29-1, got {_short(arbitration_id)}")
    if any(type(flag) is not bool for flag in flags):
        raise MalformedFrameError(f"frame flags: expected booleans, got {_short(flags)}")
    data = getattr(message, "data", None)
    if not isinstance(data, (bytes, bytearray)) or len(data) > 64:
        raise MalformedFrameError(f"data: expected at most 64 bytes, got {_short(data)}")
    return arbitration_id, bytes(data), flags[1]


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} chars)"


class ErrorLog:
    """Logs contained exceptions without flooding: the first ``first`` of each kind, then
    every ``every``-th (with the count). A loop that must survive any input counts every
    exception and logs through this."""

    def __init__(self, logger: logging.Logger, first: int = 5, every: int = 1000):
        self._log, self._first, self._every = logger, first, every
        self._seen: dict[str, int] = {}

    def __call__(self, kind: str, error: BaseException) -> None:
        n = self._seen.get(kind, 0) + 1
        self._seen[kind] = n
        if n <= self._first or n % self._every == 0:
            self._log.warning("%s #%d contained: %s: %s", kind, n, type(error).__name__,
                              _short(str(error), 200))
