"""The per-image feature store of the real-photograph testbed: every image's features computed
once, on the executor, and kept on disk.

An image is ``(kind, frame, markers in its view)`` (:mod:`.images`: ``real`` or ``render``);
two placements whose markers in a frame's view are the same share that image (the marker-free
image serves every placement with no marker in view, the nested OMP prefixes share most). Each
image's features are one ``.npz`` in ``folder`` named by the hash of its key and of the
settings, written atomically as they arrive: an interrupted run resumes with what was done.
No pickle: plain arrays.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.imaging.engine import marker_key
from markerplace.imaging.features import ImageFeatures
from markerplace.markers import Marker
from markerplace.progress import progress_bar
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import write_npz
from markerplace.runtime.cache import hash_of
from markerplace.testbed.frames.frame_features import image_task

log = logging.getLogger(__name__)

__all__ = ["ImageKey", "image_key", "FeatureStore"]

ImageKey = tuple
"""``(kind, frame index, markers)``: markers a tuple of :class:`~markerplace.markers.Marker`
sorted by :func:`~markerplace.imaging.engine.marker_key` (only those in the frame's view)."""

MEMORY_IMAGES = 2000
"""Images whose features :meth:`FeatureStore.get` keeps in memory (oldest dropped first)."""
_FIELDS = ("keypoints", "descriptors", "points_world", "tag_ids", "tag_corners")


def image_key(kind: str, frame: int, markers: Sequence[Marker]) -> ImageKey:
    """The canonical key of an image (markers sorted, so the order of a placement does not matter)."""
    return kind, int(frame), tuple(sorted(markers, key=marker_key))


class FeatureStore:
    """Features of images by :data:`ImageKey`, in ``folder`` (module docstring).

    Args:
        folder: where the ``.npz`` files go (created).
        settings_key: hash of everything else an image depends on (frames, imaging, composite).
    """

    def __init__(self, folder: str | Path, settings_key: str):
        self.folder = Path(folder)
        run_folder.make_dirs(self.folder)
        self.settings_key = settings_key
        self._memory: dict[str, ImageFeatures] = {}

    def _path(self, key: ImageKey) -> Path:
        kind, frame, markers = key
        return self.folder / f"{kind}-{frame:06d}-{hash_of(self.settings_key, kind, frame, [marker_key(m) for m in markers])}.npz"

    def has(self, key: ImageKey) -> bool:
        return self._path(key).is_file()

    def get(self, key: ImageKey) -> ImageFeatures:
        """The features of an image computed earlier (:meth:`compute`)."""
        path = self._path(key)
        feats = self._memory.get(path.name)
        if feats is None:
            with np.load(path, allow_pickle=False) as z:
                arrays = {name: z[name] for name in z.files}
            feats = ImageFeatures(*(arrays.pop(f) for f in _FIELDS),
                                  extras={k[len("extra_"):]: v for k, v in arrays.items() if k.startswith("extra_")})
            if len(self._memory) >= MEMORY_IMAGES:  # bounded: a long run touches tens of thousands of images
                self._memory.pop(next(iter(self._memory)))
            self._memory[path.name] = feats
        return feats

    def compute(self, keys: Sequence[ImageKey], executor, job, desc: str, progress: bool = True) -> None:
        """Compute every key not on disk yet, on ``executor`` with ``job`` (:func:`.images.frame_job`)."""
        unique = {self._path(k).name: k for k in keys}  # markers compare by identity: dedupe by content
        todo = [k for name, k in unique.items() if not (self.folder / name).is_file()]
        if len(todo) < len(unique):
            log.info("%s: %d of %d images already computed", desc, len(unique) - len(todo), len(unique))
        if not todo:
            return
        with progress_bar(len(todo), desc, "image", progress) as bar:
            for i, feats in executor.map(image_task, todo, job):
                write_npz(self._path(todo[i]), **{f: getattr(feats, f) for f in _FIELDS},
                          **{f"extra_{k}": np.asarray(v) for k, v in feats.extras.items()})
                bar.update(1)
