// Loads exported glTF assets with three.js's GLTFLoader in headless Chromium (WebGL2 on
// SwiftShader) and checks, in a real page:
//  - the load: no error or warning on the console; one mesh, a MeshPhysicalMaterial where the
//    asset carries KHR_materials_anisotropy (else MeshStandardMaterial) with the textures
//    expected (base colour in sRGB, metalness and roughness, a normal map where asked for, an
//    anisotropy map and anisotropy > 0 with the extension), vertex tangents, and the vertex and
//    triangle counts the export reported;
//  - the render: a frame under a directional light (head-on, orthographic camera along -z, the
//    image's pixel grid) is not blank over the object (the capture's mask), and the shading
//    follows the surface: with lights from (+-1, 0, 1) and (0, +-1, 1), the differences
//    I(+x) - I(-x) and I(+y) - I(-y) correlate positively with the true normals' x and y
//    (the synthetic capture's gt_normals.npy): the side facing the light is brighter, the top of
//    the sphere when lit from above (glTF's +Y-up normal maps). The same with the normal map's
//    green flipped (normalScale.y = -1, the wrong convention) must fail, which shows the check
//    can tell.
//
//   node threejs-check.js --three DIR --mask mask.png --normals gt_normals.npy \
//       --asset FILE [--normal-map yes|no] [--vertices N --triangles N] [--asset ...]
"use strict";
const fs = require("fs");
const path = require("path");
const { launchChromium } = require("./browser");
const { PNG } = require("pngjs");

function parseArgs(argv) {
  const a = { assets: [], minCorr: 0.5 };
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i], v = () => argv[++i];
    const last = () => {
      if (!a.assets.length) throw new Error(`${k} before --asset`);
      return a.assets[a.assets.length - 1];
    };
    if (k === "--three") a.three = path.resolve(v());
    else if (k === "--mask") a.mask = v();
    else if (k === "--normals") a.normals = v();
    else if (k === "--min-corr") a.minCorr = Number(v());
    else if (k === "--shots") a.shots = v();
    else if (k === "--asset") a.assets.push({ file: path.resolve(v()), normalMap: true });
    else if (k === "--normal-map") last().normalMap = v() === "yes";
    else if (k === "--vertices") last().vertices = Number(v());
    else if (k === "--triangles") last().triangles = Number(v());
    else throw new Error(`unknown argument ${k}`);
  }
  if (!a.three || !a.mask || !a.normals || !a.assets.length) {
    throw new Error("--three, --mask, --normals and at least one --asset are required");
  }
  return a;
}

// A little-endian float32 .npy file: { shape, data }.
function readNpy(file) {
  const b = fs.readFileSync(file);
  if (b.toString("latin1", 1, 6) !== "NUMPY") throw new Error(`${file}: not an .npy file`);
  const major = b[6];
  const hlen = major === 1 ? b.readUInt16LE(8) : b.readUInt32LE(8);
  const start = major === 1 ? 10 : 12;
  const header = b.toString("latin1", start, start + hlen);
  if (!/'descr':\s*'<f4'/.test(header) || /'fortran_order':\s*True/.test(header)) {
    throw new Error(`${file}: not a C-ordered little-endian float32 array (${header.trim()})`);
  }
  const shape = header.match(/'shape':\s*\(([^)]*)\)/)[1].split(",").filter((s) => s.trim()).map(Number);
  const off = start + hlen;
  const n = shape.reduce((p, s) => p * s, 1);
  const data = new Float32Array(b.buffer.slice(b.byteOffset + off, b.byteOffset + off + 4 * n));
  return { shape, data };
}

