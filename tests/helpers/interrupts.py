"""Stop the real command line as a terminal does, and judge how it ends.

:func:`interrupt_cli` starts ``python -m markerplace.cli ARGS`` as the leader of its own process
group (``start_new_session=True``, as a shell starts a job), waits until its log shows a line
holding ``wait_for``, waits ``delay`` seconds more, then sends ``signal`` to the whole group
(``os.killpg``: what Ctrl-C in a terminal does) and measures how long the command and every
process of the group take to end (psutil). Whatever is left when it gives up is killed, so a
failed check leaves nothing behind.

Used by ``tests/e2e/test_interrupts.py`` and ``scripts/hostile_inputs.py``.
"""

from __future__ import annotations

import os
import signal as _signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import psutil

from . import SRC

LIMIT_S = 5.0
"""The command and every process of its group must be gone this long after the signal."""


@dataclass
class Interrupted:
    """How an interrupted command ended.

    Attributes:
        returncode: the command's exit code (None: still running after ``LIMIT_S``).
        exit_s: seconds from the signal to the command's exit (inf if it did not).
        empty_s: seconds from the signal until no process of its group was left (inf if never).
        before: processes of the group just before the signal (the command included).
        left: ``(pid, name, cmdline)`` of the processes still alive ``LIMIT_S`` after the signal.
        stderr: everything the command wrote to stderr (its log).
        reached: whether the log showed ``wait_for`` (else the signal was never sent).
    """

    returncode: int | None
    exit_s: float
    empty_s: float
    before: int
    left: list = field(default_factory=list)
    stderr: str = ""
    reached: bool = True

    def problems(self, expect_code: int = 130, limit_s: float = LIMIT_S) -> list[str]:
        """What is wrong, as short phrases (empty: it ended as it should)."""
        out = []
        if not self.reached:
            out.append("the log never showed the stage")
            return out
        if self.returncode != expect_code:
            out.append(f"exit {self.returncode}, expected {expect_code}")
        if self.exit_s > limit_s:
            out.append(f"exited after {self.exit_s:.1f} s")
        if self.empty_s > limit_s or self.left:
            out.append(f"processes left after {limit_s:g} s: {self.left}")
        if "Traceback" in self.stderr:
            out.append("a traceback in the log")
        lines = [ln for ln in self.stderr.splitlines() if ln.startswith("markerplace:")]
        if len(lines) != 1 or "re-run the same command" not in lines[0]:
            out.append(f"no single line saying how to resume: {lines}")
        return out


def group_members(pgid: int) -> list[psutil.Process]:
    """Live processes (zombies excluded) whose process group is ``pgid``."""
    out = []
    for p in psutil.process_iter():
        try:
            if os.getpgid(p.pid) == pgid and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except (ProcessLookupError, psutil.Error):
            continue
    return out


def describe(p: psutil.Process) -> tuple:
    """``(pid, command line)`` of a process, as far as it can still be read."""
    try:
        return p.pid, " ".join(p.cmdline())[:120]
    except psutil.Error:
        return p.pid, "?"


def interrupt_cli(args: list[str], wait_for: str, delay: float = 0.5, sig: int = _signal.SIGINT,
                  start_timeout: float = 300.0, limit_s: float = LIMIT_S, cwd: str | Path | None = None,
                  env: dict | None = None, until=None) -> Interrupted:
    """Run the CLI with ``args``, signal its process group once ``wait_for`` is logged (and,
    with ``until``, a callable, once it also returns True: e.g. a file the stage writes
    exists); see the module docstring. The child gets SIGINT's default disposition (a shell's
    background job would inherit it ignored)."""
    cmd = [sys.executable, "-m", "markerplace.cli", *args]
    env = {**os.environ, **(env or {})}
    src = str(SRC)
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=cwd, env=env,
                            start_new_session=True,
                            preexec_fn=lambda: _signal.signal(_signal.SIGINT, _signal.SIG_DFL))
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in proc.stderr:
            lines.append(line)
            if wait_for in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    pgid = proc.pid
    try:
        deadline = time.monotonic() + start_timeout
        while not seen.is_set() and proc.poll() is None and time.monotonic() < deadline:
            seen.wait(0.05)
        while until is not None and seen.is_set() and not until() and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        if until is not None and not until():
            seen.clear()
        if not seen.is_set():
            return Interrupted(proc.poll(), float("inf"), float("inf"), 0, [], "".join(lines), reached=False)
        time.sleep(delay)
        before = len(group_members(pgid))
        t0 = time.monotonic()
        os.killpg(pgid, sig)
        try:
            proc.wait(timeout=limit_s)
            exit_s = time.monotonic() - t0
        except subprocess.TimeoutExpired:
            exit_s = float("inf")
        empty_s = float("inf")
        while time.monotonic() - t0 <= limit_s:
            if not group_members(pgid):
                empty_s = time.monotonic() - t0
                break
            time.sleep(0.05)
        left = [describe(p) for p in group_members(pgid)]
        reader.join(timeout=2.0)
        return Interrupted(proc.returncode if exit_s != float("inf") else None, exit_s, empty_s, before, left,
                           "".join(lines))
    finally:
        for p in group_members(pgid):
            try:
                p.kill()
            except psutil.Error:
                pass
        if proc.poll() is None:
            proc.kill()
            proc.wait()
