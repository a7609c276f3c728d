#!/usr/bin/env bash
# A sweep of hostile cases against a symframe binary: shared folders and concurrent runs,
# links planted inside output folders, planted staging plans and foreign lock holders, user
# folders named like symframe's, outputs that would replace inputs, forged manifests, devices
# and FIFOs as path arguments, small files declaring huge images in every format, huge light
# files, calibration circles far larger than the image, and --quiet on every command.
#
#   scripts/hostile-sweep.sh PATH/TO/symframe [--keep]
#
# Works in a fresh temporary folder (kept with --keep, else removed). Every case runs the
# binary once (a few run two at once) and checks that:
#   - no file outside the case's output folder changed, appeared or went (a snapshot of the
#     whole work folder, sizes, modification times and MD5 sums, before and after), and no
#     input or user file inside it either;
#   - its peak memory (/usr/bin/time -f %M) stayed under 600 MB;
#   - it did not panic (exit status 101, or "panicked" on stderr) nor hang (a time limit);
#   - it succeeded, or failed with a clear message (a "symframe: error: ..." line of at most
#     a few lines), as the case expects.
# Prints one line per case, PASS or FAIL with the reason, then a summary; exits 1 on any FAIL.
# Needs bash, python3 (to forge files), GNU coreutils, findutils and /usr/bin/time. Takes a
# few minutes on two cores.