// The page: an import map for three and its addons, and checkAsset(), which loads one asset,
// describes it, and renders it under each light given (RGBA bytes, top row first).
const PAGE = `<!doctype html><html><head><meta charset="utf-8">
<script type="importmap">{"imports": {"three": "/three/build/three.module.js",
  "three/addons/": "/three/examples/jsm/"}}</script></head>
<body style="margin:0"><canvas id="c"></canvas>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
const canvas = document.getElementById("c");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setClearColor(0x000000, 1);
window.threeRevision = THREE.REVISION;
window.loadAsset = async (url) => {
  window.gltf = await new GLTFLoader().loadAsync(url);
  return true;
};
window.describe = () => {
  const meshes = [];
  window.gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
  return meshes.map((m) => {
    const mat = m.material, g = m.geometry;
    const cs = (t) => (t ? t.colorSpace : null);
    return {
      type: mat.type,
      map: cs(mat.map), normalMap: cs(mat.normalMap), metalnessMap: cs(mat.metalnessMap),
      roughnessMap: cs(mat.roughnessMap), anisotropyMap: cs(mat.anisotropyMap),
      anisotropy: mat.anisotropy ?? null, normalScale: mat.normalScale ? mat.normalScale.toArray() : null,
      vertices: g.attributes.position.count,
      triangles: (g.index ? g.index.count : g.attributes.position.count) / 3,
      tangents: !!g.attributes.tangent,
      extension: !!(window.gltf.parser.json.extensionsUsed || []).includes("KHR_materials_anisotropy"),
      lightIntensity: mat.userData?.symframe?.lightIntensity ?? null,
    };
  });
};
// Renders the loaded asset w x h, the camera looking down -z at the image rectangle
// (one unit wide, h / w tall) under a white directional light from each of dirs.
window.render = (w, h, dirs, flipGreen) => {
  const scene = new THREE.Scene();
  scene.add(window.gltf.scene);
  const box = new THREE.Box3().setFromObject(window.gltf.scene);
  const a = h / w;
  const camera = new THREE.OrthographicCamera(-0.5, 0.5, a / 2, -a / 2, 0.01, box.max.z - box.min.z + 2);
  camera.position.set(0, 0, box.max.z + 1);
  const light = new THREE.DirectionalLight(0xffffff, Math.PI);
  scene.add(light, light.target);
  window.gltf.scene.traverse((o) => {
    if (o.isMesh && o.material.normalScale) o.material.normalScale.y = Math.abs(o.material.normalScale.y) * (flipGreen ? -1 : 1);
  });
  renderer.setSize(w, h, false);
  const gl = renderer.getContext();
  const out = [];
  for (const d of dirs) {
    light.position.set(d[0], d[1], d[2]);
    renderer.render(scene, camera);
    const px = new Uint8Array(4 * w * h);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const rows = new Uint8Array(4 * w * h);
    for (let y = 0; y < h; y++) rows.set(px.subarray(4 * w * (h - 1 - y), 4 * w * (h - y)), 4 * w * y);
    out.push(Array.from(rows));
  }
  scene.remove(window.gltf.scene);
  return out;
};
window.pageReady = true;
</script></body></html>`;

const lum = (px, p) => 0.2126 * px[4 * p] + 0.7152 * px[4 * p + 1] + 0.0722 * px[4 * p + 2];

function corr(xs, ys) {
  const n = xs.length;
  const mx = xs.reduce((s, v) => s + v, 0) / n, my = ys.reduce((s, v) => s + v, 0) / n;
  let sxy = 0, sxx = 0, syy = 0;
  for (let i = 0; i < n; i++) {
    sxy += (xs[i] - mx) * (ys[i] - my);
    sxx += (xs[i] - mx) ** 2;
    syy += (ys[i] - my) ** 2;
  }
  return sxx > 0 && syy > 0 ? sxy / Math.sqrt(sxx * syy) : 0;
}

