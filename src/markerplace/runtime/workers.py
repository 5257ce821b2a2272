"""Process pools for per-image work (rendering, SIFT, localization).

Parallelism is across processes, each with its own GL context, so every worker runs its
numerical libraries single-threaded: threaded BLAS / OpenMP / OpenCV on small per-image
problems is several times slower when the workers already fill the cores. Workers are spawned
(not forked) so no GL or BLAS state is inherited.
"""

from __future__ import annotations

import multiprocessing as mp
import os
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
def spawn_pool(workers: int, initializer: Callable, initargs: tuple) -> Iterator[mp.pool.Pool]:
    """A spawned pool whose children start with single-threaded BLAS / OpenMP.

    The parent's environment is restored as soon as the children have started.
    """
    saved = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update({k: "1" for k in THREAD_ENV})
    try:
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
