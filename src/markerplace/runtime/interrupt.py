"""Ctrl-C and SIGTERM for the command line: stop within seconds, leave no process behind.

A terminal's Ctrl-C sends SIGINT to the whole process group: the main process and every worker.
What happens then:

* Workers never see SIGINT (:func:`markerplace.runtime.workers.children_without_sigint`): no
  worker tracebacks, no pool respawning interrupted workers. Only the main process reacts.
* In the main process the first SIGINT raises :class:`KeyboardInterrupt` and SIGTERM raises
  :class:`Terminated` (a ``KeyboardInterrupt``), so the same clean-up runs for both: executors
  terminate their process pools or close their Dask cluster
  (:mod:`markerplace.runtime.executor`), stages keep the parts they finished. Further signals
  while stopping are ignored (a second Ctrl-C cannot interrupt the clean-up half-way).
* The raised exception can be swallowed where Python cannot pass it on (a ``gc`` callback of
  Dask, a destructor: "Exception ignored in ..."). So the signal is also remembered:
  :func:`raise_if_stopping` raises it again at the next progress update or stage, and a command
  that returns normally after a signal still ends with the signal's exit code and message; the
  swallowed exception itself is not printed (``sys.unraisablehook``: only our own
  ``KeyboardInterrupt`` is kept quiet, anything else is reported as usual).
* After a signal, :func:`stop_children` ends whatever child processes are left (terminate, then
  kill after ``CHILD_WAIT_S``); multiprocessing's resource tracker is left alone: it ignores signals and
  exits by itself when this process is gone (the watchdog's exit first unlinks this process's
  semaphores, :func:`release_semaphores`, so the tracker has no leak to warn about).
* A watchdog thread learns of the signal through :func:`signal.set_wakeup_fd`, which the C-level
  handler writes even while the main thread sits in a long C call (FAISS, a compiled kernel).
  If the process still runs ``GRACE_S`` seconds after the signal, the watchdog prints the
  message, stops the children and ends the process with the same exit code. So the command
  ends within about ``GRACE_S + CHILD_WAIT_S + 0.5`` seconds (4.3 s) whatever it was doing.

Exit codes: 130 after SIGINT, 143 after SIGTERM (128 + the signal number, as a shell reports).
The message says how to resume: re-run the same command; finished stages (and the finished
parts of an interrupted stage) are reused.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from contextlib import contextmanager
from multiprocessing import synchronize, util
from typing import Iterator

from markerplace.runtime.cache_home import remove_temporary

__all__ = ["Terminated", "InterruptGuard", "deferred", "raise_if_stopping", "stop_children", "release_semaphores",
           "exit_code", "resume_message", "GRACE_S", "CHILD_WAIT_S"]

GRACE_S = 3.0
"""Seconds the main thread has after the first signal to clean up before the watchdog ends the process."""
CHILD_WAIT_S = 0.8
"""Seconds a terminated child has to exit before it is killed."""

_STOP = b"\x00"  # written to the wakeup pipe to end the watchdog (no signal has number 0)


class Terminated(KeyboardInterrupt):
    """Raised in the main thread on SIGTERM, so that SIGTERM cleans up as Ctrl-C does."""


_deferring = 0  # depth of deferred() blocks (main thread)
_pending: list[int] = []  # the signal that arrived inside one
_received: list[int] = []  # the signal the active guard received (empty: none)


def raise_if_stopping() -> None:
    """In the main thread, raise the signal the command received again (its first exception may
    have been swallowed, see the module docstring); nothing when none was received, inside a
    :func:`deferred` block, or in another thread."""
    if _received and not _deferring and threading.current_thread() is threading.main_thread():
        raise Terminated() if _received[0] == signal.SIGTERM else KeyboardInterrupt()


@contextmanager
def deferred() -> Iterator[None]:
    """A block that a Ctrl-C or SIGTERM does not cut in two (under :class:`InterruptGuard`): the
    signal is held and raised when the block ends. For steps that leave a mess when cut, such as
    starting a process pool (a worker whose parent stops writing its start-up data dies with an
    ``EOFError`` traceback, and a half-built pool is never terminated). The watchdog still ends
    the process ``GRACE_S`` after the signal."""
    global _deferring
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
        if _deferring == 0 and _pending:
            signum = _pending.pop()
            _pending.clear()
            raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def exit_code(signum: int) -> int:
    """The shell's exit status of a process ended by ``signum``: 128 + its number."""
    return 128 + int(signum)


def resume_message(signum: int, resumable: bool = True) -> str:
    """The one line printed when a run stops on ``signum``; ``resumable``: the command caches
    its stages (``plan``, ``evaluate``, ``study``, ``check``), else its output is written
    atomically at the end, so nothing half-written is left."""
    what = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}"
    if resumable:
        return (f"markerplace: {what}; to resume, re-run the same command: finished stages and the finished "
                "parts of the interrupted stage are reused")
    return f"markerplace: {what}; nothing was written: re-run the same command to start again"


def _is_resource_tracker(proc) -> bool:
    try:
        return any("resource_tracker" in part for part in proc.cmdline())
    except Exception:  # gone or not ours to read
        return False


def stop_children(wait_s: float = CHILD_WAIT_S) -> int:
    """Terminate every child process of this one (recursively), kill those still alive after
    ``wait_s`` seconds; returns how many were found. Multiprocessing's resource tracker is
    spared: it ignores SIGTERM and exits on its own once its parent has gone."""
    import psutil

    try:
        children = [p for p in psutil.Process().children(recursive=True) if not _is_resource_tracker(p)]
    except psutil.Error:
        return 0
    for p in children:
        try:
            p.terminate()
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(children, timeout=wait_s)
    for p in alive:
        try:
            p.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(alive, timeout=min(wait_s, 0.5))
    return len(children)


