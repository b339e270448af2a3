"""The results file's format: its schema version, where its parts live, and how a
task's record becomes an HDF5 group and back (docs/results-file.md).

A record's arrays become datasets, its scalars attributes of the task's group; every
dataset carries ``units`` and ``long_name`` and labelled dimension scales
(``knitsweep.quantities``). ``store.writer`` writes files in this format,
``store.read`` reads them.
"""

from __future__ import annotations

import json
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from ..stitches import DEFAULT_STITCH
from .checksum import DIGEST_ATTRS, Damaged, FileCheck, read_verified

RESULTS_SCHEMA_VERSION = 3
"""The results-file format this knitsweep writes (3: a table per kind, ``store.table``;
2: a group per task)."""
READABLE_SCHEMAS = (1, 2, 3)
"""Results-file formats this knitsweep reads."""
REWRITABLE_SCHEMAS = (2, 3)
"""… and can rewrite whole into a new file (``merge``, ``recover``): those whose records
read back exactly (schema 1 kept fewer fields)."""
POINTS, SWEEPS, SERIES = "points", "sweeps", "series"
KINDS = (POINTS, SWEEPS, SERIES)
_STR = None  # h5py string dtype, created lazily


def now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def journal_dir(path: Path) -> Path:
    return path.with_name(path.name + ".journal")


def progress_path(path: Path) -> Path:
    return path.with_name(path.name + ".progress.json")


def lock_path(path: Path) -> Path:
    return path.with_name(path.name + ".lock")


def _h5():
    import h5py

    return h5py


def _string_dtype():
    global _STR
    if _STR is None:
        _STR = _h5().string_dtype()
    return _STR


def split_record(record: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(arrays, scalars) of a task's record: what becomes datasets and what becomes
    attributes of its group."""
    arrays = {k: v for k, v in record.items() if isinstance(v, np.ndarray) and v.ndim > 0}
    return arrays, {k: v for k, v in record.items() if k not in arrays}


RENAMED = {"energy_gap": "jamming_gap"}
"""Record names that files and journal entries of earlier versions used: old -> new."""


def renamed(values: dict[str, Any]) -> dict[str, Any]:
    """``values`` (a record or its attributes, as read) under today's names."""
    for old, new in RENAMED.items():
        if old in values and new not in values:
            values[new] = values.pop(old)
    return values


def attr_value(value: Any) -> Any:
    """A record's scalar as stored: bool, int, float or str (a dict as sorted JSON);
    None for no value."""
    if value is None:
        return None
    if isinstance(value, dict):
        return json.dumps(value, sort_keys=True)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    return str(value)


_LEADING_DIM = {"start": "start of the zero-force relaxation",
                "step": "strain step (0: the zero-force state)"}  # fmt: skip


def describe_dataset(group, kind: str, name: str) -> None:
    """``units``, ``long_name`` and dimension scales of dataset ``name`` (xarray and
    netCDF readers then see named dimensions and coordinates)."""
    from ..quantities import TRAILING_DIMS, axis_labels, dataset_quantity, leading_dimension

    ds = group[name]
    q = dataset_quantity(kind, name)
    ds.attrs["units"] = q.units if q else "1"
    ds.attrs["long_name"] = q.long_name if q else name.replace("_", " ")
    trailing = TRAILING_DIMS.get(name, ())
    dims = list(trailing[-(ds.ndim) :]) if ds.ndim <= len(trailing) else list(trailing)
    if ds.ndim > len(trailing) and kind in (POINTS, SWEEPS):
        dims = [leading_dimension(kind, name), *dims]
    if len(dims) != ds.ndim:
        return
    for axis, dim in enumerate(dims):
        scale = group.get(dim)
        if scale is None:
            labels = axis_labels(dim, str(group.attrs.get("stitch", DEFAULT_STITCH)))
            if labels is None:  # the leading dimension: 0 … n-1
                scale = group.create_dataset(dim, data=np.arange(ds.shape[axis]))
                scale.attrs["long_name"] = _LEADING_DIM[dim]
            else:
                scale = group.create_dataset(dim, data=np.array(labels, dtype=object),
                                             dtype=_string_dtype())  # fmt: skip
                scale.attrs["long_name"] = dim.replace("_", " ")
            scale.attrs["units"] = "1"
            scale.make_scale(dim)
        if scale.shape[0] == ds.shape[axis]:
            ds.dims[axis].attach_scale(scale)


def _read_group(group, with_data: bool = True) -> tuple[dict[str, Any], dict[str, Any]]:
    """(meta, record) of a task group, unchecked (``read_task`` checks it first)."""
    return _contents(*raw_group(group, with_data))


def raw_group(group, with_data: bool = True) -> tuple[dict[str, Any], dict[str, Any]]:
    """(attributes, dataset values) of a task group as HDF5 gives them, unchecked
    (dimension scales and the digest attributes left out)."""
    attrs = {k: v for k, v in group.attrs.items() if k not in DIGEST_ATTRS}
    data = {}
    if with_data:
        data = {
            k: ds[()]
            for k, ds in group.items()
            if isinstance(ds, _h5().Dataset) and not ds.is_scale
        }  # fmt: skip  (scales: coordinates)
    return attrs, data


def _contents(attrs: dict[str, Any], data: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(meta, record) from a group's attributes and dataset values as HDF5 gave them."""
    meta = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in attrs.items()}
    record = {}
    for k, v in data.items():
        if isinstance(v, np.ndarray) and v.dtype.kind == "O":
            v = np.array([s.decode() if isinstance(s, bytes) else s for s in v], dtype=object)
        record[k] = v
    return renamed(meta), record


def read_task(group, with_data: bool, check: FileCheck | None = None):
    """(meta, record) of a task group after its checksum is verified (``record`` empty
    unless ``with_data``); None if it is damaged, which ``check`` then records."""
    kind, tid = group.name.strip("/").split("/")[:2]
    try:
        verified, attrs, data = read_verified(group)
        meta, record = _contents(attrs, data if with_data else {})
    except Damaged as e:
        if check is not None:
            check.damaged.append((kind, tid, str(e)))
        return None
    except Exception as e:  # e.g. undecodable bytes that no checksum covered
        if check is not None:
            check.damaged.append((kind, tid, f"unreadable ({type(e).__name__})"))
        return None
    if check is not None:
        if verified:
            check.verified += 1
        else:
            check.unverified += 1
    return meta, record
