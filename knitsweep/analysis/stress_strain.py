"""Stress–strain jamming metrics: the secant modulus Y_sec and the offset stress σ0
(paper "Reducing or Inducing Jamming", SI "Disappearing Linear Elasticity";
docs/model.md §9).

``strain`` ε is dimensionless and strictly increasing with ε_0 = 0 at the zero-force
step; ``stress`` σ is the 2D stress in N/mm with σ_0 = 0 (docs/model.md §8). Re-exported by
:mod:`knitsweep.analysis.metrics`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..quantities import SECANT_STRAIN
from ._common import (
    PlainDict,
    check_int,
    check_scalar,
    check_strain_stress,
)
from .fitting import LinearFit, fit_line


@dataclass(frozen=True)
class SecantModulus(PlainDict):
    """Secant modulus Y_sec = σ(ε_at)/ε_at (paper Eq. 1, docs/model.md §9).

    Attributes:
        Y_sec: N/mm, or None when the sweep does not reach ε_at.
        at: the strain ε_at (0.02 in the paper).
        stress_at: σ(ε_at), N/mm, linearly interpolated; None with ``Y_sec``.
        reason: why ``Y_sec`` is None, else None.
    """

    Y_sec: float | None
    at: float
    stress_at: float | None
    reason: str | None


@dataclass(frozen=True)
class OffsetStress(PlainDict):
    """Offset stress σ0 from a line fitted to the softened regime (docs/model.md §9).

    Attributes:
        sigma0: N/mm, the σ-axis intercept at ε = 0 of the fitted line; None when
            ``has_linear_regime`` is False.
        slope: N/mm, the fitted slope (modulus of the softened, linear regime).
        has_linear_regime: False when the curve goes straight from jamming to
            non-linear stiffening (paper SI "Disappearing Linear Elasticity").
        window: (ε_lo, ε_hi) used: the user's bounds, or the strains of the first
            and last fitted samples; None when nothing was fitted.
        n_points: number of samples fitted (0 when none).
        method: 'auto' (tangent-modulus band) or 'window' (user bounds).
        fit: the full least-squares fit with its residuals, or None.
        tangent_min: N/mm, the minimum tangent modulus E_min that sets the band
            ('auto' only, else None).
        search_start: the strain where the initial rise ends and the search for
            E_min begins ('auto' only, else None).
        reason: why there is no linear regime, else None.
    """

    sigma0: float | None
    slope: float | None
    has_linear_regime: bool
    window: tuple[float, float] | None
    n_points: int
    method: Literal["auto", "window"]
    fit: LinearFit | None
    tangent_min: float | None
    search_start: float | None
    reason: str | None


def secant_modulus(
    strain: np.ndarray, stress: np.ndarray, at: float = SECANT_STRAIN
) -> SecantModulus:
    """Secant modulus Y_sec = σ(ε_at)/ε_at (paper Eq. 1; docs/model.md §9).

    Args:
        strain: shape (n,), strictly increasing, dimensionless.
        stress: shape (n,), N/mm.
        at: the strain ε_at > 0 (the paper fixes 0.02).

    Returns:
        :class:`SecantModulus`; σ(ε_at) is linearly interpolated between the two
        neighbouring steps. ``Y_sec`` is None (with a reason) when ε_at lies outside
        the sampled strains, e.g. a sweep that stopped before ε = 0.02.

    Raises:
        ValueError: non-finite or mismatched arrays, strain not increasing, at ≤ 0.
    """
    eps, sig = check_strain_stress(strain, stress)
    at = check_scalar("at", at, positive=True)
    if eps[-1] < at:
        reason = f"the sweep ends at strain {eps[-1]:.6g} < {at:g}"
        return SecantModulus(None, at, None, reason)
    if eps[0] > at:
        reason = f"the sweep starts at strain {eps[0]:.6g} > {at:g}"
        return SecantModulus(None, at, None, reason)
    stress_at = float(np.interp(at, eps, sig))
    return SecantModulus(stress_at / at, at, stress_at, None)


def tangent_modulus(strain: np.ndarray, stress: np.ndarray, halfwidth: int = 0) -> np.ndarray:
    """Tangent modulus dσ/dε at every step, N/mm, shape (n,), n ≥ 2.

    ``halfwidth = 0``: second-order central differences on the non-uniform grid
    (``numpy.gradient``; exact for a quadratic through three neighbouring steps),
    first-order one-sided differences at the two ends.
    ``halfwidth = m ≥ 1``: the slope of the least-squares line through steps
    i − m .. i + m (truncated at the ends), which divides the effect of uncorrelated
    noise in σ by about m^1.5/√3 at the price of smearing kinks over m steps.
    """
    eps, sig = check_strain_stress(strain, stress)
    m = check_int("halfwidth", halfwidth, 0)
    if eps.size < 2:
        raise ValueError("strain: needs at least 2 steps for a tangent modulus")
    if m == 0:
        return np.gradient(sig, eps, edge_order=1)
    n = eps.size
    E = np.empty(n)
    for i in range(n):
        x = eps[max(0, i - m) : i + m + 1]
        y = sig[max(0, i - m) : i + m + 1]
        dx = x - x.mean()
        E[i] = np.dot(dx, y - y.mean()) / np.dot(dx, dx)
    return E


def _no_regime(reason: str, tangent_min: float | None, search_start: float | None) -> OffsetStress:
    return OffsetStress(None, None, False, None, 0, "auto", None, tangent_min, search_start, reason)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs of True in ``mask`` as inclusive (first, last) index pairs."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


# For the stresses of knitsweep's sweeps the tangent modulus is a numerical
# derivative (of a finite difference of the energy, or of the envelope stress): smooth
# it over 11 steps and ask for a softened regime spanning at least 1 % strain.
# Measured on the phase_small job: sigma0 then exists for every sweep and falls
# smoothly to zero at the transition (paper Fig. 2f); unsmoothed, a third of the
# sweeps had none.
FD_STRESS_SMOOTHING = {"halfwidth": 5, "min_span": 0.01}


@dataclass(frozen=True)
class StressDrops(PlainDict):
    """Where a finite-difference stress falls along a tension sweep, and whether the
    falls come from switches of the winning start (docs/model.md §8–9).

    Each step's state is the lowest-energy of several chains; where the winner
    changes, the energies differenced for σ come from different chains, and σ can
    drop although every chain's own stress rises: the curve is discontinuous there.

    Attributes:
        n_switches: steps whose winning start differs from the previous step's.
        n_drops: steps j with σ_j < σ_{j-1}.
        n_switching_drops: drops within the stencil of a switch (the winner changes
            somewhere in steps j-2 .. j+1, whose energies σ_{j-1} and σ_j use).
        first_drop_strain: strain of the first switching drop, None without one.
        discontinuous: True when there is a switching drop.
    """

    n_switches: int
    n_drops: int
    n_switching_drops: int
    first_drop_strain: float | None
    discontinuous: bool


def stress_drops(
    strain: np.ndarray, stress: np.ndarray, winner: np.ndarray | None = None
) -> StressDrops:
    """:class:`StressDrops` of one sweep.

    Args:
        strain: shape (n,), strictly increasing.
        stress: shape (n,), N/mm, the finite-difference stress.
        winner: shape (n,), the winning start of each step (None: no switches known).
    """
    eps, sig = check_strain_stress(strain, stress)
    drops = np.flatnonzero(np.diff(sig) < 0.0) + 1
    if winner is None:
        changed = np.zeros(eps.size, dtype=bool)
    else:
        w = np.asarray(winner)
        if w.shape != eps.shape:
            raise ValueError(f"winner: shape {w.shape}, strain has {eps.shape}")
        changed = np.r_[False, w[1:] != w[:-1]]
    switching = [j for j in drops if changed[max(j - 1, 0) : j + 2].any()]
    return StressDrops(
        n_switches=int(np.count_nonzero(changed)),
        n_drops=int(drops.size),
        n_switching_drops=len(switching),
        first_drop_strain=float(eps[switching[0]]) if switching else None,
        discontinuous=bool(switching),
    )


def offset_stress(
    strain: np.ndarray,
    stress: np.ndarray,
    window: tuple[float, float] | None = None,
    *,
    band: float = 0.25,
    min_points: int = 4,
    min_span: float = 0.0,
    halfwidth: int = 0,
) -> OffsetStress:
    """Offset stress σ0: the ε = 0 intercept of a line through the softened regime.

    Paper "Reducing or Inducing Jamming" and docs/model.md §9: σ0 is the σ-axis intercept
    of a linear fit to the post-jammed (softened, linear-elastic) part of σ(ε).

    With ``window = (ε_lo, ε_hi)`` the line is fitted, by least squares, to exactly
    the steps with ε_lo ≤ ε ≤ ε_hi (``method='window'``; ``has_linear_regime`` is then
    True by fiat). Otherwise (``method='auto'``):

    1. Tangent modulus E_i = dσ/dε at every step (:func:`tangent_modulus` with
       ``halfwidth``; the default 0 is plain central differences).
    2. End of the initial (jammed) rise: s = the first index with E_s ≥ E_{s+1},
       i.e. the first local maximum of E (s = 0 when E starts by falling or is flat).
       If E increases strictly over the whole sweep there is no initial rise (an
       unjammed, strain-stiffening curve) and s = 0.
    3. The search ends at the first step past s whose tangent modulus is not
       positive: a stress drop is a rearrangement of the stitch (a switch of basin),
       not part of an elastic regime. E_min = min of E_i over s ≤ i < that end. If
       nothing positive remains there is no linear regime.
    4. In-band steps: (1 − band)·E_min ≤ E_i ≤ (1 + band)·E_min. Candidate regimes
       are the maximal contiguous runs of in-band steps that contain at least one
       step i ≥ s (a run may extend back before s when the "rise" is within the band,
       e.g. a straight unjammed curve), have ≥ ``min_points`` steps and span a strain
       range ε_last − ε_first ≥ ``min_span``.
    5. The softened regime is the candidate with the longest strain span (ties: more
       steps, then the earlier one). σ = σ0 + Y·ε is fitted there by least squares;
       ``sigma0`` = σ0, ``slope`` = Y.
    6. No candidate ⇒ ``has_linear_regime = False``, ``sigma0 = None``: the curve goes
       straight from jamming to non-linear stiffening (paper SI "Disappearing Linear
       Elasticity").

    An unjammed curve (no steep initial rise) gets a regime starting at ε = 0 and
    σ0 ≈ 0. A steep kink between the jammed and softened slopes has an intermediate
    central-difference tangent and so falls outside the band; the stiffening part is
    inside the band while its tangent is ≤ (1 + band)·E_min, so a gently stiffening
    curve biases the fit by the stiffening it admits (smaller ``band`` reduces that).

    Args:
        strain: shape (n,), strictly increasing, dimensionless.
        stress: shape (n,), N/mm.
        window: optional (ε_lo, ε_hi) fitting bounds, ε_lo < ε_hi.
        band: relative half-width of the tangent-modulus band (> 0; 0.25 = ±25 %).
        min_points: fewest steps in a linear regime (≥ 2).
        min_span: smallest strain span of a linear regime (≥ 0).
        halfwidth: tangent-modulus smoothing (≥ 0, see :func:`tangent_modulus`);
            raise it for noisy stresses. The line is always fitted to the raw σ.

    Returns:
        :class:`OffsetStress`.

    Raises:
        ValueError: bad arrays (naming them), bad parameters, or a user window that
            holds fewer than 2 steps.
    """
    eps, sig = check_strain_stress(strain, stress)
    band = check_scalar("band", band, positive=True)
    min_span = check_scalar("min_span", min_span)
    if min_span < 0.0:
        raise ValueError(f"min_span = {min_span!r}: must be >= 0")
    min_points = check_int("min_points", min_points, 2)
    halfwidth = check_int("halfwidth", halfwidth, 0)

    if window is not None:
        return _offset_stress_in_window(eps, sig, window)

    n = eps.size
    if n < min_points:
        return _no_regime(f"only {n} step(s), fewer than min_points = {min_points}", None, None)
    E = tangent_modulus(eps, sig, halfwidth)
    falls = np.flatnonzero(E[:-1] >= E[1:])
    s = int(falls[0]) if falls.size else 0
    drops = np.flatnonzero(E[s:] <= 0.0)
    end = s + int(drops[0]) if drops.size else n
    search_start = float(eps[s])
    if end <= s:
        reason = f"the tangent modulus past the initial rise is not positive ({E[s]:.6g} N/mm)"
        return _no_regime(reason, float(E[s]), search_start)
    E_min = float(np.min(E[s:end]))

    in_band = (E >= (1.0 - band) * E_min) & (E <= (1.0 + band) * E_min)
    in_band[end:] = False
    candidates = [
        (float(eps[b] - eps[a]), b - a + 1, -a, a, b)
        for a, b in _runs(in_band)
        if b >= s and b - a + 1 >= min_points and eps[b] - eps[a] >= min_span
    ]
    if not candidates:
        reason = (
            f"no run of >= {min_points} steps spanning >= {min_span:g} in strain has a "
            f"tangent modulus within ±{band:g} of its minimum {E_min:.6g} N/mm"
        )
        return _no_regime(reason, E_min, search_start)
    *_, a, b = max(candidates)
    fit = fit_line(eps[a : b + 1], sig[a : b + 1])
    return OffsetStress(
        sigma0=fit.intercept,
        slope=fit.slope,
        has_linear_regime=True,
        window=(float(eps[a]), float(eps[b])),
        n_points=fit.n_points,
        method="auto",
        fit=fit,
        tangent_min=E_min,
        search_start=search_start,
        reason=None,
    )


def _offset_stress_in_window(
    eps: np.ndarray, sig: np.ndarray, window: tuple[float, float]
) -> OffsetStress:
    try:
        lo, hi = window
    except (TypeError, ValueError):
        raise ValueError(f"window = {window!r}: expected (eps_lo, eps_hi)") from None
    lo = check_scalar("window[0]", lo)
    hi = check_scalar("window[1]", hi)
    if not lo < hi:
        raise ValueError(f"window = ({lo!r}, {hi!r}): needs eps_lo < eps_hi")
    inside = (eps >= lo) & (eps <= hi)
    if np.count_nonzero(inside) < 2:
        raise ValueError(
            f"window = ({lo!r}, {hi!r}) holds {np.count_nonzero(inside)} step(s); "
            "a line needs at least 2"
        )
    fit = fit_line(eps[inside], sig[inside])
    return OffsetStress(
        sigma0=fit.intercept,
        slope=fit.slope,
        has_linear_regime=True,
        window=(lo, hi),
        n_points=fit.n_points,
        method="window",
        fit=fit,
        tangent_min=None,
        search_start=None,
        reason=None,
    )
