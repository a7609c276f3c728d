#!/usr/bin/env bash
# Browser test of `symframe view`: renders a small synthetic capture, estimates and fits it
# (Ward, then glTF: each page is checked),
# writes the viewer, renders it in headless Chromium (WebGL2 on SwiftShader) in several states
# and compares each screenshot with the picture the command line makes of the same state:
# `symframe relight` at three lights and with every edit, the fit's albedo pictures, and the
# estimate's normal, tangent, confidence and source pictures; then relights by a change of the
# URL fragment and by a mouse drag. The view `samples` (--from-samples) against `symframe
# relight --from-samples`, also on a capture whose rig does not reach a light's halfway vector
# (read at its mirror images). Fails when a PSNR over the object is below 45 dB (30 dB is
# the requirement; about 67 dB is measured: pixels differ by at most one level in 255).
#   .ci/viewer-test.sh [--size N] [--screenshot FILE.png]
# --screenshot also saves a picture of the whole viewer (the README's docs/viewer.png is made
# with --size 224 --screenshot docs/viewer.png).
# SYMFRAME=path/to/symframe uses that binary instead of building the debug one.
#
# Needs Chromium (Debian's `chromium`, installed here with apt-get when missing and running as
# root), node and npm (playwright-core and pngjs from npm, into target/viewer-test-node).
# Without them it says so and skips.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
size=64
screenshot=""
while [ $# -gt 0 ]; do
    case "$1" in
        --size) size="$2"; shift 2 ;;
        --screenshot) screenshot="$(realpath -m "$2")"; shift 2 ;;
        *) echo "viewer-test: unknown argument $1" >&2; exit 2 ;;
    esac
done
skip() {
    echo "viewer-test: skipping the browser test of symframe view: $*"
    exit 0
}
command -v node >/dev/null && command -v npm >/dev/null || skip "node and npm are not installed"

# shellcheck source=find-chromium.sh
source "$here/find-chromium.sh"

node_dir="$root/target/viewer-test-node"
if [ ! -d "$node_dir/node_modules/playwright-core" ] || [ ! -d "$node_dir/node_modules/pngjs" ]; then
    mkdir -p "$node_dir"
    # playwright-core drives the system Chromium (it downloads no browser); pngjs reads PNGs.
    npm install --silent --no-audit --no-fund --prefix "$node_dir" playwright-core@1.65.1 pngjs@7.0.0 >/dev/null ||
        skip "npm could not install playwright-core and pngjs"
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
"$sf" -q synth -o "$work/data" --size "$size" --rig cone:200 --model ward
"$sf" -q estimate "$work/data" -o "$work/est"
"$sf" -q fit "$work/data" --frames "$work/est" -o "$work/fit" --model ward
"$sf" -q fit "$work/data" --frames "$work/est" -o "$work/gltf" --model gltf
# From the work folder, so that the page's title is just "fit".
(cd "$work" && "$sf" -q view fit -o viewer.html && "$sf" -q view gltf -o viewer_gltf.html &&
    "$sf" -q view est -o viewer_est.html &&
    "$sf" -q view fit -o viewer_pyramid.html --pyramid-above 32 --tile-size 16)

l1=0.3,0.4,0.866 l2=-0.5,0.2,0.84 l3=0.1,-0.6,0.79
"$sf" -q relight "$work/fit" -o "$work/relit" --light "$l1" --light "$l2" --light "$l3"
edits="exposure=0.5&diffuse=0.7&specular=1.5&roughness=0.8&rotate=60"
"$sf" -q relight "$work/fit" -o "$work/edited" --light "$l2" --exposure 0.5 --diffuse-scale 0.7 \
    --specular-scale 1.5 --roughness-scale 0.8 --rotate-tangents 60

args=(--viewer "$work/viewer.html" --mask "$work/data/mask.png" --min-psnr 45 --interact
    --case "light=$l1" "$work/relit/relit_000.png"
    --case "light=$l2" "$work/relit/relit_001.png"
    --case "light=$l3" "$work/relit/relit_002.png"
    --case "light=$l2&$edits" "$work/edited/relit_000.png"
    --case "view=kd" "$work/fit/kd.png"
    --case "view=ks" "$work/fit/ks.png"
    --case "view=normal" "$work/est/normals.png"
    --case "view=tangent" "$work/est/tangents.png"
    --case "view=confidence" "$work/est/confidence.png"
    --case "view=source" "$work/est/source.png")
