"""Watching a Dask cluster while the work runs: no wait without end, no traceback.

Dask's own client waits without limit for a scheduler that has no workers (its tasks sit in
the ``no-worker`` state), and a scheduler that goes away reaches the caller as a
``FuturesCancelledError`` traceback. Here:

* **No worker** (at the start of each map, and whenever no result came for :data:`POLL_S`
  seconds): :func:`wait_for_workers` waits up to ``--cluster-wait`` seconds for a worker to
  join, with a log line when the wait starts and every :data:`PROGRESS_EVERY_S` seconds, then
  stops with one line naming the address and how to start a worker.
* **Workers that leave** while others remain: Dask runs their tasks again on the others (a task
  that was running on :data:`ALLOWED_FAILURES` workers that died is Dask's ``KilledWorker``:
  one line). When none remain, the same bounded wait, then one line.
* **The scheduler goes away**: one line naming its address and how to resume.

Results are handed to the caller as they arrive, before any of these errors, so the caller
keeps what finished (a stage writes its parts; re-running the same command resumes from them).
Every error is a :class:`~markerplace.errors.UserError` (exit code 2); Dask's own logging is
silenced first, so its reconnection tracebacks do not follow the line.
"""

from __future__ import annotations

import logging
import time
from concurrent.futures import CancelledError
from typing import Any, Iterator, Sequence

from markerplace.errors import UserError
from markerplace.runtime.cluster import SCHEDULER_TIMEOUT_S

log = logging.getLogger(__name__)

__all__ = ["CLUSTER_WAIT_S", "POLL_S", "PROGRESS_EVERY_S", "ALLOWED_FAILURES", "SchedulerLost", "lost_scheduler",
           "running_threads",
           "wait_for_workers", "results_as_completed", "silence_dask"]

CLUSTER_WAIT_S = 60.0
"""Default of ``--cluster-wait``: seconds to wait for a Dask worker to join."""
POLL_S = 1.0
"""Seconds without a result after which the cluster's workers are counted again."""
PROGRESS_EVERY_S = 15.0
"""Seconds between the log lines of a wait for workers."""
ALLOWED_FAILURES = 3
"""Dask's ``distributed.scheduler.allowed-failures`` default: a task running on this many workers
that died is given up (``KilledWorker``)."""


class SchedulerLost(Exception):
    """The scheduler does not answer (a closed connection, a timeout, a closed client)."""


def silence_dask() -> None:
    """Dask's logging off: after a fault, its reconnection attempts log tracebacks. Dask's
    logging configuration gives some of its loggers (``distributed.client``, ...) levels of
    their own, so each is set, not only their parent."""
    names = [n for n in list(logging.root.manager.loggerDict) if n == "distributed" or n.startswith("distributed.")]
    for name in ["distributed", *names]:
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _start_hint(address: str) -> str:
    if address.lower().startswith("local:"):
        return "the local cluster's workers could not be restarted (out of memory?)"
    return f"start workers with `dask worker {address} --nthreads 1`"


def lost_scheduler(address: str, progress: str = "") -> UserError:
    """The one line for a scheduler that went away (Dask's logging silenced first)."""
    silence_dask()
    return UserError(f"--cluster {address}: lost the connection to the Dask scheduler{progress}; to resume, start "
                     f"the scheduler and its workers again at {address} and re-run the same command (finished "
                     "stages and the finished parts of this one are reused)")


def running_threads(client) -> int:
    """Threads of the scheduler's running workers (0: none).

    Raises:
        SchedulerLost: the client is closed or the scheduler does not answer within
            :data:`~markerplace.runtime.cluster.SCHEDULER_TIMEOUT_S`.
    """
    if getattr(client, "status", "running") not in ("running", "connecting", "newly-created"):
        raise SchedulerLost(client.status)
    try:
        info = client.sync(client.scheduler.identity, n_workers=-1, callback_timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, CancelledError, RuntimeError) as err:  # comm closed, timeout (an OSError), loop gone
        raise SchedulerLost(str(err)) from None
    return sum(int(w.get("nthreads", 1)) for w in (info.get("workers") or {}).values()
               if str(w.get("status", "running")) == "running")


