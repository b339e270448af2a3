"""The fault campaign's short form (scripts/fault_campaign.py, docs/fault-campaign.md):
SIGTERM to the master alone, SIGINT to one worker alone and SIGKILL to each of them,
at random instants of an ``mpirun -n 3`` run; symbolic links planted beside the results
file; a full disk. Every trial ends as README promises, no rank is left 30 s after the
signal, and the resumed file equals an uninterrupted run (integration; root for the
tmpfs of the full disk, as CI has)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "fault_campaign.py"


@pytest.mark.slow
@pytest.mark.mpi
def test_the_short_campaign_finds_every_promise_kept(tmp_path):
    if os.geteuid() != 0:
        pytest.fail("the campaign mounts a tmpfs for its full disk: run as root (CI does)")
    proc = subprocess.run([sys.executable, SCRIPT, "--short", "--only", "signals,symlinks,disk",
                           "--seed", "3", "--keep", tmp_path / "work"], capture_output=True,
                          text=True, timeout=1200)  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = [line for line in proc.stdout.splitlines() if line.startswith("| SIG")]
    assert {r.split("|")[1].strip() for r in rows} == {
        "SIGTERM to master",
        "SIGINT to worker",
        "SIGKILL to worker",
        "SIGKILL to master",
    }
    for row in rows:  # trials, landed, as promised, failed
        cells = [c.strip() for c in row.split("|")[2:6]]
        assert cells[2] == cells[0] and cells[3] == "0", row
    assert "| symbolic links planted | 2 |" in proc.stdout
    assert "| full disk (tmpfs) | 1 |" in proc.stdout and "FAILED" not in proc.stdout
