"""Predictions of an evaluation, stored apart from its metrics (glue-factory's eval pipeline):
per placement and test set, the estimated pose of every test image.

``cache/predictions/<key>.npz`` holds ``est`` (N, 4, 4) ``world_from_cam`` estimates (all NaN
where localization failed); its ``.meta.json`` records the key (a hash of the map, the markers,
the test images and the localizer settings) and the method, run, k and test set. Metrics are
computed from these by :func:`markerplace.testbed.reporting.summary.write_outputs`.

While one (placement, image set) is being localized, :class:`PartialPrediction` commits the
estimates as they arrive to ``<key>.partial.npz`` (every ``every`` images, atomically), so an
interrupted localization resumes with the images it had not finished; the file is removed once
the whole prediction is saved.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.runtime import cache, run_folder
from markerplace.runtime.atomic_io import write_npz

log = logging.getLogger(__name__)

__all__ = ["prediction_path", "load_prediction", "save_prediction", "PartialPrediction", "COMMIT_EVERY"]

COMMIT_EVERY = 128
"""Estimates per commit of an unfinished prediction (an interruption loses at most this many)."""


def prediction_path(folder: str | Path, key: str) -> Path:
    return Path(folder) / f"{key}.npz"


def load_prediction(folder: str | Path, key: str) -> np.ndarray | None:
    """The (N, 4, 4) estimates stored under ``key``, or None when missing or damaged."""
    def read(path: Path) -> np.ndarray:
        with np.load(path, allow_pickle=False) as f:
            return f["est"]

    return cache.load_fresh(prediction_path(folder, key), key, read)


def save_prediction(folder: str | Path, key: str, est: np.ndarray, **meta) -> None:
    """Store (N, 4, 4) estimates under ``key`` (atomically), with ``meta`` in the meta file."""
    path = prediction_path(folder, key)
    write_npz(path, est=np.asarray(est, np.float64))
    cache.mark_done(path, key, **meta)


class PartialPrediction:
    """The estimates of one unfinished prediction, committed in chunks (see the module docstring).

    Args:
        folder: the predictions folder.
        key: the prediction's key (:func:`save_prediction`'s).
        every: estimates per commit (default :data:`COMMIT_EVERY`).
    """

    def __init__(self, folder: str | Path, key: str, every: int | None = None):
        self.path = Path(folder) / f"{key}.partial.npz"
        self.key, self.every = str(key), int(COMMIT_EVERY if every is None else every)
        self._est: dict[int, np.ndarray] = {}
        self._new = 0

    def done(self) -> dict[int, np.ndarray]:
        """Image index -> (4, 4) estimate of every image an earlier, interrupted run committed
        (a damaged or foreign file is dropped with a warning)."""
        if not self.path.exists():
            return {}
        try:
            with np.load(self.path, allow_pickle=False) as z:
                if str(z["key"]) != self.key:
                    raise ValueError("made for another prediction")
                self._est = {int(i): np.asarray(e, np.float64) for i, e in zip(z["images"], z["est"])}
        except Exception as err:  # noqa: BLE001 - any damage: those images are localized again
            log.warning("predictions: dropping %s (%s)", self.path, err)
            run_folder.remove(self.path)
            self._est = {}
        return dict(self._est)

    def add(self, index: int, est: np.ndarray) -> None:
        """Keep image ``index``'s (4, 4) estimate; committed with every ``every``-th one."""
        self._est[int(index)] = np.asarray(est, np.float64)
        self._new += 1
        if self._new >= self.every:
            self.flush()

    def flush(self) -> None:
        """Write every estimate held so far (atomically)."""
        if self._new:
            idx = sorted(self._est)
            write_npz(self.path, key=np.asarray(self.key), images=np.asarray(idx, np.int64),
                      est=np.stack([self._est[i] for i in idx]).reshape(-1, 4, 4))
            self._new = 0

    def discard(self) -> None:
        """Remove the file (the whole prediction is saved)."""
        run_folder.remove(self.path)
        self._est, self._new = {}, 0
