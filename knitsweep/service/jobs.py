"""Job specs: what a sweep computes, validated before any compute starts.

A job file is TOML (see ``jobs/*.toml`` and docs/job-files.md).
It names a grid over the stitch parameters, the directions to pull, a fidelity
preset with optional overrides, the sweep protocol, the starts and seed, and the
optional observables to store. Every value is checked when the file is loaded;
errors name the field (``grid.L_mm.step = -0.1: …``) and nothing is written.

Tasks are content-addressed (signac): a point's id is a hash of its canonical
parameters and numerical settings, a sweep's id adds the direction and protocol.
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_serializer,
    model_validator,
)

from ..analysis.transitions import GAP_THRESHOLD
from ..config import (
    Direction,
    Fidelity,
    InputError,
    SolverSettings,
    StartSettings,
    StitchName,
    StitchParams,
    SweepProtocol,
    zero_force_solvers,
)
from ..errors import MAX_SEED, describe_validation_error
from ..paths import check_path_for_stitch
from ..presets import DEFAULT_PRESET, PRESETS, preset_sections
from ..stitches import DEFAULT_STITCH, STITCH_CHOICES, get_stitch
from ..stitches.chart import chart_stitch_names
from ..util.safe_files import read_text
from .grid import MAX_POINTS, Grid
from .id_forms import FIDELITY_FORMS, PARAMS_FORMS, STARTS_FORMS, id_form, protocol_id_form

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

JOB_SCHEMA_VERSION = 1
"""The job-file format this knitsweep reads (``schema_version`` in a job file)."""
_STRICT = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, strict=True)
MAX_JOB_FILE_BYTES = 16_000_000
"""A job file is a few hundred bytes (a list of 10^5 values ~1 MB); past this it is not one."""
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+=,@-]*$")


class Store(BaseModel):
    """Optional observables; off unless asked (each costs time or space)."""

    model_config = _STRICT

    states: bool = Field(
        False, description="the state (n_state entries: 30 for stockinette) at every strain step"
    )
    contact_forces: bool = Field(
        False, description="contact forces by class (self, same row, NN/NNN column) per step"
    )
    geometry: bool = Field(
        False, description="control points (n_segments, 6, 3) at every strain step"
    )
    packing_fraction: bool = Field(
        False, description="packing fraction φ (quasi-Monte Carlo over the tube) of every state"
    )


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
    last_crossing: bool = Field(
        False,
        description="also refine where a re-entrant series (jammed again beyond its first "
        "crossing, the paper's (L/r)_trans) unjams for good: its last crossing",
    )


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
    seed: int = Field(0, ge=0, lt=MAX_SEED)
    directions: list[Direction] = Field(
        default_factory=lambda: ["x", "y"],
        min_length=1,
        description="the load paths each point is swept along (knitsweep.paths): 'x', 'y' "
        "(uniaxial, the paper's), 'biaxial' (equibiaxial), 'strip_x', 'strip_y' (one period "
        "pulled, the other held), 'shear', 'shear_free' (simple shear, the periods held or "
        "relaxed; free yarns only), 'ray:<rate_x>,<rate_y>[,<rate_xy>]'",
    )
    preset: str = DEFAULT_PRESET
    stitch: StitchName = Field(
        DEFAULT_STITCH,
        description=f"stitch pattern of every point: one of {STITCH_CHOICES} "
        "(several: the grid axis grid.stitch)",
    )
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

    @model_validator(mode="before")
    @classmethod
    def _chart_is_the_stitch(cls, data: Any) -> Any:
        """``chart = ["KKPP"]``: the stitch of every point is that knit/purl chart
        (``chart:KKPP``; several charts: ``[grid] chart``)."""
        if not isinstance(data, dict) or "chart" not in data:
            return data
        data = dict(data)
        chart = data.pop("chart")
        if "stitch" in data:
            raise ValueError(f"chart = {chart!r} and stitch = {data['stitch']!r}: give the "
                             "stitch in one place")  # fmt: skip
        try:
            names = chart_stitch_names(chart, "chart")
        except InputError as e:
            raise ValueError(str(e)) from None
        if len(names) > 1:
            raise ValueError("chart: one chart here; several charts are a grid axis: "
                             "[grid] chart = [[...], [...]]")  # fmt: skip
        data["stitch"] = names[0]
        return data

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

    @model_serializer(mode="wrap")
    def _stitch_once(self, handler: Any) -> dict[str, Any]:
        # with the grid axis grid.stitch, the one-stitch field is not written (job_json
        # then reads back as the same job)
        out = handler(self)
        if self.grid.stitch is not None:
            out.pop("stitch", None)
        return out

    @field_validator("stitch", mode="before")
    @classmethod
    def _one_stitch(cls, v: Any) -> Any:
        if isinstance(v, (list, tuple)):
            raise ValueError("one stitch name here; several stitches are a grid axis: "
                             "[grid] stitch = [...]")  # fmt: skip
        return v

    @field_validator("directions")
    @classmethod
    def _unique_directions(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError("repeated direction")
        return v

    @model_validator(mode="after")
    def _valid_points(self) -> JobSpec:
        if self.grid.stitch is not None and "stitch" in self.model_fields_set:
            raise ValueError(f"stitch = {self.stitch!r} and grid.stitch = "
                             f"{list(self.grid.stitch)}: give the stitch in one place")  # fmt: skip
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
        for stitch in self.stitches:
            for d in self.directions:
                try:
                    check_path_for_stitch(d, stitch)
                except ValueError as e:
                    raise ValueError(f"directions: {e}") from None
        if self.mode == "adaptive":
            zipped = any("L_mm" in g for g in self.grid.zip)
            if "L_mm" not in axes or zipped:
                raise ValueError("mode = 'adaptive' refines each series along grid.L_mm: L_mm "
                                 "cannot be tied or zipped")  # fmt: skip
            if len(axes["L_mm"]) < 2:
                raise ValueError("mode = 'adaptive' needs at least 2 coarse values in grid.L_mm")
        return self

    @property
    def stitches(self) -> tuple[str, ...]:
        """The stitches every grid point is computed for: ``grid.stitch``, else the
        one ``stitch``."""
        return self.grid.stitch if self.grid.stitch is not None else (self.stitch,)

    def solver_notes(self) -> list[str]:
        """Where the job's minimiser does not relax a stitch's zero-force states alone,
        which ones do and why (``config.zero_force_solvers``), one line a stitch: what a
        run says before it computes."""
        notes = (zero_force_solvers(name, self.solver.method) for name in self.stitches)
        return [note for note in notes if note]

    def points(self) -> list[StitchParams]:
        """Every grid point, in a fixed order (stitch, k, B, r_core, r, p, reg, then L)."""
        order = ("k_mN_per_mm2", "B_mN_mm2", "r_core_mm", "r_mm", "p", "regularization_mN_mm4",
                 "L_mm")  # fmt: skip
        out = []
        combinations = self.grid.combinations(order)
        for stitch in self.stitches:
            for values in combinations:
                try:
                    out.append(StitchParams(twist_bound=self.grid.twist_bound, stitch=stitch,
                                            **values))  # fmt: skip
                except ValidationError as e:
                    where = ", ".join(f"{k}={v}" for k, v in values.items())
                    raise ValueError(f"grid point ({where}): "
                                     f"{describe_validation_error(e)}") from None  # fmt: skip
        return out

    def full_form(self) -> dict[str, Any]:
        """Everything that determines the results (name, description and run settings
        excluded), with effective settings after the preset, every field written: the
        job format's newest form (``id_forms.FORM_VERSION``)."""
        d = self.model_dump(mode="json", exclude={"name", "description", "run", "preset"})
        d.pop("stitch", None)  # one stitch where it was before, several as an axis of the grid
        stitches = self.stitches
        d["fidelity"] = fidelity_dump(self.fidelity, stitches)
        d["grid"] = self.grid.axes() | {"twist_bound": self.grid.twist_bound}
        if len(stitches) == 1:
            d["stitch"] = stitches[0]
        else:
            d["grid"]["stitch"] = list(stitches)
        d["grid"]["ties"] = {n: str(tie) for n, tie in self.grid.ties().items()}
        d["grid"]["zip"] = self.grid.zip
        return d

    def unread_settings(self) -> tuple[str, ...]:
        """Paths of the canonical form (``full_form``) that this job's results do not
        depend on: ``fidelity.contact_sampling`` when none of its stitches is a free yarn
        (the ansatz samples by parameter whatever it says), so that such a job's file
        can grow by a free yarn, whose placement the setting then resolves."""
        return () if _has_free_yarn(self.stitches) else ("fidelity.contact_sampling",)

    def canonical(self) -> dict[str, Any]:
        """The dict the job's id hashes: its full form migrated down to the earliest
        form of the job format that holds it (``id_forms.id_form``), so that a job
        using nothing a later form added keeps the id it had then."""
        return id_form(self.full_form())

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
    carried_from: str | None = None
    """With ``[starts] carry``: the id of the point whose zero-force state this one
    starts from (its series neighbour of next larger L); None: the shipped starts."""


