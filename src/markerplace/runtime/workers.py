"""Process pools for per-image work (rendering, SIFT, localization).

Parallelism is across processes, each with its own GL context, so every worker runs its
numerical libraries single-threaded: threaded BLAS / OpenMP / OpenCV on small per-image
problems is several times slower when the workers already fill the cores. Workers are spawned
(not forked) so no GL or BLAS state is inherited.

Workers never see SIGINT: a terminal's Ctrl-C goes to the whole process group, and only the
main process should react (terminate the pool, print how to resume;
:mod:`markerplace.runtime.interrupt`). Children started inside :func:`children_without_sigint`
inherit a blocked SIGINT, and the pool initializer :func:`worker_signals` ignores it for good and
asks the kernel to end the worker when the main process dies (even by SIGKILL), so no worker is
left behind writing ``BrokenPipeError`` tracebacks.
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
from typing import Callable, Iterator

THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def default_workers(requested: int = 0, cap: int = 4) -> int:
    """``requested`` if > 0, else the CPU count capped at ``cap``."""
    return requested if requested > 0 else max(1, min(os.cpu_count() or 1, cap))


def single_threaded_libraries() -> None:
    """Call in a worker: one OpenCV thread (BLAS threads are fixed by the spawn environment)."""
    import cv2

    cv2.setNumThreads(1)


@contextmanager
def children_without_sigint() -> Iterator[None]:
    """Block SIGINT in the calling (main) thread for the duration: processes and threads started
    inside inherit the blocked signal (so a Dask ``LocalCluster``'s event-loop thread and the
    worker processes it spawns never get a ``KeyboardInterrupt``). A SIGINT arriving meanwhile
    is delivered to the main process as usual (another thread takes it, or the main thread when
    the block ends); nothing is lost."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    # multiprocessing starts its resource tracker on first use and then UNBLOCKS SIGINT in the
    # thread that started it (instead of restoring the mask): start it now, outside the block
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


_PR_SET_PDEATHSIG = 1


def worker_signals(parent_pid: int | None = None) -> None:
    """Call first in a worker process: ignore SIGINT (only the main process handles Ctrl-C) and,
    on Linux, receive SIGTERM when the parent dies, so a killed main process leaves no worker.

    Args:
        parent_pid: the main process's pid; a worker whose parent is already gone exits at once.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # a pending SIGINT was just discarded
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # pragma: no cover - no prctl
        return
    if parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)  # the parent died before prctl: nobody will read our results


@contextmanager
def spawn_pool(workers: int, initializer: Callable, initargs: tuple) -> Iterator[mp.pool.Pool]:
    """A spawned pool whose children start with single-threaded BLAS / OpenMP.

    The parent's environment is restored as soon as the children have started. The children
    (and the pool's own threads, which respawn workers) start with SIGINT blocked
    (:func:`children_without_sigint`); ``initializer`` should call :func:`worker_signals`. On an
    exception in the ``with`` body the pool is terminated (workers get SIGTERM), not joined.
    """
    saved = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update({k: "1" for k in THREAD_ENV})
    try:
        with children_without_sigint():
            pool = mp.get_context("spawn").Pool(workers, initializer=initializer, initargs=initargs)
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
        pool.terminate()
        raise
    finally:
        pool.join()
