#!/usr/bin/env bash
# grotto's cluster steps on a real scheduler, across several nodes, one of them
# lost mid-build. Run as root; installs Debian's slurm-wlm and munge where missing.
#
# The cluster, made here and removed after: one `slurmctld` and NODES `slurmd`s, each node in its
# own network namespace (a veth pair on a private bridge, its own address), UTS namespace (its own
# hostname, node1..N) and mount namespace (its own /tmp and /etc/hosts), munge shared. The work
# directory is shared the way clusters share it: over NFS from the controller's side where the
# kernel has an NFS client and server, else bind-mounted into every node; the script says which.
# Submitted as docs/manifest.md "Cluster builds" shows: `plan`, a `build-tile` job array after it
# (afterok, --requeue), `assemble` after the array. The node-loss case: once a node's build-tile job
# has a tile package's temp file open, that node loses power (SIGKILL to its slurmd, job steps and
# jobs; its link goes down); Slurm marks it down and requeues its tasks on the others. The package
# must be byte for byte one `grotto-pack build` of the same scans, and the jobs' logs must show at
# least two hostnames building tiles. Prints the jobs, where they ran, the requeue, the figures
# (wall times, what went through the shared directory) and the comparison.
#
# Where namespaces or the bridge cannot be made, says why and runs the one-node cluster instead
# (slurmctld and slurmd on localhost), without the node-loss case.
# GROTTO_PACK: the grotto-pack binary (default: a release build made here).
# GROTTO_SLURM_OPTIONAL=1 (scripts/test.sh sets it): where no scheduler can start at all (no root,
# no packages, the daemons refuse), say so and exit 0; a failed job or a package that differs
# fails either way.
# GROTTO_SLURM_KILL=0: no node-loss case (for timing runs).
# Usage: scripts/test-slurm.sh [POINTS] [SHARDS] [NODES]   (default: 200000, 6, 3)
set -euo pipefail
cd "$(dirname "$0")/.."
points=${1:-200000}
shards=${2:-6}
nodes=${3:-3}
kill_case=${GROTTO_SLURM_KILL:-1}
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
# Not under /tmp: every node mounts a /tmp of its own.
work=$(mktemp -d /var/tmp/grotto-slurm.XXXXXX)
chmod 755 "$work"
shared=$work/shared
mkdir -p "$shared/jobs" "$work/state" "$work/spool" "$work/run" "$work/log"
echo "work: $work"
tag=$(basename "$work" | tail -c 7)
net=10.213.$((RANDOM % 200 + 20))
br=gb-$tag
ns_of() { echo "grotto-$tag-n$1"; }

# munge: a key, then the daemon (its socket is a file, so every namespace reaches it).
if [ ! -s /etc/munge/munge.key ]; then
    mkdir -p /etc/munge
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    chown munge:munge /etc/munge/munge.key
    chmod 400 /etc/munge/munge.key
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge
chown munge:munge /run/munge /var/log/munge /var/lib/munge
started_munge=0
# A munged that is going away (a run just before this one stopped it) is waited for, not trusted.
for _ in $(seq 50); do
    pgrep -x munged >/dev/null && [ ! -S /run/munge/munge.socket.2 ] || break
    sleep 0.1
done
if ! pgrep -x munged >/dev/null; then
    runuser -u munge -- /usr/sbin/munged --force || cannot "munged did not start"
    started_munge=1
fi

mode=one
made_bridge=0
made_ns=()
nfs_server=0
# The nodes' namespaces, their links, the bridge and the NFS export.
teardown_net() {
    local i pid
    for i in "${made_ns[@]}"; do
        for pid in $(ip netns pids "$(ns_of "$i")" 2>/dev/null); do kill -9 "$pid" 2>/dev/null || true; done
        # Deleting the namespace deletes its end of the veth pair, and so the pair.
        ip netns del "$(ns_of "$i")" 2>/dev/null || true
        ip link del "gv-$tag-$i" 2>/dev/null || true
    done
    made_ns=()
    if [ "$nfs_server" = 1 ]; then
        exportfs -u "$net.0/24:$shared" 2>/dev/null || true
        rpc.nfsd 0 2>/dev/null || true
        nfs_server=0
    fi
    [ "$made_bridge" = 0 ] || ip link del "$br" 2>/dev/null || true
    made_bridge=0
    return 0
}
# Stops the daemons (each waited for: slurmctld saves its state as it shuts down), and whatever
# did not write its pid file (a daemon that never came up).
stop_daemons() {
    local d pid
    for d in "$work"/run/slurmd-*.pid "$work/slurmctld.pid"; do
        [ -f "$d" ] || continue
        pid=$(cat "$d")
        kill "$pid" 2>/dev/null || continue
        for _ in $(seq 100); do
            kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
    done
    pkill -f -- "-f $work/slurm.conf" 2>/dev/null || true
}
stop() {
    set +e
    stop_daemons
    teardown_net
    if [ "$started_munge" = 1 ]; then
        pkill -x munged 2>/dev/null
        for _ in $(seq 50); do
            pgrep -x munged >/dev/null || break
            sleep 0.1
        done
    fi
    return 0
}
trap stop EXIT

