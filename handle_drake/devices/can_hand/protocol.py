"""The TCP protocol between the proxy driver and the CAN bus server (pure, no sockets).

We carry hand-level messages (whole vectors in SI units), not raw CAN frames:
the server owns the bus-side conventions (ids, scaling, rate limits, limits,
watchdog), so a client needs no CAN knowledge and one TCP message replaces 6
to 9 frames.

Every message is a frame::

    offset  size  field
    0       2     magic b"HC"
    2       1     protocol version (1)
    3       1     message type
    4       4     payload length N, uint32 little-endian (N <= 65536)
    8       N     payload

All numbers are little-endian; vectors are float64. Message types:

=====  =========  ===========  ====================================================
type   name       direction    payload
=====  =========  ===========  ====================================================
1      HELLO      c -> s       nq u16, nu u16, nt u16, hand kind (utf-8)
2      WELCOME    s -> c       same layout as HELLO, the server's hand
3      COMMAND    c -> s       seq u32, q[nu] f64 (rad, command order)
4      STATE      s -> c       seq_ack u32, hand_state u8, flags u8, pad u16,
                               hand_time f64 (s), q[nq], v[nq] (rad/s),
                               tactile[nt] (N), setpoint[nu] (rad)
5      STATS_REQ  c -> s       empty
6      STATS      s -> c       JSON object of counters (utf-8)
7      ERROR      s -> c       message (utf-8); the server closes after a
                               failed HELLO or a broken frame
=====  =========  ===========  ====================================================

A client sends HELLO first; the server answers WELCOME if nq, nu, nt and the
hand kind match its hand, ERROR otherwise. ``seq_ack`` in STATE is the
client ``seq`` of the newest command the hand has applied (0 before any).
STATE ``flags``: bit 0 ``FLAG_HOLDING`` (watchdog hold), bit 1
``FLAG_CLAMPED`` (the last command was clamped to joint limits), bit 2
``FLAG_RATE_LIMITED`` (the setpoint is still stepping towards the command).

A frame with a bad magic, an unknown version or an oversized length breaks
the stream (:class:`ProtocolError`, the connection is closed); a well-framed
message with a bad payload is rejected and counted, and the stream goes on.
"""

from __future__ import annotations

import dataclasses as dc
import json
import struct

import numpy as np

__all__ = [
    "MAGIC",
    "VERSION",
    "MAX_PAYLOAD",
    "HELLO",
    "WELCOME",
    "COMMAND",
    "STATE",
    "STATS_REQ",
    "STATS",
    "ERROR",
    "FLAG_HOLDING",
    "FLAG_CLAMPED",
    "FLAG_RATE_LIMITED",
    "ProtocolError",
    "PayloadError",
    "HandInfo",
    "StateMessage",
    "FrameReader",
    "pack",
    "pack_hello",
    "unpack_hello",
    "pack_command",
    "unpack_command",
    "pack_state",
    "unpack_state",
    "pack_stats",
    "unpack_stats",
]

MAGIC = b"HC"
VERSION = 1
MAX_PAYLOAD = 65536
HEADER = struct.Struct("<2sBBI")
HELLO, WELCOME, COMMAND, STATE, STATS_REQ, STATS, ERROR = 1, 2, 3, 4, 5, 6, 7
_TYPES = {HELLO, WELCOME, COMMAND, STATE, STATS_REQ, STATS, ERROR}
FLAG_HOLDING, FLAG_CLAMPED, FLAG_RATE_LIMITED = 1, 2, 4

_HELLO = struct.Struct("<HHH")
_COMMAND = struct.Struct("<I")
_STATE = struct.Struct("<IBBHd")


class ProtocolError(ValueError):
    """The byte stream is not this protocol; the connection must be closed."""


class PayloadError(ValueError):
    """A well-framed message whose payload is wrong (size, values)."""


def pack(message_type: int, payload: bytes = b"") -> bytes:
    """One framed message."""
    if message_type not in _TYPES:
        raise ValueError(f"message_type: expected one of {sorted(_TYPES)}, got {message_type}")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload: expected at most {MAX_PAYLOAD} bytes, got {len(payload)}")
    return HEADER.pack(MAGIC, VERSION, message_type, len(payload)) + payload


