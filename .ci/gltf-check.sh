#!/usr/bin/env bash
# Validates glTF files with the Khronos glTF validator (npm `gltf-validator`), installed into
# .ci/node_modules on first use. Exits non-zero when any file has an error.
#   .ci/gltf-check.sh FILE.gltf|FILE.glb...
# With no arguments: renders a small synthetic capture, estimates, fits it with both models
# (glTF: the fitted material; Ward: converted), integrates and exports it (quad and mesh,
# .gltf and .glb) with the debug build, then validates those.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
if ! command -v node >/dev/null; then
    echo "gltf-check: node is not installed" >&2
    exit 1
fi
if [ ! -d "$here/node_modules/gltf-validator" ]; then
    (cd "$here" && npm install --silent --no-audit --no-fund --prefix "$here" gltf-validator@2.0.0-dev.3.10 >/dev/null)
fi
files=("$@")
if [ ${#files[@]} -eq 0 ]; then
    work="$(mktemp -d)"
    trap 'rm -rf "$work"' EXIT
    (cd "$root" && cargo build --locked -q -p symframe-cli)
    sf="$root/target/debug/symframe"
    "$sf" synth -o "$work/data" --size 48 --rig cone:200 --model ward >/dev/null
    "$sf" estimate "$work/data" -o "$work/est" >/dev/null
    "$sf" fit "$work/data" --frames "$work/est" -o "$work/fit" --model gltf >/dev/null
    "$sf" fit "$work/data" --frames "$work/est" -o "$work/ward" --model ward >/dev/null
    "$sf" integrate "$work/est" -o "$work/int" --solver poisson >/dev/null
    "$sf" export gltf "$work/fit" -o "$work/quad.gltf" >/dev/null
    "$sf" export gltf "$work/fit" -o "$work/quad.glb" >/dev/null
    "$sf" export gltf "$work/ward" -o "$work/ward.glb" >/dev/null
    "$sf" export gltf "$work/est" -o "$work/est.glb" >/dev/null
    "$sf" export gltf "$work/fit" --mesh --depth "$work/int/depth.npy" -o "$work/mesh.glb" >/dev/null
    files=("$work/quad.gltf" "$work/quad.glb" "$work/ward.glb" "$work/est.glb" "$work/mesh.glb")
fi
node "$here/gltf-validate.js" "${files[@]}"
