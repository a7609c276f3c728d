#!/usr/bin/env bash
# Times symframe's JPEG decoding against libjpeg-turbo on the same files, one thread each, the
# files in memory (docs/performance.md, "JPEG decoding"), and compares the decoded values.
#
#   scripts/jpeg-decode-bench.sh [-r ROUNDS] [-s "WxH ..."] DIR
#
# DIR receives the test files (written once, reused by later runs): for each size (default
# "2000x1500 6000x4000") a photograph-like picture (`jpeg_decode --make`), encoded by cjpeg as
# baseline JPEG of quality 90 with 4:2:0 (cjpeg's default) and 4:4:4 chroma. ROUNDS (default
# 3): the two decoders run alternately that many times; symframe's time is its best of 5
# decodes into the file's 8-bit samples (what the tile cache stores), libjpeg-turbo's is
# tjbench's mean over one second of decodes into RGB (after half a second of warm-up); the
# table gives the range over the rounds. "differ" is the share of samples where the two
# decoders' values differ (IDCT and chroma upsampling are not specified to the bit), "max" the
# largest difference in 8-bit codes.
#
# Needs libjpeg-turbo's tools (Debian: apt-get install libjpeg-turbo-progs, for cjpeg, djpeg
# and tjbench) and python3; nothing of it is a build dependency of symframe.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=3 sizes="2000x1500 6000x4000"
while getopts "r:s:" opt; do
    case $opt in
    r) rounds=$OPTARG ;;
    s) sizes=$OPTARG ;;
    *) exit 2 ;;
    esac
done
shift $((OPTIND - 1))
[ $# -eq 1 ] || { sed -n '2,18p' "$0"; exit 2; }
dir=$1
for tool in cjpeg djpeg tjbench python3; do
    command -v $tool >/dev/null || {
        echo "needs $tool (apt-get install libjpeg-turbo-progs python3)" >&2
        exit 1
    }
done
mkdir -p "$dir"
cargo build --release -q -p symframe-io --example jpeg_decode
ours="${CARGO_TARGET_DIR:-target}/release/examples/jpeg_decode"

files=()
for size in $sizes; do
    w=${size%x*} h=${size#*x}
    ppm="$dir/photo-$size.ppm"
    [ -s "$ppm" ] || "$ours" --make "$w" "$h" "$ppm"
    for sub in 420:2x2 444:1x1; do
        f="$dir/photo-$size-q90-${sub%%:*}.jpg"
        [ -s "$f" ] || cjpeg -quality 90 -baseline -sample "${sub#*:}" -outfile "$f" "$ppm"
        files+=("$f")
    done
done

echo "| file | size | bits/pixel | symframe (ms) | libjpeg-turbo (ms) | ratio | differ | max |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- |"
for f in "${files[@]}"; do
    name=$(basename "$f")
    ours_ms=() turbo_ms=() ratios=()
    for _ in $(seq "$rounds"); do
        o=$("$ours" -r 5 "$f" | sed -E 's/.* codes best ([0-9.]+) ms.*/\1/')
        fps=$(tjbench "$f" -benchtime 1 -warmup 0.5 -nowrite 2>&1 | sed -nE 's/.*Frame rate: *([0-9.]+) fps.*/\1/p' | head -1)
        t=$(python3 -c "print(f'{1000 / $fps:.1f}')")
        ours_ms+=("$o") turbo_ms+=("$t")
        ratios+=("$(python3 -c "print(f'{$o / $t:.2f}')")")
    done
    range() { printf '%s\n' "$@" | sort -g | sed -n '1p;$p' | paste -sd- | sed -E 's/^([^-]+)-\1$/\1/'; }
    "$ours" --ppm "$dir" "$f"
    djpeg -ppm -outfile "$dir/turbo.ppm" "$f"
    cmp=$(python3 - "$dir/${name%.jpg}.ppm" "$dir/turbo.ppm" "$f" <<'EOF'
import os, sys
def body(p):
    b = open(p, "rb").read()
    i = 0
    for _ in range(3):
        i = b.index(b"\n", i) + 1
    return b[:i].split()[1:3], b[i:]
(sa, a), (sb, b) = body(sys.argv[1]), body(sys.argv[2])
assert sa == sb and len(a) == len(b), "sizes differ"
diff = [abs(x - y) for x, y in zip(a, b)]
n = sum(1 for d in diff if d)
w, h = int(sa[0]), int(sa[1])
print(f"{w} x {h} | {8 * os.path.getsize(sys.argv[3]) / (w * h):.2f} | {n / len(a):.1%} | {max(diff)}")
EOF
)
    rm -f "$dir/turbo.ppm" "$dir/${name%.jpg}.ppm"
    size=${cmp%% | *} rest=${cmp#* | }
    bpp=${rest%% | *} rest=${rest#* | }
    echo "| $name | $size | $bpp | $(range "${ours_ms[@]}") | $(range "${turbo_ms[@]}") | $(range "${ratios[@]}") | $rest |"
done
