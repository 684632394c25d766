"""Configuration of the CAN hand chain: driver (proxy), bus server, simulated firmware.

:class:`CanHandDriverConfig` is what a scenario's ``!CanHandDriver`` holds
(Drake YAML: plain fields with defaults). The server and firmware configs
mirror the ``handle-drake can-server`` / ``can-sim`` command-line options.
Units are SI (s, Hz, rad, rad/s, N).

No ``from __future__ import annotations`` here: ``CanHandDriverConfig`` is
read by Drake's ``yaml_load_typed`` (as the scenario's ``!CanHandDriver``),
which needs real types in the dataclass fields.
"""

import dataclasses as dc
import ipaddress
import math

__all__ = [
    "driver_config",
    "BUS_INTERFACES",
    "FRAME_FORMATS",
    "FEEDBACK_MODES",
    "DEFAULT_FEEDBACK",
    "DEFAULT_SERVER_PORT",
    "DEFAULT_MULTICAST_GROUP",
    "DEFAULT_MULTICAST_PORT",
    "BusConfig",
    "CanHandDriverConfig",
    "CanServerConfig",
    "CanFirmwareConfig",
]

BUS_INTERFACES = ("virtual", "udp_multicast", "socketcan")
FRAME_FORMATS = ("classic", "fd")
#: When the simulated hand sends the feedback that acknowledges a setpoint (CanFirmwareConfig).
FEEDBACK_MODES = ("cycle", "on_request")
#: Each hand's own behaviour: the Shadow's controller publishes once per control cycle; the
#: Barrett's pucks answer the host's request (libbarrett drives the loop, see can_hand.firmware).
DEFAULT_FEEDBACK = {"shadow": "cycle", "barrett": "on_request"}
DEFAULT_SERVER_PORT = 47800
DEFAULT_MULTICAST_GROUP = "239.74.163.2"  # python-can's IPv4 default group
DEFAULT_MULTICAST_PORT = 43113


