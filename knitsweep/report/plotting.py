"""Shared look of the phase-diagram figures: colours, fonts, panels, labels.

matplotlib is imported here lazily (inside functions), and only through its
object-oriented API with the Agg canvas: no pyplot, no global backend switch, no
display. Colours follow the paper: contact energy coral and bending energy blue
(Fig. 3); regimes pink (jammed in x and y), orange (jammed only in y) and green
(unjammed) (Fig. 4c, 5a); pulls in x purple and in y blue (Fig. S4, S5).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..quantities import SERIES_PARAMS
from .path_style import RAY_COLOUR, PerPath
from .reduce import Reduction
from .series import series_key
from .tables import series_label

CONTACT_COLOUR = "#ee6a50"  # coral: contact energy gap ΔE_c
BENDING_COLOUR = "#2f6db5"  # blue: bending energy gap ΔE_b


DIRECTION_COLOUR = PerPath(
    {
        "x": "#7b3fa0",
        "y": "#2f8fd0",  # paper SI: x purple, y blue
        "biaxial": "#c0392b",
        "strip_x": "#b8860b",
        "strip_y": "#138d75",
        "shear": "#d35400",
        "shear_free": "#7f8c8d",
    },
    lambda _path: RAY_COLOUR,
)
REGIME_FILL = {
    "jammed_xy": "#f6c4d6",  # pink
    "jammed_y_only": "#fbd5a5",  # orange
    "jammed_x_only": "#cfc8e8",  # lavender: the converse the paper finds very unlikely
    "unjammed": "#cde9c3",  # green
}
REGIME_LABEL = {
    "jammed_xy": "jammed in x and y",
    "jammed_y_only": "jammed only in y",
    "jammed_x_only": "jammed only in x (rare)",
    "unjammed": "unjammed",
}
TRANSITION_LINE = PerPath(
    {
        "x": "#d9730d",
        "y": "#2e8b46",  # paper Fig. 4c: x orange, y green
        "biaxial": "#c0392b",
        "strip_x": "#8e6c0b",
        "strip_y": "#117864",
        "shear": "#a04000",
        "shear_free": "#616a6b",
    },
    lambda _path: RAY_COLOUR,
)
BRACKET_FILL = "#b9e3b0"  # light green: the transition bracket (paper Fig. 3)
THRESHOLD_COLOUR = "#555555"
PARTIAL_COLOUR = "#b00020"
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h")
LINESTYLES = ("-", "--", "-.", ":")

STYLE = {
    "font.family": "DejaVu Sans",
    "mathtext.fontset": "dejavusans",
    "font.size": 11,
    "axes.titlesize": 11,
    "axes.labelsize": 11,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "legend.fontsize": 10,
    "legend.title_fontsize": 10,
    "figure.titlesize": 12,
    "axes.grid": True,
    "grid.alpha": 0.25,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "lines.linewidth": 1.6,
    "lines.markersize": 5.5,
    "savefig.dpi": 150,
}

WIDTHS = {"column": 3.4, "page": 7.0}
"""Journal figure widths, inches: one column, the whole page."""

JOURNAL_RC = {
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "legend.fontsize": 7,
    "legend.title_fontsize": 7,
    "figure.titlesize": 8,
    "lines.linewidth": 1.1,
    "lines.markersize": 3.5,
    "axes.linewidth": 0.6,
    "savefig.dpi": 300,
}
"""Sizes at journal widths: fonts of 7–8 pt at the printed size."""


FILE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42, "svg.fonttype": "none"}
"""Fonts in the files, whatever the style: TrueType (Type 42) in PDF and PostScript,
which journals accept (Type 3 they often refuse), and SVG text as text, editable."""


@dataclass(frozen=True)
class FigureOptions:
    """How the figures are drawn (``knitsweep phase-diagram --format/--width/--style``).

    Attributes:
        formats: file formats to write, of png, pdf, svg.
        width: 'auto' (each figure its own size, the user's font sizes), 'column'
            (3.4 in) or 'page' (7.0 in), with fonts of 7–8 pt at that width.
        title: draw each figure's title (what it shows and the fixed parameters).
        style: None keeps the user's matplotlib style (matplotlibrc); 'knitsweep' is
            this project's look; any other name or path is a matplotlib style.
    """

    formats: tuple[str, ...] = ("png",)
    width: str = "auto"
    title: bool = True
    style: str | None = None

    def __post_init__(self) -> None:
        from ..errors import InputError

        bad = [f for f in self.formats if f not in FORMATS]
        if bad or not self.formats:
            raise InputError(f"format = {','.join(self.formats)!r}: give one or more of "
                             f"{', '.join(FORMATS)}, comma-separated")  # fmt: skip
        if self.width not in ("auto", *WIDTHS):
            raise InputError(f"width = {self.width!r}: must be auto, column or page")


FORMATS = ("png", "pdf", "svg")
_OPTIONS: contextvars.ContextVar[FigureOptions | None] = contextvars.ContextVar(
    "figure_options", default=None
)


def current_options() -> FigureOptions:
    """The options of the figures being drawn (set by ``style``)."""
    return _OPTIONS.get() or FigureOptions()


L_OVER_R = "$L/r$"


MAX_PANELS = 8


class SkipFigure(Exception):
    """A figure the results file has no data for; the message says why."""


@contextlib.contextmanager
def style(options: FigureOptions | None = None) -> Iterator[None]:
    """The figures' look for the duration of drawing and saving: the user's
    matplotlib style unless ``options.style`` names one, plus the journal sizes when
    a journal width is asked for."""
    import matplotlib
    import matplotlib.style

    options = options or FigureOptions()
    token = _OPTIONS.set(options)
    try:
        with contextlib.ExitStack() as stack:
            if options.style == "knitsweep":  # matplotlib's defaults, then this look
                stack.enter_context(matplotlib.style.context(["default", STYLE]))
            elif options.style is not None:
                try:
                    stack.enter_context(matplotlib.style.context(options.style))
                except OSError:
                    from ..errors import InputError

                    raise InputError(f"style = {options.style!r}: not a matplotlib style "
                                     "(name, file or URL) nor 'knitsweep'") from None  # fmt: skip
            if options.width != "auto":
                stack.enter_context(matplotlib.rc_context(JOURNAL_RC))
            stack.enter_context(matplotlib.rc_context(FILE_RC))
            yield
    finally:
        _OPTIONS.reset(token)


def new_figure(width: float, height: float, wide: bool = False) -> Any:
    """A matplotlib Figure on an Agg canvas (constrained layout). ``width`` and
    ``height`` (inches) are the figure's own size; at a journal width it is scaled
    to that width (a ``wide`` figure, too dense for one column, to the page width
    even when one column is asked for)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    options = current_options()
    if options.width != "auto":
        # fonts do not shrink with the figure: the height shrinks less than the width
        target = WIDTHS["page" if wide else options.width]
        height = min(max(height * (target / width) ** 0.35, 0.5 * target), 2.2 * target)
        width = target
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def title(fig: Any, red: Reduction, text: str) -> None:
    """Figure title: what it shows and the fixed parameters; for a partial results
    file, a first line saying so, and the whole title in red. Without titles
    (``FigureOptions.title``) a partial file still gets its warning line."""
    options = current_options()
    fixed = series_label(red.constants, red.constants)
    lines = [text] + ([fixed] if fixed else []) if options.title else []
    if red.partial:
        lines.insert(0, f"PARTIAL RESULTS ({red.partial_reason})")
    # a character of the title's type is ~0.55 of its size wide: wrap to the figure
    size = font_points("figure.titlesize")
    chars = max(20, int(fig.get_figwidth() * 72.0 / (0.55 * size * 1.2)))
    lines = [
        w
        for i, line in enumerate(lines)
        for w in _balanced(line, chars, i > 0 and fixed and line == fixed)
    ]
    if lines:
        fig.suptitle("\n".join(lines), fontsize=size * 1.2,
                     color=PARTIAL_COLOUR if red.partial else "black")  # fmt: skip


def panel_title(ax: Any, head: str, *details: str, **kw: Any) -> None:
    """A panel's title: ``head`` and its details joined by '; ' when that fits over the
    panel, else one per line (always at column width); a detail too long for the panel
    (a series label, 'stitch = garter, k = 0.1 mN/mm²') breaks between its parameters,
    never inside one 'symbol = value unit', so that neighbouring titles do not meet
    and none runs past the figure's edge."""
    parts = [head, *(d for d in details if d)]
    chars = panel_chars(ax, font_points("axes.titlesize", kw.get("fontsize")))
    line = "; ".join(parts)
    if not narrow() and _visible(line) <= chars:
        ax.set_title(line, **kw)
        return
    lines = [w for i, p in enumerate(parts) for w in _wrap(p, chars, parameters=i > 0)]
    ax.set_title("\n".join(lines), **kw)


def title_overhangs(ax: Any) -> bool:
    """Whether a line of the title of ``ax`` is likely wider than the axes (the
    constrained layout makes no room for that overhang at the sides)."""
    size = ax.title.get_fontsize()
    lines = ax.get_title().split("\n")
    return max(map(_visible, lines)) > panel_chars(ax, size) / 1.1


def font_points(rc_key: str, size: Any = None) -> float:
    """A font size in points: ``size`` (points or a name such as 'large'), else the
    matplotlib setting ``rc_key`` (e.g. 'legend.fontsize')."""
    import matplotlib
    from matplotlib.font_manager import FontProperties

    return FontProperties(size=matplotlib.rcParams[rc_key] if size is None else size
                          ).get_size_in_points()  # fmt: skip


def panel_chars(ax: Any, size: float) -> int:
    """About how many characters of ``size`` points fit in a line over ``ax``: its
    width as placed before the layout, a little overhang allowed (a character of
    DejaVu Sans is ~0.58 of its size wide on average)."""
    width_pt = ax.get_position().width * ax.get_figure().get_figwidth() * 72.0
    return max(12, int(1.1 * width_pt / (0.58 * size)))


def narrow() -> bool:
    """True at column width (panels of 1.5–3 in)."""
    return current_options().width == "column"


def sci(value: float, digits: int = 3) -> str:
    """A number for a title or note: plain when 1e-3 <= |v| < 1e4, else mathtext
    ``1.23\times10^{-4}`` (no e-notation)."""
    if value == 0.0 or 1e-3 <= abs(value) < 1e4:
        return f"{value:.{digits}g}"
    mantissa, exponent = f"{value:.{digits - 1}e}".split("e")
    return rf"${mantissa}\times10^{{{int(exponent)}}}$"


def finish(fig: Any) -> Any:
    """Last touches of every figure before it is saved: at column width, at most 3-5
    major ticks on linear axes (crowded tick labels otherwise meet); legends and
    movable labels moved off the data (``declutter``)."""
    from matplotlib.ticker import AutoLocator, MaxNLocator

    from .declutter import declutter

    if narrow():
        for ax in fig.axes:
            for axis, n in ((ax.xaxis, 3), (ax.yaxis, 5)):
                if type(axis.get_major_locator()) is AutoLocator:
                    axis.set_major_locator(MaxNLocator(nbins=n, steps=[1, 2, 5, 10]))
    declutter(fig)
    return fig


def _visible(text: str) -> int:
    """Characters of ``text`` as drawn: inside a $math$ span a command counts one and
    braces, sub- and superscript marks none; outside, every character counts."""
    import re

    def math(span: str) -> str:
        return re.sub(r"[{}_^$]", "", re.sub(r"\\[A-Za-z]+", "x", span))

    pieces = re.split(r"(\$[^$]*\$)", text)
    return sum(len(math(p)) if p.startswith("$") else len(p) for p in pieces)


def _wrap(text: str, chars: int, parameters: bool = False) -> list[str]:
    """``text`` in lines of about ``chars`` visible characters, broken only between
    words, never inside a $math$ span nor (``parameters``: a 'k = 0.1 mN/mm², B = …'
    list) inside one 'symbol = value unit'; existing line breaks are kept."""
    import re

    if "\n" in text:
        return [w for line in text.split("\n") for w in _wrap(line, chars, parameters)]
    atoms = ([a + "," for a in text.split(", ")[:-1]] + [text.split(", ")[-1]] if parameters
             else re.findall(r"\S*\$[^$]*\$\S*|\S+", text))  # fmt: skip
    lines, line = [], ""
    for a in atoms:
        if line and _visible(line) + 1 + _visible(a) > chars:
            lines.append(line)
            line = a
        else:
            line = f"{line} {a}" if line else a
    return [*lines, line] if line else lines


def _balanced(text: str, chars: int, parameters: bool = False) -> list[str]:
    """:func:`_wrap` into as few lines as at ``chars``, but of even lengths (no last
    line of a lone word)."""
    lines = _wrap(text, chars, parameters)
    while chars > 10 and len(_wrap(text, chars - 1, parameters)) == len(lines):
        chars -= 1
    return _wrap(text, chars, parameters)


def series_keys(red: Reduction, direction: str | None = None) -> list[tuple[Any, ...]]:
    """The series (values of the stitch, k, B, r_core, r, p …) with analysed sweeps, sorted."""
    keys = {c.series for c in red.curves if direction is None or c.direction == direction}
    return sorted(keys)


def series_rows(red: Reduction, key: Sequence[Any], direction: str) -> list[dict[str, Any]]:
    """The sweep rows of one series and direction, by L/r."""
    rows = (r for r in red.sweeps if r["direction"] == direction and series_key(r) == key)
    return sorted(rows, key=lambda r: r["L_over_r"])


def label_of(red: Reduction, key: Sequence[Any], chars: int | None = None) -> str:
    """Label of a series by the parameters that vary in the file ('' if none vary);
    with ``chars``, in lines of about that many characters, broken only between
    parameters ('stitch = garter,' over 'k = 0.1 mN/mm²')."""
    text = series_label(dict(zip(SERIES_PARAMS, key, strict=True)), red.varying)
    return text if chars is None else "\n".join(_wrap(text, chars, parameters=True))


def legend_below(ax: Any, labels: Sequence[str]) -> bool:
    """Whether a legend of ``labels`` on ``ax`` goes below the axes (a figure legend)
    rather than over the data: more than 5 entries at column width, 8 at the page's,
    or entries longer than 0.6 of the panel's width (it would cover half of it)."""
    size = font_points("legend.fontsize")
    longest = max((_visible(line) for t in labels for line in t.split("\n")), default=0)
    return len(labels) > (5 if narrow() else 8) or longest > 0.6 * panel_chars(ax, size)


def series_legend(fig: Any, ax: Any, handles: Sequence[Any], below: bool | None = None,
                  **kw: Any) -> Any:  # fmt: skip
    """A legend of ``handles`` (series, and the lines that go with them): on ``ax``
    (``kw``: its place and frame), or below the axes when ``below`` (default
    :func:`legend_below`), in one column at column width, its entries broken between
    parameters when longer than the column."""
    if below is None:
        below = legend_below(ax, [h.get_label() for h in handles])
    if not below:
        return ax.legend(handles=handles, **kw)
    size = font_points("legend.fontsize")
    chars = int(fig.get_figwidth() * 72.0 / (0.58 * size))  # the figure's width
    for h in handles:  # a handle and its gap take ~6 characters
        label = h.get_label()
        h.set_label("\n".join(_wrap(label, chars - 8, parameters=" = " in label)))
    lines = [h.get_label().count("\n") + 1 for h in handles]
    longest = max(_visible(line) for h in handles for line in h.get_label().split("\n"))
    ncols = legend_columns(max(1, min(len(handles), 3, chars // (longest + 8))))
    # the axes keep their height: the figure grows by the legend's rows
    rows = [max(lines[i : i + ncols]) for i in range(0, len(lines), ncols)]
    fig.set_figheight(fig.get_figheight() + (sum(rows) * 1.25 + 0.8) * size / 72.0)
    return fig.legend(handles=handles, loc="outside lower center", frameon=False, ncols=ncols)


def caption(fig: Any, ax: Any, text: str, **kw: Any) -> Any:
    """A caption below the axes (inside, it would cover the data), smaller and grey:
    the figure's bottom line, or, when a legend already sits below the axes, right
    under the x label of ``ax`` (above that legend, which would cover it)."""
    kw = {"fontsize": max(7.0, 0.85 * float(ax.xaxis.label.get_fontsize())), "color": "0.3",
          **kw}  # fmt: skip
    if not any(getattr(leg, "_outside_loc", None) for leg in fig.legends):
        return fig.supxlabel(text, **kw)
    return ax.annotate(text, (0.5, 0.0), xycoords=ax.xaxis.label, xytext=(0.0, -3.0),
                       textcoords="offset points", ha="center", va="top", **kw)  # fmt: skip


def limit_panels(keys: list, what: str, notes: list[str]) -> list:
    """At most :data:`MAX_PANELS` series; a note says how many were left out."""
    if len(keys) > MAX_PANELS:
        notes.append(f"{what}: showing the first {MAX_PANELS} of {len(keys)} series")
        return keys[:MAX_PANELS]
    return keys


def L_colours(red: Reduction) -> tuple[Any, Any]:
    """(colormap, norm) colouring curves by L in mm over the file's range."""
    import matplotlib as mpl
    from matplotlib.colors import ListedColormap, Normalize

    base = mpl.colormaps["viridis"]
    cmap = ListedColormap(base(np.linspace(0.0, 0.88, 256)))  # keep the light end readable
    Ls = [c.L_mm for c in red.curves] or [0.0, 1.0]
    lo, hi = min(Ls), max(Ls)
    if hi == lo:
        lo, hi = lo - 0.5, hi + 0.5
    return cmap, Normalize(lo, hi)


def L_colourbar(fig: Any, axes: Any, cmap: Any, norm: Any, below: bool = False) -> None:
    """A colourbar labelled L (mm), shared by ``axes``: on their right, or ``below``
    them, horizontal (beside panels whose titles are wider than they are: the
    layout leaves no room for a title's overhang, the colourbar would cover it)."""
    from matplotlib.cm import ScalarMappable

    where = {"location": "bottom", "shrink": 0.7, "aspect": 30} if below else {"shrink": 0.6,
                                                                            "aspect": 25}  # fmt: skip
    cb = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=axes, **where)
    cb.set_label("$L$ (mm)" if current_options().width != "auto" else
                 "yarn length per stitch $L$ (mm)")  # fmt: skip


def jammed_legend(fig: Any, directions: Sequence[str], extra: Sequence[Any] = ()) -> None:
    """Figure legend for the line styles: jammed (solid) and unjammed (dashed), and
    ``extra`` handles (e.g. the metric lines of Fig. 1b)."""
    from matplotlib.lines import Line2D

    gaps = ", ".join(
        r"$\Delta E_c$ for x" if d == "x" else r"$\Delta E_b$ for y" for d in directions
    )
    handles = [
        Line2D([], [], color="0.3", ls="-", label=f"jammed (gap ≥ threshold: {gaps})"),
        Line2D([], [], color="0.3", ls="--", label="unjammed"),
        *extra,
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=legend_columns(2),
               frameon=False)  # fmt: skip


def legend_columns(n: int) -> int:
    """Columns of a figure legend of ``n`` entries: one at column width."""
    return 1 if current_options().width == "column" else n


def grid_of_panels(fig: Any, n: int, ncols: int) -> list[Any]:
    """``n`` axes in a grid of ``ncols`` columns; unused cells are removed."""
    nrows = -(-n // ncols)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.remove()
    return flat[:n]


def parameter_axis(ax: Any, values: Sequence[float]) -> None:
    """x axis over a swept parameter: log scale when it spans ≥ a decade, ticks at
    the sampled values."""
    from matplotlib.ticker import NullFormatter

    xs = sorted(set(values))
    if xs[0] > 0.0 and xs[-1] / xs[0] >= 10.0:
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
    if len(xs) <= 8:
        ax.set_xticks(xs)
        ax.set_xticklabels([f"{v:g}" for v in xs])
