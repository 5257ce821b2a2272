"""Every relative link of the README and docs/ points at a file of the repository and, with a
``#fragment``, at a heading of that file, by GitHub's rule for heading anchors (lower case,
punctuation other than ``-`` dropped, each space a ``-``, ``-1``, ``-2`` ... for repeats), so a
renamed heading or a moved page cannot leave a dead link on the rendered pages."""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading's text (code spans and links as their text)."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.replace("`", "")).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


@lru_cache(maxsize=None)
def anchors(page: Path) -> frozenset[str]:
    """Every heading anchor of ``page`` (headings inside fenced code blocks are not headings)."""
    found: set[str] = set()
    count: dict[str, int] = {}
    fenced = False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"#{1,6}\s+(.*)$", line)
        if m:
            a = github_anchor(m.group(1))
            n = count.get(a, 0)
            count[a] = n + 1
            found.add(a if n == 0 else f"{a}-{n}")
    return frozenset(found)


def test_github_anchor_rule():
    assert github_anchor("Evidence: the office at k = 5 (2000 images per set, 5 + 5 runs)") == \
        "evidence-the-office-at-k--5-2000-images-per-set-5--5-runs"
    assert github_anchor("The `paper` model, [seed](x.md)") == "the-paper-model-seed"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    dead = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):  # http(s), mailto
            continue
        path, _, fragment = target.partition("#")
        dest = (page.parent / path) if path else page
        if not dest.exists():
            dead.append(f"{target} (no such file)")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            dead.append(f"{target} (no such heading)")
    assert not dead, f"{page.relative_to(ROOT)}: dead links: {dead}"
