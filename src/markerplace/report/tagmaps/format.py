"""What every tag-map format shares: the registry, the base class, and exact number formatting.

A format is a class registered with ``@TAG_MAP_FORMATS.register`` in its own module of this
package (``name``, ``summary``, ``file``: the file name in ``tagmaps/``, and
:meth:`TagMapFormat.text`); :func:`markerplace.report.tagmaps.write.write_tag_maps` writes every
registered format. Its test reads the file with the consumer's own parser and conventions
(``tests/helpers/consumers.py``, ``tests/e2e/test_install_roundtrip.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np

from markerplace.registry import Registry
from markerplace.runtime.atomic_io import clean_float

__all__ = ["TAG_MAP_FORMATS", "TagMapContext", "TagMapFormat", "quaternion_wxyz", "rotation_vector", "yaml_number"]

TAG_MAP_FORMATS = Registry("tag-map format", "tag map")
"""Every tag-map format by name, in the order the files are written."""


@dataclass(frozen=True)
class TagMapContext:
    """What a format may need besides the markers.

    Attributes:
        name: bundle / body name (letters, digits, ``_``).
        field: WPILib ``field`` (length, width), metres.
        frame_note: words saying which frame the poses are in (written as a comment).
        default_size: black-square edge of the first tag, metres (0 without tags).
    """

    name: str
    field: tuple[float, float]
    frame_note: str
    default_size: float


class TagMapFormat:
    """A known-tag map file format (subclass it and register it)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    file: ClassVar[str] = ""
    """File name in the model frame; file-axes versions insert a suffix before the extension."""

    @dataclass(frozen=True)
    class Config:
        """No settings."""

    default_conf = Config()

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        """The file's text for ``markers`` (model frame: z up, metres)."""
        raise NotImplementedError


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z), w >= 0, of a (3, 3) rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3,) axis x angle (radians) of a (3, 3) rotation matrix (angle in [0, pi])."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, float)).as_rotvec()


def yaml_number(v: float) -> str:
    """A float as YAML 1.1 and 1.2 both read it back exactly (``1e-05`` -> ``1.0e-05``)."""
    s = repr(clean_float(v, None))  # exact, never -0.0
    if "e" in s and "." not in s.split("e")[0]:
        s = s.replace("e", ".0e", 1)
    return s
