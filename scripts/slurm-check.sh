#!/usr/bin/env bash
# A real Slurm run of the README's sharded recipe on this one machine (not part of `cargo test`):
# installs Slurm and munge from the Debian packages when missing, starts munged, slurmctld and
# slurmd with a one-node configuration in a temporary folder, renders a small dataset with
# `symframe synth`, submits scripts/slurm/estimate-shards.sbatch as a 4-task array and
# scripts/slurm/merge.sbatch with `--dependency=afterok`, and checks that the merged maps equal
# a single-machine `symframe estimate` byte for byte. Stops the daemons on exit.
#
# Needs root (daemons run as root, `SlurmUser=root`) and no systemd. Environment:
#   SYMFRAME_BIN     the symframe binary (default: build target/release/symframe)
#   SLURM_CHECK_DIR  working folder (default: a new /tmp/symframe-slurm.XXXXXX, kept)
#   SIZE, LIGHTS     the synthetic dataset (default 128 pixels, 400 lights)
#   SHARDS           array tasks (default 4)
#   CTLD_PORT, SLURMD_PORT  the daemons' ports (default 6817, 6818)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK=${SLURM_CHECK_DIR:-$(mktemp -d /tmp/symframe-slurm.XXXXXX)}
SIZE=${SIZE:-128}
LIGHTS=${LIGHTS:-400}
SHARDS=${SHARDS:-4}
CTLD_PORT=${CTLD_PORT:-6817}
SLURMD_PORT=${SLURMD_PORT:-6818}
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
say() { echo "slurm-check: $*"; }
now() { date +%s.%N; }
since() { echo "$(now) - $1" | bc | xargs printf '%.1f'; }

if [ "$(id -u)" != 0 ]; then
    say "needs root (the daemons run as root)"
    exit 1
fi

# 1. Slurm and munge from the Debian packages.
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null; then
    say "installing slurm-wlm and munge"
    apt-get update -q
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge bc
fi
command -v bc >/dev/null || DEBIAN_FRONTEND=noninteractive apt-get install -y -q bc
say "$(slurmctld -V), $(munged -V 2>&1 | head -n 1)"

# 2. The symframe binary (release).
if [ -z "${SYMFRAME_BIN:-}" ]; then
    t=$(now)
    (cd "$ROOT" && nice -n 10 cargo build --release --locked -p symframe-cli)
    SYMFRAME_BIN=$ROOT/target/release/symframe
    say "release build: $(since "$t") s"
fi
mkdir -p "$WORK/bin"
ln -sf "$(cd "$(dirname "$SYMFRAME_BIN")" && pwd)/$(basename "$SYMFRAME_BIN")" "$WORK/bin/symframe"
export PATH=$WORK/bin:$PATH

# 3. munge and a one-node Slurm configuration, everything under $WORK.
ETC=$WORK/etc
mkdir -p "$ETC" "$WORK/munge" "$WORK/state" "$WORK/spool" "$WORK/log" "$WORK/run"
chmod 700 "$WORK/munge"
if [ ! -f "$WORK/munge/munge.key" ]; then
    dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1024 count=1 status=none
fi
chmod 400 "$WORK/munge/munge.key"
MUNGE_SOCKET=$WORK/munge/munge.socket
NODE=$(hostname -s)
# The node's real CPUs and memory, as slurmd sees them (a larger figure drains the node).
NODE_HW=$(slurmd -C | head -n 1 | sed -e 's/^NodeName=[^ ]* //')
cat >"$ETC/slurm.conf" <<EOF
ClusterName=symframe-check
SlurmctldHost=$NODE
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCKET
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/run/slurmctld.pid
SlurmdPidFile=$WORK/run/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
NodeName=$NODE $NODE_HW State=UNKNOWN
PartitionName=check Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$ETC/slurm.conf

stop_daemons() {
    local f pid i
    for f in "$WORK/run/slurmd.pid" "$WORK/run/slurmctld.pid" "$WORK/run/munged.pid"; do
        [ -s "$f" ] || continue
        pid=$(cat "$f")
        kill "$pid" 2>/dev/null || continue
        for i in $(seq 1 100); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
    done
    say "daemons stopped; logs in $WORK/log"
}
trap stop_daemons EXIT

say "starting munged, slurmctld, slurmd (configuration $SLURM_CONF)"
munged --force --socket="$MUNGE_SOCKET" --key-file="$WORK/munge/munge.key" \
    --pid-file="$WORK/run/munged.pid" --log-file="$WORK/log/munged.log" \
    --seed-file="$WORK/munge/munged.seed"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"

t=$(now)
until sinfo -h -N -o '%T' 2>/dev/null | grep -qx idle; do
    if [ "$(echo "$(now) - $t > 60" | bc)" = 1 ]; then
        say "the node did not become idle within 60 s:"
        sinfo -N -l || true
        tail -n 20 "$WORK/log/slurmctld.log" "$WORK/log/slurmd.log" || true
        exit 1
    fi
    sleep 1
done
say "node idle after $(since "$t") s: $(sinfo -h -N -o '%N %c CPUs %m MB %T')"

