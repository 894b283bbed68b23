#!/usr/bin/env bash
# Issue 20: grotto's cluster steps on a real scheduler. Installs Debian's slurm-wlm and munge
# where missing, starts a one-node Slurm cluster on this machine (munged, slurmctld and slurmd on
# localhost, with a minimal slurm.conf in a temp dir; run as root), and submits what
# docs/manifest.md "Cluster builds" shows: `plan`, a job array of `build-tile` shards that starts
# after it (afterok), and `assemble` after the array, each step with its own --threads and
# --memory-budget. Then compares the package with one `grotto-pack build` of the same scans, byte
# for byte, and stops the daemons. Prints the jobs, their states and the comparison.
# GROTTO_PACK: the grotto-pack binary to use (default: a release build made here).
# GROTTO_SLURM_OPTIONAL=1 (the test script sets it): where a scheduler cannot start on the machine
# (no root, no packages, the daemons refuse), say so and exit 0; a job that fails or a package
# that differs fails either way.
# Usage: scripts/test-slurm.sh [POINTS] [SHARDS]   (default: 200000, 4)
set -euo pipefail
cd "$(dirname "$0")/.."
points=${1:-200000}
shards=${2:-4}
cannot() {
    if [ "${GROTTO_SLURM_OPTIONAL:-0}" = 1 ]; then
        echo "SKIPPED the Slurm test: $1" >&2
        exit 0
    fi
    echo "$1" >&2
    exit 2
}
[ "$(id -u)" -eq 0 ] || cannot "it must run as root (it installs packages and starts slurmctld and slurmd)"
missing=()
for p in slurm-wlm munge; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null; } || cannot "installing ${missing[*]} failed"
fi
if [ -n "${GROTTO_PACK:-}" ]; then
    pack=$(realpath "$GROTTO_PACK")
else
    cargo build --release --locked -p grotto-preprocess
    pack=$(pwd)/target/release/grotto-pack
fi
work=$(mktemp -d /tmp/grotto-slurm.XXXXXX)
chmod 755 "$work"
echo "work: $work"

# munge: a key, then the daemon (its own socket and pid in the temp dir).
if [ ! -s /etc/munge/munge.key ]; then
    mkdir -p /etc/munge
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    chown munge:munge /etc/munge/munge.key
    chmod 400 /etc/munge/munge.key
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown munge:munge /run/munge /var/log/munge /var/lib/munge
started_munge=0
if ! pgrep -x munged >/dev/null; then
    runuser -u munge -- /usr/sbin/munged --force || cannot "munged did not start"
    started_munge=1
fi

mkdir -p "$work/state" "$work/spool" "$work/jobs"
cat > "$work/slurm.conf" <<CONF
ClusterName=grotto-test
SlurmctldHost=localhost
SlurmUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
MinJobAge=3600
NodeName=localhost CPUs=$(nproc) State=UNKNOWN
PartitionName=main Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$work/slurm.conf
stop() {
    local d pid
    for d in slurmd slurmctld; do
        [ -f "$work/$d.pid" ] || continue
        pid=$(cat "$work/$d.pid")
        kill "$pid" 2>/dev/null || continue
        # slurmctld saves its state as it shuts down: wait (up to 10 s) before the directory goes.
        for _ in $(seq 100); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
    done
    [ "$started_munge" = 1 ] && pkill -x munged 2>/dev/null || true
}
trap stop EXIT
/usr/sbin/slurmctld -f "$SLURM_CONF" || cannot "slurmctld did not start: $(tail -3 "$work/slurmctld.log" 2>/dev/null)"
/usr/sbin/slurmd -f "$SLURM_CONF" || cannot "slurmd did not start: $(tail -3 "$work/slurmd.log" 2>/dev/null)"
up=0
for _ in $(seq 60); do
    if sinfo -h -o %T 2>/dev/null | grep -Eq "idle|mixed"; then up=1; break; fi
    sleep 1
done
[ "$up" = 1 ] || cannot "the node did not come up in 60 s: $(tail -3 "$work/slurmctld.log" 2>/dev/null)"
sinfo

"$pack" synth --out "$work/scans" --points "$points" --formats las --segments 8 >/dev/null
manifest=$work/scans/manifest.toml
opts=(--leaf-m 0.125 --min-tile-m 2 --max-tile-m 4)
"$pack" build "$manifest" -o "$work/one.grotto" --work-dir "$work/one.work" --threads 2 "${opts[@]}" >/dev/null

# The job scripts as docs/manifest.md shows them: a different --threads and budget per step.
cat > "$work/jobs/plan.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-plan --cpus-per-task=1 --output=$work/jobs/plan-%j.out
exec "$pack" plan "$manifest" --work-dir "$work/cluster.work" --threads 1 --memory-budget 256M ${opts[*]}
JOB
cat > "$work/jobs/tiles.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-tiles --cpus-per-task=1 --output=$work/jobs/tiles-%A_%a.out
exec "$pack" build-tile "$manifest" --work-dir "$work/cluster.work" --shard "\$SLURM_ARRAY_TASK_ID/\$SLURM_ARRAY_TASK_COUNT" \\
    --threads "\$SLURM_CPUS_PER_TASK" --memory-budget 512M ${opts[*]}
JOB
cat > "$work/jobs/assemble.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-assemble --cpus-per-task=2 --output=$work/jobs/assemble-%j.out
exec "$pack" assemble "$manifest" --work-dir "$work/cluster.work" -o "$work/cluster.grotto" --threads 2 ${opts[*]}
JOB
plan=$(sbatch --parsable "$work/jobs/plan.sh")
tiles=$(sbatch --parsable --array=0-$((shards - 1)) --dependency=afterok:"$plan" "$work/jobs/tiles.sh")
assemble=$(sbatch --parsable --dependency=afterok:"$tiles" "$work/jobs/assemble.sh")
echo "submitted: plan $plan, build-tile array $tiles (0-$((shards - 1))), assemble $assemble"
for _ in $(seq 1800); do
    [ -z "$(squeue -h -o %i)" ] && break
    sleep 1
done
[ -z "$(squeue -h -o %i)" ] || { squeue; echo "jobs still queued after 30 minutes" >&2; exit 1; }
for j in "$plan" "$tiles" "$assemble"; do
    scontrol -o show job "$j" | grep -oE "^JobId=[0-9]+( ArrayJobId=[0-9]+ ArrayTaskId=[0-9]+)?|JobName=[^ ]+|JobState=[A-Z]+|ExitCode=[0-9:]+|Dependency=[^ ]+|NumCPUs=[0-9]+" | \
        paste -sd' ' | sed 's/ JobId=/\nJobId=/g'
done
cat "$work"/jobs/*.out | grep -Ev "^\s*$" | sed 's/^/  /'
for j in "$plan" "$tiles" "$assemble"; do
    if scontrol -o show job "$j" | grep -v "JobState=COMPLETED" | grep -q .; then
        echo "job $j did not complete" >&2
        exit 1
    fi
done
if cmp "$work/one.grotto" "$work/cluster.grotto"; then
    echo "the Slurm build is byte for byte the one-process build ($(stat -c %s "$work/one.grotto") bytes)"
    stop
    trap - EXIT
    rm -rf "$work" || echo "warning: could not remove $work" >&2
else
    echo "the Slurm build differs from the one-process build" >&2
    exit 1
fi
