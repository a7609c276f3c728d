#!/usr/bin/env bash
# Makes the glTF assets that .ci/gltf-check.sh and .ci/threejs-check.sh check: renders a small
# synthetic capture (a 48 x 48 sphere, Ward, 200 lights), estimates, fits it with both models
# (glTF: the fitted material; Ward: converted), integrates, and exports
#   quad.gltf, quad.glb  the glTF fit on a quad (normal map)
#   ward.glb             the Ward fit, converted
#   est.glb              the estimate alone (grey material)
#   mesh.glb             the glTF fit on the integrated mesh (normals in the geometry)
# into DIR, each with the export's summary line in NAME.log (its vertex and triangle counts).
#   .ci/gltf-assets.sh SYMFRAME DIR
set -euo pipefail
sf="$1"
work="$2"
"$sf" -q synth -o "$work/data" --size 48 --rig cone:200 --model ward >/dev/null
"$sf" -q estimate "$work/data" -o "$work/est" >/dev/null
"$sf" -q fit "$work/data" --frames "$work/est" -o "$work/fit" --model gltf >/dev/null
"$sf" -q fit "$work/data" --frames "$work/est" -o "$work/ward" --model ward >/dev/null
"$sf" -q integrate "$work/est" -o "$work/int" --solver poisson >/dev/null
export_as() {
    local out="$1"
    shift
    "$sf" export gltf "$@" -o "$work/$out" >"$work/$out.log"
}
export_as quad.gltf "$work/fit"
export_as quad.glb "$work/fit"
export_as ward.glb "$work/ward"
export_as est.glb "$work/est"
export_as mesh.glb "$work/fit" --mesh --depth "$work/int/depth.npy"