if [ -n "$screenshot" ]; then
    args+=(--screenshot "$screenshot")
fi
node "$here/viewer-test.js" "${args[@]}"

# The same for the glTF fit of the capture (its model in the shader; no specular factor).
"$sf" -q relight "$work/gltf" -o "$work/grelit" --light "$l1" --light "$l2" --light "$l3"
"$sf" -q relight "$work/gltf" -o "$work/gedited" --light "$l2" --exposure 0.5 --diffuse-scale 0.7 \
    --roughness-scale 0.8 --rotate-tangents 60
node "$here/viewer-test.js" --viewer "$work/viewer_gltf.html" --mask "$work/data/mask.png" --min-psnr 45 --interact \
    --case "light=$l1" "$work/grelit/relit_000.png" \
    --case "light=$l2" "$work/grelit/relit_001.png" \
    --case "light=$l3" "$work/grelit/relit_002.png" \
    --case "light=$l2&exposure=0.5&diffuse=0.7&roughness=0.8&rotate=60" "$work/gedited/relit_000.png" \
    --case "view=base_color" "$work/gltf/base_color.png"

# The estimate folder itself (no fit): its maps' pictures, a relit view, the legends.
node "$here/viewer-test.js" --viewer "$work/viewer_est.html" --mask "$work/data/mask.png" --min-psnr 45 --interact \
    --case "view=normal" "$work/est/normals.png" \
    --case "view=tangent" "$work/est/tangents.png" \
    --case "view=confidence" "$work/est/confidence.png" \
    --case "view=source" "$work/est/source.png" \
    --nonblank "light=$l1"

# The view `samples`: the capture's photographs relit themselves, against `symframe relight
# --from-samples`, at lights inside the rig, and on a capture of halfway angles up to 30
# degrees at a light whose halfway vector is outside it (the slice read at its mirror images).
l4=-0.85,0.3,0.43
"$sf" -q synth -o "$work/half" --size 48 --rig cone:120:30 --model ward
"$sf" -q estimate "$work/half" -o "$work/half_est"
"$sf" -q fit "$work/half" --frames "$work/half_est" -o "$work/half_fit" --model ward
(cd "$work" && "$sf" -q view fit -o viewer_samples.html --from-samples data &&
    "$sf" -q view half_fit -o viewer_half.html --from-samples half)
"$sf" -q relight "$work/fit" -o "$work/srelit" --from-samples "$work/data" --light "$l1" --light "$l3"
"$sf" -q relight "$work/half_fit" -o "$work/hrelit" --from-samples "$work/half" --light "$l4" --light "$l1"
node "$here/viewer-test.js" --viewer "$work/viewer_samples.html" --mask "$work/data/mask.png" --min-psnr 45 \
    --case "view=samples&light=$l1" "$work/srelit/relit_000.png" \
    --case "view=samples&light=$l3&exposure=0" "$work/srelit/relit_001.png" \
    --case "light=$l1" "$work/relit/relit_000.png"
node "$here/viewer-test.js" --viewer "$work/viewer_half.html" --mask "$work/half/mask.png" --min-psnr 45 \
    --case "view=samples&light=$l4" "$work/hrelit/relit_000.png" \
    --case "view=samples&light=$l1" "$work/hrelit/relit_001.png"

# The Ward fit as a pyramid of 16 px tiles (3 levels at 64 px: halving until one tile holds
# the map): the coarse level at once, tiles on demand.
levels=1 side=$size
while [ "$side" -gt 16 ]; do side=$(((side + 1) / 2)) levels=$((levels + 1)); done
node "$here/viewer-test.js" --viewer "$work/viewer_pyramid.html" --mask "$work/data/mask.png" --min-psnr 45 \
    --pyramid 16 "$levels" --case "light=$l1" "$work/relit/relit_000.png"
echo "viewer-test: passed in $(($(date +%s) - start)) s (${size}x${size} fit, $(stat -c %s "$work/viewer.html") byte page)"
