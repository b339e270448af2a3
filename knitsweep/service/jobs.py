"""Job specs: what a sweep computes, validated before any compute starts.

A job file is TOML (see ``jobs/*.toml`` and the README's job-spec reference).
It names a grid over the stitch parameters, the directions to pull, a fidelity
preset with optional overrides, the sweep protocol, the starts and seed, and the
optional observables to store. Every value is checked when the file is loaded;
errors name the field (``grid.L_mm.step = -0.1: …``) and nothing is written.

Tasks are content-addressed (signac): a point's id is a hash of its canonical
parameters and numerical settings, a sweep's id adds the direction and protocol.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import sys
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_serializer,
    field_validator,
    model_validator,
)

from ..analysis.transitions import GAP_THRESHOLD
from ..config import (
    DEFAULT_PRESET,
    PRESETS,
    Fidelity,
    InputError,
    SolverSettings,
    StartSettings,
    StitchParams,
    SweepProtocol,
    describe_validation_error,
    preset_sections,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

JOB_SCHEMA_VERSION = 1
"""The job-file format this knitsweep reads (``schema_version`` in a job file)."""
_STRICT = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, strict=True)
MAX_POINTS = 1_000_000
MAX_JOB_FILE_BYTES = 16_000_000
"""A job file is a few hundred bytes (a list of 10^5 values ~1 MB); past this it is not one."""
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+=,@-]*$")


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
    (same number of values; e.g. ``zip = [["L_mm", "r_mm"]]``)."""

    model_config = _STRICT

    L_mm: Axis = Field(description="yarn length per stitch L (mm)")
    k_mN_per_mm2: Axis = 0.6
    B_mN_mm2: Axis = 90.0
    r_core_mm: Axis = 0.325
    r_mm: Axis = 0.74
    p: Axis = 2.4
    regularization_mN_mm4: Axis = 2.0
    twist_bound: float = 0.9
    zip: list[list[str]] = Field(
        default_factory=list, description="groups of axes that vary together, not crossed"
    )

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
        """Number of grid points (ties and zips counted as they combine)."""
        axes = self.axes()
        n = 1
        for name, values in axes.items():
            group = next((g for g in self.zip if name in g), None)
            if group is None or group[0] == name:
                n *= len(values)
        return n


class Store(BaseModel):
    """Optional observables; off unless asked (each costs time or space)."""

    model_config = _STRICT

    states: bool = Field(False, description="the 30-entry state at every strain step")
    contact_forces: bool = Field(
        False, description="contact forces by class (self, same row, NN/NNN column) per step"
    )
    geometry: bool = Field(False, description="control points (8, 6, 3) at every strain step")


class RunSettings(BaseModel):
    """How the run behaves (does not change results, so not part of the job hash)."""

    model_config = _STRICT

    task_timeout_s: float = Field(
        3600.0,
        gt=0.0,
        le=1e6,
        description="wall-time budget of one task (s, <= 1e6); beyond it: failed: timeout",
    )
    checkpoint_s: float = Field(
        10.0,
        gt=0.0,
        le=86400.0,
        description="seconds between consolidations of results into the HDF5 file (<= 1 day)",
    )
    stop_grace_s: float = Field(
        30.0,
        ge=0.0,
        le=3600.0,
        description="on SIGTERM/SIGINT, how long to wait for the workers to stop (s, <= 3600)",
    )


class AdaptiveSettings(BaseModel):
    """The adaptive search for (L/r)_trans (``mode = "adaptive"``): ``grid.L_mm`` is
    the coarse grid that brackets each series' transition, then the bracket
    shrinks below ``tolerance_mm`` (see ``knitsweep.service.adaptive``)."""

    model_config = _STRICT

    tolerance_mm: float = Field(0.005, gt=0.0, le=1.0, description="final bracket width in L (mm)")
    threshold_mJ: float = Field(
        GAP_THRESHOLD,
        gt=0.0,
        le=1.0,
        description="energy-gap threshold between jammed and unjammed (mJ, <= 1)",
    )
    secant_span_mm: float = Field(
        0.05,
        gt=0.0,
        le=10.0,
        description="shortest L span of the secant that extrapolates the gap (mm, <= 10)",
    )
    max_refinements: int = Field(40, ge=1, le=1000, description="refinements per series, at most")


