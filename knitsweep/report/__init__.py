"""The post-processor: results files → tables and the paper's figures (docs/model.md §9).

* :mod:`.reduce` — per-sweep metrics, per-series transitions, per-point regimes;
* :mod:`.results` — ``knitsweep.load``: the same tables as pandas DataFrames and xarray;
* :mod:`.tables` — CSV files and the printed table;
* :mod:`.figures` — the figures (matplotlib, imported only when drawing).

:func:`phase_diagram` is what ``knitsweep phase-diagram`` calls; it reads its files
with :func:`.results.load`, so the command and the Python API cannot disagree.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..analysis import GAP_THRESHOLD
from .reduce import Reduction, reduce_results
from .results import Results, load
from .tables import problems_text, transitions_text, write_tables

if TYPE_CHECKING:
    from .figures import FigureOutcome
    from .plotting import FigureOptions

__all__ = [
    "PhaseDiagramReport",
    "Reduction",
    "Results",
    "load",
    "phase_diagram",
    "problems_text",
    "reduce_results",
    "summary_lines",
    "transitions_text",
    "write_tables",
]


@dataclass(frozen=True)
class PhaseDiagramReport:
    """What :func:`phase_diagram` did: the results, the tables and the figures."""

    results: Results
    tables: list[Path]
    figures: list[FigureOutcome]

    @property
    def reduction(self) -> Reduction:
        return self.results.reduction

    def lines(self) -> list[str]:
        """The report as printed by the command."""
        out = summary_lines(self.reduction)
        out += [f"wrote {p}" for p in self.tables]
        out += [f.line for f in self.figures]
        return out


def summary_lines(red: Reduction) -> list[str]:
    """What the command prints once the files are read: the status line, the
    transitions table, the problems and the notes."""
    out = [red.status_line, "", transitions_text(red), ""]
    out += problems_text(red)
    out += [f"note: {n}" for n in red.notes]
    return out


def phase_diagram(
    results: str | Path | Sequence[str | Path],
    out_dir: str | Path | None = None,
    threshold: float = GAP_THRESHOLD,
    figures: bool = True,
    options: FigureOptions | None = None,
    progress: Callable[[str], None] | None = None,
) -> PhaseDiagramReport:
    """Read results files and write their tables and figures.

    Args:
        results: HDF5 results file(s) of ``knitsweep run`` (also while written);
            several files combine into one study (e.g. two values of k, paper Fig. 5a).
        out_dir: directory for the CSV and figure files [``<first results
            stem>_phase_diagram`` beside the first file].
        threshold: energy-gap threshold, mJ (paper: ``GAP_THRESHOLD``).
        figures: write the figures (False: tables only).
        options: formats, width, titles and style of the figures.
        progress: told each line of :meth:`PhaseDiagramReport.lines` as soon as it
            is known: the summary once the files are read, then ``wrote …`` as each
            table and figure file is written.

    Raises:
        InputError: unreadable or wrong-schema results file, threshold ≤ 0.
    """
    paths = [Path(results)] if isinstance(results, (str, Path)) else [Path(p) for p in results]
    tell = progress or (lambda line: None)
    res = load(*paths, threshold=threshold, warn=False)
    for line in summary_lines(res.reduction):
        tell(line)
    first = paths[0]
    out = Path(out_dir) if out_dir is not None else first.with_name(f"{first.stem}_phase_diagram")
    tables = write_tables(res, out, lambda path: tell(f"wrote {path}"))
    outcomes: list[FigureOutcome] = []
    if figures:
        from .figures import write_figures

        outcomes = write_figures(res.reduction, out, options, lambda o: tell(o.line))
    return PhaseDiagramReport(res, tables, outcomes)
