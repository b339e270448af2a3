#!/usr/bin/env bash
# Stop the SLURM daemons that .ci/slurm-up.sh started (best effort, always exits 0).
#
#   .ci/slurm-down.sh          # stop daemons recorded by slurm-up.sh
#   .ci/slurm-down.sh --all    # stop slurmd, slurmctld and munged via their pid
#                              # files even if slurm-up.sh did not start them
#
# Running jobs are killed with the daemons. Configuration, munge key and
# slurmctld state (/var/lib/slurm) are kept, so slurm-up.sh restarts quickly.
set -euo pipefail

RECORD=/run/knitsweep-slurm-ci/started

log() { echo "[slurm-down] $*"; }

ALL=0
[[ ${1:-} == --all ]] && ALL=1

wanted() { # daemon name
    ((ALL)) && return 0
    [[ -r $RECORD ]] && grep -qx "$1" "$RECORD"
}

# stop NAME PIDFILE
stop() {
    local name=$1 pidfile=$2 pid comm
    pid=$(tr -dc '0-9' <"$pidfile" 2>/dev/null || true)
    comm=$(cat "/proc/$pid/comm" 2>/dev/null || true)
    if [[ -z $pid || ( $comm != "$name" && $comm != "$name-wlm" ) ]]; then
        log "$name: not running"
    elif ! wanted "$name"; then
        log "$name: running (pid $pid) but not started by slurm-up.sh; leaving it alone (use --all to stop it)"
        return 0
    else
        log "$name: sending TERM to pid $pid"
        kill -TERM "$pid" 2>/dev/null || true
        for _ in $(seq 1 40); do
            [[ -d /proc/$pid ]] || break
            sleep 0.5
        done
        if [[ -d /proc/$pid ]]; then
            log "$name: still alive after 20 s, sending KILL"
            kill -KILL "$pid" 2>/dev/null || true
        fi
        log "$name: stopped"
    fi
    rm -f "$pidfile"
    if [[ -w $RECORD ]]; then
        sed -i "/^$name\$/d" "$RECORD" || true
    fi
}

stop slurmd /run/slurmd.pid
stop slurmctld /run/slurmctld.pid
stop munged /run/munge/munged.pid
exit 0
