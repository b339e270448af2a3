"""The results as one tidy ``xarray.Dataset`` over the grid's own dimensions
(``Results.to_xarray``; docs/tutorials/results-in-python.md).

Layout (CF Conventions 1.10 attributes: every variable has ``units`` and
``long_name``):

* dimensions: ``direction`` (x, y), each parameter that takes more than one value in
  the results (``L_mm`` always; ``stitch`` (names), ``k_mN_per_mm2``, ``B_mN_mm2``,
  ``r_core_mm`` … when they vary; those that do not are scalar coordinates), and ``step`` (strain step, 0:
  the zero-force state). The grid is the outer product of each parameter's values;
  cells without a task (an adaptive search's L values differ between series) are
  missing;
* per-step quantities over (direction, parameters…, step): ``stress_N_per_mm``,
  ``bending_energy_mJ`` …, with ``strain`` a coordinate of the same shape, so
  ``ds.stress_N_per_mm.sel(direction="x").plot.line(x="strain", hue="L_mm")`` draws
  one curve per L;
* per-sweep metrics over (direction, parameters…): the columns of ``Results.sweeps``
  (``Y_sec_N_per_mm``, ``delta_E_c_mJ``, ``jammed``, ``task_id`` …);
* per-point quantities over (parameters…): the columns of ``Results.points`` that the
  sweeps do not repeat, ``status`` and ``regime`` as ``point_status``, ``point_regime``;
* transitions over (direction, parameters but L…): the columns of
  ``Results.transitions`` (``L_over_r_trans``, ``bracket_lower`` …), ``status`` as
  ``transition_status``.

Missing values: NaN for floats; integers stay integers with ``_FillValue`` −1 (in
``encoding``, as netCDF writes it); booleans stay ``bool`` where every cell is
present, otherwise become int8 flags (0 false, 1 true, ``_FillValue`` −1, CF
``flag_values``/``flag_meanings``); strings are ``""`` where missing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..quantities import COLUMN_QUANTITY, PARAMETERS, units_of_column

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

GRID_PARAMETERS = tuple(p for p in PARAMETERS if p != "L_over_r")
"""Parameters that can be dimensions, in this order."""
INT_FILL = -1
_IDS = ("point_id", "file", "step")


def attrs_of(column: str) -> dict[str, str]:
    """CF ``units`` and ``long_name`` of a table column."""
    q = COLUMN_QUANTITY.get(column)
    if q is not None:
        return {"units": q.units, "long_name": q.long_name}
    return {"units": units_of_column(column) or "1", "long_name": column.replace("_", " ")}


def _axes(frames: Sequence[pd.DataFrame]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(dimension parameters → sorted values, constant parameters → value)."""
    dims, consts = {}, {}
    for p in GRID_PARAMETERS:
        if p == "stitch":  # names: a dimension of its own when a study has several
            values = np.array(sorted({str(v) for f in frames if p in f for v in f[p]}),
                              dtype=object)  # fmt: skip
            if len(values) > 1:
                dims[p] = values
            elif len(values) == 1:
                consts[p] = str(values[0])
            continue
        values = np.unique(np.concatenate([f[p].to_numpy(float) for f in frames if p in f]
                                          or [np.empty(0)]))  # fmt: skip
        values = values[np.isfinite(values)]
        if len(values) > 1 or (p == "L_mm" and len(values)):
            dims[p] = values
        elif len(values) == 1:
            consts[p] = float(values[0])
    return dims, consts


def _cells(frame: pd.DataFrame, axes: dict[str, np.ndarray]) -> tuple[np.ndarray, ...]:
    """Each row's index along each axis (``direction`` or a parameter)."""
    out = []
    for name, values in axes.items():
        col = frame[name].to_numpy()
        out.append(np.searchsorted(values, col) if name not in ("direction", "stitch")
                   else np.array([list(values).index(v) for v in col], dtype=int))  # fmt: skip
    return tuple(out)


