"""Servers on 127.0.0.1 that are not Dask schedulers, for the ``--cluster`` checks
(``tests/cli/test_checked_inputs.py``, ``scripts/hostile_inputs.py``)."""

from __future__ import annotations

import os
import socket
import threading


class LoopbackServer:
    """A TCP server on 127.0.0.1 (a free port) that accepts every connection and then either
    never answers (``garbage=False``: a silent server) or sends bytes that announce a 2**64-byte
    message followed by random bytes (``garbage=True``). Use as a context manager."""

    def __init__(self, garbage: bool):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.garbage = garbage
        self.conns: list[socket.socket] = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.garbage:
                try:
                    conn.sendall(b"\xff" * 8 + os.urandom(4096))
                except OSError:
                    pass

    def close(self) -> None:
        for c in self.conns:
            c.close()
        self.sock.close()

    def __enter__(self) -> "LoopbackServer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
