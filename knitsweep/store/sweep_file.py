"""Stress–strain tables of a single sweep (``knitsweep sweep``), as CSV text or a
small HDF5 file, named as everywhere else (``knitsweep.quantities``)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..quantities import STEP_QUANTITIES, registered

if TYPE_CHECKING:
    from ..config import StitchParams

COLUMNS = ("strain", "a_x", "a_y", "stress", "stress_envelope", "bending_energy",
           "contact_energy", "total_energy", *(o.name for o in registered("step")), "winner",
           "converged")  # fmt: skip
"""The per-step quantities of the CSV table, in order (the registered step observables,
``quantities.registered("step")``, after the energies)."""


def sweep_table(result) -> str:
    """CSV whose header names each column with its unit suffix (``stress_N_per_mm``).

    ``result`` is a ``strain_sweep.SweepResult``: the store sits below the layer that
    computes it and reads only its arrays."""
    buf = io.StringIO()
    buf.write(",".join(STEP_QUANTITIES[name].column for name in COLUMNS) + "\n")
    cols = [getattr(result, name) for name in COLUMNS]
    for row in zip(*cols, strict=True):
        buf.write(",".join(_fmt(v) for v in row) + "\n")
    return buf.getvalue()


def _fmt(v) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v)).lower()
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return f"{float(v):.10g}"


def write_sweep(path: str | Path, result, params: StitchParams) -> None:
    """Write one sweep to ``.csv`` (the table) or ``.h5`` (every per-step array)."""
    path = Path(path)
    if path.suffix == ".csv":
        from ..formats import replace_file

        replace_file(path, sweep_table(result).encode())
        return
    import h5py

    from .format import SWEEPS, describe_dataset

    with h5py.File(path, "w") as f:
        f.attrs["direction"] = result.direction
        f.attrs["status"] = result.status
        f.attrs["stop_reason"] = result.stop_reason
        for key, value in params.model_dump().items():
            f.attrs[key] = value
        for name, value in {**result.arrays(), "total_energy": result.total_energy}.items():
            f.create_dataset(name, data=value)
            describe_dataset(f, SWEEPS, name)