class FrameReader:
    """Splits a byte stream into ``(type, payload)`` messages.

    :meth:`feed` takes any chunk of received bytes and returns the complete
    messages in it; a partial message waits for the next chunk.
    """

    def __init__(self):
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        self._buffer += data
        messages = []
        while len(self._buffer) >= HEADER.size:
            magic, version, message_type, length = HEADER.unpack_from(self._buffer)
            if magic != MAGIC:
                raise ProtocolError(f"bad magic {bytes(magic)!r}, expected {MAGIC!r}")
            if version != VERSION:
                raise ProtocolError(f"protocol version {version}, expected {VERSION}")
            if length > MAX_PAYLOAD:
                raise ProtocolError(f"payload of {length} bytes, expected at most {MAX_PAYLOAD}")
            if len(self._buffer) < HEADER.size + length:
                break
            payload = bytes(self._buffer[HEADER.size:HEADER.size + length])
            del self._buffer[:HEADER.size + length]
            messages.append((message_type, payload))
        return messages


@dc.dataclass(frozen=True)
class HandInfo:
    """What HELLO/WELCOME exchange: the hand's kind and sizes."""

    kind: str
    nq: int
    nu: int
    nt: int


def pack_hello(info: HandInfo, message_type: int = HELLO) -> bytes:
    return pack(message_type, _HELLO.pack(info.nq, info.nu, info.nt) + info.kind.encode())


def unpack_hello(payload: bytes) -> HandInfo:
    if len(payload) < _HELLO.size:
        raise PayloadError(f"HELLO: expected at least {_HELLO.size} bytes, got {len(payload)}")
    nq, nu, nt = _HELLO.unpack_from(payload)
    try:
        kind = payload[_HELLO.size:].decode()
    except UnicodeDecodeError:
        raise PayloadError("HELLO: hand kind is not utf-8") from None
    return HandInfo(kind=kind, nq=nq, nu=nu, nt=nt)


def pack_command(seq: int, q) -> bytes:
    q = np.ascontiguousarray(q, dtype="<f8")
    return pack(COMMAND, _COMMAND.pack(int(seq) % (1 << 32)) + q.tobytes())


def unpack_command(payload: bytes, nu: int) -> tuple[int, np.ndarray]:
    """``(seq, q)``; PayloadError unless the payload holds exactly nu finite values."""
    expected = _COMMAND.size + 8 * nu
    if len(payload) != expected:
        got = (len(payload) - _COMMAND.size) / 8
        raise PayloadError(f"COMMAND: expected {nu} joint values, got {got:g}")
    (seq,) = _COMMAND.unpack_from(payload)
    q = np.frombuffer(payload, dtype="<f8", offset=_COMMAND.size).astype(float)
    if not np.all(np.isfinite(q)):
        raise PayloadError(f"COMMAND: expected finite values, got {q.tolist()}")
    return seq, q


@dc.dataclass(frozen=True)
class StateMessage:
    """A decoded STATE: one hand cycle as the server saw it."""

    seq_ack: int
    hand_state: int
    flags: int
    hand_time: float
    q: np.ndarray
    v: np.ndarray
    tactile: np.ndarray
    setpoint: np.ndarray


def pack_state(state: StateMessage) -> bytes:
    head = _STATE.pack(state.seq_ack % (1 << 32), state.hand_state, state.flags, 0,
                       state.hand_time)
    body = np.concatenate([state.q, state.v, state.tactile, state.setpoint]).astype("<f8")
    return pack(STATE, head + body.tobytes())


def unpack_state(payload: bytes, info: HandInfo) -> StateMessage:
    n = 2 * info.nq + info.nt + info.nu
    if len(payload) != _STATE.size + 8 * n:
        raise PayloadError(
            f"STATE: expected {_STATE.size + 8 * n} bytes for {info.kind}, got {len(payload)}"
        )
    seq_ack, hand_state, flags, _, hand_time = _STATE.unpack_from(payload)
    values = np.frombuffer(payload, dtype="<f8", offset=_STATE.size).astype(float)
    nq, nt = info.nq, info.nt
    return StateMessage(
        seq_ack=seq_ack, hand_state=hand_state, flags=flags, hand_time=hand_time,
        q=values[:nq], v=values[nq:2 * nq], tactile=values[2 * nq:2 * nq + nt],
        setpoint=values[2 * nq + nt:],
    )


def pack_stats(counters: dict) -> bytes:
    return pack(STATS, json.dumps(counters, sort_keys=True).encode())


def unpack_stats(payload: bytes) -> dict:
    try:
        value = json.loads(payload.decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise PayloadError(f"STATS: not a JSON object ({error})") from None
    if not isinstance(value, dict):
        raise PayloadError(f"STATS: expected a JSON object, got {type(value).__name__}")
    return value
