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
    >>> res.sweeps.attrs["units"]["Y_sec_N_per_mm"]    # 'N/mm'

Columns that only a job storing more fills (contact forces, packing fractions) are left
out when no task of the files stored them (``load(..., all_columns=True)`` keeps them);
a missing number is NaN, a missing flag or count pandas' NA (dtypes ``boolean``,
``Int64``); each task's wall time on its worker is its ``seconds``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.transitions import GAP_THRESHOLD
from ..errors import InputError
from ..quantities import PARAMETER_NAMES, PARAMETERS, SERIES_PARAMS, STEP_QUANTITIES, table_column
from ..stitches import STITCH_NAMES
from ..store.format import SWEEPS
from .reduce import Reduction, reduce_results
from .tidy import attrs_of

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

PARAMETER_COLUMNS = tuple(PARAMETERS)
"""Parameter columns of every table, in this order (``L_over_r`` last)."""


def _frame(rows: list[dict[str, Any]], first: Sequence[str], file_of: dict[str, str] | None = None,
           seconds_of: dict[str, float] | None = None) -> pd.DataFrame:  # fmt: skip
    import pandas as pd

    df = pd.DataFrame([{table_column(k): v for k, v in row.items()} for row in rows])
    if df.empty:
        return pd.DataFrame(columns=list(first))
    if seconds_of is not None and "task_id" in df.columns:
        df["seconds"] = df["task_id"].map(seconds_of).astype(float)
    if file_of is not None and "task_id" in df.columns:  # (a damaged row names its own)
        given = df["file"] if "file" in df.columns else [None] * len(df)
        df["file"] = [file_of.get(t, f) for t, f in zip(df["task_id"], given, strict=True)]
    lead = [c for c in first if c in df.columns]
    return df[lead + [c for c in df.columns if c not in lead]]


TEXT_COLUMNS = frozenset({"task_id", "point_id", "kind", "status", "sweep_status", "direction",
                          "stitch", "regime", "sigma0_source", "sigma0_reason", "message",
                          "file"})  # fmt: skip
"""Columns of text (the others hold numbers or flags)."""


def stored_only(column: str) -> bool:
    """Whether a column comes from data a job stores only when asked: contact forces
    (``[store] contact_forces``: ``F_…``, ``pair_F_…`` and their ratios) and packing
    fractions (``[store] packing_fraction``)."""
    return (column.startswith(("F_", "pair_F_", "packing_fraction"))
            or column in ("force_ratio_xy", "generalised_force_ratio_xy"))  # fmt: skip


