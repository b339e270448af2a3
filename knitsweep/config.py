"""Validated parameters, in the paper's user-facing units (MODEL.md §1).

``StitchParams`` holds the physics of one stitch (yarn and cell), ``Fidelity``
the numerical discretisation. Both are frozen pydantic models that refuse unknown
fields and out-of-range values at construction, with a message that names the
field, the value and the allowed range. ``StitchParams.internal()`` converts once
to the internal units (N, mm) used by the kernels.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, NamedTuple

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

_CONFIG = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, validate_default=True)


def _positive(v: float) -> float:
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError("must be a finite number > 0")
    return v


def _non_negative(v: float) -> float:
    if not (math.isfinite(v) and v >= 0.0):
        raise ValueError("must be a finite number >= 0")
    return v


Positive = Annotated[float, AfterValidator(_positive)]
NonNegative = Annotated[float, AfterValidator(_non_negative)]


class InternalParams(NamedTuple):
    """Kernel parameters in internal units: mm, N, N mm^2 (MODEL.md §1)."""

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

    model_config = _CONFIG

    L_mm: Positive = Field(11.6, description="yarn length per stitch L (mm)")
    B_mN_mm2: Positive = Field(90.0, description="bending modulus B (mN mm^2)")
    k_mN_per_mm2: Positive = Field(0.6, description="compression constant k (mN/mm^2)")
    p: float = Field(2.4, description="contact exponent p, 1 < p <= 20")
    r_mm: Positive = Field(0.74, description="yarn radius r (mm)")
    r_core_mm: Positive = Field(0.325, description="incompressible core radius r_core (mm)")
    regularization_mN_mm4: NonNegative = Field(
        2.0, description="curvature-derivative regularisation (mN mm^4); 2 = reference 0.002 N mm^4"
    )
    twist_bound: float = Field(
        0.9, description="bound c_tw on the crossover twist: cos(tw) >= c_tw"
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


class Fidelity(BaseModel):
    """Numerical discretisation: the speed/accuracy knobs of one energy evaluation."""

    model_config = _CONFIG

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


class SolverSettings(BaseModel):
    """Constrained minimiser settings (SciPy SLSQP with exact Jacobians, MODEL.md §7)."""

    model_config = _CONFIG

    ftol: float = Field(
        1e-10,
        gt=0.0,
        le=1e-2,
        description="SLSQP precision goal on the energy (mJ); the authors' effective value "
        "was SciPy's default 1e-6, the paper quotes 1e-5",
    )
    maxiter: int = Field(2000, ge=1, le=1_000_000, description="SLSQP iteration limit")
    length_tol_mm: Positive = Field(
        1e-6, description="largest |length - L| (mm) that counts as meeting the constraint"
    )
    continuation_dL_mm: Positive = Field(
        0.1, description="largest change of L (mm) per continuation stage"
    )
    continuation_factor: float = Field(
        2.0, gt=1.0, description="largest factor of k or B per continuation stage"
    )
    continuation_dr_mm: Positive = Field(
        0.02, description="largest change of r or r_core (mm) per continuation stage"
    )
    continuation_dp: Positive = Field(0.1, description="largest change of p per stage")


class InputError(ValueError):
    """Bad user input, reported as one line naming the field and the allowed range."""


def describe_validation_error(err: ValidationError | InputError) -> str:
    """One line per problem: ``field = value: what is allowed``."""
    if isinstance(err, InputError):
        return str(err)
    parts = []
    for e in err.errors():
        loc = ".".join(str(x) for x in e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        if not loc:  # a model-level check: its message names the fields itself
            parts.append(msg)
        elif e["type"] == "extra_forbidden":
            parts.append(f"{loc}: unknown field")
        elif "input" in e and e["type"] != "missing":
            parts.append(f"{loc} = {e['input']!r}: {msg}")
        else:
            parts.append(f"{loc}: {msg}")
    return "; ".join(parts)