# The network: a bridge with the controller's address, then one namespace per node. Any step that
# fails leaves $why and the one-node cluster runs instead.
why=""
make_network() {
    ip link add "$br" type bridge 2>/dev/null || { why="cannot make a bridge (ip link add type bridge)"; return 1; }
    made_bridge=1
    ip addr add "$net.1/24" dev "$br" && ip link set "$br" up || { why="cannot address the bridge"; return 1; }
    printf '127.0.0.1 localhost\n%s.1 grotto-ctl\n' "$net" > "$work/hosts"
    local i
    for i in $(seq "$nodes"); do
        echo "$net.$((10 + i)) node$i" >> "$work/hosts"
    done
    for i in $(seq "$nodes"); do
        local ns
        ns=$(ns_of "$i")
        ip netns add "$ns" 2>/dev/null || { why="cannot make a network namespace (ip netns add)"; return 1; }
        made_ns+=("$i")
        ip link add "gv-$tag-$i" type veth peer name eth0 netns "$ns" &&
            ip link set "gv-$tag-$i" master "$br" up &&
            ip -n "$ns" addr add "$net.$((10 + i))/24" dev eth0 &&
            ip -n "$ns" link set eth0 up && ip -n "$ns" link set lo up ||
            { why="cannot wire node$i's veth pair to the bridge"; return 1; }
        mkdir -p "$work/node$i/tmp"
    done
}

# The shared directory over NFS where this kernel serves and mounts it (nfsd and nfs), exported
# from the controller's address; each node mounts it in its own namespace. Else a bind mount.
nfs_why=""
try_nfs() {
    grep -qw nfs /proc/filesystems && grep -qw nfsd /proc/filesystems ||
        { nfs_why="this kernel has no NFS client or server (nfs, nfsd not in /proc/filesystems)"; return 1; }
    if ! dpkg-query -W -f='${Status}' nfs-kernel-server 2>/dev/null | grep -q "install ok installed"; then
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends nfs-kernel-server \
            >/dev/null 2>&1 || { nfs_why="installing nfs-kernel-server failed"; return 1; }
    fi
    mountpoint -q /proc/fs/nfsd || mount -t nfsd nfsd /proc/fs/nfsd 2>/dev/null
    pgrep -x rpcbind >/dev/null || rpcbind 2>/dev/null
    exportfs -o rw,sync,no_root_squash,no_subtree_check "$net.0/24:$shared" 2>/dev/null &&
        rpc.nfsd 4 2>/dev/null && { pgrep -x rpc.mountd >/dev/null || rpc.mountd 2>/dev/null; } ||
        { nfs_why="the NFS server did not start (exportfs, rpc.nfsd, rpc.mountd)"; return 1; }
    nfs_server=1
    mkdir -p "$work/probe"
    nsenter --net="/run/netns/$(ns_of 1)" unshare --mount --propagation private \
        sh -c "mount -t nfs -o vers=4.2,hard $net.1:$shared $work/probe && test -d $work/probe/jobs" 2>/dev/null ||
        { nfs_why="a node could not mount the export"; return 1; }
}

# Starts node i's slurmd in its namespaces: hostname node<i>, its own /tmp and /etc/hosts, the
# shared directory mounted at the same path the controller's side uses.
start_node() {
    local i=$1 mount_shared
    if [ "$share_kind" = nfs ]; then
        mount_shared="mount -t nfs -o vers=4.2,hard $net.1:$shared $shared"
    else
        mount_shared="mount --bind $shared $shared"
    fi
    # nsenter, not `ip netns exec`: that mounts a /sys of its own, without the cgroup tree slurmd
    # reads.
    nsenter --net="/run/netns/$(ns_of "$i")" unshare --uts --mount --propagation private sh -ec "
        hostname node$i
        mount --bind $work/hosts /etc/hosts
        mount --bind $work/node$i/tmp /tmp
        $mount_shared
        exec /usr/sbin/slurmd -f $work/slurm.conf"
}

