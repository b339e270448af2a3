"""Figures that fit: every figure at ``--width column`` and ``page``, drawn with the Agg
renderer, has no text overlapping other text and none past the figure's edge (boxes
from ``get_window_extent`` of every text artist drawn), fonts of at least 7 pt; its PDF
embeds TrueType fonts only (``pdffonts`` of poppler-utils, a real PDF tool) and its
SVG keeps text as text."""

import io
import shutil
import subprocess
from itertools import combinations

import numpy as np
import pytest
from results_factory import write_results

from knitsweep.report import load
from knitsweep.report.figures import FIGURES
from knitsweep.report.plotting import FigureOptions, SkipFigure, finish, style

WIDTHS = ("column", "page")
EDGE_PX = 1.0  # a box may touch the edge by a pixel (anti-aliasing)
OVERLAP_PX2 = 4.0  # two boxes may share a sliver of two by two pixels


@pytest.fixture(scope="module")
def reduction(tmp_path_factory):
    """The synthetic series written for two stitches, so that every series label carries
    the stitch and the patterns figure has something to compare, and along biaxial load
    paths too (the in-plane figure)."""
    path = write_results(tmp_path_factory.mktemp("lay") / "synthetic.h5",
                         stitches=("stockinette", "garter"),
                         directions=("x", "y", "biaxial", "strip_x", "ray:1,-0.2"))  # fmt: skip
    return load(path).reduction


def drawn_texts(fig):
    """[(text artist, its box in display pixels)] of every non-empty text the Agg
    renderer draws (tick labels past the axis limits are not drawn, so not counted)."""
    from matplotlib.text import Text

    drawn = []
    real = Text.draw

    def record(self, renderer):
        real(self, renderer)
        if self.get_visible() and self.get_text().strip():
            drawn.append((self, self.get_window_extent(renderer)))

    Text.draw = record
    try:
        fig.canvas.draw()
    finally:
        Text.draw = real
    return drawn


def layout_problems(fig) -> list[str]:
    """Texts past the figure's edge, overlapping pairs, fonts under 7 pt."""
    texts = drawn_texts(fig)
    W, H = fig.bbox.width, fig.bbox.height
    out = []
    for t, b in texts:
        label = repr(t.get_text()[:40])
        if b.x0 < -EDGE_PX or b.y0 < -EDGE_PX or b.x1 > W + EDGE_PX or b.y1 > H + EDGE_PX:
            out.append(f"{label} past the edge: {b.bounds} in {W:.0f} x {H:.0f}")
        if any(line.replace("\\$", "").count("$") % 2 for line in t.get_text().split("\n")):
            out.append(f"{label}: a line breaks a $math$ span (its source would show)")
        if t.get_fontsize() < 7.0 - 1e-9:
            out.append(f"{label}: {t.get_fontsize():.1f} pt")
    for (t1, b1), (t2, b2) in combinations(texts, 2):
        w = min(b1.x1, b2.x1) - max(b1.x0, b2.x0)
        h = min(b1.y1, b2.y1) - max(b1.y0, b2.y0)
        if w > 0 and h > 0 and w * h > OVERLAP_PX2:
            out.append(f"{t1.get_text()[:30]!r} overlaps {t2.get_text()[:30]!r}")
    for legend in [*fig.legends, *(a.get_legend() for a in fig.axes if a.get_legend())]:
        b = legend.get_window_extent(fig.canvas.get_renderer())
        if b.x0 < -EDGE_PX or b.y0 < -EDGE_PX or b.x1 > W + EDGE_PX or b.y1 > H + EDGE_PX:
            out.append(f"legend clipped: {b.bounds} in {W:.0f} x {H:.0f}")
    return out


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", list(FIGURES))
def test_figures_fit_their_width(reduction, name, width):
    with style(FigureOptions(width=width, style="knitsweep")):
        try:
            fig = finish(FIGURES[name](reduction, []))
        except SkipFigure:
            pytest.fail(f"{name}: the synthetic file has data for every figure")
        expected = {"column": 3.4, "page": 7.0}[width]
        assert fig.get_figwidth() in (expected, 7.0), fig.get_figwidth()  # wide ones: a page
        problems = layout_problems(fig)
    assert not problems, "\n".join(problems)


def test_the_overlap_check_finds_overlaps():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_title("a title far too long for a figure two inches wide")
    ax.text(0.5, 0.5, "one")
    ax.text(0.5, 0.5, "two")
    ax.set_xlabel("onset $(L/r)_{\\rm\ntrans}$")
    problems = layout_problems(fig)
    assert any("breaks a $math$ span" in p for p in problems)
    assert any("past the edge" in p for p in problems)
    assert any("'one' overlaps 'two'" in p for p in problems)


def test_pdf_fonts_are_truetype_and_svg_text_is_text(reduction, tmp_path):
    pdffonts = shutil.which("pdffonts")
    assert pdffonts, "pdffonts (poppler-utils) is missing: bash .ci/browser-up.sh installs it"
    with style(FigureOptions(width="column", style="knitsweep")):
        fig = FIGURES["fig3_energy_gaps.png"](reduction, [])
        pdf = tmp_path / "f.pdf"
        fig.savefig(pdf)
        svg = io.BytesIO()
        fig.savefig(svg, format="svg")
    listing = subprocess.run([pdffonts, str(pdf)], capture_output=True, text=True, check=True)
    rows = listing.stdout.splitlines()[2:]  # after the header and its rule
    assert rows, listing.stdout
    assert all(" TrueType " in r or "CID TrueType" in r for r in rows), listing.stdout
    assert "Type 3" not in listing.stdout
    text = svg.getvalue().decode()
    assert "<text" in text and "energy gap" in text


