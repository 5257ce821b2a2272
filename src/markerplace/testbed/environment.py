"""What a result was computed with: Python, the libraries its numbers depend on, and the GL
renderer.

Recall is measured on renders described by SIFT and localized by OpenCV: another OpenCV, NumPy,
FAISS or Mesa version can draw or describe a few pixels differently and flip a few test images,
so an evaluation's ``config.json`` records these next to its settings. ``make setup`` installs
the exact versions of ``constraints.txt``; this record says which ones a result really used.
"""

from __future__ import annotations

import logging
import platform
from importlib import metadata

from markerplace.render.gl_resources import create_context

log = logging.getLogger(__name__)

__all__ = ["PACKAGES", "environment", "gl_info"]

#: Distributions whose versions can change a result (rendering, features, matching, geometry).
PACKAGES = ("markerplace", "numpy", "scipy", "opencv-python-headless", "faiss-cpu", "moderngl", "glcontext",
            "pupil-apriltags", "open3d-cpu", "trimesh")


def gl_info() -> dict[str, str]:
    """``GL_RENDERER`` and ``GL_VERSION`` of a standalone EGL context (e.g. llvmpipe, Mesa's
    version); ``{"error": ...}`` when no context can be made."""
    try:
        ctx = create_context()
    except Exception as err:  # noqa: BLE001 - the record says why instead of failing the run
        return {"error": str(err)}
    try:
        return {k: str(ctx.info.get(k, "?")) for k in ("GL_RENDERER", "GL_VERSION")}
    finally:
        ctx.release()


def environment(gl: bool = True) -> dict:
    """Python, platform, :data:`PACKAGES` versions (None: not installed) and, with ``gl``,
    :func:`gl_info`."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    out = {"python": platform.python_version(), "platform": platform.platform(), "packages": versions}
    if gl:
        out["gl"] = gl_info()
    return out
