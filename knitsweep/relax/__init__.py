"""Constrained relaxation at fixed yarn length, and continuation in parameters.

docs/model.md §7: minimise E = E_b + E_c subject to length(x) = L and cos(tw) >= c_tw,
either with every entry free (the zero-force state) or with one cell period fixed (a
strain step), by a Newton–KKT trust-region method (``newton``) or SciPy's SLSQP
(``slsqp``), both on the exact gradients. Every result says truthfully how it ended
(``result.assess``): a non-finite, unconverged or core-overlapping state is never
called converged.
"""

from ..config import CONVERGED, NOT_CONVERGED, NOT_KNITTABLE
from .chains import Chain, merge_chains
from .continuation import continuation_path, walk_starts
from .newton import Curvature
from .relaxer import Relaxer, free_entries, relax, single_threaded
from .result import Relaxation

__all__ = [
    "CONVERGED",
    "NOT_CONVERGED",
    "NOT_KNITTABLE",
    "Chain",
    "Curvature",
    "Relaxation",
    "Relaxer",
    "continuation_path",
    "free_entries",
    "merge_chains",
    "relax",
    "single_threaded",
    "walk_starts",
]
