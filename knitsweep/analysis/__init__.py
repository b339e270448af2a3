"""Post-processing of strain sweeps into the paper's jamming metrics (docs/model.md §9).

Pure numpy, no I/O: arrays and floats in, frozen dataclasses out (each with an
``as_dict()`` of plain, NaN-free values; None means "not available").

* :mod:`.metrics` — one sweep: secant modulus Y_sec, offset stress σ0, energy gaps
  ΔE_b and ΔE_c, aspect ratio, area and thickness strains.
* :mod:`.transitions` — a series in L/r: the onset of unjamming (L/r)_trans, its
  bracket, the jammed-regime line fit over the linear run (Table S4) and ΔL/r;
  regimes; grouping of records into series.
* :mod:`.fitting` — the straight-line least-squares fit both use.
* :mod:`.paper` — the paper's tabulated numbers, for comparisons only.
"""

from .fitting import LinearFit, fit_line
from .metrics import (
    JAMMING_GAP,
    SECANT_STRAIN,
    EnergyGaps,
    OffsetStress,
    SecantModulus,
    StressDrops,
    SweepMetrics,
    area_strain,
    aspect_ratio,
    energy_gaps,
    offset_stress,
    secant_modulus,
    stress_drops,
    sweep_metrics,
    tangent_modulus,
    thickness_strain,
)
from .transitions import (
    GAP_THRESHOLD,
    RARE_REGIME,
    REGIMES,
    SERIES_KEYS,
    GapSeries,
    Transition,
    group_series,
    linear_jammed_run,
    regime,
    series_transitions,
    threshold_crossing,
    transition,
    transition_from_bracket,
)

__all__ = [
    "GAP_THRESHOLD",
    "JAMMING_GAP",
    "RARE_REGIME",
    "REGIMES",
    "SECANT_STRAIN",
    "SERIES_KEYS",
    "EnergyGaps",
    "GapSeries",
    "LinearFit",
    "OffsetStress",
    "SecantModulus",
    "StressDrops",
    "SweepMetrics",
    "Transition",
    "area_strain",
    "aspect_ratio",
    "energy_gaps",
    "fit_line",
    "group_series",
    "linear_jammed_run",
    "offset_stress",
    "regime",
    "secant_modulus",
    "series_transitions",
    "stress_drops",
    "sweep_metrics",
    "tangent_modulus",
    "thickness_strain",
    "threshold_crossing",
    "transition",
    "transition_from_bracket",
]
