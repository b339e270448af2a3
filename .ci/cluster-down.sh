#!/usr/bin/env bash
# Stop the namespace cluster of .ci/cluster-up.sh: every job, slurmd, slurmctld and
# munged it runs, every process still inside a node, then the nodes' namespaces
# (their holders), the veths and the switch namespace. Exit 0 when nothing of the
# cluster is left, 1 (said on stderr) if something could not be removed.
#
#   sudo .ci/cluster-down.sh
#
# The nodes are found by their holders' pid files and, so that a cluster whose
# run directory was lost is found too, by their mounts: any process whose
# /etc/slurm is the cluster's. Their processes are found by network namespace,
# never by name, so nothing of the machine's own (e.g. the single-node SLURM of
# .ci/slurm-up.sh) is touched. Logs under $CLUSTER_BASE/log are kept.
set -uo pipefail

BASE=${CLUSTER_BASE:-/var/lib/knitsweep-cluster}
RUN_DIR=/run/knitsweep-cluster
SWITCH=knit-switch
HERE_NET=$(readlink /proc/self/ns/net)
log() { echo "[cluster-down] $*"; }
rc=0

MOUNT_SIGNATURE="^[0-9]+ [0-9]+ [0-9:]+ [^ ]*knitsweep-cluster/etc-slurm /etc/slurm "
# pids of every process in network namespace $1 (as readlink shows it: net:[N])
pids_in() {
    local pattern=${1//[/\\[}
    pattern=${pattern//]/\\]}
    find /proc -mindepth 3 -maxdepth 3 -path '/proc/[0-9]*/ns/net' -lname "$pattern" \
        2>/dev/null | cut -d/ -f3
}

# the nodes' network namespaces: from the holders' pid files, and from the mounts
declare -A nets=()
for f in "$RUN_DIR"/holder-*.pid; do
    [[ -r $f ]] || continue
    pid=$(tr -dc '0-9' <"$f")
    ns=$(readlink "/proc/$pid/ns/net" 2>/dev/null) || continue
    [[ $ns != "$HERE_NET" ]] && nets[$ns]=1
done
for f in $(grep -l -E "$MOUNT_SIGNATURE" /proc/[0-9]*/mountinfo 2>/dev/null); do
    ns=$(readlink "${f%/mountinfo}/ns/net" 2>/dev/null) || continue
    [[ $ns != "$HERE_NET" ]] && nets[$ns]=1
done
log "nodes found: ${#nets[@]}"

all_pids() {
    local ns
    for ns in "${!nets[@]}"; do pids_in "$ns"; done
}
comm_of() { cat "/proc/$1/comm" 2>/dev/null; }

if ((${#nets[@]})); then
    # 1. slurmd and slurmctld first, gently (slurmd ends its jobs' steps)
    for pid in $(all_pids); do
        case $(comm_of "$pid") in slurmd | slurmctld) kill -TERM "$pid" 2>/dev/null ;; esac
    done
    for _ in $(seq 1 40); do
        busy=0
        for pid in $(all_pids); do
            case $(comm_of "$pid") in slurmd | slurmctld) busy=1 ;; esac
        done
        ((busy)) || break
        sleep 0.25
    done
    # 2. then everything left in the nodes: steps, ranks, munged, the holders
    for sig in TERM KILL; do
        for pid in $(all_pids); do kill -"$sig" "$pid" 2>/dev/null; done
        for _ in $(seq 1 40); do
            [[ -z $(all_pids) ]] && break
            sleep 0.25
        done
    done
    left=$(all_pids | tr '\n' ' ')
    if [[ -n $left ]]; then
        log "processes still alive in the nodes: $left" >&2
        rc=1
    else
        log "every process of the nodes stopped; their namespaces are gone with them"
    fi
fi

# 3. the switch (its veth ends go with it; the nodes' ends went with their namespaces)
if ip netns list 2>/dev/null | grep -qw "$SWITCH"; then
    if ip netns delete "$SWITCH"; then log "netns $SWITCH deleted"; else
        log "could not delete netns $SWITCH" >&2
        rc=1
    fi
fi
for v in $(ip -o link show 2>/dev/null | awk -F': ' '{print $2}' | grep -E '^vknit[0-9]+' | cut -d@ -f1); do
    ip link delete "$v" 2>/dev/null && log "deleted stray veth $v"
done
rm -rf "$RUN_DIR"
# nothing may be left that has the cluster's mounts
left=$(grep -l -E "$MOUNT_SIGNATURE" /proc/[0-9]*/mountinfo 2>/dev/null | cut -d/ -f3 | tr '\n' ' ')
if [[ -n $left ]]; then
    log "processes with the cluster's mounts are still alive: $left" >&2
    rc=1
fi
exit "$rc"
