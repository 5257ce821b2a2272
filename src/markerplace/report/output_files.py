"""Extra files of a plan folder, each a registered :class:`OutputFile`.

A plan writes its built-in outputs (:func:`markerplace.report.plan_outputs.write_plan_outputs`:
placement.json, tags.pdf, tagmaps/, report.html, ...), then one file per class registered in
:data:`OUTPUT_FILES`, in registration order: ``file`` (its name in the plan folder) written
atomically by :meth:`OutputFile.write` from a :class:`PlanOutputs` (the placed tags as
placement.json has them, user frame). Its name is claimed like the built-in outputs' before any
work (:func:`markerplace.pipelines.plan.plan_outputs`). Adding one: a subclass with ``name``,
``summary``, ``file`` and :meth:`~OutputFile.write`, decorated ``@OUTPUT_FILES.register`` in a
module the plan imports (``tests/test_extensions.py`` registers a toy).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Sequence

from markerplace.registry import Registry
from markerplace.runtime.atomic_io import atomic_path

__all__ = ["OUTPUT_FILES", "OutputFile", "PlanOutputs", "output_file_patterns", "write_output_files"]

OUTPUT_FILES = Registry("output file", "plan")
"""Every extra plan output by name, in the order they are written."""


@dataclass(frozen=True)
class PlanOutputs:
    """What an output file may read (user frame: z up, metres, the model file's coordinates).

    Attributes:
        scene: the scene argument (built-in name or mesh path).
        method: the placement method.
        records: placement.json's marker records, in placement order.
        markers: the placed :class:`~markerplace.markers.Marker` list, in placement order.
        existing: the ``--existing`` markers.
        summary: placement.json's ``summary`` object.
    """

    scene: str
    method: str
    records: Sequence[dict]
    markers: Sequence
    existing: Sequence
    summary: dict


class OutputFile:
    """Base class of an extra plan output (subclass it and register it)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    file: ClassVar[str] = ""
    """Its path in the plan folder (no wildcards)."""

    @dataclass(frozen=True)
    class Config:
        """No settings."""

    default_conf: ClassVar = Config()

    def write(self, path: Path, outputs: PlanOutputs) -> None:
        """Write the file at ``path`` (a temporary name, renamed to ``file`` once written)."""
        raise NotImplementedError


def output_file_patterns() -> list[str]:
    """The files of the registered outputs (for :func:`markerplace.runtime.claims.refuse_foreign`)."""
    return [cls.file for cls in OUTPUT_FILES.values()]


def write_output_files(out_dir: str | Path, outputs: PlanOutputs) -> list[Path]:
    """Write every registered output file into ``out_dir``, atomically; returns their paths."""
    written = []
    for cls in OUTPUT_FILES.values():
        path = Path(out_dir) / cls.file
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            cls().write(Path(tmp), outputs)
        written.append(path)
    return written