def _positive(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")


def _nonnegative(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value >= 0):
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")


def _priority(value) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 99:
        raise ValueError(f"realtime_priority: expected an integer in 0..99 (0: normal "
                         f"scheduling), got {value!r}")


def _port(name: str, value, allow_zero: bool = True) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not (
            (0 if allow_zero else 1) <= value <= 65535):
        low = 0 if allow_zero else 1
        raise ValueError(f"{name}: expected an integer port in {low}..65535, got {value!r}")


@dc.dataclass
class CanHandDriverConfig:
    """The proxy driver: where the CAN bus server is and how often to talk to it.

    Attributes:
        host, port: the server's TCP address (loopback by default).
        hand_kind: "" to use the station's hand; otherwise it must equal it.
        period: s, the driver's update period (command out, state in).
        connect_timeout: s, for one TCP connect + handshake attempt.
        reconnect_interval: s, wait between attempts while disconnected.
        status_timeout: s, a connection without STATE for this long counts as
            "connected, no hand data".
        realtime_priority: 0 (normal scheduling) or 1..99: the client's
            receive thread runs under SCHED_FIFO at this priority (see
            :func:`handle_drake.devices.can_hand.bus.use_realtime_priority`).
    """

    host: str = "127.0.0.1"
    port: int = DEFAULT_SERVER_PORT
    hand_kind: str = ""
    period: float = 0.002
    connect_timeout: float = 0.5
    reconnect_interval: float = 0.2
    status_timeout: float = 0.1
    realtime_priority: int = 0

    def validate(self) -> None:
        if not isinstance(self.host, str) or not self.host:
            raise ValueError(f"host: expected a host name or address, got {self.host!r}")
        _priority(self.realtime_priority)
        _port("port", self.port, allow_zero=False)
        if self.hand_kind not in ("", "shadow", "barrett"):
            raise ValueError(
                f"hand_kind: expected '', 'shadow' or 'barrett', got {self.hand_kind!r}")
        for name in ("period", "connect_timeout", "reconnect_interval", "status_timeout"):
            _positive(name, getattr(self, name))


@dc.dataclass
class BusConfig:
    """A python-can bus: ``interface`` in virtual | udp_multicast | socketcan.

    ``channel``: the virtual bus name, the multicast group address, or the
    SocketCAN interface (``can0``, ``vcan0``). ``port``: the UDP port of the
    multicast bus (ignored otherwise).

    ``frame_format``: the hand's message layout on this bus, "fd" (CAN FD,
    ``hand_fd.dbc``: one frame per command and one per hand cycle) or
    "classic" (8-byte CAN 2.0 frames, ``hand.dbc``: 6 + 9 frames per Shadow
    cycle, 2 + 4 per Barrett cycle). The server and the hand must agree. FD is
    the default: the classic layout cannot carry a 1 kHz Shadow cycle on a
    real 1 Mbit/s bus (1.6-2.0 ms of bus time per cycle) and costs 15 frames
    of per-frame work per cycle on the simulated buses. The virtual and
    udp_multicast buses carry FD frames; a SocketCAN interface needs an FD
    MTU (``ip link set can0 mtu 72``, and for a real controller
    ``type can bitrate 1000000 dbitrate 5000000 fd on``). Use "classic" for a
    hand or adapter that speaks only CAN 2.0.

    ``multicast_interface``: the local IPv4 address of the interface a
    udp_multicast bus joins and sends on (default 127.0.0.1: the bus stays on
    this host); "" keeps python-can's socket, bound to every interface (see
    :mod:`handle_drake.devices.can_hand.bus`).
    """

    interface: str = "virtual"
    channel: str = "handle_drake"
    port: int = DEFAULT_MULTICAST_PORT
    frame_format: str = "fd"
    multicast_interface: str = "127.0.0.1"

    def validate(self) -> None:
        if self.interface not in BUS_INTERFACES:
            raise ValueError(f"bus: expected one of {list(BUS_INTERFACES)}, got {self.interface!r}")
        if self.frame_format not in FRAME_FORMATS:
            raise ValueError(f"frame_format: expected one of {list(FRAME_FORMATS)}, "
                             f"got {self.frame_format!r}")
        if not isinstance(self.channel, str) or not self.channel:
            raise ValueError(f"channel: expected a non-empty string, got {self.channel!r}")
        _port("bus port", self.port, allow_zero=False)
        if self.interface == "udp_multicast":
            try:
                address = ipaddress.ip_address(self.channel)
            except ValueError:
                raise ValueError(
                    f"channel: udp_multicast needs a multicast group address, got {self.channel!r}"
                ) from None
            if not address.is_multicast:
                raise ValueError(f"channel: {self.channel} is not a multicast address")
            if not isinstance(self.multicast_interface, str):
                raise ValueError(f"multicast_interface: expected an IPv4 address or '', got "
                                 f"{self.multicast_interface!r}")
            if self.multicast_interface:
                try:
                    ipaddress.IPv4Address(self.multicast_interface)
                except ValueError:
                    raise ValueError(f"multicast_interface: expected an IPv4 address of a "
                                     f"local interface or '', got "
                                     f"{self.multicast_interface[:60]!r}") from None


@dc.dataclass
class CanServerConfig:
    """The CAN bus server.

    Attributes:
        host, port: TCP listen address; loopback unless told otherwise
            (port 0 picks a free port).
        hand_kind, coupling_ratio: the hand on the bus.
        bus: the CAN bus.
        max_setpoint_rate: Hz, most commits sent per second (newer commands
            replace pending ones).
        rate_tolerance: slots (of ``1 / max_setpoint_rate`` s) of arrival
            jitter the rate limit passes without holding a command (GCRA's
            tolerance): any window of ``T`` seconds holds at most
            ``1 + rate_tolerance + max_setpoint_rate * T`` commits. One slot
            lets a client at exactly the limit whose command came up to a
            slot late be followed at once by its next, on-time command (a
            burst of two commits); half a slot held 1.4 % of a 1 kHz
            client's commands on a loaded 2-core machine (measured), each
            then replaced by the next and acknowledged a period later.
        max_step: rad, largest change of any joint between two commits.
        watchdog: s, without a command for this long the setpoint freezes
            (the hand holds where its setpoint is).
        velocity_time_constant: s, low-pass of the finite-difference velocity.
        realtime_priority: 0 (normal scheduling) or 1..99: the bus and I/O
            threads run under SCHED_FIFO at this priority.
        max_clients: connections beyond this many are told "server full" and
            closed at once.
        hello_timeout: s, a connection that has not completed HELLO by then is
            closed (idle or half-open connections cannot pile up).
        max_client_backlog: bytes of unread output one client may hold; STATE
            messages beyond it are dropped for that client, and a reply that
            does not fit disconnects it.
        slow_client_timeout: s, a client whose backlog stays full this long
            (it stopped reading) is disconnected. A client that reads its
            STATE stream is never idle, whether it sends commands or not.
    """

    host: str = "127.0.0.1"
    port: int = DEFAULT_SERVER_PORT
    hand_kind: str = "shadow"
    coupling_ratio: float | None = None
    bus: BusConfig = dc.field(default_factory=BusConfig)
    max_setpoint_rate: float = 1000.0
    rate_tolerance: float = 1.0
    max_step: float = 0.02
    watchdog: float = 0.25
    velocity_time_constant: float = 0.01
    realtime_priority: int = 0
    max_clients: int = 32
    hello_timeout: float = 5.0
    max_client_backlog: int = 256 * 1024
    slow_client_timeout: float = 2.0

    def validate(self) -> None:
        if not isinstance(self.host, str) or not self.host:
            raise ValueError(f"host: expected a listen address, got {self.host!r}")
        for name, low, high in (("max_clients", 1, 4096),
                                ("max_client_backlog", 4096, 1 << 30)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise ValueError(f"{name}: expected an integer in {low}..{high}, got {value!r}")
        _positive("hello_timeout", self.hello_timeout)
        _positive("slow_client_timeout", self.slow_client_timeout)
        _port("port", self.port)
        if self.hand_kind not in ("shadow", "barrett"):
            raise ValueError(f"hand: expected 'shadow' or 'barrett', got {self.hand_kind!r}")
        self.bus.validate()
        for name in ("max_setpoint_rate", "max_step", "watchdog"):
            _positive(name, getattr(self, name))
        _nonnegative("velocity_time_constant", self.velocity_time_constant)
        _nonnegative("rate_tolerance", self.rate_tolerance)
        if self.rate_tolerance > 10:
            raise ValueError(f"rate_tolerance: expected at most 10 slots, got "
                             f"{self.rate_tolerance!r}")
        _priority(self.realtime_priority)


@dc.dataclass
class CanFirmwareConfig:
    """The simulated hand on the bus: joint position loops, sensors, a virtual object.

    Each actuated joint is a critically damped (``damping_ratio``) second-order
    loop of natural frequency ``natural_frequency`` (Hz) on its setpoint,
    velocity-limited to ``max_velocity`` and stopped at the joint limits;
    coupled joints follow their leader. Positions carry Gaussian noise
    (``position_noise`` rad), tactile pads ``tactile_noise`` N.

    ``object_closure`` in (0, 1] places a virtual object: each closing joint
    stops at ``lower + object_closure * (upper - lower)`` and its fingertip
    reports ``contact_stiffness`` (N/rad) times how far the setpoint presses
    past that stop. None: no object.

    ``realtime_priority`` 1..99 runs the firmware thread under SCHED_FIFO (0:
    normal scheduling).

    ``feedback``: when the feedback that acknowledges a setpoint goes out.
    "cycle": once per control cycle (``rate``), acknowledging the setpoints
    read at the cycle's start. "on_request": as soon as a setpoint is
    applied (FD: its one SETPOINT frame; classic: its SETPOINT_COMMIT; one
    reply for the newest when several were waiting), carrying the state of
    the last joint-model step; a cycle in which no setpoint came still
    publishes its own feedback. None: the hand's own
    behaviour (:data:`DEFAULT_FEEDBACK`: Barrett on_request, Shadow cycle).
    """

    hand_kind: str = "shadow"
    coupling_ratio: float | None = None
    bus: BusConfig = dc.field(default_factory=BusConfig)
    rate: float = 500.0  # Hz, control and publish rate (classic 1 Mbit/s fits ~500 Shadow cycles)
    natural_frequency: float = 5.0
    damping_ratio: float = 1.0
    max_velocity: float = 4.0
    position_noise: float = 0.0005
    tactile_noise: float = 0.005
    object_closure: float | None = None
    contact_stiffness: float = 20.0
    seed: int = 0
    realtime_priority: int = 0
    feedback: str | None = None

    def feedback_mode(self, hand_kind: str | None = None) -> str:
        """``feedback``, or the default of ``hand_kind`` (this config's hand when None)."""
        if self.feedback is not None:
            return self.feedback
        return DEFAULT_FEEDBACK[hand_kind or self.hand_kind]

    def validate(self) -> None:
        if self.hand_kind not in ("shadow", "barrett"):
            raise ValueError(f"hand: expected 'shadow' or 'barrett', got {self.hand_kind!r}")
        if self.feedback is not None and self.feedback not in FEEDBACK_MODES:
            raise ValueError(f"feedback: expected one of {list(FEEDBACK_MODES)} (or None: the "
                             f"hand's default), got {self.feedback!r}")
        self.bus.validate()
        for name in ("rate", "natural_frequency", "damping_ratio", "max_velocity",
                     "contact_stiffness"):
            _positive(name, getattr(self, name))
        _nonnegative("position_noise", self.position_noise)
        _nonnegative("tactile_noise", self.tactile_noise)
        _priority(self.realtime_priority)
        if self.object_closure is not None and not (0 < self.object_closure <= 1):
            raise ValueError(
                f"object_closure: expected a value in (0, 1], got {self.object_closure}")


def driver_config(driver) -> CanHandDriverConfig:
    """A :class:`CanHandDriverConfig` from a scenario's ``!CanHandDriver`` (same field names)."""
    if isinstance(driver, CanHandDriverConfig):
        values = dc.asdict(driver)
    elif dc.is_dataclass(driver):
        values = {f.name: getattr(driver, f.name) for f in dc.fields(driver)}
    else:
        raise TypeError(f"driver: expected a CanHandDriver dataclass, got {type(driver).__name__}")
    known = {f.name for f in dc.fields(CanHandDriverConfig)}
    config = CanHandDriverConfig(**{k: v for k, v in values.items() if k in known})
    config.validate()
    return config
