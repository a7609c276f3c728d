// The headless Chromium the browser checks (viewer-test.js, threejs-check.js) run in: WebGL2
// without a GPU, ANGLE on SwiftShader; no network, sync or first-run work. Playwright starts it
// with a new empty profile folder of its own.
"use strict";

const { chromium } = require("playwright-core");

/** Launches Chromium (`$CHROMIUM`, else /usr/bin/chromium). */
function launchChromium() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    args: [
      "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync",
      "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    ],
  });
}

module.exports = { launchChromium };
