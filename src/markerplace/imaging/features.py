"""The one feature container: features of many images in flat arrays, a folder of ``.npy`` files.

Image i owns rows ``offsets[i]:offsets[i+1]`` of ``keypoints`` (K, 2) float32 pixels,
``descriptors`` (K, 128) uint8 (OpenCV SIFT values rounded) and ``points_world`` (K, 3) float32
world metres (NaN where the depth gave no point), and tags ``tag_offsets[i]:tag_offsets[i+1]`` of
``tag_ids`` (T,) int32 and ``tag_corners`` (T, 4, 2) float32 pixels (the detector's order: BL, BR, TR, TL). Optional
per-image ``extras`` (e.g. ``candidate_unoccluded`` (N, C) bool) live next to them.

Folders can be memory-mapped (workers read the map database without copying it), and
:class:`FeatureWriter` streams images to disk in parts as they are computed: memory stays
bounded by one part, and an interrupted stage resumes from the parts already written.
"""

from __future__ import annotations

import logging
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import allocate, atomic_path, write_npy

log = logging.getLogger(__name__)

__all__ = ["ImageFeatures", "FeatureSet", "FeatureWriter"]


@dataclass(frozen=True, eq=False)
class ImageFeatures:
    """Features of one image (shapes as in the module docstring, K keypoints, T tags).

    Attributes:
        keypoints, descriptors, points_world, tag_ids, tag_corners: see the module docstring.
        extras: per-image arrays stored with the set (same shape for every image).
    """

    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    tag_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    tag_corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 2), np.float32))
    extras: dict = field(default_factory=dict)

    def with_3d_only(self) -> "ImageFeatures":
        """Only the keypoints that have a 3D point (what a map database keeps)."""
        keep = np.isfinite(self.points_world).all(axis=1)
        return ImageFeatures(self.keypoints[keep], self.descriptors[keep], self.points_world[keep],
                             self.tag_ids, self.tag_corners, self.extras)


_ROWS = (("keypoints", (2,), np.float32), ("descriptors", (128,), np.uint8), ("points_world", (3,), np.float32))
_TAGS = (("tag_ids", (), np.int32), ("tag_corners", (4, 2), np.float32))


@dataclass(frozen=True, eq=False)
class FeatureSet:
    """Features of N images (see the module docstring)."""

    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    offsets: np.ndarray
    tag_ids: np.ndarray
    tag_corners: np.ndarray
    tag_offsets: np.ndarray
    extras: dict = field(default_factory=dict)

    FIELDS = ("keypoints", "descriptors", "points_world", "offsets", "tag_ids", "tag_corners", "tag_offsets")

    def __len__(self) -> int:
        return len(self.offsets) - 1

    @property
    def image_index(self) -> np.ndarray:
        """(K,) int32 image of each keypoint row."""
        return np.repeat(np.arange(len(self), dtype=np.int32), np.diff(self.offsets))

    def image(self, i: int) -> ImageFeatures:
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        ta, tb = int(self.tag_offsets[i]), int(self.tag_offsets[i + 1])
        return ImageFeatures(np.asarray(self.keypoints[a:b]), np.asarray(self.descriptors[a:b]),
                             np.asarray(self.points_world[a:b]), np.asarray(self.tag_ids[ta:tb]),
                             np.asarray(self.tag_corners[ta:tb]), {k: np.asarray(v[i]) for k, v in self.extras.items()})

    @classmethod
    def from_images(cls, images: Sequence[ImageFeatures]) -> "FeatureSet":
        counts = np.array([len(f.keypoints) for f in images], dtype=np.int64)
        tcounts = np.array([len(f.tag_ids) for f in images], dtype=np.int64)

        def cat(name, shape, dtype):
            arrs = [np.asarray(getattr(f, name)).reshape((-1,) + shape) for f in images]
            return np.concatenate(arrs).astype(dtype) if arrs else np.zeros((0,) + shape, dtype)

        extras = {}
        if images and images[0].extras:
            extras = {k: np.stack([np.asarray(f.extras[k]) for f in images]) for k in images[0].extras}
        return cls(*(cat(n, s, d) for n, s, d in _ROWS), np.concatenate([[0], np.cumsum(counts)]),
                   *(cat(n, s, d) for n, s, d in _TAGS), np.concatenate([[0], np.cumsum(tcounts)]), extras)

    def with_images(self, updates: dict[int, ImageFeatures]) -> "FeatureSet":
        """A copy where image i is replaced by ``updates[i]``."""
        return FeatureSet.from_images([updates.get(i) or self.image(i) for i in range(len(self))])

    def save(self, folder: str | Path) -> None:
        """Write one ``.npy`` per array into ``folder`` (each atomically)."""
        folder = Path(folder)
        for name in self.FIELDS:
            write_npy(folder / f"{name}.npy", np.ascontiguousarray(getattr(self, name)))
        for name, arr in self.extras.items():
            write_npy(folder / f"extra_{name}.npy", np.ascontiguousarray(arr))

    @classmethod
    def load(cls, folder: str | Path, mmap: bool = False) -> "FeatureSet":
        folder = Path(folder)
        mode = "r" if mmap else None
        arrays = {n: np.load(folder / f"{n}.npy", mmap_mode=mode, allow_pickle=False) for n in cls.FIELDS}
        extras = {p.stem[len("extra_"):]: np.load(p, mmap_mode=mode, allow_pickle=False)
                  for p in sorted(folder.glob("extra_*.npy"))}
        return cls(**arrays, extras=extras)

    @staticmethod
    def exists(folder: str | Path) -> bool:
        return all((Path(folder) / f"{n}.npy").exists() for n in FeatureSet.FIELDS)


