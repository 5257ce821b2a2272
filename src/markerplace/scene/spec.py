"""How any process (a worker, a cluster node) rebuilds the same scene: a picklable recipe."""

from __future__ import annotations

from dataclasses import dataclass

from markerplace.scene import load_scene

__all__ = ["SceneSpec"]


@dataclass(frozen=True)
class SceneSpec:
    """``load_scene(spec, up, unit_scale, seed)``: a built-in name or a mesh path (a cluster's
    workers need the same path, e.g. on a shared file system) and how to read it."""

    spec: str
    up: str | None = None
    unit_scale: float | None = None
    seed: int = 0

    def load(self):
        return load_scene(self.spec, up=self.up, unit_scale=self.unit_scale, seed=self.seed)