class JobSpec(BaseModel):
    """A whole job. ``fidelity``, ``solver`` and ``protocol`` start from ``preset``
    and take any field given explicitly."""

    model_config = _STRICT

    schema_version: int = Field(
        description=f"job file format; this knitsweep reads {JOB_SCHEMA_VERSION}"
    )
    name: str = Field(
        min_length=1,
        max_length=200,
        description="names the default output <name>.h5: letters, digits and ._+=,@- only",
    )
    description: str = Field("", max_length=10_000)
    seed: int = Field(0, ge=0, lt=2**63)
    directions: list[Literal["x", "y"]] = Field(default_factory=lambda: ["x", "y"], min_length=1)
    preset: str = DEFAULT_PRESET
    mode: Literal["grid", "adaptive"] = Field(
        "grid", description="'grid': every grid point; 'adaptive': bisect each L series' transition"
    )
    adaptive: AdaptiveSettings = AdaptiveSettings()
    grid: Grid
    fidelity: Fidelity = Fidelity()
    solver: SolverSettings = SolverSettings()
    protocol: SweepProtocol = SweepProtocol()
    starts: StartSettings = StartSettings()
    store: Store = Store()
    run: RunSettings = RunSettings()

    @model_validator(mode="before")
    @classmethod
    def _apply_preset(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        name = data.get("preset", DEFAULT_PRESET)
        if not isinstance(name, str) or name not in PRESETS:
            return data  # reported by the field validator below
        return {**data, **preset_sections(name, data)}

    @field_validator("schema_version")
    @classmethod
    def _known_schema(cls, v: int) -> int:
        if v != JOB_SCHEMA_VERSION:
            raise ValueError(
                f"this knitsweep reads job files of schema_version {JOB_SCHEMA_VERSION}; "
                f"convert the file or use the knitsweep version that wrote it"
            )
        return v

    @field_validator("name")
    @classmethod
    def _file_name(cls, v: str) -> str:
        if not _NAME.match(v):
            raise ValueError(
                "must start with a letter or digit and hold only letters, digits and ._+=,@- "
                "(it names the output file: no path separators)"
            )
        return v

    @field_validator("preset")
    @classmethod
    def _known_preset(cls, v: str) -> str:
        if v not in PRESETS:
            raise ValueError(f"must be one of {', '.join(PRESETS)}")
        return v

    @field_validator("directions")
    @classmethod
    def _unique_directions(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("repeated direction")
        return v

    @model_validator(mode="after")
    def _valid_points(self) -> JobSpec:
        self.grid.check_ties_and_zips()
        axes = self.grid.axes()
        n = self.grid.size()
        if n > MAX_POINTS:
            raise ValueError(f"grid has {n} points, more than {MAX_POINTS}")
        for name, values in axes.items():
            for v in values:  # each value alone first, for a message naming the axis
                try:
                    StitchParams(**{name: v})
                except ValidationError as e:
                    if name not in ("r_core_mm", "r_mm"):
                        raise ValueError(f"grid.{describe_validation_error(e)}") from None
        self.points()  # every combination (r_core < r) is a valid stitch
        if self.mode == "adaptive":
            zipped = any("L_mm" in g for g in self.grid.zip)
            if "L_mm" not in axes or zipped:
                raise ValueError("mode = 'adaptive' refines each series along grid.L_mm: L_mm "
                                 "cannot be tied or zipped")  # fmt: skip
            if len(axes["L_mm"]) < 2:
                raise ValueError("mode = 'adaptive' needs at least 2 coarse values in grid.L_mm")
        return self

    def points(self) -> list[StitchParams]:
        """Every grid point, in a fixed order (k, B, r_core, r, p, reg, then L)."""
        order = ("k_mN_per_mm2", "B_mN_mm2", "r_core_mm", "r_mm", "p", "regularization_mN_mm4",
                 "L_mm")  # fmt: skip
        out = []
        for values in self.grid.combinations(order):
            try:
                out.append(StitchParams(twist_bound=self.grid.twist_bound, **values))
            except ValidationError as e:
                where = ", ".join(f"{k}={v}" for k, v in values.items())
                raise ValueError(f"grid point ({where}): {describe_validation_error(e)}") from None
        return out

    def canonical(self) -> dict[str, Any]:
        """Everything that determines the results (name, description and run
        settings excluded), with effective settings after the preset."""
        d = self.model_dump(mode="json", exclude={"name", "description", "run", "preset"})
        d["grid"] = self.grid.axes() | {"twist_bound": self.grid.twist_bound}
        ties = {n: str(tie) for n, tie in self.grid.ties().items()}
        if ties:  # (absent when empty: the hashes of plain grids stay what they were)
            d["grid"]["ties"] = ties
        if self.grid.zip:
            d["grid"]["zip"] = self.grid.zip
        return d

    @property
    def job_hash(self) -> str:
        return digest(self.canonical())


def canonical_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def digest(obj: Any, n: int = 16) -> str:
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:n]


@dataclass(frozen=True)
class PointTask:
    """Zero-force relaxation of one grid point (shared by its sweeps)."""

    task_id: str
    params: StitchParams
    seed: int


@dataclass(frozen=True)
class SweepTask:
    """One strain sweep: a point's zero-force state pulled in one direction."""

    task_id: str
    point_id: str
    direction: str


def _numerics(job: JobSpec) -> dict[str, Any]:
    return {
        "fidelity": job.fidelity.model_dump(mode="json"),
        "solver": job.solver.model_dump(mode="json"),
        "starts": job.starts.model_dump(mode="json"),
        "seed": job.seed,
    }


def point_task(job: JobSpec, params: StitchParams) -> PointTask:
    """The zero-force task of one point; its id hashes the parameters and numerics."""
    pid = digest({"params": params.model_dump(mode="json"), **_numerics(job)})
    seed = int(hashlib.sha256(f"{job.seed}:{pid}".encode()).hexdigest()[:15], 16)
    return PointTask(pid, params, seed)


def sweep_task(job: JobSpec, point_id: str, direction: str) -> SweepTask:
    sid = digest({"point": point_id, "direction": direction,
                  "protocol": job.protocol.model_dump(mode="json")})  # fmt: skip
    return SweepTask(sid, point_id, direction)


def plan(job: JobSpec) -> tuple[list[PointTask], list[SweepTask]]:
    """All tasks of a grid job (for an adaptive job: its coarse grid): one
    zero-force task per point, one sweep per (point, direction). Ids hash the
    canonical parameters, never file names."""
    points, sweeps = [], []
    for params in job.points():
        p = point_task(job, params)
        points.append(p)
        sweeps.extend(sweep_task(job, p.task_id, d) for d in job.directions)
    return points, sweeps


def load_job(path: str | Path) -> JobSpec:
    """Read and validate a TOML job file; every problem is one ``InputError`` naming
    the file and the field (also for binary, non-UTF-8 and absurdly nested files)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            raw = f.read(MAX_JOB_FILE_BYTES + 1)
    except OSError as e:
        raise InputError(f"job file {path}: {e.strerror or e}") from None
    if len(raw) > MAX_JOB_FILE_BYTES:
        raise InputError(f"job file {path}: larger than {MAX_JOB_FILE_BYTES} bytes, not a job file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"job file {path}: not UTF-8 text (byte {e.start}); save it as UTF-8 "
                         "TOML") from None  # fmt: skip
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"job file {path}: not valid TOML: {e}") from None
    except RecursionError:
        raise InputError(f"job file {path}: not a job file (nested too deeply)") from None
    try:
        return JobSpec(**data)
    except ValidationError as e:
        raise InputError(f"job file {path}: {describe_validation_error(e, JobSpec)}") from None
    except RecursionError:
        raise InputError(f"job file {path}: not a job file (nested too deeply)") from None
