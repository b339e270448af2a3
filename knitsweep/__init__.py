"""knitsweep: fast simulations of jammed knitted fabric (stockinette and knit/purl patterns).

Importing the package does no work: no MPI, no numba compilation, no file access.
``knitsweep.load(*paths)`` reads results files into pandas DataFrames and an
xarray Dataset (``knitsweep.report.results``); ``knitsweep.load_energy_density(path)``
reads a fabric's fitted energy density (``knitsweep.analysis.energy_density``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from .report.results import Results

from ._version import __version__

__all__ = ["__version__", "load", "load_energy_density"]


def load(*paths: str | Path, threshold: float | None = None, all_columns: bool = False) -> Results:
    """Read one or several results files (also while a run writes them) into
    :class:`knitsweep.report.results.Results`: ``points``, ``sweeps``, ``curves``,
    ``transitions`` and ``problems`` DataFrames and ``to_xarray()``.

    ``threshold``: the energy-gap threshold between jammed and unjammed (mJ;
    default the paper's, ``knitsweep.analysis.transitions.GAP_THRESHOLD``);
    ``all_columns``: keep the columns that no task of the files stored (contact forces,
    packing fractions: all NaN), which are left out by default. Damaged
    tasks are skipped with a ``knitsweep.errors.DamagedResultsWarning`` naming how
    many and the first ids (``res.problems`` lists them all, ``status`` "damaged").
    """
    from .analysis.transitions import GAP_THRESHOLD
    from .report.results import load as _load
    from .report.results import warn_damaged

    res = _load(
        *paths,
        threshold=GAP_THRESHOLD if threshold is None else threshold,
        all_columns=all_columns,
        warn=False,
    )
    warn_damaged(res.reduction.roots)  # (stacklevel: the caller's line)
    return res


def load_energy_density(path: str | Path):
    """Read an energy density written by ``knitsweep energy-density``: an
    :class:`knitsweep.analysis.energy_density.EnergyDensity` with ``W``, ``stress`` and
    ``tangent`` at any strain (ε_xx, ε_yy) and ``in_domain``."""
    from .analysis.energy_density import load_energy_density as _load_density

    return _load_density(path)
