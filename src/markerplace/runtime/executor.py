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
  processes. Workers keep their state per job and thread between tasks. A scheduler without
  workers is waited for (``--cluster-wait``), lost workers and a lost scheduler end in one line
  (:mod:`markerplace.runtime.cluster_watch`).

Results do not depend on the backend: every item is computed the same way, and the caller
puts results back in item order.

Stopping: a ``map`` that is left before its last result (Ctrl-C, SIGTERM, an error in the
caller) marks the executor as aborted, and :meth:`Executor.close` then stops the work instead of
waiting for it: the process pool is terminated (its workers get SIGTERM), the Dask futures are
cancelled and a ``LocalCluster`` is closed with short timeouts. Workers of either kind never see
SIGINT (:mod:`markerplace.runtime.workers`, :mod:`markerplace.runtime.interrupt`).
"""

from __future__ import annotations

import logging
import math
import os
import signal
import threading
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Sequence

from markerplace.errors import UserError
from markerplace.runtime.cache_home import cache_root
from markerplace.runtime.cluster import SCHEDULER_TIMEOUT_S, check_scheduler, parse_cluster
from markerplace.runtime.cluster_watch import (
    CLUSTER_WAIT_S,
    SchedulerLost,
    lost_scheduler,
    results_as_completed,
    running_threads,
    silence_dask,
    wait_for_workers,
)
from markerplace.runtime.workers import WORKER_ENV, children_without_sigint, default_workers, single_threaded_libraries, spawn_pool
from markerplace.settings import setting

log = logging.getLogger(__name__)

__all__ = ["RuntimeConfig", "WorkerJob", "Executor", "InProcessExecutor", "PoolExecutor", "DaskExecutor",
           "make_executor"]


_RUN_COMMANDS = ("plan", "evaluate", "study")
"""The commands with ``--cluster`` (``check`` has ``--workers`` only)."""


@dataclass(frozen=True)
class RuntimeConfig:
    """Where per-image work runs.

    Attributes:
        workers: local processes (0 = CPU count, at most 4; 1 = in this process): the one
            ``--workers`` of ``plan``, ``evaluate``, ``study`` and ``check``.
        cluster: None (local processes), ``local:N`` (start a Dask ``LocalCluster`` of N
            workers) or a Dask scheduler address such as ``tcp://10.0.0.5:8786``.
        cluster_wait: with ``cluster``: seconds to wait for a worker when the scheduler has none
            (:func:`markerplace.runtime.cluster_watch.wait_for_workers`).
        batch: items per task (0 = automatic: about four tasks per worker, at most 32 items).
    """

    workers: int = setting(0, flag="--workers", bounds=(0, 256), shown_default="CPUs (max 4)",
                           hint="0 (automatic) or a number of processes, e.g. 2",
                           help="processes for rendering + SIFT, one GL context each (0: the CPU count, at most 4; "
                                "1: in this process); not with --cluster")
    cluster: str | None = setting(None, flag="--cluster", metavar="local:N|tcp://HOST:PORT", commands=_RUN_COMMANDS,
                                  help="run rendering + SIFT on a Dask cluster: local:N starts N local workers (N up "
                                       "to the CPU count), an address (tcp://HOST:PORT, tls://HOST:PORT) uses a "
                                       "running scheduler (results do not depend on where they run)")
    cluster_wait: float = setting(CLUSTER_WAIT_S, flag="--cluster-wait", metavar="SECONDS", bounds=(0, 86400),
                                  commands=_RUN_COMMANDS,
                                  units="s", hint="seconds to wait for a Dask worker, e.g. 60",
                                  help="with --cluster: seconds to wait for a Dask worker when the scheduler has none "
                                       "(when the work starts, or after every worker left) before stopping with an error")
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
    """Runs ``fn(state, item)`` over items; see the module docstring.

    Backends implement :meth:`_map`; :meth:`map` counts the maps not run to their end, so
    :meth:`close` knows whether to wait for the work or to stop it (:attr:`aborted`).
    """

    name = "executor"
    workers = 1

    def __init__(self, batch: int = 0):
        self.batch = batch
        self._aborted = False
        self._unfinished = 0

    @property
    def aborted(self) -> bool:
        """A map was left before its last result (or the ``with`` block raised): stop, do not wait."""
        return self._aborted or self._unfinished > 0

    def batch_size(self, n: int) -> int:
        if self.batch > 0:
            return self.batch
        return max(1, min(32, math.ceil(n / (4 * max(self.workers, 1)))))

    def map(self, fn: Callable, items: Sequence, job: WorkerJob) -> Iterator[tuple[int, Any]]:
        """Yield ``(index, fn(state, items[index]))`` for every item, in completion order."""
        self._unfinished += 1
        yield from self._map(fn, items, job)
        self._unfinished -= 1  # not reached when the caller stops early (an exception, Ctrl-C)

    def _map(self, fn: Callable, items: Sequence, job: WorkerJob) -> Iterator[tuple[int, Any]]:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self._aborted = True
        self.close()


class InProcessExecutor(Executor):
    """Everything in this process, in item order."""

    name = "in-process"

    def _map(self, fn, items, job):
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

    def _map(self, fn, items, job):
        pool = self._pool(job)
        tasks = [(job, fn, b) for b in _batches(items, self.batch_size(len(items)))]
        for results in pool.imap_unordered(_pool_run, tasks):
            yield from results

    def close(self) -> None:
        """Join the pools, or terminate them after an aborted map (see the module docstring)."""
        pools, self._pools = self._pools, {}
        abort = self.aborted
        for ctx, _ in pools.values():
            if abort:  # terminate: SIGTERM to the workers, their unfinished tasks dropped
                ctx.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None)
            else:
                ctx.__exit__(None, None, None)


CLOSE_TIMEOUT_S = 1.0
"""Seconds the Dask client and a ``LocalCluster`` get to close after an aborted map."""


class DaskExecutor(Executor):
    """Tasks on a Dask distributed cluster (an existing scheduler or a ``LocalCluster``).

    The address is checked first (:func:`check_scheduler`: the scheme, a connect and
    handshake timeout); the cluster's event-loop thread and a ``LocalCluster``'s worker
    processes start with SIGINT blocked (:func:`~markerplace.runtime.workers.children_without_sigint`).
    """

    name = "dask"

    def __init__(self, address: str, batch: int = 0, cluster_wait: float = CLUSTER_WAIT_S):
        super().__init__(batch)
        self.address, self.cluster_wait = address, float(cluster_wait)
        try:
            import dask
            from distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover - dependency declared
            raise UserError("--cluster needs dask[distributed]: pip install 'dask[distributed]'") from None
        self._cluster = None
        self.client = None
        kind, n, _ = parse_cluster(address)
        timeouts = {"distributed.comm.timeouts.connect": f"{SCHEDULER_TIMEOUT_S:g}s"}
        logging.getLogger("distributed").setLevel(max(logging.WARNING, logging.getLogger("markerplace").level))
        try:
            if kind == "local":
                env = dict(WORKER_ENV)
                scratch = cache_root()  # the workers' folders there, not in $TMPDIR/dask-scratch-space
                with dask.config.set({"distributed.nanny.pre-spawn-environ": env}), children_without_sigint():
                    self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                 dashboard_address=":0",
                                                 local_directory=None if scratch is None else str(scratch / "dask"))
                    self.client = Client(self._cluster)
            else:
                check_scheduler(address)
                try:
                    with dask.config.set(timeouts), children_without_sigint():
                        self.client = Client(address, timeout=f"{2 * SCHEDULER_TIMEOUT_S:g}s")
                except Exception as err:  # a scheduler that went away, a version clash, ...
                    reason = " ".join(str(err).split())[:200] or type(err).__name__
                    raise UserError(f"--cluster {address}: cannot use the Dask scheduler ({reason})") from None
            try:
                self.workers = running_threads(self.client)  # 0: waited for at the first map
            except SchedulerLost:
                raise lost_scheduler(address) from None
        except BaseException:
            self._aborted = True
            self.close()
            raise
        log.info("dask: %d worker thread(s) at %s", self.workers, self.client.scheduler.address)

    def _map(self, fn, items, job):
        # a scheduler without workers: wait for one (--cluster-wait) before sizing the batches
        self.workers = wait_for_workers(self.client, self.address, self.cluster_wait)
        futures = [self.client.submit(_run_batch, job, fn, b, pure=False)
                   for b in _batches(items, self.batch_size(len(items)))]
        # left early: close() closes the client, the scheduler drops its tasks
        for results in results_as_completed(self.client, futures, self.address, self.cluster_wait):
            yield from results

    def close(self) -> None:
        """Close the worker states, the client and a ``LocalCluster``; after an aborted map
        quickly (no state closing, short timeouts, the cluster's shutdown chatter silenced)."""
        abort = self.aborted
        timeout = CLOSE_TIMEOUT_S if abort else None
        if abort:
            silence_dask()
            self._stop_local_workers()
        if self.client is not None:
            if not abort:
                try:
                    self.client.run(_close_states)
                except Exception:  # pragma: no cover - teardown
                    log.debug("closing dask worker states failed", exc_info=True)
            try:
                self.client.close(timeout=timeout)
            except Exception as err:  # pragma: no cover - teardown (after an abort: the short timeout, one line)
                log.debug("closing the dask client failed: %s", err, exc_info=not abort)
            self.client = None
        if self._cluster is not None:
            try:
                self._cluster.close(timeout=timeout)
            except Exception as err:  # pragma: no cover - teardown (after an abort: the short timeout, one line)
                log.debug("closing the dask cluster failed: %s", err, exc_info=not abort)
            self._cluster = None

    def _stop_local_workers(self) -> None:
        """SIGTERM to a ``LocalCluster``'s worker processes: they stop at once and silently,
        instead of logging the cancellation of the tasks they were running."""
        workers = getattr(self._cluster, "workers", None) or {}
        for nanny in list(workers.values()):
            pid = getattr(getattr(getattr(nanny, "process", None), "process", None), "pid", None)
            if pid:
                try:
                    os.kill(pid, signal.SIGTERM)
                except OSError:
                    pass


def make_executor(config: RuntimeConfig = RuntimeConfig()) -> Executor:
    """The executor ``config`` names (see :class:`RuntimeConfig`)."""
    if config.cluster:
        return DaskExecutor(config.cluster, config.batch, config.cluster_wait)
    workers = default_workers(config.workers)
    if workers <= 1:
        return InProcessExecutor(config.batch)
    return PoolExecutor(workers, config.batch)
