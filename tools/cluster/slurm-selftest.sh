#!/usr/bin/env bash
# A real test of `voxcone batch --slurm` against a real Slurm: a one-node cluster on this machine
# (munged, slurmctld and slurmd started here with a private configuration, ports and state, so a
# Slurm already installed is left alone), an 8-job manifest submitted as an array of 4 tasks, one
# task cancelled while it renders and requeued, then --status and --merge: every job's image must
# be valid and the merged table must hold every row. Stops the daemons it started; exits non-zero
# on any loss, 77 (skipped) only where the machine cannot run Slurm at all.
#
#   bash tools/cluster/slurm-selftest.sh [VOXCONE_EXECUTABLE]
#
# Needs slurm-wlm and munge (installed with apt-get when missing and run as root). Checked with
# Debian 12's slurm-wlm 22.05 and munge, as root, without systemd or cgroups
# (proctrack/linuxproc, task/none, select/cons_tres).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VOXCONE="${1:-$ROOT/build/voxcone}"
[ -x "$VOXCONE" ] || { echo "slurm-selftest: no voxcone executable at $VOXCONE (build first)" >&2; exit 1; }
VOXCONE="$(cd "$(dirname "$VOXCONE")" && pwd)/$(basename "$VOXCONE")"

say() { echo "slurm-selftest: $*"; }
skip() { say "SKIPPED: $*"; exit 77; }
fail() { say "FAILED: $*"; exit 1; }

# --- Slurm and munge -----------------------------------------------------------------------
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
    say "installing slurm-wlm and munge"
    { DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge ||
      { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurm-wlm munge; }; } \
      >/tmp/slurm-selftest-apt.log 2>&1 || skip "apt-get install slurm-wlm munge failed (see /tmp/slurm-selftest-apt.log)"
  else
    skip "slurm-wlm and munge are not installed and cannot be installed here (not root, or no apt-get)"
  fi
fi
# slurmd runs jobs as their user and slurmctld must own its state: a one-node test cluster
# needs root (SlurmUser=root) here.
[ "$(id -u)" -eq 0 ] || skip "the one-node test cluster runs its daemons as root"

WORK="$(mktemp -d /tmp/voxcone-slurm-selftest.XXXXXX)"
chmod 755 "$WORK"
HOST="$(hostname -s)"
# Ports of our own, away from Slurm's defaults (6817/6818), so a real installation is untouched.
CTLD_PORT=$((17000 + RANDOM % 2000))
SLURMD_PORT=$((CTLD_PORT + 1))
MUNGE_SOCKET="$WORK/munge/munge.socket"
PIDS=()

cleanup() {
  set +e
  if [ -n "${SLURM_CONF:-}" ] && [ -f "$SLURM_CONF" ]; then scancel --quiet --user=root >/dev/null 2>&1; fi
  for pidfile in "$WORK/slurmd.pid" "$WORK/slurmctld.pid" "$WORK/munge/munged.pid"; do
    [ -f "$pidfile" ] && kill "$(cat "$pidfile")" 2>/dev/null
  done
  sleep 1
  for pidfile in "$WORK/slurmd.pid" "$WORK/slurmctld.pid" "$WORK/munge/munged.pid"; do
    [ -f "$pidfile" ] && kill -9 "$(cat "$pidfile")" 2>/dev/null
  done
  if [ "${KEEP:-0}" = 1 ]; then say "kept $WORK"; else rm -rf "$WORK"; fi
}
trap cleanup EXIT

# --- munged, with its own key and socket -----------------------------------------------------
mkdir -p "$WORK/munge"
chmod 700 "$WORK/munge"
dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$WORK/munge/munge.key"
munged --force --key-file="$WORK/munge/munge.key" --socket="$MUNGE_SOCKET" \
  --pid-file="$WORK/munge/munged.pid" --log-file="$WORK/munge/munged.log" \
  --seed-file="$WORK/munge/munged.seed" ||
  skip "munged does not start here (see $WORK/munge/munged.log)"
