"""Shared test set-up: SIGINT as at a terminal, the plans that test modules share, built-in scenes.

Helper modules and constants (``REPO``, ``DATA``, ``FAST``) are in ``tests/helpers``; a folder's
own fixtures are in its ``conftest.py`` (``tests/scan/conftest.py``).

The Ctrl-C tests need the terminal's SIGINT disposition (Python's default handler), in this
process (the in-process guard tests) and in the commands it starts. A shell starts a background
job, and some CI runners start the test command, with SIGINT ignored, which every child would
inherit and which markerplace deliberately keeps (``runtime.interrupt``): the suite restores the
default handler once, so the tests see what a person at a terminal gets.
"""

from __future__ import annotations

import signal

import pytest

from helpers import FAST


@pytest.fixture(scope="session", autouse=True)
def terminal_sigint():
    """SIGINT handled as in an interactive terminal for the whole session (restored after)."""
    old = signal.getsignal(signal.SIGINT)
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if old is signal.SIG_IGN:
        signal.signal(signal.SIGINT, old)


@pytest.fixture(scope="session")
def run_plan(tmp_path_factory):
    """Factory: ``run_plan(k, scene="tiny", options=FAST, folder="plan")`` runs ``markerplace plan
    SCENE -k K --out DIR OPTIONS`` in this process into ``DIR = <fresh temporary folder>/SCENE``,
    asserts exit 0 and returns DIR. A module-scoped fixture calls it once for the plan its tests
    share (each call plans anew: tests may damage or replan their folder)."""

    def run(k: int, *, scene: str = "tiny", options=FAST, folder: str = "plan"):
        from markerplace.cli.main import main

        out = tmp_path_factory.mktemp(folder) / scene
        assert main(["plan", scene, "-k", str(k), "--out", str(out), *options]) == 0
        return out

    return run


@pytest.fixture(scope="module")
def house():
    """The built-in two-storey ``house``, loaded once per module."""
    from markerplace.scene import load_scene

    return load_scene("house")


@pytest.fixture(scope="session")
def tiny_frames(tmp_path_factory):
    """A 40-frame handheld-like RGB-D sequence of ``tiny`` in the markerplace layout
    (:mod:`helpers.frames`), written once per session; returns its folder."""
    from helpers.frames import write_tiny_frames

    return write_tiny_frames(tmp_path_factory.mktemp("frames") / "tiny")


@pytest.fixture(scope="module")
def browser():
    """A headless chromium WebDriver (:mod:`helpers.browser`), one per module."""
    from helpers.browser import start_browser

    driver = start_browser()
    yield driver
    driver.quit()
