// Runs the Khronos glTF validator on each file given; prints its issue counts and messages;
// exits 1 if any file has an error.
const fs = require("fs");
const path = require("path");
const validator = require(path.join(__dirname, "node_modules", "gltf-validator"));

async function check(file) {
  const data = new Uint8Array(fs.readFileSync(file));
  const dir = path.dirname(file);
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(dir, decodeURIComponent(uri)), (err, d) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(d)));
      }),
  });
  const i = report.issues;
  console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints`);
  for (const m of i.messages) {
    if (m.severity <= 1) console.log(`  [${m.severity === 0 ? "error" : "warning"}] ${m.code} ${m.pointer || ""}: ${m.message}`);
  }
  return i.numErrors;
}

(async () => {
  let errors = 0;
  for (const f of process.argv.slice(2)) errors += await check(f);
  process.exit(errors > 0 ? 1 : 0);
})().catch((e) => { console.error(`gltf-check: ${e}`); process.exit(1); });
