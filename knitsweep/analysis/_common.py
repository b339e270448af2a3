"""Shared helpers of the analysis layer: input checks and plain-value export.

Every public function of ``knitsweep.analysis`` checks its inputs here, so that a
bad array fails with a ``ValueError`` that names the argument, and every result
dataclass inherits :class:`PlainDict` so that ``as_dict()`` gives JSON-ready plain
Python values (float, int, bool, str, None, lists and dicts of those), never NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..paths import load_path
from ..util.plain_values import plain_value


def to_plain(value: Any) -> Any:
    """``value`` in plain Python values, non-finite floats as None
    (``config.plain_value``)."""
    return plain_value(value, finite=True)


class PlainDict:
    """Mixin for the frozen result dataclasses: ``as_dict()`` with plain values."""

    def as_dict(self) -> dict[str, Any]:
        """Fields as plain floats/ints/bools/strings/lists; None where not available."""
        return to_plain(self)


def check_array(
    name: str, values: Any, *, min_size: int = 1, allow_inf: bool = False
) -> np.ndarray:
    """Return ``values`` as a 1-D float array; ValueError naming ``name`` otherwise.

    Refuses non-numeric input, arrays that are not 1-D, fewer than ``min_size``
    entries, and NaN or infinite entries (with the index of the first bad one);
    ``allow_inf`` lets +inf through.
    """
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a 1-D array of numbers") from None
    if a.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array, got shape {a.shape}")
    if a.size < min_size:
        raise ValueError(f"{name}: needs at least {min_size} value(s), got {a.size}")
    ok = np.isfinite(a) | ((a == np.inf) if allow_inf else False)
    bad = np.flatnonzero(~ok)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{name}: entry {i} is {float(a[i])!r}; all entries must be finite numbers"
        )
    return a


def check_same_length(**arrays: np.ndarray) -> int:
    """Common length of the named arrays; ValueError listing the lengths otherwise."""
    lengths = {name: a.shape[0] for name, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        listing = ", ".join(f"{name}: {n}" for name, n in lengths.items())
        raise ValueError(f"arrays of one sweep must have the same length ({listing})")
    return next(iter(lengths.values()))


def check_increasing(name: str, a: np.ndarray) -> None:
    """ValueError naming ``name`` unless ``a`` is strictly increasing."""
    steps = np.diff(a)
    bad = np.flatnonzero(steps <= 0.0)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{name}: must be strictly increasing, but entry {i + 1} ({float(a[i + 1])!r}) "
            f"does not exceed entry {i} ({float(a[i])!r})"
        )


def check_scalar(name: str, value: Any, *, positive: bool = False) -> float:
    """Return ``value`` as a finite float (> 0 if ``positive``); ValueError otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: expected a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} = {v!r}: must be finite")
    if positive and v <= 0.0:
        raise ValueError(f"{name} = {v!r}: must be > 0")
    return v


def check_direction(direction: Any) -> str:
    """Return ``direction`` if it names a load path ('x', 'y', 'biaxial', …); ValueError
    listing them otherwise."""
    return load_path(direction).name


def check_int(name: str, value: int, minimum: int) -> int:
    """Return ``value`` as an int ≥ ``minimum``; ValueError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} = {value!r}: must be an integer >= {minimum}")
    return int(value)


def check_strain_stress(strain: Any, stress: Any) -> tuple[np.ndarray, np.ndarray]:
    """Checked float copies of a sweep's strain (strictly increasing) and stress."""
    eps = check_array("strain", strain)
    sig = check_array("stress", stress)
    check_same_length(strain=eps, stress=sig)
    check_increasing("strain", eps)
    return eps, sig
