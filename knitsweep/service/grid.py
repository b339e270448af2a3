"""The parameter grid of a job: numbers, lists, ``{start, stop, step}`` ranges, ties
(``r_core_mm = "0.45 * r_mm"``), zipped axes and the stitches, and the grid points they
make.
Validated when a job file is read (``jobs.JobSpec`` checks each point as a stitch).
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_serializer,
    field_validator,
    model_serializer,
    model_validator,
)

from ..errors import InputError, describe_validation_error
from ..stitches import STITCH_CHOICES, check_stitch_name, unknown_stitch
from ..stitches.chart import chart_stitch_names

_STRICT = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, strict=True)
MAX_POINTS = 1_000_000
"""Most values of one axis, and most grid points."""


class Range(BaseModel):
    """Inclusive range ``start, start + step, …, <= stop`` (decimal arithmetic, so
    0.1 steps give 11.6, not 11.600000000000001)."""

    model_config = _STRICT

    start: float
    stop: float
    step: float = Field(gt=0.0)

    @model_validator(mode="after")
    def _ordered(self) -> Range:
        if self.stop < self.start:
            raise ValueError(f"empty range: stop {self.stop} < start {self.start}")
        if (self.stop - self.start) / self.step > MAX_POINTS:
            raise ValueError(f"more than {MAX_POINTS} values")
        return self

    def values(self) -> list[float]:
        start, stop, step = (Decimal(repr(v)) for v in (self.start, self.stop, self.step))
        n = int((stop - start) / step + Decimal("1e-9"))
        return [float(start + i * step) for i in range(n + 1)]


GRID_PARAMETERS = ("L_mm", "k_mN_per_mm2", "B_mN_mm2", "r_core_mm", "r_mm", "p",
                   "regularization_mN_mm4")  # fmt: skip
"""The stitch parameters a grid can vary."""

_TIE = re.compile(r"\s*(?:(?P<f1>[0-9.eE+-]+)\s*\*\s*)?(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
                  r"(?:\s*\*\s*(?P<f2>[0-9.eE+-]+))?\s*")  # fmt: skip


@dataclass(frozen=True)
class Tie:
    """A parameter tied to another: value = ``factor`` × the value of ``to``."""

    factor: float
    to: str

    def __str__(self) -> str:
        return f"{self.factor!r} * {self.to}"


def parse_tie(text: str) -> Tie:
    """'0.45 * r_mm', 'r_mm * 0.45' or 'r_mm' -> Tie; ValueError naming the form."""
    m = _TIE.fullmatch(text)
    factor_text = None if m is None else (m["f1"] or m["f2"])
    if m is None or (m["f1"] and m["f2"]):
        raise ValueError(f"{text!r}: a tie is '<number> * <parameter>', e.g. '0.45 * r_mm'")
    try:
        factor = 1.0 if factor_text is None else float(factor_text)
    except ValueError:
        raise ValueError(f"{text!r}: {factor_text!r} is not a number") from None
    if not (math.isfinite(factor) and factor > 0.0):
        raise ValueError(f"{text!r}: the factor must be a finite number > 0")
    if m["name"] not in GRID_PARAMETERS:
        raise ValueError(f"{text!r}: {m['name']!r} is not one of {', '.join(GRID_PARAMETERS)}")
    return Tie(factor, m["name"])


Axis = float | list[float] | Range | Tie


def _axis_values(axis: Axis) -> list[float]:
    if isinstance(axis, Range):
        return axis.values()
    if isinstance(axis, list):
        return list(axis)
    return [axis]


class Grid(BaseModel):
    """The parameter grid, in the paper's units. Each entry is a number, a list, a
    ``{start, stop, step}`` range, or a tie to another entry (``r_core_mm = "0.45 *
    r_mm"``: r_core follows r). The grid is the Cartesian product of its axes, where
    the axes named together in one ``zip`` group count as one axis and vary together
    (same number of values; e.g. ``zip = [["L_mm", "r_mm"]]``). ``stitch`` is one more
    axis, of names (``stitch = ["stockinette", "garter"]``: every point for each stitch;
    never tied or zipped); ``axes`` and ``combinations`` hold the numbers only and
    ``JobSpec.points`` crosses them with the stitches."""

    model_config = _STRICT

    L_mm: Axis = Field(description="yarn length per stitch L (mm)")
    k_mN_per_mm2: Axis = 0.6
    B_mN_mm2: Axis = 90.0
    r_core_mm: Axis = 0.325
    r_mm: Axis = 0.74
    p: Axis = 2.4
    regularization_mN_mm4: Axis = 2.0
    twist_bound: float = 0.9
    stitch: tuple[str, ...] | None = Field(
        None,
        description="stitch pattern(s): a name or a list of distinct names, one of "
        f"{STITCH_CHOICES}; every point is computed for every stitch",
    )
    zip: list[list[str]] = Field(
        default_factory=list, description="groups of axes that vary together, not crossed"
    )

    @model_validator(mode="before")
    @classmethod
    def _charts_are_stitches(cls, data: Any) -> Any:
        """``chart``: a knit/purl chart (rows of K and P, bottom first) or a list of
        charts, each one more stitch of the axis ``stitch`` (``chart:KKPP``,
        ``stitches.chart``)."""
        if not isinstance(data, dict) or "chart" not in data:
            return data
        data = dict(data)
        try:
            charts = chart_stitch_names(data.pop("chart"), "grid.chart")
        except InputError as e:
            raise ValueError(str(e)) from None
        given = data.get("stitch")
        stitches = [] if given is None else [given] if isinstance(given, str) else list(given)
        data["stitch"] = [*stitches, *charts]
        return data

    @field_validator("stitch", mode="before")
    @classmethod
    def _parse_stitches(cls, v: Any) -> Any:
        """A stitch name or a non-empty list of distinct names -> a tuple of names."""
        if v is None:
            return v
        names = [v] if isinstance(v, str) else v
        if not isinstance(names, (list, tuple)) or not names:
            raise ValueError(f"expected a stitch name or a non-empty list of names, one of "
                             f"{STITCH_CHOICES}")  # fmt: skip
        for name in names:
            why = unknown_stitch(name)
            if why is not None:
                raise ValueError(f"{name!r} is not a stitch: {why}")
        names = [check_stitch_name(name) for name in names]  # charts spelled canonically
        if len(set(names)) != len(names):
            raise ValueError("repeated values")
        return tuple(names)

    @model_serializer(mode="wrap")
    def _without_default_stitch(self, handler: Any) -> dict[str, Any]:
        # absent unless given: the job_json of every job without it stays as it was
        out = handler(self)
        if out.get("stitch") is None:
            out.pop("stitch", None)
        return out

    @field_validator(*GRID_PARAMETERS, mode="before")
    @classmethod
    def _parse_axis(cls, v: Any) -> Any:
        """A number, a non-empty list of distinct numbers, a {start, stop, step}
        table, or a tie '<number> * <parameter>'."""
        if isinstance(v, dict):
            try:
                return Range(**v)
            except ValidationError as e:
                raise ValueError(describe_validation_error(e, Range)) from None
        if isinstance(v, list):
            if not v:
                raise ValueError("empty list: give at least one value")
            if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                raise ValueError("a list of numbers is expected")
            if not all(math.isfinite(x) for x in v):
                raise ValueError("every value must be a finite number")
            if len(set(v)) != len(v):
                raise ValueError("repeated values")
            return [float(x) for x in v]
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            if not math.isfinite(v):
                raise ValueError("must be a finite number")
            return float(v)
        if isinstance(v, str):
            return parse_tie(v)
        if isinstance(v, (Range, Tie)):
            return v
        raise ValueError(
            "expected a number, a list of numbers, {start, stop, step} or a tie such as "
            "'0.45 * r_mm'"
        )

    def check_ties_and_zips(self) -> None:
        """ValueError unless every tie follows an untied axis and every zip group
        names distinct, untied axes of equal length (called by ``JobSpec``, so that
        the message is not prefixed with the whole grid)."""
        for name, tie in self.ties().items():
            if tie.to == name:
                raise ValueError(f"grid.{name} = '{tie}': a parameter cannot follow itself")
            if isinstance(getattr(self, tie.to), Tie):
                raise ValueError(f"grid.{name} = '{tie}': grid.{tie.to} is itself tied; tie "
                                 f"both to one parameter")  # fmt: skip
        seen: set[str] = set()
        for group in self.zip:
            unknown = [n for n in group if n not in GRID_PARAMETERS]
            if unknown:
                raise ValueError(f"grid.zip: {unknown[0]!r} is not one of "
                                 f"{', '.join(GRID_PARAMETERS)}")  # fmt: skip
            if len(group) < 2 or len(set(group)) != len(group):
                raise ValueError(f"grid.zip: {group} must name two or more different axes")
            if seen & set(group):
                raise ValueError(f"grid.zip: {sorted(seen & set(group))[0]!r} is in two groups")
            seen |= set(group)
            tied = [n for n in group if isinstance(getattr(self, n), Tie)]
            if tied:
                raise ValueError(f"grid.zip: grid.{tied[0]} is tied; zip the axis it follows")
            lengths = {n: len(_axis_values(getattr(self, n))) for n in group}
            if len(set(lengths.values())) > 1:
                listing = ", ".join(f"{n}: {k}" for n, k in lengths.items())
                raise ValueError(f"grid.zip: {group} need the same number of values ({listing})")

    @field_serializer(*GRID_PARAMETERS, mode="wrap")
    def _write_axis(self, v: Any, handler: Any) -> Any:
        return str(v) if isinstance(v, Tie) else handler(v)

    def ties(self) -> dict[str, Tie]:
        """The tied parameters: name -> Tie."""
        return {n: getattr(self, n) for n in GRID_PARAMETERS if isinstance(getattr(self, n), Tie)}

    def axes(self) -> dict[str, list[float]]:
        """The values of every parameter that is not tied (zipped ones included)."""
        return {n: _axis_values(getattr(self, n)) for n in GRID_PARAMETERS
                if not isinstance(getattr(self, n), Tie)}  # fmt: skip

    def combinations(self, order: tuple[str, ...] = GRID_PARAMETERS) -> list[dict[str, float]]:
        """Every grid point as {parameter: value} (ties applied), in a fixed order:
        the product over ``order``, a zip group where its first member comes."""
        axes = self.axes()
        groups: list[tuple[str, ...]] = []
        for name in order:
            if name not in axes or any(name in g for g in groups):
                continue
            group = next((tuple(g) for g in self.zip if name in g), (name,))
            groups.append(group)
        values = [list(zip(*(axes[n] for n in g), strict=True)) for g in groups]
        out = []
        for combo in itertools.product(*values):
            point = {n: v for g, vs in zip(groups, combo, strict=True)
                     for n, v in zip(g, vs, strict=True)}  # fmt: skip
            for name, tie in self.ties().items():  # 12 digits: 0.297, not 0.29700000000000004
                point[name] = float(f"{tie.factor * point[tie.to]:.12g}")
            out.append({n: point[n] for n in order})
        return out

    def size(self) -> int:
        """Number of grid points (ties and zips counted as they combine), times the
        number of stitches of ``stitch``."""
        axes = self.axes()
        n = len(self.stitch) if self.stitch is not None else 1
        for name, values in axes.items():
            group = next((g for g in self.zip if name in g), None)
            if group is None or group[0] == name:
                n *= len(values)
        return n