class FeatureWriter:
    """Streams the features of N images into a :class:`FeatureSet` folder.

    Images arrive in any order (:meth:`add`); every ``part_size`` images are written as one
    ``parts/part_<first>.npz`` (atomically). :meth:`done` tells which images earlier, interrupted
    runs already wrote (``key`` must match: a part file records the key it was computed for).
    :meth:`finish` assembles the folder with two passes over the parts (count, then copy into
    memory-mapped ``.npy`` files), so memory stays bounded by one part, and removes the parts.
    """

    def __init__(self, folder: str | Path, num_images: int, key: str, part_size: int = 64):
        self.folder = Path(folder)
        self.parts = self.folder / "parts"
        self.num_images = int(num_images)
        self.key = str(key)
        self.part_size = int(part_size)
        self._buffer: dict[int, ImageFeatures] = {}
        self._dropped: set[Path] = set()
        run_folder.make_dirs(self.parts)

    def _part_files(self) -> list[Path]:
        return sorted(p for p in self.parts.glob("part_*.npz") if p not in self._dropped)

    def done(self) -> set[int]:
        """Images already written by earlier runs with the same key (damaged parts are dropped:
        deleted when markerplace wrote them, else left alone and ignored)."""
        out: set[int] = set()
        for p in self._part_files():
            try:
                with np.load(p, allow_pickle=False) as z:
                    if str(z["key"]) != self.key:
                        raise ValueError("computed for other settings")
                    out.update(int(i) for i in z["images"])
            except Exception as err:  # noqa: BLE001 - any damage: recompute those images
                log.warning("features: dropping %s (%s)", p, err)
                self._dropped.add(p)
                run_folder.remove(p)
        return out

    def add(self, index: int, features: ImageFeatures) -> None:
        self._buffer[int(index)] = features
        if len(self._buffer) >= self.part_size:
            self.flush()

    def flush(self) -> None:
        if not self._buffer:
            return
        idx = sorted(self._buffer)
        fs = FeatureSet.from_images([self._buffer[i] for i in idx])
        arrays = {n: getattr(fs, n) for n in FeatureSet.FIELDS}
        arrays.update({f"extra_{k}": v for k, v in fs.extras.items()})
        with atomic_path(self.parts / f"part_{idx[0]:08d}.npz") as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, images=np.asarray(idx, np.int64), key=np.asarray(self.key), **arrays)
        self._buffer.clear()

    def finish(self) -> FeatureSet:
        """Assemble the folder from all parts (every image must be present) and load it."""
        self.flush()
        files = self._part_files()
        counts = np.zeros(self.num_images, np.int64)
        tcounts = np.zeros(self.num_images, np.int64)
        extra_shapes: dict[str, tuple] = {}
        seen = np.zeros(self.num_images, bool)
        for p in files:
            with np.load(p, allow_pickle=False) as z:
                img = z["images"]
                counts[img] = np.diff(z["offsets"])
                tcounts[img] = np.diff(z["tag_offsets"])
                seen[img] = True
                for name in z.files:
                    if name.startswith("extra_"):
                        extra_shapes[name] = (z[name].shape[1:], z[name].dtype)
        if not seen.all():
            raise RuntimeError(f"features: {int((~seen).sum())} of {self.num_images} images missing in {self.parts}")
        offsets = np.concatenate([[0], np.cumsum(counts)])
        tag_offsets = np.concatenate([[0], np.cumsum(tcounts)])
        shapes = {name: ((int(offsets[-1]),) + shape, dtype) for name, shape, dtype in _ROWS}
        shapes.update({name: ((int(tag_offsets[-1]),) + shape, dtype) for name, shape, dtype in _TAGS})
        shapes.update({name: ((self.num_images,) + shape, dtype) for name, (shape, dtype) in extra_shapes.items()})
        with ExitStack() as stack:  # each array filled in a temporary file, renamed when all are complete
            out = {name: _memmap(stack.enter_context(atomic_path(self.folder / f"{name}.npy")), shape, dtype)
                   for name, (shape, dtype) in shapes.items()}
            self._fill(out, files, offsets, tag_offsets, extra_shapes)
            for arr in out.values():
                arr.flush()
            del out
        write_npy(self.folder / "offsets.npy", offsets)
        write_npy(self.folder / "tag_offsets.npy", tag_offsets)
        run_folder.remove_tree(self.parts)
        return FeatureSet.load(self.folder)

    @staticmethod
    def _fill(out: dict, files: list, offsets: np.ndarray, tag_offsets: np.ndarray, extra_shapes: dict) -> None:
        """Copy every part's rows into the (memory-mapped) arrays ``out``."""
        for p in files:
            with np.load(p, allow_pickle=False) as z:
                img = z["images"]
                po, pt = z["offsets"], z["tag_offsets"]
                for j, i in enumerate(img):
                    for name, _, _ in _ROWS:
                        out[name][offsets[i]:offsets[i + 1]] = z[name][po[j]:po[j + 1]]
                    for name, _, _ in _TAGS:
                        out[name][tag_offsets[i]:tag_offsets[i + 1]] = z[name][pt[j]:pt[j + 1]]
                for name in extra_shapes:
                    out[name][img] = z[name]


def _memmap(path: Path, shape: tuple, dtype) -> np.memmap:
    """A new ``.npy`` file at ``path`` mapped for writing, its blocks reserved (a full disk
    fails here, not with SIGBUS while it is filled)."""
    arr = np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape)
    allocate(path)
    return arr
