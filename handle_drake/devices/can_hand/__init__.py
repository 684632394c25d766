"""The CAN-bus hand interface: messages, bus server, simulated firmware, proxy driver.

The chain (seed report, section 2.1: MuscleHandProxy -> TCP -> CANbusServer):

    Drake diagram -- CanHandProxy (LeafSystem) --TCP--> CanBusServer --CAN--> hand
                                                                       (or SimulatedHandFirmware)

- :mod:`~handle_drake.devices.can_hand.messages`: the message layouts (``hand_fd.dbc``: CAN FD,
  one frame per command and per hand cycle, the default; ``hand.dbc``: classic
  8-byte CAN 2.0 frames; ``BusConfig.frame_format`` picks one) and pure
  encode/decode;
- :mod:`~handle_drake.devices.can_hand.protocol`: the framed TCP protocol (pure);
- :mod:`~handle_drake.devices.can_hand.server`: the bus server (rate limits, clamps, watchdog);
- :mod:`~handle_drake.devices.can_hand.firmware`: a simulated hand on the bus;
- :mod:`~handle_drake.devices.can_hand.client` and
  :mod:`~handle_drake.devices.can_hand.driver`: the proxy;
- ``MakeHardwareStation`` (the hardware branch of the station) lives beside
  ``MakeHandStation`` in :mod:`handle_drake.station`.
"""

from handle_drake.devices.can_hand.config import (
    BusConfig,
    CanFirmwareConfig,
    CanHandDriverConfig,
    CanServerConfig,
)
from handle_drake.devices.can_hand.layout import HandLayout, hand_layout

__all__ = [
    "AddCanHandDriver",
    "BusConfig",
    "CanBusServer",
    "CanFirmwareConfig",
    "CanHandClient",
    "CanHandDriverConfig",
    "CanHandProxy",
    "CanServerConfig",
    "FdHandCodec",
    "HandCodec",
    "HandLayout",
    "SimulatedHandFirmware",
    "hand_layout",
    "make_codec",
]


def __getattr__(name):
    # Heavier modules (pydrake systems, sockets, threads) load on first use.
    lazy = {
        "AddCanHandDriver": "driver", "CanHandProxy": "driver", "CanBusServer": "server",
        "CanHandClient": "client", "HandCodec": "messages", "FdHandCodec": "messages",
        "make_codec": "messages",
        "SimulatedHandFirmware": "firmware",
    }
    if name in lazy:
        import importlib

        return getattr(importlib.import_module(f"handle_drake.devices.can_hand.{lazy[name]}"), name)
    raise AttributeError(f"module 'handle_drake.devices.can_hand' has no attribute {name!r}")
