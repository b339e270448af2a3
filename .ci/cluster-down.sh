#!/usr/bin/env bash
# Stop the namespace cluster of .ci/cluster-up.sh: every job, slurmd, slurmctld and
# munged it runs, every process still inside a node, then the nodes' namespaces
# (their holders), the veths and the switch namespace. Best effort; exit 0, or 1
# if something could not be removed (said on stderr).
#
#   sudo .ci/cluster-down.sh
#
# Processes are found by the network namespace they are in (a node's), never by
# name, so nothing of the machine's own (e.g. the single-node SLURM of
# .ci/slurm-up.sh) is touched. Logs under $CLUSTER_BASE/log are kept.
set -uo pipefail

BASE=${CLUSTER_BASE:-/var/lib/knitsweep-cluster}
RUN_DIR=/run/knitsweep-cluster
SWITCH=knit-switch
log() { echo "[cluster-down] $*"; }
rc=0

# every process whose network namespace is that of holder pid $1 (itself included)
in_netns_of() {
    local ns
    ns=$(readlink "/proc/$1/ns/net" 2>/dev/null) || return 0
    find /proc -mindepth 3 -maxdepth 3 -path '/proc/[0-9]*/ns/net' -lname "$ns" 2>/dev/null |
        cut -d/ -f3
}

holders=()
for f in "$RUN_DIR"/holder-*.pid; do
    [[ -r $f ]] || continue
    n=${f##*/holder-}
    n=${n%.pid}
    pid=$(tr -dc '0-9' <"$f")
    if [[ -n $pid && -d /proc/$pid ]] && [[ $(readlink "/proc/$pid/ns/net") != $(readlink /proc/self/ns/net) ]]; then
        holders+=("$n:$pid")
    fi
done

# 1. the daemons first, gently (slurmd ends its jobs' steps), then all that is left
for h in "${holders[@]}"; do
    n=${h%%:*}
    for f in "$RUN_DIR/slurmd-$n.pid" "$RUN_DIR/slurmctld.pid"; do
        pid=$({ tr -dc '0-9' <"$f"; } 2>/dev/null || true)
        [[ -n $pid && -d /proc/$pid ]] || continue
        # only if it really runs in this node
        [[ $(readlink "/proc/$pid/ns/net") == $(readlink "/proc/${h#*:}/ns/net") ]] || continue
        kill -TERM "$pid" 2>/dev/null || true
    done
done
for _ in $(seq 1 40); do
    left=0
    for h in "${holders[@]}"; do
        for pid in $(in_netns_of "${h#*:}"); do
            comm=$(cat "/proc/$pid/comm" 2>/dev/null || true)
            [[ $comm == slurmd || $comm == slurmctld ]] && left=1
        done
    done
    ((left)) || break
    sleep 0.25
done
for sig in TERM KILL; do
    for h in "${holders[@]}"; do
        for pid in $(in_netns_of "${h#*:}"); do
            kill -"$sig" "$pid" 2>/dev/null || true
        done
    done
    for _ in $(seq 1 40); do
        left=0
        for h in "${holders[@]}"; do
            [[ -n $(in_netns_of "${h#*:}") ]] && left=1
        done
        ((left)) || break
        sleep 0.25
    done
done
for h in "${holders[@]}"; do
    if [[ -n $(in_netns_of "${h#*:}") ]]; then
        log "node ${h%%:*}: processes still alive: $(in_netns_of "${h#*:}" | tr '\n' ' ')" >&2
        rc=1
    else
        log "node ${h%%:*}: every process stopped, namespaces released"
    fi
done

# 2. the switch (its veth ends go with it; the nodes' ends went with their namespaces)
if ip netns list 2>/dev/null | grep -qw "$SWITCH"; then
    ip netns delete "$SWITCH" && log "netns $SWITCH deleted" || { log "could not delete netns $SWITCH" >&2; rc=1; }
fi
for v in $(ip -o link show 2>/dev/null | awk -F': ' '{print $2}' | grep -E '^vknit[0-9]+' | cut -d@ -f1); do
    ip link delete "$v" 2>/dev/null && log "deleted stray veth $v"
done
rm -rf "$RUN_DIR"
exit "$rc"
