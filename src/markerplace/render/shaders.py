"""GLSL sources of the renderer.

One vertex shader; the fragment shader is generated for the outputs requested (RGB, depth,
normal), so a pass that needs only depth skips texture sampling and lighting.

Vertex attributes (world frame): ``in_pos`` (3f, metres), ``in_normal`` (3f), ``in_uv`` (2f, GL
texture coordinates: t = 0 is image row 0), ``in_color`` (4 x u8 normalized, base colour x vertex
colour). Uniforms: ``proj`` (4x4, OpenCV intrinsics -> clip, see gl_resources.projection_matrix),
``cam_from_world`` (4x4), ``cam_pos`` (3, world).

The map's light model (:data:`AMBIENT` + :data:`HEADLIGHT`) is baked into every render; a
*relit* fragment shader (``fragment(..., relit=True)``, the testbed's ``lighting`` query
condition) replaces it by :data:`RELIT_UNIFORMS` set per render
(:class:`markerplace.render.renderer.Lighting`): ambient + headlight + a directional "sun"
(``u_sun * max(n . u_sun_dir, 0)`` on the camera-facing normal, so surfaces facing away are in
shade) and, beyond a vertical plane through ``u_cut_point`` with horizontal normal
``u_cut_normal`` (world xy, metres), every term dimmed by ``u_dim`` (a zone with its lights off;
0.5 m smooth transition).
"""

from __future__ import annotations

VERTEX = """
#version 330
uniform mat4 proj;
uniform mat4 cam_from_world;
uniform vec3 cam_pos;
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
in vec4 in_color;
out vec3 v_normal;
out vec3 v_view;
out vec2 v_uv;
out vec4 v_color;
out float v_depth;
void main() {
    vec4 p_cam = cam_from_world * vec4(in_pos, 1.0);
    v_depth = p_cam.z;
    v_normal = in_normal;
    v_view = cam_pos - in_pos;
    v_uv = in_uv;
    v_color = in_color;
    gl_Position = proj * p_cam;
}
"""

# Lighting: ambient + a headlight term on the camera-facing normal. Deterministic, view-dependent
# only through the angle of incidence, and mild so textures stay recognisable.
AMBIENT = 0.6
HEADLIGHT = 0.4


#: Uniforms of the relit fragment shader: name -> GLSL type.
RELIT_UNIFORMS = {"u_ambient": "float", "u_headlight": "float", "u_sun": "float", "u_sun_dir": "vec3",
                  "u_cut_point": "vec2", "u_cut_normal": "vec2", "u_dim": "float"}


def _relit_body() -> list[str]:
    """GLSL lines of the relit light model (see the module docstring): sets ``light``."""
    return ["vec3 p = cam_pos - v_view;",
            "float side = smoothstep(-0.25, 0.25, dot(p.xy - u_cut_point, u_cut_normal));",
            "float light = (u_ambient + u_headlight * c + u_sun * max(dot(n, u_sun_dir), 0.0)) * (1.0 - u_dim * side);"]


def fragment(rgb: bool, depth: bool, normal: bool, alpha: bool = False, relit: bool = False) -> str:
    """Fragment shader writing the requested outputs to consecutive colour attachments.

    Attachment order: rgb (RGBA8) if requested, then depth (R32F) if requested, then the world
    normal (RGBA32F, xyz = unit normal facing the camera) if requested. With ``alpha`` the rgb
    output carries the surface's opacity (vertex colour alpha x texture alpha) for blending
    (transparent parts); otherwise its alpha is 1. With ``relit`` the rgb output uses the relit
    light model (:data:`RELIT_UNIFORMS`) instead of the map's.
    """
    outs, body, loc = [], [], 0
    need_n = rgb or normal
    if need_n:
        body.append("vec3 n = normalize(v_normal);")
        body.append("vec3 v = normalize(v_view);")
        body.append("float c = dot(n, v);")
        body.append("if (c < 0.0) { n = -n; c = -c; }")
    if rgb:
        outs.append(f"layout(location = {loc}) out vec4 out_rgb;")
        body.append("vec4 albedo = v_color * texture(tex, v_uv);")
        if relit:
            body.extend(_relit_body())
            body.append(f"out_rgb = vec4(albedo.rgb * light, {'albedo.a' if alpha else '1.0'});")
        else:
            body.append(f"out_rgb = vec4(albedo.rgb * ({AMBIENT} + {HEADLIGHT} * c), {'albedo.a' if alpha else '1.0'});")
        loc += 1
    if depth:
        outs.append(f"layout(location = {loc}) out float out_depth;")
        body.append("out_depth = v_depth;")
        loc += 1
    if normal:
        outs.append(f"layout(location = {loc}) out vec4 out_normal;")
        body.append("out_normal = vec4(n, 1.0);")
        loc += 1
    return "\n".join(
        [
            "#version 330",
            "uniform sampler2D tex;",
            *([f"uniform {t} {n};" for n, t in RELIT_UNIFORMS.items()] + ["uniform vec3 cam_pos;"]
              if relit and rgb else []),
            "in vec3 v_normal;",
            "in vec3 v_view;",
            "in vec2 v_uv;",
            "in vec4 v_color;",
            "in float v_depth;",
            *outs,
            "void main() {",
            *("    " + b for b in body),
            "}",
        ]
    )
