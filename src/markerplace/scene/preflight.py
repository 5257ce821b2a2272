"""A mesh file checked before it is read (called by :func:`markerplace.scene.loader.load_mesh_file`):
a file that is not what its name says, or too large for this machine, is refused in a second
with one line, instead of being read for minutes into many GiB of memory.

* Header (:func:`check_header`): a PLY starts with ``ply`` and a header that ends within
  :data:`HEADER_BYTES`, whose element counts fit the bytes after it (a binary row is its
  properties' bytes, a list at least its count; an ASCII row at least two bytes per property); a
  GLB starts with ``glTF``, and its declared length and JSON chunk fit the file; a ``.gltf``
  is JSON text (``{`` first) whose buffer files hold the bytes it declares; an OBJ is text
  (no NUL byte in its first :data:`HEADER_BYTES`) with OBJ statements (``v``, ``f``, ...) there.
* Textures (:func:`texture_sizes`): the size of every texture image, from its header only
  (embedded in a GLB, files next to a ``.gltf`` or named by an OBJ's MTL files). One larger than
  :data:`MAX_TEXTURE_SIDE` on a side (the usual OpenGL limit, which the renderer subsamples to
  anyway) is downscaled on load with a warning naming it (:func:`downscaled`); one over
  :data:`MAX_TEXTURE_PIXELS` is refused naming it. Pillow's own limit, which made trimesh drop
  a large texture without a word, is lifted to that while the model loads
  (:func:`pillow_limit`).
* Memory (:func:`check_memory`): the peak memory of loading (file bytes times
  :data:`LOAD_BYTES_PER_FILE_BYTE` of the format, measured on meshes of 2 million faces, plus
  :data:`BYTES_PER_TEXEL` per texture pixel, plus the full decode of the largest texture that
  is downscaled) against the memory free now
  (:func:`available_memory_bytes`); over it is refused naming ``--force``, which
  :func:`allow_large_models` records for the process (the CLI sets it). Worker processes do
  not check again.
"""

from __future__ import annotations

import io
import json
import logging
import math
import multiprocessing
import os
import re
import struct
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

from markerplace.errors import UserError
from markerplace.scene.mesh_text import decode_text, original_names

log = logging.getLogger("markerplace.scene.loader")

__all__ = ["check_header", "texture_sizes", "check_textures", "check_memory", "allow_large_models", "pillow_limit", "downscaled",
           "Texture", "available_memory_bytes"]

HEADER_BYTES = 64 * 1024
"""A PLY header must end, and an OBJ's first statement appear, within this many bytes."""
MAX_TEXTURE_SIDE = 16384
"""Textures larger than this on a side (pixels) are downscaled on load, with a warning."""
MAX_TEXTURE_PIXELS = 1 << 30
"""Textures with more pixels than this (32768 x 32768) are refused: 3 GiB decoded."""
LOAD_BYTES_PER_FILE_BYTE = {"binary": 20.0, "ascii ply": 18.0, ".obj": 10.0}
"""Peak memory of loading per byte of mesh data: 18-20 for binary and ASCII PLY and GLB, 10 for
OBJ (1 M vertices, 2 M faces: 0.63 GB from a 36 MB GLB or a 38 MB binary PLY, 0.72 GB from an 82 MB
OBJ)."""
BYTES_PER_TEXEL = 8.0
"""Memory per texture pixel while loading (the decoded image, its RGB copy, the GL upload)."""
BASE_LOAD_BYTES = 0.1e9
"""Memory of the loader's libraries (trimesh, Pillow)."""

_PLY_TYPES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
              "int": 4, "int32": 4, "uint": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_OBJ_STATEMENTS = {"v", "vt", "vn", "vp", "f", "l", "p", "o", "g", "s", "mtllib", "usemtl"}
_force = [False]


@dataclass(frozen=True)
class Texture:
    """A texture image a model uses: ``name`` for messages (a file, or ``MODEL image N``),
    ``width`` x ``height`` pixels, ``stored`` bytes inside the mesh file (embedded images)."""

    name: str
    width: int
    height: int
    stored: int = 0


