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
    >>> ds = res.to_xarray()    # over (direction, L_mm, …, step); strain a coordinate
    >>> ds.stress_N_per_mm.sel(direction="x").plot.line(x="strain", hue="L_mm")
    >>> res.select(L_mm=11.0, direction="x").curves
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.transitions import GAP_THRESHOLD
from ..quantities import PARAMETERS, SERIES_PARAMS, STEP_QUANTITIES, table_column
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
    if file_of is not None and "task_id" in df.columns:  # (a damaged row names its own)
        given = df["file"] if "file" in df.columns else [None] * len(df)
        df["file"] = [file_of.get(t, f) for t, f in zip(df["task_id"], given, strict=True)]
    lead = [c for c in first if c in df.columns]
    return df[lead + [c for c in df.columns if c not in lead]]


class Results:
    """The tables of one or several results files (see the module docstring).

    Attributes:
        reduction: the post-processor's reduction (what the figures draw).
        paths: the files read.
        threshold: the energy-gap threshold used, mJ.
    """

    def __init__(self, reduction: Reduction, where: dict[str, Any] | None = None) -> None:
        self.reduction = reduction
        self.where = dict(where or {})
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
        return _tidy(_frame(self.reduction.points, ("task_id", "status", *PARAMETER_COLUMNS),
                            self._file_of), self.where)  # fmt: skip

    @cached_property
    def sweeps(self) -> pd.DataFrame:
        """One row per analysed sweep: Y_sec, σ0, the energy gaps, strains, regime."""
        first = ("task_id", "point_id", "direction", "status", *PARAMETER_COLUMNS)
        return _tidy(_frame(self.reduction.sweeps, first, self._file_of), self.where)

    @cached_property
    def transitions(self) -> pd.DataFrame:
        """One row per series (parameters but L, and direction): (L/r)_trans, its
        bracket, the jammed-regime fit and ΔL/r; ``file``: the file(s) its sweeps
        were read from (comma-separated)."""
        files: dict[tuple, set[str]] = {}
        for r in self.reduction.sweeps:
            key = (r["direction"], *(r[p] for p in SERIES_PARAMS))
            files.setdefault(key, set()).add(self._file_of.get(r["task_id"], ""))
        rows = [{**t, "file": ", ".join(sorted(files.get(
            (t["direction"], *(t[p] for p in SERIES_PARAMS)), ())))}
            for t in self.reduction.transitions]  # fmt: skip
        return _tidy(_frame(rows, ("direction", *SERIES_PARAMS)), self.where)

    @cached_property
    def problems(self) -> pd.DataFrame:
        """One row per task that failed, cannot be knitted or cannot be analysed, with
        its parameters and the file it was read from."""
        import pandas as pd

        first = ("kind", "task_id", "status", "direction", *PARAMETER_COLUMNS, "message")
        df = _frame(self.reduction.problems, first, self._file_of)
        if "file" not in df.columns:
            df["file"] = pd.Series(dtype=object)
        return _tidy(df, self.where)

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
        return _tidy(pd.concat(parts, ignore_index=True), self.where)

    def to_xarray(self) -> xr.Dataset:
        """One tidy ``xarray.Dataset`` over the grid's own dimensions (``direction``,
        ``L_mm`` and the parameters that vary, ``step``; ``strain`` a coordinate),
        with the sweep metrics, point quantities and transitions; CF ``Conventions``,
        ``units`` and ``long_name`` on every variable; the layout and fill values are
        in :mod:`knitsweep.report.tidy`. Needs the optional ``xarray``
        (``pip install 'knitsweep[xarray]'``).

            >>> ds = knitsweep.load("demo.h5").to_xarray()
            >>> ds.stress_N_per_mm.sel(direction="x").plot.line(x="strain", hue="L_mm")
        """
        try:
            import xarray  # noqa: F401
        except ImportError:
            raise ImportError(
                "Results.to_xarray() needs xarray: pip install 'knitsweep[xarray]'"
            ) from None
        from .tidy import to_dataset

        return to_dataset(self)

    def select(self, **where: Any) -> Results:
        """The same tables with only the rows whose columns match: a value (floats
        compared to 1e-9 relative), or a list of values. Columns a table lacks do not
        filter it (``select(direction="x")`` keeps every point).

            >>> res.select(L_mm=11.0, direction="x").curves
            >>> res.select(k_mN_per_mm2=[0.1, 1.0]).to_xarray()

        Raises:
            KeyError: a name that is no column of any table.
        """
        known = set().union(*(getattr(self, t).columns for t in TABLE_NAMES))
        unknown = sorted(set(where) - known)
        if unknown:
            raise KeyError(f"select: no column {', '.join(unknown)} (columns: "
                           f"{', '.join(sorted(known))})")  # fmt: skip
        return Results(self.reduction, {**self.where, **where})


