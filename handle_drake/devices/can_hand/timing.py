"""Bus time of CAN and CAN FD frames and of a hand cycle (pure; see :mod:`.messages`)."""

from __future__ import annotations

from handle_drake.devices.can_hand.frames import FD_LENGTHS


def frame_time(data_bytes: int, fd: bool, nominal_bitrate: float = 1e6,
               data_bitrate: float = 5e6, worst_case_stuffing: bool = False) -> float:
    """Seconds one standard-id data frame occupies the bus, interframe space included.

    Classic CAN 2.0A: ``47 + 8 s`` bits, plus up to ``floor((33 + 8 s) / 4)``
    stuff bits (Davis, Burns, Bril, Lukkien 2007: 111 / 135 bits for 8 bytes).
    CAN FD with bit-rate switching (ISO 11898-1:2015 field lengths): 30 bits
    at the nominal rate (SOF, id, RRS, IDE, FDF, res, BRS; CRC delimiter,
    ACK, ACK delimiter, EOF, IFS) and at the data rate ESI, DLC, the data,
    the 4-bit stuff count, the CRC (17 bits up to 16 data bytes, 21 above) and
    its fixed stuff bits (6 or 7). ``worst_case_stuffing`` adds one bit per
    four of the dynamically stuffed fields (an upper bound).
    """
    if fd:
        if data_bytes not in FD_LENGTHS:
            raise ValueError(f"data_bytes: expected a CAN FD length {FD_LENGTHS}, "
                             f"got {data_bytes}")
        crc, fixed = (17, 6) if data_bytes <= 16 else (21, 7)
        nominal, data = 30, 1 + 4 + 8 * data_bytes + 4 + crc + fixed
        if worst_case_stuffing:
            nominal += 4  # SOF..BRS: 17 bits
            data += (5 + 8 * data_bytes) // 4
        return nominal / nominal_bitrate + data / data_bitrate
    if not 0 <= data_bytes <= 8:
        raise ValueError(f"data_bytes: expected 0..8 for a classic frame, got {data_bytes}")
    bits = 47 + 8 * data_bytes
    if worst_case_stuffing:
        bits += (33 + 8 * data_bytes) // 4
    return bits / nominal_bitrate


def cycle_bus_time(codec, nominal_bitrate: float = 1e6, data_bitrate: float = 5e6,
                   worst_case_stuffing: bool = False) -> float:
    """Seconds of bus time of one command plus one hand cycle of ``codec``'s layout."""
    out, back = codec.cycle_frame_lengths
    return sum(frame_time(n, codec.is_fd, nominal_bitrate, data_bitrate, worst_case_stuffing)
               for n in (*out, *back))