for _ in $(seq 50); do [ -S "$MUNGE_SOCKET" ] && break; sleep 0.1; done
[ -S "$MUNGE_SOCKET" ] || skip "munged gave no socket"
chmod 755 "$WORK/munge"

# --- a one-node cluster ----------------------------------------------------------------------
CPUS="$(nproc)"
MEM_MB=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 / 2 ))
mkdir -p "$WORK/state" "$WORK/spool"
export SLURM_CONF="$WORK/slurm.conf"
cat >"$SLURM_CONF" <<EOF
ClusterName=voxcone-selftest
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
# A requeued job waits cred_expire seconds before it may start again (default 120).
AuthInfo=socket=$MUNGE_SOCKET,cred_expire=10
CredType=cred/munge
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/slurmctld.pid
SlurmdPidFile=$WORK/slurmd.pid
SlurmctldLogFile=$WORK/slurmctld.log
SlurmdLogFile=$WORK/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
ReturnToService=2
KillWait=5
MinJobAge=2
SlurmctldTimeout=30
SlurmdTimeout=30
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=selftest Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -c -f "$SLURM_CONF" || skip "slurmctld does not start here (see $WORK/slurmctld.log)"
slurmd -f "$SLURM_CONF" || skip "slurmd does not start here (see $WORK/slurmd.log)"
say "cluster up: $HOST, $CPUS CPUs, ports $CTLD_PORT/$SLURMD_PORT, work $WORK"
STATE=""
for _ in $(seq 120); do
  STATE="$(sinfo -h -n "$HOST" -o %t 2>/dev/null | head -1 || true)"
  [ "$STATE" = idle ] && break
  sleep 0.5
done
[ "$STATE" = idle ] || { tail -5 "$WORK/slurmctld.log" "$WORK/slurmd.log" >&2 || true; skip "the node never became idle (state '$STATE')"; }

# --- the manifest: 8 tiny jobs, one long enough to be cancelled while it renders ---------------
OUT="$WORK/out"
MANIFEST="$WORK/manifest.json"
cat >"$MANIFEST" <<EOF
{"defaults": {"scene": "$ROOT/data/scenes/cornell-box.json", "res": "16x16", "method": "path", "seed": 3},
 "jobs": [{"name": "long", "spp": 15000}],
 "grid": {"spp": [1, 2, 3, 4, 5, 6, 7]}}
EOF
START=$(date +%s.%N)
SUBMIT="$("$VOXCONE" batch "$MANIFEST" -o "$OUT" --slurm --shards 4 -t 1)"
echo "$SUBMIT"
JOB="$(echo "$SUBMIT" | sed -n 's/^submitted job array \([0-9]*\):.*/\1/p')"
[ -n "$JOB" ] || fail "no job id in: $SUBMIT"

# Task 0 holds the long job (jobs 0 and 4 of 8 with 4 shards): cancel it while its render runs.
for _ in $(seq 600); do
  pgrep -f -- "--spp 15000" >/dev/null && break
  sleep 0.1
done
pgrep -f -- "--spp 15000" >/dev/null || fail "the long render never started"
sleep 1
say "cancelling task ${JOB}_0 while it renders"
scancel "${JOB}_0"
for _ in $(seq 100); do
  S="$(squeue -h -j "${JOB}_0" -o %T 2>/dev/null || true)"
  [ -z "$S" ] && break
  sleep 0.2
done
say "requeueing task ${JOB}_0"
if ! scontrol requeue "${JOB}_0" 2>"$WORK/requeue.err"; then
  # A cancelled task that Slurm will not requeue is resubmitted by hand with the same script.
  say "scontrol requeue refused ($(cat "$WORK/requeue.err")); resubmitting task 0 with sbatch --array=0"
  sbatch --parsable --array=0 "$OUT/slurm/manifest.sbatch" >/dev/null
fi
if "$VOXCONE" batch "$MANIFEST" -o "$OUT" --status >"$WORK/status-mid.txt"; then
  fail "--status called the batch complete while task 0 was still to run: $(cat "$WORK/status-mid.txt")"
fi

# Wait for the array (the requeued task included) to leave the queue.
for _ in $(seq 1200); do
  [ -z "$(squeue -h -o %i 2>/dev/null)" ] && break
  sleep 0.5
