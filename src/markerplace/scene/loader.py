"""Load a mesh file (glTF/GLB, OBJ + MTL, PLY) into a normalized :class:`Scene` (z up, metres).

Axis conventions
----------------
* glTF is y-up by its specification: a glTF point (x, y, z) becomes the world point (x, -z, y)
  (a +90 deg rotation about x). ``up`` may override this for files exported with the wrong axis.
* OBJ and PLY have no convention: ``up`` names the file's up axis (default ``"z"``).
* ``unit_scale`` multiplies coordinates after the rotation (e.g. 0.01 for centimetres).

Checks and recentring (:mod:`markerplace.scene.sanity`)
--------------------------------------------------------
* Before anything is read (:mod:`markerplace.scene.preflight`): a named pipe, a device or a
  link loop is named as such; the header must fit the file's size and format; texture sizes
  are read from their headers (a huge one downscaled with a warning naming it); the memory the
  load takes is compared with the free memory (``--force`` overrides).
* Vertices with NaN/inf coordinates are dropped with the faces using them (a warning gives the
  counts); a file with more than 5 % such vertices is refused.
* A model whose bounding-box centre lies more than 1 km from the origin (survey coordinates) is
  recentred in float64 before the float32 conversion: internal = file (rotated, scaled) -
  ``offset``, a whole-metre (3,) vector kept in ``scene.meta["world_offset"]``. This is the only
  place the shift is applied; :mod:`markerplace.scene.worldframe` undoes it on every coordinate the
  user gives or reads (``--pose``, ``--start``, ``--existing``, ``--markers``, ``--placements``,
  placement.json/csv, tag sheets, scores.npz, figures), so users only ever see file coordinates.
* Up axis: when the floor (area facing up at the bottom, furniture tops above it) fits another
  axis far better than the one read, a warning names the ``--up`` value to try.
* Texture files a ``.gltf`` or ``.mtl`` names but that are missing are named in a warning.

Materials are kept: textures as (H, W, 3) uint8 RGB arrays (row 0 = top), UVs in the glTF/trimesh
convention (v grows upwards), per-vertex RGBA colours, and the base colour (glTF
``baseColorFactor`` / MTL ``Kd``). Identical texture images are shared between parts. Glass
(glTF ``alphaMode`` BLEND with alpha < 0.9 or ``KHR_materials_transmission``; MTL ``d`` < 0.9 or
``Tr`` > 0.1) becomes ``MeshPart.transparent`` (:mod:`.transparency`).

Names are kept in ``MeshPart.names`` for :func:`markerplace.scene.semantics.classify` (tags stay
off windows, doors, furniture, ...): for glTF the node, its parent nodes (a ``Window_3`` group
holding a ``Cube.012`` mesh), the mesh and the material; for OBJ the material (trimesh groups
OBJ faces by material, so ``o``/``g`` names are not kept); never the file's own name (a
``window_scan.ply`` is not a window).
"""

from __future__ import annotations

import hashlib
import io
import logging
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.input_paths import input_kind
from markerplace.scene import preflight, sanity
from markerplace.scene.mesh_text import decode_text, original_names
from markerplace.scene.transparency import material_transparency, read_gltf_json
from markerplace.scene.types import MeshPart, Scene
from markerplace.scene.worldframe import OFFSET_KEY

log = logging.getLogger(__name__)

SUPPORTED_EXTENSIONS = (".glb", ".gltf", ".obj", ".ply")
GREY = (0.7, 0.7, 0.7, 1.0)
MAX_DIAGONAL_M = 1000.0
MIN_EXTENT_M = 1.0

_FORMAT_NAMES = {".glb": "binary glTF", ".gltf": "glTF", ".obj": "Wavefront OBJ", ".ply": "PLY"}

