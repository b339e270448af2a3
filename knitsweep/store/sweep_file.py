"""Stress–strain tables of a single sweep (``knitsweep sweep``), as CSV text or a
small HDF5 file, named as everywhere else (``knitsweep.quantities``)."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..quantities import STEP_QUANTITIES, registered

if TYPE_CHECKING:
    from ..config import StitchParams

COLUMNS = ("strain", "a_x", "a_y", "stress", "stress_envelope", "stress_xx", "stress_yy", "stress_xy",
           "bending_energy", "contact_energy", "total_energy",
           *(o.name for o in registered("step")), "winner", "converged")  # fmt: skip
"""The per-step quantities of the CSV table, in order (the registered step observables,
``quantities.registered("step")``, after the energies)."""


INPUTS_PREFIX = "# knitsweep sweep inputs: "
"""How the first line of a sweep's CSV table starts: the inputs as JSON follow."""


def sweep_inputs(params, direction: str, numerics, starts, seed: int) -> dict:
    """What a sweep was run with, as plain data: the direction, the stitch parameters
    (named with their units: ``L_mm``, ``k_mN_per_mm2``), and the numerics (preset,
    fidelity, solver, protocol, starts, seed)."""
    return {"direction": direction,
            "parameters": {"stitch": params.stitch, **params.model_dump(mode="json"),
                           "L_over_r": params.L_mm / params.r_mm},
            "numerics": {**numerics.model_dump(mode="json"),
                         "starts": starts.model_dump(mode="json"), "seed": seed}}  # fmt: skip


def sweep_table(result, inputs: dict | None = None) -> str:
    """CSV whose header names each column with its unit suffix (``stress_N_per_mm``),
    after a comment line of the ``inputs`` (``sweep_inputs``) as JSON, if given
    (``pandas.read_csv(path, comment="#")`` reads the table).

    ``result`` is a ``strain_sweep.SweepResult``: the store sits below the layer that
    computes it and reads only its arrays."""
    buf = io.StringIO()
    if inputs is not None:
        buf.write(INPUTS_PREFIX + json.dumps(inputs) + "\n")
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


def write_sweep(path: str | Path, result, params: StitchParams, inputs: dict | None = None) -> None:
    """Write one sweep to ``.csv`` (the table) or ``.h5`` (every per-step array, each
    with its ``units``; the parameters and the ``inputs``, as JSON in ``inputs_json``,
    as root attributes)."""
    path = Path(path)
    if path.suffix == ".csv":
        from ..util.safe_files import replace_file

        replace_file(path, sweep_table(result, inputs).encode())
        return
    import h5py

    from .format import SWEEPS, describe_dataset

    with h5py.File(path, "w") as f:
        f.attrs["direction"] = result.direction
        f.attrs["status"] = result.status
        f.attrs["stop_reason"] = result.stop_reason
        for key, value in params.model_dump().items():
            f.attrs[key] = value
        if inputs is not None:
            f.attrs["inputs_json"] = json.dumps(inputs)
        for name, value in {**result.arrays(), "total_energy": result.total_energy}.items():
            f.create_dataset(name, data=value)
            describe_dataset(f, SWEEPS, name)
