"""Marker models: the information a marker seen from a camera pose adds to that pose.

A marker model turns "camera ``world_from_cam`` sees the tag ``world_from_marker`` of edge
``size``" into a 6x6 information matrix ``M`` in the camera tangent space (omega, nu), the same
space as :func:`markerplace.plan.score.localizability.pose_information` (right perturbation
``T' = T Exp(xi)``, GTSAM's ``Pose3`` convention; units 1/rad^2 and 1/m^2). The planner adds
``M`` to ``Lambda`` at every pose that sees the marker (visibility is decided elsewhere:
:func:`~markerplace.plan.score.localizability.marker_visibility` and rendered occlusion).

Models are chosen by name (``--marker-model``) from :data:`MARKER_MODELS`:

* ``paper``: :class:`PaperModel`, the paper's relative-pose factor (docs/design.md section 4);
* ``corners``: :class:`CornersModel`, the tag's 4 corners as known 3D points.

Adding a model: write a :class:`MarkerModel` subclass in this file with ``name``, ``summary``,
a frozen ``Config`` (its own settings, documented defaults), ``default_conf = Config()`` and
:meth:`MarkerModel.information`, decorated with ``@MARKER_MODELS.register``. The CLI choices,
help and validation pick it up from the registry; its test goes next to
``tests/plan/score/test_marker_models.py``. Noise shared by every model (pixel sigma, the paper model's
relative-pose and prior sigmas) stays in :class:`~markerplace.plan.score.localizability.NoiseConfig`,
the one home of the synthetic problem's noise (docs/design.md section 3).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from markerplace.geometry import invert, marker_corners_local
from markerplace.plan.score.localizability import NoiseConfig, gram, whitened_jacobians
from markerplace.registry import Registry, configure

log = logging.getLogger(__name__)

#: Every marker model by name, in registration order (``--marker-model``).
MARKER_MODELS = Registry("marker model", "--marker-model")


class MarkerModel:
    """Base class of marker models; instances are built with ``cls(noise, **conf_overrides)``.

    Attributes:
        name: registry name (class attribute).
        summary: a few words for help texts (class attribute).
        default_conf: the model's own settings (class attribute, a frozen ``Config``).
        noise: the noise of the localization problem (:class:`NoiseConfig`).
        conf: ``default_conf`` with the overrides given at construction.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""

    @dataclass(frozen=True)
    class Config:
        """No settings of its own."""

    default_conf: ClassVar = Config()

    def __init__(self, noise: NoiseConfig | None = None, **conf):
        self.noise = NoiseConfig() if noise is None else noise
        self.conf = configure(self.default_conf, conf)

    def information(self, world_from_cam: np.ndarray, world_from_marker: np.ndarray, size: float,
                    K: np.ndarray) -> np.ndarray:
        """Camera information from one marker at every given pose.

        Args:
            world_from_cam: (N, 4, 4) camera poses (OpenCV camera, metres).
            world_from_marker: (4, 4) marker pose (origin at the tag centre, z out of the wall).
            size: black-square edge, metres.
            K: (3, 3) pinhole camera matrix, pixels.

        Returns:
            (N, 6, 6) symmetric PSD information matrices in the camera tangent space (omega, nu).
            Visibility is the caller's business; a model may still return 0 where the tag could
            not be detected (e.g. too small in the image).
        """
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.conf})"


def get_marker_model(name: str, noise: NoiseConfig | None = None, **conf) -> MarkerModel:
    """The marker model registered as ``name``, with ``noise`` and ``conf`` overrides of its
    ``default_conf``.

    Raises:
        UserError: unknown name (one line listing the known ones).
    """
    return MARKER_MODELS.lookup(name)(noise, **conf)


