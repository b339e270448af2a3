"""Every setting of the library, validated; no numba, no scipy (docs/model.md §1, §7, §8).

* ``StitchParams``: the physics of one stitch, in the paper's user-facing units;
  ``StitchParams.internal()`` converts once to the kernels' units (N, mm).
* ``Fidelity``: the discretisation of one energy evaluation.
* ``SolverSettings``: the constrained minimiser and the continuation in parameters.
* ``SweepProtocol``: the strain schedule of a sweep.
* ``StartSettings``: the starting states of a zero-force relaxation.
* (in ``knitsweep.presets``) the presets: the speed/accuracy trade in one word.

All are frozen, strict pydantic models: they refuse unknown fields (with a "did
you mean"), values of the wrong type (no string-to-number or bool-to-number
coercion: ``"0.005"`` and ``true`` are not numbers) and out-of-range values at
construction, with a message naming the field, the value and the allowed range.
Every number has a physical upper bound too (stated in its field), so a mistyped
1e300 is refused instead of sending the continuation or a sweep on an endless road.
The status words shared by every layer are defined here too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any, Literal, NamedTuple, get_args

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
)

from .errors import InputError as InputError  # the settings' error, re-exported
from .paths import check_path, load_path
from .stitches import DEFAULT_STITCH, STITCH_CHOICES, check_stitch_name, unknown_stitch
from .util.plain_values import plain_value

STRICT = ConfigDict(
    frozen=True, extra="forbid", allow_inf_nan=False, validate_default=True, strict=True
)
"""Every settings model's pydantic configuration: frozen, strict, unknown fields refused."""


def _positive(v: float) -> float:
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError("must be a finite number > 0")
    return v


Positive = Annotated[float, AfterValidator(_positive)]


def _known_stitch(v: str) -> str:
    why = unknown_stitch(v)
    if why is not None:
        raise ValueError(why)
    return check_stitch_name(v)  # a chart's canonical spelling


StitchName = Annotated[str, AfterValidator(_known_stitch)]
"""The name of a stitch knitsweep knows (``knitsweep.stitches.STITCH_NAMES``, or a chart's,
``chart:KKPP``, in its canonical spelling)."""


def within(lo: float, hi: float, *, open_lo: bool = False, unit: str = ""):
    """A float field in [lo, hi] (or (lo, hi] with ``open_lo``) whose message states the
    whole allowed range: ``must be a finite number in (0, 100] mm``."""
    where = f"{'(' if open_lo else '['}{lo:g}, {hi:g}]{' ' + unit if unit else ''}"

    def check(v: float) -> float:
        if not (math.isfinite(v) and (v > lo if open_lo else v >= lo) and v <= hi):
            raise ValueError(f"must be a finite number in {where}")
        return v

    return Annotated[float, AfterValidator(check)]


# ---- statuses -------------------------------------------------------------------
CONVERGED, NOT_CONVERGED, NOT_KNITTABLE = "converged", "not_converged", "not_knittable"
"""How a relaxation ended (docs/model.md §7)."""
DONE, FAILED = "done", "failed"
"""How a task of a job ended (besides NOT_KNITTABLE)."""


# ---- physics ----------------------------------------------------------------------
class InternalParams(NamedTuple):
    """Kernel parameters in internal units: mm, N, N mm^2 (docs/model.md §1)."""

    L: float  # yarn length per stitch, mm
    bend: float  # B/2, N mm^2
    reg: float  # N mm^4
    r: float  # mm
    rc: float  # mm
    k: float  # N/mm^2
    p: float
    twist_bound: float