# world_from_file rotations for each up axis of the file.
_UP_ROTATIONS = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),  # (x, y, z) -> (x, -z, y)
    "-y": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),  # (x, y, z) -> (x, z, -y)
    "x": np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),  # (x, y, z) -> (-z, y, x)
    "-x": np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]),  # (x, y, z) -> (z, y, -x)
    "-z": np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]]),  # (x, y, z) -> (x, -y, -z)
}
UP_CHOICES = tuple(_UP_ROTATIONS)


def up_rotation(up: str) -> np.ndarray:
    """(3, 3) rotation ``world_from_file`` that maps the file's ``up`` axis onto world +z."""
    key = str(up).strip().lower().lstrip("+")
    if key not in _UP_ROTATIONS:
        raise UserError(f"--up {up!r} is not an axis; use one of {', '.join(UP_CHOICES)}")
    return _UP_ROTATIONS[key]


def load_mesh_file(path: str | Path, up: str | None = None, unit_scale: float | None = None) -> Scene:
    """Read a mesh file and return a :class:`Scene` in the world frame (z up, metres).

    Args:
        path: a ``.glb``, ``.gltf``, ``.obj`` or ``.ply`` file.
        up: the file's up axis (z, y, -y, x, -x, -z). Default: ``y`` for glTF, ``z`` otherwise.
        unit_scale: factor from file units to metres (default 1).

    Raises:
        UserError: missing file, unsupported format, unreadable file, no faces, or a size that is
            not plausible in metres (bounding-box diagonal > 1000 m or largest extent < 1 m).
    """
    path = Path(path)
    ext = path.suffix.lower()
    kind = input_kind(path)
    if kind not in (None, "missing", "a folder"):  # a FIFO, /dev/zero, a link loop: never read, never "no such file"
        raise UserError(f"{path} is {kind}: give a mesh file ({', '.join(SUPPORTED_EXTENSIONS)})")
    if ext not in SUPPORTED_EXTENSIONS:
        raise UserError(
            f"{path}: unknown scene format {ext or '(no extension)'!r}; supported: "
            f"{', '.join(SUPPORTED_EXTENSIONS)} or a built-in name (see `markerplace scene list`)"
        )
    if path.is_dir():
        raise UserError(f"{path} is a folder, not a mesh file; give the model file inside it "
                        f"({', '.join(SUPPORTED_EXTENSIONS)})")
    if not path.is_file():
        raise UserError(f"{path}: no such file; give a mesh file ({', '.join(SUPPORTED_EXTENSIONS)}) or a built-in name")
    if path.stat().st_size == 0:
        raise UserError(f"{path} is empty (0 bytes): the export or copy did not finish; export the model again")
    scale = 1.0 if unit_scale is None else float(unit_scale)
    if not np.isfinite(scale) or scale <= 0:
        raise UserError(f"--unit-scale {unit_scale!r} must be a positive number (e.g. 0.01 for centimetres)")
    is_gltf = ext in (".glb", ".gltf")
    R = up_rotation(up if up is not None else ("y" if is_gltf else "z"))
    try:  # header against size, texture sizes, memory: refused at once, not after minutes (scene.preflight)
        data_kind = preflight.check_header(path, ext)
        textures = preflight.texture_sizes(path, ext)
    except OSError as err:
        raise UserError(f"cannot read {path}: {err.strerror or err}") from None
    preflight.check_textures(textures, sanity.warn_once)
    preflight.check_memory(path, data_kind, textures)
    with preflight.pillow_limit():
        return _load(path, ext, R, scale, is_gltf, up)


