// symframe viewer: decodes the maps (in the page, and for a large map tiles of a pyramid in
// the folder beside it) into WebGL2 half-float textures and relights them with the fragment
// shader as the controls (or the URL fragment) say; zooms and pans.
//
// URL fragment (all optional), e.g. viewer.html#light=0.3,0.4,0.87&exposure=1&view=relit:
//   light=x,y,z      light direction, camera frame (x right, y up, z toward the camera)
//   exposure=E       stops (the picture is times 2^E, clamped, sRGB-encoded)
//   diffuse=S, specular=S, roughness=S   factors on kd, ks and both roughnesses (a glTF fit:
//                    on the base colour and the roughness; no specular factor; an estimate:
//                    on its stand-in material)
//   rotate=DEG       tangent rotation about the normal, degrees
//   view=NAME        relit, normal, tangent, kd, ks (Ward) or base_color (glTF), confidence,
//                    anisotropy, source, samples (the capture's photographs relit themselves,
//                    where the page was written with --from-samples)
//   zoom=Z           screen (CSS) pixels per map pixel (absent: the map fits the canvas)
//   cx=X, cy=Y       the map point at the canvas' centre, map pixels from the top left corner
//                    (default: the map's centre); zoom=1 in a canvas of the map's size shows
//                    map pixel (i, j) at canvas pixel (i, j)
//   ui=0             the canvas alone, filling the window (for screenshots and tests)
// Hooks for tests: window.symframeReady becomes true once the first frame is drawn;
// window.symframeFrames counts frames drawn; window.symframeTilesLoaded counts pyramid tiles
// loaded (window.symframeDecodeMs: the time spent decoding them and the page's level,
// window.symframeReadyAt: when the first frame was drawn, ms after navigation);
// window.symframeIdle() is true when no tile is wanted or on its way and the last
// frame shows every loaded tile; window.symframeView() is the view's state.
"use strict";