def allow_large_models(force: bool) -> None:
    """``--force``: load a model even when :func:`check_memory` estimates more than is free."""
    _force[0] = bool(force)


def _refuse(path: Path, fmt: str, reason: str) -> UserError:
    return UserError(f"{path} is not a valid {fmt} file: {reason}; check the file (a copy that did not finish, "
                     "or another format renamed?) or export the model again")


def check_header(path: Path, ext: str) -> str:
    """Check the file's header against its size (see the module docstring); returns the kind of
    data for the memory estimate (``"binary"``, ``"ascii ply"`` or ``".obj"``)."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(HEADER_BYTES)
    if ext == ".ply":
        return _check_ply(path, head, size)
    if ext == ".glb":
        _check_glb(path, head, size)
        return "binary"
    if ext == ".gltf":
        if not head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"{"):
            raise _refuse(path, "glTF", "a .gltf file is JSON text starting with '{'")
        return "binary"
    if b"\x00" in head:
        raise _refuse(path, "Wavefront OBJ", f"binary data (a NUL byte at {head.index(0)}) where OBJ text should be")
    lines = decode_text(head).splitlines()[:-1] if len(head) == HEADER_BYTES else decode_text(head).splitlines()
    words = [ln.split()[0] for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if words and not _OBJ_STATEMENTS & set(words):
        raise _refuse(path, "Wavefront OBJ", f"no OBJ statement (v, f, o, ...) in its first {len(head) // 1024} KiB")
    return ".obj"


def _check_ply(path: Path, head: bytes, size: int) -> str:
    if not re.match(rb"ply\r?\n", head):
        raise _refuse(path, "PLY", "it does not start with 'ply'")
    end = re.search(rb"end_header\r?\n", head)
    if end is None:
        raise _refuse(path, "PLY", f"no end_header in its first {HEADER_BYTES // 1024} KiB")
    fmt, elements = "", []  # elements: [name, count, [(row bytes, is_list)]]
    for line in head[:end.start()].decode("latin-1").splitlines():
        w = line.split()
        if w[:1] == ["format"] and len(w) > 1:
            fmt = w[1]
        elif w[:1] == ["element"] and len(w) == 3:
            if not w[2].isdigit():
                raise _refuse(path, "PLY", f"element {w[1]} has count {w[2]!r}")
            elements.append((w[1], int(w[2]), []))
        elif w[:1] == ["property"] and elements and len(w) >= 3:
            size_of = _PLY_TYPES.get(w[2] if w[1] == "list" else w[1], 0)  # a list: its count's bytes at least
            elements[-1][2].append(size_of)
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _refuse(path, "PLY", f"format {fmt or '(none)'!r} is not ascii or binary")
    ascii = fmt == "ascii"
    need = sum(count * (2 * len(props) if ascii else sum(props)) for _, count, props in elements)
    need = max(0, need - 1) if ascii else need  # the last ASCII row needs no separator after it
    body = size - end.end()
    if need > body:
        counts = ", ".join(f"{count:,} {name}" for name, count, _ in elements)
        raise _refuse(path, "PLY", f"its header claims {counts}, which need at least {need:,} bytes, but only "
                                   f"{body:,} follow it (truncated?)")
    return "ascii ply" if ascii else "binary"


def _check_glb(path: Path, head: bytes, size: int) -> None:
    if len(head) < 20 or head[:4] != b"glTF":
        raise _refuse(path, "binary glTF", "it does not start with 'glTF'")
    _, length, chunk, kind = struct.unpack_from("<IIII", head, 4)
    if length > size:
        raise _refuse(path, "binary glTF", f"its header says {length:,} bytes but the file has {size:,} (truncated?)")
    if kind != 0x4E4F534A or 20 + chunk > length:
        raise _refuse(path, "binary glTF", "its first chunk is not a JSON chunk inside the file")


def _gltf_document(path: Path, ext: str) -> tuple[dict, int]:
    """(the glTF JSON, the file offset of a GLB's BIN chunk data or -1)."""
    with open(path, "rb") as fh:
        if ext == ".gltf":
            return json.loads(fh.read().decode("utf-8-sig")), -1
        _, _, _, chunk, _ = struct.unpack("<IIIII", fh.read(20))  # magic, version, length; JSON chunk length, type
        doc = json.loads(fh.read(chunk).decode("utf-8"))
        header = fh.read(8)
        return doc, (20 + chunk + 8 if len(header) == 8 and header[4:] == b"BIN\x00" else -1)


def _image_size(data: bytes | Path) -> tuple[int, int] | None:
    from PIL import Image

    try:
        with pillow_limit(None), Image.open(io.BytesIO(data) if isinstance(data, bytes) else data) as im:
            return im.size
    except Exception:  # not an image Pillow knows: trimesh decides
        return None


def texture_sizes(path: Path, ext: str) -> list[Texture]:
    """Every texture image of the model whose size can be read from its header (see the module
    docstring); unreadable ones are left to the loader. Raises :class:`UserError` for a ``.gltf``
    whose buffer file is shorter than it declares."""
    try:
        if ext == ".obj":
            return _mtl_textures(path)
        if ext not in (".glb", ".gltf"):
            return []
        doc, bin_at = _gltf_document(path, ext)
    except (OSError, ValueError, struct.error):
        return []  # the loader reports a damaged file
    buffers, views = doc.get("buffers") or [], doc.get("bufferViews") or []
    for b in buffers if ext == ".gltf" else []:
        uri = b.get("uri") if isinstance(b, dict) else None
        f = path.parent / unquote(uri) if isinstance(uri, str) and not uri.startswith("data:") else None
        if f is not None and f.is_file() and f.stat().st_size < int(b.get("byteLength") or 0):
            raise _refuse(path, "glTF", f"its buffer {uri} has {f.stat().st_size:,} bytes of the "
                                        f"{int(b['byteLength']):,} it declares (truncated?)")
    out = []
    for i, image in enumerate(doc.get("images") or []):
        if not isinstance(image, dict):
            continue
        name = f"{path.name} image {i}" + (f" ({image['name']})" if isinstance(image.get("name"), str) else "")
        uri, view = image.get("uri"), image.get("bufferView")
        try:
            if isinstance(uri, str) and not uri.startswith("data:"):
                size, stored, name = _image_size(path.parent / unquote(uri)), 0, str(path.parent / unquote(uri))
            elif isinstance(view, int) and 0 <= view < len(views) and bin_at >= 0 and views[view].get("buffer", 0) == 0:
                offset, length = bin_at + int(views[view].get("byteOffset", 0)), int(views[view]["byteLength"])
                with open(path, "rb") as fh:
                    fh.seek(offset)
                    size, stored = _image_size(fh.read(min(length, 4 << 20))), length
            else:
                continue
        except (OSError, KeyError, TypeError, ValueError):
            continue
        if size is not None:
            out.append(Texture(name, size[0], size[1], stored))
    return out


def _mtl_textures(path: Path) -> list[Texture]:
    with open(path, "rb") as fh:
        head = decode_text(fh.read(1 << 20))
    out = []
    for line in head.splitlines():
        if not line.startswith("mtllib"):
            continue
        mtl = next((path.parent / n for n in original_names(line[6:].strip()) if (path.parent / n).is_file()), None)
        if mtl is None:
            continue
        for entry in decode_text(mtl.read_bytes()[:1 << 20]).splitlines():
            w = entry.strip().split()
            if len(w) > 1 and w[0].lower().startswith("map_"):
                image = next((mtl.parent / n for n in original_names(w[-1]) if (mtl.parent / n).is_file()), None)
                size = _image_size(image) if image is not None else None
                if size is not None and all(t.name != str(image) for t in out):
                    out.append(Texture(str(image), size[0], size[1]))
    return out


def check_textures(textures: list[Texture], warn) -> None:
    """Refuse a texture over :data:`MAX_TEXTURE_PIXELS`; ``warn`` (a ``warn_once``) about each
    one larger than :data:`MAX_TEXTURE_SIDE` on a side, which is downscaled on load."""
    for t in textures:
        if t.width * t.height > MAX_TEXTURE_PIXELS:
            raise UserError(f"texture {t.name} is {t.width} x {t.height} pixels ({3 * t.width * t.height / 2**30:.1f} "
                            f"GiB decoded), more than markerplace reads ({MAX_TEXTURE_PIXELS / 2**20:.0f} M pixels): "
                            f"shrink it to at most {MAX_TEXTURE_SIDE} pixels a side and export the model again")
        step = _step(t.width, t.height)
        if step > 1:
            warn("texture %s is %d x %d pixels, more than %d on a side: downscaled to %d x %d while loading",
                 t.name, t.width, t.height, MAX_TEXTURE_SIDE, t.width // step, t.height // step)


def _step(width: int, height: int) -> int:
    return max(1, math.ceil(max(width, height) / MAX_TEXTURE_SIDE))


def downscaled(image):
    """A Pillow image no larger than :data:`MAX_TEXTURE_SIDE` on a side (``image`` itself when it
    is; a JPEG is decoded at the smaller size directly)."""
    step = _step(*image.size)
    if step == 1:
        return image
    w, h = image.size
    image.draft("RGB", (w // step, h // step))  # JPEG: decode at 1/2, 1/4 or 1/8 scale
    step = _step(*image.size)
    return image if step == 1 else image.reduce(step)


@contextmanager
def pillow_limit(pixels: int | None = -1):
    """Pillow's decompression-bomb limit at ``pixels`` (default :data:`MAX_TEXTURE_PIXELS`; None:
    none, to read a header) while inside: its own default, 89 M pixels, warns on a 10000 x 10000
    texture and refuses a 16384 x 16384 one."""
    from PIL import Image

    saved = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = MAX_TEXTURE_PIXELS if pixels == -1 else pixels
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            yield
    finally:
        Image.MAX_IMAGE_PIXELS = saved


def available_memory_bytes() -> float:
    """Memory free for a new allocation now (bytes): ``MemAvailable`` of ``/proc/meminfo``, or
    the cgroup's limit less its use when lower; the physical memory where neither is known."""
    free = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                free = float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if free is None:
        try:
            free = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
        except (ValueError, OSError, AttributeError):
            return math.inf
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text().strip()
        if limit.isdigit() and used.isdigit():
            free = min(free, float(int(limit) - int(used)))
    except OSError:
        pass
    return free


def check_memory(path: Path, kind: str, textures: list[Texture]) -> float:
    """Refuse (one line, naming ``--force``) a model whose estimated load memory exceeds the
    memory free now, unless :func:`allow_large_models`; returns the estimate (bytes)."""
    data = path.stat().st_size + sum(_sidecar_bytes(path))
    data -= sum(t.stored for t in textures)
    texels = sum(t.width * t.height / _step(t.width, t.height) ** 2 for t in textures)
    full = max((4.0 * t.width * t.height for t in textures if _step(t.width, t.height) > 1), default=0.0)
    need = BASE_LOAD_BYTES + LOAD_BYTES_PER_FILE_BYTE[kind] * max(data, 0) + BYTES_PER_TEXEL * texels + full
    if multiprocessing.parent_process() is not None:
        return need  # a worker: the main process checked
    free = available_memory_bytes()
    if need > free:
        text = (f"{path}: loading it needs about {need / 2**30:.1f} GiB of memory ({data / 2**20:,.0f} MiB of mesh "
                f"data, {texels / 1e6:,.0f} M texture pixels), more than the {free / 2**30:.1f} GiB free now")
        if not _force[0]:
            raise UserError(f"{text}: free memory, simplify or split the model, or pass --force to try anyway")
        log.warning("%s; going on because of --force", text)
    return need


def _sidecar_bytes(path: Path):
    """Sizes of the buffer files a ``.gltf`` names (read with it)."""
    if path.suffix.lower() != ".gltf":
        return
    try:
        doc = json.loads(path.read_bytes().decode("utf-8-sig"))
    except (OSError, ValueError):
        return
    for b in doc.get("buffers") or [] if isinstance(doc, dict) else []:
        uri = b.get("uri") if isinstance(b, dict) else None
        if isinstance(uri, str) and not uri.startswith("data:") and (path.parent / unquote(uri)).is_file():
            yield (path.parent / unquote(uri)).stat().st_size