def _load(path: Path, ext: str, R: np.ndarray, scale: float, is_gltf: bool, up: str | None) -> Scene:
    """The body of :func:`load_mesh_file` once the file passed its checks."""
    instances = _read_instances(path, ext)
    if not instances:
        raise UserError(f"{path}: the file contains no triangle faces (a point cloud or empty mesh?); give a triangle mesh")
    world_from_file = np.eye(4)
    world_from_file[:3, :3] = R * scale
    instances = sanity.drop_non_finite(instances, world_from_file, path)
    lo, hi = _world_bounds(instances, world_from_file)
    _check_units(lo, hi, path, scale)
    offset = sanity.recentre_offset(lo, hi)
    world_from_file[:3, 3] = -offset  # the one place the internal frame is shifted (markerplace.scene.worldframe)
    sanity.warn_missing_textures(path)
    parts = _to_parts(instances, world_from_file, path.stem, read_gltf_json(path) if is_gltf else None)
    scene = Scene(name=path.stem, parts=tuple(parts), source=str(path),
                  meta={OFFSET_KEY: offset.tolist()} if np.any(offset) else {})
    sanity.check_up_axis(scene, R, _UP_ROTATIONS, path, up if up is not None else ("y" if is_gltf else "z"))
    return scene


def _resolver(path: Path):
    """trimesh's resolver of the files a model names (MTL, textures, glTF buffers), restricted to
    the model's folder as trimesh's own, but: a name outside the folder is recorded in
    ``.outside`` and treated as missing (trimesh's message about its own API is never shown), MTL
    text is decoded by :func:`decode_text` and handed on as UTF-8, and a name from Latin-1 text is
    also looked up by its original bytes."""
    from trimesh.resolvers import FilePathResolver

    class Resolver(FilePathResolver):
        outside: list[str]

        def get(self, name: str):
            data = None
            for candidate in original_names(name):
                try:
                    data = super().get(candidate)
                    break
                except ValueError:  # escapes the folder
                    if name not in self.outside:
                        self.outside.append(name)
                except FileNotFoundError:
                    continue
            if data is None:
                raise FileNotFoundError(name)
            if name.lower().endswith(".mtl"):
                data = decode_text(data).encode("utf-8")
            return data

    r = Resolver(str(path))
    r.outside = []
    return r


def _read_instances(path: Path, ext: str) -> list[tuple]:
    """Every triangle-mesh instance of the file's scene graph: (name, trimesh.Trimesh, (4, 4)
    file_from_mesh, names): ``names`` as :attr:`MeshPart.names` (see the module docstring)."""
    import trimesh

    fmt = _FORMAT_NAMES[ext]
    resolver = _resolver(path)
    try:
        if ext == ".obj":  # decoded here, with its MTL files, by one rule
            text = decode_text(path.read_bytes())
            loaded = trimesh.load(io.BytesIO(text.encode("utf-8")), file_type="obj", resolver=resolver,
                                  force="scene", process=False)
        else:
            loaded = trimesh.load(str(path), file_type=ext[1:], resolver=resolver, force="scene", process=False)
        if not isinstance(loaded, trimesh.Scene):
            loaded = trimesh.Scene(loaded)
        parents = loaded.graph.transforms.parents
        base = loaded.graph.base_frame
        own = {path.name, path.stem}
        out = []
        for node in loaded.graph.nodes_geometry:
            transform, geom_name = loaded.graph[node]
            mesh = loaded.geometry[geom_name]
            if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces) > 0:
                chain, at = [], node
                while at is not None and at != base and len(chain) < 32:
                    chain.append(str(at))
                    at = parents.get(at)
                material = getattr(getattr(mesh.visual, "material", None), "name", None)
                names = [n for n in (*chain, str(geom_name), material) if n and str(n) not in own]
                out.append((str(geom_name), mesh, np.asarray(transform, dtype=np.float64),
                            tuple(dict.fromkeys(str(n) for n in names))))
    except Exception as err:  # trimesh raises many kinds of errors on corrupt input
        if resolver.outside:
            raise UserError(f"could not read {path}: it needs {', '.join(resolver.outside[:3])}, outside the model's "
                            "folder, which is not read; copy the file(s) next to the model and fix the reference") \
                from None
        reason = " ".join(str(err).split())[:200] or type(err).__name__
        raise UserError(f"could not read {path}: {reason}; check the file is a valid {fmt} file") from None
    if resolver.outside:
        sanity.warn_once("%s: file(s) outside the model's folder are not read: %s; copy them next to the model "
                         "and fix the reference", path, ", ".join(resolver.outside[:5]))
    return out


