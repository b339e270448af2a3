#!/usr/bin/env bash
# Run a command on a node of the namespace cluster of .ci/cluster-up.sh, the way
# `ssh NODE COMMAND` runs it on a real one: in that node's network, UTS (hostname)
# and mount (private /tmp, /dev/shm, /etc/hosts, /etc/slurm, /run/munge) namespaces.
#
#   .ci/cluster-exec.sh knit2 hostname                 # -> knit2
#   mpirun -launcher ssh -launcher-exec .ci/cluster-exec.sh -hosts knit1,knit2 ...
#
# ssh's calling convention: leading options (hydra passes -x) are ignored, the
# first word is the node, and the remaining words are joined with spaces and run
# by `sh -c` on the node, as sshd would. The environment is passed on as it is
# (hydra sends the ranks' environment through its own protocol anyway); the
# working directory is kept if the node has it, else it is /.
set -euo pipefail

RUN_DIR=${CLUSTER_RUN_DIR:-/run/knitsweep-cluster}

while [[ ${1:-} == -* ]]; do
    case $1 in
    -l | -p | -o | -i | -F) shift 2 ;; # ssh options that take a value
    *) shift ;;
    esac
done
node=${1:?usage: cluster-exec.sh NODE COMMAND...}
shift
node=${node%%:*}
node=${node#*@}
pidfile=$RUN_DIR/holder-$node.pid
[[ -r $pidfile ]] || {
    echo "cluster-exec.sh: no node $node (no $pidfile; is .ci/cluster-up.sh running?)" >&2
    exit 255
}
pid=$(tr -dc '0-9' <"$pidfile")
[[ -n $pid && -d /proc/$pid ]] || {
    echo "cluster-exec.sh: node $node is down (holder pid '$pid' is gone)" >&2
    exit 255
}
(($#)) || set -- "${SHELL:-/bin/sh}" -l
# (nsenter --wd would resolve the directory here, not on the node)
export CLUSTER_EXEC_WD=$PWD
exec nsenter --target "$pid" --mount --uts --net -- /bin/sh -c \
    'cd "$CLUSTER_EXEC_WD" 2>/dev/null || cd /; unset CLUSTER_EXEC_WD; eval "$1"' sh "$*"
