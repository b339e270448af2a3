"""Results as data: ``knitsweep.load(*paths)`` reads results files into pandas
DataFrames and an xarray Dataset.

One or several files (of one job or of different jobs: tasks are content-addressed,
so a task in two files counts once), also while a run writes them (journal
included). The tables are the post-processor's own (``reduce.reduce_results``), so
``knitsweep phase-diagram`` and this API cannot disagree. Column names follow
``knitsweep.quantities``: parameters as in job files (``L_mm``, ``k_mN_per_mm2`` …,
plus ``L_over_r``), quantities with a unit suffix (``Y_sec_N_per_mm``,
``delta_E_c_mJ``, ``stress_N_per_mm``), dimensionless ones without.

    >>> import knitsweep
    >>> res = knitsweep.load("demo.h5")
    >>> res.sweeps[["direction", "L_mm", "Y_sec_N_per_mm", "delta_E_c_mJ"]]
    >>> res.curves.query("direction == 'x'").groupby("L_mm").plot(x="strain", y="stress_N_per_mm")
    >>> ds = res.to_xarray()    # stress (sweep, step) with units and long_name
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.transitions import GAP_THRESHOLD
from ..quantities import (
    COLUMN_QUANTITY,
    PARAMETERS,
    STEP_QUANTITIES,
    table_column,
    units_of_column,
)
from ..store.format import SWEEPS
from .reduce import Reduction, reduce_results

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

PARAMETER_COLUMNS = tuple(PARAMETERS)
"""Parameter columns of every table, in this order (``L_over_r`` last)."""


def _frame(
    rows: list[dict[str, Any]], first: Sequence[str], file_of: dict[str, str] | None = None
) -> pd.DataFrame:
    import pandas as pd

    df = pd.DataFrame([{table_column(k): v for k, v in row.items()} for row in rows])
    if df.empty:
        return pd.DataFrame(columns=list(first))
    if file_of is not None and "task_id" in df.columns:
        df["file"] = df["task_id"].map(file_of)
    lead = [c for c in first if c in df.columns]
    return df[lead + [c for c in df.columns if c not in lead]]


class Results:
    """The tables of one or several results files (see the module docstring).

    Attributes:
        reduction: the post-processor's reduction (what the figures draw).
        paths: the files read.
        threshold: the energy-gap threshold used, mJ.
    """

    def __init__(self, reduction: Reduction) -> None:
        self.reduction = reduction
        self.paths = reduction.paths
        self.threshold = reduction.threshold

    def __repr__(self) -> str:
        red = self.reduction
        return (f"<knitsweep.Results: {len(red.points)} points, {len(red.sweeps)} sweeps, "
                f"{len(red.transitions)} series from {len(self.paths)} file(s)"
                f"{'; PARTIAL: ' + red.partial_reason if red.partial else ''}>")  # fmt: skip

    @property
    def partial(self) -> bool:
        """True unless every file is a complete run with every planned task."""
        return self.reduction.partial

    @cached_property
    def points(self) -> pd.DataFrame:
        """One row per point: its zero-force state (periods, aspect ratio, energies,
        thickness), status, regime and, if stored, contact forces by class."""
        return _frame(self.reduction.points, ("task_id", "status", *PARAMETER_COLUMNS),
                      self._file_of)  # fmt: skip

    @cached_property
    def sweeps(self) -> pd.DataFrame:
        """One row per analysed sweep: Y_sec, σ0, the energy gaps, strains, regime."""
        first = ("task_id", "point_id", "direction", "status", *PARAMETER_COLUMNS)
        return _frame(self.reduction.sweeps, first, self._file_of)

    @cached_property
    def transitions(self) -> pd.DataFrame:
        """One row per series (parameters but L, and direction): (L/r)_trans, its
        bracket, the jammed-regime fit and ΔL/r."""
        return _frame(self.reduction.transitions, ("direction",))

    @cached_property
    def problems(self) -> pd.DataFrame:
        """One row per task that failed, cannot be knitted or cannot be analysed."""
        return _frame(self.reduction.problems, ("kind", "task_id", "status", "direction"),
                      self._file_of)  # fmt: skip

    @cached_property
    def _file_of(self) -> dict[str, str]:
        """The file each task was read from."""
        return {e.task_id: e.meta["file"] for e in self.reduction.entries}

    @cached_property
    def curves(self) -> pd.DataFrame:
        """One row per step of every analysed sweep: the sweep's id, direction and
        parameters, ``step``, and every per-step quantity (``strain``,
        ``stress_N_per_mm``, ``stress_envelope_N_per_mm``, ``bending_energy_mJ`` …,
        ``area_strain``, ``thickness_strain``)."""
        import pandas as pd

        analysed = {c.task_id: c for c in self.reduction.curves}
        rows = {r["task_id"]: r for r in self.reduction.sweeps}
        parts = []
        for e in self.reduction.entries:
            if e.kind != SWEEPS or e.task_id not in analysed:
                continue
            n = len(e.record["strain"])
            cols: dict[str, Any] = {"task_id": e.task_id, "point_id": rows[e.task_id]["point_id"],
                                    "direction": rows[e.task_id]["direction"]}  # fmt: skip
            cols |= {p: rows[e.task_id].get(p, e.meta.get(p)) for p in PARAMETER_COLUMNS}
            cols["step"] = np.arange(n)
            for name, q in STEP_QUANTITIES.items():
                value = e.record.get(name)
                if value is not None and np.ndim(value) == 1 and len(value) == n:
                    cols[q.column] = value
            c = analysed[e.task_id]
            cols |= {"area_strain": c.area_strain, "thickness_strain": c.thickness_strain}
            parts.append(pd.DataFrame(cols))
        if not parts:
            return pd.DataFrame(columns=["task_id", "direction", *PARAMETER_COLUMNS, "step"])
        return pd.concat(parts, ignore_index=True)

    def to_xarray(self) -> xr.Dataset:
        """An ``xarray.Dataset``: per-step quantities over (``sweep``, ``step``)
        (shorter sweeps padded with NaN), sweep metrics over ``sweep``, point
        quantities over ``point``, with the parameters as coordinates; every
        variable carries ``units`` and ``long_name``. Needs the optional ``xarray``
        (``pip install 'knitsweep[xarray]'``)."""
        try:
            import xarray as xr
        except ImportError:
            raise ImportError(
                "Results.to_xarray() needs xarray: pip install 'knitsweep[xarray]'"
            ) from None

        curves, sweeps, points = self.curves, self.sweeps, self.points
        ids = list(sweeps["task_id"]) if len(sweeps) else []
        n_step = int(curves["step"].max()) + 1 if len(curves) else 0
        index = {tid: i for i, tid in enumerate(ids)}
        data_vars: dict[str, Any] = {}
        for name, q in STEP_QUANTITIES.items():
            if q.column not in curves.columns:
                continue
            grid = np.full((len(ids), n_step), np.nan)
            rows = curves["task_id"].map(index).to_numpy()
            grid[rows, curves["step"].to_numpy()] = curves[q.column].to_numpy(dtype=float)
            data_vars[name] = (
                ("sweep", "step"),
                grid,
                {"units": q.units, "long_name": q.long_name},
            )
        for column in _numeric(sweeps):
            data_vars[column] = ("sweep", sweeps[column].to_numpy(), _attrs(column))
        for column in _numeric(points):
            data_vars[f"point_{column}"] = ("point", points[column].to_numpy(), _attrs(column))
        coords: dict[str, Any] = {"sweep": ids, "step": np.arange(n_step),
                                  "point": list(points["task_id"]) if len(points) else []}  # fmt: skip
        for column in ("direction", "point_id", "file", *PARAMETER_COLUMNS):
            if column in sweeps.columns:
                coords[column] = ("sweep", sweeps[column].to_numpy(), _attrs(column))
            if column in PARAMETER_COLUMNS and column in points.columns:
                coords[f"point_{column}"] = ("point", points[column].to_numpy(), _attrs(column))
        ds = xr.Dataset(data_vars, coords=coords)
        ds["step"].attrs = {"units": "1", "long_name": "strain step (0: the zero-force state)"}
        ds["sweep"].attrs = {"units": "1", "long_name": "task id of the sweep"}
        ds["point"].attrs = {"units": "1", "long_name": "task id of the point"}
        ds.attrs = {"files": ", ".join(map(str, self.paths)), "gap_threshold_mJ": self.threshold,
                    "partial": int(self.partial)}  # fmt: skip
        return ds


def _numeric(df: pd.DataFrame) -> list[str]:
    """Numeric and boolean columns that are not parameters (those become coordinates)."""
    import pandas as pd

    return [c for c in df.columns if c not in PARAMETER_COLUMNS
            and (pd.api.types.is_numeric_dtype(df[c]) or pd.api.types.is_bool_dtype(df[c]))]  # fmt: skip


def _attrs(column: str) -> dict[str, str]:
    q = COLUMN_QUANTITY.get(column)
    if q is not None:
        return {"units": q.units, "long_name": q.long_name}
    return {"units": units_of_column(column), "long_name": column.replace("_", " ")}


def load(*paths: str | Path, threshold: float = GAP_THRESHOLD) -> Results:
    """Read one or several results files (also while a run writes them).

    Args:
        paths: HDF5 results files of ``knitsweep run`` (results schema 1 or 2).
        threshold: the energy-gap threshold between jammed and unjammed, mJ.

    Returns:
        :class:`Results` with ``points``, ``sweeps``, ``curves``, ``transitions``
        and ``problems`` DataFrames and ``to_xarray()``.

    Raises:
        knitsweep.config.InputError: a missing, unreadable or foreign file.
    """
    if len(paths) == 1 and isinstance(paths[0], (list, tuple)):
        paths = tuple(paths[0])
    return Results(reduce_results(list(paths), threshold))
