"""Opening a python-can bus from a :class:`BusConfig` (the thin transport).

- ``virtual``: python-can's in-process bus (all ends in one process).
- ``udp_multicast``: frames as UDP multicast datagrams, across processes on
  one host (loopback, TTL 1). A socket also receives its own frames, so every
  node ignores the ids it sends itself.
- ``socketcan``: a Linux CAN interface (``can0``, or ``vcan0`` for a virtual
  kernel bus); needs the interface to exist, and for the fd frame format an
  FD-capable one (MTU 72).

The bus is opened able to receive CAN FD frames whenever the interface can,
also for the classic layout: a frame of the wrong format then reaches the
node and is rejected and counted instead of vanishing inside python-can.
"""

from __future__ import annotations

import logging
import os

import can

from handle_drake.can_hand.config import BusConfig

__all__ = ["open_bus", "socketcan_available", "socketcan_fd_capable", "use_realtime_priority"]

log = logging.getLogger(__name__)

_CANFD_MTU = 72  # struct canfd_frame; a CAN 2.0 interface has MTU 16


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
        return can.Bus(interface="udp_multicast", channel=config.channel, port=config.port,
                       hop_limit=1, fd=True)
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
