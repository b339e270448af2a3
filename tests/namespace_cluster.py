"""The namespace cluster of ``.ci/cluster-up.sh`` as the multihost tests see it: its
paths, running a command on a node (like ``ssh node``), a node's kernel cache, and a
watcher of the ranks (which node each runs on, which files it opens, from /proc)."""

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from conftest import stored_meta

import knitsweep

REPO = Path(__file__).resolve().parents[1]
VENV = Path(sys.executable).parent.parent
SOURCE = Path(knitsweep.__file__).resolve().parents[1]  # the checkout the nodes import
UP, DOWN, EXEC = (REPO / ".ci" / f"cluster-{s}.sh" for s in ("up", "down", "exec"))
BASE = Path("/var/lib/knitsweep-cluster")
RUN_DIR = Path("/run/knitsweep-cluster")
SHARED = BASE / "shared"  # the same path on every node
NODES = ("knit1", "knit2")
NODE_CACHE = "/tmp/knitsweep-numba-root"  # NUMBA_CACHE_DIR on a node (the template's default)


def holder(node):
    """The pid holding ``node``'s namespaces."""
    return int((RUN_DIR / f"holder-{node}.pid").read_text())


def node_tmp(node) -> Path:
    """``node``'s /tmp as this (the machine's) namespace sees it."""
    return BASE / "nodes" / node / "tmp"


def namespaces(pid):
    """(uts, mnt, net) namespace ids of a process."""
    return tuple(os.readlink(f"/proc/{pid}/ns/{ns}") for ns in ("uts", "mnt", "net"))


def enter(node, cwd="/"):
    """The command prefix that runs a command on ``node`` in ``cwd`` (a path on the
    node: nsenter's own --wd would resolve it here)."""
    nsenter = ["nsenter", "-t", str(holder(node)), "-m", "-u", "-n", "--"]
    return [*nsenter, "/bin/sh", "-c", 'cd "$0" && exec "$@"', str(cwd)]


def on_node(node, argv, cwd="/", env=None, timeout=120, check=True):
    """Run ``argv`` on ``node`` (its namespaces), like ``ssh node argv``."""
    proc = subprocess.run([*enter(node, cwd), *map(str, argv)], env=env or run_env(), capture_output=True,
                          text=True, timeout=timeout)  # fmt: skip
    if check:
        assert proc.returncode == 0, f"on {node}: {argv}: {proc.stdout}\n{proc.stderr}"
    return proc


def run_env(**extra):
    """This venv and this checkout on PATH/PYTHONPATH; no KNITSWEEP_* or SLURM_*
    settings of the caller; the node-local kernel cache."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("KNITSWEEP_", "SLURM_", "PMI"))}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SOURCE), env.get("PYTHONPATH")]))
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '/usr/bin:/bin')}"
    env["KNITSWEEP_VENV"] = str(VENV)
    env["NUMBA_CACHE_DIR"] = NODE_CACHE
    env.pop("TMPDIR", None)
    env.update(extra)
    return env


def kernel_cache(node) -> Path:
    """``node``'s kernel cache directory, as this namespace sees it."""
    code = "import numba, knitsweep.kernels; print(numba.config.CACHE_DIR)"
    inside = on_node(node, [sys.executable, "-c", code]).stdout.strip()
    assert inside.startswith("/tmp/"), inside
    return node_tmp(node) / inside.removeprefix("/tmp/")


def cached_on(node) -> bool:
    code = "from knitsweep import kernels; print(kernels.cached())"
    return on_node(node, [sys.executable, "-c", code]).stdout.strip() == "True"


# ---- watching the ranks: where they run, what they open -----------------------------
class RankWatcher(threading.Thread):
    """Scans /proc every 20 ms for knitsweep ranks carrying ``marker`` in their
    environment: each rank's node (by its UTS namespace, i.e. not what the rank
    says) and every file under ``watched`` (node paths) it has open."""

    def __init__(self, marker, watched):
        super().__init__(daemon=True)
        self.marker = f"KNITSWEEP_TEST_RUN={marker}".encode()
        self.watched = [str(w) for w in watched]
        self.node_of_uts = {namespaces(holder(n))[0]: n for n in NODES}
        self.ranks = {}  # pid -> (rank, node)
        self.opened = {}  # rank -> set of paths
        self.done = threading.Event()
        self._skip = {}  # pid -> the command line it had when found not to be a rank

    def run(self):
        while not self.done.is_set():
            self.scan()
            time.sleep(0.02)
        self.scan()

    def scan(self):
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            pid = int(entry)
            try:
                if pid not in self.ranks:
                    # a rank is forked by hydra's proxy (or slurmstepd) and then
                    # execs python: look again whenever a process's command changes
                    cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
                    if self._skip.get(pid) == cmd:
                        continue
                    self._identify(pid, cmd)
                if pid in self.ranks:
                    rank = self.ranks[pid][0]
                    for fd in os.listdir(f"/proc/{pid}/fd"):
                        target = os.readlink(f"/proc/{pid}/fd/{fd}")
                        if any(target.startswith(w) for w in self.watched):
                            self.opened.setdefault(rank, set()).add(target)
            except OSError:  # gone meanwhile
                continue

    def _identify(self, pid, cmdline):
        cmd = cmdline.split(b"\0")
        python = Path(cmd[0].decode(errors="replace")).name.startswith("python")
        if not python or b"knitsweep" not in cmd or b"run" not in cmd:
            self._skip[pid] = cmdline
            return
        env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
        if self.marker not in env:
            self._skip[pid] = cmdline
            return
        env = dict(e.split(b"=", 1) for e in env if b"=" in e)
        # hydra's PMI_RANK first: under mpirun in SLURM, SLURM_PROCID numbers its proxies
        rank = env.get(b"PMI_RANK", env.get(b"SLURM_PROCID"))
        if rank is None:
            return  # not an MPI rank (yet)
        node = self.node_of_uts.get(namespaces(pid)[0], "the machine itself")
        self.ranks[pid] = (int(rank), node)

    def stop(self):
        self.done.set()
        self.join(timeout=10)

    def node_of_rank(self):
        return {rank: node for rank, node in self.ranks.values()}


def placements(path):
    """{(kind, task id): (rank, host)} as the results file records them."""
    return {(kind, tid): (int(m["rank"]), str(m["host"]))
            for kind in ("points", "sweeps") for tid, m in stored_meta(path, kind).items()}  # fmt: skip


def assert_placed_where_computed(out, watcher, nodes_used=NODES):
    """Every task's recorded host is the node its rank ran on (seen in /proc), and
    tasks ran on each of ``nodes_used``; no rank but 0 opened the results files."""
    where = watcher.node_of_rank()
    placed = placements(out)
    for key, (rank, host) in placed.items():
        assert rank in where, f"{key}: rank {rank} was never seen running ({where})"
        assert host == where[rank], (
            f"{key}: recorded on {host}, but rank {rank} ran on {where[rank]}"
        )
    assert {host for _, host in placed.values()} == set(nodes_used), placed
    assert where[0] == "knit1", where
    assert watcher.opened.get(0), f"the scan never saw the master's files open: {watcher.opened}"
    others = {r: p for r, p in watcher.opened.items() if r != 0}
    assert not others, f"ranks other than the master opened the results: {others}"