set -u
if [[ $# -lt 1 || ! -x $1 ]]; then
    echo "usage: $0 PATH/TO/symframe [--keep]" >&2
    exit 2
fi
BIN=$(realpath "$1")
KEEP=${2:-}
for tool in python3 /usr/bin/time timeout md5sum find mkfifo; do
    command -v "$tool" >/dev/null || { echo "hostile-sweep: needs $tool" >&2; exit 2; }
done

T=$(mktemp -d "${TMPDIR:-/tmp}/symframe-sweep.XXXXXX")
T=$(realpath "$T")
cleanup() {
    # Background jobs of the concurrency cases, if a case was interrupted.
    jobs -p | xargs -r kill 2>/dev/null
    if [[ $KEEP == --keep ]]; then
        echo "work folder kept: $T"
    else
        rm -rf "$T"
    fi
}
trap cleanup EXIT
mkdir -p "$T/in" "$T/home" "$T/cases" "$T/work"

RSS_LIMIT_KB=$((600 * 1024))
N=0
FAILS=0
FAILED=()

# --- snapshots -------------------------------------------------------------------------------

# Every entry under $T but the cases' scratch files: path, type, and for a file its size,
# modification time and MD5 (files over 16 MB by size and time only); for a link its target.
snapshot() {
    (
        cd "$T" || exit 1
        find . -path ./.run -prune -o -printf '%p\t%y\t%l\n' | LC_ALL=C sort >"$1.entries"
        find . -path ./.run -prune -o -type f -size -16M -print0 | LC_ALL=C sort -z \
            | xargs -0 -r md5sum >"$1.sums"
        find . -path ./.run -prune -o -type f -printf '%p\t%s\t%T@\n' | LC_ALL=C sort \
            >"$1.times"
    )
}

# The paths that differ between snapshots $1 and $2 (appeared, went, changed).
changed_paths() {
    {
        diff <(cut -f1,2,3 "$1.entries") <(cut -f1,2,3 "$2.entries")
        diff "$1.sums" "$2.sums" | sed -E 's/^([<>]) [0-9a-f]+  /\1 /'
        diff "$1.times" "$2.times"
    } | grep -E '^[<>] ' | sed -E 's/^[<>] //' | cut -f1 | sed -E 's#^\./##' | LC_ALL=C sort -u
}

# Whether path $1 (relative to $T) is inside one of the allowed folders and not protected.
allowed() {
    local p=$1 a
    for a in "${PROTECT[@]}"; do
        a=${a#"$T"/}
        [[ $p == "$a" || $p == "$a"/* ]] && return 1
    done
    for a in "${ALLOW[@]}"; do
        a=${a#"$T"/}
        [[ $p == "$a" || $p == "$a"/* ]] && return 0
    done
    return 1
}

# --- running a case ---------------------------------------------------------------------------

ALLOW=()
PROTECT=()
mkdir -p "$T/.run"

# case NAME EXPECT ARGS...: runs the binary with ARGS in $T/work (stdin /dev/null) and checks
# it. EXPECT: ok | quiet (ok, nothing printed) | err | err:REGEX | ok:REGEX (stderr or stdout
# match) | stopped (status 130, --stop-after-tiles) | stopped-or-err | any (succeeds or fails
# clearly). ALLOW: folders the run may write into; PROTECT:
# paths in them it must not touch. Environment for the run: CASE_ENV (VAR=VALUE ...);
# CASE_TIMEOUT seconds (default 120).
case_() {
    local name=$1 expect=$2
    shift 2
    N=$((N + 1))
    snapshot "$T/.run/before"
    local rc
    (
        cd "$T/work" || exit 1
        # shellcheck disable=SC2086
        env ${CASE_ENV:-} /usr/bin/time -f %M -o "$T/.run/rss" \
            timeout -k 5 "${CASE_TIMEOUT:-120}" "$BIN" "$@" \
            >"$T/.run/out" 2>"$T/.run/err" </dev/null
    )
    rc=$?
    snapshot "$T/.run/after"
    check "$name" "$expect" "$rc" "$(tail -n 1 "$T/.run/rss" 2>/dev/null)" "$T/.run/out" "$T/.run/err"
}

# check NAME EXPECT RC RSS_KB STDOUT_FILE STDERR_FILE: the verdict of one run.
check() {
    local name=$1 expect=$2 rc=$3 rss=$4 out=$5 err=$6 why=() p
    [[ $rss =~ ^[0-9]+$ ]] || rss=0
    if [[ $rc == 101 ]] || grep -q panicked "$err"; then
        why+=("panicked (status $rc): $(grep -m1 panicked "$err")")
    fi
    if [[ $rc == 124 || $rc == 137 ]]; then
        why+=("timed out")
    fi
    if ((rss > RSS_LIMIT_KB)); then
        why+=("peak memory $((rss / 1024)) MB")
    fi
    while IFS= read -r p; do
        [[ -z $p ]] && continue
        allowed "$p" || why+=("touched $p")
    done < <(changed_paths "$T/.run/before" "$T/.run/after")
    local first
    first=$(grep -v -E '^(symframe[a-z ]*: )?warning:' "$err" | head -n 1)
    case $expect in
    ok | ok:*)
        [[ $rc == 0 ]] || why+=("failed (status $rc): $first")
        if [[ $expect == ok:* ]] && ! grep -qE -- "${expect#ok:}" "$err" "$out"; then
            why+=("no '${expect#ok:}' in its output")
        fi
        ;;
    quiet)
        [[ $rc == 0 ]] || why+=("failed (status $rc): $first")
        [[ -s $out || -s $err ]] && why+=("printed with --quiet: $(cat "$out" "$err" | head -n 1)")
        ;;
    err | err:*)
        if [[ $rc == 0 ]]; then
            why+=("succeeded, expected an error")
        elif ! [[ $first == *"error"* ]]; then
            why+=("no error message (status $rc): '$first'")
        elif (($(wc -l <"$err") > 8)); then
            why+=("error message of $(wc -l <"$err") lines")
        fi
        if [[ $expect == err:* ]] && ! grep -qE -- "${expect#err:}" "$err"; then
            why+=("error '$first' does not match '${expect#err:}'")
        fi
        ;;
    stopped | stopped-or-err)
        # --stop-after-tiles: every image decoded, then stopped as Ctrl-C stops it.
        if [[ $rc != 130 && ! ($expect == stopped-or-err && $rc != 0 && $first == *error*) ]]; then
            why+=("status $rc, expected 130 (stopped): $first")
        fi
        ;;
    any)
        if [[ $rc != 0 && $first != *"error"* ]]; then
            why+=("no error message (status $rc): '$first'")
        fi
        ;;
    esac
    if ((${#why[@]})); then
        FAILS=$((FAILS + 1))
        FAILED+=("$name")
        local IFS='; '
        printf 'FAIL %-58s %s\n' "$name" "${why[*]}"
    else
        printf 'PASS %-58s %s\n' "$name" "$(short "$rc" "$rss" "$first")"
    fi
}

# What a passing case did, briefly.
short() {
    local m=$3
    ((${#m} > 90)) && m="${m:0:87}..."
    if [[ $1 == 0 ]]; then
        echo "ok, $(($2 / 1024)) MB"
    else
        echo "refused, $(($2 / 1024)) MB: ${m#symframe: error: }"
    fi
}

# The files and links now under folder $1 (to protect what is there, not what a run adds).
existing() {
    find "$1" \( -type f -o -type l \) -print
}

# A fresh output folder for a case: $T/cases/NAME (removed first).
fresh() {
    rm -rf "${T:?}/cases/$1"
    mkdir -p "$T/cases/$1"
    echo "$T/cases/$1"
}

# Removes a case's folder once checked, so snapshots stay small.
done_with() {
    rm -rf "${T:?}/cases/$1"
}

run() { # run ARGS...: the binary, quietly, for fixtures; fails the sweep if it fails.
    if ! (cd "$T/work" && "$BIN" "$@" >"$T/.run/fixture.log" 2>&1); then
        echo "hostile-sweep: fixture failed: symframe $*" >&2
        cat "$T/.run/fixture.log" >&2
        exit 2
    fi
}

# --- fixtures ----------------------------------------------------------------------------------

echo "hostile-sweep: $BIN, work folder $T"
IN=$T/in
run synth -o "$IN/data" --size 24 --rig cone:30 --model lambertian --quiet
run synth -o "$IN/png" --size 24 --rig cone:30 --model lambertian --format png16 --quiet
run synth -o "$IN/chrome" --size 32 --rig cone:12 --model lambertian --chrome-sphere --quiet
run estimate "$IN/data" -o "$IN/est" --quiet
run fit "$IN/data" --frames "$IN/est" -o "$IN/fit" --model ward --quiet
run fit "$IN/data" --frames "$IN/est" -o "$IN/gfit" --model gltf --quiet
run estimate "$IN/data" -o "$IN/shard1" --tiles 1/2 --tile-size 8 --method woodham --quiet
run estimate "$IN/data" -o "$IN/shard2" --tiles 2/2 --tile-size 8 --method woodham --quiet
# The user's own files, which no run may touch.
echo "export PATH=/usr/bin" >"$T/home/.bashrc"
echo "notes" >"$T/home/notes.txt"
mkdir -p "$T/home/folder" && echo "kept" >"$T/home/folder/file.txt"
echo '{"asset": {"version": "2.0"}, "note": "a user glTF"}' >"$T/home/scene.gltf"
mkfifo "$T/home/fifo"
# The chrome sphere's circle, from the synthetic scene (for calibrate).
SPHERE=$(python3 -c "import json; print(json.load(open('$IN/chrome/scene.json'))['chrome_sphere']['sphere_arg'])")
# Forged images: small files declaring 8000 x 8000 pixels, in every format.
python3 - "$IN/huge" <<'EOF'
import os, struct, sys, zlib
d = sys.argv[1]
os.makedirs(d, exist_ok=True)
W = H = 8000
def png(path, w, h):
    raw = zlib.compress(b"\0" * ((3 * w + 1) * h), 9)
    def chunk(k, b):
        return struct.pack(">I", len(b)) + k + b + struct.pack(">I", zlib.crc32(k + b))
    open(path, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                           + chunk(b"IDAT", raw) + chunk(b"IEND", b""))
def jpeg(path, w, h):
    # A baseline header declaring w x h and a scan of a few KB of zeros: truncated data.
    q = bytes([0] + [1] * 64)
    sof = struct.pack(">BHHB", 8, h, w, 3) + bytes([1, 0x11, 0, 2, 0x11, 0, 3, 0x11, 0])
    dht = bytes([0x00] + [0] * 15 + [1]) + bytes([0]) + bytes([0x10] + [0] * 15 + [1]) + bytes([0])
    sos = bytes([3, 1, 0x00, 2, 0x00, 3, 0x00, 0, 63, 0])
    seg = lambda m, b: b"\xff" + bytes([m]) + struct.pack(">H", len(b) + 2) + b
    open(path, "wb").write(b"\xff\xd8" + seg(0xdb, q) + seg(0xc0, sof) + seg(0xc4, dht) + seg(0xda, sos)
                           + b"\0" * 8192 + b"\xff\xd9")
def exr(path, w, h):
    def attr(n, t, v):
        return n.encode() + b"\0" + t.encode() + b"\0" + struct.pack("<i", len(v)) + v
    ch = b"".join(n.encode() + b"\0" + struct.pack("<i", 1) + b"\0\0\0\0" + struct.pack("<ii", 1, 1) for n in "BGR") + b"\0"
    win = struct.pack("<4i", 0, 0, w - 1, h - 1)
    hd = (b"\x76\x2f\x31\x01\x02\0\0\0" + attr("channels", "chlist", ch) + attr("compression", "compression", b"\x03")
          + attr("dataWindow", "box2i", win) + attr("displayWindow", "box2i", win) + attr("lineOrder", "lineOrder", b"\0")
          + attr("pixelAspectRatio", "float", struct.pack("<f", 1)) + attr("screenWindowCenter", "v2f", b"\0" * 8)
          + attr("screenWindowWidth", "float", struct.pack("<f", 1)) + b"\0")
    nb = (h + 15) // 16
    table, chunks, offs, cache = len(hd) + 8 * nb, b"", [], {}
    for b in range(nb):
        lines = min(16, h - 16 * b)
        if lines not in cache:
            cache[lines] = zlib.compress(b"\0" + b"\x80" * (lines * w * 6 - 1), 9)
        offs.append(table + len(chunks))
        chunks += struct.pack("<ii", 16 * b, len(cache[lines])) + cache[lines]
    open(path, "wb").write(hd + b"".join(struct.pack("<Q", o) for o in offs) + chunks)
def tiff(path, w, h, rows=16):
    strips = (h + rows - 1) // rows
    data = zlib.compress(b"\0" * (rows * w * 12), 9)
    ifd = 8 + len(data)
    ents = [(256, 4, [w]), (257, 4, [h]), (258, 3, [32] * 3), (259, 3, [8]), (262, 3, [2]), (273, 4, [8] * strips),
            (277, 3, [3]), (278, 4, [rows]), (279, 4, [len(data)] * strips), (284, 3, [1]), (339, 3, [3] * 3)]
    at = ifd + 2 + 12 * len(ents) + 4
    out, extra = b"II*\0" + struct.pack("<I", ifd) + data + struct.pack("<H", len(ents)), b""
    for tag, ty, vals in ents:
        bs = b"".join(struct.pack("<H" if ty == 3 else "<I", v) for v in vals)
        out += struct.pack("<HHI", tag, ty, len(vals))
        if len(bs) <= 4:
            out += bs.ljust(4, b"\0")
        else:
            out += struct.pack("<I", at)
            at += len(bs)
            extra += bs
    open(path, "wb").write(out + b"\0\0\0\0" + extra)
def hdr(path, w, h):
    n = w - 1
    line = bytes([0, 0, 0, 0, 1, 1, 1, n & 255]) + (bytes([1, 1, 1, n >> 8]) if n > 255 else b"")
    open(path, "wb").write(f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode() + line * h)
def pfm(path, w, h):
    open(path, "wb").write(f"PF\n{w} {h}\n-1.0\n".encode() + b"\0" * 4096)
for ext, f in [("png", png), ("jpg", jpeg), ("exr", exr), ("tif", tiff), ("hdr", hdr), ("pfm", pfm)]:
    sub = os.path.join(d, ext)
    os.makedirs(sub, exist_ok=True)
    f(os.path.join(sub, f"0.{ext}"), W, H)
    for i in (1, 2):
        data = open(os.path.join(sub, f"0.{ext}"), "rb").read()
        open(os.path.join(sub, f"{i}.{ext}"), "wb").write(data)
    open(os.path.join(sub, "lights.lp"), "w").write(
        f"3\n0.{ext} 0 0 1\n1.{ext} 0.5 0 0.866\n2.{ext} 0 0.5 0.866\n")
# A mask far larger than the images.
open(os.path.join(d, "mask.png"), "wb").write(open(os.path.join(d, "png", "0.png"), "rb").read())
EOF
IMG0=$(cd "$IN/data" && ls images | head -n 1)
echo "hostile-sweep: fixtures ready"
echo

# === 1. --quiet on every command ================================================================
ALLOW=("$T/cases/quiet")
PROTECT=()
Q=$(fresh quiet)
case_ "quiet: synth" quiet --quiet synth -o "$Q/synth" --size 16 --rig cone:12 --model lambertian
case_ "quiet: estimate" quiet --quiet estimate "$IN/data" -o "$Q/est" --method woodham
case_ "quiet: estimate --tiles" quiet estimate "$IN/data" -o "$Q/s1" --tiles 1/2 --tile-size 8 \
    --method woodham --quiet
case_ "quiet: merge" quiet merge "$IN/shard1" "$IN/shard2" -o "$Q/merged" --quiet
case_ "quiet: fit" quiet fit "$IN/data" --frames "$IN/est" -o "$Q/fit" --quiet
case_ "quiet: relight" quiet relight "$IN/fit" --light 0.2,0.1,1 -o "$Q/relit" --quiet
case_ "quiet: view" quiet view "$IN/fit" -o "$Q/viewer.html" --quiet
cp -r "$IN/est" "$Q/est-copy"
case_ "quiet: eval" quiet eval "$IN/data" "$Q/est-copy" --quiet
case_ "quiet: integrate" quiet integrate "$IN/est" -o "$Q/depth" --quiet
case_ "quiet: export gltf" quiet export gltf "$IN/fit" -o "$Q/asset.gltf" --quiet
case_ "quiet: calibrate" quiet calibrate "$IN/chrome/lights.lp" -o "$Q/cal/lights.lp" --sphere "$SPHERE" --quiet
case_ "quiet: calibrate, sphere found" quiet calibrate "$IN/chrome/lights.lp" -o "$Q/cal2/lights.lp" --quiet
case_ "quiet: demo" quiet demo -o "$Q/demo" --size 16 --lights 40 --quiet
done_with quiet

# === 2. shared folders and concurrent runs ======================================================

# Two jobs into one folder at once: the second is refused at once, the first finishes.
C=$(fresh conc)
ALLOW=("$C")
PROTECT=()
concurrent() { # concurrent NAME EXPECT_SECOND FIRST_ARGS... -- SECOND_ARGS...
    local name=$1 expect=$2 first=() second=()
    shift 2
    while [[ $1 != -- ]]; do first+=("$1"); shift; done
    shift
    second=("$@")
    (cd "$T/work" && SYMFRAME_TEST_HOLD_LOCK_S=3 timeout 120 "$BIN" "${first[@]}" \
        >"$T/.run/first.out" 2>"$T/.run/first.err") &
    local pid=$!
    sleep 1
    case_ "$name" "$expect" "${second[@]}"
    wait $pid
    local rc=$?
    [[ $rc == 0 ]] || {
        FAILS=$((FAILS + 1))
        FAILED+=("$name (first job)")
        echo "FAIL $name (first job): status $rc: $(head -n 1 "$T/.run/first.err")"
    }
}
concurrent "concurrent: estimate + estimate, one folder" "err:in use by process" \
    estimate "$IN/data" -o "$C/a" --method woodham --quiet -- \
    estimate "$IN/data" -o "$C/a" --method woodham --quiet
concurrent "concurrent: estimate + fit, one folder" "err:in use by process" \
    estimate "$IN/data" -o "$C/b" --method woodham --quiet -- \
    fit "$IN/data" --frames "$IN/est" -o "$C/b" --quiet
concurrent "concurrent: synth + synth, one folder" "err:in use by process" \
    synth -o "$C/c" --size 16 --rig cone:12 --model lambertian --quiet -- \
    synth -o "$C/c" --size 16 --rig cone:12 --model lambertian --quiet
concurrent "concurrent: merge + relight, one folder" "err:in use by process" \
    merge "$IN/shard1" "$IN/shard2" -o "$C/d" --quiet -- \
    relight "$IN/fit" --light 0,0,1 -o "$C/d" --quiet
cp -r "$IN/est" "$C/est-e"
concurrent "concurrent: eval + integrate on one estimate" any \
    eval "$IN/data" "$C/est-e" --quiet -- \
    integrate "$C/est-e" -o "$C/depth-e" --quiet
# Two jobs sharing one --cache folder, into two folders: both finish, with the same maps.
concurrent "concurrent: shared --cache" ok \
    estimate "$IN/data" -o "$C/f1" --cache "$C/cache" --method woodham --quiet -- \
    estimate "$IN/data" -o "$C/f2" --cache "$C/cache" --method woodham --quiet
N=$((N + 1))
if cmp -s "$C/f1/normals.npy" "$C/f2/normals.npy"; then
    printf 'PASS %-58s %s\n' "concurrent: shared --cache gives equal maps" "normals.npy equal"
else
    FAILS=$((FAILS + 1)); FAILED+=("shared cache maps")
    printf 'FAIL %-58s %s\n' "concurrent: shared --cache gives equal maps" "normals.npy differ"
fi
# A folder of a shared share: a rerun into a finished folder replaces its own set only.
echo "mine" >"$C/a/my-notes.txt"
PROTECT=("$C/a/my-notes.txt")
case_ "rerun into a finished folder keeps the user's files" ok \
    estimate "$IN/data" -o "$C/a" --method woodham --quiet
done_with conc

# === 3. links inside the output folder ==========================================================

V=$T/home
links() { # links NAME LINK_NAME TARGET EXPECT ARGS... (ARGS with OUT for the output folder)
    local name=$1 link=$2 target=$3 expect=$4
    shift 4
    local o
    o=$(fresh "link")
    mkdir -p "$(dirname "$o/out/$link")"
    ln -s "$target" "$o/out/$link"
    ALLOW=("$o")
    PROTECT=("$o/out/$link")
    local args=() a
    for a in "$@"; do args+=("${a//OUT/$o/out}"); done
    case_ "$name" "$expect" "${args[@]}"
    done_with link
}
EST=(estimate "$IN/data" -o OUT --method woodham --quiet)
links "link: .symframe-lock -> user file (estimate)" .symframe-lock "$V/notes.txt" err "${EST[@]}"
links "link: .symframe-lock -> missing file (estimate)" .symframe-lock "$V/new-file" err "${EST[@]}"
links "link: .symframe-tiles -> user folder" .symframe-tiles "$V/folder" err "${EST[@]}"
links "link: .symframe-cache -> user folder" .symframe-cache "$V/folder" err "${EST[@]}"
links "link: normals.npy -> user file" normals.npy "$V/notes.txt" any "${EST[@]}"
links "link: normals.exr -> user file" normals.exr "$V/notes.txt" any "${EST[@]}"
links "link: report.json -> user file" report.json "$V/notes.txt" err "${EST[@]}"
links "link: .symframe-staging-1-abc -> user folder" .symframe-staging-1-0000000000000001 "$V/folder" any "${EST[@]}"
links "link: staging folder in a real folder" .symframe-staging-2-abc/.ready "$V/notes.txt" any "${EST[@]}"
links "link: .symframe-lock -> user file (fit)" .symframe-lock "$V/notes.txt" err \
    fit "$IN/data" --frames "$IN/est" -o OUT --quiet
links "link: kd.npy -> user file (fit)" kd.npy "$V/notes.txt" any \
    fit "$IN/data" --frames "$IN/est" -o OUT --quiet
links "link: .symframe-lock -> user file (relight)" .symframe-lock "$V/notes.txt" err \
    relight "$IN/fit" --light 0,0,1 -o OUT --quiet
links "link: relit_000.png -> user file (relight)" relit_000.png "$V/notes.txt" any \
    relight "$IN/fit" --light 0,0,1 -o OUT --quiet
links "link: .symframe-lock -> user file (merge)" .symframe-lock "$V/notes.txt" err \
    merge "$IN/shard1" "$IN/shard2" -o OUT --quiet
links "link: .symframe-lock -> user file (synth)" .symframe-lock "$V/notes.txt" err \
    synth -o OUT --size 16 --rig cone:12 --model lambertian --quiet
links "link: depth.npy -> user file (integrate)" depth.npy "$V/notes.txt" any \
    integrate "$IN/est" -o OUT --quiet
links "link: .symframe-tiles -> user folder (merge)" .symframe-tiles "$V/folder" any \
    merge "$IN/shard1" "$IN/shard2" -o OUT --quiet
# The cache file's own name: learnt from a first run, then planted as a link.
o=$(fresh cachelink)
run estimate "$IN/data" -o "$o/first" --method woodham --quiet
CACHE_NAME=$(cd "$o/first/.symframe-cache" && ls ./*.stack | head -n 1)
mkdir -p "$o/out/.symframe-cache"
cp "$V/notes.txt" "$V/cache-victim"
ln -s "$V/cache-victim" "$o/out/.symframe-cache/$CACHE_NAME"
ALLOW=("$o")
PROTECT=("$o/first")
case_ "link: cache file -> user file" any estimate "$IN/data" -o "$o/out" --method woodham --quiet
done_with cachelink

# === 4. planted staging plans, foreign lock holders, user folders named like the tool's ===========

plan() { # plan DIR TOKEN FILES_JSON REMOVE_JSON: a switch plan with a made-up checksum
    mkdir -p "$1"
    printf '{"files": %s, "remove": %s, "token": "%s", "checksum": "0123456789abcdef"}' \
        "$3" "$4" "$2" >"$1/.ready"
}
o=$(fresh plans)
ALLOW=("$o")
mkdir -p "$o/a"
plan "$o/a/.symframe-staging-4242-00000000000000aa" 00000000000000aa \
    "[\"../../../home/.bashrc\", \"normals.npy\"]" "[\"$V/notes.txt\", \"../../../home/folder/file.txt\"]"
echo "staged" >"$o/a/.symframe-staging-4242-00000000000000aa/normals.npy"
PROTECT=("$o/a/.symframe-staging-4242-00000000000000aa")
case_ "plan: absolute and .. names, no lock" ok:"left alone" "${EST[@]/OUT/$o/a}"
# A foreign lock holder (a dead process) whose token names the planted staging folder.
mkdir -p "$o/b"
echo "999999 00000000000000bb" >"$o/b/.symframe-lock"
plan "$o/b/.symframe-staging-999999-00000000000000bb" 00000000000000bb \
    "[\"../../../home/.bashrc\"]" "[\"$V/notes.txt\"]"
PROTECT=("$o/b/.symframe-staging-999999-00000000000000bb")
case_ "plan: foreign lock holder's token, bad names" any "${EST[@]/OUT/$o/b}"
mkdir -p "$o/c"
echo "999999 00000000000000cc" >"$o/c/.symframe-lock"
plan "$o/c/.symframe-staging-999999-00000000000000cc" 00000000000000cc "[\"normals.npy\"]" "[\"report.json\"]"
echo "forged" >"$o/c/.symframe-staging-999999-00000000000000cc/normals.npy"
echo '{"user": true}' >"$o/c/notes.json"
PROTECT=("$o/c/.symframe-staging-999999-00000000000000cc" "$o/c/notes.json")
case_ "plan: plain names, foreign token, bad checksum" ok:"left alone" "${EST[@]/OUT/$o/c}"
mkdir -p "$o/d"
printf '%s' "$(head -c 100000 /dev/zero | tr '\0' 'x')" >"$o/d/.symframe-lock"
case_ "plan: a lock file of 100 KB of junk" any "${EST[@]/OUT/$o/d}"
mkdir -p "$o/e/.symframe-staging-notes" "$o/e/.symframe-staging-" "$o/e/.symframe-staging-1-2-3"
echo "my notes" >"$o/e/.symframe-staging-notes/todo.txt"
echo "x" >"$o/e/.symframe-staging-/a" && echo "y" >"$o/e/.symframe-staging-1-2-3/.ready"
PROTECT=("$o/e/.symframe-staging-notes" "$o/e/.symframe-staging-" "$o/e/.symframe-staging-1-2-3")
case_ "user folders named .symframe-staging-*" ok "${EST[@]/OUT/$o/e}"
mkdir -p "$o/f/.symframe-staging-7-0000000000000007"
plan "$o/f/.symframe-staging-7-0000000000000007" 0000000000000007 '"not a list"' '{}'
mkfifo "$o/f/.symframe-staging-7-0000000000000007/normals.npy"
PROTECT=("$o/f/.symframe-staging-7-0000000000000007")
case_ "plan: malformed, a FIFO staged" any "${EST[@]/OUT/$o/f}"
for cmd in fit relight merge synth; do
    mkdir -p "$o/$cmd"
    plan "$o/$cmd/.symframe-staging-5-0000000000000005" 0000000000000005 \
        "[\"../../../home/.bashrc\"]" "[\"$V/notes.txt\"]"
    PROTECT=("$o/$cmd/.symframe-staging-5-0000000000000005")
    case $cmd in
    fit) args=(fit "$IN/data" --frames "$IN/est" -o "$o/$cmd" --quiet) ;;
    relight) args=(relight "$IN/fit" --light 0,0,1 -o "$o/$cmd" --quiet) ;;
    merge) args=(merge "$IN/shard1" "$IN/shard2" -o "$o/$cmd" --quiet) ;;
    synth) args=(synth -o "$o/$cmd" --size 16 --rig cone:12 --model lambertian --quiet) ;;
    esac
    case_ "plan: planted in a $cmd folder" any "${args[@]}"
done
done_with plans

# === 5. outputs that would replace inputs ========================================================

o=$(fresh replace)
ALLOW=("$o")
# estimate into its own input folder, an image named like an output.
cp -r "$IN/data" "$o/own"
mapfile -t PROTECT < <(printf '%s\n' "$o/own/images" "$o/own/lights.lp" "$o/own/mask.png" "$o/own/gt_normals.npy")
case_ "estimate into its own input folder" ok estimate "$o/own" -o "$o/own" --method woodham --quiet
cp -r "$IN/data" "$o/named"
mv "$o/named/images/$IMG0" "$o/named/normals.exr"
sed -i "s#images/$IMG0#normals.exr#" "$o/named/lights.lp"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/named"))
case_ "estimate: an input image named normals.exr" err:"is an input of this run" \
    estimate "$o/named" -o "$o/named" --method woodham --quiet
cp -r "$IN/data" "$o/named-png"
mv "$o/named-png/images/$IMG0" "$o/named-png/images/normals.exr"
sed -i "s#images/$IMG0#images/normals.exr#" "$o/named-png/lights.lp"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/named-png"))
case_ "estimate -o the images' folder, an image named normals.exr" err \
    estimate "$o/named-png/lights.lp" -o "$o/named-png/images" --method woodham --quiet
mkdir -p "$o/m" && cp "$IN/data/mask.png" "$o/m/source.png"
mapfile -t PROTECT < <(printf '%s\n' "$o/m/source.png")
case_ "estimate --mask at an output's name in OUT" err \
    estimate "$IN/data" -o "$o/m" --mask "$o/m/source.png" --method woodham --quiet
# demo over a user's folder.
mkdir -p "$o/demo/dataset" && echo "my lights" >"$o/demo/dataset/lights.lp"
mapfile -t PROTECT < <(printf '%s\n' "$o/demo/dataset")
case_ "demo -o over a user's folder" err demo -o "$o/demo" --size 16 --lights 40 --quiet
mkdir -p "$o/demo2/estimate" && echo "mine" >"$o/demo2/estimate/normals.npy"
mapfile -t PROTECT < <(printf '%s\n' "$o/demo2/estimate")
case_ "demo -o over a user's estimate folder" err demo -o "$o/demo2" --size 16 --lights 40 --quiet
# view over fit maps and over a user's page.
cp -r "$IN/fit" "$o/fit"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit"))
case_ "view -o the fit's kd.npy" err view "$o/fit" -o "$o/fit/kd.npy" --quiet
case_ "view -o the fit's fit.json" err view "$o/fit" -o "$o/fit/fit.json" --quiet
echo "<html>mine</html>" >"$o/page.html"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit") "$o/page.html")
case_ "view -o a user's HTML page" err view "$o/fit" -o "$o/page.html" --quiet
# export over another file.
cp "$V/scene.gltf" "$o/scene.gltf"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit") "$o/scene.gltf")
case_ "export -o a user's .gltf" err export gltf "$o/fit" -o "$o/scene.gltf" --quiet
cp "$V/notes.txt" "$o/asset.bin"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit") "$o/asset.bin")
case_ "export -o beside a user's .bin" err export gltf "$o/fit" -o "$o/asset.gltf" --quiet
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit"))
case_ "export -o a fit map" err export gltf "$o/fit" -o "$o/fit/kd.npy" --quiet
case_ "export -o into the fit folder" any export gltf "$o/fit" -o "$o/fit/asset.glb" --quiet
# fit, relight, integrate, calibrate, synth, merge over their inputs.
cp -r "$IN/est" "$o/frames"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/frames"))
case_ "fit -o its frames folder" err fit "$IN/data" --frames "$o/frames" -o "$o/frames" --quiet
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/fit"))
case_ "relight -o its fit folder" any relight "$o/fit" --light 0,0,1 -o "$o/fit" --quiet
cp -r "$IN/est" "$o/est-depth"
echo "mine" >"$o/est-depth/depth.npy"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/est-depth"))
case_ "integrate -o an estimate with a user's depth.npy" err integrate "$o/est-depth" -o "$o/est-depth" --quiet
cp -r "$IN/shard1" "$o/shard1"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/shard1"))
case_ "merge -o one of its shards" any merge "$o/shard1" "$IN/shard2" -o "$o/shard1" --quiet
cp -r "$IN/chrome" "$o/chrome"
mapfile -t PROTECT < <(printf '%s\n' $(existing "$o/chrome"))
case_ "calibrate -o its own .lp" err calibrate "$o/chrome/lights.lp" -o "$o/chrome/lights.lp" --quiet
case_ "calibrate -o an image of its input" err \
    calibrate "$o/chrome" -o "$o/chrome/images/$(ls "$o/chrome/images" | head -n 1)" --quiet
cp "$IN/data/lights.lp" "$o/rig.lp"
mkdir -p "$o/rigdir" && cp "$IN/data/lights.lp" "$o/rigdir/lights.lp"
mapfile -t PROTECT < <(printf '%s\n' "$o/rig.lp" "$o/rigdir")
case_ "synth into the folder of its rig's .lp" err \
    synth -o "$o/rigdir" --rig "lp:$o/rigdir/lights.lp" --size 16 --model lambertian --quiet
case_ "synth -o a user's folder" err synth -o "$T/home/folder" --size 16 --rig cone:12 --quiet
done_with replace

# === 6. forged manifests =========================================================================

o=$(fresh manifests)
ALLOW=("$o")
PROTECT=()
forge_shard() { # forge_shard DIR PYTHON_EXPR_ON_m: a copy of shard1 with its shard.json changed
    rm -rf "$1"
    cp -r "$IN/shard1" "$1"
    python3 - "$1/shard.json" "$2" <<'EOF'
import json, sys
p, expr = sys.argv[1], sys.argv[2]
m = json.load(open(p))
def find(o, key):
    if isinstance(o, dict):
        if key in o: return o
        for v in o.values():
            r = find(v, key)
            if r is not None: return r
    return None
exec(expr)
json.dump(m, open(p, "w"))
EOF
}
forge_shard "$o/s-huge" "g=find(m,'width') or m; g['width']=65536; g['height']=2048; (find(m,'tile_size') or m)['tile_size']=1"
case_ "shard.json: 65536 x 2048, tiles of 1" err merge "$o/s-huge" "$IN/shard2" -o "$o/m1" --quiet
forge_shard "$o/s-zero" "(find(m,'of') or m)['of']=0"
case_ "shard.json: of 0" err merge "$o/s-zero" "$IN/shard2" -o "$o/m2" --quiet
forge_shard "$o/s-neg" "(find(m,'tile_size') or m)['tile_size']=-5"
case_ "shard.json: negative tile size" err merge "$o/s-neg" "$IN/shard2" -o "$o/m3" --quiet
forge_shard "$o/s-big" "(find(m,'width') or m)['width']=2**64+7"
case_ "shard.json: width 2^64 + 7" err merge "$o/s-big" "$IN/shard2" -o "$o/m4" --quiet
forge_shard "$o/s-tiles" "(find(m,'tiles') or m)['tiles']=list(range(10**6))"
case_ "shard.json: a million tiles listed" err merge "$o/s-tiles" "$IN/shard2" -o "$o/m5" --quiet
rm -rf "$o/s-deep" && cp -r "$IN/shard1" "$o/s-deep"
python3 -c "print('['*100000 + ']'*100000)" >"$o/s-deep/shard.json"
case_ "shard.json: nested 100,000 deep" err merge "$o/s-deep" "$IN/shard2" -o "$o/m6" --quiet
rm -rf "$o/s-sparse" && cp -r "$IN/shard1" "$o/s-sparse"
truncate -s 2G "$o/s-sparse/shard.json"
case_ "shard.json: sparse 2 GB" err merge "$o/s-sparse" "$IN/shard2" -o "$o/m7" --quiet
rm -rf "$o/s-sparse"
rm -rf "$o/s-tile" && cp -r "$IN/shard1" "$o/s-tile"
for f in "$o/s-tile"/.symframe-tiles/tile-*.bin; do truncate -s 1G "$f"; break; done
case_ "shard: a tile result file of 1 GB" err merge "$o/s-tile" "$IN/shard2" -o "$o/m8" --quiet
rm -rf "$o/s-tile"
case_ "merge: a shard twice" err merge "$IN/shard1" "$IN/shard1" -o "$o/m9" --quiet
# fit.json for relight, view, export.
forge_fit() { # forge_fit DIR PYTHON_EXPR_ON_m
    rm -rf "$1"
    cp -r "$IN/fit" "$1"
    python3 - "$1/fit.json" "$2" <<'EOF'
import json, sys
p, expr = sys.argv[1], sys.argv[2]
m = json.load(open(p))
def find(o, key):
    if isinstance(o, dict):
        if key in o: return o
        for v in o.values():
            r = find(v, key)
            if r is not None: return r
    return None
exec(expr)
json.dump(m, open(p, "w"))
EOF
}
forge_fit "$o/f-size" "g=find(m,'width') or m; g['width']=65536; g['height']=65536"
case_ "fit.json: 65536 x 65536 (relight)" any relight "$o/f-size" --light 0,0,1 -o "$o/r1" --quiet
case_ "fit.json: 65536 x 65536 (view)" any view "$o/f-size" -o "$o/v1.html" --quiet
case_ "fit.json: 65536 x 65536 (export)" any export gltf "$o/f-size" -o "$o/e1.glb" --quiet
# (A Ward fit's relight and export read only its maps; a glTF fit's read its exposure.)
forge_fit "$o/f-junk" "m.clear(); m['model']=['ward']*5"
case_ "fit.json: junk (relight, Ward)" any relight "$o/f-junk" --light 0,0,1 -o "$o/r2" --quiet
case_ "fit.json: junk (view, Ward)" any view "$o/f-junk" -o "$o/v2.html" --quiet
rm -rf "$o/g-junk" && cp -r "$IN/gfit" "$o/g-junk"
echo '{"exposure": "bright", "model": 7}' >"$o/g-junk/fit.json"
case_ "fit.json: junk exposure (relight, glTF)" err relight "$o/g-junk" --light 0,0,1 -o "$o/r2g" --quiet
case_ "fit.json: junk exposure (export, glTF)" err export gltf "$o/g-junk" -o "$o/e2g.glb" --quiet
python3 -c "print('{\"exposure\": ' + '['*100000 + ']'*100000 + '}')" >"$o/g-junk/fit.json"
case_ "fit.json: nested 100,000 deep (relight, glTF)" err relight "$o/g-junk" --light 0,0,1 -o "$o/r2h" --quiet
rm -rf "$o/f-npy" && cp -r "$IN/fit" "$o/f-npy"
python3 - "$o/f-npy/kd.npy" <<'EOF'
import sys
h = "{'descr': '<f4', 'fortran_order': False, 'shape': (65536, 65536, 3), }"
h += " " * (118 - len(h)) + "\n"
open(sys.argv[1], "wb").write(b"\x93NUMPY\x01\x00" + len(h).to_bytes(2, "little") + h.encode() + b"\0" * 4096)
EOF
case_ "kd.npy declaring 65536 x 65536 x 3 (relight)" err relight "$o/f-npy" --light 0,0,1 -o "$o/r3" --quiet
case_ "kd.npy declaring 65536 x 65536 x 3 (view)" err view "$o/f-npy" -o "$o/v3.html" --quiet
case_ "kd.npy declaring 65536 x 65536 x 3 (export)" err export gltf "$o/f-npy" -o "$o/e3.glb" --quiet
# report.json of an estimate, for fit, eval, integrate, export.
forge_est() { # forge_est DIR PYTHON_EXPR_ON_m
    rm -rf "$1"
    cp -r "$IN/est" "$1"
    python3 - "$1/report.json" "$2" <<'EOF'
import json, sys
p, expr = sys.argv[1], sys.argv[2]
m = json.load(open(p))
def find(o, key):
    if isinstance(o, dict):
        if key in o: return o
        for v in o.values():
            r = find(v, key)
            if r is not None: return r
    return None
exec(expr)
json.dump(m, open(p, "w"))
EOF
}
forge_est "$o/e-size" "g=find(m,'width') or m; g['width']=65536; g['height']=65536"
case_ "report.json: 65536 x 65536 (fit)" any fit "$IN/data" --frames "$o/e-size" -o "$o/fit1" --quiet
case_ "report.json: 65536 x 65536 (integrate)" any integrate "$o/e-size" -o "$o/d1" --quiet
forge_est "$o/e-junk" "m.clear(); m['inputs']={'fingerprint': 'x'*100000}"
case_ "report.json: junk (fit)" any fit "$IN/data" --frames "$o/e-junk" -o "$o/fit2" --quiet
case_ "report.json: junk (eval)" any eval "$IN/data" "$o/e-junk" --quiet
forge_est "$o/e-npy" "pass"
python3 - "$o/e-npy/normals.npy" <<'EOF'
import sys
h = "{'descr': '<f4', 'fortran_order': False, 'shape': (65536, 65536, 3), }"
h += " " * (118 - len(h)) + "\n"
open(sys.argv[1], "wb").write(b"\x93NUMPY\x01\x00" + len(h).to_bytes(2, "little") + h.encode() + b"\0" * 4096)
EOF
case_ "normals.npy declaring 65536 x 65536 x 3 (integrate)" err integrate "$o/e-npy" -o "$o/d2" --quiet
case_ "normals.npy declaring 65536 x 65536 x 3 (eval)" err eval "$IN/data" "$o/e-npy" --quiet
case_ "normals.npy declaring 65536 x 65536 x 3 (fit)" err fit "$IN/data" --frames "$o/e-npy" -o "$o/fit3" --quiet
done_with manifests

# === 7. devices and FIFOs as every path argument ==================================================

o=$(fresh devices)
ALLOW=("$o")
PROTECT=()
F=$T/home/fifo
mkfifo "$o/lights.lp"
cp -r "$IN/est" "$o/estc"
ln -s /dev/zero "$o/zero.png"
mkfifo "$o/fifo.png"
for dev in /dev/zero "$F"; do
    what=$([[ $dev == /dev/zero ]] && echo /dev/zero || echo FIFO)
    img=$([[ $dev == /dev/zero ]] && echo "$o/zero.png" || echo "$o/fifo.png")
    case_ "$what as estimate's input" err estimate "$dev" -o "$o/a" --quiet
    case_ "$what as --mask (a .png)" err:"not a regular file" \
        estimate "$IN/data" -o "$o/b" --mask "$img" --method woodham --quiet
    case_ "$what as relight --lights" err relight "$IN/fit" --lights "$dev" -o "$o/c" --quiet
    case_ "$what as relight --depth" err \
        relight "$IN/fit" --light 0,0,1 --shadows --depth "$dev" -o "$o/d" --quiet
    case_ "$what as relight --region (a .png)" err:"not a regular file" \
        relight "$IN/fit" --light 0,0,1 --rotate-tangents 30 --region "$img" -o "$o/e" --quiet
    case_ "$what as export --depth" err export gltf "$IN/fit" --mesh --depth "$dev" -o "$o/f.glb" --quiet
    case_ "$what as calibrate's image list" err calibrate "$dev" -o "$o/g/lights.lp" --quiet
    case_ "$what as fit --mask (a .png)" err:"not a regular file" \
        fit "$IN/data" --frames "$IN/est" --mask "$img" -o "$o/h" --quiet
    case_ "$what as synth --rig lp:" err synth -o "$o/i" --rig "lp:$dev" --size 16 --quiet
    case_ "$what as eval's dataset" err eval "$dev" "$o/estc" --quiet
    case_ "$what as view --frames" err view "$IN/fit" --frames "$dev" -o "$o/j.html" --quiet
done
case_ "/dev/null as estimate -o" err estimate "$IN/data" -o /dev/null --method woodham --quiet
case_ "/dev/null as --cache" err estimate "$IN/data" -o "$o/k" --cache /dev/null --method woodham --quiet
case_ "/dev/null as view -o" err view "$IN/fit" -o /dev/null --quiet
case_ "/dev/null as export -o" err export gltf "$IN/fit" -o /dev/null --quiet
case_ "/dev/null as calibrate -o" err calibrate "$IN/chrome" -o /dev/null --quiet
case_ "FIFO as an .lp file" err estimate "$o/lights.lp" -o "$o/l" --quiet
# Files inside the folders a command reads, replaced by devices and FIFOs.
devin() { # devin NAME SRC FILE DEV EXPECT ARGS... (ARGS with DIR for the copy of SRC)
    local name=$1 src=$2 file=$3 dev=$4 expect=$5
    shift 5
    rm -rf "$o/copy"
    cp -r "$src" "$o/copy"
    rm -f "$o/copy/$file"
    if [[ $dev == fifo ]]; then mkfifo "$o/copy/$file"; else ln -s "$dev" "$o/copy/$file"; fi
    local args=() a
    for a in "$@"; do args+=("${a//DIR/$o/copy}"); done
    case_ "$name" "$expect" "${args[@]}"
}
for dev in /dev/zero fifo; do
    devin "$dev as fit.json (relight, glTF)" "$IN/gfit" fit.json "$dev" err relight DIR --light 0,0,1 -o "$o/m" --quiet
    devin "$dev as fit.json (view)" "$IN/fit" fit.json "$dev" err view DIR -o "$o/n.html" --quiet
    devin "$dev as fit.json (export, glTF)" "$IN/gfit" fit.json "$dev" err export gltf DIR -o "$o/p.glb" --quiet
    devin "$dev as kd.npy (relight)" "$IN/fit" kd.npy "$dev" err relight DIR --light 0,0,1 -o "$o/q" --quiet
    devin "$dev as shard.json (merge)" "$IN/shard1" shard.json "$dev" err merge DIR "$IN/shard2" -o "$o/r" --quiet
    devin "$dev as report.json (fit --frames)" "$IN/est" report.json "$dev" any fit "$IN/data" --frames DIR -o "$o/s" --quiet
    devin "$dev as normals.npy (integrate)" "$IN/est" normals.npy "$dev" err integrate DIR -o "$o/t" --quiet
    devin "$dev as normals.npy (eval)" "$IN/est" normals.npy "$dev" err eval "$IN/data" DIR --quiet
    devin "$dev as an image (estimate)" "$IN/data" "images/$IMG0" "$dev" err estimate DIR -o "$o/u" --quiet
    devin "$dev as mask.png (estimate)" "$IN/data" mask.png "$dev" err estimate DIR -o "$o/v" --method woodham --quiet
    devin "$dev as gt_normals.npy (eval)" "$IN/data" gt_normals.npy "$dev" err eval DIR "$o/estc" --quiet
    devin "$dev as scene.json (eval)" "$IN/data" scene.json "$dev" any eval DIR "$o/estc" --quiet
    devin "$dev as light_intensities.txt" "$IN/data" light_intensities.txt "$dev" err estimate DIR -o "$o/w" --method woodham --quiet
    devin "$dev as an image (calibrate)" "$IN/chrome" "images/$(ls "$IN/chrome/images" | head -n 1)" "$dev" err \
        calibrate DIR/lights.lp -o "$o/x/lights.lp" --quiet
done
done_with devices

# === 8. small files declaring huge images, in every format =========================================

o=$(fresh huge)
ALLOW=("$o")
PROTECT=()
for ext in png jpg exr tif hdr pfm; do
    # (A PFM must hold every sample it declares; a truncated JPEG scan may decode as black.)
    expect=stopped
    [[ $ext == pfm ]] && expect=err
    [[ $ext == jpg ]] && expect=stopped-or-err
    case_ "8000 x 8000 $ext stack, --decode-memory 16" "$expect" \
        estimate "$IN/huge/$ext/lights.lp" -o "$o/$ext" --decode-memory 16 --cache-format f16 \
        --stop-after-tiles 1 --method woodham --quiet
    rm -rf "${o:?}/$ext"
    case_ "8000 x 8000 $ext as --mask" err \
        estimate "$IN/data" -o "$o/mask-$ext" --mask "$IN/huge/$ext/0.$ext" --method woodham --quiet
    printf '3\n%s 0 0 1\n%s 0.5 0 0.866\n%s 0 0.5 0.866\n' "$IN/data/images/$IMG0" \
        "$IN/huge/$ext/0.$ext" "$IN/huge/$ext/1.$ext" >"$o/mixed-$ext.lp"
    case_ "8000 x 8000 $ext after a small image" err \
        estimate "$o/mixed-$ext.lp" -o "$o/mixed-$ext" --method woodham --quiet
    case_ "8000 x 8000 $ext to calibrate" err \
        calibrate "$IN/huge/$ext" -o "$o/cal-$ext/lights.lp" --sphere 4000,4000,1000 --quiet
    case_ "8000 x 8000 $ext to calibrate, sphere looked for" err \
        calibrate "$IN/huge/$ext" -o "$o/cal-$ext/lights.lp" --quiet
    rm -rf "${o:?}/cal-$ext" "${o:?}/mask-$ext" "${o:?}/mixed-$ext"
done
case_ "8000 x 8000 PNG mask for 24 x 24 images" err \
    estimate "$IN/data" -o "$o/mask-big" --mask "$IN/huge/mask.png" --method woodham --quiet
case_ "8000 x 8000 relight --region" err \
    relight "$IN/fit" --light 0,0,1 --rotate-tangents 30 --region "$IN/huge/mask.png" -o "$o/region" --quiet
done_with huge

# === 9. huge light files ==========================================================================

o=$(fresh lights)
ALLOW=("$o")
PROTECT=()
python3 - "$o" "$IN/data" <<'EOF'
import os, sys
o, data = sys.argv[1], sys.argv[2]
img = sorted(os.listdir(os.path.join(data, "images")))[0]
with open(os.path.join(o, "many.lp"), "w") as f:
    f.write("150000\n")
    for i in range(150000):
        f.write(f"{data}/images/{img} 0 0 1\n")
with open(os.path.join(o, "declares.lp"), "w") as f:
    f.write("7000000\n" + f"{data}/images/{img} 0 0 1\n" * 3)
with open(os.path.join(o, "relight-many.txt"), "w") as f:
    f.write("0 0 1\n" * 150000)
with open(os.path.join(o, "list.txt"), "w") as f:
    f.write(f"{data}/images/{img}\n" * 150000)
with open(os.path.join(o, "one-line.lp"), "w") as f:
    f.write("3" + "\r" * 10 + "x" * 1000000)
os.makedirs(os.path.join(o, "dili"), exist_ok=True)
with open(os.path.join(o, "dili", "light_directions.txt"), "w") as f:
    f.write("0 0 1\n" * 200000)
with open(os.path.join(o, "dili", "filenames.txt"), "w") as f:
    f.write(f"{data}/images/{img}\n" * 3)
EOF
truncate -s 100M "$o/sparse.lp"
case_ ".lp of 150,000 lights" err:"100000" estimate "$o/many.lp" -o "$o/a" --quiet
case_ ".lp declaring 7,000,000 lights" err estimate "$o/declares.lp" -o "$o/b" --quiet
case_ ".lp of a 1 MB line, CR line ends" err estimate "$o/one-line.lp" -o "$o/c" --quiet
case_ ".lp of 100 MB (sparse)" err:"larger than" estimate "$o/sparse.lp" -o "$o/d" --quiet
case_ "light_directions.txt of 200,000 rows" err estimate "$o/dili" -o "$o/e" --quiet
case_ "relight --lights of 150,000 lights" err relight "$IN/fit" --lights "$o/relight-many.txt" -o "$o/f" --quiet
case_ "relight --lights of 100 MB (sparse)" err relight "$IN/fit" --lights "$o/sparse.lp" -o "$o/g" --quiet
case_ "calibrate: an image list of 150,000 lines" err:"100000" calibrate "$o/list.txt" -o "$o/h/l.lp" --quiet
case_ "synth --rig lp: of 150,000 lights" err synth -o "$o/i" --rig "lp:$o/many.lp" --size 16 --quiet
done_with lights

# === 10. calibrate's circles =====================================================================

o=$(fresh circles)
ALLOW=("$o")
PROTECT=()
for s in 8,8,1e12 8,8,1e300 8,8,0 8,8,-5 8,8,nan 8,8,inf -1e9,8,4 8,1e9,4 1,1,1000 0,0,1 "8,8" "a,b,c"; do
    case_ "calibrate --sphere $s" err calibrate "$IN/chrome/lights.lp" -o "$o/c/lights.lp" --sphere "$s" --quiet
done
if [[ -n $SPHERE ]]; then
    for s in 8,8,1e12 8,8,-1; do
        case_ "calibrate --matte-sphere $s" err \
            calibrate "$IN/chrome/lights.lp" -o "$o/m/lights.lp" --sphere "$SPHERE" --matte-sphere "$s" --quiet
    done
fi
done_with circles

# === summary =====================================================================================

echo
if ((FAILS)); then
    echo "hostile-sweep: $FAILS of $N cases FAILED:"
    printf '  %s\n' "${FAILED[@]}"
    exit 1
fi
echo "hostile-sweep: all $N cases passed"