def _world_bounds(instances: list[tuple], world_from_file: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3,) min and max corners in metres of all instances' bounding boxes in the world frame."""
    corners = []
    for _, mesh, file_from_mesh, *_ in instances:
        (x0, y0, z0), (x1, y1, z1) = np.asarray(mesh.bounds, dtype=float)
        box = np.array([[x, y, z, 1.0] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)])
        corners.append(box @ (world_from_file @ file_from_mesh).T)
    pts = np.concatenate(corners)[:, :3]
    return pts.min(axis=0), pts.max(axis=0)


def _to_parts(instances: list[tuple], world_from_file: np.ndarray, stem: str, gltf: dict | None = None) -> list[MeshPart]:
    """Convert mesh instances to :class:`MeshPart` in the world frame ((4, 4) ``world_from_file``).

    ``gltf`` is the file's glTF JSON (None for OBJ/PLY); see-through materials become
    ``MeshPart.transparent`` by the rules of :mod:`.transparency`.
    """
    parts: list[MeshPart] = []
    textures: dict[str, np.ndarray] = {}
    untextured = 0
    for i, (geom_name, mesh, file_from_mesh, names) in enumerate(instances):
        world_from_mesh = world_from_file @ file_from_mesh
        A, t = world_from_mesh[:3, :3], world_from_mesh[:3, 3]
        vertices = np.asarray(mesh.vertices, dtype=np.float64) @ A.T + t
        faces = np.asarray(mesh.faces, dtype=np.int64)
        if np.linalg.det(A) < 0:  # a mirroring transform flips the winding
            faces = faces[:, ::-1]
        uv, colors, texture, base = _visual(mesh, textures)
        normals = _file_normals(mesh, A)
        if colors is not None and getattr(mesh.visual, "kind", None) == "face":
            # face colours: give every face its own three vertices
            vertices, faces, colors, uv, normals = _unshare(vertices, faces, colors, uv, normals)
        if texture is None and colors is None and base is None:
            untextured += 1
            base = GREY
        transparent, opacity = material_transparency(getattr(mesh.visual, "material", None), gltf)
        if opacity is not None:  # OBJ: the MTL's dissolve becomes the base colour alpha
            base = (*(base if base is not None else (1.0, 1.0, 1.0, 1.0))[:3], opacity)
        name = geom_name or f"{stem}_{i}"
        parts.append(
            MeshPart(
                name=name,
                vertices=vertices.astype(np.float32),
                faces=faces.astype(np.int32),
                uv=None if uv is None else uv.astype(np.float32),
                colors=colors,
                texture=texture,
                base_color=tuple(float(c) for c in (base if base is not None else (1.0, 1.0, 1.0, 1.0))),
                normals=None if normals is None else normals.astype(np.float32),
                transparent=transparent,
                names=names,
            )
        )
    if untextured:
        sanity.warn_once(
            "%d of %d mesh parts have no texture, vertex colours or material colour; they are drawn "
            "in plain grey and will give few image features",
            untextured,
            len(parts),
        )
    if parts and all(p.texture is None and p.colors is None for p in parts):
        sanity.warn_once("the model has no textures or vertex colours: expect few image features")
    return parts


