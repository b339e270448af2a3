"""A fault campaign against ``knitsweep run`` and the results files it writes: signals
and kills straight to one rank of ``mpirun`` (the master alone or one worker alone) and
to mpirun, truncated files, flipped bytes, planted symbolic links and a full disk. Each
trial checks what the documentation promises (docs/how-to/runs.md "Exit codes",
docs/journal.md "Crash safety, the journal and checkpoints"): how the run ends, that no rank is left 30 s after the signal, and that
nothing is lost, duplicated or changed: the damaged or interrupted file, recovered if
needed and resumed, holds the same tasks with bit-identical arrays as an uninterrupted
run. Prints one table row per kind of fault, and each failure.

Run (as root for the full disk: it mounts a small tmpfs):

    python scripts/fault_campaign.py                  # the full campaign (docs/fault-campaign.md)
    python scripts/fault_campaign.py --short          # one or two trials a kind (CI)
    python scripts/fault_campaign.py --only signals --trials 30 --seed 1

Exit code 1 if any trial failed. Trials are reproducible from ``--seed`` (the instants
and offsets; the machine's load moves where an instant lands in the run).
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "tests" / "data" / "jobs" / "tiny.toml"  # 2 points, 4 sweeps, ~2 s serially
VOLATILE = {"seconds", "relax_seconds", "wall_seconds", "rank", "host", "started_at"}
LEFT_AFTER_S = 30.0  # no rank may be left this long after the signal
RANKS = 3
BIN = Path(sys.executable).parent
MPIRUN = shutil.which("mpirun", path=str(BIN)) or shutil.which("mpirun")
SIGNALS = {"TERM": signal.SIGTERM, "INT": signal.SIGINT, "KILL": signal.SIGKILL}


def env() -> dict[str, str]:
    e = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    e.pop("KNITSWEEP_TEST_SIGNAL_AT", None)
    return e


def knitsweep(*args, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "knitsweep", *map(str, args)], env=env(),
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


def physics(path: Path) -> dict:
    """(kind, task id) -> arrays and status, timings and placement left out; raises on a
    task stored twice."""
    from knitsweep.store.read import iter_entries

    out: dict = {}
    for e in iter_entries(path, with_data=True):
        key = (e.kind, e.task_id)
        if key in out:
            raise AssertionError(f"{e.kind} {e.task_id} stored twice")
        rec = {k: np.asarray(v) for k, v in e.record.items() if k not in VOLATILE}
        rec["status"] = np.asarray(e.meta.get("status"))
        out[key] = rec
    return out


def differences(a: dict, b: dict) -> str:
    """'' if the two files' physics are identical, else the first difference."""
    if a.keys() != b.keys():
        return f"tasks differ: {len(a)} vs {len(b)} ({sorted(a.keys() ^ b.keys())[:2]})"
    for key in a:
        if a[key].keys() != b[key].keys():
            return f"{key}: other arrays"
        for name in a[key]:
            x, y = a[key][name], b[key][name]
            if x.shape != y.shape or not np.array_equal(x, y):
                return f"{key[0]} {key[1]} {name} differs"
    return ""


@dataclass
class Tally:
    trials: int = 0
    ok: int = 0
    landed: int = 0  # trials whose fault hit a run still going (signals)
    signal: bool = False
    seconds: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    def add(self, problem: str, seconds: float | None = None, landed: bool | None = None) -> None:
        self.trials += 1
        if landed is not None:
            self.signal = True
            self.landed += landed
        if seconds is not None:
            self.seconds.append(seconds)
        if problem:
            self.failures.append(problem)
        else:
            self.ok += 1


