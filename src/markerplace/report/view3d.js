/* markerplace 3D view (report/view3d.py writes the data): WebGL 1, no library, no network.
   Each div.mp-view3d holds a canvas, a label layer, a cut slider and its data as JSON (base64
   arrays). Orbit: drag; pan: right-drag or shift-drag; zoom: wheel or pinch; click: pick by an
   id render into an off-screen framebuffer. window.mpView3d[id] is each view's API (the tests'). */
(function () {
  "use strict";
  if (window.mpView3d) { window.mpView3d.start(); return; }
  var registry = {};
  Object.defineProperty(registry, "start", {value: startAll});
  window.mpView3d = registry;

  function bytes(s) {
    var bin = atob(s), a = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) a[i] = bin.charCodeAt(i);
    return a;
  }
  // ---- column-major 4x4 maths
  function mul(a, b) {
    var o = new Float32Array(16);
    for (var c = 0; c < 4; c++) for (var r = 0; r < 4; r++) {
      var s = 0;
      for (var k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  }
  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function add(a, b, s) { return [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function norm(a) { var l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function lookAt(eye, at) {
    var f = norm(sub(at, eye)), s = norm(cross(f, [0, 0, 1])), u = cross(s, f);
    return new Float32Array([s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
      -dot(s, eye), -dot(u, eye), dot(f, eye), 1]);
  }
  function perspective(fovy, aspect, near, far) {
    var t = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return new Float32Array([t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
  }

  // ---- shaders
  var VS = "attribute vec3 aPos; attribute vec3 aCol; uniform mat4 uMvp; uniform vec3 uLo; uniform vec3 uExt;" +
    "varying vec3 vW; varying vec3 vC; void main() { vec3 w = uLo + aPos * uExt; vW = w; vC = aCol;" +
    " gl_Position = uMvp * vec4(w, 1.0); gl_PointSize = 4.0; }";
  var FS_LIT = "#extension GL_OES_standard_derivatives : enable\nprecision highp float; uniform vec3 uEye;" +
    " uniform float uCut; varying vec3 vW; varying vec3 vC; void main() { if (vW.z > uCut) discard;" +
    " vec3 n = normalize(cross(dFdx(vW), dFdy(vW))); float l = 0.35 + 0.65 * abs(dot(n, normalize(uEye - vW)));" +
    " gl_FragColor = vec4(vC * l, 1.0); }";
  var FS_UNLIT = "precision highp float; uniform float uCut; varying vec3 vW; varying vec3 vC;" +
    " void main() { if (vW.z > uCut) discard; gl_FragColor = vec4(vC, 1.0); }";
  var FS_FLAT = "precision highp float; uniform float uCut; uniform vec4 uColor; varying vec3 vW;" +
    " void main() { if (vW.z > uCut) discard; gl_FragColor = uColor; }";

  function program(gl, vs, fs) {
    var p = gl.createProgram();
    [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]].forEach(function (x) {
      var s = gl.createShader(x[0]);
      gl.shaderSource(s, x[1]);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    });
    gl.bindAttribLocation(p, 0, "aPos");
    gl.bindAttribLocation(p, 1, "aCol");
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    var u = {};
    ["uMvp", "uLo", "uExt", "uEye", "uCut", "uColor"].forEach(function (n) { u[n] = gl.getUniformLocation(p, n); });
    return {p: p, u: u};
  }

  function View(root) {
    var data = JSON.parse(root.querySelector("script.mp-view3d-data").textContent);
    var stage = root.querySelector(".mp-view3d-stage"), canvas = stage.querySelector("canvas");
    var layer = stage.querySelector(".mp-view3d-labels"), slider = root.querySelector("input.mp-cut");
    var cutText = root.querySelector(".mp-cut-value");
    var api = {frames: 0, error: null, selected: null};
    registry[root.id] = api;
    var gl = canvas.getContext("webgl", {antialias: true, preserveDrawingBuffer: true});
    if (!gl) {
      api.error = "this browser has no WebGL: the 3D view cannot be shown";
      stage.textContent = api.error;
      return;
    }
    var wide = data.index_bits === 32 && gl.getExtension("OES_element_index_uint");
    if (data.index_bits === 32 && !wide) {
      api.error = "this browser lacks 32-bit indices (OES_element_index_uint): the 3D view cannot be shown";
      stage.textContent = api.error;
      return;
    }
    var lit = gl.getExtension("OES_standard_derivatives");
    var meshProg = program(gl, VS, lit ? FS_LIT : FS_UNLIT), flatProg = program(gl, VS, FS_FLAT);
    var lo = data.lo, ext = data.extent, hi = [lo[0] + ext[0], lo[1] + ext[1], lo[2] + ext[2]];

    function buffer(target, array) {
      var b = gl.createBuffer();
      gl.bindBuffer(target, b);
      gl.bufferData(target, array, gl.STATIC_DRAW);
      return b;
    }
    var pos = buffer(gl.ARRAY_BUFFER, new Uint16Array(bytes(data.positions).buffer));
    var col = buffer(gl.ARRAY_BUFFER, bytes(data.colors));
    var idx = bytes(data.indices).buffer;
    var ibo = buffer(gl.ELEMENT_ARRAY_BUFFER, wide ? new Uint32Array(idx) : new Uint16Array(idx));
    var tags = [];
    data.planned.forEach(function (t, i) { tags.push({kind: "planned", index: i, t: t, rgb: data.colors_rgb.planned, scale: 1}); });
    data.found.forEach(function (t, i) { tags.push({kind: "found", index: i, t: t, rgb: data.colors_rgb.found, scale: 1}); });
    function quadVerts(t, scale) {
      var c = t.centre, out = [];
      [0, 1, 2, 0, 2, 3].forEach(function (k) {
        var p = t.corners[k];
        out.push(c[0] + scale * (p[0] - c[0]), c[1] + scale * (p[1] - c[1]), c[2] + scale * (p[2] - c[2]));
      });
      return out;
    }
    var quads = [];
    tags.forEach(function (g) { quads = quads.concat(quadVerts(g.t, 1)); });
    tags.forEach(function (g) { quads = quads.concat(quadVerts(g.t, 1.35)); });  // the selection frame
    var tagBuf = buffer(gl.ARRAY_BUFFER, new Float32Array(quads.length ? quads : [0, 0, 0]));
    var pathFlat = [].concat.apply([], data.path);
    var pathBuf = buffer(gl.ARRAY_BUFFER, new Float32Array(pathFlat.length ? pathFlat : [0, 0, 0]));
    var labels = tags.map(function (g) {
      var d = document.createElement("div");
      d.className = "mp-label mp-" + g.kind;
      d.textContent = g.t.label;
      d.style.background = "rgb(" + g.rgb.join(",") + ")";
      layer.appendChild(d);
      return d;
    });

    // ---- camera: orbit about a target
    var fov = 45 * Math.PI / 180, cam = {}, cut = hi[2] + 0.01;
    var topOfTags = -Infinity;
    tags.forEach(function (g) { topOfTags = Math.max(topOfTags, g.t.centre[2] + g.t.size / 2); });
    var defaultCut = isFinite(topOfTags) ? Math.min(hi[2] + 0.01, topOfTags + 0.3) : hi[2] + 0.01;
    slider.min = (lo[2]).toFixed(2);
    slider.max = (hi[2] + 0.05).toFixed(2);
    function setCut(z) {
      cut = z;
      slider.value = String(z);
      cutText.textContent = z.toFixed(2);
    }
    function reset() {
      setCut(defaultCut);
      var r = 0.5 * Math.hypot(ext[0], ext[1], Math.min(ext[2], cut - lo[2]));
      var aspect = canvas.clientWidth / Math.max(canvas.clientHeight, 1);
      cam = {target: [lo[0] + ext[0] / 2, lo[1] + ext[1] / 2, (lo[2] + Math.min(cut, hi[2])) / 2],
             az: -1.9, el: 1.0, dist: 0.95 * r / Math.tan(fov / 2) / Math.min(1, aspect)};
    }
    function eye() {
      var ce = Math.cos(cam.el);
      return add(cam.target, [ce * Math.cos(cam.az), ce * Math.sin(cam.az), Math.sin(cam.el)], cam.dist);
    }
    function mvp() {
      var near = Math.max(0.02, cam.dist * 0.02), far = cam.dist * 4 + 2 * Math.hypot(ext[0], ext[1], ext[2]);
      return mul(perspective(fov, canvas.width / Math.max(canvas.height, 1), near, far), lookAt(eye(), cam.target));
    }

    function resize() {
      var dpr = window.devicePixelRatio || 1;
      var w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
      if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; pick.size = null; }
    }
    function attribs(prog, quantised) {
      gl.uniform3fv(prog.u.uLo, quantised ? lo : [0, 0, 0]);
      gl.uniform3fv(prog.u.uExt, quantised ? ext : [1, 1, 1]);
    }
    function drawMesh(prog, M, idColor) {
      gl.useProgram(prog.p);
      gl.uniformMatrix4fv(prog.u.uMvp, false, M);
      gl.uniform1f(prog.u.uCut, cut);
      attribs(prog, true);
      if (idColor) gl.uniform4fv(prog.u.uColor, idColor); else gl.uniform3fv(prog.u.uEye, eye());
      gl.bindBuffer(gl.ARRAY_BUFFER, pos);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 3, gl.UNSIGNED_SHORT, true, 0, 0);
      if (idColor) gl.disableVertexAttribArray(1); else {
        gl.bindBuffer(gl.ARRAY_BUFFER, col);
        gl.enableVertexAttribArray(1);
        gl.vertexAttribPointer(1, 3, gl.UNSIGNED_BYTE, true, 0, 0);
      }
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ibo);
      gl.drawElements(gl.TRIANGLES, data.triangles * 3, wide ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
      gl.disableVertexAttribArray(1);
    }
    function rgba(rgb) { return [rgb[0] / 255, rgb[1] / 255, rgb[2] / 255, 1]; }
    function idColor(id) { return [(id & 255) / 255, ((id >> 8) & 255) / 255, 0, 1]; }
    function drawTags(M, forPick) {
      gl.useProgram(flatProg.p);
      gl.uniformMatrix4fv(flatProg.u.uMvp, false, M);
      gl.uniform1f(flatProg.u.uCut, cut);
      attribs(flatProg, false);
      gl.bindBuffer(gl.ARRAY_BUFFER, tagBuf);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      gl.enable(gl.POLYGON_OFFSET_FILL);
      var sel = api.selected;
      tags.forEach(function (g, i) {
        if (!forPick && sel && sel.kind === g.kind && sel.index === g.index) {
          gl.polygonOffset(-1, -2);
          gl.uniform4fv(flatProg.u.uColor, [1, 0.85, 0.1, 1]);
          gl.drawArrays(gl.TRIANGLES, 6 * (tags.length + i), 6);
        }
        gl.polygonOffset(g.kind === "found" ? -3 : -2, g.kind === "found" ? -6 : -4);
        gl.uniform4fv(flatProg.u.uColor, forPick ? idColor(2 + i) : rgba(g.rgb));
        gl.drawArrays(gl.TRIANGLES, 6 * i, 6);
      });
      gl.disable(gl.POLYGON_OFFSET_FILL);
      if (!forPick && data.path.length > 1) {
        gl.bindBuffer(gl.ARRAY_BUFFER, pathBuf);
        gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
        gl.uniform4fv(flatProg.u.uColor, rgba(data.colors_rgb.path));
        gl.drawArrays(gl.LINE_STRIP, 0, data.path.length);
        gl.drawArrays(gl.POINTS, 0, data.path.length);
      }
    }
    function draw() {
      resize();
      var M = mvp();
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(0.93, 0.945, 0.96, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.enable(gl.DEPTH_TEST);
      drawMesh(meshProg, M, null);
      drawTags(M, false);
      placeLabels(M);
      api.frames += 1;
      pick.size = null;  // the id image is stale
      clearTimeout(dimTimer);
      dimTimer = setTimeout(dimHidden, 250);
    }
    /* Once the camera rests: the label of a tag that the id render does not see is dimmed. */
    var dimTimer = null;
    function dimHidden() {
      var M = mvp();
      tags.forEach(function (g, i) {
        var s = project(M, g.t.centre);
        labels[i].classList.toggle("mp-hidden", !s || idAt(s[0], s[1]) !== 2 + i);
      });
    }

    // ---- picking: ids rendered into a framebuffer (0 nothing, 1 the model, 2 + i tag i)
    var pick = {fb: gl.createFramebuffer(), tex: gl.createTexture(), depth: gl.createRenderbuffer(), size: null};
    function renderPick() {
      if (pick.size) return;
      var w = canvas.width, h = canvas.height;
      gl.bindTexture(gl.TEXTURE_2D, pick.tex);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, w, h, 0, gl.RGBA, gl.UNSIGNED_BYTE, null);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.bindRenderbuffer(gl.RENDERBUFFER, pick.depth);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT16, w, h);
      gl.bindFramebuffer(gl.FRAMEBUFFER, pick.fb);
      gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, pick.tex, 0);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, pick.depth);
      gl.viewport(0, 0, w, h);
      gl.clearColor(0, 0, 0, 0);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.enable(gl.DEPTH_TEST);
      var M = mvp();
      drawMesh(flatProg, M, idColor(1));
      drawTags(M, true);
      pick.size = [w, h];
    }
    function idAt(clientX, clientY) {
      renderPick();
      var r = canvas.getBoundingClientRect(), dpr = canvas.width / Math.max(r.width, 1);
      var x = Math.floor((clientX - r.left) * dpr), y = canvas.height - 1 - Math.floor((clientY - r.top) * dpr);
      if (x < 0 || y < 0 || x >= canvas.width || y >= canvas.height) return 0;
      var px = new Uint8Array(4);
      gl.bindFramebuffer(gl.FRAMEBUFFER, pick.fb);
      gl.readPixels(x, y, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      return px[0] + 256 * px[1];
    }
    function project(M, p) {
      var x = M[0] * p[0] + M[4] * p[1] + M[8] * p[2] + M[12], y = M[1] * p[0] + M[5] * p[1] + M[9] * p[2] + M[13];
      var w = M[3] * p[0] + M[7] * p[1] + M[11] * p[2] + M[15];
      if (w <= 1e-6) return null;
      var r = canvas.getBoundingClientRect();
      return [r.left + (x / w + 1) / 2 * r.width, r.top + (1 - y / w) / 2 * r.height];
    }
    function placeLabels(M) {
      var r = canvas.getBoundingClientRect();
      tags.forEach(function (g, i) {
        var t = g.t, found = g.kind === "found", h = t.size / 2 * (found ? 0.7 : 1) + 0.03;
        var s = project(M, add(t.centre, t.up, found ? -h : h));  // planned: number above, found: below
        var hidden = !s || t.centre[2] > cut;
        labels[i].style.display = hidden ? "none" : "";
        if (!hidden) {
          labels[i].style.left = (s[0] - r.left) + "px";
          labels[i].style.top = (s[1] - r.top) + "px";
        }
      });
    }

    function select(kind, index) {
      api.selected = {kind: kind, index: index};
      var g = tags.filter(function (x) { return x.kind === kind && x.index === index; })[0];
      document.querySelectorAll(".mp-selected").forEach(function (e) { e.classList.remove("mp-selected"); });
      var card = g && g.t.card ? document.getElementById(g.t.card) : null;
      if (card) {
        card.classList.add("mp-selected");
        if (card.tagName === "DETAILS") card.open = true;
        card.scrollIntoView({block: "start"});
      }
      draw();
      root.dispatchEvent(new CustomEvent("mp-tag-select", {detail: {kind: kind, index: index, card: g && g.t.card}}));
    }
    function pickAt(clientX, clientY) {
      var id = idAt(clientX, clientY);
      return id >= 2 && id - 2 < tags.length ? {kind: tags[id - 2].kind, index: tags[id - 2].index} : null;
    }

    // ---- pointer: orbit, pan, zoom, click
    var pointers = {}, drag = null;
    canvas.style.touchAction = "none";
    canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
    canvas.addEventListener("pointerdown", function (e) {
      canvas.setPointerCapture(e.pointerId);
      pointers[e.pointerId] = [e.clientX, e.clientY];
      drag = {x: e.clientX, y: e.clientY, moved: 0, pan: e.button === 2 || e.shiftKey, pinch: null};
    });
    canvas.addEventListener("pointermove", function (e) {
      if (!drag || !pointers[e.pointerId]) return;
      var ids = Object.keys(pointers);
      if (ids.length === 2) {
        pointers[e.pointerId] = [e.clientX, e.clientY];
        var a = pointers[ids[0]], b = pointers[ids[1]], d = Math.hypot(a[0] - b[0], a[1] - b[1]);
        if (drag.pinch) cam.dist *= drag.pinch / Math.max(d, 1);
        drag.pinch = d;
        drag.moved += 10;
        draw();
        return;
      }
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY; drag.moved += Math.abs(dx) + Math.abs(dy);
      if (drag.pan) {
        var f = norm(sub(cam.target, eye())), s = norm(cross(f, [0, 0, 1])), u = cross(s, f);
        var k = cam.dist * 2 * Math.tan(fov / 2) / Math.max(canvas.clientHeight, 1);
        cam.target = add(add(cam.target, s, -dx * k), u, dy * k);
      } else {
        cam.az -= dx * 0.008;
        cam.el = Math.max(-1.5, Math.min(1.55, cam.el + dy * 0.008));
      }
      draw();
    });
    function up(e) {
      var click = drag && drag.moved < 5 && Object.keys(pointers).length === 1 && e.button === 0;
      delete pointers[e.pointerId];
      if (click) {
        var hit = pickAt(e.clientX, e.clientY);
        if (hit) select(hit.kind, hit.index);
      }
      if (!Object.keys(pointers).length) drag = null;
    }
    canvas.addEventListener("pointerup", up);
    canvas.addEventListener("pointercancel", function (e) { delete pointers[e.pointerId]; drag = null; });
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      cam.dist = Math.max(0.2, cam.dist * Math.exp(0.001 * e.deltaY));
      draw();
    }, {passive: false});
    slider.addEventListener("input", function () { setCut(Number(slider.value)); draw(); });
    root.querySelector("button.mp-reset").addEventListener("click", function () { reset(); draw(); });
    window.addEventListener("resize", draw);

    // ---- the API (tests, and other scripts of the page)
    api.draw = draw;
    api.select = select;
    api.pickAt = pickAt;
    api.setCut = function (z) { setCut(z); draw(); };
    api.reset = function () { reset(); draw(); };
    api.labels = function (on) { layer.style.display = on ? "" : "none"; };
    api.orbit = function (daz, del) { cam.az += daz; cam.el = Math.max(-1.5, Math.min(1.55, cam.el + del)); draw(); };
    api.camera = function () { return {target: cam.target.slice(), az: cam.az, el: cam.el, dist: cam.dist, cut: cut}; };
    api.focusTag = function (kind, index) {
      var g = tags.filter(function (x) { return x.kind === kind && x.index === index; })[0], n = g.t.normal;
      cam = {target: g.t.centre.slice(), az: Math.atan2(n[1], n[0]), el: Math.asin(Math.max(-1, Math.min(1, n[2]))) + 0.2,
             dist: Math.max(1.2, 4 * g.t.size)};
      if (g.t.centre[2] + g.t.size / 2 > cut) setCut(g.t.centre[2] + g.t.size / 2 + 0.05);
      draw();
    };
    /* Each tag's centre on the page (client CSS pixels), and whether the id render sees it there. */
    api.projectedTags = function () {
      var M = mvp();
      return tags.map(function (g, i) {
        var s = project(M, g.t.centre);
        return {kind: g.kind, index: g.index, id: g.t.id, label: g.t.label, card: g.t.card,
                x: s ? s[0] : null, y: s ? s[1] : null, visible: !!s && idAt(s[0], s[1]) === 2 + i};
      });
    };
    reset();
    draw();
    api.triangles = data.triangles;
    api.ready = true;
  }

  function startAll() {
    document.querySelectorAll("div.mp-view3d").forEach(function (root) {
      if (root.dataset.started) return;
      root.dataset.started = "1";
      try { View(root); } catch (err) {
        registry[root.id] = {error: String(err), frames: 0};
        root.querySelector(".mp-view3d-stage").textContent = "3D view failed: " + err;
      }
    });
  }
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", startAll); else startAll();
})();
