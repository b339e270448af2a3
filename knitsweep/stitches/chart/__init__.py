"""Knit/purl charts as cells of several stitches (docs/model.md §12); numpy only.

A knitter's chart is rows of ``K`` (knit) and ``P`` (purl), the bottom row first. Its
cell here is one course of yarn through a whole row of the chart: ``cell_stitches``
stitches, each 8 free quintic segments, every joint of the row G2 (the free yarn of
``stockinette_free``, as many joints as segments), closing by a translation of the
row's width; a purl stitch is a knit stitch seen from the back, which its start is
(its control points mirrored through the fabric plane) and which the relaxation is free
to change. The rows above repeat the row by translation, or, for a chart whose rows
alternate between a row and its purl image (every K a P: garter, seed), by the glide
that mirrors every other row (``mirror_parity`` (0, 1), with the yarn's height above
the mirror plane an entry, as garter's ``z0``). A chart whose rows differ otherwise
(moss, welting, basketweave) needs a cell of several yarns: refused with the row that
says so.

The state's periods are per stitch and the energies and length are per stitch
(``Stitch.cell_stitches``; the image group divides the cell's sums), so that a chart is
a stitch to every layer above: ``get_stitch("chart:KKPP")``. The four named patterns are
charts too (``["K"]``, ``["K", "P"]``, ``["KP"]``, ``["KP", "PK"]``), and the
charts of several of their stitches are checked against them (tests/test_charts.py).
"""

from __future__ import annotations

import functools
import importlib
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ..base import MIRROR, MIRROR_CLASSES, Gauge, Stitch
from ..stockinette_free import gauge, layout
from ..stockinette_free.ansatz import to_free

PREFIX = "chart:"
"""A chart's stitch name is this and its rows, bottom first, joined by ``ROW_SEPARATOR``
(``chart:KP-PK``)."""
ROW_SEPARATOR = "-"
ROW_SPLIT = re.compile(r"[-/,\s]+")
"""What separates rows in a chart written in one string (``--chart KP/PK``)."""
MAX_CELL_STITCHES = 16
"""Most stitches in a chart's row: the relaxation's Hessian is dense, (85 n)² entries
for n stitches (16: 1360², 15 MB, and a factorisation 4096 times one stitch's), and the
cell's Jacobian 8 n × 18 × 85 n doubles (16: 26 MB)."""
SEGMENTS_PER_STITCH = 8


def complement(row: str) -> str:
    """The row seen from the back: every K a P and every P a K."""
    return row.translate(str.maketrans("KP", "PK"))


def parse_chart(chart: object, field: str = "chart") -> tuple[str, ...]:
    """The rows of a chart (bottom row first, upper case), from a list of strings or one
    string whose rows are separated by ``-``, ``/``, ``,`` or spaces; InputError naming
    ``field``, the row and the column of what is wrong."""
    if isinstance(chart, str):
        rows = [r for r in ROW_SPLIT.split(chart.strip()) if r]
    elif isinstance(chart, Sequence) and all(isinstance(r, str) for r in chart):
        rows = [r.strip() for r in chart]
    else:
        raise InputError(f"{field} = {chart!r}: a chart is a list of rows of K and P, "
                         "bottom row first, e.g. [\"KKPP\"] (2x2 rib)")  # fmt: skip
    if not rows:
        raise InputError(f"{field} = {chart!r}: an empty chart; give at least one row of K "
                         "and P")  # fmt: skip
    rows = [r.upper() for r in rows]
    for i, row in enumerate(rows, 1):
        if not row:
            raise InputError(f"{field} row {i}: an empty row; every row needs K or P stitches")
        for j, ch in enumerate(row, 1):
            if ch not in "KP":
                raise InputError(f"{field} row {i}, column {j} = {ch!r}: a stitch is K (knit) "
                                 "or P (purl)")  # fmt: skip
        if len(row) != len(rows[0]):
            raise InputError(f"{field} row {i} = {row!r}: {len(row)} stitches, row 1 has "
                             f"{len(rows[0])}; every row of a chart has as many")  # fmt: skip
    width = len(rows[0])
    if width > MAX_CELL_STITCHES:
        n = 85 * width
        raise InputError(f"{field}: a row of {width} stitches is a cell of {n} state entries "
                         f"(a dense {n} x {n} Hessian, {8 * n * n / 2**20:.0f} MB); at most "
                         f"{MAX_CELL_STITCHES} stitches in a row")  # fmt: skip
    return tuple(rows)


