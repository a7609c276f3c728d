#!/usr/bin/env bash
# Times symframe's EXR decoding against the OpenEXR C++ library for every compression, scan
# lines and tiles, half and float, on files OpenEXR itself writes; one thread each, files read
# into memory first; and checks that both decode the same values to the bit
# (docs/performance.md, "Decoding, every compression").
#
#   scripts/exr-compression-bench.sh [-r ROUNDS] [-s "SIZE:COUNT ..."] [-o REGEX] DIR
#
# DIR receives the test files (written once, reused by later runs; about 1.7 GB with the
# default sizes, "128:200 1024:4": 200 images of 128 x 128 and 4 of 1024 x 1024 per set).
# -o keeps the sets whose name (e.g. scan-float-piz) matches REGEX. ROUNDS (default 3): the
# two decoders run alternately that many times, each time taking its best of 3 passes over the
# set; the table gives the range of the per-image times and of the ratio of each round.
#
# Needs g++, pkg-config and OpenEXR's development files (Debian: apt-get install
# libopenexr-dev); nothing of it is a build dependency of symframe.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=3 sizes="128:200 1024:4" only=.
while getopts "r:s:o:" opt; do
    case $opt in
    r) rounds=$OPTARG ;;
    s) sizes=$OPTARG ;;
    o) only=$OPTARG ;;
    *) exit 2 ;;
    esac
done
shift $((OPTIND - 1))
[ $# -eq 1 ] || { sed -n '2,16p' "$0"; exit 2; }
dir=$1
command -v g++ >/dev/null && pkg-config --exists OpenEXR || {
    echo "needs g++ and OpenEXR's development files (apt-get install libopenexr-dev)" >&2
    exit 1
}
mkdir -p "$dir"
ref="$dir/exr-reference"
g++ -O2 -std=c++17 scripts/exr-reference.cpp -o "$ref" $(pkg-config --cflags --libs OpenEXR)
cargo build --release -q -p symframe-io --example decode_time
ours="${CARGO_TARGET_DIR:-target}/release/examples/decode_time"

best() { sed -n 's/.*best \([0-9.]*\) ms.*/\1/p'; }
echo "OpenEXR $(pkg-config --modversion OpenEXR); load $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| size | set | symframe ms/image | OpenEXR ms/image | ratio | values |"
echo "|---|---|---:|---:|---:|---|"
for sc in $sizes; do
    size=${sc%%:*} count=${sc##*:}
    sdir="$dir/$size"
    if [ ! -f "$sdir/.complete-$count" ]; then
        rm -rf "$sdir"
        "$ref" write "$sdir" "$size" "$count"
        touch "$sdir/.complete-$count"
    fi
    for set in $(ls "$sdir" | grep -E -- "$only"); do
        files=("$sdir/$set"/*.exr)
        theirs=$("$ref" sum "${files[@]}")
        if ! mine=$("$ours" --sum "${files[@]}" 2>&1); then
            echo "| $size | $set | refused | | | ${mine##*panicked at*: } |" | tr '\n' ' '
            echo
            continue
        fi
        [ "$mine" = "$theirs" ] && values=identical || values="DIFFER ($mine, OpenEXR $theirs)"
        a=() b=() q=()
        for _ in $(seq "$rounds"); do
            x=$("$ours" -r 3 "${files[@]}" | best)
            y=$("$ref" time -r 3 "${files[@]}" | best)
            a+=("$x") b+=("$y") q+=("$(echo "$x $y" | awk '{printf "%.2f", $1 / $2}')")
        done
        range() { printf '%s\n' "$@" | sort -g | sed -n '1p;$p' | paste -sd- | sed 's/^\(.*\)-\1$/\1/'; }
        echo "| $size | $set | $(range "${a[@]}") | $(range "${b[@]}") | $(range "${q[@]}") | $values |"
    done
done
