"""GL resources of the offscreen renderer: the EGL context, the projection, textures, shader
programs and vertex arrays (moderngl). Drawing is :class:`markerplace.render.renderer.Renderer`'s.

Camera model: OpenCV pinhole (x right, y down, z forward), pixel centres at integer
coordinates; :func:`projection_matrix` maps it to GL clip space so that image row 0 (the top)
is read back first and depth runs from :data:`NEAR` to :data:`FAR` metres. Textures are uint8
RGB with array row 0 at GL t = 0 (texture coordinates are flipped to match, see
:mod:`markerplace.render.vertices`). Tag textures are drawn :data:`TAG_PIXELS_PER_BIT` texels
per tag bit, magnified nearest-neighbour so their edges stay sharp.
"""

from __future__ import annotations

import logging

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.render import shaders
from markerplace.render.vertices import VERTEX_ATTRS
from markerplace.tagfamily import tag_image

log = logging.getLogger(__name__)

__all__ = ["NEAR", "FAR", "TAG_PIXELS_PER_BIT", "EGL_HINT", "projection_matrix", "create_context", "upload_texture",
           "tag_texture", "build_program", "vertex_array"]

NEAR = 0.05
"""Near clipping distance, metres."""
FAR = 100.0
"""Far clipping distance, metres."""
TAG_PIXELS_PER_BIT = 16
"""Texture resolution of marker images."""
EGL_HINT = "install libegl1 libegl-mesa0 libgl1-mesa-dri, or run `make setup`"


def projection_matrix(intrinsics: Intrinsics, near: float = NEAR, far: float = FAR) -> np.ndarray:
    """(4, 4) clip-from-camera matrix for OpenCV intrinsics (camera x right, y down, z forward).

    Image pixel u (centre at integer u) covers GL window x in [u, u + 1], so
    x_ndc = 2 (u + 0.5) / W - 1. Likewise image row v maps to GL window row v (not flipped), so
    ``fbo.read`` returns image row 0 first. Depth: z = near -> -1, z = far -> +1, w = z.
    """
    W, H = intrinsics.width, intrinsics.height
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 * intrinsics.fx / W
    P[0, 2] = 2.0 * (intrinsics.cx + 0.5) / W - 1.0
    P[1, 1] = 2.0 * intrinsics.fy / H
    P[1, 2] = 2.0 * (intrinsics.cy + 0.5) / H - 1.0
    P[2, 2] = (far + near) / (far - near)
    P[2, 3] = -2.0 * far * near / (far - near)
    P[3, 2] = 1.0
    return P


def create_context():
    """Standalone moderngl context on EGL. Raises :class:`UserError` with an install hint if it fails."""
    try:
        import moderngl

        return moderngl.create_standalone_context(backend="egl")
    except Exception as exc:  # missing libEGL, no driver, ...
        raise UserError(f"cannot create an OpenGL context on EGL ({exc.__class__.__name__}: {exc}): {EGL_HINT}") from exc


def upload_texture(ctx, image: np.ndarray, *, mipmaps: bool, anisotropy: float):
    """A GL texture of a scene image ((H, W) grey or (H, W, 3+) uint8; subsampled to the GL size
    limit), trilinear with mipmaps or bilinear without."""
    import moderngl

    img = np.ascontiguousarray(image)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.dtype != np.uint8:
        raise UserError(f"scene texture has dtype {img.dtype}: textures must be uint8 RGB")
    img = img[:, :, :3]
    max_size = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
    step = int(np.ceil(max(img.shape[:2]) / max_size))
    if step > 1:
        log.warning("texture of %dx%d px exceeds the GL limit %d: subsampled by %d", img.shape[1], img.shape[0], max_size, step)
        img = img[::step, ::step]
    img = np.ascontiguousarray(img)
    # Row 0 of the array goes to GL t = 0; texture coordinates are flipped accordingly.
    tex = ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), alignment=1)
    if mipmaps:
        tex.build_mipmaps()
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    else:
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.anisotropy = anisotropy
    return tex


def tag_texture(ctx, tag_id: int):
    """A GL texture of tag36h11 ``tag_id`` with its white quiet zone (nearest-neighbour magnification)."""
    import moderngl

    img = tag_image(tag_id, TAG_PIXELS_PER_BIT)
    rgb = np.ascontiguousarray(np.repeat(img[:, :, None], 3, axis=2))
    tex = ctx.texture((img.shape[1], img.shape[0]), 3, rgb.tobytes(), alignment=1)
    tex.build_mipmaps()
    tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


def build_program(ctx, proj: np.ndarray, outputs: tuple[bool, bool, bool], alpha: bool = False, relit: bool = False):
    """The shader program writing ``outputs`` (rgb, depth, normal), blending by alpha when
    ``alpha``, with the relit light model when ``relit`` (:func:`markerplace.render.shaders.fragment`);
    ``proj`` is the (4, 4) float32 :func:`projection_matrix`."""
    prog = ctx.program(vertex_shader=shaders.VERTEX,
                       fragment_shader=shaders.fragment(*outputs, alpha=alpha, relit=relit))
    prog["proj"].write(proj.T.tobytes())
    if "tex" in prog:
        prog["tex"].value = 0
    return prog


def vertex_array(ctx, prog, vbo, ibo=None):
    """A vertex array of ``vbo`` (records of :data:`~markerplace.render.vertices.VERTEX_DTYPE`)
    for ``prog``, skipping the fields the program does not read; drawn through the uint32 index
    buffer ``ibo`` (three entries per triangle) when given."""
    fmt, names = [], []
    for name, f, nbytes in VERTEX_ATTRS:
        if name in prog:
            fmt.append(f)
            names.append(name)
        else:
            fmt.append(f"{nbytes}x")
    if ibo is None:
        return ctx.vertex_array(prog, [(vbo, " ".join(fmt), *names)])
    return ctx.vertex_array(prog, [(vbo, " ".join(fmt), *names)], index_buffer=ibo, index_element_size=4)
