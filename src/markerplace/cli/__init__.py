"""Command line: one module per subcommand group; :func:`main` is the ``markerplace`` entry point."""

from markerplace.cli.main import main

__all__ = ["main"]