def wait_for_workers(client, address: str, wait_s: float, after: str = "") -> int:
    """Wait up to ``wait_s`` seconds for a running worker; returns the workers' threads (> 0).

    Args:
        client: a connected ``distributed.Client``.
        address: the ``--cluster`` value, for the messages.
        wait_s: seconds to wait (``--cluster-wait``).
        after: what has been done so far, for the messages (``" (3 of 8 tasks finished)"``).

    Raises:
        UserError: no worker within ``wait_s`` seconds, or the scheduler went away.
    """
    start = time.monotonic()
    next_log = start
    while True:
        try:
            threads = running_threads(client)
        except SchedulerLost:
            raise lost_scheduler(address, after) from None
        if threads:
            if next_log > start:
                log.info("dask: a worker joined %s after %.0f s", address, time.monotonic() - start)
            return threads
        now = time.monotonic()
        if now - start >= wait_s:
            silence_dask()
            what = "every Dask worker left and none joined" if after else "no Dask worker joined the scheduler"
            raise UserError(f"--cluster {address}: {what} within {wait_s:g} s{after}; {_start_hint(address)}, "
                            "then re-run the same command (finished stages and parts are reused), or wait longer "
                            "with --cluster-wait SECONDS")
        if now >= next_log:
            log.info("dask: no worker at %s%s; waiting for one to join (%.0f of %g s, --cluster-wait)", address,
                     after, now - start, wait_s)
            next_log = now + PROGRESS_EVERY_S
        time.sleep(min(POLL_S, max(0.05, wait_s - (now - start))))


def results_as_completed(client, futures: Sequence, address: str, wait_s: float) -> Iterator[Any]:
    """Yield each future's result as it finishes, watching the cluster (see the module docstring).

    Args:
        client: the futures' ``distributed.Client``.
        futures: the submitted tasks.
        address: the ``--cluster`` value, for the messages.
        wait_s: seconds to wait for a worker when none is left (``--cluster-wait``).

    Raises:
        UserError: every worker left for ``wait_s`` seconds, the scheduler went away, or a task
            killed :data:`ALLOWED_FAILURES` workers. A task's own error is raised as it is.
    """
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    n, done = len(futures), 0
    pending = as_completed(futures)
    quiet_since = time.monotonic()
    while not pending.is_empty():
        if not pending.has_ready():
            finished = getattr(pending, "thread_condition", None)  # notified when a future finishes
            if finished is None:
                time.sleep(0.05)
            else:
                with finished:
                    finished.wait(timeout=0.2)
            if pending.has_ready() or time.monotonic() - quiet_since < POLL_S:
                continue
            progress = f" ({done} of {n} tasks finished)"
            try:
                if not running_threads(client):
                    wait_for_workers(client, address, wait_s, after=progress)
            except SchedulerLost:
                raise lost_scheduler(address, progress) from None
            quiet_since = time.monotonic()
            continue
        fut = next(pending)
        try:
            result = fut.result()
        except CancelledError:  # the scheduler went away (Dask cancels every future of the client)
            raise lost_scheduler(address, f" ({done} of {n} tasks finished)") from None
        except KilledWorker:
            silence_dask()
            raise UserError(f"--cluster {address}: a task was running on {ALLOWED_FAILURES} Dask workers that died "
                            f"({done} of {n} tasks finished); out of memory? See the workers' logs, then re-run the "
                            "same command (finished stages and parts are reused)") from None
        except (OSError, TimeoutError):
            try:
                running_threads(client)
            except SchedulerLost:
                raise lost_scheduler(address, f" ({done} of {n} tasks finished)") from None
            raise  # the task's own error: the scheduler still answers
        done += 1
        quiet_since = time.monotonic()
        yield result