def row_and_parity(rows: tuple[str, ...], field: str = "chart") -> tuple[str, int]:
    """(the cell's row, pn): pn 0 if every row is the first (the rows translate), 1 if
    the rows alternate between the first and its purl image (every other row mirrored);
    InputError naming the first row that is neither (a cell of several yarns)."""
    first, back = rows[0], complement(rows[0])
    if all(r == first for r in rows):
        return first, 0
    if len(rows) % 2 == 0 and all(r == (first if i % 2 == 0 else back) for i, r in enumerate(rows)):
        return first, 1
    # the first row that breaks the alternation, else the last (an odd number of rows)
    bad = next((i for i, r in enumerate(rows) if r != (back if i % 2 else first)), len(rows) - 1)
    raise InputError(f"{field} row {bad + 1} = {rows[bad]!r}: the rows of a chart here are "
                     f"its first row, {first!r}, repeated, or alternating with its purl image "
                     f"{back!r} over an even number of rows; other charts need a cell of "
                     "several yarns, not supported yet")  # fmt: skip


def chart_stitch_names(value: object, field: str = "chart") -> list[str]:
    """The stitch names of a job's ``chart`` entry: one chart (a list of rows, or one
    string) or several (a list of charts, each a list of rows); InputError naming
    ``field`` (with the chart's number among several) and what is wrong."""
    if isinstance(value, list) and value and all(isinstance(c, list) for c in value):
        charts = [(c, f"{field}[{i}]") for i, c in enumerate(value)]
    else:
        charts = [(value, field)]
    names = []
    for chart, where in charts:
        rows = parse_chart(chart, where)
        row_and_parity(rows, where)
        names.append(chart_name(rows))
    return names


def chart_name(rows: Sequence[str]) -> str:
    """The stitch name of a chart (``PREFIX`` and its rows)."""
    return PREFIX + ROW_SEPARATOR.join(rows)


def is_chart_name(name: object) -> bool:
    return isinstance(name, str) and name.startswith(PREFIX)


def check_chart_name(name: str, field: str = "stitch") -> str:
    """The canonical name of the chart ``name`` names (``chart:`` and its rows); InputError
    naming ``field`` and what is wrong."""
    rows = parse_chart(name[len(PREFIX) :], field)
    row_and_parity(rows, field)
    return chart_name(rows)


def _source(row: str, pn: int) -> str:
    """The one-stitch pattern whose starts a chart's stitches take their shape from: the
    knit stitch of rib (pn 0) or seed (pn 1) where the row mixes K and P (its yarn passes
    through the fabric plane between them), of the free stockinette (pn 0) or garter (pn
    1) where it does not."""
    mixed = "K" in row and "P" in row
    return ("seed" if mixed else "garter") if pn else ("rib" if mixed else "stockinette_free")


@dataclass(frozen=True, eq=False)
class ChartStitch(Stitch):
    """A chart's cell (module docstring): a ``Stitch`` whose starts are built from its
    source pattern's (``_source``) rather than read."""

    rows: tuple[str, ...] = ()
    row: str = ""
    source: str = ""

    @property
    def mixes_row(self) -> bool:
        return "K" in self.row and "P" in self.row

    @property
    def keeps_linking(self) -> bool:
        row = self.row
        twins = any(row[i] == row[i - 1] for i in range(len(row)))  # cyclically
        return self.mixes_row and twins

    @property
    def segment_names(self) -> tuple[str, ...]:
        """Segment s of the cell as "segment s (stitch c of the row, K or P)"."""
        per = SEGMENTS_PER_STITCH
        return tuple(f"segment {s} (stitch {s // per + 1} of the row, {self.row[s // per]})"
                     for s in range(self.n_segments))  # fmt: skip

    def shipped_starts(self) -> tuple[np.ndarray, ...]:
        starts = self._loaded.get("starts")
        if starts is None:
            starts = tuple(self._build_start(i) for i in range(1, self.n_starts + 1))
            for x in starts:
                x.setflags(write=False)
            self._loaded["starts"] = starts
        return starts

    def _build_start(self, index: int) -> np.ndarray:
        src = _source_stitch(self.source)
        x = src.start(index)
        cp, jac = src.buffers()
        src.control_points(x, cp, jac)
        return row_state(cp, float(x[-2]), float(x[-1]), self.row, lifted=any(self.mirror_parity))


