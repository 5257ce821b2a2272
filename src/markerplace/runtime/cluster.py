"""``--cluster`` addresses: parsed, checked against the server before any work, and watched.

:func:`parse_cluster` accepts ``local:N`` (a Dask ``LocalCluster`` of N worker processes on this
machine, 1 <= N <= its usable CPUs) and ``tcp://HOST:PORT`` / ``tls://HOST:PORT`` of a running
scheduler; anything else is a one-line :class:`~markerplace.errors.UserError`.
:func:`check_scheduler` connects with a timeout and reads the handshake a Dask scheduler sends
first, so a silent server or one answering garbage gives one line within seconds (Dask's own
client would wait minutes, or try to allocate what the garbage announces).

While the work runs, :mod:`markerplace.runtime.cluster_watch` watches the cluster: a scheduler
without workers, workers that all leave and a scheduler that goes away each end in one line
(exit code 2) instead of a wait without end or a traceback; workers that leave while others
remain are Dask's to handle (it runs their tasks again on the others).
"""

from __future__ import annotations

import os
import socket
import struct
import time

from markerplace.errors import UserError

__all__ = ["CLUSTER_SCHEMES", "SCHEDULER_TIMEOUT_S", "HANDSHAKE_MAX_BYTES", "usable_cpus", "parse_cluster",
           "check_scheduler"]

CLUSTER_SCHEMES = ("tcp", "tls")
"""Schemes of a Dask scheduler address that ``--cluster`` accepts (besides ``local:N``)."""


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity), at least 1."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def parse_cluster(text: str) -> tuple[str, str | int, int | None]:
    """Parse a ``--cluster`` value: ``local:N`` or ``tcp://HOST:PORT`` / ``tls://HOST:PORT``.

    Returns:
        ``("local", N, None)`` with 1 <= N <= the usable CPUs (a ``LocalCluster`` of N worker
        processes on this machine), or ``(scheme, host, port)`` of a running scheduler.

    Raises:
        UserError: anything else (another scheme, no port, N not a whole number in range).
    """
    text = str(text).strip()
    form = "local:N (N worker processes here) or tcp://HOST:PORT of a running Dask scheduler, e.g. tcp://10.0.0.5:8786"
    if text.lower().startswith("local:"):
        n_text = text.split(":", 1)[1].strip()
        cpus = usable_cpus()
        if not (n_text.isascii() and n_text.isdigit()):
            raise UserError(f"--cluster {text!r}: N must be a whole number of workers, e.g. local:{min(2, cpus)}")
        n = int(n_text)
        if not 1 <= n <= cpus:
            raise UserError(f"--cluster {text!r}: N must be between 1 and {cpus} (the CPUs of this machine), "
                            f"e.g. local:{min(2, cpus)}")
        return "local", n, None
    scheme, sep, rest = text.partition("://")
    if not sep or scheme.lower() not in CLUSTER_SCHEMES:
        raise UserError(f"--cluster {text!r}: give {form} (the scheme must be tcp:// or tls://)")
    host, colon, port_text = rest.rpartition(":")
    host = host.strip("[]")
    port_ok = port_text.isascii() and port_text.isdigit() and 1 <= int(port_text) <= 65535
    if not colon or not host or not port_ok or "/" in rest:
        raise UserError(f"--cluster {text!r}: give {form} (HOST:PORT with a port in 1..65535)")
    return scheme.lower(), host, int(port_text)


SCHEDULER_TIMEOUT_S = 5.0
"""Seconds a Dask scheduler has to accept a connection and to send its handshake."""
HANDSHAKE_MAX_BYTES = 1 << 16
"""A Dask handshake (a small msgpack dict) is far below this; a longer announced message is not one."""


def check_scheduler(address: str, timeout_s: float | None = None) -> None:
    """Refuse, with one line, a ``--cluster`` address where no Dask scheduler answers.

    Connects (``timeout_s``, default :data:`SCHEDULER_TIMEOUT_S`) and, for ``tcp://``, reads the
    handshake a Dask scheduler sends first (distributed's framing: an 8-byte little-endian length,
    the frame table, a msgpack dict with ``python`` and ``compression``), at most
    :data:`HANDSHAKE_MAX_BYTES`, within ``timeout_s``.
    A server that accepts and never answers, or answers something else, is refused here instead
    of hanging Dask's client or letting it allocate what the garbage announces. ``tls://`` is
    only connected to (its handshake is encrypted).

    Raises:
        UserError: a malformed address, no connection, no answer in time, or not a Dask answer.
    """
    scheme, host, port = parse_cluster(address)
    if scheme == "local":
        return
    timeout_s = SCHEDULER_TIMEOUT_S if timeout_s is None else float(timeout_s)
    start = "start one with `dask scheduler` and workers with `dask worker ADDRESS --nthreads 1`"
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except socket.timeout:
        raise UserError(f"--cluster {address}: no connection within {timeout_s:g} s: cannot reach the Dask "
                        f"scheduler; check the address and firewall, or {start}") from None
    except OSError as err:
        raise UserError(f"--cluster {address}: cannot reach the Dask scheduler ({err.strerror or err}); "
                        f"{start}") from None
    if scheme != "tcp":
        sock.close()
        return
    deadline = time.monotonic() + timeout_s

    def read(n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise socket.timeout
            sock.settimeout(left)
            chunk = sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("closed")
            buf += chunk
        return buf

    not_dask = (f"--cluster {address}: the server there does not answer like a Dask scheduler; check the port "
                f"(a scheduler listens on 8786 by default) or {start}")
    with sock:
        try:
            (n,) = struct.unpack("<Q", read(8))
            if not 16 <= n <= HANDSHAKE_MAX_BYTES:
                raise UserError(not_dask)
            body = read(n)
        except socket.timeout:
            raise UserError(f"--cluster {address}: the server accepted the connection but sent no Dask handshake "
                            f"within {timeout_s:g} s; is it a Dask scheduler? {start}") from None
        except OSError:
            raise UserError(not_dask) from None
    try:
        import msgpack
        from distributed.protocol.utils import unpack_frames

        info = msgpack.unpackb(bytes(unpack_frames(body)[0]), raw=False)
    except Exception:
        raise UserError(not_dask) from None
    if not isinstance(info, dict) or "python" not in info:
        raise UserError(not_dask)