async function main() {
  const a = parseArgs(process.argv.slice(2));
  const maskPng = PNG.sync.read(fs.readFileSync(a.mask));
  const [w, h] = [maskPng.width, maskPng.height];
  const gt = readNpy(a.normals);
  if (gt.shape.join() !== [h, w, 3].join()) throw new Error(`${a.normals}: shape ${gt.shape}, mask ${w}x${h}`);
  const object = [];
  for (let p = 0; p < w * h; p++) {
    if (maskPng.data[4 * p] > 0 && [0, 1, 2].every((c) => Number.isFinite(gt.data[3 * p + c]))) object.push(p);
  }
  if (!object.length) throw new Error("the mask selects no pixel");
  const s = Math.SQRT1_2;
  const dirs = [[0, 0, 1], [s, 0, s], [-s, 0, s], [0, s, s], [0, -s, s]];

  const started = Date.now();
  const browser = await launchChromium();
  let failures = 0;
  const fail = (msg) => { failures++; console.log(`threejs-check:   FAIL ${msg}`); };
  try {
    const page = await browser.newPage({ viewport: { width: 256, height: 256 }, deviceScaleFactor: 1 });
    // Everything comes from a made-up origin served from disk (ES modules do not load from
    // file://): the page, three.js, and the assets' folders.
    const origin = "http://symframe.test";
    const dirsByName = new Map();
    await page.route(`${origin}/**`, async (route) => {
      const u = new URL(route.request().url());
      const p = decodeURIComponent(u.pathname);
      let file = null, body = null;
      if (p === "/") body = PAGE;
      else if (p.startsWith("/three/")) file = path.join(a.three, p.slice("/three/".length));
      else {
        const m = p.match(/^\/assets\/(\d+)\/(.+)$/);
        if (m && dirsByName.has(m[1])) file = path.join(dirsByName.get(m[1]), m[2]);
      }
      if (body !== null) return route.fulfill({ status: 200, contentType: "text/html", body });
      if (!file || !fs.existsSync(file)) return route.fulfill({ status: 404, body: "not found" });
      const type = file.endsWith(".js") ? "text/javascript" : file.endsWith(".png") ? "image/png"
        : file.endsWith(".gltf") ? "model/gltf+json" : "application/octet-stream";
      return route.fulfill({ status: 200, contentType: type, body: fs.readFileSync(file) });
    });
    let messages = [];
    page.on("console", (m) => {
      // SwiftShader's "GPU stall due to ReadPixels" notes are Chromium's, not the asset's.
      if (/GPU stall due to ReadPixels/.test(m.text())) return;
      if (m.type() === "warning" || m.type() === "error") messages.push(`${m.type()}: ${m.text()}`);
    });
    page.on("pageerror", (e) => messages.push(`page error: ${e.message}`));
    await page.goto(`${origin}/`);
    await page.waitForFunction(() => window.pageReady, null, { timeout: 30000 });
    const revision = await page.evaluate(() => window.threeRevision);
    if (messages.length) fail(`the page: ${messages.join("; ")}`);
    console.log(`threejs-check: three.js r${revision} (GLTFLoader) in headless Chromium ${browser.version()}, ` +
                `WebGL2 on SwiftShader; ${object.length} object pixels of ${w}x${h}`);

    for (const [i, asset] of a.assets.entries()) {
      const name = path.basename(asset.file);
      const before = failures;
      dirsByName.set(String(i), path.dirname(asset.file));
      messages = [];
      const t0 = Date.now();
      let loaded = true;
      try {
        await page.evaluate((u) => window.loadAsset(u), `${origin}/assets/${i}/${encodeURIComponent(name)}`);
      } catch (e) {
        loaded = false;
        fail(`${name}: GLTFLoader failed: ${e.message.split("\n")[0]}`);
      }
      const loadMs = Date.now() - t0;
      if (messages.length) fail(`${name}: the console while loading: ${messages.join("; ")}`);
      if (!loaded) continue;
      const meshes = await page.evaluate(() => window.describe());
      const m = meshes[0];
      const checks = [];
      const expect = (ok, what) => { checks.push(what); if (!ok) fail(`${name}: ${what}`); };
      expect(meshes.length === 1, `one mesh (${meshes.length})`);
      if (!m) continue;
      expect(m.type === (m.extension ? "MeshPhysicalMaterial" : "MeshStandardMaterial"), `${m.type}`);
      expect(m.map === "srgb", `base colour map in sRGB (${m.map})`);
      expect(m.metalnessMap !== null && m.roughnessMap !== null, "metalness and roughness maps");
      expect((m.normalMap !== null) === asset.normalMap,
             asset.normalMap ? "a normal map" : `no normal map (normals in the geometry)`);
      if (m.normalMap !== null) expect(m.normalMap !== "srgb", `normal map not in sRGB (${m.normalMap})`);
      expect(m.tangents, "vertex tangents");
      if (m.extension) {
        expect(m.anisotropy > 0 && m.anisotropyMap !== null, `anisotropy ${m.anisotropy} with an anisotropy map`);
      }
      if (asset.vertices !== undefined) expect(m.vertices === asset.vertices, `${m.vertices} vertices (the export: ${asset.vertices})`);
      if (asset.triangles !== undefined) expect(m.triangles === asset.triangles, `${m.triangles} triangles (the export: ${asset.triangles})`);

      // Rendering.
      messages = [];
      const t1 = Date.now();
      const shots = await page.evaluate(([w, h, d]) => window.render(w, h, d, false), [w, h, dirs]);
      let flipped = null;
      if (m.normalMap !== null) flipped = await page.evaluate(([w, h, d]) => window.render(w, h, d, true), [w, h, dirs]);
      const renderMs = Date.now() - t1;
      if (a.shots) {
        fs.mkdirSync(a.shots, { recursive: true });
        for (const [k, px] of [...shots, ...(flipped || [])].entries()) {
          const png = new PNG({ width: w, height: h });
          png.data = Buffer.from(px);
          fs.writeFileSync(path.join(a.shots, `${name.replace(/\./g, "_")}_${k}.png`), PNG.sync.write(png));
        }
      }
      if (messages.length) fail(`${name}: the console while rendering: ${messages.join("; ")}`);
      const head = object.map((p) => lum(shots[0], p));
      const lit = head.filter((v) => v >= 8).length / head.length;
      const mean = head.reduce((x, y) => x + y, 0) / head.length;
      const spread = Math.sqrt(head.reduce((x, v) => x + (v - mean) ** 2, 0) / head.length);
      // Reported, not checked: three.js takes the anisotropy direction in the vertex tangent
      // frame without re-orthogonalising it to the normal-mapped normal, so on the quad, where
      // the half vector meets the quad's normal (head-on light and view), the anisotropic
      // highlight saturates wherever the normal map tilts the normal.
      const saturated = head.filter((v) => v >= 254).length / head.length;
      expect(lit >= 0.95 && mean >= 20, `not blank: ${(100 * lit).toFixed(1)}% of the object lit, mean ${mean.toFixed(1)}`);
      // The shading's sign: differences between opposite lights against the true normals.
      const signs = (imgs) => {
        const out = {};
        for (const [axis, plus, minus, c] of [["x", 1, 2, 0], ["y", 3, 4, 1]]) {
          const diff = object.map((p) => lum(imgs[plus], p) - lum(imgs[minus], p));
          const n = object.map((p) => gt.data[3 * p + c]);
          // The half facing the light (n > 0.3) against the other (n < -0.3), lit from +axis.
          const hi = object.filter((p, k) => n[k] > 0.3).map((p) => lum(imgs[plus], p));
          const lo = object.filter((p, k) => n[k] < -0.3).map((p) => lum(imgs[plus], p));
          const avg = (v) => v.reduce((x, y) => x + y, 0) / v.length;
          out[axis] = { corr: corr(diff, n), facing: avg(hi), away: avg(lo) };
        }
        return out;
      };
      const sg = signs(shots);
      for (const [axis, side] of [["x", "right"], ["y", "top"]]) {
        const r = sg[axis];
        expect(r.corr >= a.minCorr && r.facing > r.away,
               `lit from +${axis}: the ${side} brighter (mean ${r.facing.toFixed(1)} vs ${r.away.toFixed(1)}), ` +
               `corr(I(+${axis}) - I(-${axis}), n_${axis}) = ${r.corr.toFixed(3)}`);
      }
      let flipNote = "";
      if (flipped) {
        const f = signs(flipped);
        // The wrong convention must turn the y check around (x stays right).
        expect(f.y.corr < 0 && f.y.facing < f.y.away && f.x.corr >= a.minCorr,
               `the green channel flipped (the wrong convention) fails the y check: corr ${f.y.corr.toFixed(3)}`);
        flipNote = `; green flipped: corr_y ${f.y.corr.toFixed(3)} (caught)`;
      }
      console.log(`threejs-check: ${name}: ${failures > before ? "FAILED" : "ok"}: ${m.type}, ${m.vertices} vertices, ${m.triangles} triangles, ` +
                  `maps ${["map", "normalMap", "metalnessMap", "roughnessMap", "anisotropyMap"].filter((k) => m[k] !== null).join("/")}, ` +
                  `anisotropy ${m.anisotropy}; load ${loadMs} ms, ${shots.length + (flipped ? flipped.length : 0)} frames ${renderMs} ms; ` +
                  `head-on: ${(100 * lit).toFixed(1)}% lit, mean ${mean.toFixed(1)} (sd ${spread.toFixed(1)}, ` +
                  `${(100 * saturated).toFixed(0)}% saturated); ` +
                  `+x: ${sg.x.facing.toFixed(1)} vs ${sg.x.away.toFixed(1)}, corr ${sg.x.corr.toFixed(3)}; ` +
                  `+y: ${sg.y.facing.toFixed(1)} vs ${sg.y.away.toFixed(1)}, corr ${sg.y.corr.toFixed(3)}${flipNote}`);
    }
  } finally {
    await browser.close();
  }
  if (failures) {
    console.error(`threejs-check: ${failures} check(s) failed`);
    process.exit(1);
  }
  console.log(`threejs-check: ${a.assets.length} assets passed (browser ${((Date.now() - started) / 1000).toFixed(1)} s)`);
}

main().catch((e) => {
  console.error("threejs-check:", e.message);
  process.exit(1);
});
