"""Renders with markers kept on disk between runs of one evaluation folder.

A testbed image rendered with markers depends only on the image (its set's feature key and
index: scene, pose, imaging settings) and on the markers in its view (id, size and pose of
each). Renders are deterministic, so features keyed by a hash of those are the same whenever
they are computed again: this store keeps them in ``cache/renders/`` so that a later run in the
same folder (another k, another test set, the study's runs, a resumed run, the ceiling's
single-tag runs) only renders what it has not rendered before. It skips work and approximates
nothing. The folder may be deleted at any time; it only costs the renders again.

Layout: ``part_<n>.npz`` files, each a :class:`~markerplace.imaging.features.FeatureSet`'s
arrays plus ``keys`` (N,) str, written atomically as renders arrive (``part_size`` at a time),
so an interrupted run keeps what it rendered. A damaged part is dropped with a warning.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Iterable

import numpy as np

from markerplace.imaging.features import FeatureSet, ImageFeatures
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path

log = logging.getLogger(__name__)

__all__ = ["RenderStore"]


class RenderStore:
    """Image features keyed by content hashes, in part files under ``folder``.

    Args:
        folder: the store's folder (created on the first write).
        part_size: renders per part file.
    """

    def __init__(self, folder: str | Path, part_size: int = 256):
        self.folder = Path(folder)
        self.part_size = int(part_size)
        self._index: dict[str, tuple[Path, int]] | None = None
        self._pending: dict[str, ImageFeatures] = {}
        self._next = 0

    def _scan(self) -> dict[str, tuple[Path, int]]:
        if self._index is None:
            self._index = {}
            for p in sorted(self.folder.glob("part_*.npz")):
                try:
                    with np.load(p, allow_pickle=False) as z:
                        keys = [str(k) for k in z["keys"]]
                except Exception as err:  # noqa: BLE001 - any damage: those renders are made again
                    log.warning("renders: dropping %s (%s)", p, err)
                    run_folder.remove(p)
                    continue
                self._index.update({k: (p, j) for j, k in enumerate(keys)})
                self._next = max(self._next, int(p.stem.split("_")[1]) + 1)
        return self._index

    def __contains__(self, key: str) -> bool:
        return key in self._pending or key in self._scan()

    def __len__(self) -> int:
        return len(set(self._scan()) | set(self._pending))

    def get(self, keys: Iterable[str]) -> dict[str, ImageFeatures]:
        """The stored features of every key of ``keys`` held (others are left out)."""
        index = self._scan()
        out = {k: self._pending[k] for k in keys if k in self._pending}
        by_part: dict[Path, list[tuple[str, int]]] = {}
        for k in keys:
            if k not in out and k in index:
                p, j = index[k]
                by_part.setdefault(p, []).append((k, j))
        for p, wanted in by_part.items():
            with np.load(p, allow_pickle=False) as z:
                fs = FeatureSet(**{n: z[n] for n in FeatureSet.FIELDS})
            for k, j in wanted:  # copies: a held render must not keep its whole part in memory
                f = fs.image(j)
                out[k] = ImageFeatures(f.keypoints.copy(), f.descriptors.copy(), f.points_world.copy(),
                                       f.tag_ids.copy(), f.tag_corners.copy())
        return out

    def put(self, key: str, features: ImageFeatures) -> None:
        """Keep ``features`` under ``key``; written with the next full part or :meth:`flush`."""
        self._pending[key] = ImageFeatures(features.keypoints, features.descriptors, features.points_world,
                                           features.tag_ids, features.tag_corners)
        if len(self._pending) >= self.part_size:
            self.flush()

    def flush(self) -> None:
        """Write the pending renders as one part file (atomically)."""
        if not self._pending:
            return
        index = self._scan()
        keys = list(self._pending)
        fs = FeatureSet.from_images([self._pending[k] for k in keys])
        path = self.folder / f"part_{self._next:06d}.npz"
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, keys=np.asarray(keys), **{n: getattr(fs, n) for n in FeatureSet.FIELDS})
        index.update({k: (path, j) for j, k in enumerate(keys)})
        self._next += 1
        self._pending.clear()
