"""Plain Python values from numpy's, HDF5's and dataclasses' (one converter for every
layer: records, journal entries, tables, JSON)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any


def plain_value(v: Any, *, finite: bool = False, strict: bool = False) -> Any:
    """``v`` in plain Python values, the one converter of every layer: numpy scalars and
    0-d arrays as Python scalars, bytes as str, arrays, lists and tuples as lists,
    dicts (keys as str) and dataclasses as dicts, recursively.

    ``finite``: non-finite floats become None (JSON and tables). ``strict``: TypeError
    for anything that is not then None, bool, int, float, str, list or dict (what a
    journal entry may hold)."""
    if isinstance(v, bytes):  # an attribute of a foreign or damaged file may not be UTF-8
        return v.decode("utf-8", "backslashreplace")
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        v = {f.name: getattr(v, f.name) for f in dataclasses.fields(v)}
    if isinstance(v, dict):
        return {str(k): plain_value(x, finite=finite, strict=strict) for k, x in v.items()}
    if hasattr(v, "item") and getattr(v, "ndim", None) == 0:
        v = v.item()
    elif isinstance(v, (list, tuple)) or (hasattr(v, "tolist") and getattr(v, "ndim", 0) > 0):
        return [plain_value(x, finite=finite, strict=strict) for x in v]
    if finite and isinstance(v, float) and not math.isfinite(v):
        return None
    if strict and not (v is None or isinstance(v, (bool, int, float, str))):
        raise TypeError(f"not a plain value: {type(v).__name__}")
    return v