done
[ -z "$(squeue -h -o %i 2>/dev/null)" ] || fail "the array is still queued after 10 minutes: $(squeue)"
WALL=$(awk "BEGIN {print $(date +%s.%N) - $START}")

"$VOXCONE" batch "$MANIFEST" -o "$OUT" --status || fail "jobs missing after the requeue"
"$VOXCONE" batch "$MANIFEST" -o "$OUT" --merge || fail "--merge found jobs missing or failed"
ROWS="$(python3 -c "import json; print(len(json.load(open('$OUT/results.json'))['rows']))")"
[ "$ROWS" = 8 ] || fail "the merged table has $ROWS rows, not 8"
OKS="$(python3 -c "import json; print(sum(r['status'] == 'ok' for r in json.load(open('$OUT/results.json'))['rows']))")"
[ "$OKS" = 8 ] || fail "$OKS of 8 rows ok in the merged table"
for exr in "$OUT"/*.exr; do
  "$VOXCONE" compare "$exr" "$exr" >/dev/null || fail "$exr does not open as an image"
done
N_EXR="$(ls "$OUT"/*.exr | wc -l)"
[ "$N_EXR" = 8 ] || fail "$N_EXR images, not 8"
grep -q "stopped by\|interrupted\|CANCELLED" "$OUT"/slurm/*_0.log 2>/dev/null || say "note: task 0's log does not mention the cancel"
say "fault test passed: 8 jobs as 4 array tasks, task 0 cancelled while rendering and requeued, 8 of 8 images valid, merged table of 8 rows, ${WALL} s"

# --- a study on the cluster gives the study run here, row for row --------------------------------
# voxcone's levels x photons (5 x 4) at 16x16 against a 16x16 path reference: the CSV of
# `study levels --slurm` must equal the local one in every column but the times, the memory
# and the Pareto flags (which follow the times).
SCENE="$ROOT/data/scenes/cornell-box.json"
"$VOXCONE" render "$SCENE" --method path --spp 256 --res 16x16 -t 2 -q -o "$WORK/ref" >/dev/null
START=$(date +%s.%N)
"$VOXCONE" study levels "$SCENE" --reference "$WORK/ref.exr" --photons 2000,5000,10000,20000 -t 1 --no-chart \
  -o "$WORK/study-local" >"$WORK/study-local.txt" 2>&1 || fail "the local study failed: $(tail -3 "$WORK/study-local.txt")"
LOCAL_S=$(awk "BEGIN {print $(date +%s.%N) - $START}")
START=$(date +%s.%N)
"$VOXCONE" study levels "$SCENE" --reference "$WORK/ref.exr" --photons 2000,5000,10000,20000 -t 1 --no-chart \
  --slurm -o "$WORK/study-slurm" >"$WORK/study-slurm.txt" 2>&1 || fail "the Slurm study failed: $(tail -3 "$WORK/study-slurm.txt")"
SLURM_S=$(awk "BEGIN {print $(date +%s.%N) - $START}")
python3 - "$WORK/study-local/levels.csv" "$WORK/study-slurm/levels.csv" <<'PY' || fail "the Slurm study's CSV differs from the local one"
import csv, sys
rows = [list(csv.DictReader(open(p))) for p in sys.argv[1:]]
varying = {"seconds", "peak_rss_mb", "pareto"}
if len(rows[0]) != 20 or len(rows[1]) != 20:
    sys.exit(f"expected 20 rows each, got {len(rows[0])} and {len(rows[1])}")
for a, b in zip(*rows):
    for k in a:
        if k not in varying and a[k] != b[k]:
            sys.exit(f"{a['name']}: {k} {a[k]} here, {b[k]} on Slurm")
print(f"slurm-selftest: study levels x photons: 20 rows equal in {len(rows[0][0]) - len(varying)} columns")
PY
say "PASSED: the fault test (${WALL} s) and a 5 x 4 levels x photons study equal row for row (local ${LOCAL_S} s, Slurm ${SLURM_S} s)"
