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
  const a = { cases: [], minPsnr: 30, shots: null, screenshot: null, loadOnly: false };
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i], v = () => argv[++i];
    if (k === "--viewer") a.viewer = path.resolve(v());
    else if (k === "--mask") a.mask = v();
    else if (k === "--min-psnr") a.minPsnr = Number(v());
    else if (k === "--case") a.cases.push({ fragment: v(), ref: v() });
    else if (k === "--shots") a.shots = v();
    else if (k === "--screenshot") a.screenshot = v();
    else if (k === "--load-only") a.loadOnly = true;
    else throw new Error(`unknown argument ${k}`);
  }
  if (!a.viewer) throw new Error("--viewer is required");
  return a;
}

const readPng = (file) => PNG.sync.read(fs.readFileSync(file));

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
    if (a.loadOnly) {
      const { page, size, loadMs, decodeMs } = await open("ui=0", 1200, 1200);
      console.log(`viewer-test: ${path.basename(a.viewer)} (${(fs.statSync(a.viewer).size / 1e6).toFixed(1)} MB, ` +
                  `${size[0]}x${size[1]}): first frame ${loadMs} ms after navigation (decoding and upload ${decodeMs.toFixed(0)} ms)`);
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
    for (let i = 0; i < a.cases.length; i++) {
      const c = a.cases[i], ref = readPng(c.ref);
      if (last) await last.close();
      const { page, size, loadMs } = await open(`${c.fragment}&ui=0`, ref.width, ref.height);
      last = page;
      if (size[0] !== ref.width || size[1] !== ref.height) throw new Error(`canvas ${size} but reference ${ref.width}x${ref.height}`);
      const { ok, shot } = await compare(page, c, c.fragment, loadMs);
      failed ||= !ok;
      if (a.shots) fs.writeFileSync(path.join(a.shots, `view_${String(i).padStart(3, "0")}.png`), shot);
    }
    // The last page again, changed by its fragment alone (the interactive path): the first case.
    if (last && a.cases.length > 1) {
      const before = await last.evaluate(() => window.symframeFrames);
      await last.evaluate((f) => { location.hash = `${f}&ui=0`; }, a.cases[0].fragment);
      await last.waitForFunction((n) => window.symframeFrames > n, before, { timeout: 10000 });
      failed ||= !(await compare(last, a.cases[0], `${a.cases[0].fragment} after a fragment change`)).ok;
      // A drag to a quarter of the width and height from the top left puts the light at
      // x = -0.5, y = 0.5 (z = sqrt(0.5)), draws a frame and writes the light into the fragment.
      const box = await last.locator("#view").boundingBox();
      const frames = await last.evaluate(() => window.symframeFrames);
      await last.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
      await last.mouse.down();
      await last.mouse.move(box.x + box.width * 0.25, box.y + box.height * 0.25, { steps: 4 });
      await last.mouse.up();
      await last.waitForFunction((n) => window.symframeFrames > n, frames, { timeout: 10000 });
      const hash = await last.evaluate(() => location.hash);
      const l = new URLSearchParams(hash.slice(1)).get("light").split(",").map(Number);
      const want = [-0.5, 0.5, Math.SQRT1_2], tol = 2.5 / box.width;
      const ok = l.every((v, i) => Math.abs(v - want[i]) < tol);
      failed ||= !ok;
      console.log(`viewer-test: a drag to (1/4, 1/4) set ${hash} (light ${want.map((v) => v.toFixed(3))} expected) ${ok ? "ok" : "FAIL"}`);
    }
    if (last) await last.close();
    if (a.screenshot && a.cases.length > 0) {
      const ref = readPng(a.cases[0].ref);
      const w = Math.max(ref.width, 256) + 320, h = Math.max(ref.height, 600) + 24;
      const { page } = await open(a.cases[0].fragment, w, h);
      // A pixel's readout, as when hovering.
      const box = await page.locator("#view").boundingBox();
      await page.mouse.move(box.x + box.width * 0.6, box.y + box.height * 0.35);
      await page.screenshot({ path: a.screenshot });
      console.log(`viewer-test: wrote ${a.screenshot}`);
      await page.close();
    }
  } finally {
    await browser.close();
  }
  if (failed) {
    console.error(`viewer-test: a PSNR is below ${a.minPsnr} dB`);
    process.exit(1);
  }
}

main().catch((e) => {
  console.error("viewer-test:", e.message);
  process.exit(1);
});
