// Renders a `symframe view` page in headless Chromium (WebGL2 on SwiftShader, no GPU) in given
// states (URL fragments: a light, edits) and compares each screenshot with `symframe relight`'s
// picture of the same fit with the same light and edits: PSNR
// over the object's mask, with the reference's largest value there as the peak (as
// symframe::relight::image_psnr). Exits non-zero when a PSNR is below the threshold.
//
//   node viewer-test.js --viewer V.html --mask mask.png --min-psnr 30 \
//       --case light=x,y,z relit_000.png [--case 'light=x,y,z&exposure=1' relit.png ...] \
//       [--shots DIR] [--screenshot docs/viewer.png] [--load-only]
//
// --shots keeps the screenshots; --screenshot also saves a picture of the whole viewer (panel
// included) for the README; --load-only just opens the page and prints its load time.
"use strict";
const fs = require("fs");
const path = require("path");
const { launchChromium } = require("./browser");
const { PNG } = require("pngjs");

function parseArgs(argv) {
  const a = { cases: [], minPsnr: 30, shots: null, screenshot: null, loadOnly: false, interact: false,
              pyramid: null, nonblank: [], loadViewport: [1200, 800] };
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i], v = () => argv[++i];
    if (k === "--viewer") a.viewer = path.resolve(v());
    else if (k === "--mask") a.mask = v();
    else if (k === "--min-psnr") a.minPsnr = Number(v());
    else if (k === "--case") a.cases.push({ fragment: v(), ref: v() });
    else if (k === "--shots") a.shots = v();
    else if (k === "--screenshot") a.screenshot = v();
    else if (k === "--load-only") a.loadOnly = true;
    else if (k === "--interact") a.interact = true;
    else if (k === "--pyramid") a.pyramid = { tile: Number(v()), levels: Number(v()) };
    else if (k === "--nonblank") a.nonblank.push(v());
    else if (k === "--viewport") a.loadViewport = v().split("x").map(Number);
    else throw new Error(`unknown argument ${k}`);
  }
  if (!a.viewer) throw new Error("--viewer is required");
  return a;
}

const readPng = (file) => PNG.sync.read(fs.readFileSync(file));

// What the page should show of the map picture `ref` (and which pixels hold the object, from
// `mask`) in a canvas of cw x ch pixels at view {zoom, cx, cy} (screen pixels per map pixel, the
// map point at the centre), showing pyramid level `level` (every 2^level-th map pixel): canvas
// pixel (i, j) shows map pixel floor(c + (i + 0.5 - cw / 2) / zoom), rounded down to a multiple
// of 2^level. Outside the map the mask is 0.
function expected(ref, mask, v, cw, ch, level = 0) {
  const s = 2 ** level;
  const img = { width: cw, height: ch, data: Buffer.alloc(cw * ch * 4) };
  const m = { width: cw, height: ch, data: Buffer.alloc(cw * ch * 4) };
  for (let j = 0; j < ch; j++) {
    for (let i = 0; i < cw; i++) {
      let x = Math.floor(v.cx + (i + 0.5 - cw / 2) / v.zoom), y = Math.floor(v.cy + (j + 0.5 - ch / 2) / v.zoom);
      if (x < 0 || y < 0 || x >= ref.width || y >= ref.height) continue;
      x -= x % s;
      y -= y % s;
      const src = (y * ref.width + x) * 4, dst = (j * cw + i) * 4;
      for (let c = 0; c < 4; c++) img.data[dst + c] = ref.data[src + c];
      m.data[dst] = !mask || mask.data[src] ? 255 : 0;
    }
  }
  return { img, mask: m };
}

// PSNR (dB) of RGB `img` against `ref` over the pixels where `mask` is non-zero.
function psnr(img, ref, mask) {
  if (img.width !== ref.width || img.height !== ref.height) {
    throw new Error(`screenshot ${img.width}x${img.height}, reference ${ref.width}x${ref.height}`);
  }
  let sse = 0, count = 0, peak = 0, worst = 0;
  for (let p = 0; p < ref.width * ref.height; p++) {
    if (mask && mask.data[p * 4] === 0) continue;
    for (let c = 0; c < 3; c++) {
      const d = img.data[p * 4 + c] - ref.data[p * 4 + c];
      sse += d * d;
      worst = Math.max(worst, Math.abs(d));
      peak = Math.max(peak, ref.data[p * 4 + c]);
    }
    count += 3;
  }
  if (count === 0) throw new Error("the mask selects no pixel");
  const rms = Math.sqrt(sse / count);
  return { db: rms === 0 ? Infinity : 20 * Math.log10(peak / rms), rms, peak, worst, pixels: count / 3 };
}

