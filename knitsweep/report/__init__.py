"""The post-processor: a results file → tables and the paper's figures (docs/model.md §9).

* :mod:`.reduce` — per-sweep metrics, per-series transitions, per-point regimes;
* :mod:`.tables` — CSV files and the printed table;
* :mod:`.figures` — the PNG figures (matplotlib, imported only when drawing).

:func:`phase_diagram` is what ``knitsweep phase-diagram`` calls.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..analysis import GAP_THRESHOLD
from .reduce import Reduction, reduce_results
from .tables import problems_text, transitions_text, write_tables

if TYPE_CHECKING:
    from .figures import FigureOutcome

__all__ = [
    "PhaseDiagramReport",
    "Reduction",
    "phase_diagram",
    "problems_text",
    "reduce_results",
    "transitions_text",
    "write_tables",
]


@dataclass(frozen=True)
class PhaseDiagramReport:
    """What :func:`phase_diagram` did: the reduction, the tables and the figures."""

    reduction: Reduction
    tables: list[Path]
    figures: list[FigureOutcome]

    def lines(self) -> list[str]:
        """The report as printed by the command."""
        red = self.reduction
        out = [red.status_line, "", transitions_text(red), ""]
        out += problems_text(red)
        out += [f"note: {n}" for n in red.notes]
        out += [f"wrote {p}" for p in self.tables]
        out += [f.line for f in self.figures]
        return out


def phase_diagram(
    results: str | Path,
    out_dir: str | Path | None = None,
    threshold: float = GAP_THRESHOLD,
    figures: bool = True,
) -> PhaseDiagramReport:
    """Reduce a results file and write its tables and figures.

    Args:
        results: HDF5 results file of ``knitsweep run`` (also while it is written).
        out_dir: directory for the CSV and PNG files [``<results stem>_phase_diagram``
            beside the results file].
        threshold: energy-gap threshold, mJ (paper: ``GAP_THRESHOLD``).
        figures: write the PNG figures (False: tables only).

    Raises:
        InputError: unreadable or wrong-schema results file, threshold ≤ 0.
    """
    results = Path(results)
    red = reduce_results(results, threshold)
    out = (
        Path(out_dir) if out_dir is not None else results.with_name(f"{results.stem}_phase_diagram")
    )
    tables = write_tables(red, out)
    outcomes: list[FigureOutcome] = []
    if figures:
        from .figures import write_figures

        outcomes = write_figures(red, out)
    return PhaseDiagramReport(red, tables, outcomes)