@dataclass(frozen=True)
class SweepTask:
    """One strain sweep: a point's zero-force state pulled in one direction."""

    task_id: str
    point_id: str
    direction: str


def params_form(params: StitchParams, **exclude: Any) -> dict[str, Any]:
    """A point's parameters as task ids hash them: their id form
    (``id_forms.PARAMS_FORMS``; ``exclude`` as ``model_dump``'s)."""
    return PARAMS_FORMS.id_form(params.model_dump(mode="json", **exclude))


def fidelity_dump(fidelity: Fidelity, stitches: tuple[str, ...]) -> dict[str, Any]:
    """``fidelity`` dumped with its 'auto' contact sampling resolved for ``stitches``:
    'yarn_arclength' where one of them is a free yarn, else 'parameter' (what the ansatz
    always uses), so that the ansatz's jobs and tasks keep the ids they had before the
    setting existed and a free yarn's hash what it computes."""
    d = fidelity.model_dump(mode="json")
    if d["contact_sampling"] == "auto":
        d["contact_sampling"] = fidelity.sampling_for(_has_free_yarn(stitches))
    return d


def _has_free_yarn(stitches: tuple[str, ...]) -> bool:
    """Whether one of ``stitches`` is a free yarn (has a gauge: its contact sampling is
    the setting's; the ansatz's is always by parameter)."""
    return any(get_stitch(name).gauge is not None for name in stitches)


