"""Numbers printed in the paper, for side-by-side comparisons (Gonzalez et al. 2025).

Only values the paper states in its tables; knitsweep never computes with them. The
benchmark ``benchmarks/compare_paper.py``, the figures and the tests put knitsweep's
results beside them. Energies in N·mm (the paper's "J"), forces in N, lengths in mm,
k in mN/mm².
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import pairwise
from typing import Any, NamedTuple

from ..stitches import DEFAULT_STITCH

TABLE_1 = {"B_mN_mm2": 90.0, "r_core_mm": 0.325, "r_mm": 0.74, "p": 2.4}
"""Paper Table 1's B, r_core, r and p (its k, 0.6 mN/mm², varies between the tables)."""


def at_table_1(params: Mapping[str, Any], **values: float) -> bool:
    """Whether ``params`` (names as in ``StitchParams``) hold Table 1's B, r_core, r, p
    and the given ``values`` (e.g. ``k_mN_per_mm2=0.1``), to 1e-12, for the paper's
    stitch (a ``stitch`` other than the default one never is)."""
    if params.get("stitch", DEFAULT_STITCH) != DEFAULT_STITCH:
        return False
    want = TABLE_1 | values
    return all(abs(float(params[k]) - v) <= 1e-12 for k, v in want.items())


class TableS4Row(NamedTuple):
    """One row of paper Table S4: the line fitted to the jammed regime of the contact
    energy gap of x pulls, against L in mm (B = 90 mN·mm², r = 0.74 mm)."""

    slope_mJ_per_mm: float
    intercept_mJ: float
    max_abs_residual_mJ: float
    mean_abs_residual_mJ: float
    mse_mJ2: float

    @property
    def zero_L_mm(self) -> float:
        """Where the paper's line reaches zero gap, −intercept/slope (mm)."""
        return -self.intercept_mJ / self.slope_mJ_per_mm


TABLE_S4 = {
    0.001: TableS4Row(-6.99e-4, 0.0077, 6.24e-5, 2.92e-5, 1.25e-9),
    0.1: TableS4Row(-1.55e-3, 0.0176, 1.71e-5, 6.54e-6, 6.97e-11),
    0.2: TableS4Row(-2.00e-3, 0.0230, 2.94e-5, 1.47e-5, 3.12e-10),
    0.4: TableS4Row(-2.64e-3, 0.0306, 5.54e-5, 2.08e-5, 7.35e-10),
    0.5: TableS4Row(-2.88e-3, 0.0334, 3.74e-5, 1.19e-5, 3.09e-10),
    0.7: TableS4Row(-2.91e-3, 0.0343, 5.32e-5, 2.99e-5, 1.14e-9),
    0.8: TableS4Row(-3.00e-3, 0.0355, 8.37e-5, 4.61e-5, 2.69e-9),
    0.9: TableS4Row(-3.12e-3, 0.0370, 70.5e-6, 3.63e-5, 1.75e-9),
    1.0: TableS4Row(-3.03e-3, 0.0361, 1.08e-4, 4.68e-5, 3.34e-9),
    1.1: TableS4Row(-3.15e-3, 0.0376, 88.5e-6, 5.19e-5, 3.30e-9),
    1.2: TableS4Row(-3.27e-3, 0.0390, 6.64e-5, 2.62e-5, 9.87e-10),
    1.3: TableS4Row(-3.10e-3, 0.0373, 1.02e-4, 3.86e-5, 2.20e-9),
    1.5: TableS4Row(-3.13e-3, 0.0380, 9.79e-5, 46.5e-6, 2.99e-9),
    1.7: TableS4Row(-2.83e-3, 0.0349, 7.26e-5, 3.97e-5, 2.30e-9),
    2.0: TableS4Row(-2.91e-3, 0.0361, 1.29e-4, 4.94e-5, 4.54e-9),
    3.0: TableS4Row(-2.92e-3, 0.0371, 5.48e-5, 2.71e-5, 1.00e-9),
    4.0: TableS4Row(-2.49e-3, 0.0328, 9.39e-5, 3.14e-5, 1.91e-9),
}
"""Paper Table S4 by k (mN/mm²). (Three residuals are written in units of 1e-6 so that
the gap threshold's literal appears in one place only, ``transitions.GAP_THRESHOLD``.)"""

