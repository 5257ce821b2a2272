"""Progress of long loops: a live bar on a terminal, periodic log lines in a log file.

A tqdm bar rewrites its line with carriage returns, which is what a person at a terminal wants
and what a log file of a multi-hour ``evaluate`` (``nohup ... > run.log``, CI) does not: there
each refresh becomes more text on one endless line. :func:`progress_bar` picks per call: a tqdm
bar when stderr is a terminal, otherwise a :class:`LogProgress` that writes one ``INFO`` line
(done / total, rate, time left) at most every ``interval_s`` seconds and one when the loop ends.

Both time the rate from the first finished item on: what comes before it is start-up (worker
processes, GL contexts, the scene upload), which would otherwise make the first estimate of
the time left many times too long.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Iterable, Iterator, TypeVar

from markerplace.runtime.interrupt import raise_if_stopping

log = logging.getLogger("markerplace.progress")

__all__ = ["progress_bar", "track", "LogProgress", "LOG_INTERVAL_S", "format_duration"]

LOG_INTERVAL_S = 60.0
"""Seconds between two progress lines in a log (not a terminal)."""

T = TypeVar("T")


def format_duration(seconds: float) -> str:
    """A time span as a person writes it: ``75.2`` -> ``'1 min 15 s'``; under a minute ``'42 s'``;
    from an hour ``'2 h 05 min'``. The one formatter of durations in logs and messages."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class LogProgress:
    """Counts done items and logs ``desc: done/total unit (p %), rate, about T left`` at
    most every ``interval_s`` seconds (and ``desc: starting, ...`` at debug level), then ``desc: total unit in T`` when closed (not when the
    ``with`` block ends in an exception, e.g. Ctrl-C); the same ``update``/context-manager
    interface as a tqdm bar.

    Args:
        total: number of items, >= 0.
        desc: what is counted (the log line's prefix).
        unit: name of one item (``img``, ``pose``, ``frame``).
        initial: items already done before this run (a resumed stage); not in the rate.
        interval_s: seconds between two lines; ``clock`` (seconds, monotonic) is for tests.
    """

    def __init__(self, total: int, desc: str, unit: str, initial: int = 0, interval_s: float = LOG_INTERVAL_S,
                 clock=time.monotonic):
        self.total, self.desc, self.unit = int(total), desc, unit
        self.n = self._start_n = int(initial)
        self.interval_s, self._clock = float(interval_s), clock
        self._t0 = self._last = self._started = clock()
        self._closed = False
        self._warm = False
        log.debug("%s: starting, %d/%d %s", desc, self.n, self.total, unit)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more done items; log a line when ``interval_s`` has passed since the last."""
        raise_if_stopping()
        self.n += int(n)
        now = self._clock()
        if not self._warm:  # the rate starts at the first finished item (see the module docstring)
            self._warm = True
            self._start_n, self._t0 = self.n, now
            return
        if now - self._last >= self.interval_s and self.n < self.total:
            self._last = now
            rate = (self.n - self._start_n) / max(now - self._t0, 1e-9)
            left = (self.total - self.n) / rate if rate > 0 else float("inf")
            eta = f", about {format_duration(left)} left" if left != float("inf") else ""
            speed = f"{rate:.1f} {self.unit}/s" if rate >= 1.0 else f"{1.0 / max(rate, 1e-9):.1f} s/{self.unit}"
            log.info("%s: %d/%d %s (%.0f %%), %s%s", self.desc, self.n, self.total, self.unit,
                     100.0 * self.n / max(self.total, 1), speed, eta)

    def close(self) -> None:
        """Log the closing line once (with the time this run took), if anything was done."""
        if self._closed:
            return
        self._closed = True
        if self._warm:
            log.info("%s: %d/%d %s in %s", self.desc, self.n, self.total, self.unit,
                     format_duration(self._clock() - self._started))

    def __enter__(self) -> "LogProgress":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:  # stopped (Ctrl-C, an error): no "done" line for a loop that was not
            self._closed = True
            return
        self.close()


class _NoProgress:
    """What :func:`progress_bar` returns when progress is off: counts nothing, shows nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> "_NoProgress":
        return self

    def __exit__(self, *exc) -> None:
        pass


def progress_bar(total: int, desc: str, unit: str, enabled: bool = True, initial: int = 0):
    """A progress counter for a loop of ``total`` items (use as a context manager, ``update()``
    per item): a tqdm bar on a terminal, :class:`LogProgress` lines when stderr is not one
    (a log file), nothing when ``enabled`` is False (``--quiet``)."""
    if not enabled:
        return _NoProgress()
    isatty = getattr(sys.stderr, "isatty", None)
    if isatty is not None and isatty():
        return _terminal_bar(total, desc, unit, initial)
    return LogProgress(total, desc, unit, initial=initial)


def _terminal_bar(total: int, desc: str, unit: str, initial: int):
    """A tqdm bar whose rate and time left start at the first finished item."""
    from tqdm import tqdm

    class _Bar(tqdm):
        _warm = False

        def update(self, n=1):
            raise_if_stopping()
            if self._warm:
                return super().update(n)
            self._warm = True
            self.n += n
            self.initial += n  # done during start-up: not in the rate
            self.start_t = self.last_print_t = self._time()
            self.last_print_n = self.n
            self.refresh()
            return True

    return _Bar(total=total, initial=initial, desc=desc, unit=unit, leave=False)


def track(items: Iterable[T], desc: str, unit: str, enabled: bool = True, total: int | None = None) -> Iterator[T]:
    """Yield ``items`` while counting them with :func:`progress_bar` (``total`` defaults to
    ``len(items)``)."""
    if total is None:
        total = len(items)  # type: ignore[arg-type]
    with progress_bar(total, desc, unit, enabled) as bar:
        for item in items:
            yield item
            bar.update()
