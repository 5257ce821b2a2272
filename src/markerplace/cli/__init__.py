"""Command line: one module per subcommand group; :func:`main` is the ``markerplace`` entry point."""

from .main import main

__all__ = ["main"]