class StitchParams(BaseModel):
    """Physical inputs of one stitch, in the paper's units (paper Table 1)."""

    model_config = STRICT

    # bounds: far beyond any knitted yarn (paper Table 1: L ~ 11 mm, r 0.74 mm, k 0.1-1.7,
    # B 45-360), and near enough that the continuation from the shipped starts (steps of
    # 0.1 mm in L, 0.02 mm in r, factors of 2 in k and B) stays finite
    L_mm: within(0.0, 100.0, open_lo=True, unit="mm") = Field(
        11.6, description="yarn length per stitch L (mm), <= 100"
    )
    B_mN_mm2: within(1e-3, 1e6, unit="mN mm^2") = Field(
        90.0, description="bending modulus B (mN mm^2), 1e-3 to 1e6"
    )
    k_mN_per_mm2: within(1e-6, 1e4, unit="mN/mm^2") = Field(
        0.6, description="compression constant k (mN/mm^2), 1e-6 to 1e4"
    )
    p: float = Field(2.4, description="contact exponent p, 1 < p <= 20")
    r_mm: within(0.01, 10.0, unit="mm") = Field(0.74, description="yarn radius r (mm), 0.01 to 10")
    r_core_mm: Positive = Field(0.325, description="incompressible core radius r_core (mm), < r")
    regularization_mN_mm4: within(0.0, 1e4, unit="mN mm^4") = Field(
        2.0,
        description="curvature-derivative regularisation (mN mm^4), <= 1e4; 2 = reference "
        "0.002 N mm^4",
    )
    twist_bound: float = Field(
        0.9, description="bound c_tw on the crossover twist: cos(tw) >= c_tw"
    )
    stitch: StitchName = Field(
        DEFAULT_STITCH, description=f"stitch pattern: one of {STITCH_CHOICES}"
    )

    @field_validator("p")
    @classmethod
    def _p_above_one(cls, v: float) -> float:
        # above 20 the contact kernel's zeta**(1-p) would leave its exp's range
        # (|(1-p) log zeta| <= 708 for zeta >= 1e-5); fabrics have p of 2 to 4
        if not 1.0 < v <= 20.0:
            raise ValueError("must satisfy 1 < p <= 20")
        return v

    @field_validator("r_core_mm")
    @classmethod
    def _core_inside_yarn(cls, v: float, info: ValidationInfo) -> float:
        r = info.data.get("r_mm")
        if r is not None and not v < r:
            raise ValueError(f"must satisfy 0 < r_core_mm < r_mm = {r}")
        return v

    @field_validator("twist_bound")
    @classmethod
    def _twist_in_range(cls, v: float) -> float:
        if not -1.0 <= v < 1.0:
            raise ValueError("must be in [-1, 1)")
        return v

    @property
    def L_over_r(self) -> float:
        return self.L_mm / self.r_mm

    @classmethod
    def from_flat(cls, values: Mapping[str, Any]) -> StitchParams:
        """The parameters from a mapping that holds every field among other keys
        (e.g. the attributes of a results-file group; ``stitch`` may be absent: the
        default stitch, as written before stitches were a choice)."""
        return cls(**{k: plain_value(values[k]) for k in cls.model_fields
                      if k != "stitch" or k in values})  # fmt: skip

    def internal(self) -> InternalParams:
        """Convert to the kernels' N/mm units once (mN -> N)."""
        return InternalParams(
            L=self.L_mm,
            bend=0.5 * self.B_mN_mm2 * 1e-3,
            reg=self.regularization_mN_mm4 * 1e-3,
            r=self.r_mm,
            rc=self.r_core_mm,
            k=self.k_mN_per_mm2 * 1e-3,
            p=self.p,
            twist_bound=self.twist_bound,
        )

    @classmethod
    def from_internal(cls, L: float, bend: float, reg: float, r: float, rc: float, k: float,
                      p: float, twist_bound: float = 0.9) -> StitchParams:  # fmt: skip
        """Build from the reference code's internal units (N, mm)."""
        return cls(
            L_mm=L,
            B_mN_mm2=2e3 * bend,
            k_mN_per_mm2=1e3 * k,
            p=p,
            r_mm=r,
            r_core_mm=rc,
            regularization_mN_mm4=1e3 * reg,
            twist_bound=twist_bound,
        )


ImageMode = Literal["cutoff", "reference"]
ContactSampling = Literal["auto", "parameter", "arclength", "yarn_arclength"]


