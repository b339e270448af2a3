"""Stress–strain tables of a single sweep, as CSV text or a small HDF5 file."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..config import StitchParams
from ..strain_sweep import SweepResult

COLUMNS = (
    ("strain", "strain", "1"),
    ("a_x", "a_x", "mm"),
    ("a_y", "a_y", "mm"),
    ("stress", "stress", "N/mm"),
    ("stress_envelope", "stress_envelope", "N/mm"),
    ("bending_energy", "E_b", "mJ"),
    ("contact_energy", "E_c", "mJ"),
    ("total_energy", "E", "mJ"),
    ("thickness", "dz", "mm"),
    ("winner", "start", "-"),
    ("converged", "converged", "-"),
)


def sweep_table(result: SweepResult) -> str:
    """CSV with a header line naming each column and its unit."""
    buf = io.StringIO()
    buf.write(",".join(f"{label} [{unit}]" for _, label, unit in COLUMNS) + "\n")
    cols = [getattr(result, name) for name, _, _ in COLUMNS]
    for row in zip(*cols, strict=True):
        buf.write(",".join(_fmt(v) for v in row) + "\n")
    return buf.getvalue()


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v)).lower()
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return f"{float(v):.10g}"


def write_sweep(path: str | Path, result: SweepResult, params: StitchParams) -> None:
    """Write one sweep to ``.csv`` (the table) or ``.h5`` (every per-step array)."""
    path = Path(path)
    if path.suffix == ".csv":
        path.write_text(sweep_table(result))
        return
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["direction"] = result.direction
        f.attrs["status"] = result.status
        f.attrs["stop_reason"] = result.stop_reason
        f.attrs["params"] = params.model_dump_json()
        for name, value in result.arrays().items():
            f.create_dataset(name, data=value)
        f.create_dataset("total_energy", data=result.total_energy)