def row_state(cp: np.ndarray, a_x: float, a_y: float, row: str, lifted: bool) -> np.ndarray:
    """The chart state of a row of stitches (``row``, K and P), each the stitch of control
    points ``cp`` (8, 6, 3), mm, seen from the front (K) or the back (P, mirrored through
    z = 0), placed a_x apart along the course: the chain read into the free layout
    (``ansatz.to_free``), with z0 (joint 0's height above the mirror plane) before the
    periods when ``lifted``. Where a stitch meets one of the same kind the chain has the
    source's junction into a mirrored stitch, which the free layout reads G2 (a start)."""
    cp = np.asarray(cp, dtype=float)
    pieces = [(cp * MIRROR if ch == "P" else cp) + np.array([c * a_x, 0.0, 0.0])
              for c, ch in enumerate(row)]  # fmt: skip
    chain = np.concatenate(pieces)
    x = to_free(chain, a_x, a_y)
    if lifted:
        x = np.concatenate([x[:-2], [chain[0, 0, 2]], x[-2:]])
    return x


def supercell_state(x: np.ndarray, cp: np.ndarray, parity: tuple[int, int], copies: int,
                    lifted: bool) -> np.ndarray:  # fmt: skip
    """A one-stitch pattern's state ``x`` (control points ``cp``, mirror ``parity``) as the
    chart state of ``copies`` of its row's repeat: the stitch and its images (m, 0), m = 0
    .. copies·w − 1 with w = 2 where the row mirrors (rib, seed), so that the chart's row is
    that pattern's, the same curve (to round-off)."""
    w = 2 if parity[0] else 1
    row = "".join("P" if (parity[0] * m) % 2 else "K" for m in range(w * copies))
    return row_state(cp, float(x[-2]), float(x[-1]), row, lifted)


def _source_stitch(name: str) -> Stitch:
    """A named pattern's stitch (the registry's subpackage), without importing the
    registry above this module."""
    return importlib.import_module(f"knitsweep.stitches.{name}").STITCH


def _bounds(n_segments: int, stitches: int, lifted: bool):
    def bounds(L: float, r: float, sampling: str = "parameter"):
        lo, hi = layout.chain_bounds(n_segments, stitches, L, r, sampling)
        if lifted:  # |z0| <= L, before the periods
            lo = np.concatenate([lo[:-2], [-L], lo[-2:]])
            hi = np.concatenate([hi[:-2], [L], hi[-2:]])
        return lo, hi

    return bounds


@functools.lru_cache(maxsize=64)
def chart_stitch(name: str) -> ChartStitch:
    """The stitch of the chart called ``name`` (``chart:`` and its rows; InputError if it
    is not a chart this module builds)."""
    rows = parse_chart(name[len(PREFIX) :], "stitch")
    row, pn = row_and_parity(rows, "stitch")
    c = len(row)
    n_seg = SEGMENTS_PER_STITCH * c
    lifted = pn == 1
    names = layout.chain_names(n_seg)
    if lifted:
        names = (*names[:-2], "z0", *names[-2:])
    source = _source(row, pn)
    src = _source_stitch(source)
    kind = {0: "rows repeated", 1: "every other row mirrored"}[pn]
    return ChartStitch(
        name=chart_name(rows),
        description=f"chart {' / '.join(rows)} (bottom row first): a row of {c} stitch"
        f"{'es' if c > 1 else ''} {row}, {kind}",
        state_names=names,
        n_segments=n_seg,
        segment_weights=np.ones(n_seg),
        bounds=_bounds(n_seg, c, lifted),
        twist_index=None,
        starts=tuple(f"{source}'s {start}" for start in src.starts),
        data_package=src.data_package,
        geometry_module="knitsweep.stitches.chart.geometry",
        images="glides",
        contact_classes=MIRROR_CLASSES,
        path_order=tuple(range(n_seg)),
        closing_shift=(c, 0),
        mirror_parity=(0, pn),
        rough=src.rough or "P" in row,
        stage_dL_mm=src.stage_dL_mm,
        gauge=Gauge(
            gauge.speed_entries(n_seg), gauge.regauge, gauge.JOINT_STIFFNESS, gauge.JOINT_RULE
        ),
        cell_stitches=c,
        rows=rows,
        row=row,
        source=source,
    )
