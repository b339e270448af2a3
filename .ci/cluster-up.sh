#!/usr/bin/env bash
# Bring up a small multi-node SLURM cluster on this one machine, for CI: each
# "node" is a set of Linux namespaces (network, UTS, mount) held open by one
# sleeping process, so that to MPI and SLURM it is a host of its own:
#
#   - its own hostname (knit1, knit2, ...; UTS namespace),
#   - its own network stack with one address on a private /24 (default
#     10.226.26.0/24: knit1 = .11, knit2 = .12, ...), a veth into a bridge that
#     lives in a namespace of its own (knit-switch); nothing is routed outside,
#     and no address of the machine itself is used,
#   - its own /tmp and /dev/shm (mount namespace), its own /etc/hosts (the nodes'
#     names and addresses only), /etc/slurm (this cluster's slurm.conf) and
#     /run/munge (its own munged, all with one shared key, as on a real cluster),
#   - slurmd on every node, slurmctld on knit1 (the head node computes too).
#
# What the nodes share is the machine's file system (apart from the above): the
# code and the virtualenv, as a shared software installation would be, and
# $CLUSTER_BASE/shared, the cluster's "shared scratch" for job files and results
# that several nodes must see. Everything else a run needs has to travel by MPI.
#
#   sudo .ci/cluster-up.sh            # install if needed, start, wait for idle nodes
#   .ci/cluster-exec.sh knit1 sinfo   # run a command on a node (like ssh)
#   sudo .ci/cluster-down.sh          # stop every daemon, delete every namespace
#
# Idempotent: if the cluster is up and healthy it returns at once. A half-started
# cluster (from a killed run) is torn down first. Fails loudly (exit 1, log tails
# on stderr) if anything does not come up; on failure it tears down what it made.
#
# Knobs: CLUSTER_NODES (2 or 3, default 2), CLUSTER_SUBNET (first three octets of
# the private /24, default 10.226.26), CLUSTER_UP_TIMEOUT (s, default 60),
# CLUSTER_SHARE (colon-separated directories under /tmp that every node sees as the
# machine does, like a shared software install: a checkout or a virtualenv that
# lives in /tmp; this checkout is added when it is under /tmp).
set -Eeuo pipefail

