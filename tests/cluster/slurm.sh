#!/usr/bin/env bash
# The cluster test (issue 26): a real one-node SLURM on this host runs the README's job array
# (scripts/cluster/fdimc-array.sbatch) on the CI deck in 4 tasks with `--shard auto`; one task is
# requeued mid-run (scontrol requeue) and resumes; the merged records and summaries must equal a
# one-machine run of the same deck and seed; merge must refuse a missing or a doubled shard. Installs
# slurmctld, slurmd and munge (Debian packages) when missing; stops every daemon it started, by pid.
# `.ci/run` runs it after the tests. Usage: bash tests/cluster/slurm.sh   (KEEP=1 keeps the work folder)
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
# Where cargo builds (CARGO_TARGET_DIR, else ./target): the binaries are looked for where they were built.
TARGET=$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
FDIMC="${FDIMC:-$TARGET/release/fdimc}"
SAME="$TARGET/release/examples/same_records"
DECK=studies/ci_seed000.toml
TRIALS=32768      # 4 shards of 8192 trials: two part files each, so a task can be stopped between them
TIMEOUT_S=300

fail() { echo "FAIL: $*" >&2; exit 1; }
# Built (or found up to date) every time, so a stale binary is never what is tested.
cargo build --release --locked --bin fdimc --example same_records

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v sbatch >/dev/null \
    || ! command -v munged >/dev/null; then
    [ "$(id -u)" = 0 ] || fail "SLURM and munge are not installed, and installing them needs root"
    echo "== installing slurmctld slurmd slurm-client munge (apt-get)"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurmctld slurmd slurm-client munge >/dev/null
fi

W=$(mktemp -d /tmp/fdimc-slurm.XXXXXX)
export SLURM_CONF=$W/slurm.conf
STARTED=()   # pids of the daemons this script started
cleanup() {
    for pid in "${STARTED[@]}"; do kill "$pid" 2>/dev/null || true; done
    for _ in $(seq 50); do
        alive=0
        for pid in "${STARTED[@]}"; do kill -0 "$pid" 2>/dev/null && alive=1; done
        [ $alive = 0 ] && break
        sleep 0.2
    done
    for pid in "${STARTED[@]}"; do kill -9 "$pid" 2>/dev/null || true; done
    if [ "${KEEP:-0}" = 1 ]; then echo "kept $W"; else rm -rf "$W"; fi
}
trap cleanup EXIT

# munge: the key the package made, the daemon as its own user (unless one already answers).
if ! munge -n >/dev/null 2>&1; then
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge
    [ -s /etc/munge/munge.key ] || { mungekey --create --keyfile=/etc/munge/munge.key; chown munge:munge /etc/munge/munge.key; }
    rm -f /run/munge/munged.pid
    runuser -u munge -- /usr/sbin/munged
    for _ in $(seq 50); do [ -s /run/munge/munged.pid ] && break; sleep 0.1; done
    [ -s /run/munge/munged.pid ] || fail "munged did not start"
    STARTED+=("$(cat /run/munge/munged.pid)")
fi

HOST=$(hostname -s)
CPUS=$(nproc)
mkdir -p "$W/state" "$W/spool"
cat > "$SLURM_CONF" <<CONF
ClusterName=fdimc-ci
SlurmctldHost=$HOST
SlurmctldPort=6917
SlurmdPort=6918
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$W/state
SlurmdSpoolDir=$W/spool
SlurmctldPidFile=$W/slurmctld.pid
SlurmdPidFile=$W/slurmd.pid
SlurmctldLogFile=$W/slurmctld.log
SlurmdLogFile=$W/slurmd.log
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
NodeName=$HOST CPUs=$CPUS State=UNKNOWN
PartitionName=ci Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
/usr/sbin/slurmctld -f "$SLURM_CONF"
/usr/sbin/slurmd -f "$SLURM_CONF"
for f in slurmctld slurmd; do
    for _ in $(seq 50); do [ -s "$W/$f.pid" ] && break; sleep 0.1; done
    [ -s "$W/$f.pid" ] || fail "$f did not start: $(tail -5 "$W/$f.log" 2>/dev/null)"
    STARTED+=("$(cat "$W/$f.pid")")
