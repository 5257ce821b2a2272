"""Fixtures of the report tests: the headless browser (:mod:`helpers.browser`)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def browser():
    """A headless chromium WebDriver, one per module."""
    from helpers.browser import start_browser

    driver = start_browser()
    yield driver
    driver.quit()
