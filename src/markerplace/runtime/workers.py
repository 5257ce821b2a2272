"""Process pools for per-image work (rendering, SIFT, localization).

Parallelism is across processes, each with its own GL context, so every worker runs its
numerical libraries single-threaded: threaded BLAS / OpenMP / OpenCV on small per-image
problems is several times slower when the workers already fill the cores. Workers are spawned
(not forked) so no GL or BLAS state is inherited.

Signals: a terminal's Ctrl-C (and ``kill -TERM -PGID``) goes to the whole process group, and
only the main process should react (terminate the pool, print how to resume;
:mod:`markerplace.runtime.interrupt`). Pool workers start with SIGINT and SIGTERM blocked
(:func:`children_without_sigint`); :func:`worker_signals` then ignores SIGINT, lets SIGTERM end
the worker only when the main process stops the pool (a worker killed by the group's SIGTERM
would be respawned while the pool is being stopped), and asks the kernel to kill the worker
when the main process dies (even by SIGKILL), so no worker is left behind writing
``BrokenPipeError`` tracebacks.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import multiprocessing as mp
import os
import signal
import sys
import threading
from contextlib import contextmanager
from multiprocessing import resource_tracker
from typing import Callable, Iterator

from markerplace.runtime.heap import keep_freed_memory
from markerplace.runtime.interrupt import deferred

WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "LP_NUM_THREADS": "0"}
"""Environment of spawned workers: one BLAS / OpenMP thread, and Mesa llvmpipe rasterizing in the
drawing thread (``LP_NUM_THREADS=0``; by default it adds a thread per CPU to every worker's GL
context, which only contend with the other workers when they already fill the cores)."""


def default_workers(requested: int = 0, cap: int = 4) -> int:
    """``requested`` if > 0, else the CPU count capped at ``cap``."""
    return requested if requested > 0 else max(1, min(os.cpu_count() or 1, cap))


def single_threaded_libraries() -> None:
    """Call in a worker: one OpenCV thread (BLAS threads are fixed by the spawn environment), and
    freed memory kept for the next image (:func:`markerplace.runtime.heap.keep_freed_memory`)."""
    import cv2

    cv2.setNumThreads(1)
    keep_freed_memory()


@contextmanager
def children_without_sigint(sigterm: bool = False) -> Iterator[None]:
    """Block SIGINT (and with ``sigterm`` SIGTERM) in the calling (main) thread for the duration:
    processes and threads started inside inherit the blocked signals (so a Dask
    ``LocalCluster``'s event-loop thread and the worker processes it spawns never get a
    ``KeyboardInterrupt``; a pool worker unblocks them in :func:`worker_signals`, once its
    handlers are in place). A signal arriving meanwhile reaches the main process as usual
    (another thread takes it, or the main thread when the block ends); nothing is lost."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    # multiprocessing starts its resource tracker on first use and then UNBLOCKS SIGINT and
    # SIGTERM in the thread that started it (instead of restoring the mask): start it now

    resource_tracker.ensure_running()
    blocked = {signal.SIGINT, signal.SIGTERM} if sigterm else {signal.SIGINT}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, blocked)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


_PR_SET_PDEATHSIG = 1


def worker_signals(parent_pid: int, stop) -> None:
    """Call first in a pool worker. SIGINT is ignored: only the main process handles Ctrl-C.
    SIGTERM ends the worker only when the pool is being stopped (``stop``, a multiprocessing
    Event the main process sets before ``Pool.terminate``) or the parent is gone: a SIGTERM
    sent to the whole process group is the main process's to handle, and a worker that died
    of it would be respawned by the pool while the main process stops it. On Linux the kernel
    kills the worker (SIGKILL) when the main process dies, even by SIGKILL.

    Args:
        parent_pid: the main process's pid; a worker whose parent is already gone exits at once.
        stop: the pool's stop event.
    """
    def on_sigterm(signum, frame):
        if stop.is_set() or os.getppid() != parent_pid:
            os._exit(0)

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, on_sigterm)
    if hasattr(signal, "pthread_sigmask"):  # a pending SIGINT was just discarded, a SIGTERM is handled
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl
            pass
    if os.getppid() != parent_pid:
        os._exit(1)  # the parent died before prctl: nobody will read our results


def _worker_init(parent_pid: int, stop, initializer: Callable, initargs: tuple) -> None:
    worker_signals(parent_pid, stop)
    initializer(*initargs)


@contextmanager
def spawn_pool(workers: int, initializer: Callable, initargs: tuple) -> Iterator[mp.pool.Pool]:
    """A spawned pool whose children start with single-threaded BLAS / OpenMP.

    The parent's environment is restored as soon as the children have started. The children
    (and the pool's own threads, which respawn workers) start with SIGINT and SIGTERM blocked
    (:func:`children_without_sigint`) and run :func:`worker_signals` before ``initializer``. On
    an exception in the ``with`` body the pool is terminated (its stop event set, workers sent
    SIGTERM), not joined.
    """
    ctx = mp.get_context("spawn")
    stop = ctx.Event()
    saved = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    pool = None

    def terminate() -> None:
        stop.set()
        pool.terminate()

    try:
        with children_without_sigint(sigterm=True), deferred():  # a signal now would leave half-started workers
            pool = ctx.Pool(workers, initializer=_worker_init, initargs=(os.getpid(), stop, initializer, initargs))
    except BaseException:
        if pool is not None:  # the signal held while the pool started: stop it
            terminate()
            pool.join()
        raise
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    try:
        yield pool
        pool.close()
    except BaseException:
        terminate()
        raise
    finally:
        pool.join()