(function () {
  const VIEWS = ["relit", "normal", "tangent", "kd", "ks", "confidence", "anisotropy", "source",
                 "base_color", "samples"];
  const DEFAULTS = { light: [0, 0, 1], exposure: 0, diffuse: 1, specular: 1, roughness: 1,
                     rotate: 0, view: "relit", ui: 1, zoom: null, cx: null, cy: null };
  const $ = (id) => document.getElementById(id);
  const status = (msg) => { $("status").textContent = msg; };
  window.symframeReady = false;
  window.symframeFrames = 0;
  window.symframeTilesLoaded = 0;

  const data = JSON.parse($("symframe-data").textContent);
  const W = data.width, H = data.height;
  const PYR = data.pyramid;
  const TOP = PYR ? PYR.levels - 1 : 0;
  const TILE = PYR ? PYR.tile : Math.max(W, H);
  const copy = (s) => Object.assign({}, s, { light: s.light.slice() });
  const state = copy(DEFAULTS);
  let lightMode = false;

  // ---- URL fragment <-> state -------------------------------------------------------------
  function num(v, lo, hi) {
    const x = Number(v);
    return v !== null && v !== "" && Number.isFinite(x) ? Math.min(hi, Math.max(lo, x)) : null;
  }
  function readFragment() {
    const params = new URLSearchParams(location.hash.replace(/^#/, ""));
    const s = copy(DEFAULTS);
    if (params.has("light")) {
      const l = params.get("light").split(",").map(Number);
      const len = Math.hypot(l[0], l[1], l[2]);
      if (l.length === 3 && l.every(Number.isFinite) && len > 0) s.light = l.map((v) => v / len);
    }
    for (const [k, lo, hi] of [["exposure", -20, 20], ["diffuse", 0, 1e3], ["specular", 0, 1e3],
                               ["roughness", 1e-3, 1e3], ["rotate", -3600, 3600],
                               ["zoom", 1e-4, 1e4], ["cx", -1e7, 1e7], ["cy", -1e7, 1e7]]) {
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
    if (state.zoom !== null) {
      const v = view();
      parts.push("zoom=" + String(Math.round(v.zoom * 1e6) / 1e6), "cx=" + r(v.cx), "cy=" + r(v.cy));
    }
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
  async function decodeTexture(s, w, h) {
    const stream = new Blob([base64Bytes(s)]).stream().pipeThrough(new DecompressionStream("deflate"));
    const bytes = new Uint8Array(await new Response(stream).arrayBuffer());
    const n = bytes.length >> 1;
    if (n !== w * h * 4) throw new Error(`a texture has ${n} values, ${w * h * 4} expected`);
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
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true,
                                           premultipliedAlpha: false, alpha: false });
  const NAMES = ["geom", "frame", "kd", "ks", "est"];
  const SAMPLERS = ["uGeom", "uFrame", "uKd", "uKs", "uEst"];
  let program = null, uniforms = {}, blank = null;

  function compile(type, src) {
    const sh = gl.createShader(type);
    gl.shaderSource(sh, src.trim());
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(sh));
    return sh;
  }
  // A new texture bound to `target`, read texel by texel (nearest, clamped at the edges).
  function nearestTexture(target) {
    const tex = gl.createTexture();
    gl.bindTexture(target, tex);
    for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(target, p, gl.NEAREST);
    for (const p of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T]) gl.texParameteri(target, p, gl.CLAMP_TO_EDGE);
    return tex;
  }
  function texture(w, h, px) {
    const tex = nearestTexture(gl.TEXTURE_2D);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA16F, w, h, 0, gl.RGBA, gl.HALF_FLOAT, px);
    return tex;
  }
  function arrayTexture(w, h, layers, px) {
    const tex = nearestTexture(gl.TEXTURE_2D_ARRAY);
    gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, gl.RGBA16F, w, h, layers, 0, gl.RGBA, gl.HALF_FLOAT, px);
    return tex;
  }
  function floatTexture(w, h, px) {
    const tex = nearestTexture(gl.TEXTURE_2D);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, px);
    return tex;
  }
  // The view `samples`: the frames and slices as one texture array (layer 0 normals, 1
  // tangents, then one per light), the rig's triangles as three RGBA32F texels a row.
  async function addSamples(smp) {
    const layers = smp.lights + 2;
    if (layers > gl.getParameter(gl.MAX_ARRAY_TEXTURE_LAYERS)) throw new Error(`the samples have ${smp.lights} lights; this browser's texture arrays take ${gl.getParameter(gl.MAX_ARRAY_TEXTURE_LAYERS) - 2}`);
    const px = await decodeTexture(smp.layers, W, H * layers);
    gl.activeTexture(gl.TEXTURE5);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, arrayTexture(W, H, layers, px));
    const tri = new Float32Array(smp.triangles.length * 12);
    smp.triangles.forEach((rows, k) => rows.forEach((row, r) => tri.set(row, 12 * k + 4 * r)));
    gl.activeTexture(gl.TEXTURE6);
    gl.bindTexture(gl.TEXTURE_2D, floatTexture(3, smp.triangles.length, tri));
    gl.uniform1i(uniforms.uTriangles, smp.triangles.length);
  }
  function setup() {
    program = gl.createProgram();
    gl.attachShader(program, compile(gl.VERTEX_SHADER, $("vertex-shader").textContent));
    gl.attachShader(program, compile(gl.FRAGMENT_SHADER, $("fragment-shader").textContent));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(program));
    gl.useProgram(program);
    for (const name of SAMPLERS.concat(["uView", "uLight", "uGain", "uDiffuse", "uSpecular",
                                        "uRoughness", "uRotation", "uModel", "uIntensity", "uRect",
                                        "uCenter", "uZoom", "uCanvas", "uOrigin", "uScale",
                                        "uSamples", "uTris", "uTriangles"])) {
      uniforms[name] = gl.getUniformLocation(program, name);
    }
    gl.uniform1i(uniforms.uModel, { ward: 0, gltf: 1, estimate: 2 }[data.model] || 0);
    gl.uniform1f(uniforms.uIntensity, data.light_intensity || 1);
    SAMPLERS.forEach((name, unit) => gl.uniform1i(uniforms[name], unit));
    // The view `samples` reads units 5 (the texture array) and 6 (the triangulation); until
    // (or unless) the samples are loaded, blank textures of the right kinds sit there.
    gl.uniform1i(uniforms.uSamples, 5);
    gl.uniform1i(uniforms.uTris, 6);
    gl.uniform1i(uniforms.uTriangles, 0);
    gl.activeTexture(gl.TEXTURE5);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, arrayTexture(1, 1, 1, new Uint16Array(4)));
    gl.activeTexture(gl.TEXTURE6);
    gl.bindTexture(gl.TEXTURE_2D, floatTexture(1, 1, new Float32Array(4)));
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    blank = texture(1, 1, new Uint16Array(4));
    gl.bindVertexArray(gl.createVertexArray());
  }

  // ---- Tiles: the page's level, and the pyramid's loaded on demand --------------------------
  // A tile: level k, position (x, y) in tiles, size w x h texels; maps (half floats, for the
  // readout) and textures by NAMES.
  const tiles = new Map();
  const key = (k, x, y) => `${k}/${x}/${y}`;
  const wanted = new Map(); // key -> [k, x, y] not yet asked for
  const loading = new Set();
  const failed = new Set(); // tiles whose script did not load: not asked for again
  const MAX_LOADING = 6;
  const BUDGET = 12e6; // texels of tiles kept besides those on screen
  let decoding = 0, shownAll = true, useTick = 0;

  async function addTile(k, x, y, w, h, t) {
    decoding++;
    const t0 = performance.now();
    try {
      const maps = await Promise.all(NAMES.map((n) => (t[n] ? decodeTexture(t[n], w, h) : null)));
      const tex = maps.map((m) => (m ? texture(w, h, m) : null));
      tiles.set(key(k, x, y), { k, x, y, w, h, maps, tex, used: ++useTick });
      shownAll = false;
    } finally {
      decoding--;
      window.symframeDecodeMs = (window.symframeDecodeMs || 0) + performance.now() - t0;
    }
  }
  // Tile scripts call this (works from file: URLs, where fetch does not).
  window.symframeTile = function (k, x, y, w, h, t) {
    addTile(k, x, y, w, h, t).then(() => {
      window.symframeTilesLoaded++;
      loading.delete(key(k, x, y));
      pump();
      redraw();
    }, (e) => status("symframe viewer: tile " + key(k, x, y) + ": " + e.message));
  };
  function pump() {
    while (loading.size < MAX_LOADING && wanted.size > 0) {
      const [id, [k, x, y]] = wanted.entries().next().value;
      wanted.delete(id);
      loading.add(id);
      const el = document.createElement("script");
      el.onload = () => el.remove();
      el.onerror = () => {
        el.remove();
        loading.delete(id);
        failed.add(id);
        status(`symframe viewer: ${PYR.dir}/${k}/${x}_${y}.js did not load (is the folder beside the page?)`);
        pump();
      };
      el.src = `${PYR.dir}/${k}/${x}_${y}.js`;
      document.head.appendChild(el);
    }
  }
  // Frees the least recently drawn tiles beyond the budget (never the page's level).
  function evict() {
    let total = 0;
    const list = [];
    for (const t of tiles.values()) {
      if (t.k === TOP) continue;
      total += t.w * t.h;
      list.push(t);
    }
    if (total <= BUDGET) return;
    list.sort((a, b) => a.used - b.used);
    for (const t of list) {
      if (total <= BUDGET || t.used === useTick) break;
      for (const x of t.tex) if (x) gl.deleteTexture(x);
      tiles.delete(key(t.k, t.x, t.y));
      total -= t.w * t.h;
    }
  }
  window.symframeIdle = () => wanted.size === 0 && loading.size === 0 && decoding === 0 && shownAll && !pending;

  // ---- The view: zoom (CSS pixels per map pixel) and the map point at the centre ------------
  const dpr = () => window.devicePixelRatio || 1;
  function cssSize() {
    return [canvas.clientWidth || 1, canvas.clientHeight || 1];
  }
  function fitZoom() {
    const [cw, ch] = cssSize();
    return Math.min(cw / W, ch / H);
  }
  function view() {
    return {
      zoom: state.zoom !== null ? state.zoom : fitZoom(),
      cx: state.cx !== null ? state.cx : W / 2,
      cy: state.cy !== null ? state.cy : H / 2,
    };
  }
  window.symframeView = () => {
    const v = view();
    return Object.assign(v, { fit: state.zoom === null, level: levelFor(v.zoom * dpr()),
                              canvas: [canvas.width, canvas.height], lightMode });
  };
  // The map point under a point of the canvas (CSS pixels from its top left).
  function mapAt(px, py) {
    const v = view(), [cw, ch] = cssSize();
    return [v.cx + (px - cw / 2) / v.zoom, v.cy + (py - ch / 2) / v.zoom];
  }
  function setView(zoom, cx, cy) {
    const lo = Math.min(fitZoom(), 1) / 8;
    state.zoom = Math.min(512, Math.max(lo, zoom));
    state.cx = cx;
    state.cy = cy;
    writeFragment();
    redraw();
  }
  // Zooms by `f` keeping the map point under (px, py) (CSS pixels in the canvas) in place.
  function zoomAbout(px, py, f) {
    const v = view(), [cw, ch] = cssSize();
    const [mx, my] = mapAt(px, py);
    const lo = Math.min(fitZoom(), 1) / 8;
    const z = Math.min(512, Math.max(lo, v.zoom * f));
    setView(z, mx - (px - cw / 2) / z, my - (py - ch / 2) / z);
  }
  function panBy(dx, dy) {
    const v = view();
    setView(v.zoom, v.cx - dx / v.zoom, v.cy - dy / v.zoom);
  }
  // The pyramid level drawn at `zoom` device pixels per map pixel: one texel to about one
  // device pixel (at 1:1 and closer, full resolution).
  function levelFor(zoom) {
    return Math.max(0, Math.min(TOP, Math.round(Math.log2(1 / zoom))));
  }

  let pending = false;
  function draw() {
    pending = false;
    const d = dpr();
    const [cw, ch] = cssSize();
    const bw = Math.max(1, Math.round(cw * d)), bh = Math.max(1, Math.round(ch * d));
    if (canvas.width !== bw || canvas.height !== bh) {
      canvas.width = bw;
      canvas.height = bh;
    }
    gl.viewport(0, 0, bw, bh);
    gl.clearColor(0.15, 0.15, 0.15, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    const v = view();
    const zoom = v.zoom * d;
    const rad = state.rotate * Math.PI / 180;
    gl.uniform1i(uniforms.uView, VIEWS.indexOf(state.view));
    gl.uniform3fv(uniforms.uLight, state.light);
    gl.uniform1f(uniforms.uGain, 2 ** state.exposure);
    gl.uniform1f(uniforms.uDiffuse, state.diffuse);
    gl.uniform1f(uniforms.uSpecular, state.specular);
    gl.uniform1f(uniforms.uRoughness, state.roughness);
    gl.uniform2f(uniforms.uRotation, Math.cos(rad), Math.sin(rad));
    gl.uniform2f(uniforms.uCenter, v.cx, v.cy);
    gl.uniform1f(uniforms.uZoom, zoom);
    gl.uniform2f(uniforms.uCanvas, bw, bh);
    // The map rectangle on screen.
    const x0 = Math.max(0, v.cx - bw / 2 / zoom), x1 = Math.min(W, v.cx + bw / 2 / zoom);
    const y0 = Math.max(0, v.cy - bh / 2 / zoom), y1 = Math.min(H, v.cy + bh / 2 / zoom);
    const level = levelFor(zoom);
    useTick++;
    const drawn = [];
    if (x1 > x0 && y1 > y0) {
      // Coarse levels first, finer ones over them as they arrive.
      for (let k = TOP; k >= level; k--) {
        const span = TILE * 2 ** k;
        for (let ty = Math.floor(y0 / span); ty * span < y1; ty++) {
          for (let tx = Math.floor(x0 / span); tx * span < x1; tx++) {
            const t = tiles.get(key(k, tx, ty));
            if (t) {
              drawTile(t);
              drawn.push(t);
            } else if (k === level && !loading.has(key(k, tx, ty)) && !failed.has(key(k, tx, ty))) {
              wanted.set(key(k, tx, ty), [k, tx, ty]);
            }
          }
        }
      }
    }
    // Tiles no longer on screen are not fetched.
    for (const [id, [k, tx, ty]] of wanted) {
      const span = TILE * 2 ** k;
      if (k !== level || (tx + 1) * span <= x0 || tx * span >= x1 || (ty + 1) * span <= y0 || ty * span >= y1) {
        wanted.delete(id);
      }
    }
    shownAll = true;
    window.symframeFrames++;
    drawBall();
    if (PYR) {
      evict();
      pump();
    }
    const pct = v.zoom * 100;
    $("zoomOut").textContent = `zoom ${pct >= 10 ? Math.round(pct) : pct.toPrecision(2)}%` +
      (state.zoom === null ? " (fit)" : "") + (PYR ? `, pyramid level ${level} of ${TOP}` : "") +
      `, centre ${v.cx.toFixed(1)}, ${v.cy.toFixed(1)}`;
  }
  function drawTile(t) {
    const s = 2 ** t.k, span = TILE * s;
    t.used = useTick;
    for (let unit = 0; unit < 5; unit++) {
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, t.tex[unit] || blank);
    }
    gl.uniform4f(uniforms.uRect, t.x * span, t.y * span, Math.min(W, t.x * span + t.w * s),
                 Math.min(H, t.y * span + t.h * s));
    gl.uniform2f(uniforms.uOrigin, t.x * span, t.y * span);
    gl.uniform1f(uniforms.uScale, s);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
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
    legend();
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
  function capture(el, id) {
    try { el.setPointerCapture(id); } catch (e) { /* a synthetic pointer */ }
  }
  function setLightMode(on) {
    lightMode = on;
    $("lightMode").checked = on;
    canvas.style.cursor = on ? "crosshair" : "grab";
  }

  // The canvas: a drag pans (with shift, the right button or in light mode it moves the
  // light), two pointers pinch-zoom, the wheel zooms about the cursor.
  const pointers = new Map();
  let gesture = null;
  function local(ev) {
    const r = canvas.getBoundingClientRect();
    return [ev.clientX - r.left, ev.clientY - r.top];
  }
  function pinchOf() {
    const [a, b] = [...pointers.values()];
    return { mid: [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2], dist: Math.hypot(a[0] - b[0], a[1] - b[1]) };
  }
  function canvasInput() {
    canvas.addEventListener("contextmenu", (ev) => ev.preventDefault());
    canvas.addEventListener("pointerdown", (ev) => {
      capture(canvas, ev.pointerId);
      pointers.set(ev.pointerId, local(ev));
      if (pointers.size === 2) {
        gesture = Object.assign({ kind: "pinch" }, pinchOf());
      } else if (pointers.size === 1) {
        const light = ev.shiftKey || ev.button === 2 || lightMode;
        gesture = { kind: light ? "light" : "pan", at: local(ev) };
        if (light) lightFromPointer(ev, canvas);
        else canvas.style.cursor = "grabbing";
      }
    });
    canvas.addEventListener("pointermove", (ev) => {
      readout(ev);
      if (!pointers.has(ev.pointerId)) return;
      pointers.set(ev.pointerId, local(ev));
      if (!gesture) return;
      if (gesture.kind === "light") {
        lightFromPointer(ev, canvas);
      } else if (gesture.kind === "pan") {
        const p = local(ev);
        panBy(p[0] - gesture.at[0], p[1] - gesture.at[1]);
        gesture.at = p;
      } else if (gesture.kind === "pinch" && pointers.size === 2) {
        const now = pinchOf();
        panBy(now.mid[0] - gesture.mid[0], now.mid[1] - gesture.mid[1]);
        if (gesture.dist > 0 && now.dist > 0) zoomAbout(now.mid[0], now.mid[1], now.dist / gesture.dist);
        gesture = Object.assign({ kind: "pinch" }, now);
      }
    });
    const up = (ev) => {
      pointers.delete(ev.pointerId);
      if (pointers.size === 1 && gesture && gesture.kind === "pinch") {
        gesture = { kind: "pan", at: [...pointers.values()][0] };
      } else if (pointers.size === 0) {
        gesture = null;
        canvas.style.cursor = lightMode ? "crosshair" : "grab";
      }
    };
    canvas.addEventListener("pointerup", up);
    canvas.addEventListener("pointercancel", up);
    canvas.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      const px = ev.deltaMode === 1 ? 16 : ev.deltaMode === 2 ? 400 : 1;
      const f = Math.exp(-Math.max(-400, Math.min(400, ev.deltaY * px)) * 0.002);
      const [x, y] = local(ev);
      zoomAbout(x, y, f);
    }, { passive: false });
    window.addEventListener("keydown", (ev) => {
      if (ev.target instanceof HTMLInputElement || ev.target instanceof HTMLSelectElement ||
          ev.ctrlKey || ev.metaKey || ev.altKey) return;
      const [cw, ch] = cssSize();
      const step = 0.1 * Math.min(cw, ch);
      const acts = {
        "+": () => zoomAbout(cw / 2, ch / 2, 2), "=": () => zoomAbout(cw / 2, ch / 2, 2),
        "-": () => zoomAbout(cw / 2, ch / 2, 0.5), "_": () => zoomAbout(cw / 2, ch / 2, 0.5),
        "0": () => { state.zoom = state.cx = state.cy = null; writeFragment(); redraw(); },
        "1": () => { const v = view(); setView(1 / dpr(), v.cx, v.cy); },
        ArrowLeft: () => panBy(step, 0), ArrowRight: () => panBy(-step, 0),
        ArrowUp: () => panBy(0, step), ArrowDown: () => panBy(0, -step),
        l: () => setLightMode(!lightMode), L: () => setLightMode(!lightMode),
      };
      if (acts[ev.key]) {
        ev.preventDefault();
        acts[ev.key]();
      }
    });
  }

  // ---- Legends: what the colours of the current view mean ----------------------------------
  // The shader's colour maps, for the legends' pictures.
  function viridis(t) {
    t = Math.min(1, Math.max(0, t));
    const c = [[0.2777273272234177, 0.005407344544966578, 0.3340998053353061],
               [0.1050930431085774, 1.404613529898575, 1.384590162594685],
               [-0.3308618287255563, 0.214847559468213, 0.09509516302823659],
               [-4.634230498983486, -5.799100973351585, -19.33244095627987],
               [6.228269936347081, 14.17993336680509, 56.69055260068105],
               [4.776384997670288, -13.74514537774601, -65.35303263337234],
               [-5.435455855934631, 4.645852612178535, 26.3124352495832]];
    return [0, 1, 2].map((i) => {
      let v = c[6][i];
      for (let k = 5; k >= 0; k--) v = c[k][i] + t * v;
      return Math.min(1, Math.max(0, v));
    });
  }
  function hue(turns) {
    const h = (turns - Math.floor(turns)) * 6, s = Math.min(Math.floor(h), 5), f = h - s;
    return [[1, f, 0], [1 - f, 1, 0], [0, 1, f], [0, 1 - f, 1], [f, 0, 1], [1, 0, 1 - f]][s];
  }
  const srgb = (v) => (v <= 0.0031308 ? v * 12.92 : 1.055 * v ** (1 / 2.4) - 0.055);
  function paint(w, h, colour) {
    const c = document.createElement("canvas");
    c.width = w;
    c.height = h;
    const g = c.getContext("2d"), img = g.createImageData(w, h);
    for (let y = 0; y < h; y++) {
      for (let x = 0; x < w; x++) {
        const rgb = colour(x, y), i = (y * w + x) * 4;
        if (!rgb) continue;
        for (let k = 0; k < 3; k++) img.data[i + k] = Math.round(Math.min(1, Math.max(0, rgb[k])) * 255);
        img.data[i + 3] = 255;
      }
    }
    g.putImageData(img, 0, 0);
    return c;
  }
  function colourBar(colour, lo, hi, caption) {
    const box = document.createElement("div");
    box.className = "bar";
    box.appendChild(paint(200, 14, (x) => colour(x / 199)));
    const ticks = document.createElement("div");
    ticks.className = "ticks";
    for (const t of [0, 0.25, 0.5, 0.75, 1]) {
      const s = document.createElement("span");
      s.textContent = String(Math.round((lo + t * (hi - lo)) * 100) / 100);
      ticks.appendChild(s);
    }
    box.appendChild(ticks);
    const p = document.createElement("div");
    p.className = "hint";
    p.textContent = caption;
    box.appendChild(p);
    return box;
  }
  function disc(colour, caption) {
    const box = document.createElement("div");
    box.className = "disc";
    const r = 48;
    box.appendChild(paint(2 * r, 2 * r, (x, y) => {
      const u = (x + 0.5 - r) / r, v = (r - y - 0.5) / r;
      return u * u + v * v <= 1 ? colour(u, v) : null;
    }));
    const p = document.createElement("div");
    p.className = "hint";
    p.textContent = caption;
    box.appendChild(p);
    return box;
  }
  function legend() {
    const el = $("legend"), v = state.view;
    el.replaceChildren();
    el.dataset.view = v;
    const title = document.createElement("div");
    title.className = "legend-title";
    el.appendChild(title);
    if (v === "relit") {
      title.textContent = "Relit";
      const p = document.createElement("div");
      p.className = "hint";
      p.textContent = data.model === "estimate"
        ? "An estimate has no material: grey Lambert (kd 0.5) plus a Ward lobe (ks 0.15), alpha 0.35 along the tangent and 0.12 across it (0.2 where there is no tangent), times the sliders' factors. The ball shows the light."
        : `The fitted ${({ gltf: "glTF metallic-roughness", auto: "per-pixel (Ward or glTF, whichever predicted the validation lights better)" })[data.model] || "anisotropic Ward"} model under the light (the ball), times 2^exposure, clamped, sRGB.`;
      el.appendChild(p);
      el.appendChild(colourBar((t) => [srgb(t), srgb(t), srgb(t)], 0, 1, "radiance × 2^exposure (linear) → shown grey"));
    } else if (v === "normal") {
      title.textContent = "Normal: colour = (n + 1) / 2";
      el.appendChild(disc((u, w) => [(u + 1) / 2, (w + 1) / 2, (Math.sqrt(Math.max(0, 1 - u * u - w * w)) + 1) / 2],
                          "normals seen from the camera: x right (red), y up (green), z toward the camera (blue); black: no normal"));
    } else if (v === "tangent") {
      title.textContent = "Tangent: hue = twice its angle";
      el.appendChild(disc((u, w) => hue(2 * Math.atan2(w, u) / (2 * Math.PI)),
                          "direction of the tangent in the image plane (x right, y up); t and −t have the same colour (red: horizontal, cyan: vertical); black: none (isotropic)"));
    } else if (v === "confidence" || v === "anisotropy") {
      title.textContent = v === "confidence" ? "Confidence" : "Anisotropy";
      el.appendChild(colourBar(viridis, 0, 1, "viridis over [0, 1]; black: no value"));
    } else if (v === "source") {
      title.textContent = "Source of each pixel's normal";
      const list = document.createElement("div");
      list.className = "swatches";
      data.sources.forEach((name, i) => {
        const row = document.createElement("div");
        row.className = "swatch";
        const chip = document.createElement("span");
        chip.className = "chip";
        const c = (data.source_colors || [])[i] || [255, 0, 255];
        chip.style.background = `rgb(${c[0]}, ${c[1]}, ${c[2]})`;
        row.appendChild(chip);
        row.appendChild(document.createTextNode(name));
        list.appendChild(row);
      });
      el.appendChild(list);
    } else {
      const names = { kd: "Diffuse albedo kd", ks: "Specular albedo ks", base_color: "Base colour" };
      title.textContent = names[v] || v;
      el.appendChild(colourBar((t) => [srgb(t), srgb(t), srgb(t)], 0, 1,
                               "per channel, linear albedo (times its slider's factor), clamped, sRGB-encoded; black: no fitted model"));
    }
  }

  // ---- Readout under the cursor ---------------------------------------------------------------
  // The finest loaded tile holding map pixel (x, y), and the texel index in it.
  function texelAt(x, y) {
    for (let k = 0; k <= TOP; k++) {
      const s = 2 ** k, span = TILE * s;
      const t = tiles.get(key(k, Math.floor(x / span), Math.floor(y / span)));
      if (t) {
        const i = (Math.floor(y / s) - t.y * TILE) * t.w + (Math.floor(x / s) - t.x * TILE);
        return { t, i };
      }
    }
    return null;
  }
  function readout(ev) {
    if (!program) return;
    const [px, py] = local(ev);
    const [mx, my] = mapAt(px, py);
    const x = Math.floor(mx), y = Math.floor(my);
    if (x < 0 || y < 0 || x >= W || y >= H) return;
    const found = texelAt(x, y);
    if (!found) return;
    const { t, i } = found, maps = t.maps;
    const at = (m, c) => halfToFloat(m[i * 4 + c]);
    const f = (v) => (Number.isFinite(v) ? v.toFixed(4).padStart(8) : "     n/a");
    const vec = (m) => [0, 1, 2].map((c) => f(at(m, c))).join("");
    const flag = Math.round(at(maps[0], 3));
    const lines = [`pixel   x ${x}, y ${y}` + (t.k > 0 ? ` (level ${t.k})` : "")];
    const pxl = new Uint8Array(4), d = dpr();
    gl.readPixels(Math.floor(px * d), canvas.height - 1 - Math.floor(py * d), 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pxl);
    lines.push(`shown   ${pxl[0]} ${pxl[1]} ${pxl[2]} (sRGB)`);
    lines.push("normal " + (flag > 0 ? vec(maps[0]) : "     n/a"));
    lines.push("tangent" + (at(maps[1], 3) > 0.5 ? vec(maps[1]) : "     n/a (isotropic)"));
    if (data.model === "estimate") {
      // No fitted material.
    } else if ((flag === 2 && data.model === "gltf") || flag === 3) {
      lines.push("base   " + vec(maps[2]));
      lines.push("metallic " + f(at(maps[2], 3)) + "  roughness " + f(at(maps[3], 0)));
      lines.push("anisotropy strength " + f(at(maps[3], 1)));
    } else if (flag === 2) {
      if (data.model === "auto") lines.push("model   Ward (chosen by validation lights)");
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
    if (data.format !== 2) throw new Error("unknown data format " + data.format);
    const tw = Math.ceil(W / 2 ** TOP), th = Math.ceil(H / 2 ** TOP);
    const most = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    if (tw > most || th > most) throw new Error(`the maps are ${tw} x ${th}; this browser's WebGL2 takes at most ${most} x ${most} (write a pyramid: symframe view --pyramid-above)`);
    const t0 = performance.now();
    setup();
    await addTile(TOP, 0, 0, tw, th, data.textures);
    if (data.samples) await addSamples(data.samples);
    // Only the controls of the model: a glTF fit has no free specular albedo.
    if (data.model === "gltf") $("specularRow").hidden = true;
    $("modelNote").textContent = { ward: "Anisotropic Ward fit.", gltf: "glTF metallic-roughness fit.",
                                   auto: "Per-pixel choice of Ward or glTF metallic-roughness (by validation lights); the specular factor edits the Ward pixels.",
                                   estimate: "An estimate's frames, shaded with a stand-in grey material." }[data.model] || "";
    const sel = $("viewSel");
    for (const v of data.views) sel.add(new Option(v, v));
    sel.addEventListener("change", () => { state.view = sel.value; legend(); writeFragment(); redraw(); });
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
    $("fit").addEventListener("click", () => { state.zoom = state.cx = state.cy = null; writeFragment(); redraw(); });
    $("lightMode").addEventListener("change", () => setLightMode($("lightMode").checked));
    canvasInput();
    $("ball").addEventListener("pointerdown", (ev) => { capture($("ball"), ev.pointerId); lightFromPointer(ev, $("ball")); });
    $("ball").addEventListener("pointermove", (ev) => { if ($("ball").hasPointerCapture(ev.pointerId)) lightFromPointer(ev, $("ball")); });
    window.addEventListener("hashchange", applyFragment);
    new ResizeObserver(redraw).observe(canvas);
    Object.assign(state, readFragment());
    setLightMode(false);
    syncControls();
    draw();
    gl.finish();
    window.symframeLoadMs = performance.now() - t0;
    window.symframeReadyAt = performance.now();
    window.symframeReady = true;
  }
  start().catch((e) => {
    status("symframe viewer: " + e.message);
    window.symframeError = e.message;
  });
})();
