"""Is a Dask scheduler at this address? A bounded look before ``distributed.Client``.

``Client(address, timeout=...)`` trusts the peer: a listener that accepts and
never speaks held ``babble --executor dask://...`` past 100 s despite
``--connect-timeout 3``; one that sends one byte raised ``struct.error``; one
that sends garbage or an HTTP answer had Dask read the first 8 bytes as a
frame length ("MemoryError ... 3.07 EiB"). :func:`probe_scheduler` connects
with a plain socket and reads the greeting every Dask server sends first on a
new connection (``distributed.comm.core.Listener.on_connection`` writes its
handshake before it reads the client's), all within one deadline:

- the TCP comm's framing: an 8-byte length, then ``n_frames`` (8 bytes),
  ``n_frames`` frame lengths (8 bytes each) and the frames;
- frame 0 is msgpack of a mapping with the keys ``compression``, ``python``
  and ``pickle-protocol`` (``Comm.handshake_info``).

A greeting longer than :data:`MAX_GREETING` bytes, fewer bytes than announced,
silence or anything else is an :class:`ExecutorError` naming the address and
what it sent. :func:`connect_client` then opens the ``Client`` in a thread and
waits for it no longer than the timeout.
"""

from __future__ import annotations

import socket
import struct
import threading
import time

__all__ = ["MAX_GREETING", "probe_scheduler", "connect_client"]

MAX_GREETING = 1 << 16  # bytes: Dask's handshake is ~60 bytes
_HANDSHAKE_KEYS = {"compression", "python", "pickle-protocol"}


def _error(where: str, what: str):
    from handle_drake.learning.cluster import ExecutorError

    return ExecutorError(f"executor dask://{where}: {what}")


def _split(address: str) -> tuple[str, int]:
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    return host.strip("[]"), int(port)


def _read(sock: socket.socket, n: int, deadline: float, where: str, got: int, timeout: float):
    data = bytearray()
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise _error(where, f"no Dask greeting within {timeout:g} s (--connect-timeout): "
                                f"the listener sent {got + len(data)} bytes and then nothing; "
                                "is it a Dask scheduler?")
        sock.settimeout(left)
        try:
            chunk = sock.recv(min(n - len(data), 65536))
        except TimeoutError:
            continue  # the deadline check above says so
        except OSError as error:
            raise _error(where, f"the connection failed while reading Dask's greeting "
                                f"({error.strerror or error})") from None
        if not chunk:
            raise _error(where, f"the listener closed the connection after {got + len(data)} "
                                "bytes, without Dask's greeting: not a Dask scheduler")
        data += chunk
    return bytes(data)


def probe_scheduler(address: str, timeout: float) -> None:
    """Returns when the peer at ``address`` (``tcp://HOST:PORT``) greets as a Dask
    server within ``timeout`` s; raises :class:`ExecutorError` otherwise."""
    import msgpack

    host, port = _split(address)
    where = f"{host}:{port}"
    deadline = time.monotonic() + timeout
    while True:  # a scheduler that is starting: tried again until the deadline, as Dask does
        try:
            sock = socket.create_connection((host, port),
                                            timeout=max(0.01, deadline - time.monotonic()))
            break
        except OSError as error:
            if time.monotonic() + 0.2 >= deadline:
                raise _error(where, f"no Dask scheduler answered at {address} within "
                                    f"{timeout:g} s ({error.strerror or error}); start one with "
                                    f"`dask scheduler` and point workers at it with "
                                    f"`dask worker {address}`") from None
            time.sleep(0.2)
    with sock:
        head = _read(sock, 8, deadline, where, 0, timeout)
        (length,) = struct.unpack("Q", head)
        if not 16 <= length <= MAX_GREETING:
            raise _error(where, f"the listener is not a Dask scheduler: its first bytes "
                                f"{head!r} announce a {length}-byte message (Dask's greeting "
                                f"is under {MAX_GREETING} bytes)")
        body = _read(sock, length, deadline, where, 8, timeout)
    try:
        (n_frames,) = struct.unpack_from("Q", body)
        if not 1 <= n_frames <= 16:
            raise ValueError(f"{n_frames} frames")
        sizes = struct.unpack_from(f"{n_frames}Q", body, 8)
        start = 8 * (1 + n_frames)
        if start + sum(sizes) != length:
            raise ValueError("frame sizes do not add up")
        message = msgpack.unpackb(body[start:start + sizes[0]], raw=False, use_list=True,
                                  strict_map_key=False)
    except (ValueError, struct.error, msgpack.UnpackException, TypeError) as error:
        raise _error(where, f"the listener is not a Dask scheduler: its greeting is not "
                            f"Dask's ({error})"[:300]) from None
    if not (isinstance(message, dict) and _HANDSHAKE_KEYS <= set(message)):
        raise _error(where, "the listener is not a Dask scheduler: its greeting lacks Dask's "
                            "handshake")


def connect_client(address: str, timeout: float):
    """``distributed.Client(address)`` within ``timeout`` s (a Client still
    connecting then is left to its daemon thread). Call :func:`probe_scheduler` first."""
    from distributed import Client

    left = timeout
    box: dict = {}

    def connect():
        try:
            box["client"] = Client(address, timeout=left)
        except BaseException as error:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = error

    thread = threading.Thread(target=connect, name="dask-connect", daemon=True)
    thread.start()
    thread.join(left + 1.0)
    if thread.is_alive():
        raise _error(address.removeprefix("tcp://"),
                     f"the Dask server greeted but no Client connected within {timeout:g} s "
                     "(--connect-timeout); is it a scheduler (not a worker)?")
    if "error" in box:
        raise box["error"]
    return box["client"]