done
for _ in $(seq 100); do sinfo -h -o %T 2>/dev/null | grep -q idle && break; sleep 0.2; done
sinfo -h -o %T | grep -q idle || fail "the node is not idle: $(sinfo 2>&1)"
echo "$(date +%T) == SLURM up on $HOST ($CPUS CPUs): daemons ${STARTED[*]}"

# The reference: one machine, the same deck, seed and trial count.
"$FDIMC" run "$DECK" --trials $TRIALS --out "$W/single" --quiet

# The README's job array, 4 tasks of one CPU each; each task's log appended across a requeue.
JOB=$(DECK=$DECK OUT=$W/array FDIMC=$FDIMC FDIMC_ARGS="--trials $TRIALS" \
    sbatch --parsable --array=0-3 --cpus-per-task=1 --chdir="$ROOT" --open-mode=append \
    --output="$W/task-%a.log" scripts/cluster/fdimc-array.sbatch)
echo "$(date +%T) == submitted job array $JOB"

# Requeue task 1 once its first part file is written (mid-run: its second is not).
deadline=$((SECONDS + TIMEOUT_S))
parts="$W/array/shard-1-of-4/parts"
until compgen -G "$parts/part-*.parquet" >/dev/null; do
    [ $SECONDS -lt $deadline ] || fail "task 1 wrote no part file within ${TIMEOUT_S} s: $(cat "$W"/task-1.log 2>/dev/null)"
    sleep 0.05
done
scontrol requeue "${JOB}_1"
# SLURM makes a requeued job wait two minutes before it is eligible again (once its old copy is gone,
# its reason is BeginTime); a test need not wait.
for _ in $(seq 100); do
    [ "$(squeue -h -j "${JOB}_1" -o %r 2>/dev/null)" = BeginTime ] && { scontrol update JobId="${JOB}_1" StartTime=now; break; }
    sleep 0.2
done
echo "$(date +%T) == requeued task ${JOB}_1 after its first part file"

while [ -n "$(squeue -h -j "$JOB" 2>/dev/null)" ]; do
    [ $SECONDS -lt $deadline ] || { squeue; fail "the array did not finish within ${TIMEOUT_S} s"; }
    sleep 0.5
done
for i in 0 1 2 3; do
    m="$W/array/shard-$i-of-4/manifest.json"
    grep -q '"complete": true' "$m" 2>/dev/null || fail "task $i did not complete: $(cat "$W/task-$i.log")"
done
grep -Eq "\(([0-9]+) run, [1-9][0-9]* resumed\)" "$W/task-1.log" \
    || fail "the requeued task did not resume its parts: $(cat "$W/task-1.log")"
echo "$(date +%T) == all 4 tasks complete; the requeued one resumed: $(grep -Eo '\([0-9]+ run, [0-9]+ resumed\)' "$W/task-1.log" | tail -1)"

"$FDIMC" merge "$W"/array/shard-*-of-4 --out "$W/merged" >/dev/null
"$SAME" "$W/single/trials.parquet" "$W/merged/trials.parquet" || fail "merged records differ from one machine's"
for f in "$W"/single/*.csv; do
    cmp -s "$f" "$W/merged/$(basename "$f")" || fail "$(basename "$f") differs between one machine and the merged array"
done
echo "$(date +%T) == merged records and summaries identical to the one-machine run"

# merge refuses a missing shard and a doubled one, and writes nothing.
for shards in "0 1 2" "0 1 1 2 3"; do
    dirs=()
    for i in $shards; do dirs+=("$W/array/shard-$i-of-4"); done
    if "$FDIMC" merge "${dirs[@]}" --out "$W/bad" 2>"$W/merge.err"; then fail "merge took shards $shards"; fi
    grep -q "need shards 0..4 exactly once each" "$W/merge.err" || fail "merge of $shards: $(cat "$W/merge.err")"
    [ ! -e "$W/bad" ] || fail "a refused merge wrote $W/bad"
done
echo "$(date +%T) == merge refuses a missing or doubled shard"
echo "PASS: the SLURM cluster test"
