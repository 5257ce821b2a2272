"""Set-up of the scan tests (``fuse``, simulated scans), which read the CLI's one-line errors."""

from __future__ import annotations

import logging

import pytest


@pytest.fixture(autouse=True)
def _log_to_this_tests_stderr():
    """The CLI's log handler binds sys.stderr once; rebind it to this test's captured stream."""
    logger = logging.getLogger("markerplace")
    saved = logger.handlers[:]
    logger.handlers.clear()
    yield
    logger.handlers[:] = saved
