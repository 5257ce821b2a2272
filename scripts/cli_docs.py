"""Rewrite the option tables of docs/cli.md from the parser and the config fields.

Usage: ``python scripts/cli_docs.py`` (rewrites docs/cli.md) or ``python scripts/cli_docs.py
--check`` (exit code 1 when docs/cli.md is out of date). The tables sit between
``<!-- options:plan -->`` / ``<!-- /options:plan -->`` (and ``evaluate``) markers;
:mod:`markerplace.cli.option_docs` makes them.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from markerplace.cli.option_docs import rewrite

log = logging.getLogger("cli_docs")

DOCS = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check that docs/cli.md is up to date")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    text = DOCS.read_text(encoding="utf-8")
    new = rewrite(text)
    if new == text:
        log.info("%s is up to date", DOCS)
        return 0
    if args.check:
        log.error("%s is out of date: run python scripts/cli_docs.py", DOCS)
        return 1
    DOCS.write_text(new, encoding="utf-8")
    log.info("rewrote the option tables of %s", DOCS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
