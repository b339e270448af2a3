"""Jamming metrics of one strain sweep (docs/model.md §9; paper "Reducing or Inducing
Jamming", "Energy Markers for Jamming", "Anisotropic Markers", SI "Disappearing
Linear Elasticity").

A sweep in one direction ('x' or 'y') is a set of arrays over steps i = 0..n−1, where
step 0 is the zero-force state (docs/model.md §8):

* ``strain`` ε, dimensionless, strictly increasing, ε_0 = 0;
* ``stress`` σ, N/mm (2D stress), σ_0 = 0;
* ``bending_energy`` E_b and ``contact_energy`` E_c, N·mm (= mJ; the paper's "J");
* ``a_x``, ``a_y`` (cell periods) and ``thickness`` Δz, mm.

All functions are pure: arrays and floats in, frozen dataclasses (with ``as_dict()``)
or arrays out. The stress–strain metrics (Y_sec, σ0) live in
:mod:`knitsweep.analysis.stress_strain` and are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..paths import PATHS, load_path
from ._common import (
    PlainDict,
    check_array,
    check_direction,
    check_same_length,
    check_scalar,
    check_strain_stress,
)
from .stress_strain import (
    SECANT_STRAIN,
    OffsetStress,
    SecantModulus,
    StressDrops,
    offset_stress,
    secant_modulus,
    stress_drops,
    tangent_modulus,
)

__all__ = [
    "JAMMING_GAP",
    "SECANT_STRAIN",
    "EnergyGaps",
    "OffsetStress",
    "SecantModulus",
    "StressDrops",
    "SweepMetrics",
    "area_strain",
    "aspect_ratio",
    "energy_gaps",
    "offset_stress",
    "secant_modulus",
    "stress_drops",
    "sweep_metrics",
    "tangent_modulus",
    "thickness_strain",
]

JAMMING_GAP = {name: path.gap for name, path in PATHS.items()}
"""Which energy gap marks jamming along each load path (paper Fig. 3, docs/model.md §9):
the contact gap ΔE_c for x, the bending gap ΔE_b for y, and along the biaxial paths that
of their leading period (``knitsweep.paths``)."""


@dataclass(frozen=True)
class EnergyGaps(PlainDict):
    """Energy gaps ΔE_i = E_i(zero force) − min over the sweep of E_i (paper Eq. 4).

    All energies in N·mm (the paper's "J"). Both gaps are ≥ 0 by construction,
    since the minimum includes the zero-force step.

    Attributes:
        delta_E_b: bending-energy gap ΔE_b (marks jamming in y).
        delta_E_c: contact-energy gap ΔE_c (marks jamming in x).
        E_b_rest, E_c_rest: the energies at the zero-force step 0.
        E_b_min, E_c_min: their minima over the sweep.
        index_min_b, index_min_c: the first step where each minimum is reached.
    """

    delta_E_b: float
    delta_E_c: float
    E_b_rest: float
    E_c_rest: float
    E_b_min: float
    E_c_min: float
    index_min_b: int
    index_min_c: int

    def jamming_gap(self, direction: str) -> float:
        """The gap that marks jamming along load path ``direction``: ΔE_c for 'x', ΔE_b for
        'y', the leading period's along the biaxial paths (``JAMMING_GAP``)."""
        return float(getattr(self, load_path(direction).gap))


@dataclass(frozen=True)
class SweepMetrics(PlainDict):
    """All jamming metrics of one strain sweep (docs/model.md §9).

    Attributes:
        direction: the load path ('x', 'y', 'biaxial', 'strip_x', 'strip_y').
        n_steps: number of steps, including the zero-force step 0.
        max_strain: last strain reached.
        max_stress: N/mm, largest stress reached.
        secant: the secant modulus Y_sec at ε = 0.02.
        offset: the offset stress σ0 and its fit, on the envelope stress when the
            sweep has one (``sigma0_source``).
        sigma0_source: 'envelope' (σ0 fitted to the envelope stress, continuous
            where the winning start switches) or 'stress' (the finite-difference one).
        drops: where the finite-difference stress falls at start switches (a
            discontinuous curve).
        gaps: both energy gaps.
        jamming_gap: N·mm, ``gaps.jamming_gap(direction)`` (ΔE_c for x, ΔE_b for y).
        a_x0, a_y0: mm, the zero-force cell periods.
        aspect_ratio: a_y0/a_x0 (paper Fig. 5a).
        thickness0: mm, the zero-force thickness Δz.
        area_strain_min, area_strain_max: extremes of a_x a_y/(a_x0 a_y0) − 1.
        min_area_at_zero_force: area_strain_min ≥ −area_tol, i.e. the zero-force
            state has the smallest area of the sweep (paper: true when jammed in y).
        thickness_strain_min, thickness_strain_max: extremes of Δz/Δz0 − 1.
        thickness_strain_at: Δz/Δz0 − 1 at the secant strain (linear interpolation),
            None if the sweep does not reach it (paper: jammed-in-x fabrics shrink
            in z at small strain, unjammed ones expand).
    """

    direction: str
    n_steps: int
    max_strain: float
    max_stress: float
    secant: SecantModulus
    offset: OffsetStress
    sigma0_source: str
    drops: StressDrops
    gaps: EnergyGaps
    jamming_gap: float
    a_x0: float
    a_y0: float
    aspect_ratio: float
    thickness0: float
    area_strain_min: float
    area_strain_max: float
    min_area_at_zero_force: bool
    thickness_strain_min: float
    thickness_strain_max: float
    thickness_strain_at: float | None


def energy_gaps(bending_energy: np.ndarray, contact_energy: np.ndarray) -> EnergyGaps:
    """Energy gaps ΔE_b, ΔE_c of one sweep (paper Eq. 4, docs/model.md §9).

    Args:
        bending_energy: E_b per step, shape (n,), N·mm; step 0 is the zero-force state.
        contact_energy: E_c per step, shape (n,), N·mm.

    Returns:
        :class:`EnergyGaps` with ΔE_i = E_i[0] − min_j E_i[j] ≥ 0.
    """
    E_b = check_array("bending_energy", bending_energy)
    E_c = check_array("contact_energy", contact_energy)
    check_same_length(bending_energy=E_b, contact_energy=E_c)
    i_b = int(np.argmin(E_b))
    i_c = int(np.argmin(E_c))
    return EnergyGaps(
        delta_E_b=float(E_b[0] - E_b[i_b]),
        delta_E_c=float(E_c[0] - E_c[i_c]),
        E_b_rest=float(E_b[0]),
        E_c_rest=float(E_c[0]),
        E_b_min=float(E_b[i_b]),
        E_c_min=float(E_c[i_c]),
        index_min_b=i_b,
        index_min_c=i_c,
    )


def aspect_ratio(a_x0: float, a_y0: float) -> float:
    """Zero-force stitch aspect ratio a_y0/a_x0 (paper Fig. 5a), from periods in mm."""
    return check_scalar("a_y0", a_y0, positive=True) / check_scalar("a_x0", a_x0, positive=True)


def area_strain(a_x: np.ndarray, a_y: np.ndarray) -> np.ndarray:
    """Area strain a_x a_y/(a_x0 a_y0) − 1 per step, shape (n,) (paper Fig. 5b, SI S13).

    Args:
        a_x, a_y: cell periods per step, shape (n,), mm, > 0; step 0 is the reference.
    """
    ax = check_array("a_x", a_x)
    ay = check_array("a_y", a_y)
    check_same_length(a_x=ax, a_y=ay)
    if np.any(ax <= 0.0) or np.any(ay <= 0.0):
        raise ValueError("a_x, a_y: cell periods must be > 0")
    return (ax * ay) / (ax[0] * ay[0]) - 1.0


def thickness_strain(thickness: np.ndarray) -> np.ndarray:
    """Thickness strain Δz/Δz0 − 1 per step, shape (n,) (docs/model.md §9, SI Fig. S12).

    Args:
        thickness: Δz = z_max − z_min + 2r per step, shape (n,), mm, > 0.
    """
    dz = check_array("thickness", thickness)
    if np.any(dz <= 0.0):
        raise ValueError("thickness: must be > 0")
    return dz / dz[0] - 1.0


def sweep_metrics(
    direction: str,
    strain: np.ndarray,
    stress: np.ndarray,
    bending_energy: np.ndarray,
    contact_energy: np.ndarray,
    a_x: np.ndarray,
    a_y: np.ndarray,
    thickness: np.ndarray,
    *,
    stress_envelope: np.ndarray | None = None,
    winner: np.ndarray | None = None,
    at: float = SECANT_STRAIN,
    window: tuple[float, float] | None = None,
    band: float = 0.25,
    min_points: int = 4,
    min_span: float = 0.0,
    halfwidth: int = 0,
    area_tol: float = 0.0,
) -> SweepMetrics:
    """Every jamming metric of one sweep (docs/model.md §9), as one :class:`SweepMetrics`.

    Args:
        direction: the load path ('x', 'y' or a biaxial one, knitsweep.paths).
        strain, stress, bending_energy, contact_energy, a_x, a_y, thickness: per-step
            arrays, all shape (n,), step 0 the zero-force state (units in the module
            docstring).
        stress_envelope: optional shape (n,), N/mm, the envelope stress (docs/model.md
            §8). σ0 is fitted to it when given: it needs no differencing across steps
            won by different starts, so the switching drops of ``stress`` (which stop
            the softened-regime search) are absent.
        winner: optional shape (n,), the winning start per step, for ``drops``.
        at: strain of the secant modulus (paper: 0.02).
        window, band, min_points, min_span, halfwidth: passed to :func:`offset_stress`.
        area_tol: tolerance (≥ 0) of ``min_area_at_zero_force``.

    Raises:
        ValueError: bad direction, arrays of different lengths, non-finite values
            (naming the array), or bad parameters.
    """
    direction = check_direction(direction)
    eps, sig = check_strain_stress(strain, stress)
    arrays = {
        "bending_energy": check_array("bending_energy", bending_energy),
        "contact_energy": check_array("contact_energy", contact_energy),
        "a_x": check_array("a_x", a_x),
        "a_y": check_array("a_y", a_y),
        "thickness": check_array("thickness", thickness),
    }
    n = check_same_length(strain=eps, stress=sig, **arrays)
    area_tol = check_scalar("area_tol", area_tol)
    if area_tol < 0.0:
        raise ValueError(f"area_tol = {area_tol!r}: must be >= 0")

    secant = secant_modulus(eps, sig, at)
    fitted = sig if stress_envelope is None else check_array("stress_envelope", stress_envelope)
    check_same_length(strain=eps, stress_envelope=fitted)
    offset = offset_stress(
        eps, fitted, window, band=band, min_points=min_points, min_span=min_span,
        halfwidth=halfwidth,
    )  # fmt: skip
    gaps = energy_gaps(arrays["bending_energy"], arrays["contact_energy"])
    area = area_strain(arrays["a_x"], arrays["a_y"])
    dz = thickness_strain(arrays["thickness"])
    dz_at = float(np.interp(secant.at, eps, dz)) if eps[0] <= secant.at <= eps[-1] else None
    a_x0 = float(arrays["a_x"][0])
    a_y0 = float(arrays["a_y"][0])
    return SweepMetrics(
        direction=direction,
        n_steps=n,
        max_strain=float(eps[-1]),
        max_stress=float(np.max(sig)),
        secant=secant,
        offset=offset,
        sigma0_source="stress" if stress_envelope is None else "envelope",
        drops=stress_drops(eps, sig, winner),
        gaps=gaps,
        jamming_gap=gaps.jamming_gap(direction),
        a_x0=a_x0,
        a_y0=a_y0,
        aspect_ratio=aspect_ratio(a_x0, a_y0),
        thickness0=float(arrays["thickness"][0]),
        area_strain_min=float(np.min(area)),
        area_strain_max=float(np.max(area)),
        min_area_at_zero_force=bool(np.min(area) >= -area_tol),
        thickness_strain_min=float(np.min(dz)),
        thickness_strain_max=float(np.max(dz)),
        thickness_strain_at=dz_at,
    )