def labels_on_data(fig) -> list[str]:
    """Texts and legends inside an axes that cover its data (markers, lines in data
    coordinates: ``declutter.data_points``), after the figure is drawn."""
    from knitsweep.report.declutter import covers, data_points

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    out = []
    for ax in fig.axes:
        pts, half = data_points(ax, renderer)
        if not len(pts):
            continue
        labels = [t for t in ax.texts if t.get_visible() and t.get_text().strip()]
        legend = ax.get_legend()
        for a in labels + ([legend] if legend is not None else []):
            n = covers(a.get_window_extent(renderer), pts, half)
            if n:
                what = repr(a.get_text()[:40]) if hasattr(a, "get_text") else "a legend"
                out.append(f"{what} covers {n} data points of {ax.get_title()[:30]!r}")
    return out


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", list(FIGURES))
def test_no_label_covers_data(reduction, name, width):
    with style(FigureOptions(width=width, style="knitsweep")):
        fig = finish(FIGURES[name](reduction, []))
        problems = labels_on_data(fig)
    assert not problems, "\n".join(problems)


def test_the_data_check_finds_labels_on_data():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 3))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1], marker="o", ls="none")
    ax.scatter([0.5], [0.2], s=80)
    ax.plot([0, 1], [1, 0])
    ax.text(0.0, 0.0, "on a marker")
    ax.text(0.5, 0.2, "on a scatter point")
    ax.text(0.5, 0.5, "on the line")
    ax.text(0.1, 0.55, "free")
    got = labels_on_data(fig)
    assert len(got) == 3 and not any("free" in g for g in got), got


def test_declutter_moves_a_legend_off_the_data():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    x = np.linspace(0, 1, 30)
    ax.plot(x, 1 - x, marker="o", label="falling, a long label")
    ax.plot(x, x, marker="s", label="rising, a long label")
    ax.legend(loc="center")  # on the crossing
    assert labels_on_data(fig)
    finish(fig)
    assert not labels_on_data(fig)


@pytest.mark.parametrize("width", WIDTHS)
def test_fig4c_draws_every_series_and_names_every_region(reduction, width):
    """A panel for each stitch's series, and the legend has an entry of every colour
    that shades a regime (the 'jammed only in x' region too)."""
    from matplotlib.colors import to_hex

    from knitsweep.report.plotting import REGIME_FILL

    with style(FigureOptions(width=width, style="knitsweep")):
        fig = finish(FIGURES["fig4c_phase_diagram.png"](reduction, []))
    titles = " ".join(ax.get_title() for ax in fig.axes)
    assert "stitch = stockinette" in titles and "stitch = garter" in titles, titles
    regime = {to_hex(c) for c in REGIME_FILL.values()}

    def fills(artists):
        return {to_hex(c) for a in artists if hasattr(a, "get_facecolor")
                for c in np.atleast_2d(a.get_facecolor())} & regime  # fmt: skip

    drawn = [a for ax in fig.axes for a in [*ax.patches, *ax.collections]
             if not hasattr(a, "get_paths") or any(len(q.vertices) for q in a.get_paths())]  # fmt: skip
    shaded = fills(drawn)
    named = fills(h for leg in fig.legends for h in leg.legend_handles)
    assert shaded and shaded <= named, (shaded, named)


def test_fig4c_names_the_jammed_only_in_x_region(reduction):
    """Where (L/r)_trans in x lies above y's (jammed in x after y has unjammed), the
    lavender region is drawn and the legend names it (it once named three regions
    whatever was drawn)."""
    import dataclasses

    from knitsweep.report.plotting import REGIME_LABEL

    y_of = {tuple(t[p] for p in ("stitch", "k_mN_per_mm2", "r_mm")): t["L_over_r_trans"]
            for t in reduction.transitions if t["direction"] == "y"}  # fmt: skip
    moved = []
    for t in reduction.transitions:
        key = tuple(t[p] for p in ("stitch", "k_mN_per_mm2", "r_mm"))
        if t["direction"] == "x" and t["status"] == "transition" and y_of.get(key) is not None:
            t = {**t, "L_over_r_trans": y_of[key] + 0.3}
        moved.append(t)
    red = dataclasses.replace(reduction, transitions=moved)
    with style(FigureOptions(width="page", style="knitsweep")):
        fig = finish(FIGURES["fig4c_phase_diagram.png"](red, []))
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert REGIME_LABEL["jammed_x_only"] in labels, labels


def test_a_movable_note_on_another_text_is_moved_off_it():
    """A note (``movable``) drawn over a fixed label, away from any data (the ΔL/r note
    of fig3 on the (L/r)_trans line's label, seen at the paper's k = 0.1), leaves it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from knitsweep.report.declutter import declutter, movable

    fig = Figure(figsize=(4, 3))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot([0.0, 1.0], [0.0, 0.2], marker="o")
    ax.set_ylim(0, 1)
    ax.text(0.5, 0.8, "15.54")
    movable(ax.text(0.49, 0.8, "ΔL/r = -0.073\n(zero beyond the transition)"))
    assert any("overlaps" in p for p in layout_problems(fig))
    declutter(fig)
    assert not layout_problems(fig), layout_problems(fig)
