"""Logging set-up shared by the CLI and library code (library modules use ``logging.getLogger``)."""

from __future__ import annotations

import logging
import sys


def setup_logging(quiet: bool = False, verbose: bool = False) -> None:
    """Configure the root ``markerplace`` logger to write ``level: message`` lines to stderr."""
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    logger = logging.getLogger("markerplace")
    logger.setLevel(level)
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
        logger.addHandler(handler)
    logger.propagate = False
