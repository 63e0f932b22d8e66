"""Is there a Dask scheduler at an address? One TCP connection, a time limit, and the scheduler's own greeting.

``dask.distributed.Client`` trusts whatever answers: an HTTP server never speaks first, so the client waits
forever; a server answering random bytes has them read as a frame length (``MemoryError: Unable to allocate 668
PiB``). A Dask comm greets first: right after the connection, each side writes its handshake (the frame lengths
as 8-byte integers, then a small msgpack map naming ``compression``, ``python`` and ``pickle-protocol``;
``distributed.comm.core.Listener.on_connection``). :func:`check_scheduler` reads that greeting, bounded in
bytes and seconds, before the client is made.
"""

from __future__ import annotations

import socket
import struct
import time
from urllib.parse import urlsplit

from workbench.errors import WorkbenchError

__all__ = ["check_scheduler", "GREETING_LIMIT"]

#: A scheduler's greeting is a few dozen bytes; anything announcing more is not one.
GREETING_LIMIT = 1 << 16


def _read(sock: socket.socket, n: int, deadline: float, address: str) -> bytes:
    out = b""
    while len(out) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        sock.settimeout(left)
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise WorkbenchError(f"{address}: not a Dask scheduler: it closed the connection "
                                 f"after {len(out)} byte(s) of a greeting")
        out += chunk
    return out


def check_scheduler(address: str, timeout: float = 10.0) -> None:
    """Connect to ``address`` (``tcp://HOST:PORT`` or ``HOST:PORT``) and check that a Dask scheduler greets.

    ``inproc://`` (this process's own) passes unchecked; other schemes (``tls://``, ``ws://``, ``ucx://``) are
    refused.

    Raises
    ------
    WorkbenchError
        One line: nothing listens, nothing greets within ``timeout`` seconds (an HTTP server), or the greeting
        is not a Dask handshake (random bytes, another protocol).
    """
    text = str(address).strip()
    if "://" not in text:
        text = f"tcp://{text}"
    try:
        parts = urlsplit(text)
    except ValueError:  # "tcp://[::1": an unclosed IPv6 bracket
        raise WorkbenchError(f"{address}: not a scheduler address (tcp://HOST:PORT)") from None
    if parts.scheme == "inproc":  # a scheduler in this very process (a test's LocalCluster): nothing to check
        return
    if parts.scheme != "tcp":
        # tls:// needs certificates the workbench has no option for, ws:// and ucx:// extra packages and their
        # own handshakes: refused by name here rather than failing inside the client (TypeError, WebSocketError)
        raise WorkbenchError(f"{address}: the workbench connects to Dask schedulers at tcp://HOST:PORT only, not "
                             f"{parts.scheme}://")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        raise WorkbenchError(f"{address}: not a scheduler address (tcp://HOST:PORT)") from None
    if not host or port is None:
        raise WorkbenchError(f"{address}: not a scheduler address (tcp://HOST:PORT)")
    deadline = time.monotonic() + float(timeout)
    try:
        with socket.create_connection((host, port), timeout=float(timeout)) as sock:
            (size,) = struct.unpack("<Q", _read(sock, 8, deadline, address))
            if not 16 <= size <= GREETING_LIMIT:
                raise WorkbenchError(f"{address}: not a Dask scheduler: its first bytes announce a "
                                     f"{size}-byte message, not a handshake")
            body = _read(sock, size, deadline, address)
    except TimeoutError:
        raise WorkbenchError(f"{address}: not a Dask scheduler: no handshake within {timeout:g} s (a Dask "
                             "scheduler speaks first; an HTTP server waits for a request)") from None
    except OSError as exc:
        raise WorkbenchError(f"cannot reach the Dask scheduler at {address}: {exc.strerror or exc}") from None
    (n_frames,) = struct.unpack("<Q", body[:8])
    lengths = struct.unpack(f"<{n_frames}Q", body[8:8 + 8 * n_frames]) if 0 < n_frames <= 16 else ()
    if not lengths or 8 + 8 * n_frames + sum(lengths) != size or b"pickle-protocol" not in body:
        raise WorkbenchError(f"{address}: not a Dask scheduler: its greeting is not a Dask handshake")