class Campaign:
    def __init__(self, work: Path, rng: random.Random) -> None:
        self.work = work
        self.rng = rng
        self.tallies: dict[str, Tally] = {}
        self.reference = work / "reference.h5"
        t0 = time.monotonic()
        proc = knitsweep("run", JOB, "--out", self.reference, "--quiet")
        if proc.returncode != 0:
            sys.exit(f"the uninterrupted run failed: {proc.stderr}")
        self.serial_s = time.monotonic() - t0
        self.ref = physics(self.reference)
        self.n = 0

    def fresh(self, name: str) -> Path:
        self.n += 1
        d = self.work / f"{self.n:03d}-{name}"
        d.mkdir()
        return d / "f.h5"

    def tally(self, kind: str) -> Tally:
        return self.tallies.setdefault(kind, Tally())

    # ---- resuming and comparing -------------------------------------------------

    def completes(self, out: Path, recover: bool = False) -> str:
        """Resume ``out`` (after ``knitsweep recover`` if asked, or if the run refuses
        the file and says to); '' if it then equals the uninterrupted run."""
        if recover:
            r = knitsweep("recover", out, "--job", JOB, timeout=60)
            if r.returncode not in (0, 2) or "Traceback" in r.stderr:
                return f"recover exit {r.returncode}: {r.stderr.strip()[-200:]}"
        run = knitsweep("run", JOB, "--out", out, "--quiet")
        if run.returncode == 2 and "knitsweep recover" in run.stderr and not recover:
            return self.completes(out, recover=True)
        if run.returncode != 0:
            return f"resume exit {run.returncode}: {run.stderr.strip()[-200:]}"
        try:
            return differences(self.ref, physics(out))
        except Exception as e:  # a reader that fails on the resumed file is a failure
            return f"resumed file unreadable: {type(e).__name__}: {e}"

    # ---- signals and kills straight to a rank ------------------------------------

    def ranks(self, root: int) -> dict[str, int]:
        """mpirun's processes (hydra starts each rank in a session of its own, so they
        are found as mpirun's descendants): 'mpirun', 'master', 'worker' (the highest
        rank) and 'rank<i>' -> pid, from /proc."""
        children: dict[int, list[int]] = {}
        for p in Path("/proc").iterdir():
            if p.name.isdigit():
                try:
                    ppid = int((p / "stat").read_text().rsplit(")", 1)[1].split()[1])
                except (OSError, IndexError, ValueError):
                    continue
                children.setdefault(ppid, []).append(int(p.name))
        found: dict[str, int] = {"mpirun": root}
        todo = [root]
        while todo:
            pid = todo.pop()
            todo.extend(children.get(pid, []))
            try:
                environ = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            rank = next((v[9:].decode() for v in environ if v.startswith(b"PMI_RANK=")), None)
            if rank is not None:
                found[f"rank{rank}"] = pid
                if rank == "0":
                    found["master"] = pid
                elif rank == str(RANKS - 1):
                    found["worker"] = pid
        return found

    @staticmethod
    def left(pids) -> list[int]:
        """Which of ``pids`` still run (zombies do not count)."""
        alive = []
        for pid in pids:
            try:
                state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except (OSError, IndexError):
                continue
            if state != "Z":
                alive.append(pid)
        return alive

    def signal_trial(self, target: str, name: str, delay_max: float) -> None:
        kind = f"SIG{name} to {target}"
        out = self.fresh(f"{name}-{target}")
        cmd = [MPIRUN, "-n", str(RANKS), sys.executable, "-m", "knitsweep", "run", str(JOB),
               "--out", str(out), "--quiet"]  # fmt: skip
        proc = subprocess.Popen(cmd, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)  # fmt: skip
        deadline = time.monotonic() + 120
        pids: dict[str, int] = {}
        while (sum(k.startswith("rank") for k in pids) < RANKS and time.monotonic() < deadline
               and proc.poll() is None):  # fmt: skip
            pids = self.ranks(proc.pid)
            time.sleep(0.05)
        if target not in pids:
            proc.kill()
            _, err = proc.communicate()
            self.tally(kind).add(f"no {target} rank appeared: {err.strip()[-200:]}")
            return
        time.sleep(self.rng.uniform(0.2, delay_max))  # start-up, compute or the end
        running = proc.poll() is None and not (out.exists() and _finished(out))
        sent = time.monotonic()
        try:
            os.kill(pids[target], SIGNALS[name])
        except ProcessLookupError:
            running = False
        try:
            _, err = proc.communicate(timeout=LEFT_AFTER_S)
            seconds = time.monotonic() - sent
        except subprocess.TimeoutExpired:
            seconds = None
            err = ""
        problem = ""
        stragglers = self.left(pids.values()) if seconds is not None else list(pids.values())
        if seconds is not None and stragglers:  # mpirun has gone: the ranks get a moment
            time.sleep(max(0.0, LEFT_AFTER_S - seconds))
            stragglers = self.left(pids.values())
        if seconds is None or stragglers:
            problem = f"processes left {LEFT_AFTER_S:.0f} s after the signal: {stragglers}"
            for pid in self.left(pids.values()):
                with _suppress():
                    os.kill(pid, signal.SIGKILL)
            proc.communicate()
        elif name != "KILL" and running:
            lines = [x for x in err.splitlines() if x.startswith("interrupted by")]
            if proc.returncode not in (0, 3):
                problem = f"exit {proc.returncode}, not 3: {err.strip()[-300:]}"
            elif "Traceback" in err:
                problem = f"a traceback: {err.strip()[-300:]}"
            elif proc.returncode == 3 and not lines:
                problem = f"exit 3 without saying so: {err.strip()[-200:]}"
        if not problem and out.exists():
            problem = self.completes(out)
        self.tally(kind).add(problem, seconds, running)

    # ---- damaged files -----------------------------------------------------------

    def truncation_trial(self, cut: int) -> None:
        out = self.fresh(f"cut{cut}")
        shutil.copy(self.reference, out)
        size = out.stat().st_size
        os.truncate(out, max(0, size - cut) if cut > 0 else 0)
        t0 = time.monotonic()
        try:
            r = knitsweep("recover", out, "--job", JOB, timeout=60)
        except subprocess.TimeoutExpired:
            self.tally("truncation, recover, resume").add(f"recover of a cut of {cut} B hung 60 s")
            return
        seconds = time.monotonic() - t0
        problem = ""
        if r.returncode not in (0, 2) or "Traceback" in r.stderr:
            problem = f"cut {cut} B: recover exit {r.returncode}: {r.stderr.strip()[-200:]}"
        leftovers = [p.name for p in out.parent.iterdir() if p.name.endswith(".tmp")]
        if not problem and leftovers:
            problem = f"cut {cut} B: temporary files left: {leftovers}"
        if not problem:
            problem = self.completes(out)
            problem = problem and f"cut {cut} B: {problem}"
        self.tally("truncation, recover, resume").add(problem, seconds)

    def flip_trial(self) -> None:
        out = self.fresh("flip")
        shutil.copy(self.reference, out)
        size = out.stat().st_size
        offset = self.rng.randrange(0, size - 1)
        n = self.rng.choice((1, 8, 64))
        with open(out, "r+b") as fh:
            fh.seek(offset)
            data = fh.read(n)
            fh.seek(offset)
            fh.write(bytes(b ^ 0xA5 for b in data))
        problem = ""
        for command in (("status", out), ("phase-diagram", out, "--out", out.parent / "pd",
                                          "--no-figures")):  # fmt: skip
            r = knitsweep(*command, timeout=120)
            if r.returncode not in (0, 2) or "Traceback" in r.stderr:
                problem = f"{n} B at {offset}: {command[0]} exit {r.returncode}: {r.stderr[-200:]}"
                break
        if not problem:
            problem = self.completes(out)
            problem = problem and f"{n} B at {offset}: {problem}"
        self.tally("byte flips, resume").add(problem)

    def symlink_trial(self, which: str) -> None:
        out = self.fresh(f"link-{which}")
        outside = out.parent.parent / f"outside-{self.n}"
        outside.write_bytes(b"must stay")
        if which != "results file":
            shutil.copy(self.reference, out)
        place = {"results file": out, "shadow": out.with_name(f".{out.name}.shadow"),
                 "spare": out.with_name(f".{out.name}.spare"),
                 "lock": out.with_name(out.name + ".lock"),
                 "journal": out.with_name(out.name + ".journal")}[which]  # fmt: skip
        place.symlink_to(outside)
        r = knitsweep("run", JOB, "--out", out, "--quiet")
        lines = r.stderr.strip().splitlines()
        problem = ""
        if outside.read_bytes() != b"must stay":
            problem = f"{which}: the file outside was written"
        elif r.returncode != 2 or len(lines) != 1 or not lines[0].startswith("error: "):
            problem = f"{which}: exit {r.returncode}, not one error line: {r.stderr[-200:]}"
        elif str(place.name) not in lines[0]:
            problem = f"{which}: the message does not name {place.name}: {lines[0]}"
        self.tally("symbolic links planted").add(problem)

    def full_disk_trial(self, size_kib: int) -> None:
        kind = "full disk (tmpfs)"
        mnt = Path(tempfile.mkdtemp(dir=self.work))
        m = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs", str(mnt)],
                           capture_output=True, text=True)  # fmt: skip
        if m.returncode != 0:
            self.tally(kind).add(f"cannot mount a tmpfs (root?): {m.stderr.strip()}")
            return
        try:
            out = mnt / "f.h5"
            r = knitsweep("run", JOB, "--out", out, "--quiet")
            lines = [x for x in r.stderr.strip().splitlines() if x.startswith("error: ")]
            problem = ""
            if r.returncode not in (2, 3) or "Traceback" in r.stderr or len(lines) != 1:
                problem = f"{size_kib} KiB: exit {r.returncode}: {r.stderr.strip()[-300:]}"
            temps = [p.name for p in mnt.iterdir() if p.name.startswith(".")]
            if not problem and temps:
                problem = f"{size_kib} KiB: left behind {temps}"
            if not problem and out.exists():  # fix the cause (room elsewhere), resume there
                moved = self.fresh("disk-full-moved")
                for p in mnt.iterdir():
                    dest = moved.with_name(p.name.replace("f.h5", moved.name))
                    (shutil.copytree if p.is_dir() else shutil.copy)(p, dest)
                problem = self.completes(moved)
            self.tally(kind).add(problem)
        finally:
            subprocess.run(["umount", str(mnt)], capture_output=True)
            with _suppress():
                mnt.rmdir()

    # ---- the table -----------------------------------------------------------------

    def table(self) -> str:
        rows = ["| fault | trials | landed mid-run | as promised | failed | ended within (median, max) |",
                "|---|---:|---:|---:|---:|---|"]  # fmt: skip
        for kind, t in self.tallies.items():
            ended = (f"{np.median(t.seconds):.1f} s, {max(t.seconds):.1f} s" if t.seconds
                     else "")  # fmt: skip
            landed = t.landed if t.signal else "-"
            rows.append(f"| {kind} | {t.trials} | {landed} | {t.ok} | {len(t.failures)} | "
                        f"{ended} |")  # fmt: skip
        return "\n".join(rows)


