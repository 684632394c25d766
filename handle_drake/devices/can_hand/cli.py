"""``handle-drake can-server`` and ``handle-drake can-sim``.

Examples (two shells, one multicast CAN bus on this host)::

    handle-drake can-sim --hand shadow --bus udp_multicast --channel 239.74.163.2
    handle-drake can-server --listen 127.0.0.1:47800 --bus udp_multicast --channel 239.74.163.2

``--frame-format fd|classic`` (default fd) picks the hand's message layout
(``hand_fd.dbc`` or ``hand.dbc``); the server and the hand must use the same.
Both print one ``ready`` line on stdout once running (the server's line holds
the bound address, useful with port 0) and stop cleanly on SIGINT or
SIGTERM. Also runnable as ``python -m handle_drake.devices.can_hand.cli``.
"""

from __future__ import annotations

import argparse
import gc
import ipaddress
import logging
import signal
import sys
import threading

from handle_drake.base.arguments import non_empty
from handle_drake.devices.can_hand.config import (
    BUS_INTERFACES,
    DEFAULT_FEEDBACK,
    DEFAULT_MULTICAST_GROUP,
    DEFAULT_MULTICAST_PORT,
    DEFAULT_SERVER_PORT,
    FEEDBACK_MODES,
    FRAME_FORMATS,
    BusConfig,
    CanFirmwareConfig,
    CanServerConfig,
)

__all__ = ["register", "main", "parse_listen"]

_DEFAULT_CHANNEL = {"virtual": "handle_drake", "udp_multicast": DEFAULT_MULTICAST_GROUP,
                    "socketcan": "can0"}


def parse_listen(text: str) -> tuple[str, int]:
    """``"HOST:PORT"`` -> ``(host, port)``; ValueError naming the problem."""
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise ValueError(f"--listen: expected HOST:PORT, got {text!r}")
    try:
        number = int(port)
    except ValueError:
        raise ValueError(f"--listen: port must be an integer, got {port!r}") from None
    if not 0 <= number <= 65535:
        raise ValueError(f"--listen: port must be in 0..65535, got {number}")
    return host.strip("[]"), number


def _add_bus_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hand", choices=("shadow", "barrett"), default="shadow",
                   help="the hand on the bus (its joints and CAN messages; default shadow)")
    p.add_argument("--coupling-ratio", type=float, default=None,
                   help="Shadow xFJ1 = ratio * xFJ2 (1.0 C6 hand, 1.1 C5 hand)")
    p.add_argument("--bus", choices=BUS_INTERFACES, default="udp_multicast",
                   help="python-can interface (virtual works inside one process only)")
    p.add_argument("--channel", type=non_empty, default=None,
                   help="virtual bus name, multicast group, or SocketCAN interface "
                        f"(defaults: {_DEFAULT_CHANNEL})")
    p.add_argument("--bus-port", type=int, default=DEFAULT_MULTICAST_PORT,
                   help="UDP port of the udp_multicast bus")
    p.add_argument("--multicast-interface", default="127.0.0.1",
                   help="IPv4 address of the interface the udp_multicast bus joins and sends "
                        "on (default loopback: the bus stays on this host); '' = any interface")
    p.add_argument("--frame-format", choices=FRAME_FORMATS, default="fd",
                   help="the hand's message layout: fd (CAN FD, one frame per command and "
                        "per hand cycle) or classic (8-byte CAN 2.0 frames)")
    p.add_argument("--rt-priority", type=int, default=0,
                   help="1..99: run the bus threads under SCHED_FIFO at this priority "
                        "(needs CAP_SYS_NICE or an rtprio limit); 0: normal scheduling")
    p.add_argument("--log-level", default="WARNING",
                   help="Python logging level (DEBUG, INFO, WARNING, ERROR; default WARNING)")


def register(subparsers) -> None:
    """Adds ``can-server`` and ``can-sim`` to an argparse sub-parser collection."""
    p = subparsers.add_parser("can-server", help="bridge TCP clients and the CAN-bus hand")
    p.add_argument("--listen", default=f"127.0.0.1:{DEFAULT_SERVER_PORT}",
                   help="HOST:PORT to accept clients on (loopback by default; port 0 = any)")
    _add_bus_arguments(p)
    p.add_argument("--max-rate", type=float, default=1000.0, help="Hz, most setpoint commits/s")
    p.add_argument("--rate-tolerance", type=float, default=1.0,
                   help="slots of command jitter the rate limit passes (a burst of at most "
                        "1 + this many commits)")
    p.add_argument("--max-step", type=float, default=0.02, help="rad per joint per commit")
    p.add_argument("--watchdog", type=float, default=0.25,
                   help="s without a command before the setpoint freezes")
    p.add_argument("--max-clients", type=int, default=32,
                   help="connections beyond this many are refused ('server full')")
    p.add_argument("--hello-timeout", type=float, default=5.0,
                   help="s, a connection without a HELLO by then is closed")
    p.add_argument("--max-client-backlog", type=int, default=256 * 1024,
                   help="bytes of unread output per client; beyond it STATEs are dropped and a "
                        "client that stays there for 2 s is disconnected")
    p.add_argument("--with-sim", action="store_true",
                   help="also run the simulated hand firmware in this process")
    p.set_defaults(func=_cmd_server)

    p = subparsers.add_parser("can-sim", help="simulated CAN-bus hand firmware")
    _add_bus_arguments(p)
    _add_firmware_arguments(p)
    p.set_defaults(func=_cmd_sim)


