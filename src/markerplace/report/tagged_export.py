"""``markerplace export PLAN_DIR --gltf OUT.glb``: the plan's model with every tag on its wall,
as one binary glTF that opens in any glTF viewer or in Blender.

Frames. The vertex data is in the model's **original axes and units**: the loader's up-axis
rotation R, unit scale s and recentring offset o are undone (:mod:`markerplace.scene.loader`,
:mod:`markerplace.scene.worldframe`): ``p_file = (s R)^-1 (p_internal + o)``. For a built-in
scene the original frame is markerplace's world (z up, metres). Two nodes carry the rest:

* the root ``model_file_frame`` has the matrix ``GLTF_FROM_WORLD @ (s R)`` (4x4, column-major in
  the file), which maps file coordinates to glTF's y-up metres, so viewers show the model upright
  and at scale; for a glTF input (y up, metres) it is the identity and is left out;
* under it, ``recentred`` has the translation ``(s R)^-1 o`` (float64 in the JSON) when the
  model was recentred, so far-away (survey) coordinates keep full precision while the float32
  vertex data stays small.

Every tag (placed and ``--existing``) is a quad named ``tag_<id>`` with the tag36h11 image and
its white quiet zone as texture (nearest-neighbour sampling), edge
:func:`markerplace.tagfamily.outer_size`, lifted :data:`TAG_LIFT_M` off the wall so it never
z-fights with it; it faces out of the wall (one-sided, like the printed sheet).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.runtime.atomic_io import atomic_path
from markerplace.scene.export import GLTF_FROM_WORLD, scene_to_glb_bytes
from markerplace.scene.source import world_from_file_rotation
from markerplace.scene.types import MeshPart, Scene
from markerplace.scene.worldframe import markers_to_internal, world_offset
from markerplace.tagfamily import outer_size, tag_image

log = logging.getLogger(__name__)

__all__ = ["tag_part", "export_plan_glb", "TAG_LIFT_M"]

TAG_LIFT_M = 0.002
PIXELS_PER_BIT = 16


def tag_part(marker) -> MeshPart:
    """A textured quad of ``marker`` (internal frame): 4 vertices TL, TR, BR, BL as a facing
    viewer sees them, 2 triangles counter-clockwise seen from the marker's +z."""
    h = outer_size(marker.size) / 2.0
    T = np.asarray(marker.world_from_marker, dtype=np.float64)
    local = np.array([[-h, h, TAG_LIFT_M], [h, h, TAG_LIFT_M], [h, -h, TAG_LIFT_M], [-h, -h, TAG_LIFT_M]])
    verts = local @ T[:3, :3].T + T[:3, 3]
    gray = tag_image(marker.tag_id, PIXELS_PER_BIT)
    return MeshPart(name=f"tag_{marker.tag_id}", vertices=verts.astype(np.float32),
                    faces=np.array([[0, 3, 2], [0, 2, 1]], dtype=np.int32),
                    uv=np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=np.float32),  # v up (MeshPart convention)
                    texture=np.repeat(gray[:, :, None], 3, axis=2),
                    normals=np.repeat(T[None, :3, 2], 4, axis=0).astype(np.float32))


def export_plan_glb(folder, out: str | Path) -> dict:
    """Write the model of the plan ``folder`` (:class:`~markerplace.plan.folder.PlanFolder`) with
    its tags to ``out`` (binary glTF, atomically). Returns a summary (tags, faces, frames)."""
    scene = folder.spec.load()
    folder.check_scene(scene)  # placement.json on the candidates of config.json's scene (as check and evaluate test)
    offset = world_offset(scene)
    R = world_from_file_rotation(folder.scene, folder.scene_options.get("up"))
    builtin = R is None
    scale = 1.0 if builtin else float(folder.scene_options.get("unit_scale") or 1.0)
    world_from_file = (np.eye(3) if builtin else R) * scale
    file_from_world = np.linalg.inv(world_from_file)
    markers = markers_to_internal(list(folder.markers) + list(folder.existing), offset)
    tags = [tag_part(m) for m in markers]
    tagged = Scene(name=f"{scene.name}_tags", parts=tuple(scene.parts) + tuple(tags), source=scene.source)
    view = np.eye(4)
    view[:3, :3] = GLTF_FROM_WORLD @ world_from_file
    roots = []
    if not np.allclose(view, np.eye(4), atol=1e-12):
        roots.append({"name": "model_file_frame", "matrix": [float(v) for v in view.T.ravel()]})
    if np.any(offset):
        roots.append({"name": "recentred", "translation": [float(v) for v in file_from_world @ offset]})
    data = scene_to_glb_bytes(tagged, data_from_world=file_from_world, roots=roots,
                              nearest_parts=frozenset(t.name for t in tags))
    with atomic_path(out) as tmp:
        Path(tmp).write_bytes(data)
    summary = {"tags": [int(m.tag_id) for m in markers], "faces": int(tagged.num_faces),
               "frame": "z-up world, metres (built-in)" if builtin else
               f"file axes (up {folder.scene_options.get('up') or 'default'}), file units x {scale:g} = metres",
               "root_matrix": roots[0]["matrix"] if roots and "matrix" in roots[0] else None,
               "translation": roots[-1]["translation"] if roots and "translation" in roots[-1] else None}
    log.debug("wrote %s: %d tags, %d faces", out, len(tags), tagged.num_faces)
    return summary