class Fidelity(BaseModel):
    """Numerical discretisation: the speed/accuracy knobs of one energy evaluation."""

    model_config = STRICT

    samples_per_segment: int = Field(
        10, ge=2, le=200, description="contact samples per spline segment N (reference: 10)"
    )
    quadrature_nodes: int = Field(
        32, ge=2, le=256, description="Gauss–Legendre nodes per segment for bending and length"
    )
    images: ImageMode = Field(
        "cutoff",
        description="periodic images searched for contacts: 'cutoff' (every image that can "
        "touch) or 'reference' (the authors' fixed box m in -1..1, n in -3..3)",
    )
    contact_sampling: ContactSampling = Field(
        "auto",
        description="where a free yarn's (stockinette_free, garter, rib, seed) contact "
        "samples sit: 'auto' (the default: 'yarn_arclength' for a free yarn), "
        "'yarn_arclength' (evenly spaced along the whole yarn by arclength, its end speeds "
        "held at L/8 as the parametrisation's gauge; docs/model.md §11), 'parameter' (at "
        "the curve parameters (j + 1/2)/N of each segment, the paper's, with the free "
        "yarn's speed box) or 'arclength' (at those fractions of each segment's "
        "arclength); the paper's ansatz (stockinette) samples by parameter whatever this is",
    )

    def sampling_for(self, free_yarn: bool) -> str:
        """The placement a stitch's contact sum uses: ``contact_sampling`` with 'auto'
        resolved ('yarn_arclength' for a free yarn, 'parameter' otherwise); a stitch
        that is no free yarn (the ansatz) samples by parameter whatever it says."""
        if not free_yarn:
            return "parameter"
        return "yarn_arclength" if self.contact_sampling == "auto" else self.contact_sampling


# ---- minimisers ----------------------------------------------------------------
class SolverInfo(NamedTuple):
    """One minimiser of the solver registry (``SOLVERS``): what it is and what the
    energy goal ``SolverSettings.ftol`` means for it; ``relax.relaxer`` binds each name
    to its implementation."""

    name: str
    description: str
    energy_goal: str
    """What ``ftol`` (mJ) bounds when this minimiser stops."""
    walks: bool
    """Whether a large change of the fixed period is walked in sub-steps from the chain's
    last solution (worth it only for a minimiser that carries the curvature there)."""


SOLVERS: dict[str, SolverInfo] = {s.name: s for s in (
    SolverInfo("newton", "Newton–KKT trust region on a finite-difference Hessian of the exact "
               "gradients, carried along a chain (SLSQP finishes what it cannot)",
               "the Newton decrement ½ rᵀH⁻¹r, the energy the quadratic model still expects to "
               "gain", walks=True),
    SolverInfo("slsqp", "SciPy's SLSQP, the authors' minimiser",
               "SciPy's ftol: SLSQP stops once the energy changes by less than this from one "
               "iteration to the next", walks=False),
)}  # fmt: skip
"""The solver registry: every minimiser ``SolverSettings.method`` can name. The
setting's allowed values, its help text and the error messages are built from it."""
SOLVER_NAMES: tuple[str, ...] = tuple(SOLVERS)
SolverName = Literal[SOLVER_NAMES]  # type: ignore[valid-type]


def zero_force_solvers(stitch: str, method: str) -> str:
    """Empty if the ``method`` minimiser alone relaxes the zero-force states of ``stitch``,
    else which minimisers do and why (what a job and ``knitsweep relax`` say before they
    compute; ``relax.continuation.walk_starts`` runs exactly this). Strain steps always
    use ``method``."""
    from .stitches import get_stitch

    if not get_stitch(stitch).rough or method == "slsqp":
        return ""
    return (f"{stitch}: zero-force states are relaxed by SLSQP at the intermediate stages of "
            f"the continuation and by the lower of {method}'s and SLSQP's minima at the target "
            f"(then {method} from SLSQP's), not by {method} alone: the free yarn's energy has "
            f"shallow minima in which {method} crawls and each minimiser misses some (docs/"
            f"model.md §11); its strain steps use {method}")  # fmt: skip