def _variable(values: np.ndarray, where: tuple, shape: tuple) -> tuple[np.ndarray, dict, dict]:
    """(array of ``shape`` with ``values`` at ``where``, extra attrs, encoding)."""
    import pandas as pd

    filled = np.zeros(shape, dtype=bool)
    filled[where] = True
    complete = bool(filled.all())
    kind = values.dtype.kind
    if kind == "O":  # object columns: numbers (or None) or text
        numeric = pd.to_numeric(pd.Series(values), errors="coerce")
        if numeric.notna().sum() >= pd.Series(values).notna().sum() and numeric.notna().any():
            values, kind = numeric.to_numpy(float), "f"
        elif pd.Series(values).map(lambda v: isinstance(v, str) or v is None).all():
            values, kind = np.array(["" if v is None else v for v in values], dtype=object), "U"
        else:
            raise TypeError
    if kind in "US":
        out = np.full(shape, "", dtype=object)
        out[where] = values
        return out, {}, {}
    if kind == "b":
        if complete:
            out = np.zeros(shape, dtype=bool)
            out[where] = values
            return out, {}, {}
        out = np.full(shape, INT_FILL, dtype=np.int8)
        out[where] = values.astype(np.int8)
        flags = {"flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "false true"}
        return out, flags, {"_FillValue": np.int8(INT_FILL)}
    if kind in "iu":
        out = np.full(shape, INT_FILL, dtype=np.int64)
        out[where] = values
        return out, {}, {"_FillValue": np.int64(INT_FILL)}
    out = np.full(shape, np.nan)
    out[where] = values.astype(float)
    return out, {}, {}


def _add(ds_vars: dict, frame: pd.DataFrame, axes: dict, skip: set[str], prefix: str,
         taken: set[str], extra_dim: tuple[str, np.ndarray] | None = None) -> None:  # fmt: skip
    """Every column of ``frame`` (but ``skip``) as a variable over ``axes``."""
    if frame.empty:
        return
    where = _cells(frame, axes)
    dims = tuple(axes)
    shape = tuple(len(v) for v in axes.values())
    if extra_dim is not None:
        where = (*where, frame[extra_dim[0]].to_numpy(int))
        dims, shape = (*dims, extra_dim[0]), (*shape, len(extra_dim[1]))
    # one task per cell: the first (of several files: the first file's)
    first = ~frame.assign(_c=list(zip(*where, strict=True)))["_c"].duplicated().to_numpy()
    where = tuple(w[first] for w in where)
    for column in frame.columns:
        if column in skip:
            continue
        try:
            data, extra, encoding = _variable(frame[column].to_numpy()[first], where, shape)
        except TypeError:
            continue  # a column of lists or mixed values: not a grid variable
        if data.dtype.kind == "f" and not np.isfinite(data).any():
            continue  # not stored in this file (e.g. contact forces)
        name = f"{prefix}{column}" if column in taken else column
        taken.add(name)
        ds_vars[name] = (dims, data, {**attrs_of(column), **extra}, encoding)


def to_dataset(results: Any) -> xr.Dataset:
    """The Dataset of a :class:`~.results.Results` (module docstring: the layout)."""
    import xarray as xr

    curves, sweeps, points, transitions = (results.curves, results.sweeps, results.points,
                                           results.transitions)  # fmt: skip
    params, consts = _axes([f for f in (sweeps, points) if not f.empty])
    directions = np.array(sorted(set(sweeps.get("direction", [])) | set(
        transitions.get("direction", []))), dtype=object)  # fmt: skip
    sweep_axes = {"direction": directions, **params}
    series_axes = {"direction": directions, **{p: v for p, v in params.items() if p != "L_mm"}}
    n_step = int(curves["step"].max()) + 1 if len(curves) else 0
    ids = {"task_id", "point_id", "direction", "L_over_r", *GRID_PARAMETERS}
    vars_: dict[str, Any] = {}
    taken: set[str] = set()
    _add(vars_, curves, sweep_axes, ids | {"step"}, "", taken, ("step", np.arange(n_step)))
    _add(vars_, sweeps, sweep_axes, ids - {"task_id"} | {"file"}, "", taken)
    repeated = set(sweeps.columns) - {"status", "regime"}
    _add(vars_, points, dict(params), ids | repeated | {"file"}, "point_", taken)
    _add(vars_, transitions, series_axes, ids | {"file"}, "transition_", taken)
    coords: dict[str, Any] = {"direction": ("direction", directions, {"long_name": "direction "
                              "of the pull", "units": "1"}), "step": ("step", np.arange(n_step),
                              {"long_name": "strain step (0: the zero-force state)", "units": "1"})}  # fmt: skip
    for p, values in params.items():
        coords[p] = (p, values, {**attrs_of(p), "axis": "X" if p == "L_mm" else ""})
    for p, value in consts.items():
        coords[p] = ((), value, attrs_of(p))
    if "strain" in vars_:
        dims, data, attrs, _ = vars_.pop("strain")
        coords["strain"] = (dims, data, attrs)
    if "r_mm" in consts and "L_mm" in params:
        coords["L_over_r"] = ("L_mm", params["L_mm"] / consts["r_mm"], attrs_of("L_over_r"))
    ds = xr.Dataset({k: (d, v, a) for k, (d, v, a, _) in vars_.items()}, coords=coords)
    for k, (_, _, _, encoding) in vars_.items():
        ds[k].encoding.update(encoding)
    for c in ds.coords:  # CF: no empty attribute strings
        ds[c].attrs = {k: v for k, v in ds[c].attrs.items() if v != ""}
    ds.attrs = {"Conventions": "CF-1.10", "title": f"knitsweep results: {results.reduction.job_name}",
                "source": "knitsweep", "files": ", ".join(map(str, results.paths)),
                "gap_threshold_mJ": results.threshold, "partial": int(results.partial)}  # fmt: skip
    return ds