def _typed(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with each column of Python objects (numbers, flags or text with ``None``
    where missing) in the dtype its values mean: float (NaN), ``boolean`` or ``Int64``
    (NA), or text; a column with no value at all as float NaN, or text if it holds text."""
    import pandas as pd

    out = {}
    for name in df.columns:
        col = df[name]
        if col.dtype != object:
            out[name] = col
            continue
        present = col[col.notna()]
        kinds = {type(v) for v in present}
        if name in TEXT_COLUMNS or (kinds and all(issubclass(k, str) for k in kinds)):
            # pandas 3's text dtype (NaN where missing); pandas 2 would write "None"
            out[name] = col.astype("str") if pd.__version__ >= "3" else col
        elif kinds and all(issubclass(k, (bool, np.bool_)) for k in kinds):
            out[name] = col.astype("boolean")
        elif kinds and all(issubclass(k, (int, np.integer)) and not issubclass(k, (bool, np.bool_))
                           for k in kinds):  # fmt: skip
            out[name] = col.astype("Int64")
        else:  # numbers, or nothing: NaN where missing
            out[name] = pd.to_numeric(col, errors="coerce").astype(float)
    return pd.DataFrame(out, index=df.index)


def _described(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with the units and long name of each column in ``df.attrs`` (``units``,
    ``long_names``: column -> text; "1" for dimensionless, "" for text and ids)."""
    attrs = {c: attrs_of(c) for c in df.columns}
    df.attrs = {"units": {c: "" if c in TEXT_COLUMNS else a["units"] for c, a in attrs.items()},
                "long_names": {c: a["long_name"] for c, a in attrs.items()}}  # fmt: skip
    return df


class Results:
    """The tables of one or several results files (see the module docstring).

    Attributes:
        reduction: the post-processor's reduction (what the figures draw).
        paths: the files read.
        threshold: the energy-gap threshold used, mJ.
    """

    def __init__(self, reduction: Reduction, where: dict[str, Any] | None = None,
                 all_columns: bool = False) -> None:  # fmt: skip
        self.reduction = reduction
        self.where = dict(where or {})
        self.all_columns = all_columns
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
        return self._table(_frame(self.reduction.points, ("task_id", "status",
                                  *PARAMETER_COLUMNS), self._file_of, self._seconds_of))  # fmt: skip

    @cached_property
    def sweeps(self) -> pd.DataFrame:
        """One row per analysed sweep: Y_sec, σ0, the energy gaps, strains, regime."""
        first = ("task_id", "point_id", "direction", "status", *PARAMETER_COLUMNS)
        return self._table(_frame(self.reduction.sweeps, first, self._file_of, self._seconds_of))

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
        return self._table(_frame(rows, ("direction", *SERIES_PARAMS)))

    @cached_property
    def problems(self) -> pd.DataFrame:
        """One row per task that failed, cannot be knitted or cannot be analysed, with
        its parameters and the file it was read from."""
        import pandas as pd

        first = ("kind", "task_id", "status", "direction", *PARAMETER_COLUMNS, "message")
        df = _frame(self.reduction.problems, first, self._file_of, self._seconds_of)
        if "file" not in df.columns:
            df["file"] = pd.Series(dtype=object)
        return self._table(df)

    @cached_property
    def _file_of(self) -> dict[str, str]:
        """The file each task was read from."""
        return {e.task_id: e.meta["file"] for e in self.reduction.entries}

    @cached_property
    def _seconds_of(self) -> dict[str, float]:
        """Each task's wall time on its worker (s; NaN where a file does not say)."""
        return {e.task_id: float(e.meta.get("seconds", np.nan)) for e in self.reduction.entries}

    def _table(self, df: pd.DataFrame) -> pd.DataFrame:
        """A table as the user sees it: typed (``_typed``), without the ``stored_only``
        columns that no row of the files fills (unless ``all_columns``), filtered by
        ``select``'s ``where`` and sorted, with units in ``attrs``."""
        df = _typed(df)
        if not self.all_columns and len(df):
            df = df[[c for c in df.columns if not (stored_only(c) and df[c].isna().all())]]
        return _described(_tidy(df, self.where))

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
            return _described(pd.DataFrame(columns=["task_id", "direction", *PARAMETER_COLUMNS,
                                                    "step"]))  # fmt: skip
        return self._table(pd.concat(parts, ignore_index=True))

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

    def energy_density_samples(self, stitch: str | None = None, L_mm: float | None = None):
        """The one point's (``stitch``, ``L_mm``: needed where the files hold several) swept
        states as samples of the in-plane energy density W(ε_xx, ε_yy), for
        ``knitsweep.analysis.energy_density.fit_energy_density`` (docs/energy-density.md)."""
        from ..analysis.energy_density import density_samples

        sweeps = [(e.meta, e.record) for e in self.reduction.entries if e.kind == SWEEPS]
        return density_samples(sweeps, stitch, L_mm)

    def select(self, **where: Any) -> Results:
        """The same tables with only the rows whose columns match: a value (floats
        compared to 1e-9 relative), or a list of values. Columns a table lacks do not
        filter it (``select(direction="x")`` keeps every point).

            >>> res.select(L_mm=11.0, direction="x").curves
            >>> res.select(k_mN_per_mm2=[0.1, 1.0]).to_xarray()

        Raises:
            SelectionError: a name that is no column of any table (the line names the
                column meant, ``L`` -> ``L_mm``), or a value that no row has (the line
                lists the values there are).
        """
        tables = [getattr(self, t) for t in TABLE_NAMES]
        known = set().union(*(t.columns for t in tables))
        for column, want in where.items():
            if column not in known:
                raise SelectionError(_no_column(column, known))
            there = [t[column] for t in tables if column in t.columns and len(t)]
            values = list(want) if isinstance(want, (list, tuple, set, np.ndarray)) else [want]
            for value in values:
                if there and not any(_matches(col, [value]).any() for col in there):
                    raise SelectionError(_no_value(column, value, there))
        return Results(self.reduction, {**self.where, **where}, self.all_columns)


class SelectionError(InputError, KeyError):
    """``Results.select`` was given a column or a value the tables do not have; the
    message is one line that lists what there is."""

    def __str__(self) -> str:  # a KeyError would print its message quoted
        return str(self.args[0]) if self.args else ""


SHOWN_VALUES = 12
"""At most this many of a column's values in a refusal (then the range)."""


def _no_column(column: str, known: set[str]) -> str:
    import difflib

    by_symbol = {p.symbol: p.field for p in PARAMETER_NAMES.values()}
    meant = by_symbol.get(column) or next(
        (c for c in sorted(known) if c.startswith(f"{column}_")), None)  # fmt: skip
    if meant is None:
        close = difflib.get_close_matches(column, sorted(known), n=1)
        meant = close[0] if close else None
    if meant:
        return f"select: no column {column}; did you mean {meant}?"
    listing = ", ".join([*(p for p in PARAMETER_COLUMNS if p in known), "direction", "task_id"])
    return f"select: no column {column} (parameters: {listing}; or any table's column)"


def _no_value(column: str, value: Any, there: list) -> str:
    import pandas as pd

    values = [v for v in pd.concat(there, ignore_index=True).dropna().unique() if v != ""]
    try:
        values = sorted(values)
    except TypeError:
        pass
    text = [str(v) if isinstance(v, str) else f"{v:g}" if isinstance(v, (int, float, np.number))
            and not isinstance(v, (bool, np.bool_)) else str(v) for v in values]  # fmt: skip
    if len(text) > SHOWN_VALUES:
        text = [*text[: SHOWN_VALUES // 2], "…", *text[-2:]]
        text[-3] += f" ({len(values)} values)"
    known = ""
    if column == "stitch" and value not in STITCH_NAMES:
        known = f" (knitsweep's stitches: {', '.join(STITCH_NAMES)})"
    return f"select: no row has {column} = {value!r}; the results hold {', '.join(text)}{known}"


def _matches(col: pd.Series, values: list) -> np.ndarray:
    """Which rows of ``col`` hold one of ``values`` (numbers to 1e-9 relative)."""
    if all(isinstance(v, (int, float, np.number)) and not isinstance(v, (bool, np.bool_))
           for v in values):  # fmt: skip
        x = pd_numeric(col)
        keep = np.zeros(len(col), dtype=bool)
        for v in values:
            keep |= np.isclose(x, float(v), rtol=1e-9, atol=0.0)
        return keep
    return col.isin(values).to_numpy()


def pd_numeric(col: pd.Series) -> np.ndarray:
    """A column as floats (NaN where it holds no number)."""
    import pandas as pd

    return pd.to_numeric(col, errors="coerce").to_numpy(dtype=float, na_value=np.nan)


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
        df = df[_matches(df[column], values)]
    by = [c for c in SORT_ORDER if c in df.columns]
    if by and not df.empty:
        df = df.sort_values(by, kind="stable")
    return df.reset_index(drop=True)


def load(
    *paths: str | Path,
    threshold: float = GAP_THRESHOLD,
    all_columns: bool = False,
    warn: bool = True,
) -> Results:
    """Read one or several results files (also while a run writes them).

    Args:
        paths: HDF5 results files of ``knitsweep run`` (results schema 1 or 2).
        threshold: the energy-gap threshold between jammed and unjammed, mJ.
        all_columns: keep the columns that no task of the files stored (contact
            forces, packing fractions), all NaN.

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
    return Results(reduction, all_columns=all_columns)


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
