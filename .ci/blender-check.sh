#!/usr/bin/env bash
# Opens the exported glTF assets in Blender: makes the assets of .ci/gltf-assets.sh and imports
# each with Blender's own glTF importer in background mode (blender-check.py): one mesh with the
# exported vertex and triangle counts, a Principled BSDF with its base colour from a texture, a
# normal-map node on the quads (whose normals are in a texture) and none on the mesh.
#   .ci/blender-check.sh
# SYMFRAME=path/to/symframe uses that binary instead of building the debug one.
#
# Needs `blender` and numpy for Blender's Python (Debian's `blender` and `python3-numpy`,
# installed here with apt-get when missing and running as root: about 30 s); without them it
# says so and skips. Debian 12's Blender is 3.4, whose importer does not read
# KHR_materials_anisotropy (Blender 4.x does): the anisotropy is not checked here (three.js
# checks it, .ci/threejs-check.sh).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(dirname "$here")"
if ! command -v blender >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "blender-check: installing Debian's blender"
    "$here/apt-install.sh" blender python3-numpy >/dev/null 2>&1 || true
fi
if ! command -v blender >/dev/null; then
    echo "blender-check: skipping the Blender import of the exported glTF assets: blender is not installed"
    exit 0
fi
start=$(date +%s)
if [ -n "${SYMFRAME:-}" ]; then
    sf="$SYMFRAME"
else
    (cd "$root" && cargo build --locked -q -p symframe-cli)
    sf="$root/target/debug/symframe"
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
bash "$here/gltf-assets.sh" "$sf" "$work"
args=()
for name in quad.gltf quad.glb ward.glb est.glb mesh.glb; do
    line="$(cat "$work/$name.log")"
    v="$(grep -oE '[0-9]+ vertices' <<<"$line" | cut -d' ' -f1)"
    t="$(grep -oE '[0-9]+ triangles' <<<"$line" | cut -d' ' -f1)"
    normal=1
    [ "$name" = mesh.glb ] && normal=0
    args+=("$work/$name:$v:$t:$normal")
done
status=0
blender -b --factory-startup --python-exit-code 1 --python "$here/blender-check.py" -- "${args[@]}" \
    >"$work/blender.log" 2>&1 || status=$?
grep -E '^blender-check|Error|Traceback|^  File' "$work/blender.log" || true
if [ "$status" != 0 ]; then
    echo "blender-check: failed (Blender exit status $status)" >&2
    exit 1
fi
echo "blender-check: passed in $(($(date +%s) - start)) s"