NODES=${CLUSTER_NODES:-2}
SUBNET=${CLUSTER_SUBNET:-10.226.26}
TIMEOUT=${CLUSTER_UP_TIMEOUT:-60}
BASE=${CLUSTER_BASE:-/var/lib/knitsweep-cluster}
RUN_DIR=/run/knitsweep-cluster
SWITCH=knit-switch
PARTITION=cluster
HERE=$(cd "$(dirname "$0")" && pwd)
SHARE=${CLUSTER_SHARE:-}
[[ $HERE == /tmp/* ]] && SHARE="${SHARE:+$SHARE:}$(dirname "$HERE")"
EXEC=$HERE/cluster-exec.sh

T0=$SECONDS
log() { printf '[cluster-up %3ds] %s\n' "$((SECONDS - T0))" "$*"; }

[[ $NODES =~ ^[23]$ ]] || { echo "CLUSTER_NODES=$NODES: must be 2 or 3" >&2; exit 2; }
[[ $SUBNET =~ ^(10|192\.168|172\.(1[6-9]|2[0-9]|3[01]))(\.[0-9]{1,3}){1,2}$ ]] ||
    { echo "CLUSTER_SUBNET=$SUBNET: must be three octets of a private range, e.g. 10.226.26" >&2; exit 2; }
NAMES=()
for ((i = 1; i <= NODES; i++)); do NAMES+=("knit$i"); done
addr() { echo "$SUBNET.$((10 + ${1#knit}))"; }

dump_diagnostics() {
    {
        echo "================ cluster-up.sh diagnostics ================"
        for f in "$BASE"/log/*.log; do
            [[ -r $f ]] || continue
            echo "---------------- tail -n 30 $f ----------------"
            tail -n 30 "$f"
        done
        if [[ -r $RUN_DIR/holder-knit1.pid ]]; then
            echo "---------------- sinfo on knit1 ----------------"
            timeout 10 "$EXEC" knit1 sinfo -N -l 2>&1 || true
            timeout 10 "$EXEC" knit1 scontrol show node 2>&1 | grep -Ei 'NodeName|State|Reason' || true
        fi
        echo "==========================================================="
    } >&2
}
die() {
    trap - ERR
    echo "[cluster-up] FATAL: $*" >&2
    dump_diagnostics
    bash "$HERE/cluster-down.sh" >&2 || true
    exit 1
}
trap 'die "command failed (exit $?) at line $LINENO: $BASH_COMMAND"' ERR

wait_for() { # SECONDS DESCRIPTION CMD...: poll CMD every 0.25 s
    local secs=$1 what=$2
    shift 2
    local deadline=$((SECONDS + secs))
    until "$@" >/dev/null 2>&1; do
        ((SECONDS < deadline)) || die "timed out after ${secs}s waiting for: $what"
        sleep 0.25
    done
}
on() { "$EXEC" "$@"; } # on NODE CMD...: run CMD on NODE
holder_pid() { { tr -dc '0-9' <"$RUN_DIR/holder-$1.pid"; } 2>/dev/null; }
holder_alive() { local p; p=$(holder_pid "$1") && [[ -n $p && -d /proc/$p ]]; }
pid_alive() { local p; p=$({ tr -dc '0-9' <"$1"; } 2>/dev/null) && [[ -n $p && -d /proc/$p ]]; }

[[ $(id -u) -eq 0 ]] || die "must run as root"

# --------------------------------------------------------------------------
# 0. Already up?
# --------------------------------------------------------------------------
nodes_idle() { # every node answers and is idle/mixed/allocated in sinfo on knit1
    local n state
    for n in "${NAMES[@]}"; do
        state=$(timeout 5 "$EXEC" knit1 sinfo -h -N -n "$n" -o %T 2>/dev/null | head -n 1) || return 1
        [[ $state =~ ^(idle|mixed|allocated|completing)$ ]] || return 1
    done
}
healthy() {
    local n
    [[ -r $RUN_DIR/nodes && $(cat "$RUN_DIR/nodes") == "${NAMES[*]}" ]] || return 1
    for n in "${NAMES[@]}"; do holder_alive "$n" || return 1; done
    pid_alive "$RUN_DIR/slurmctld.pid" || return 1
    for n in "${NAMES[@]}"; do pid_alive "$RUN_DIR/slurmd-$n.pid" || return 1; done
    nodes_idle
}
if healthy; then
    log "cluster already up: ${NAMES[*]}"
    exit 0
fi
# whatever is there of a cluster (half-started, unhealthy, of another size, or
# left behind without its run directory) goes first
bash "$HERE/cluster-down.sh" || die "could not remove what is left of an earlier cluster"

# --------------------------------------------------------------------------
# 1. Packages (the same as .ci/slurm-up.sh, plus iproute2 and util-linux)
# --------------------------------------------------------------------------
PKGS=(munge slurmctld slurmd slurm-client iproute2 util-linux)
pkgs_installed() {
    local p
    for p in "${PKGS[@]}"; do
        [[ $(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null) == installed ]] || return 1
    done
    command -v munged && command -v slurmctld && command -v slurmd && command -v ip &&
        command -v nsenter && command -v unshare
} >/dev/null
if ! pkgs_installed; then
    log "installing ${PKGS[*]} with apt-get"
    export DEBIAN_FRONTEND=noninteractive
    ok=0
    for attempt in 1 2 3; do
        if apt-get update -q && apt-get install -y -q --no-install-recommends \
            -o Dpkg::Options::=--force-confdef -o Dpkg::Options::=--force-confold "${PKGS[@]}"; then
            ok=1
            break
        fi
        log "apt-get failed (attempt $attempt), retrying in 5 s"
        sleep 5
    done
    ((ok)) && pkgs_installed || die "apt-get could not install ${PKGS[*]}"
fi
log "$(slurmd -V), $(ip -V | cut -d, -f1)"

# --------------------------------------------------------------------------
# 2. The private /24 must be unused on this machine
# --------------------------------------------------------------------------
if ip -4 -o addr show | grep -q " $SUBNET\." || ip -4 route show | grep -q "^$SUBNET\."; then
    die "$SUBNET.0/24 is in use on this machine; choose another with CLUSTER_SUBNET"
fi

# --------------------------------------------------------------------------
# 3. Files: munge key, /etc/hosts and slurm.conf of the nodes
# --------------------------------------------------------------------------
install -d -m 0755 "$RUN_DIR" "$BASE" "$BASE/log" "$BASE/etc-slurm" "$BASE/ctld-state"
install -d -m 1777 "$BASE/shared"
install -d -o munge -g munge -m 0700 "$BASE/munge"
if [[ ! -s $BASE/munge/munge.key ]]; then
    dd if=/dev/urandom of="$BASE/munge/munge.key" bs=1024 count=1 status=none
fi
chown munge:munge "$BASE/munge/munge.key"
chmod 0400 "$BASE/munge/munge.key"

{
    echo "127.0.0.1 localhost"
    for n in "${NAMES[@]}"; do echo "$(addr "$n") $n"; done
} >"$BASE/hosts"

NCPU=$(nproc)
MEM_MIB=$(awk '/^MemTotal:/ {print int($2 / 1024)}' /proc/meminfo)
NODE_MEM=$(((MEM_MIB * 9 / 10) / NODES))
((NODE_MEM >= 256)) || NODE_MEM=256
{
    echo "# Generated by knitsweep .ci/cluster-up.sh: ${NODES} namespace nodes on one machine."
    echo "ClusterName=knitsweep-mh"
    echo "SlurmctldHost=knit1($(addr knit1))"
    cat <<EOF
SlurmctldPidFile=$RUN_DIR/slurmctld.pid
SlurmdPidFile=$RUN_DIR/slurmd-%n.pid
StateSaveLocation=$BASE/ctld-state
SlurmdSpoolDir=$BASE/nodes/%n/spool
SlurmctldLogFile=$BASE/log/slurmctld.log
SlurmdLogFile=$BASE/log/slurmd-%n.log
EOF
    cat "$HERE/slurm-policy.conf"
    for n in "${NAMES[@]}"; do
        echo "NodeName=$n NodeAddr=$(addr "$n") NodeHostname=$n CPUs=$NCPU RealMemory=$NODE_MEM State=UNKNOWN"
    done
    echo "PartitionName=$PARTITION Nodes=knit[1-$NODES] Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO"
} >"$BASE/etc-slurm/slurm.conf"
# a fresh controller state: no jobs or node states left from an earlier cluster
rm -rf "${BASE:?}/ctld-state/"*

# --------------------------------------------------------------------------
# 4. The switch: a bridge in a network namespace of its own
# --------------------------------------------------------------------------
ip netns add "$SWITCH"
echo "$SWITCH" >"$RUN_DIR/netns"
ip -n "$SWITCH" link set lo up
ip -n "$SWITCH" link add br0 type bridge
ip -n "$SWITCH" link set br0 up

# --------------------------------------------------------------------------
# 5. The nodes: namespaces held by a sleeping process each
# --------------------------------------------------------------------------
echo "${NAMES[*]}" >"$RUN_DIR/nodes"
# the machine's mount points of the nodes' own /run/munge and /etc/slurm: on a fresh
# machine (no .ci/slurm-up.sh run, no systemd-tmpfiles) neither exists, and a bind mount
# needs its target; empty directories that the machine's own munge/SLURM may use later
[[ -d /run/munge ]] || install -d -o munge -g munge -m 0755 /run/munge
[[ -d /etc/slurm ]] || install -d -m 0755 /etc/slurm
for n in "${NAMES[@]}"; do
    d=$BASE/nodes/$n
    rm -rf "$d"
    install -d -m 0755 "$d" "$d/spool"
    install -d -m 1777 "$d/tmp"
    install -d -m 0755 "$d/machine-tmp"
    install -d -o munge -g munge -m 0755 "$d/run-munge"
    install -d -o munge -g munge -m 0700 "$d/munge-lib" "$d/munge-log"
    # The holder sets up its mounts (private propagation: nothing leaks back to
    # the machine), writes its pid when ready and sleeps; the namespaces live as
    # long as it does.
    setsid unshare --uts --net --mount --propagation private -- /bin/sh -c '
        set -e
        hostname "$1"
        ip link set lo up
        mount --bind /tmp "$2/machine-tmp"
        mount --bind "$2/tmp" /tmp
        IFS=:
        for p in $5; do
            case $p in /tmp/?*) ;; *) echo "CLUSTER_SHARE: $p is not under /tmp" >&2; exit 1 ;; esac
            mkdir -p "$p"
            mount --bind "$2/machine-tmp/${p#/tmp/}" "$p"
        done
        unset IFS
        mount -t tmpfs -o mode=1777,size=256m tmpfs /dev/shm
        mount --bind "$3/hosts" /etc/hosts
        mount --bind "$3/etc-slurm" /etc/slurm
        mount --bind "$2/run-munge" /run/munge
        echo $$ > "$4.tmp" && mv "$4.tmp" "$4"
        exec sleep infinity' holder "$n" "$d" "$BASE" "$RUN_DIR/holder-$n.pid" "$SHARE" \
        </dev/null >>"$BASE/log/holder-$n.log" 2>&1 &
done
for n in "${NAMES[@]}"; do
    wait_for 10 "node $n's namespaces" holder_alive "$n"
done

# one veth per node: eth0 inside the node, vethN on the switch's bridge
for n in "${NAMES[@]}"; do
    pid=$(holder_pid "$n")
    ip link add eth0 netns "$pid" type veth peer name "v$n" netns "$SWITCH"
    ip -n "$SWITCH" link set "v$n" master br0 up
    nsenter --target "$pid" --net ip addr add "$(addr "$n")/24" dev eth0
    nsenter --target "$pid" --net ip link set eth0 up
done
for n in "${NAMES[@]}"; do
    [[ $(on "$n" hostname) == "$n" ]] || die "node $n: hostname is $(on "$n" hostname)"
    [[ $(on "$n" "getent hosts knit1" | awk '{print $1}') == "$(addr knit1)" ]] ||
        die "node $n does not resolve knit1 to $(addr knit1)"
done
log "nodes up: $(for n in "${NAMES[@]}"; do printf '%s=%s ' "$n" "$(addr "$n")"; done)on bridge br0 in netns $SWITCH"

# --------------------------------------------------------------------------
# 6. munged on every node (one key), then slurmctld on knit1, slurmd everywhere
# --------------------------------------------------------------------------
for n in "${NAMES[@]}"; do
    d=$BASE/nodes/$n
    on "$n" start-stop-daemon --start --quiet --chuid munge --pidfile /run/munge/munged.pid \
        --exec /usr/sbin/munged -- --key-file="$BASE/munge/munge.key" \
        --seed-file="$d/munge-lib/munged.seed" --log-file="$d/munge-log/munged.log" ||
        die "munged on $n failed to start (log: $d/munge-log/munged.log)"
done
for n in "${NAMES[@]}"; do
    wait_for 15 "munged on $n" on "$n" "munge -n </dev/null | unmunge"
done
# a credential made on one node is accepted on another: the key is shared
on knit1 "munge -n </dev/null" | on "knit$NODES" unmunge >/dev/null ||
    die "a munge credential from knit1 is refused on knit$NODES"
log "munged on every node; a credential from knit1 decodes on knit$NODES"

on knit1 slurmctld || die "slurmctld on knit1 exited with status $?"
wait_for 30 "slurmctld on knit1 to answer 'scontrol ping'" on knit1 "scontrol ping | grep -q 'is UP'"
for n in "${NAMES[@]}"; do
    on "$n" slurmd -N "$n" || die "slurmd on $n exited with status $?"
done
wait_for "$TIMEOUT" "nodes ${NAMES[*]} to be idle" nodes_idle
log "SLURM up: $(on knit1 sinfo -h -N -o '%N:%T' | tr '\n' ' ')"

# --------------------------------------------------------------------------
# 7. Proof: one step on every node reports that node's name
# --------------------------------------------------------------------------
got=$(on knit1 "cd / && timeout 60 srun -N $NODES --ntasks-per-node=1 hostname" | sort | tr '\n' ' ')
want=$(printf '%s\n' "${NAMES[@]}" | sort | tr '\n' ' ')
[[ $got == "$want" ]] || die "srun -N $NODES hostname gave '$got', expected '$want'"
log "srun -N $NODES hostname: $got"
trap - ERR