def _add_firmware_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rate", type=float, default=500.0, help="Hz, control and publish rate")
    p.add_argument("--natural-frequency", type=float, default=5.0, help="Hz, joint loops")
    p.add_argument("--max-velocity", type=float, default=4.0, help="rad/s")
    p.add_argument("--noise", type=float, default=0.0005, help="rad, position noise (std)")
    p.add_argument("--object-closure", type=float, default=None,
                   help="fraction of the closing range where a virtual object stops the fingers")
    p.add_argument("--seed", type=int, default=0, help="seed of the position noise")
    p.add_argument("--feedback", choices=FEEDBACK_MODES, default=None,
                   help="when the hand acknowledges a setpoint: once per control cycle (cycle) "
                        "or at once with the last step's state (on_request); default: the "
                        f"hand's own ({DEFAULT_FEEDBACK})")


def _bus(args) -> BusConfig:
    channel = args.channel or _DEFAULT_CHANNEL[args.bus]
    return BusConfig(interface=args.bus, channel=channel, port=args.bus_port,
                     frame_format=args.frame_format,
                     multicast_interface=args.multicast_interface)


def _firmware_config(args, bus: BusConfig) -> CanFirmwareConfig:
    return CanFirmwareConfig(
        hand_kind=args.hand, coupling_ratio=args.coupling_ratio, bus=bus,
        rate=getattr(args, "rate", 500.0),
        natural_frequency=getattr(args, "natural_frequency", 5.0),
        max_velocity=getattr(args, "max_velocity", 4.0),
        position_noise=getattr(args, "noise", 0.0005),
        object_closure=getattr(args, "object_closure", None), seed=getattr(args, "seed", 0),
        realtime_priority=args.rt_priority, feedback=getattr(args, "feedback", None),
    )


def _freeze_heap() -> None:
    """Moves everything allocated at start-up out of the cyclic garbage collector's reach.

    The process imports numpy, cantools and the hand models; a full (gen 2)
    collection then scans that whole heap and stalls every thread for 30-50
    ms every few seconds, which lands directly in the 1 kHz loop's p99.
    Frozen objects are never scanned again (nor freed: they live as long as
    the process anyway); the loops allocate few cyclic objects.
    """
    gc.collect()
    gc.freeze()


def _stop_event() -> threading.Event:
    stop = threading.Event()

    def handler(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def _cmd_server(args) -> int:
    from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware
    from handle_drake.devices.can_hand.server import CanBusServer

    logging.basicConfig(level=args.log_level.upper())
    host, port = parse_listen(args.listen)
    try:
        if not ipaddress.ip_address(host).is_loopback:
            logging.warning("can-server: listening on %s, reachable from other hosts", host)
    except ValueError:  # a host name
        logging.warning("can-server: listening on %r; prefer a loopback address", host)
    bus = _bus(args)
    config = CanServerConfig(host=host, port=port, hand_kind=args.hand,
                             coupling_ratio=args.coupling_ratio, bus=bus,
                             max_setpoint_rate=args.max_rate,
                             rate_tolerance=args.rate_tolerance, max_step=args.max_step,
                             watchdog=args.watchdog, realtime_priority=args.rt_priority,
                             max_clients=args.max_clients, hello_timeout=args.hello_timeout,
                             max_client_backlog=args.max_client_backlog)
    stop = _stop_event()
    firmware = None
    with CanBusServer(config) as server:
        if args.with_sim:
            firmware = SimulatedHandFirmware(_firmware_config(args, bus), layout=server.layout)
            firmware.start()
        try:
            bound_host, bound_port = server.address
            _freeze_heap()
            print(f"can-server ready {bound_host}:{bound_port} hand={args.hand} "
                  f"bus={bus.interface}:{bus.channel} frames={bus.frame_format}", flush=True)
            server.serve_until(stop)
        finally:
            if firmware is not None:
                firmware.stop()
    return 0


def _cmd_sim(args) -> int:
    from handle_drake.devices.can_hand.firmware import SimulatedHandFirmware

    logging.basicConfig(level=args.log_level.upper())
    bus = _bus(args)
    stop = _stop_event()
    with SimulatedHandFirmware(_firmware_config(args, bus)) as firmware:
        _freeze_heap()
        print(f"can-sim ready hand={args.hand} bus={bus.interface}:{bus.channel} "
              f"frames={bus.frame_format}", flush=True)
        while not stop.wait(0.2):
            if not firmware.is_alive():
                raise RuntimeError("the firmware thread died; see the log")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="handle-drake")
    subparsers = parser.add_subparsers(dest="command", required=True)
    register(subparsers)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as error:
        print(f"handle-drake {args.command}: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
