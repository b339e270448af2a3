"""Provenance of a run: library versions, host, git commit and SLURM job (the
results file's root attributes)."""

from __future__ import annotations

import os
import socket
from pathlib import Path

from .._version import __version__


def environment_metadata() -> dict[str, str]:
    """Versions, host, git commit and SLURM job of this run (root attributes)."""
    import platform
    from importlib.metadata import version

    import h5py
    import numpy

    meta = {
        "knitsweep_version": __version__,
        "python_version": platform.python_version(),
        "numpy_version": numpy.__version__,
        "scipy_version": version("scipy"),  # read without importing scipy and numba
        "numba_version": version("numba"),
        "h5py_version": h5py.__version__,
        "hdf5_version": h5py.version.hdf5_version,
        "host": socket.gethostname(),
        "slurm_job_id": os.environ.get("SLURM_JOB_ID", ""),
        "git_commit": _git_commit(),
    }
    try:
        import mpi4py

        mpi4py.rc.initialize = False  # asking for versions must not start MPI
        from mpi4py import MPI

        meta["mpi4py_version"] = mpi4py.__version__
        meta["mpi_library_version"] = MPI.Get_library_version().strip().splitlines()[0]
    except Exception as e:
        meta["mpi4py_version"] = f"unavailable ({e})"
        meta["mpi_library_version"] = "unavailable"
    return meta


def _git_commit() -> str:
    import subprocess

    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)  # fmt: skip
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if out.returncode != 0:
        return "unknown (not a git checkout)"
    return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
