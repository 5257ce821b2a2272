"""Shared test set-up.

The Ctrl-C tests need the terminal's SIGINT disposition (Python's default handler), in this
process (the in-process guard tests) and in the commands it starts. A shell starts a background
job, and some CI runners start the test command, with SIGINT ignored, which every child would
inherit and which markerplace deliberately keeps (``runtime.interrupt``): the suite restores the
default handler once, so the tests see what a person at a terminal gets.
"""

from __future__ import annotations

import signal

import pytest


@pytest.fixture(scope="session", autouse=True)
def terminal_sigint():
    """SIGINT handled as in an interactive terminal for the whole session (restored after)."""
    old = signal.getsignal(signal.SIGINT)
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, old)