# 4. A small dataset and the single-machine reference.
cd "$WORK"
rm -rf data single shard_* result cache slurm-*.out
t=$(now)
symframe --quiet synth -o data --size "$SIZE" --rig "cone:$LIGHTS"
say "synth (${SIZE}x${SIZE}, $LIGHTS lights): $(since "$t") s"
t=$(now)
symframe --quiet estimate data/lights.lp -o single
SINGLE_S=$(since "$t")
say "single-machine estimate: $SINGLE_S s"

# Waits until jobs $1 (an array) and $2 (its merge) have left the queue; fails when the merge
# can never run (a shard failed).
wait_jobs() {
    local t0
    t0=$(now)
    while [ -n "$(squeue -h -j "$1,$2" -o %i 2>/dev/null)" ]; do
        if [ "$(squeue -h -j "$2" -o %r 2>/dev/null)" = DependencyNeverSatisfied ]; then
            say "FAIL: a shard failed, the merge job will never run"
            cat slurm-*.out || true
            scancel "$2" || true
            exit 1
        fi
        if [ "$(echo "$(now) - $t0 > 1800" | bc)" = 1 ]; then
            say "FAIL: jobs still queued after 30 min"
            squeue
            exit 1
        fi
        sleep 1
    done
}

# Compares every map and picture of result/ with single/, byte for byte.
same_as_single() {
    local f status=0
    for f in normals.npy tangents.npy confidence.npy anisotropy.npy source.npy \
        normals.exr tangents.exr normals.png tangents.png confidence.png source.png; do
        if cmp -s "single/$f" "result/$f"; then
            say "identical: $f ($(stat -c %s "result/$f") bytes)"
        else
            say "FAIL: result/$f differs from single/$f"
            status=1
        fi
    done
    return "$status"
}

# 5. The README's recipe (section "Shards"): its two sbatch commands, with this check's capture
# and cache, and the resources a small machine grants (options override the #SBATCH lines).
SYMFRAME_SRC=$ROOT
t=$(now)
jobid=$(sbatch --parsable --array=1-"$SHARDS" --cpus-per-task=1 --mem=2G \
    --export=ALL,INPUT=data/lights.lp,CACHE="$WORK/cache" \
    "$SYMFRAME_SRC/scripts/slurm/estimate-shards.sbatch")
sbatch --parsable --dependency=afterok:"$jobid" "$SYMFRAME_SRC/scripts/slurm/merge.sbatch" >merge.id
say "submitted array job $jobid ($SHARDS tasks, 1 CPU each, $(nproc) CPUs on the node)" \
    "and merge job $(cat merge.id)"
wait_jobs "$jobid" "$(cat merge.id)"
SLURM_S=$(since "$t")
say "array and merge jobs done: $SLURM_S s from submission"
for f in slurm-*.out; do
    echo "--- $f"
    grep -v -E '^(decoding|tiles|merging) [0-9]+/[0-9]+' "$f" || true
done
for k in $(seq 1 "$SHARDS"); do
    if [ ! -f "shard_$k/shard.json" ]; then
        say "FAIL: shard_$k did not finish"
        exit 1
    fi
    say "shard $k/$SHARDS: $(python3 -c '
import json, sys
r = json.load(open(sys.argv[1]))["report"]
t, c = r["timings"], r["cache"]
print("load %.2f s (cache hit %s, %d images decoded), estimation %.2f s, total %.2f s"
      % (t["load_s"], c["hit"], c["images_decoded"], t["estimate_s"], t["total_s"]))
' "shard_$k/shard.json" 2>/dev/null || echo "finished (python3 shows the timings)")"
done
if [ ! -f result/report.json ]; then
    say "FAIL: the merge job wrote no result/report.json"
    exit 1
fi

# 6. Byte identity of every map and picture.
same_as_single || exit 1
say "PASS: $SHARDS Slurm shards merged equal the single-machine run byte for byte" \
    "(single ${SINGLE_S} s, Slurm ${SLURM_S} s from submission to merged)"

# 7. A shard preempted after some of its tiles: its manifest and last tile gone, the index
# resubmitted alone (SHARDS keeps the array's size), merged again.
rm -f shard_3/shard.json
rm -f "$(ls shard_3/.symframe-tiles/tile-*.bin | tail -n 1)"
t=$(now)
jobid=$(sbatch --parsable --array=3 --cpus-per-task=1 --mem=2G \
    --export=ALL,INPUT=data/lights.lp,CACHE="$WORK/cache",SHARDS="$SHARDS" \
    "$SYMFRAME_SRC/scripts/slurm/estimate-shards.sbatch")
sbatch --parsable --dependency=afterok:"$jobid" "$SYMFRAME_SRC/scripts/slurm/merge.sbatch" >merge.id
wait_jobs "$jobid" "$(cat merge.id)"
say "shard 3 resubmitted and merged again: $(since "$t") s; $(grep -o '"computed": [0-9]*' \
    shard_3/shard.json | head -n 1), $(grep -o '"reused": [0-9]*' shard_3/shard.json | head -n 1)"
same_as_single || exit 1
say "PASS: after resubmitting shard 3 alone, the merged maps still equal the single run"