# slurm.conf for the mode, then the daemons; fails with $why where the cluster does not come up.
start_cluster() {
    cat > "$work/slurm.conf" <<CONF
ClusterName=grotto-test
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
SlurmdSpoolDir=$work/spool/%n
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/run/slurmd-%n.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd-%n.log
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
MinJobAge=3600
# A lost node is noticed within 10 s (pings every third of it) and its jobs requeued.
SlurmdTimeout=10
CONF
    local i
    if [ "$mode" = multi ]; then
        {
            echo "SlurmctldHost=grotto-ctl($net.1)"
            for i in $(seq "$nodes"); do
                echo "NodeName=node$i NodeAddr=$net.$((10 + i)) CPUs=$(nproc) State=UNKNOWN"
            done
            echo "PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP"
        } >> "$work/slurm.conf"
        unshare --uts --mount --propagation private sh -ec "
            hostname grotto-ctl
            mount --bind $work/hosts /etc/hosts
            exec /usr/sbin/slurmctld -f $work/slurm.conf" ||
            { why="slurmctld did not start: $(tail -3 "$work/log/slurmctld.log" 2>/dev/null)"; return 1; }
        for i in $(seq "$nodes"); do
            start_node "$i" ||
                { why="node$i's slurmd did not start: $(tail -3 "$work/log/slurmd-node$i.log" 2>/dev/null)"; return 1; }
        done
    else
        {
            echo "SlurmctldHost=localhost"
            echo "NodeName=localhost CPUs=$(nproc) State=UNKNOWN"
            echo "PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP"
        } >> "$work/slurm.conf"
        /usr/sbin/slurmctld -f "$work/slurm.conf" ||
            { why="slurmctld did not start: $(tail -3 "$work/log/slurmctld.log" 2>/dev/null)"; return 1; }
        /usr/sbin/slurmd -f "$work/slurm.conf" ||
            { why="slurmd did not start: $(tail -3 "$work/log/slurmd-localhost.log" 2>/dev/null)"; return 1; }
    fi
    for _ in $(seq 60); do
        [ "$(sinfo -h -N -o '%T' 2>/dev/null | grep -Ec 'idle|mixed')" -eq "$nodes" ] && return 0
        sleep 1
    done
    why="the nodes did not come up in 60 s: $(sinfo -h -N -o '%N %T' 2>&1 | paste -sd,) $(tail -2 "$work/log/slurmctld.log" 2>/dev/null)"
    return 1
}