class _suppress:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return exc[0] is not None and issubclass(exc[0], OSError)


def _finished(path: Path) -> bool:
    try:
        from knitsweep.store.read import read_root

        return read_root(path).get("run_status") == "complete"
    except Exception:
        return False


FAMILIES = ("signals", "truncation", "flips", "symlinks", "disk")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=30, help="trials per signal and target")
    ap.add_argument("--short", action="store_true", help="one or two trials a kind (CI)")
    ap.add_argument(
        "--only", default=",".join(FAMILIES), help="comma-separated: " + ", ".join(FAMILIES)
    )
    ap.add_argument(
        "--targets",
        default="master,worker",
        help="whom the signals go to: master, worker, mpirun (comma-separated)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--keep", type=Path, help="work here and keep the files (default: a temporary dir)"
    )
    args = ap.parse_args(argv)
    only = {f.strip() for f in args.only.split(",") if f.strip()}
    if only - set(FAMILIES):
        ap.error(f"--only: one or more of {', '.join(FAMILIES)}")
    if MPIRUN is None and "signals" in only:
        ap.error("mpirun not found (pip install mpich)")
    work = args.keep or Path(tempfile.mkdtemp(prefix="fault-campaign-"))
    work.mkdir(parents=True, exist_ok=True)
    rng = random.Random(args.seed)
    c = Campaign(work, rng)
    print(f"uninterrupted serial run: {c.serial_s:.1f} s, {len(c.ref)} tasks; work in {work}",
          flush=True)  # fmt: skip
    trials = 1 if args.short else args.trials
    if "signals" in only:
        t0 = time.monotonic()  # an uninterrupted mpirun -n 3: the instants lie within it
        mpi = subprocess.run([MPIRUN, "-n", str(RANKS), sys.executable, "-m", "knitsweep", "run",
                              str(JOB), "--out", str(c.fresh("mpi")), "--quiet"], env=env(),
                             capture_output=True, text=True)  # fmt: skip
        delay = 0.9 * (time.monotonic() - t0)
        print(f"uninterrupted mpirun -n {RANKS}: {delay / 0.9:.1f} s (exit {mpi.returncode})",
              flush=True)  # fmt: skip
        kinds = [(t, s) for t in args.targets.split(",") for s in SIGNALS]
        if args.short:
            kinds = [("master", "TERM"), ("worker", "INT"), ("worker", "KILL"), ("master", "KILL")]
        for target, name in kinds:
            for _ in range(trials):
                c.signal_trial(target, name, delay)
            print(c.table().splitlines()[-1], flush=True)
    size = c.reference.stat().st_size
    if "truncation" in only:
        cuts = [1, 4096, size // 2, size] if args.short else (
            [1, 512, *range(4096, size + 1, 4096), size // 2, size])  # fmt: skip
        for cut in cuts:
            c.truncation_trial(cut)
    if "flips" in only:
        for _ in range(2 if args.short else 40):
            c.flip_trial()
    if "symlinks" in only:
        which = ["shadow", "lock"] if args.short else ["results file", "shadow", "spare", "lock",
                                                       "journal"]  # fmt: skip
        for w in which:
            c.symlink_trial(w)
    if "disk" in only:
        for kib in [96] if args.short else [16, 48, 96, 160, 256]:
            c.full_disk_trial(kib)
    print()
    print(c.table())
    failed = [(k, f) for k, t in c.tallies.items() for f in t.failures]
    for kind, failure in failed:
        print(f"FAILED {kind}: {failure}")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
