#!/usr/bin/env bash
# Validates glTF files with the Khronos glTF validator (npm `gltf-validator`), installed into
# .ci/node_modules on first use. Exits non-zero when any file has an error.
#   .ci/gltf-check.sh FILE.gltf|FILE.glb...
# With no arguments: makes the assets of .ci/gltf-assets.sh (a small synthetic capture, fitted
# with both models, exported as quad and mesh, .gltf and .glb) with the debug build, then
# validates those (SYMFRAME=path/to/symframe: that binary instead of the debug build).
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
    if [ -n "${SYMFRAME:-}" ]; then
        sf="$(realpath "$SYMFRAME")"
    else
        (cd "$root" && cargo build --locked -q -p symframe-cli)
        sf="$root/target/debug/symframe"
    fi
    "$here/gltf-assets.sh" "$sf" "$work"
    files=("$work/quad.gltf" "$work/quad.glb" "$work/ward.glb" "$work/est.glb" "$work/mesh.glb")
fi
node "$here/gltf-validate.js" "${files[@]}"