export SLURM_CONF=$work/slurm.conf
share_kind=bind
if make_network; then
    mode=multi
    if try_nfs; then
        share_kind=nfs
        share="NFS 4.2, exported from the controller's address and mounted by each node"
    else
        share="a bind mount into each node's mount namespace, not NFS: $nfs_why"
    fi
    if ! start_cluster; then
        echo "the multi-node cluster did not start: $why" >&2
        stop_daemons
        rm -rf "$work"/state/* "$work"/run/*
        mode=one
    fi
else
    echo "cannot make the nodes' network: $why" >&2
fi
if [ "$mode" = one ]; then
    echo "running the one-node cluster instead (no node-loss case)" >&2
    teardown_net
    nodes=1
    share="the controller's own disk (one node)"
    start_cluster || cannot "$why"
fi
echo "cluster: $nodes node(s), the work directory shared over $share"
sinfo -N -o "%N %T %c %o"

"$pack" synth --out "$shared/scans" --points "$points" --formats las --segments 8 >/dev/null
manifest=$shared/scans/manifest.toml
opts=(--leaf-m 0.125 --min-tile-m 2 --max-tile-m 4)
one_start=$(date +%s.%N)
"$pack" build "$manifest" -o "$work/one.grotto" --work-dir "$work/one.work" --threads 2 "${opts[@]}" >/dev/null
one_s=$(echo "$(date +%s.%N) $one_start" | awk '{printf "%.1f", $1 - $2}')

# The node-loss case needs a job caught with a tile's temp file open, and a tile is written in
# about 20 ms: a first run holds its first tile open 3 s (grotto-pack's test hook), a requeued one
# does not.
hold=""
if [ "$kill_case" = 1 ]; then
    hold='[ "${SLURM_RESTART_COUNT:-0}" -gt 0 ] || export GROTTO_PACK_HOLD_TILE_MS=3000'
fi
# The job scripts as docs/manifest.md shows them: a different --threads and budget per step. The
# array's log is appended to, so a requeued task's log keeps the run its node died in.
jobs=$shared/jobs
cat > "$jobs/plan.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-plan --cpus-per-task=1 --output=$jobs/plan-%j.out
exec "$pack" plan "$manifest" --work-dir "$shared/cluster.work" --threads 1 --memory-budget 256M ${opts[*]}
JOB
cat > "$jobs/tiles.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-tiles --cpus-per-task=1 --requeue --open-mode=append --output=$jobs/tiles-%A_%a.out
echo "task \$SLURM_ARRAY_TASK_ID starts on \$(hostname) (restart \${SLURM_RESTART_COUNT:-0})"
$hold
exec "$pack" build-tile "$manifest" --work-dir "$shared/cluster.work" --shard "\$SLURM_ARRAY_TASK_ID/\$SLURM_ARRAY_TASK_COUNT" \\
    --threads "\$SLURM_CPUS_PER_TASK" --memory-budget 512M ${opts[*]}
JOB
cat > "$jobs/assemble.sh" <<JOB
#!/bin/sh
#SBATCH --job-name=grotto-assemble --cpus-per-task=2 --output=$jobs/assemble-%j.out
exec "$pack" assemble "$manifest" --work-dir "$shared/cluster.work" -o "$shared/cluster.grotto" --threads 2 ${opts[*]}
JOB
submitted_at=$(date +%s.%N)
plan=$(sbatch --parsable "$jobs/plan.sh")
tiles=$(sbatch --parsable --array=0-$((shards - 1)) --dependency=afterok:"$plan" "$jobs/tiles.sh")
assemble=$(sbatch --parsable --dependency=afterok:"$tiles" "$jobs/assemble.sh")
echo "submitted: plan $plan, build-tile array $tiles (0-$((shards - 1))), assemble $assemble"

# The node-loss case: the first node seen with a tile package's temp file open in a build-tile
# job loses power: every process in its namespace (slurmd, slurmstepd, the job) gets SIGKILL
# and its link goes down. What it was writing stays half-written in the shared directory.
lost=""
partial=""
if [ "$mode" = multi ] && [ "$kill_case" = 1 ] && [ "$nodes" -ge 2 ]; then
    for round in $(seq 30000); do
        for i in $(seq "$nodes"); do
            for pid in $(ip netns pids "$(ns_of "$i")" 2>/dev/null); do
                { tr '\0' ' ' < "/proc/$pid/cmdline"; } 2>/dev/null | grep -q " build-tile " || continue
                partial=$(ls -l "/proc/$pid/fd" 2>/dev/null | grep -o '[^/]*\.partial' | head -1 || true)
                [ -n "$partial" ] || continue
                # Stopped first, so the power goes while the file is still open under its temp
                # name (not just renamed into place): checked again once it cannot move on.
                kill -STOP "$pid" 2>/dev/null || continue
                if ! ls -l "/proc/$pid/fd" 2>/dev/null | grep -q "/$partial\$"; then
                    kill -CONT "$pid" 2>/dev/null || true
                    continue
                fi
                kill -9 $(ip netns pids "$(ns_of "$i")") 2>/dev/null || true
                ip link set "gv-$tag-$i" down
                lost=$i
                break 3
            done
        done
        # The array done with nothing caught writing (asked once a second, not to load slurmctld).
        if [ $((round % 50)) = 0 ] && [ -z "$(squeue -h -j "$plan,$tiles" -o %i 2>/dev/null)" ]; then
            break
        fi
        sleep 0.02
    done
    [ -n "$lost" ] || { echo "no build-tile job was caught writing a tile: the node-loss case did not run" >&2; exit 1; }
    echo "node$lost lost (SIGKILL to its slurmd and jobs, link down) while it wrote $partial"
fi

for _ in $(seq 18000); do
    [ -z "$(squeue -h -o %i)" ] && break
    # A job that can never run (its dependency failed) would wait forever.
    if squeue -h -o %r | grep -q DependencyNeverSatisfied; then break; fi
    sleep 0.1
done
all_s=$(echo "$(date +%s.%N) $submitted_at" | awk '{printf "%.1f", $1 - $2}')
if [ -n "$(squeue -h -o %i)" ]; then
    squeue
    echo "jobs still queued: $(squeue -h -o '%i %r' | paste -sd,)" >&2
    exit 1
fi
for j in "$plan" "$tiles" "$assemble"; do
    scontrol -o show job "$j" | grep -oE "^JobId=[0-9]+( ArrayJobId=[0-9]+ ArrayTaskId=[0-9]+)?|JobName=[^ ]+| JobState=[A-Z_]+| Restarts=[0-9]+| ExitCode=[0-9:]+| NodeList=[^ ]+| NumCPUs=[0-9]+" |
        sed 's/^ //' | paste -sd' ' | sed 's/ JobId=/\nJobId=/g'
done
sinfo -N -o "%N %T %E"
for f in "$jobs"/*.out; do
    echo "  $(basename "$f"):"
    grep -Ev "^\s*$" "$f" | sed 's/^/    /'
done
for j in "$plan" "$tiles" "$assemble"; do
    if scontrol -o show job "$j" | grep -v "JobState=COMPLETED" | grep -q .; then
        echo "job $j did not complete" >&2
        exit 1
    fi
done
hosts=$(cat "$jobs"/tiles-*.out | grep -oE "^shard [0-9]+/[0-9]+ on [^:]+" | awk '{print $4}' | sort -u | paste -sd' ')
echo "tiles built on: $hosts"
if [ "$mode" = multi ] && [ "$nodes" -ge 2 ] && [ "$(echo "$hosts" | wc -w)" -lt 2 ]; then
    echo "fewer than two hosts built tiles on a $nodes-node cluster" >&2
    exit 1
fi
if [ -n "$lost" ]; then
    requeued=$(scontrol -o show job "$tiles" | grep -E "Restarts=[1-9]" | grep -oE "ArrayTaskId=[0-9]+ .*NodeList=[^ ]+" |
        sed -E 's/ArrayTaskId=([0-9]+) .*NodeList=([^ ]+)/task \1 ran again on \2/' | paste -sd', ')
    [ -n "$requeued" ] || { echo "no task of node$lost was requeued" >&2; exit 1; }
    [ -n "$(ls -A "$shared/cluster.work/tiles" | grep -F "$partial")" ] ||
        { echo "the lost node's $partial is not there: it was not lost while writing" >&2; exit 1; }
    echo "requeued after node$lost was lost: $requeued"
    echo "slurmctld on the loss:"
    grep -E "node$lost|[Rr]equeu|NODE_FAIL|(Allocate|Started) JobId=${tiles}_" "$work/log/slurmctld.log" | sed 's/^/  /' 
    left=$(ls -A "$shared/cluster.work/tiles" | grep '\.partial$' | paste -sd' ' || true)
    echo "partial files the lost node left (never taken for tiles): ${left:-none}"
fi

# Figures: wall time per step (Slurm's start and end, 1 s resolution) and what went through the
# shared directory.
span() {
    scontrol -o show job "$1" | grep -oE "(StartTime|EndTime)=[^ ]+" | sed 's/.*=//' |
        while read -r t; do date -d "$t" +%s; done | sort -n | sed -n '1p;$p' | paste -sd' ' |
        awk '{print $2 - $1}'
}
mb() { du -sb "$1" 2>/dev/null | awk '{printf "%.1f", $1 / 1e6}'; }
echo "figures: plan $(span "$plan") s, build-tile array $(span "$tiles") s on $nodes node(s), assemble $(span "$assemble") s; submission to package $all_s s; one grotto-pack build (--threads 2) $one_s s"
echo "shared directory: plan wrote $(mb "$shared/cluster.work/bins") MB of bins, the tile jobs read them and wrote $(mb "$shared/cluster.work/tiles") MB of tile packages, assemble read those and wrote the $(mb "$shared/cluster.grotto") MB package"

if cmp "$work/one.grotto" "$shared/cluster.grotto"; then
    echo "the Slurm build is byte for byte the one-process build ($(stat -c %s "$work/one.grotto") bytes)"
    stop
    trap - EXIT
    rm -rf "$work" || echo "warning: could not remove $work" >&2
else
    echo "the Slurm build differs from the one-process build" >&2
    exit 1
fi