async function main() {
  const a = parseArgs(process.argv.slice(2));
  const browser = await launchChromium();
  let failed = false;
  const check = (ok, what) => {
    console.log(`viewer-test: ${what} ${ok ? "ok" : "FAIL"}`);
    failed ||= !ok;
  };
  try {
    const url = "file://" + a.viewer;
    // Opens the page at `fragment` in a fresh tab sized `w` x `h` and waits for its first frame.
    async function open(fragment, w, h) {
      const page = await browser.newPage({ viewport: { width: w, height: h }, deviceScaleFactor: 1 });
      page.on("pageerror", (e) => console.error("page error:", e.message));
      const t0 = Date.now();
      await page.goto(url + "#" + fragment);
      await page.waitForFunction(() => window.symframeReady || window.symframeError, null, { timeout: 60000 });
      const err = await page.evaluate(() => window.symframeError);
      if (err) throw new Error(`the viewer failed: ${err}`);
      const size = await page.evaluate(() => [document.getElementById("view").width, document.getElementById("view").height]);
      const decodeMs = await page.evaluate(() => window.symframeLoadMs);
      return { page, size, loadMs: Date.now() - t0, decodeMs };
    }
    // Waits until every tile the view wants is loaded and drawn.
    async function idle(page) {
      await page.waitForFunction(() => window.symframeIdle(), null, { timeout: 120000, polling: 50 });
    }
    // Changes the page's fragment and waits for the frame it draws (and its tiles).
    async function goTo(page, fragment) {
      const before = await page.evaluate(() => window.symframeFrames);
      await page.evaluate((f) => { location.hash = f; }, fragment);
      await page.waitForFunction((n) => window.symframeFrames > n, before, { timeout: 10000 });
      await idle(page);
    }
    async function frameAfter(page, action) {
      const before = await page.evaluate(() => window.symframeFrames);
      await action();
      await page.waitForFunction((n) => window.symframeFrames > n, before, { timeout: 10000 });
      await idle(page);
    }
    const viewState = (page) => page.evaluate(() => window.symframeView());
    const canvasShot = async (page) => {
      const box = await page.locator("#view").boundingBox();
      return { box, img: PNG.sync.read(await page.screenshot({ clip: box })) };
    };
    if (a.loadOnly) {
      const [vw, vh] = a.loadViewport;
      const { page, size, loadMs, decodeMs } = await open("", vw, vh);
      const t0 = Date.now();
      await idle(page);
      const tiles = await page.evaluate(() => window.symframeTilesLoaded);
      const v = await viewState(page);
      const [readyAt, allDecode] = await page.evaluate(() => [window.symframeReadyAt, window.symframeDecodeMs]);
      console.log(`viewer-test: ${path.basename(a.viewer)} (${(fs.statSync(a.viewer).size / 1e6).toFixed(1)} MB, ` +
                  `canvas ${size[0]}x${size[1]}, zoom ${v.zoom.toFixed(4)}, level ${v.level}): first frame ${readyAt.toFixed(0)} ms after ` +
                  `navigation by the page's clock (${loadMs} ms by the test's; decoding and upload ${decodeMs.toFixed(0)} ms); ` +
                  `${tiles} tiles of the view loaded ${Date.now() - t0} ms later (${(allDecode - decodeMs).toFixed(0)} ms decoding them)`);
      await page.close();
      return;
    }
    const mask = a.mask ? readPng(a.mask) : null;
    let last = null;
    // Compares the canvas of `page` with the reference picture of `c`; returns whether it passed.
    async function compare(page, c, label, ms) {
      const ref = readPng(c.ref);
      const shot = await page.screenshot({ clip: { x: 0, y: 0, width: ref.width, height: ref.height } });
      const r = psnr(PNG.sync.read(shot), ref, mask);
      const ok = r.db >= a.minPsnr;
      console.log(`viewer-test: ${label}: PSNR ${r.db.toFixed(2)} dB over ${r.pixels} object pixels ` +
                  `(RMS ${r.rms.toFixed(3)}, largest difference ${r.worst} of peak ${r.peak}${ms ? `; ${ms} ms` : ""}) ` +
                  (ok ? "ok" : "FAIL"));
      return { ok, shot };
    }
    // The canvas of `page` against `ref` as the view shows it (zoomed, panned, a level).
    async function compareView(page, ref, label, level = 0) {
      const { box, img } = await canvasShot(page);
      const v = await viewState(page);
      const e = expected(ref, mask, v, Math.round(box.width), Math.round(box.height), level);
      const r = psnr(img, e.img, e.mask);
      check(r.db >= a.minPsnr, `${label} (zoom ${v.zoom.toFixed(3)}, centre ${v.cx.toFixed(2)}, ${v.cy.toFixed(2)}): ` +
            `PSNR ${r.db.toFixed(2)} dB over ${r.pixels} object pixels (largest difference ${r.worst})`);
      return img;
    }
    // Every case at zoom 1 in a window of the map's size: canvas pixel (i, j) is map pixel (i, j).
    for (let i = 0; i < a.cases.length; i++) {
      const c = a.cases[i], ref = readPng(c.ref);
      if (last) await last.close();
      const { page, size, loadMs } = await open(`${c.fragment}&ui=0&zoom=1`, ref.width, ref.height);
      await idle(page);
      last = page;
      if (size[0] !== ref.width || size[1] !== ref.height) throw new Error(`canvas ${size} but reference ${ref.width}x${ref.height}`);
      const { ok, shot } = await compare(page, c, c.fragment, loadMs);
      failed ||= !ok;
      if (a.shots) fs.writeFileSync(path.join(a.shots, `view_${String(i).padStart(3, "0")}.png`), shot);
    }
    // Pages that have no reference picture (an estimate's relit view): most of the object lit.
    for (const f of a.nonblank) {
      const { page } = await open(`${f}&ui=0`, 320, 320);
      const { box, img } = await canvasShot(page);
      const v = await viewState(page);
      const ref = mask || { width: 1, height: 1, data: Buffer.from([255, 255, 255, 255]) };
      const e = expected(ref, mask, v, Math.round(box.width), Math.round(box.height));
      let object = 0, lit = 0;
      for (let p = 0; p < img.width * img.height; p++) {
        if (!e.mask.data[p * 4]) continue;
        object++;
        if (img.data[p * 4] + img.data[p * 4 + 1] + img.data[p * 4 + 2] > 15) lit++;
      }
      check(object > 0 && lit > 0.5 * object, `${f}: ${lit} of ${object} object pixels lit`);
      await page.close();
    }
    // The last page again, changed by its fragment alone (the interactive path): the first case.
    if (last && a.cases.length > 1) {
      const before = await last.evaluate(() => window.symframeFrames);
      await last.evaluate((f) => { location.hash = `${f}&ui=0&zoom=1`; }, a.cases[0].fragment);
      await last.waitForFunction((n) => window.symframeFrames > n, before, { timeout: 10000 });
      failed ||= !(await compare(last, a.cases[0], `${a.cases[0].fragment} after a fragment change`)).ok;
      // A shift-drag to a quarter of the width and height from the top left puts the light at
      // x = -0.5, y = 0.5 (z = sqrt(0.5)), draws a frame and writes the light into the fragment;
      // the view does not move.
      const box = await last.locator("#view").boundingBox();
      const v0 = await viewState(last);
      const frames = await last.evaluate(() => window.symframeFrames);
      await last.keyboard.down("Shift");
      await last.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
      await last.mouse.down();
      await last.mouse.move(box.x + box.width * 0.25, box.y + box.height * 0.25, { steps: 4 });
      await last.mouse.up();
      await last.keyboard.up("Shift");
      await last.waitForFunction((n) => window.symframeFrames > n, frames, { timeout: 10000 });
      const hash = await last.evaluate(() => location.hash);
      const l = new URLSearchParams(hash.slice(1)).get("light").split(",").map(Number);
      const want = [-0.5, 0.5, Math.SQRT1_2], tol = 2.5 / box.width;
      const v1 = await viewState(last);
      check(l.every((v, i) => Math.abs(v - want[i]) < tol) && v1.cx === v0.cx && v1.cy === v0.cy,
            `a shift-drag to (1/4, 1/4) set ${hash} (light ${want.map((v) => v.toFixed(3))} expected, the view kept)`);
    }
    if (last) await last.close();
    if (a.interact && a.cases.length > 0) await interact(a.cases[0]);
    if (a.pyramid && a.cases.length > 0) await pyramid(a.cases[0]);
    if (a.screenshot && a.cases.length > 0) {
      const { page } = await open(a.cases[0].fragment, 1100, 860);
      // A pixel's readout, as when hovering.
      const box = await page.locator("#view").boundingBox();
      await page.mouse.move(box.x + box.width * 0.55, box.y + box.height * 0.4);
      await page.screenshot({ path: a.screenshot });
      console.log(`viewer-test: wrote ${a.screenshot}`);
      await page.close();
    }

    // The page as a user sees it: the canvas fills the window beside the panel with the map
    // enlarged to fit; the wheel, a drag, a pinch and the keys zoom and pan; a legend for
    // every view; only the model's controls.
    async function interact(c) {
      const ref = readPng(c.ref);
      // The case's fragment without its view (set here view by view).
      const base = c.fragment.split("&").filter((p) => !p.startsWith("view=")).join("&");
      const { page } = await open(c.fragment, 1200, 800);
      const vp = { width: 1200, height: 800 };
      const canvasBox = await page.locator("#view").boundingBox();
      const panel = await page.locator("#panel").boundingBox();
      const share = (canvasBox.width * canvasBox.height) / (vp.width * vp.height - panel.width * panel.height);
      check(share >= 0.9 && panel.width < 400,
            `the canvas fills ${(100 * share).toFixed(1)}% of the window beside the panel (${panel.width} px wide)`);
      let v = await viewState(page);
      const fit = Math.min(canvasBox.width / ref.width, canvasBox.height / ref.height);
      check(v.fit && Math.abs(v.zoom - fit) < 1e-9 && v.zoom > 1, `the map is enlarged to fit: zoom ${v.zoom.toFixed(3)}`);
      const fitShot = await compareView(page, ref, "enlarged to fit");
      // Zoom and pan by the fragment: the expected region, magnified.
      await goTo(page, `${c.fragment}&zoom=${(3.3 * fit + 0.0123).toFixed(4)}&cx=${(ref.width * 0.3 + 0.0371).toFixed(4)}&cy=${(ref.height * 0.6 + 0.0173).toFixed(4)}`);
      const zoomed = await compareView(page, ref, "zoomed and panned by the fragment");
      check(!zoomed.data.equals(fitShot.data), "zooming changes the picture");
      // The wheel zooms about the cursor: the map point under it stays.
      const at = [canvasBox.width * 0.3, canvasBox.height * 0.7];
      const mapAt = (s) => [s.cx + (at[0] - canvasBox.width / 2) / s.zoom, s.cy + (at[1] - canvasBox.height / 2) / s.zoom];
      v = await viewState(page);
      await page.mouse.move(canvasBox.x + at[0], canvasBox.y + at[1]);
      await frameAfter(page, () => page.mouse.wheel(0, -200));
      let w = await viewState(page);
      const [p0, p1] = [mapAt(v), mapAt(w)];
      check(w.zoom > v.zoom * 1.2 && Math.hypot(p0[0] - p1[0], p0[1] - p1[1]) < 1e-6,
            `the wheel zooms ${(w.zoom / v.zoom).toFixed(3)}x about the cursor (map point ${p0.map((x) => x.toFixed(3))} stays)`);
      await compareView(page, ref, "after the wheel");
      // A drag pans by as many screen pixels.
      v = w;
      await frameAfter(page, async () => {
        await page.mouse.move(canvasBox.x + 300, canvasBox.y + 300);
        await page.mouse.down();
        await page.mouse.move(canvasBox.x + 340, canvasBox.y + 270, { steps: 5 });
        await page.mouse.up();
      });
      w = await viewState(page);
      check(Math.abs((v.cx - w.cx) * v.zoom - 40) < 1e-6 && Math.abs((v.cy - w.cy) * v.zoom + 30) < 1e-6 && w.zoom === v.zoom,
            `a drag of (40, -30) px pans the map with it (centre ${v.cx.toFixed(2)}, ${v.cy.toFixed(2)} -> ${w.cx.toFixed(2)}, ${w.cy.toFixed(2)})`);
      await compareView(page, ref, "after a drag");
      const hash = new URLSearchParams((await page.evaluate(() => location.hash)).slice(1));
      check(Math.abs(Number(hash.get("zoom")) - w.zoom) < 1e-5 && Math.abs(Number(hash.get("cx")) - w.cx) < 1e-3,
            "the fragment holds the zoom and the centre");
      // A pinch (two touch pointers moving apart to twice their distance) zooms 2x about them.
      v = w;
      await frameAfter(page, () => page.evaluate(() => {
        const cv = document.getElementById("view"), r = cv.getBoundingClientRect();
        const ev = (type, id, x, y) => cv.dispatchEvent(new PointerEvent(type, {
          pointerId: id, pointerType: "touch", isPrimary: id === 1, clientX: r.left + x, clientY: r.top + y, bubbles: true, button: 0 }));
        ev("pointerdown", 1, 400, 400); ev("pointerdown", 2, 440, 400);
        ev("pointermove", 2, 480, 400);
        ev("pointerup", 1, 400, 400); ev("pointerup", 2, 480, 400);
      }));
      w = await viewState(page);
      const before = [v.cx + (420 - canvasBox.width / 2) / v.zoom, v.cy + (400 - canvasBox.height / 2) / v.zoom];
      const after = [w.cx + (440 - canvasBox.width / 2) / w.zoom, w.cy + (400 - canvasBox.height / 2) / w.zoom];
      check(Math.abs(w.zoom / v.zoom - 2) < 1e-9 && Math.hypot(before[0] - after[0], before[1] - after[1]) < 1e-6,
            `a pinch to twice the distance zooms ${(w.zoom / v.zoom).toFixed(3)}x, the point between the fingers follows them`);
      // Keys: + doubles the zoom, an arrow pans, 0 fits the map again.
      await page.mouse.move(canvasBox.x + 5, canvasBox.y + 5);
      v = w;
      await frameAfter(page, () => page.keyboard.press("+"));
      w = await viewState(page);
      check(Math.abs(w.zoom / v.zoom - 2) < 1e-9, `the + key zooms ${(w.zoom / v.zoom).toFixed(3)}x`);
      v = w;
      await frameAfter(page, () => page.keyboard.press("ArrowLeft"));
      w = await viewState(page);
      check(w.cx < v.cx && w.cy === v.cy, "the left arrow pans");
      await frameAfter(page, () => page.keyboard.press("0"));
      w = await viewState(page);
      check(w.fit && Math.abs(w.zoom - fit) < 1e-9, "the 0 key fits the map again");
      // A legend for every view, of the view shown.
      const data = await page.evaluate(() => JSON.parse(document.getElementById("symframe-data").textContent));
      for (const name of data.views) {
        await goTo(page, `${base}&view=${name}`);
        const l = await page.evaluate(() => {
          const el = document.getElementById("legend"), r = el.getBoundingClientRect();
          return { view: el.dataset.view, h: r.height, visible: el.checkVisibility(),
                   pictures: el.querySelectorAll("canvas").length, swatches: [...el.querySelectorAll(".swatch")].map((s) => s.textContent),
                   text: el.textContent };
        });
        const ok = l.view === name && l.visible && l.h > 30 &&
          (name === "source" ? l.swatches.join() === data.sources.join() : l.pictures > 0);
        check(ok, `legend of ${name}: ${l.pictures} picture(s)${name === "source" ? `, swatches ${l.swatches.join(", ")}` : ""}, "${l.text.slice(0, 60)}..."`);
      }
      // Only the controls of the model: a glTF fit has no specular factor.
      const specular = await page.evaluate(() => document.getElementById("specularRow").checkVisibility());
      check(specular === (data.model !== "gltf"), `the specular slider is ${specular ? "shown" : "hidden"} (${data.model})`);
      await page.close();
    }

    // A pyramid page: the coarsest level shows at once (no tile loaded), zooming in loads the
    // finer tiles of the view only, and at zoom 1 the full-resolution tiles show the maps.
    async function pyramid(c) {
      const ref = readPng(c.ref);
      const top = a.pyramid.levels - 1, coarse = 2 ** top;
      const { page } = await open(`${c.fragment}&ui=0&zoom=${1 / coarse}`, ref.width, ref.height);
      await idle(page);
      let n = await page.evaluate(() => window.symframeTilesLoaded);
      check(n === 0, `the pyramid's coarsest level shows without loading a tile (${n} loaded)`);
      await compareView(page, ref, `pyramid level ${top}`, top);
      await goTo(page, `${c.fragment}&ui=0&zoom=1`);
      n = await page.evaluate(() => window.symframeTilesLoaded);
      const all = Math.ceil(ref.width / a.pyramid.tile) * Math.ceil(ref.height / a.pyramid.tile);
      check(n === all, `at zoom 1 the ${all} full-resolution tiles are loaded (${n})`);
      failed ||= !(await compare(page, c, `pyramid ${c.fragment} at zoom 1`)).ok;
      await page.close();
      // Zoomed into one tile (the one at the map's centre): that tile only.
      const t = a.pyramid.tile, mid = (Math.floor(ref.width / 2 / t) + 0.5) * t;
      const z = await open(`${c.fragment}&ui=0&zoom=${ref.width / t}&cx=${mid}&cy=${mid}`, ref.width, ref.height);
      await idle(z.page);
      n = await z.page.evaluate(() => window.symframeTilesLoaded);
      check(n === 1, `zoomed into one tile, ${n} tile loaded`);
      await compareView(z.page, ref, "pyramid zoomed into a tile");
      await z.page.close();
    }
  } finally {
    await browser.close();
  }
  if (failed) {
    console.error(`viewer-test: a check failed (PSNR threshold ${a.minPsnr} dB)`);
    process.exit(1);
  }
}

main().catch((e) => {
  console.error("viewer-test:", e.message);
  process.exit(1);
});
