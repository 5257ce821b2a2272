"""Predictions of an evaluation, stored apart from its metrics (glue-factory's eval pipeline):
per placement and test set, the estimated pose of every test image.

``cache/predictions/<key>.npz`` holds ``est`` (N, 4, 4) ``world_from_cam`` estimates (all NaN
where localization failed); its ``.meta.json`` records the key (a hash of the map, the markers,
the test images and the localizer settings) and the method, run, k and test set. Metrics are
computed from these by :func:`markerplace.testbed.reporting.summary.write_outputs`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.runtime.atomic_io import write_npz
from markerplace.runtime import cache

__all__ = ["prediction_path", "load_prediction", "save_prediction"]


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
