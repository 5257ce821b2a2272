"""Executors: one interface, three backends, for per-image work (render, SIFT, localize).

A stage hands an executor a :class:`WorkerJob` (what each worker builds once and keeps between
tasks: a renderer with its GL context and the loaded scene) and a function
``fn(state, item) -> result`` over a list of items (poses). The executor groups items into
batches (one task each), runs them where it runs them and yields ``(index, result)`` as tasks
finish, so the caller can stream results to disk and drive a progress bar.

Backends (:func:`make_executor`):

* ``InProcessExecutor``: in this process, in order (tests, debugging, ``--workers 1``).
* ``PoolExecutor``: a spawned local process pool (the default, ``--workers N``).
* ``DaskExecutor``: a Dask distributed cluster: ``--cluster tcp://HOST:8786`` uses a running
  scheduler, ``--cluster local:N`` starts a ``LocalCluster`` of N single-threaded worker
  processes. Workers keep their state per job and thread between tasks.

Results do not depend on the backend: every item is computed the same way, and the caller
puts results back in item order.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

from ..errors import UserError
from .workers import THREAD_ENV, default_workers, single_threaded_libraries, spawn_pool

log = logging.getLogger(__name__)

__all__ = ["RuntimeConfig", "WorkerJob", "Executor", "InProcessExecutor", "PoolExecutor", "DaskExecutor",
           "make_executor"]


@dataclass(frozen=True)
class RuntimeConfig:
    """Where per-image work runs.

    Attributes:
        workers: local processes (0 = CPU count, at most 4; 1 = in this process).
        cluster: None (local processes), ``local:N`` (start a Dask ``LocalCluster`` of N
            workers) or a Dask scheduler address such as ``tcp://10.0.0.5:8786``.
        batch: items per task (0 = automatic: about four tasks per worker, at most 32 items).
    """

    workers: int = 0
    cluster: str | None = None
    batch: int = 0


@dataclass(frozen=True, eq=False)
class WorkerJob:
    """The state a worker builds once and reuses between tasks.

    Attributes:
        build: module-level function ``build(spec) -> state`` (run once per worker).
        spec: picklable argument of ``build`` (e.g. the scene spec and imaging settings).
        key: identity of the state: tasks with the same key reuse it.
        close: optional module-level ``close(state)`` run when the executor closes.
    """

    build: Callable[[Any], Any]
    spec: Any
    key: str
    close: Callable[[Any], None] | None = None


# --- worker side: one state per job key (and per thread under Dask) ----------------------------

_STATES: dict = {}
_LOCK = threading.Lock()


def _state(job: WorkerJob):
    """This worker's (and thread's) state for ``job``, built on first use."""
    k = (job.key, threading.get_ident())
    with _LOCK:
        entry = _STATES.get(k)
    if entry is None:
        single_threaded_libraries()
        entry = (job, job.build(job.spec))
        with _LOCK:
            _STATES[k] = entry
    return entry[1]


def _close_states() -> None:
    with _LOCK:
        items = list(_STATES.values())
        _STATES.clear()
    for job, st in items:
        if job.close is not None:
            try:
                job.close(st)
            except Exception:  # pragma: no cover - teardown
                log.debug("closing worker state failed", exc_info=True)


def _run_batch(job: WorkerJob, fn: Callable, batch: list[tuple[int, Any]]) -> list[tuple[int, Any]]:
    state = _state(job)
    return [(i, fn(state, item)) for i, item in batch]


def _pool_init(job: WorkerJob) -> None:
    _state(job)


def _pool_run(args) -> list[tuple[int, Any]]:
    job, fn, batch = args
    return _run_batch(job, fn, batch)


# --- main side ---------------------------------------------------------------------------------


def _batches(items: Sequence, size: int) -> list[list[tuple[int, Any]]]:
    indexed = list(enumerate(items))
    return [indexed[s:s + size] for s in range(0, len(indexed), size)]


class Executor:
    """Runs ``fn(state, item)`` over items; see the module docstring."""

    name = "executor"
    workers = 1

    def __init__(self, batch: int = 0):
        self.batch = batch

    def batch_size(self, n: int) -> int:
        if self.batch > 0:
            return self.batch
        return max(1, min(32, math.ceil(n / (4 * max(self.workers, 1)))))

    def map(self, fn: Callable, items: Sequence, job: WorkerJob) -> Iterator[tuple[int, Any]]:
        """Yield ``(index, fn(state, items[index]))`` for every item, in completion order."""
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class InProcessExecutor(Executor):
    """Everything in this process, in item order."""

    name = "in-process"

    def map(self, fn, items, job):
        state = _state(job)
        for i, item in enumerate(items):
            yield i, fn(state, item)

    def close(self) -> None:
        _close_states()


class PoolExecutor(Executor):
    """A spawned local process pool per job (kept open until :meth:`close`)."""

    name = "process pool"

    def __init__(self, workers: int = 0, batch: int = 0):
        super().__init__(batch)
        self.workers = default_workers(workers)
        self._pools: dict[str, Any] = {}

    def _pool(self, job: WorkerJob):
        if job.key not in self._pools:
            ctx = spawn_pool(self.workers, _pool_init, (job,))
            self._pools[job.key] = (ctx, ctx.__enter__())
        return self._pools[job.key][1]

    def map(self, fn, items, job):
        pool = self._pool(job)
        tasks = [(job, fn, b) for b in _batches(items, self.batch_size(len(items)))]
        for results in pool.imap_unordered(_pool_run, tasks):
            yield from results

    def close(self) -> None:
        pools, self._pools = self._pools, {}
        for ctx, _ in pools.values():
            ctx.__exit__(None, None, None)


class DaskExecutor(Executor):
    """Tasks on a Dask distributed cluster (an existing scheduler or a ``LocalCluster``)."""

    name = "dask"

    def __init__(self, address: str, batch: int = 0):
        super().__init__(batch)
        try:
            import dask
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - dependency declared
            raise UserError("--cluster needs dask[distributed]: pip install 'dask[distributed]'") from None
        self._cluster = None
        if address.startswith("local:"):
            try:
                n = int(address.split(":", 1)[1])
            except ValueError:
                raise UserError(f"--cluster {address!r}: give local:N with N workers, e.g. local:2") from None
            if n < 1:
                raise UserError(f"--cluster {address!r}: N must be at least 1")
            logging.getLogger("distributed").setLevel(max(logging.WARNING, logging.getLogger("markerplace").level))
            env = {k: "1" for k in THREAD_ENV}
            with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                             dashboard_address=":0")
            self.client = Client(self._cluster)
        else:
            try:
                self.client = Client(address, timeout="10s")
            except OSError as err:
                raise UserError(f"--cluster {address}: cannot reach the Dask scheduler ({err}); start one with "
                                "`dask scheduler` and workers with `dask worker ADDRESS --nthreads 1`") from None
        info = self.client.scheduler_info()
        self.workers = max(1, sum(w.get("nthreads", 1) for w in info.get("workers", {}).values()))
        log.info("dask: %d worker thread(s) at %s", self.workers, self.client.scheduler.address)

    def map(self, fn, items, job):
        from distributed import as_completed

        futures = [self.client.submit(_run_batch, job, fn, b, pure=False)
                   for b in _batches(items, self.batch_size(len(items)))]
        for fut in as_completed(futures):
            yield from fut.result()

    def close(self) -> None:
        try:
            self.client.run(_close_states)
        except Exception:  # pragma: no cover - teardown
            log.debug("closing dask worker states failed", exc_info=True)
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(config: RuntimeConfig = RuntimeConfig()) -> Executor:
    """The executor ``config`` names (see :class:`RuntimeConfig`)."""
    if config.cluster:
        return DaskExecutor(config.cluster, config.batch)
    workers = default_workers(config.workers)
    if workers <= 1:
        return InProcessExecutor(config.batch)
    return PoolExecutor(workers, config.batch)
