"""Offscreen OpenGL renderer (moderngl on EGL): RGB, planar depth and world normals of a scene.

Camera model: OpenCV pinhole (x right, y down, z forward), poses are 4x4 ``world_from_cam``,
pixel centres at integer coordinates. A world point renders at the pixel
:func:`markerplace.geometry.project` gives; image row 0 is the top. Depth is the camera-frame z
of the surface (metres, written to a float32 attachment, not recovered from the depth buffer),
0 where nothing was hit. Normals are unit world-frame surface normals flipped to face the camera,
0 where nothing was hit.

Scene upload: parts are grouped by texture object (parts sharing one texture array share one
GL texture and one vertex buffer); base colour and vertex colour are baked into a per-vertex
colour; meshes are de-indexed so parts without normals get exact flat face normals. A group of
at least :data:`~markerplace.render.culling.MIN_TRIANGLES` triangles (a scan; no built-in scene
has one) is instead sorted into spatial chunks and each view draws only the chunks that meet its
frustum (:mod:`markerplace.render.culling`) and are not hidden behind nearer ones (occlusion
queries, :mod:`markerplace.render.draws`), through an index buffer when its parts have
per-vertex normals; the images are those of the whole buffer (``Renderer(cull=False)``; tested
pixel for pixel), except where two surfaces tie in depth at a pixel centre. Every combination of
outputs gives the same RGB image (tested pixel for pixel on a scene of several chunked atlases). Markers are
extra textured quads (tag image with white quiet zone, nearest-neighbour magnification) lifted
:data:`~markerplace.render.vertices.MARKER_OFFSET` metres off the wall along their normal;
:meth:`Renderer.set_markers` replaces them without touching the scene buffers.

Transparent parts (``MeshPart.transparent``, glass) are drawn after everything opaque, far to
near by part centroid, alpha-blended into the RGB image only (opacity
:func:`~markerplace.scene.transparency.drawn_alpha`, about 0.3) with the depth test on and
depth writes off. Depth and normals are therefore those of what lies behind the glass, as a
time-of-flight or stereo depth camera mostly reports through clear glass, and the colour shows
that surface tinted by the glass; glass seen with nothing behind it blends over black with depth
0. Outputs without RGB skip the glass pass.

Here: :class:`Renderer` (scene upload, markers, drawing, read-back) and :class:`RenderResult`.
The GL context, projection, textures, programs and vertex arrays are made by
:mod:`markerplace.render.gl_resources`; the vertex records of parts and marker quads by
:mod:`markerplace.render.vertices`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Iterable, Iterator, Sequence

import numpy as np

from markerplace.geometry import Intrinsics, invert
from markerplace.markers import Marker
from markerplace.render.culling import chunk_ranges, frustum_planes, visible_chunks
from markerplace.render.draws import Draw, OcclusionTest, by_distance, query_framebuffer, scene_buffers
from markerplace.render.gl_resources import FAR, NEAR, build_program, create_context, projection_matrix, tag_texture, upload_texture, vertex_array
from markerplace.render.vertices import marker_vertices, part_vertices
from markerplace.scene.types import MeshPart, Scene

log = logging.getLogger(__name__)

__all__ = ["Lighting", "RenderResult", "Renderer"]


@dataclass(frozen=True)
class Lighting:
    """A light set-up other than the map's (the relit shader, :mod:`markerplace.render.shaders`):
    colour = albedo * (ambient + headlight * cos(incidence) + sun * max(n . sun_dir, 0))
    * (1 - dim * beyond), ``beyond`` rising 0 -> 1 across the vertical plane through
    ``cut_point`` (world xy, metres) with horizontal normal ``cut_normal`` (unit, world xy).
    The map's own light is ambient 0.6, headlight 0.4, no sun, no dimming.

    Attributes:
        ambient, headlight, sun: intensities (the map's total is 1.0 head-on).
        sun_dir: (3,) unit world direction towards the light.
        cut_point, cut_normal: the dimming plane (see above).
        dim: share of the light lost beyond the plane, in [0, 1].
    """

    ambient: float = 0.6
    headlight: float = 0.4
    sun: float = 0.0
    sun_dir: tuple = (0.0, 0.0, 1.0)
    cut_point: tuple = (0.0, 0.0)
    cut_normal: tuple = (1.0, 0.0)
    dim: float = 0.0

    def uniforms(self) -> dict:
        """Uniform name -> value of the relit shader."""
        return {"u_ambient": float(self.ambient), "u_headlight": float(self.headlight), "u_sun": float(self.sun),
                "u_sun_dir": tuple(float(v) for v in self.sun_dir),
                "u_cut_point": tuple(float(v) for v in self.cut_point),
                "u_cut_normal": tuple(float(v) for v in self.cut_normal), "u_dim": float(self.dim)}


@dataclass(frozen=True, eq=False)
class RenderResult:
    """One rendered view.

    Attributes:
        rgb: (H, W, 3) uint8 colour image, row 0 = top; None if not requested.
        depth: (H, W) float32 planar depth (camera z) in metres, 0 where nothing was hit; None if
            not requested.
        normal: (H, W, 3) float32 unit world-frame normals facing the camera, 0 where nothing was
            hit; None if not requested.
        world_from_cam: (4, 4) pose the view was rendered from.
    """

    rgb: np.ndarray | None
    depth: np.ndarray | None
    normal: np.ndarray | None
    world_from_cam: np.ndarray


class Renderer:
    """Offscreen renderer of one scene; one GL context, scene uploaded once.

    Use as a context manager (``with Renderer(scene) as r: r.render(pose)``) or call
    :meth:`close`.

    Args:
        scene: the scene (world frame, z up, metres).
        intrinsics: camera model; images are ``intrinsics.height`` x ``intrinsics.width``.
        markers: markers drawn as tag quads on their walls.
        mipmaps: build mipmaps for scene textures (trilinear minification) when True.
        anisotropy: max anisotropic filtering of scene textures (1.0 = off; it is very slow on
            llvmpipe).
        cull: draw only what a view of a large buffer (at least
            :data:`~markerplace.render.culling.MIN_TRIANGLES` triangles, e.g. a scan) can show:
            the chunks in its frustum and not hidden (:mod:`markerplace.render.draws`); the same
            images, two to three times faster on a scan. False draws every triangle.
    """

    def __init__(
        self,
        scene: Scene,
        intrinsics: Intrinsics = Intrinsics(),
        markers: Sequence[Marker] = (),
        *,
        mipmaps: bool = True,
        anisotropy: float = 1.0,
        cull: bool = True,
    ):
        self.scene = scene
        self._cull = bool(cull)
        self.intrinsics = intrinsics
        self._mipmaps = mipmaps
        self._anisotropy = float(anisotropy)
        self.ctx = create_context()
        self._closed = False
        try:
            self._setup()
            self.set_markers(markers)
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------ setup
    def _setup(self) -> None:
        import moderngl

        ctx = self.ctx
        W, H = self.intrinsics.width, self.intrinsics.height
        self._size = (W, H)
        self._proj = projection_matrix(self.intrinsics).astype("f4")
        self._white = ctx.texture((1, 1), 3, b"\xff\xff\xff")
        # Attachments shared by all output combinations.
        self._tex_rgb = ctx.renderbuffer((W, H), 4)
        self._tex_depth = ctx.renderbuffer((W, H), 1, dtype="f4")
        self._tex_normal = ctx.renderbuffer((W, H), 4, dtype="f4")
        self._zbuf = ctx.depth_renderbuffer((W, H))
        self._programs: dict = {}
        self._fbos: dict = {}
        self._vaos: dict = {}
        self._lighting: Lighting | None = None

        # Scene: one interleaved vertex buffer per distinct texture object (None = untextured);
        # transparent parts get a buffer each, drawn last (see the module docstring).
        groups: dict[int, list[MeshPart]] = {}
        textures: dict[int, np.ndarray | None] = {}
        glass: list[tuple[int, np.ndarray]] = []
        for part in self.scene.parts:
            if len(part.faces) == 0:
                continue
            key = id(part.texture) if (part.texture is not None and part.uv is not None) else 0
            textures[key] = part.texture if key else None
            if part.transparent:
                glass.append((key, part_vertices(part)))
            else:
                groups.setdefault(key, []).append(part)
        uploaded: dict[int, object] = {0: self._white}

        def texture_of(key: int):
            if key not in uploaded:
                uploaded[key] = upload_texture(ctx, textures[key], mipmaps=self._mipmaps, anisotropy=self._anisotropy)
            return uploaded[key]

        self._frustum = frustum_planes(self.intrinsics, NEAR, FAR)
        self._scene_draws = []
        for key, parts in groups.items():
            vbo, n, chunks, ibo = scene_buffers(ctx, parts, self._cull)
            occlusion = OcclusionTest(ctx, chunks, self._proj) if chunks is not None else None
            self._scene_draws.append(Draw(texture_of(key), vbo, n, chunks, ibo, occlusion))
        self._glass_draws = []  # (Draw, (3,) centroid)
        for key, data in glass:
            centroid = data["pos"].astype(np.float64).mean(axis=0)
            self._glass_draws.append((Draw(texture_of(key), ctx.buffer(data.tobytes()), len(data)), centroid))
        self._glass_fbo = ctx.framebuffer(color_attachments=[self._tex_rgb], depth_attachment=self._zbuf)
        self._glass_fbo.depth_mask = False
        self._query_fbo = query_framebuffer(ctx, self._zbuf)
        self._tag_textures: dict[int, object] = {}
        self._marker_draws: list = []
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        log.debug(
            "renderer: %d triangles in %d buffers (%d transparent), %dx%d, GL %s",
            self.scene.num_faces if self.scene.parts else 0,
            len(self._scene_draws) + len(self._glass_draws),
            len(self._glass_draws),
            W,
            H,
            ctx.info.get("GL_RENDERER", "?"),
        )

    def _tag_texture(self, tag_id: int):
        tex = self._tag_textures.get(tag_id)
        if tex is None:
            tex = tag_texture(self.ctx, tag_id)
            self._tag_textures[tag_id] = tex
        return tex

    def set_markers(self, markers: Sequence[Marker]) -> None:
        """Replace the drawn markers (the scene buffers are kept)."""
        self._make_current()
        for draw in self._marker_draws:
            draw.vbo.release()
        for key in [k for k in self._vaos if k[0] == "marker"]:
            self._vaos.pop(key).release()
        self._marker_draws = []
        for m in markers:
            data = marker_vertices(m)
            self._marker_draws.append(Draw(self._tag_texture(int(m.tag_id)), self.ctx.buffer(data.tobytes()), len(data)))
        self.markers = tuple(markers)

    def set_lighting(self, lighting: Lighting | None) -> None:
        """Light the RGB output of later renders with ``lighting`` (None: the map's light model,
        the default)."""
        self._lighting = lighting

    def _program(self, outputs: tuple[bool, bool, bool], alpha: bool = False):
        relit = self._lighting is not None and outputs[0]
        prog = self._programs.get((outputs, alpha, relit))
        if prog is None:
            prog = build_program(self.ctx, self._proj, outputs, alpha, relit)
            self._programs[(outputs, alpha, relit)] = prog
        if relit:
            for name, value in self._lighting.uniforms().items():
                prog[name].value = value
        return prog

    def _fbo(self, outputs: tuple[bool, bool, bool]):
        fbo = self._fbos.get(outputs)
        if fbo is None:
            atts = [a for a, on in zip((self._tex_rgb, self._tex_depth, self._tex_normal), outputs) if on]
            fbo = self.ctx.framebuffer(color_attachments=atts, depth_attachment=self._zbuf)
            self._fbos[outputs] = fbo
        return fbo

    def _vao(self, kind: str, index: int, draw: Draw, prog, outputs):
        key = (kind, index, outputs)
        vao = self._vaos.get(key)
        if vao is None:
            vao = vertex_array(self.ctx, prog, draw.vbo, draw.ibo)
            self._vaos[key] = vao
        return vao

    # ------------------------------------------------------------------ rendering
    def render(
        self,
        world_from_cam: np.ndarray,
        *,
        rgb: bool = True,
        depth: bool = True,
        normal: bool = True,
    ) -> RenderResult:
        """Render one view (this renderer's GL context is made current first, so several
        renderers can live in one process).

        Args:
            world_from_cam: (4, 4) camera pose (OpenCV camera frame, world z up, metres).
            rgb, depth, normal: which outputs to produce (skipping some is faster).

        Returns:
            :class:`RenderResult`; outputs not requested are None.
        """
        if self._closed:
            raise RuntimeError("renderer is closed")
        self._make_current()
        return self._render(world_from_cam, rgb, depth, normal)

    def _make_current(self) -> None:
        """Make this renderer's GL context the current one (and leave it current: moderngl's
        ``with ctx`` would restore the previous context, possibly none, on exit)."""
        self.ctx.mglo.__enter__()

    def _render(self, world_from_cam: np.ndarray, rgb: bool, depth: bool, normal: bool) -> RenderResult:
        outputs = (bool(rgb), bool(depth), bool(normal))
        if not any(outputs):
            raise ValueError("request at least one of rgb, depth, normal")
        T = np.asarray(world_from_cam, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"world_from_cam must be (4, 4), got {T.shape}")
        prog = self._program(outputs)
        fbo = self._fbo(outputs)
        cam_from_world = invert(T)
        prog["cam_from_world"].write(cam_from_world.astype("f4").T.tobytes())
        if "cam_pos" in prog:
            prog["cam_pos"].value = tuple(float(v) for v in T[:3, 3])
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        for kind, draws in (("scene", self._scene_draws), ("marker", self._marker_draws)):
            for i, draw in enumerate(draws):
                if outputs[0]:
                    draw.texture.use(0)
                vao = self._vao(kind, i, draw, prog, outputs + (prog.glo,))
                if draw.chunks is None:
                    vao.render(vertices=draw.n)
                else:
                    self._draw_chunks(draw, vao, fbo, cam_from_world, T[:3, 3])
        if outputs[0] and self._glass_draws:
            self._draw_glass(T)
        W, H = self._size
        att = 0
        out_rgb = out_depth = out_normal = None
        if outputs[0]:
            out_rgb = np.empty((H, W, 3), np.uint8)
            fbo.read_into(out_rgb, components=3, attachment=att, alignment=1)
            att += 1
        if outputs[1]:
            out_depth = np.empty((H, W), np.float32)
            fbo.read_into(out_depth, components=1, attachment=att, dtype="f4")
            att += 1
        if outputs[2]:
            out_normal = np.empty((H, W, 3), np.float32)
            fbo.read_into(out_normal, components=3, attachment=att, dtype="f4")
        return RenderResult(out_rgb, out_depth, out_normal, T.copy())

    def _draw_chunks(self, draw: Draw, vao, fbo, cam_from_world: np.ndarray, eye: np.ndarray) -> None:
        """Draw the chunks of a culled draw that the view needs: those in the frustum, in rounds
        nearest first, each after the first only where its occlusion query passes (:mod:`.draws`)."""
        rounds = by_distance(draw.chunks, visible_chunks(draw.chunks, cam_from_world, self._frustum), eye)
        for i, ids in enumerate(rounds):
            if i and len(ids):
                ids = ids[draw.occlusion.passed(self._query_fbo, cam_from_world, ids)]
                fbo.use()
            for first, count in chunk_ranges(draw.chunks, ids):
                vao.render(vertices=count, first=first)

    def _draw_glass(self, world_from_cam: np.ndarray) -> None:
        """Blend the transparent parts into the RGB attachment, far to near, without depth writes."""
        import moderngl

        ctx = self.ctx
        prog = self._program((True, False, False), alpha=True)
        prog["cam_from_world"].write(invert(world_from_cam).astype("f4").T.tobytes())
        prog["cam_pos"].value = tuple(float(v) for v in world_from_cam[:3, 3])
        self._glass_fbo.use()
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        try:
            eye = world_from_cam[:3, 3]
            order = sorted(range(len(self._glass_draws)), key=lambda i: -float(np.linalg.norm(self._glass_draws[i][1] - eye)))
            for i in order:
                draw = self._glass_draws[i][0]
                draw.texture.use(0)
                self._vao("glass", i, draw, prog, ("alpha", prog.glo)).render(vertices=draw.n)
        finally:
            ctx.disable(moderngl.BLEND)

    def render_batch(self, poses: Iterable[np.ndarray], **outputs: bool) -> Iterator[RenderResult]:
        """Render each (4, 4) ``world_from_cam`` of ``poses`` in turn (same flags as :meth:`render`)."""
        for T in poses:
            yield self.render(T, **outputs)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Release all GL objects and the context (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._make_current()
            self.ctx.release()
        except Exception:  # pragma: no cover - best effort on teardown
            log.debug("GL context release failed", exc_info=True)

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # pragma: no cover - GC safety net
        try:
            if not getattr(self, "_closed", True):
                self.close()
        except Exception:
            pass
