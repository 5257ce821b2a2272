"""Real ``dask scheduler`` and ``dask worker`` processes on 127.0.0.1 (free ports), to be killed
on purpose (``tests/runtime/test_cluster_faults.py``), and the worker task those tests run.

The processes run this interpreter (``python -m distributed.cli.dask_scheduler`` /
``dask_worker``: what the ``dask scheduler`` / ``dask worker`` commands run) with this checkout's
``src`` and ``tests`` on ``PYTHONPATH``, so the workers import the markerplace under test and
this module (the task below is pickled by reference).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import markerplace

SRC = Path(markerplace.__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def env() -> dict:
    """The environment of the processes (and of a CLI run in a subprocess)."""
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(SRC), str(TESTS), *filter(None, [e.get("PYTHONPATH")])])
    return e


class DaskProcesses:
    """A scheduler on a free port of 127.0.0.1 and the workers started with :meth:`worker`
    (single-threaded, no nanny: a killed worker stays dead). Use as a context manager: every
    process still running at the end is killed."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []
        self.scheduler = self._start("scheduler", ["distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                                   "--port", str(self.port), "--no-dashboard"])
        self._wait_for_port()

    def _start(self, name: str, args: list[str]) -> subprocess.Popen:
        log = open(self.folder / f"{name}-{len(self.procs)}.log", "wb")
        proc = subprocess.Popen([sys.executable, "-m", *args], stdout=log, stderr=subprocess.STDOUT, env=env(),
                                cwd=self.folder, start_new_session=True)
        log.close()
        self.procs.append(proc)
        return proc

    def _wait_for_port(self, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            assert self.scheduler.poll() is None, "the scheduler exited; see " + str(self.folder)
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=1).close()
                return
            except OSError:
                time.sleep(0.2)
        raise AssertionError("no scheduler listening after 60 s")

    def worker(self) -> subprocess.Popen:
        """Start one single-threaded worker without a nanny (its pid is the worker's)."""
        return self._start("worker", ["distributed.cli.dask_worker", self.address, "--nthreads", "1", "--no-nanny",
                                      "--no-dashboard", "--host", "127.0.0.1",
                                      "--local-directory", str(self.folder / "scratch")])

    @staticmethod
    def kill(proc: subprocess.Popen) -> None:
        """SIGKILL, as a crashed machine or the out-of-memory killer would."""
        try:
            os.kill(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=30)

    def __enter__(self) -> "DaskProcesses":
        return self

    def __exit__(self, *exc) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                self.kill(proc)


# --- the worker side -------------------------------------------------------------------------


def build(seconds: float) -> float:
    """The state a worker builds once: how long each item takes."""
    return float(seconds)


def slow_double(seconds: float, item: int) -> tuple[int, int]:
    """``(2 * item, the worker's pid)`` after ``seconds`` of sleep."""
    time.sleep(seconds)
    return 2 * int(item), os.getpid()
