"""Opening a python-can bus from a :class:`BusConfig` (the thin transport).

- ``virtual``: python-can's in-process bus (all ends in one process).
- ``udp_multicast``: frames as UDP multicast datagrams, across processes on
  one host (loopback, TTL 1). A socket also receives its own frames, so every
  node ignores the ids it sends itself.
- ``socketcan``: a Linux CAN interface (``can0``, or ``vcan0`` for a virtual
  kernel bus); needs the interface to exist.
"""

from __future__ import annotations

import os

import can

from handle_drake.can_hand.config import BusConfig

__all__ = ["open_bus", "socketcan_available"]


def socketcan_available(channel: str) -> bool:
    """True when the Linux network interface ``channel`` exists (e.g. ``vcan0``)."""
    return os.path.exists(f"/sys/class/net/{channel}")


def open_bus(config: BusConfig) -> can.BusABC:
    """A python-can bus for ``config``; ValueError naming the problem otherwise."""
    config.validate()
    if config.interface == "virtual":
        return can.Bus(interface="virtual", channel=config.channel, receive_own_messages=False)
    if config.interface == "udp_multicast":
        # CAN 2.0 frames only: the hand's messages are 8 bytes.
        return can.Bus(interface="udp_multicast", channel=config.channel, port=config.port,
                       hop_limit=1, fd=False)
    if not socketcan_available(config.channel):
        raise ValueError(
            f"socketcan: no network interface {config.channel!r}; create it first "
            f"(e.g. `ip link add dev {config.channel} type vcan && "
            f"ip link set up {config.channel}`)"
        )
    return can.Bus(interface="socketcan", channel=config.channel)