TABLE_S3 = {
    10.9: (1.952, 0.565),
    11.0: (1.588, 0.569),
    11.1: (1.199, 0.548),
    11.2: (0.956, 0.523),
    11.3: (0.737, 0.520),
    11.4: (0.558, 0.487),
    11.5: (0.423, 0.462),
    11.6: (0.321, 0.451),
    11.7: (0.245, 0.430),
    11.8: (0.186, 0.410),
    11.9: (0.152, 0.384),
    12.0: (0.118, 0.380),
    12.8: (0.028, 0.405),
}
"""Paper Table S3 (k = 0.1 mN/mm², zero strain): L (mm) → (|F_x|, |F_y|) in N, the x
force of the self and same-row contacts and the y force of the NN and NNN same-column
contacts, whose ratio is paper Fig. 6h."""

TABLE_S1_SIGMA0_L = {"x": (340000.0, -1.147), "y": (47.0, -0.58)}
"""Paper Table S1, σ0 of the L sweeps (Table 1 parameters, k = 0.6 mN/mm²):
direction → (A, b) of σ0 = A exp(b L/r), N/mm."""

TABLE_S1_YSEC_L = {"x": (1.1e7, -1.11), "y": (190000.0, -0.81)}
"""Paper Table S1, Y_sec of the L sweeps: direction → (A, b) of Y_sec = A exp(b L/r), N/mm."""


def ratio_crossing(Ls: Sequence[float], ratios: Sequence[float]) -> float | None:
    """L where a force ratio falls through 1, linearly interpolated between the
    neighbouring L values (sorted ascending); None if it never does."""
    for (L0, r0), (L1, r1) in pairwise(zip(Ls, ratios, strict=True)):
        if r0 >= 1.0 > r1:
            return L0 + (r0 - 1.0) / (r0 - r1) * (L1 - L0)
    return None


def table_s3_crossing_mm() -> float:
    """L (mm) where Table S3's |F_x|/|F_y| falls through 1, linearly interpolated
    between its neighbouring rows (11.46 mm)."""
    Ls = sorted(TABLE_S3)
    crossing = ratio_crossing(Ls, [TABLE_S3[L][0] / TABLE_S3[L][1] for L in Ls])
    if crossing is None:
        raise ValueError("Table S3's ratio does not cross 1")
    return crossing


PHI_END_OF_JAMMING = 0.85
"""Paper SI "Contact Volumes": sweeping L at zero strain (k = 0.1 mN/mm², Table 1's
other values), "the packing fraction that indicates the end of jamming is φ ≈ 0.85"."""

PHI_END_STRAINS_L10_5 = {"x": 0.325, "y": 0.177}
"""Paper SI "Contact Volumes": along the L = 10.5 mm sweeps, φ = 0.85 is reached at
(ε_x, ε_y) = (0.325, 0.177)."""

TABLE_S3_RMS_N = {
    10.9: 6.89e-5, 11.0: 2.30e-5, 11.1: 1.44e-5, 11.2: 3.04e-5, 11.3: 14.5e-6, 11.4: 3.63e-5,
    11.5: 2.72e-5, 11.6: 2.41e-5, 11.7: 2.01e-5, 11.8: 1.44e-5, 11.9: 8.30e-6, 12.0: 5.69e-5,
    12.8: 2.93e-6,
}  # fmt: skip
"""Paper Table S3's RMS column (N): L (mm) → RMS of a linear fit to the z force of the
same-row contacts over the first 20 points of a y pull (Δa_y = 0.001 mm). (One value
in units of 1e-6, so that the gap threshold's literal appears once only.)"""


class TableS2Row(NamedTuple):
    """One row of paper Table S2: the RMS (mJ) of a linear fit to the contact energy
    of an unjammed sweep over its first points, up to strain ``strain_final``."""

    direction: str
    k_mN_per_mm2: float
    L_mm: float
    step_mm: float
    strain_final: float
    rms_mJ: float


TABLE_S2 = (
    TableS2Row("x", 1.0, 14.0, 0.01, 0.056, 2.27e-5),
    TableS2Row("x", 1.5, 14.0, 0.01, 0.075, 4.71e-5),
    TableS2Row("x", 2.0, 15.0, 0.01, 0.052, 3.68e-5),
    TableS2Row("y", 1.0, 14.4, 0.002, 0.029, 2.51e-5),
    TableS2Row("y", 1.5, 15.4, 0.01, 0.034, 3.92e-5),
    TableS2Row("y", 2.0, 16.3, 0.002, 0.028, 3.06e-5),
)
"""Paper Table S2 (energy-gap error analysis), in its row order."""