@MARKER_MODELS.register
class PaperModel(MarkerModel):
    """The paper's model (docs/design.md section 4, 'paper').

    Graph: ``BetweenFactorPose3(cam, marker, cam_from_marker, sigma_rel)`` plus
    ``PriorFactorPose3(marker, sigma_prior)``. The between error lives in the marker's tangent
    space: ``e = xi_m - Ad(marker_from_cam) xi_c``. Marginalizing ``xi_m`` gives::

        M = A^T (Sigma_rel + Sigma_prior)^-1 A,   A = Ad(marker_from_cam)
          = (Ad(cam_from_marker) (Sigma_rel + Sigma_prior) Ad(cam_from_marker)^T)^-1

    with ``sigma_rel = noise.marker_rel_sigma`` and ``sigma_prior = noise.marker_prior_sigma``
    on all 6 components. Its noise does not depend on distance, tag size or K: ``ln det M`` is
    the same at every distance (``det A = 1``), only the direction of the information changes.
    Tested against GTSAM's marginal covariance in ``tests/plan/score/test_localizability_gtsam.py``.
    """

    name = "paper"
    summary = "relative-pose factor, as published"

    @dataclass(frozen=True)
    class Config:
        """No settings of its own: its sigmas are ``NoiseConfig.marker_rel_sigma`` and
        ``NoiseConfig.marker_prior_sigma``."""

    default_conf = Config()

    def information(self, world_from_cam: np.ndarray, world_from_marker: np.ndarray, size: float = 0.0,
                    K: np.ndarray | None = None) -> np.ndarray:
        """(N, 6, 6) information of the (N, 4, 4) poses from the (4, 4) marker; ``size`` and
        ``K`` are not used (see the class docstring)."""
        T = np.asarray(world_from_cam, dtype=float).reshape(-1, 4, 4)
        marker_from_cam = np.matmul(invert(np.asarray(world_from_marker, dtype=float))[None], T)
        R = marker_from_cam[:, :3, :3]
        t = marker_from_cam[:, :3, 3]
        # Batched adjoint in (omega, nu) order: [[R, 0], [[t]x R, R]].
        A = np.zeros((T.shape[0], 6, 6))
        A[:, :3, :3] = R
        A[:, 3:, 3:] = R
        tx = np.zeros((T.shape[0], 3, 3))
        tx[:, 0, 1], tx[:, 0, 2] = -t[:, 2], t[:, 1]
        tx[:, 1, 0], tx[:, 1, 2] = t[:, 2], -t[:, 0]
        tx[:, 2, 0], tx[:, 2, 1] = -t[:, 1], t[:, 0]
        A[:, 3:, :3] = np.matmul(tx, R)
        w = 1.0 / (self.noise.marker_rel_sigma**2 + self.noise.marker_prior_sigma**2)
        return w * np.matmul(np.swapaxes(A, 1, 2), A)


#: Default smallest projected tag edge, pixels, for the 'corners' model to count a detection.
#: AprilTag tag36h11 has 8x8 cells (6x6 data + border) inside the black square edge; below about
#: 10 px per edge (~1.25 px per cell) detection becomes unreliable.
MIN_SIDE_PX = 10.0


@MARKER_MODELS.register
class CornersModel(MarkerModel):
    """The tag's 4 corners as exactly known 3D points (docs/design.md section 4, 'corners').

    The corners of the black square are measured with pixel noise ``noise.pixel_sigma``:
    ``M = sum_corners J^T J / sigma_px^2`` (the landmark whitening of
    :mod:`markerplace.plan.score.localizability` with zero landmark variance). A pose gets ``M = 0``
    when any corner is behind the camera (z <= 1e-6 m) or outside the image, or when the
    shortest projected edge of the tag is below ``min_side_px`` pixels (too small to detect).
    Depends on distance, viewing angle and tag size.
    """

    name = "corners"
    summary = "projected tag corners; depends on distance, viewing angle and tag size"

    @dataclass(frozen=True)
    class Config:
        """Settings of the corners model.

        Attributes:
            min_side_px: detection threshold on the shortest projected tag edge, pixels
                (default :data:`MIN_SIDE_PX` = 10).
            image_size: (width, height) in pixels; None (default) = ``(2 cx, 2 cy)`` from K. A
                corner is inside when ``0 <= u <= width`` and ``0 <= v <= height``.
        """

        min_side_px: float = MIN_SIDE_PX
        image_size: tuple[float, float] | None = None

    default_conf = Config()

    def information(self, world_from_cam: np.ndarray, world_from_marker: np.ndarray, size: float,
                    K: np.ndarray) -> np.ndarray:
        """(N, 6, 6) information of the (N, 4, 4) poses from the (4, 4) marker of edge ``size``
        (metres) seen through the (3, 3) camera matrix ``K``."""
        T = np.asarray(world_from_cam, dtype=float).reshape(-1, 4, 4)
        N = T.shape[0]
        image_size = self.conf.image_size
        if image_size is None:
            image_size = (2.0 * K[0, 2], 2.0 * K[1, 2])
        W, H = float(image_size[0]), float(image_size[1])
        corners_w = marker_corners_local(size) @ np.asarray(world_from_marker)[:3, :3].T \
            + np.asarray(world_from_marker)[:3, 3]
        p_c = np.matmul(corners_w[None] - T[:, None, :3, 3], T[:, :3, :3])  # (N, 4, 3)
        z = p_c[..., 2]
        front = z > 1e-6
        zs = np.where(front, z, 1.0)
        uv = p_c[..., :2] / zs[..., None] * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
        inside = (uv[..., 0] >= 0) & (uv[..., 0] <= W) & (uv[..., 1] >= 0) & (uv[..., 1] <= H)
        edges = np.linalg.norm(uv - np.roll(uv, -1, axis=1), axis=-1)  # (N, 4)
        ok = np.all(front & inside, axis=1) & (edges.min(axis=1) >= self.conf.min_side_px)
        valid = np.broadcast_to(ok[:, None], (N, 4))
        G = whitened_jacobians(p_c[..., 0], p_c[..., 1], z, 0.0, valid, K, self.noise.pixel_sigma)
        return gram(G)


__all__ = ["MARKER_MODELS", "MIN_SIDE_PX", "CornersModel", "MarkerModel", "PaperModel", "get_marker_model"]
