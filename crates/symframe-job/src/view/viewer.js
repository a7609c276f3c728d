// symframe viewer: decodes the embedded maps into WebGL2 half-float textures and relights them
// with the fragment shader as the controls (or the URL fragment) say.
//
// URL fragment (all optional), e.g. viewer.html#light=0.3,0.4,0.87&exposure=1&view=relit:
//   light=x,y,z      light direction, camera frame (x right, y up, z toward the camera)
//   exposure=E       stops (the picture is times 2^E, clamped, sRGB-encoded)
//   diffuse=S, specular=S, roughness=S   factors on kd, ks and both roughnesses (a glTF fit:
//                    on the base colour and the roughness; no specular factor)
//   rotate=DEG       tangent rotation about the normal, degrees
//   view=NAME        relit, normal, tangent, kd, ks (Ward) or base_color (glTF), confidence,
//                    anisotropy, source
//   ui=0             the canvas alone at the page's corner (for screenshots and tests)
// window.symframeReady becomes true once the first frame is drawn; window.symframeFrames
// counts frames drawn (a test that changes the fragment waits for it to grow).
"use strict";

(function () {
  const VIEWS = ["relit", "normal", "tangent", "kd", "ks", "confidence", "anisotropy", "source",
                 "base_color"];
  const DEFAULTS = { light: [0, 0, 1], exposure: 0, diffuse: 1, specular: 1, roughness: 1,
                     rotate: 0, view: "relit", ui: 1 };
  const $ = (id) => document.getElementById(id);
  const status = (msg) => { $("status").textContent = msg; };
  window.symframeReady = false;
  window.symframeFrames = 0;

  const data = JSON.parse($("symframe-data").textContent);
  const W = data.width, H = data.height;
  const state = Object.assign({}, DEFAULTS, { light: DEFAULTS.light.slice() });

  // ---- URL fragment <-> state -------------------------------------------------------------
  function num(v, lo, hi) {
    const x = Number(v);
    return Number.isFinite(x) ? Math.min(hi, Math.max(lo, x)) : null;
  }
  function readFragment() {
    const params = new URLSearchParams(location.hash.replace(/^#/, ""));
    const s = Object.assign({}, DEFAULTS, { light: DEFAULTS.light.slice() });
    if (params.has("light")) {
      const l = params.get("light").split(",").map(Number);
      const len = Math.hypot(l[0], l[1], l[2]);
      if (l.length === 3 && l.every(Number.isFinite) && len > 0) s.light = l.map((v) => v / len);
    }
    for (const [k, lo, hi] of [["exposure", -20, 20], ["diffuse", 0, 1e3], ["specular", 0, 1e3],
                               ["roughness", 1e-3, 1e3], ["rotate", -3600, 3600]]) {
      if (params.has(k)) {
        const v = num(params.get(k), lo, hi);
        if (v !== null) s[k] = v;
      }
    }
    if (params.has("view") && data.views.includes(params.get("view"))) s.view = params.get("view");
    if (params.get("ui") === "0") s.ui = 0;
    return s;
  }
  function writeFragment() {
    const r = (v) => String(Math.round(v * 1e4) / 1e4);
    const parts = ["light=" + state.light.map(r).join(",")];
    for (const k of ["exposure", "diffuse", "specular", "roughness", "rotate"]) {
      if (state[k] !== DEFAULTS[k]) parts.push(k + "=" + r(state[k]));
    }
    if (state.view !== "relit") parts.push("view=" + state.view);
    if (!state.ui) parts.push("ui=0");
    history.replaceState(null, "", "#" + parts.join("&"));
  }

  // ---- Decoding the textures ----------------------------------------------------------------
  function base64Bytes(s) {
    if (typeof Uint8Array.fromBase64 === "function") return Uint8Array.fromBase64(s);
    const bin = atob(s);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }
  // base64 -> zlib inflate -> low bytes then high bytes -> interleaved half floats.
  async function decodeTexture(s) {
    const stream = new Blob([base64Bytes(s)]).stream().pipeThrough(new DecompressionStream("deflate"));
    const bytes = new Uint8Array(await new Response(stream).arrayBuffer());
    const n = bytes.length >> 1;
    if (n !== W * H * 4) throw new Error(`a texture has ${n} values, ${W * H * 4} expected`);
    const out = new Uint16Array(n);
    for (let i = 0; i < n; i++) out[i] = bytes[i] | (bytes[n + i] << 8);
    return out;
  }
  function halfToFloat(h) {
    const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, f = h & 0x3ff;
    if (e === 0) return s * f * 2 ** -24;
    if (e === 31) return f ? NaN : s * Infinity;
    return s * (1 + f / 1024) * 2 ** (e - 15);
  }

  // ---- WebGL2 ----------------------------------------------------------------------------------
  const canvas = $("view");
  canvas.width = W;
  canvas.height = H;
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true,
                                           premultipliedAlpha: false, alpha: false });
  let program = null, uniforms = {};

  function compile(type, src) {
    const sh = gl.createShader(type);
    gl.shaderSource(sh, src.trim());
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(sh));
    return sh;
  }
  function setup(textures) {
    program = gl.createProgram();
    gl.attachShader(program, compile(gl.VERTEX_SHADER, $("vertex-shader").textContent));
    gl.attachShader(program, compile(gl.FRAGMENT_SHADER, $("fragment-shader").textContent));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(program));
    gl.useProgram(program);
    for (const name of ["uGeom", "uFrame", "uKd", "uKs", "uEst", "uView", "uLight", "uGain", "uDiffuse",
                        "uSpecular", "uRoughness", "uRotation", "uModel", "uIntensity"]) {
      uniforms[name] = gl.getUniformLocation(program, name);
    }
    gl.uniform1i(uniforms.uModel, data.model === "gltf" ? 1 : 0);
    gl.uniform1f(uniforms.uIntensity, data.light_intensity || 1);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    ["uGeom", "uFrame", "uKd", "uKs", "uEst"].forEach((name, unit) => {
      const tex = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, tex);
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
      for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(gl.TEXTURE_2D, p, gl.CLAMP_TO_EDGE);
      const px = textures[unit] || new Uint16Array(W * H * 4);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA16F, W, H, 0, gl.RGBA, gl.HALF_FLOAT, px);
      gl.uniform1i(uniforms[name], unit);
    });
    gl.bindVertexArray(gl.createVertexArray());
    gl.viewport(0, 0, W, H);
  }

  let pending = false;
  function draw() {
    pending = false;
    const rad = state.rotate * Math.PI / 180;
    gl.uniform1i(uniforms.uView, VIEWS.indexOf(state.view));
    gl.uniform3fv(uniforms.uLight, state.light);
    gl.uniform1f(uniforms.uGain, 2 ** state.exposure);
    gl.uniform1f(uniforms.uDiffuse, state.diffuse);
    gl.uniform1f(uniforms.uSpecular, state.specular);
    gl.uniform1f(uniforms.uRoughness, state.roughness);
    gl.uniform2f(uniforms.uRotation, Math.cos(rad), Math.sin(rad));
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    window.symframeFrames++;
    drawBall();
  }
  function redraw() {
    if (!pending && program) {
      pending = true;
      requestAnimationFrame(draw);
    }
  }

  // ---- Controls -----------------------------------------------------------------------------
  const SLIDERS = { exposure: (v) => v.toFixed(1), diffuse: (v) => v.toFixed(2),
                    specular: (v) => v.toFixed(2), roughness: (v) => v.toFixed(2),
                    rotate: (v) => v.toFixed(0) + "°" };
  function syncControls() {
    for (const [k, fmt] of Object.entries(SLIDERS)) {
      $(k).value = state[k];
      $(k + "Out").textContent = fmt(state[k]);
    }
    $("viewSel").value = state.view;
    document.body.classList.toggle("bare", !state.ui);
  }
  function applyFragment() {
    Object.assign(state, readFragment());
    syncControls();
    redraw();
  }
  function lightFromPointer(ev, el) {
    const r = el.getBoundingClientRect();
    let x = ((ev.clientX - r.left) / r.width) * 2 - 1;
    let y = 1 - ((ev.clientY - r.top) / r.height) * 2;
    const d = Math.hypot(x, y);
    if (d > 0.999) { x *= 0.999 / d; y *= 0.999 / d; }
    state.light = [x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))];
    writeFragment();
    redraw();
  }
  function drawBall() {
    const c = $("ball"), g = c.getContext("2d"), r = c.width / 2;
    g.clearRect(0, 0, c.width, c.height);
    g.fillStyle = "#333";
    g.beginPath(); g.arc(r, r, r - 1, 0, 2 * Math.PI); g.fill();
    g.strokeStyle = "#666";
    g.beginPath(); g.arc(r, r, (r - 1) * Math.sin(Math.PI / 4), 0, 2 * Math.PI); g.stroke();
    g.fillStyle = "#ffd54a";
    g.beginPath();
    g.arc(r + state.light[0] * (r - 1), r - state.light[1] * (r - 1), 5, 0, 2 * Math.PI);
    g.fill();
  }
  function dragOn(el) {
    el.addEventListener("pointerdown", (ev) => { el.setPointerCapture(ev.pointerId); lightFromPointer(ev, el); });
    el.addEventListener("pointermove", (ev) => { if (el.hasPointerCapture(ev.pointerId)) lightFromPointer(ev, el); });
  }

  // ---- Readout under the cursor ---------------------------------------------------------------
  let maps = null;
  function readout(ev) {
    if (!maps) return;
    const r = canvas.getBoundingClientRect();
    const x = Math.floor(((ev.clientX - r.left) / r.width) * W);
    const y = Math.floor(((ev.clientY - r.top) / r.height) * H);
    if (x < 0 || y < 0 || x >= W || y >= H) return;
    const at = (tex, c) => halfToFloat(tex[(y * W + x) * 4 + c]);
    const f = (v) => (Number.isFinite(v) ? v.toFixed(4).padStart(8) : "     n/a");
    const vec = (tex) => [0, 1, 2].map((c) => f(at(tex, c))).join("");
    const flag = Math.round(at(maps[0], 3));
    const lines = [`pixel   x ${x}, y ${y}`];
    const px = new Uint8Array(4);
    gl.readPixels(x, H - 1 - y, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    lines.push(`shown   ${px[0]} ${px[1]} ${px[2]} (sRGB)`);
    lines.push("normal " + (flag > 0 ? vec(maps[0]) : "     n/a"));
    lines.push("tangent" + (at(maps[1], 3) > 0.5 ? vec(maps[1]) : "     n/a (isotropic)"));
    if (flag === 2 && data.model === "gltf") {
      lines.push("base   " + vec(maps[2]));
      lines.push("metallic " + f(at(maps[2], 3)) + "  roughness " + f(at(maps[3], 0)));
      lines.push("anisotropy strength " + f(at(maps[3], 1)));
    } else if (flag === 2) {
      lines.push("kd     " + vec(maps[2]));
      lines.push("ks     " + vec(maps[3]));
      lines.push("alpha_t" + f(at(maps[2], 3)) + "  alpha_b" + f(at(maps[3], 3)));
    } else {
      lines.push("no fitted model");
    }
    if (maps[4]) {
      const has = Math.round(at(maps[4], 3));
      if (has & 1) lines.push("confidence " + f(at(maps[4], 0)));
      if (has & 2) lines.push("anisotropy " + f(at(maps[4], 1)));
      if (has & 4) lines.push("source     " + (data.sources[Math.round(at(maps[4], 2))] || "?"));
    }
    $("readout").textContent = lines.join("\n");
  }

  // ---- Start --------------------------------------------------------------------------------
  async function start() {
    if (!gl) throw new Error("this browser offers no WebGL2");
    if (typeof DecompressionStream !== "function") throw new Error("this browser has no DecompressionStream");
    if (data.format !== 1) throw new Error("unknown data format " + data.format);
    const most = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    if (W > most || H > most) throw new Error(`the maps are ${W} x ${H}; this browser's WebGL2 takes at most ${most} x ${most}`);
    const t0 = performance.now();
    const t = data.textures;
    maps = await Promise.all([t.geom, t.frame, t.kd, t.ks, t.est].map((s) => (s ? decodeTexture(s) : null)));
    setup(maps);
    // A glTF fit has no free specular albedo: its slider does nothing.
    if (data.model === "gltf") $("specular").disabled = true;
    const sel = $("viewSel");
    for (const v of data.views) sel.add(new Option(v, v));
    sel.addEventListener("change", () => { state.view = sel.value; writeFragment(); redraw(); });
    for (const k of Object.keys(SLIDERS)) {
      $(k).addEventListener("input", () => {
        state[k] = Number($(k).value);
        $(k + "Out").textContent = SLIDERS[k](state[k]);
        writeFragment();
        redraw();
      });
    }
    $("reset").addEventListener("click", () => {
      for (const k of Object.keys(SLIDERS)) state[k] = DEFAULTS[k];
      syncControls();
      writeFragment();
      redraw();
    });
    dragOn(canvas);
    dragOn($("ball"));
    canvas.addEventListener("pointermove", readout);
    window.addEventListener("hashchange", applyFragment);
    Object.assign(state, readFragment());
    syncControls();
    draw();
    gl.finish();
    window.symframeLoadMs = performance.now() - t0;
    window.symframeReady = true;
  }
  start().catch((e) => {
    status("symframe viewer: " + e.message);
    window.symframeError = e.message;
  });
})();
