"""The outputs of a run checked against its run folder before any work (``--adopt``).

A run folder markerplace adopted holds files it did not write, and those are never replaced
(:mod:`markerplace.runtime.run_folder`). A file of the user's named like one of the run's outputs
(a ``placement.json`` of their own, a ``tags.pdf``, a folder named ``report.html``) would stop the
run only when it came to write it, after all the work, with half its outputs written.
:func:`refuse_foreign` finds it first: the caller names its outputs as patterns (``fnmatch``, one
folder level each, relative to the run folder: ``"placement.json"``, ``"tags/*_tag*.svg"``) right
after opening the folder; a pattern ending in ``/`` names a folder the run makes (a file there is
refused).
"""

from __future__ import annotations

import fnmatch
import os
from pathlib import Path
from typing import Iterable

from markerplace.errors import UserError
from markerplace.runtime import run_folder

__all__ = ["refuse_foreign"]


def refuse_foreign(path: str | Path, patterns: Iterable[str]) -> None:
    """Raise :class:`UserError` (one line) when an entry below the open run folder ``path``
    matches one of ``patterns`` and is not markerplace's: a file it did not write (the manifest
    says), a folder where it writes a file, or a file where it makes a folder. Outside every open
    run folder nothing is checked."""
    folder = run_folder.find(path)
    if folder is None:
        return
    base = folder.relative(path) or ""
    for pattern in patterns:
        if pattern.endswith("/"):  # a folder the run makes
            pattern = os.path.join(pattern, ".")
        sub, name = os.path.split(pattern)
        rel_dir = os.path.normpath(os.path.join(base, sub)) if sub or base else ""
        where = folder.real / rel_dir
        if rel_dir and os.path.lexists(where) and not where.is_dir():
            raise UserError(f"{folder.option} {folder.path}: {rel_dir} is a file where markerplace makes a folder; move "
                            "it away or choose another folder (checked before any work)")
        try:
            entries = sorted(os.listdir(where))
        except OSError:
            continue  # not there yet: the run makes it
        for entry in entries:
            rel = os.path.join(rel_dir, entry) if rel_dir else entry
            if not fnmatch.fnmatchcase(entry, name) or rel in folder.files:
                continue
            what = "a folder where markerplace writes a file" if (where / entry).is_dir() else \
                "not written by markerplace (the folder was adopted with it in it), so it is not replaced"
            raise UserError(f"{folder.option} {folder.path}: {rel} is {what}: move it away or choose another folder "
                            "(checked before any work)")