class SolverSettings(BaseModel):
    """Constrained minimiser settings (exact Jacobians, docs/model.md §7)."""

    model_config = STRICT

    method: SolverName = Field(
        "newton",
        description="; ".join(f"'{s.name}': {s.description}" for s in SOLVERS.values()),
    )
    ftol: float = Field(
        1e-10,
        ge=1e-16,
        le=1e-2,
        description="precision goal on the energy (mJ): "
        + "; ".join(f"{s.name}: {s.energy_goal}" for s in SOLVERS.values())
        + "; the authors' effective value was SciPy's default 1e-6, the paper quotes 1e-5",
    )
    maxiter: int = Field(2000, ge=1, le=1_000_000, description="iteration limit of a minimiser")
    substep_mm: float = Field(
        0.01,
        gt=0.0,
        le=5.0,
        description="Newton: a strain step that moves the fixed period by more than this (mm) "
        "is walked in equal sub-steps of at most this, so that the chain follows its branch "
        "instead of jumping to wherever one Newton solve lands",
    )
    length_tol_mm: Positive = Field(
        1e-6, le=0.1, description="largest |length - L| (mm) that counts as meeting the constraint"
    )
    continuation_dL_mm: Positive = Field(
        0.1, ge=1e-4, le=10.0, description="largest change of L (mm) per continuation stage"
    )
    continuation_factor: float = Field(
        2.0, gt=1.0, le=100.0, description="largest factor of k or B per continuation stage"
    )
    continuation_dr_mm: Positive = Field(
        0.02, ge=1e-4, le=1.0, description="largest change of r or r_core (mm) per stage"
    )
    continuation_dp: Positive = Field(
        0.1, ge=1e-4, le=10.0, description="largest change of p per stage"
    )

    @property
    def decrement_goal_mJ(self) -> float:
        """Newton: the largest Newton decrement (mJ) of a converged relaxation (``ftol``)."""
        return self.ftol

    @property
    def energy_change_goal_mJ(self) -> float:
        """SLSQP: the change of the energy between iterations (mJ) below which it stops
        (``ftol``, SciPy's name)."""
        return self.ftol

    def loosened(self, energy_goal_mJ: float) -> SolverSettings:
        """These settings with an energy goal no tighter than ``energy_goal_mJ`` (the
        unrecorded steps: continuation stages, a strain step's sub-steps)."""
        return self.model_copy(update={"ftol": max(self.ftol, energy_goal_mJ)})


Direction = Annotated[str, AfterValidator(check_path)]
"""A sweep's load path by name (``knitsweep.paths``: uniaxial x and y, the paper's;
equibiaxial; strip biaxial; ``ray:<rate_x>,<rate_y>[,<rate_xy>]``)."""


Observable = Literal["curve", "secant_modulus", "offset_stress", "energy_gaps"]
OBSERVABLES: tuple[str, ...] = get_args(Observable)
"""What a sweep can be asked to determine (docs/model.md §8-9): the whole stress-strain
curve; Y_sec (needs the curve past 2 % strain); sigma0 (the longest softened regime over
the sweep: needs the whole curve); the energy gaps (both energy components back above
their zero-force values, so that their minima along the sweep are known)."""


REST_TOLERANCE_MJ = 5e-6
"""How far (mJ) a sweep's energy may fall below its zero-force energy before the sweep
takes the lower state as the point's zero-force state (``SweepProtocol.rest_tolerance_mJ``):
a tenth of the paper's energy-gap threshold."""