def fidelity_form(fidelity: Fidelity, stitch: str) -> dict[str, Any]:
    """The fidelity as the ids of a ``stitch``'s tasks and series hash it: its id form
    (``id_forms.FIDELITY_FORMS``) with 'auto' resolved (``fidelity_dump``)."""
    return FIDELITY_FORMS.id_form(fidelity_dump(fidelity, (stitch,)))


def _numerics(job: JobSpec, stitch: str) -> dict[str, Any]:
    return {
        "fidelity": fidelity_form(job.fidelity, stitch),
        "solver": job.solver.model_dump(mode="json"),
        "starts": STARTS_FORMS.id_form(job.starts.model_dump(mode="json")),
        "seed": job.seed,
    }


def point_task(job: JobSpec, params: StitchParams, carried_from: str | None = None) -> PointTask:
    """The zero-force task of one point; its id hashes the parameters and numerics
    and, for a carried point, the id of the point it starts from (and so the chain of
    its series up to it)."""
    what = {"params": params_form(params), **_numerics(job, params.stitch)}
    if carried_from is not None:
        what["carried_from"] = carried_from
    pid = digest(what)
    seed = int(hashlib.sha256(f"{job.seed}:{pid}".encode()).hexdigest()[:15], 16)
    return PointTask(pid, params, seed, carried_from)


def series_key(params: StitchParams) -> str:
    """The series a point belongs to: its parameters but L."""
    return canonical_json(params_form(params, exclude={"L_mm"}))


def sweep_task(job: JobSpec, point_id: str, direction: str) -> SweepTask:
    sid = digest({"point": point_id, "direction": direction,
                  "protocol": protocol_id_form(job.protocol.model_dump(mode="json"), direction)})  # fmt: skip
    return SweepTask(sid, point_id, direction)


def plan(job: JobSpec) -> tuple[list[PointTask], list[SweepTask]]:
    """All tasks of a grid job (for an adaptive job: its coarse grid): one
    zero-force task per point, one sweep per (point, direction). Ids hash the
    canonical parameters, never file names."""
    points, sweeps = [], []
    carried = _carried_from(job) if job.starts.carry else {}
    for params in job.points():
        p = point_task(job, params, carried.get(_where(params)))
        points.append(p)
        sweeps.extend(sweep_task(job, p.task_id, d) for d in job.directions)
    return points, sweeps


def _where(params: StitchParams) -> tuple[str, float]:
    return series_key(params), params.L_mm


def _carried_from(job: JobSpec) -> dict[tuple[str, float], str]:
    """With ``[starts] carry``: per point (series, L), the id of the point it starts
    from: its series' neighbour of next larger L (the largest has none)."""
    series: dict[str, list[StitchParams]] = {}
    for params in job.points():
        series.setdefault(series_key(params), []).append(params)
    out: dict[tuple[str, float], str] = {}
    for members in series.values():
        previous = None
        for params in sorted(members, key=lambda q: -q.L_mm):
            p = point_task(job, params, previous)
            if previous is not None:
                out[_where(params)] = previous
            previous = p.task_id
    return out


def load_job(path: str | Path) -> JobSpec:
    """Read and validate a TOML job file; every problem is one ``InputError`` naming
    the file and the field (also for binary, non-UTF-8 and absurdly nested files)."""
    text = read_text(path, "job file", MAX_JOB_FILE_BYTES, hint="; save it as UTF-8 TOML")
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
