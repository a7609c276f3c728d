// Renders a `symframe view` page in headless Chromium (WebGL2 on SwiftShader, no GPU) at given
// lights and compares each screenshot with `symframe relight`'s picture of the same fit: PSNR
// over the object's mask, with the reference's largest value there as the peak (as
// symframe::relight::image_psnr). Exits non-zero when a PSNR is below the threshold.
//
//   node viewer-test.js --viewer V.html --mask mask.png --min-psnr 30 \
//       --light x,y,z --ref relit_000.png [--light ... --ref ...] [--shots DIR] \
//       [--screenshot docs/viewer.png] [--load-only]
//
// --shots keeps the screenshots; --screenshot also saves a picture of the whole viewer (panel
// included) for the README; --load-only just opens the page and prints its load time.
"use strict";
const fs = require("fs");
const path = require("path");
const { chromium } = require("playwright-core");
const { PNG } = require("pngjs");

function parseArgs(argv) {
  const a = { lights: [], refs: [], minPsnr: 30, shots: null, screenshot: null, loadOnly: false };
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i], v = () => argv[++i];
    if (k === "--viewer") a.viewer = path.resolve(v());
    else if (k === "--mask") a.mask = v();
    else if (k === "--min-psnr") a.minPsnr = Number(v());
    else if (k === "--light") a.lights.push(v());
    else if (k === "--ref") a.refs.push(v());
    else if (k === "--shots") a.shots = v();
    else if (k === "--screenshot") a.screenshot = v();
    else if (k === "--load-only") a.loadOnly = true;
    else throw new Error(`unknown argument ${k}`);
  }
  if (!a.viewer) throw new Error("--viewer is required");
  if (a.lights.length !== a.refs.length) throw new Error("give one --ref per --light");
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
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    args: [
      "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync",
      // WebGL2 without a GPU: ANGLE on SwiftShader.
      "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    ],
    // (Playwright starts Chromium with a new empty profile folder of its own.)
  });
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
    for (let i = 0; i < a.lights.length; i++) {
      const ref = readPng(a.refs[i]);
      if (last) await last.close();
      const { page, size, loadMs } = await open(`light=${a.lights[i]}&ui=0`, ref.width, ref.height);
      last = page;
      if (size[0] !== ref.width || size[1] !== ref.height) throw new Error(`canvas ${size} but reference ${ref.width}x${ref.height}`);
      const shot = await page.screenshot({ clip: { x: 0, y: 0, width: ref.width, height: ref.height } });
      if (a.shots) fs.writeFileSync(path.join(a.shots, `view_${String(i).padStart(3, "0")}.png`), shot);
      const r = psnr(PNG.sync.read(shot), ref, mask);
      const ok = r.db >= a.minPsnr;
      failed ||= !ok;
      console.log(`viewer-test: light ${a.lights[i]}: PSNR ${r.db.toFixed(2)} dB over ${r.pixels} object pixels ` +
                  `(RMS ${r.rms.toFixed(3)}, largest difference ${r.worst} of peak ${r.peak}; ${loadMs} ms) ${ok ? "ok" : "FAIL"}`);
    }
    // The same page, relit by changing the fragment (the interactive path): back to light 0.
    if (last && a.lights.length > 1) {
      const ref = readPng(a.refs[0]);
      const before = await last.evaluate(() => window.symframeFrames);
      await last.evaluate((l) => { location.hash = `light=${l}&ui=0`; }, a.lights[0]);
      await last.waitForFunction((n) => window.symframeFrames > n, before, { timeout: 10000 });
      const shot = await last.screenshot({ clip: { x: 0, y: 0, width: ref.width, height: ref.height } });
      const r = psnr(PNG.sync.read(shot), ref, mask);
      const ok = r.db >= a.minPsnr;
      failed ||= !ok;
      console.log(`viewer-test: light ${a.lights[0]} after a fragment change: PSNR ${r.db.toFixed(2)} dB ${ok ? "ok" : "FAIL"}`);
    }
    if (last) await last.close();
    if (a.screenshot && a.lights.length > 0) {
      const ref = readPng(a.refs[0]);
      const w = Math.max(ref.width, 256) + 320, h = Math.max(ref.height, 420) + 24;
      const { page } = await open(`light=${a.lights[a.lights.length - 1]}`, w, h);
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