class SweepProtocol(BaseModel):
    """The strain schedule; defaults are the authors' (docs/model.md §8)."""

    model_config = STRICT

    step_mm: float = Field(0.001, gt=0.0, le=1.0, description="small step h of the period (mm)")
    switch_strain: float = Field(
        0.05,
        ge=0.0,
        le=10.0,
        description="|strain| from which the large step applies (fixed steps)",
    )
    large_step_x_mm: float = Field(0.1, gt=0.0, le=5.0, description="large step for x pulls (mm)")
    large_step_y_mm: float = Field(0.05, gt=0.0, le=5.0, description="large step for y pulls (mm)")
    stop_stress_N_per_mm: float = Field(
        0.4, gt=0.0, le=1000.0, description="stop once |stress| exceeds this"
    )
    max_strain: float = Field(1.0, gt=0.0, le=10.0, description="stop once |strain| exceeds this")
    max_steps: int = Field(5000, ge=2, le=1_000_000, description="hard limit on steps")
    mode: Literal["tension", "compression"] = Field(
        "tension", description="pull the cell apart (tension) or push it together"
    )
    observables: tuple[Observable, ...] = Field(
        ("curve",),
        description="what the sweep must determine; it stops as soon as all are: 'curve' (to "
        "the stop stress or strain), 'secant_modulus' (Y_sec: past 2 % strain), "
        "'offset_stress' (sigma0: the whole curve, so the same as 'curve'), 'energy_gaps' "
        "(both energies back above their zero-force values)",
    )
    step_control: Literal["fixed", "adaptive"] = Field(
        "fixed",
        description="'fixed': h up to switch_strain, then the large step (the authors'); "
        "'adaptive': from h, each step chosen so that linear interpolation between steps "
        "errs by at most the tolerances below in the envelope stress and in each energy",
    )
    stress_tolerance_N_per_mm: float = Field(
        2e-5,
        gt=0.0,
        description="adaptive steps: absolute interpolation error of the stress (N/mm)",
    )
    stress_rtol: float = Field(
        2e-3,
        ge=0.0,
        le=1.0,
        description="adaptive steps: relative interpolation error of the stress",
    )
    energy_tolerance_mJ: float = Field(
        2e-7, gt=0.0, description="adaptive steps: interpolation error of E_b and E_c (mJ)"
    )
    max_step_mm: float = Field(0.1, gt=0.0, le=5.0, description="adaptive steps: largest step (mm)")
    merge_tolerance_mJ: float = Field(
        1e-9,
        ge=0.0,
        description="chains whose energies differ by at most this (mJ) and whose states differ "
        "only along soft modes (energy cost 1/2 dx.H.dx at most this) merge; 0: never",
    )

    rest_tolerance_mJ: float = Field(
        REST_TOLERANCE_MJ,
        ge=0.0,
        le=1.0,
        description="a sweep whose energy falls more than this (mJ) below its zero-force "
        "energy relaxes again at zero force from there and starts over from that lower "
        "minimum, the point's zero-force state from then on (default a tenth of the paper's "
        "gap threshold; 1 mJ turns it off)",
    )

    shear_rest: Literal["relaxed", "held"] = Field(
        "relaxed",
        description="a path that shears a free yarn starts from the zero-force state with its "
        "skew relaxed ('relaxed': the minimum in shear, this sweep's rest alone, where it lies "
        "more than rest_tolerance_mJ below the upright state) or upright ('held': the point's "
        "zero-force state, skew 0)",
    )

    @field_validator("observables", mode="before")
    @classmethod
    def _from_a_list(cls, v: Any) -> Any:
        """A job file's TOML list (its names are still checked strictly)."""
        return tuple(v) if isinstance(v, list) else v

    @field_validator("observables")
    @classmethod
    def _canonical_observables(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        """Sorted and unique; 'curve' when the whole curve is needed anyway, so that two
        requests that compute the same sweep are the same protocol (and task id)."""
        if not v:
            raise ValueError(f"give at least one of {', '.join(OBSERVABLES)}")
        if "curve" in v or "offset_stress" in v:
            return ("curve",)
        return tuple(sorted(set(v)))

    def large_step(self, direction: Direction) -> float:
        """The large step of the path's leading period (mm)."""
        return self.large_step_x_mm if load_path(direction).leading == "x" else self.large_step_y_mm


RETRIES = 3  # default [starts] retries; a retry's copies perturb the shape 1e-12 relative:
RETRY_PERTURBATION = 1e-12  # far above round-off (1e-16), far below a physical change
SPREAD_PERTURBATION = 1e-15  # [starts] spread's copies: a few ulps of each entry


class StartSettings(BaseModel):
    """How many starts per point, and where they come from (docs/model.md §7)."""

    model_config = STRICT

    count: int = Field(4, ge=1, le=64, description="starts per point (paper: 4)")
    source: Literal["shipped", "perturbed"] = Field(
        "shipped",
        description="'shipped': the authors' Init_1…Init_7 in turn (then perturbed copies); "
        "'perturbed': Init_1 with seeded random perturbations",
    )
    perturbation: float = Field(
        0.02, ge=0.0, le=0.5, description="relative std of the shape perturbations"
    )
    merge_tolerance_mJ: float = Field(
        1e-9,
        ge=0.0,
        description="starts walking the same continuation stages merge after a stage where "
        "their energies differ by at most this (mJ) and their states only along soft modes "
        "(energy cost 1/2 dx.H.dx at most this); 0: never",
    )
    carry: bool = Field(
        False,
        description="along each series (the points that differ only in L): the point of "
        "largest L relaxes from the shipped starts, every other one from the zero-force "
        "state of its neighbour of next larger L, walked there by continuation (one start; "
        "the shipped starts again if that neighbour failed)",
    )

    retries: int = Field(RETRIES, ge=0, le=16, description="a point no start of which converged "
                         "or ended too tight to knit: each start that did neither walks again "
                         f"from this many copies perturbed {RETRY_PERTURBATION:g} relative and "
                         "takes their verdict (service/retry.py); 0: never")  # fmt: skip
    spread: int = Field(1, ge=1, le=16, description="each point also relaxed from spread - 1 "
                        "copies of its winning start, each sweep from spread - 1 of its state, "
                        f"perturbed {SPREAD_PERTURBATION:g} relative: the observables' spread "
                        "(service/spread.py); 1: off")  # fmt: skip
