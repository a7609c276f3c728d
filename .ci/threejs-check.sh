#!/usr/bin/env bash
# Opens the exported glTF assets in three.js: makes the assets of .ci/gltf-assets.sh (the glTF
# fit's quad as .gltf and .glb, the Ward fit converted, the estimate alone, the integrated
# mesh), loads each with three.js's GLTFLoader in headless Chromium (WebGL2 on SwiftShader) and
# checks the load (no console error or warning; one mesh, its material's type, textures,
# anisotropy, vertex and triangle counts as exported) and the rendering (not blank over the
# object; lit from +x and +y, the side of the sphere facing the light is brighter, as the true
# normals predict: glTF's +Y-up normal maps read the right way round). See threejs-check.js.
#   .ci/threejs-check.sh
# SYMFRAME=path/to/symframe uses that binary instead of building the debug one.
#
# Needs Chromium (Debian's `chromium`, installed with apt-get when missing and running as root),
# node and npm (three, playwright-core and pngjs from npm, into target/viewer-test-node, beside
# the viewer test's); without them it says so and skips.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
three_version=0.180.0
skip() {
    echo "threejs-check: skipping the three.js check of the exported glTF assets: $*"
    exit 0
}
command -v node >/dev/null && command -v npm >/dev/null || skip "node and npm are not installed"
# shellcheck source=find-chromium.sh
source "$here/find-chromium.sh"

node_dir="$root/target/viewer-test-node"
installed_three="$(node -p "require('$node_dir/node_modules/three/package.json').version" 2>/dev/null || true)"
if [ ! -d "$node_dir/node_modules/playwright-core" ] || [ ! -d "$node_dir/node_modules/pngjs" ] ||
    [ "$installed_three" != "$three_version" ]; then
    mkdir -p "$node_dir"
    npm install --silent --no-audit --no-fund --prefix "$node_dir" playwright-core@1.65.1 pngjs@7.0.0 \
        "three@$three_version" >/dev/null || skip "npm could not install three, playwright-core and pngjs"
fi
export NODE_PATH="$node_dir/node_modules"

start=$(date +%s)
if [ -n "${SYMFRAME:-}" ]; then
    sf="$(realpath "$SYMFRAME")"
else
    (cd "$root" && cargo build --locked -q -p symframe-cli)
    sf="$root/target/debug/symframe"
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
built=$(date +%s)
"$here/gltf-assets.sh" "$sf" "$work"
made=$(date +%s)
# The export's counts, from its summary line ("..., 4 vertices, 2 triangles): wrote ...").
counts() {
    local line
    line="$(cat "$work/$1.log")"
    [[ "$line" =~ ([0-9]+)\ vertices,\ ([0-9]+)\ triangles ]] ||
        { echo "threejs-check: no counts in the export's line: $line" >&2; exit 1; }
    echo --vertices "${BASH_REMATCH[1]}" --triangles "${BASH_REMATCH[2]}"
}
args=(--three "$node_dir/node_modules/three" --mask "$work/data/mask.png" --normals "$work/data/gt_normals.npy")
for a in quad.gltf quad.glb ward.glb est.glb; do
    # shellcheck disable=SC2046
    args+=(--asset "$work/$a" $(counts "$a"))
done
# shellcheck disable=SC2046
args+=(--asset "$work/mesh.glb" --normal-map no $(counts mesh.glb))
node "$here/threejs-check.js" "${args[@]}"
end=$(date +%s)
echo "threejs-check: passed in $((end - start)) s (build $((built - start)) s, assets $((made - built)) s, browser $((end - made)) s)"