TABLE_NAMES = ("points", "sweeps", "curves", "transitions", "problems")
SORT_ORDER = ("direction", *(p for p in PARAMETER_COLUMNS if p not in ("L_mm", "L_over_r")),
              "L_mm", "step")  # fmt: skip
"""Every table's rows in this order: direction, the series parameters, L, step."""


def _tidy(df: pd.DataFrame, where: dict[str, Any]) -> pd.DataFrame:
    """``df`` filtered by ``where`` (see ``Results.select``) and sorted by SORT_ORDER."""
    for column, want in where.items():
        if column not in df.columns:
            continue
        values = list(want) if isinstance(want, (list, tuple, set, np.ndarray)) else [want]
        col = df[column]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            x = col.to_numpy(dtype=float)
            keep = np.zeros(len(df), dtype=bool)
            for v in values:
                keep |= np.isclose(x, float(v), rtol=1e-9, atol=0.0)
        else:
            keep = col.isin(values).to_numpy()
        df = df[keep]
    by = [c for c in SORT_ORDER if c in df.columns]
    if by and not df.empty:
        df = df.sort_values(by, kind="stable")
    return df.reset_index(drop=True)


def load(*paths: str | Path, threshold: float = GAP_THRESHOLD, warn: bool = True) -> Results:
    """Read one or several results files (also while a run writes them).

    Args:
        paths: HDF5 results files of ``knitsweep run`` (results schema 1 or 2).
        threshold: the energy-gap threshold between jammed and unjammed, mJ.

        warn: a ``knitsweep.errors.DamagedResultsWarning`` per file whose damaged
            tasks were skipped (naming how many and the first ids); the commands,
            which print their own notes, pass False.

    Returns:
        :class:`Results` with ``points``, ``sweeps``, ``curves``, ``transitions``
        and ``problems`` DataFrames and ``to_xarray()``.

    Raises:
        knitsweep.config.InputError: a missing, unreadable or foreign file.
    """
    if len(paths) == 1 and isinstance(paths[0], (list, tuple)):
        paths = tuple(paths[0])
    reduction = reduce_results(list(paths), threshold)
    if warn:
        warn_damaged(reduction.roots)
    return Results(reduction)


SHOWN_IDS = 5
"""How many ids of damaged tasks ``load``'s warning names."""


def warn_damaged(roots: list[dict[str, Any]], stacklevel: int = 3) -> None:
    """A ``DamagedResultsWarning`` per file whose damaged tasks (or tables) were
    skipped: how many, the first ids, and how to rebuild the file."""
    import warnings

    from ..errors import DamagedResultsWarning

    for r in roots:
        check = r.get("check")
        if check is None or not (check.damaged or check.structure):
            continue
        ids = [f"{kind[:-1]} {tid}" for kind, tid, _ in check.damaged]
        what = []
        if ids:
            more = f" and {len(ids) - SHOWN_IDS} more" if len(ids) > SHOWN_IDS else ""
            what.append(f"{len(ids)} damaged task(s) skipped ({', '.join(ids[:SHOWN_IDS])}{more})")
        what += check.structure_lines()
        warnings.warn(f"{r['file']}: {'; '.join(what)}: `knitsweep recover {r['file']}` rebuilds "
                      "it from what is intact", DamagedResultsWarning, stacklevel=stacklevel)  # fmt: skip