def _visual(mesh, textures: dict[str, np.ndarray]):
    """(uv (N, 2) | None, colors (N or 3F, 4) uint8 | None, texture | None, base RGBA floats | None)."""
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    if kind == "texture":
        material = visual.material
        uv = None if visual.uv is None else np.asarray(visual.uv, dtype=np.float64)[:, :2]
        image = getattr(material, "baseColorTexture", None)
        if image is None:
            image = getattr(material, "image", None)
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            factor = getattr(material, "diffuse", None)
        base = None if factor is None else tuple(np.asarray(factor, dtype=float).reshape(-1)[:4] / 255.0)
        texture = None
        if image is not None and uv is not None and len(uv) == len(mesh.vertices):
            texture = _shared_texture(image, textures)
        else:
            uv = None
        colors = None
        attrs = getattr(visual, "vertex_attributes", None)
        color = attrs.get("color") if attrs is not None else None
        if color is not None and len(color) == len(mesh.vertices):  # glTF COLOR_0 next to a material
            colors = _rgba_u8(color)
        return uv, colors, texture, base
    if kind == "vertex":
        return None, np.ascontiguousarray(visual.vertex_colors, dtype=np.uint8), None, None
    if kind == "face":
        return None, np.ascontiguousarray(visual.face_colors, dtype=np.uint8), None, None
    return None, None, None, None


def _rgba_u8(colors) -> np.ndarray:
    """(N, 3|4) colours, uint8 or float in [0, 1] -> (N, 4) uint8 RGBA."""
    c = np.asarray(colors)
    if c.dtype.kind == "f":
        c = np.rint(np.clip(c, 0.0, 1.0) * 255.0)
    c = c.astype(np.uint8)
    if c.shape[1] == 3:
        c = np.concatenate([c, np.full((len(c), 1), 255, np.uint8)], axis=1)
    return np.ascontiguousarray(c[:, :4])


def _shared_texture(image, textures: dict[str, np.ndarray]) -> np.ndarray:
    """PIL image -> read-only (H, W, 3) uint8 RGB array (at most
    :data:`~markerplace.scene.preflight.MAX_TEXTURE_SIDE` a side); equal images share one array."""
    image = preflight.downscaled(image)
    if image.mode in ("RGBA", "LA", "P"):
        image = image.convert("RGBA")
    arr = np.asarray(image.convert("RGB"), dtype=np.uint8)
    key = hashlib.sha1(arr.tobytes()).hexdigest() + str(arr.shape)
    if key not in textures:
        arr = np.ascontiguousarray(arr)
        arr.flags.writeable = False
        textures[key] = arr
    return textures[key]


def _file_normals(mesh, world_from_mesh: np.ndarray) -> np.ndarray | None:
    """Vertex normals stored in the file mapped by the (3, 3) linear part ``world_from_mesh``, else None."""
    try:
        cached = mesh._cache.cache.get("vertex_normals")
    except AttributeError:
        return None
    if cached is None or len(cached) != len(mesh.vertices):
        return None
    n = np.asarray(cached, dtype=np.float64) @ np.linalg.inv(world_from_mesh)  # inverse transpose
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(norm > 0, norm, 1.0)


def _unshare(vertices, faces, face_colors, uv, normals):
    """Split vertices so each face owns its 3 vertices; face colours become vertex colours."""
    idx = faces.reshape(-1)
    new_faces = np.arange(len(idx)).reshape(-1, 3)
    colors = np.repeat(face_colors, 3, axis=0)
    return (
        vertices[idx],
        new_faces,
        colors,
        None if uv is None else uv[idx],
        None if normals is None else normals[idx],
    )


def _check_units(lo: np.ndarray, hi: np.ndarray, path: Path, scale: float) -> None:
    """Fail with a ``--unit-scale`` hint when the box [lo, hi] (metres) is implausible for a building."""
    extent = hi - lo
    diagonal = float(np.linalg.norm(extent))
    if diagonal > MAX_DIAGONAL_M:
        raise UserError(
            f"{path}: the model is {diagonal:.0f} m across after scaling by {scale:g}, too big for a building; "
            f"it is probably in cm or mm: pass --unit-scale 0.01 (cm) or 0.001 (mm)"
        )
    if float(extent.max()) < MIN_EXTENT_M:
        raise UserError(
            f"{path}: the model is only {float(extent.max()):.3g} m across after scaling by {scale:g}, too small for a room; "
            f"pass --unit-scale with the size of one file unit in metres (e.g. 0.3048 for feet)"
        )