def release_semaphores() -> int:
    """Unlink the named semaphores of this process's multiprocessing objects (pool queues,
    events, locks) now, as their finalizers would at a normal interpreter exit; returns how many.

    For the watchdog, which ends the process with ``os._exit`` (no finalizers run): otherwise
    multiprocessing's resource tracker unlinks them after the process is gone and prints
    "UserWarning: resource_tracker: There appear to be N leaked semaphore objects" under the
    command's one-line message. The standard library keeps these finalizers in
    ``multiprocessing.util._finalizer_registry`` with ``SemLock._cleanup`` (unlink, then tell
    the tracker) as their callback; no public call runs only them (``util._run_finalizers``
    would also run the pools' own, which join threads and can block)."""
    released = 0
    try:
        finalizers = list(getattr(util, "_finalizer_registry", {}).values())
    except RuntimeError:  # changed by another thread meanwhile: nothing safe to do
        return 0
    for finalizer in finalizers:
        if getattr(finalizer, "_callback", None) is synchronize.SemLock._cleanup:
            try:
                finalizer()
                released += 1
            except Exception:  # already unlinked, or the tracker is gone: it has nothing to report then
                pass
    return released


class InterruptGuard:
    """Context manager around a command: the signal handlers and the watchdog of the module
    docstring. Use it in the main thread; elsewhere (or nested) it does nothing.

    After a signal, :meth:`stopped` gives the exit code and prints the message once (the
    watchdog uses the same :meth:`_announce`, so the line is never printed twice).
    """

    _active = False

    def __init__(self, grace_s: float = GRACE_S, child_wait_s: float = CHILD_WAIT_S):
        self.grace_s, self.child_wait_s = float(grace_s), float(child_wait_s)
        self.signum: int | None = None
        self.resumable = True  # set by the caller once it knows the command (see resume_message)
        self._on = False
        self._announced = False
        self._lock = threading.Lock()

    # --- handlers (main thread) ---------------------------------------------------------------

    def _handler(self, signum, frame) -> None:
        if self.signum is not None:
            return  # already stopping: the watchdog enforces the deadline
        self.signum = signum
        _received[:] = [signum]
        if _deferring:  # raised when the deferred() block ends
            _pending.append(signum)
            return
        if signum == signal.SIGTERM:
            raise Terminated()
        raise KeyboardInterrupt()

    def __enter__(self) -> "InterruptGuard":
        if threading.current_thread() is not threading.main_thread() or InterruptGuard._active:
            return self
        InterruptGuard._active = self._on = True
        self._r, self._w = os.pipe()
        os.set_blocking(self._w, False)
        self._old_wakeup = signal.set_wakeup_fd(self._w, warn_on_full_buffer=False)
        self._old = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            old = signal.getsignal(sig)
            if old is signal.SIG_IGN:  # e.g. SIGINT of a shell's background job: stays ignored
                continue
            self._old[sig] = old
            signal.signal(sig, self._handler)
        self._old_unraisable = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        self._watchdog = threading.Thread(target=self._watch, name="markerplace-interrupt-watchdog", daemon=True)
        self._watchdog.start()
        return self

    def _unraisable(self, info) -> None:
        """Quiet for the signal's own exception swallowed in a callback; the usual report else."""
        if self.signum is not None and isinstance(info.exc_value, KeyboardInterrupt):
            return
        self._old_unraisable(info)

    def __exit__(self, *exc) -> None:
        if not self._on:
            return
        self._on = InterruptGuard._active = False
        _received.clear()
        sys.unraisablehook = self._old_unraisable
        for sig, old in self._old.items():
            signal.signal(sig, old)
        signal.set_wakeup_fd(self._old_wakeup)
        if self.signum is None:
            os.write(self._w, _STOP)  # no signal: end the watchdog; after one it keeps its deadline
            self._watchdog.join()
            os.close(self._r)
            os.close(self._w)

    # --- after a signal -----------------------------------------------------------------------

    def _announce(self, signum: int) -> None:
        with self._lock:
            if self._announced:
                return
            self._announced = True
        try:
            tty = getattr(sys.stderr, "isatty", lambda: False)()
            # on a terminal the line after the echoed ^C (or a progress bar), in a log file alone
            print(("\n" if tty else "") + resume_message(signum, self.resumable), file=sys.stderr, flush=True)
        except Exception:  # stderr gone (a closed pipe): nothing to tell
            pass

    def stopped(self, err: BaseException) -> int:
        """Clean up after ``err`` (a KeyboardInterrupt that reached the command line): print the
        message once and, after a real signal, stop the children left; returns the exit code."""
        signalled = self.signum is not None
        signum = self.signum or (signal.SIGTERM if isinstance(err, Terminated) else signal.SIGINT)
        self.signum = signum  # further signals are ignored from here on
        _received.clear()  # the clean-up after it must not be cut again
        self._announce(signum)
        if signalled:  # not for a KeyboardInterrupt raised by code: the caller's own children are not ours
            stop_children(self.child_wait_s)
        return exit_code(signum)

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._r, 64)
            except OSError:
                return
            if not data or _STOP in data:
                return
            sigs = [b for b in data if b in (signal.SIGINT, signal.SIGTERM)]
            if sigs:
                break
        signum = self.signum or sigs[0]
        deadline = time.monotonic() + self.grace_s
        while time.monotonic() < deadline:
            time.sleep(0.05)
        # the main thread did not finish in time (stuck in a C call, or an interpreter shutdown hang)
        self._announce(self.signum or signum)
        try:
            stop_children(self.child_wait_s)
            release_semaphores()
            remove_temporary()  # a temporary cache folder (os._exit runs no atexit)
        finally:
            os._exit(exit_code(self.signum or signum))
