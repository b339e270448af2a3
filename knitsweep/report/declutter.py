"""Labels off the data: the last pass of every figure (``plotting.finish``).

A legend inside the axes, or a text marked movable (:func:`movable`), that covers data
(markers, or the lines of the data drawn in data coordinates; shading does not count)
is moved: a legend to the first of the usual corners where it covers none, else, with
more head room above the data, to a top corner, else beside the axes; a text (also one
that overlaps another text of its axes, such as a line's label) to the first corner of
the axes free of data and of other text. The data are what the renderer draws, in display
pixels, each marker as its box and each line sampled every 2 pixels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

LEGEND_PLACES = ("upper right", "upper left", "lower left", "lower right", "center right",
                 "center left", "upper center", "lower center")  # fmt: skip
TEXT_PLACES = ((0.98, 0.97, "right", "top"), (0.02, 0.97, "left", "top"),
               (0.98, 0.03, "right", "bottom"), (0.02, 0.03, "left", "bottom"),
               (0.5, 0.97, "center", "top"), (0.5, 0.03, "center", "bottom"))  # fmt: skip


def movable(text: Any) -> Any:
    """Mark a text as free to move off the data (its place is a hint, not a meaning)."""
    text._knitsweep_movable = True
    return text


def data_points(ax: Any, renderer: Any) -> tuple[np.ndarray, np.ndarray]:
    """Display-space centres (M, 2) and half-sizes (M,) in pixels of what ``ax`` draws
    as data: the markers of its lines and scatters, and points along its data lines."""
    from matplotlib.collections import PathCollection

    pts, half = [], []
    px = renderer.points_to_pixels(1.0)
    for line in ax.get_lines():
        if not line.get_visible() or line.get_transform() != ax.transData:
            continue  # axhline/axvline (axes coordinates) are guides, not data
        disp = ax.transData.transform(np.asarray(line.get_xydata(), dtype=float))
        disp = disp[np.all(np.isfinite(disp), axis=1)]
        if not len(disp):
            continue
        if line.get_marker() not in (None, "None", "none", "", " "):
            pts.append(disp)
            half.append(np.full(len(disp), 0.5 * line.get_markersize() * px))
        if line.get_linestyle() not in ("None", "none", "", " ") and len(disp) > 1:
            steps = np.maximum(2, (np.hypot(*np.diff(disp, axis=0).T) / 2.0).astype(int))
            seg = np.concatenate([a + (b - a) * np.linspace(0.0, 1.0, n)[:, None]
                                  for a, b, n in zip(disp[:-1], disp[1:], steps, strict=True)])  # fmt: skip
            pts.append(seg)
            half.append(np.full(len(seg), 0.5 * line.get_linewidth() * px))
    for c in ax.collections:
        if isinstance(c, PathCollection) and c.get_visible() and len(c.get_offsets()):
            disp = c.get_offset_transform().transform(np.asarray(c.get_offsets(), dtype=float))
            sizes = c.get_sizes() if len(c.get_sizes()) else np.array([36.0])
            r = np.broadcast_to(0.5 * np.sqrt(sizes) * px, (len(disp),))
            pts.append(disp)
            half.append(np.asarray(r, dtype=float))
    if not pts:
        return np.zeros((0, 2)), np.zeros(0)
    pts, half = np.concatenate(pts), np.concatenate(half)
    box = ax.get_window_extent(renderer)
    seen = ((pts[:, 0] + half >= box.x0) & (pts[:, 0] - half <= box.x1)
            & (pts[:, 1] + half >= box.y0) & (pts[:, 1] - half <= box.y1))  # fmt: skip
    return pts[seen], half[seen]


def covers(box: Any, pts: np.ndarray, half: np.ndarray) -> int:
    """How many of the data points (``data_points``) the display box ``box`` covers."""
    hit = ((pts[:, 0] + half > box.x0) & (pts[:, 0] - half < box.x1)
           & (pts[:, 1] + half > box.y0) & (pts[:, 1] - half < box.y1))  # fmt: skip
    return int(hit.sum())


def declutter(fig: Any) -> None:
    """Move the legends and movable texts of ``fig`` off its data (module docstring)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        legend = ax.get_legend()
        texts = [t for t in ax.texts if getattr(t, "_knitsweep_movable", False)]
        if legend is None and not texts:
            continue
        pts, half = data_points(ax, renderer)
        if not len(pts):
            continue
        if legend is not None and covers(legend.get_window_extent(renderer), pts, half):
            _move_legend(fig, ax, legend, renderer)
        for t in texts:
            box = t.get_window_extent(renderer)
            if covers(box, *data_points(ax, renderer)) or _on_text(box, t, ax, renderer):
                _move_text(fig, ax, t, renderer)


def _on_text(box: Any, text: Any, ax: Any, renderer: Any) -> bool:
    """Whether ``box`` (of ``text``) overlaps another non-empty text of ``ax`` (a line's
    label, another note) by more than a sliver of 2 x 2 pixels."""
    for other in ax.texts:
        if other is text or not other.get_visible() or not other.get_text().strip():
            continue
        b = other.get_window_extent(renderer)
        w = min(box.x1, b.x1) - max(box.x0, b.x0)
        h = min(box.y1, b.y1) - max(box.y0, b.y0)
        if w > 0 and h > 0 and w * h > 4.0:
            return True
    return False


def _more_room(ax: Any) -> None:
    """Raise the top of the y axis by 30 % of its range (of its decades on a log axis)."""
    bottom, top = ax.get_ylim()
    if ax.get_yscale() == "log":
        ax.set_ylim(bottom, top * (top / bottom) ** 0.3)
    else:
        ax.set_ylim(bottom, top + 0.3 * (top - bottom))


def _move_legend(fig: Any, ax: Any, legend: Any, renderer: Any) -> None:
    for place in LEGEND_PLACES:
        legend.set_loc(place)
        fig.canvas.draw()
        if not covers(legend.get_window_extent(renderer), *data_points(ax, renderer)):
            return
    for _ in range(3):  # more head room above the data, the legend in a top corner
        _more_room(ax)
        for place in LEGEND_PLACES[:2]:
            legend.set_loc(place)
            fig.canvas.draw()
            if not covers(legend.get_window_extent(renderer), *data_points(ax, renderer)):
                return
    legend.set_loc("upper left")
    legend.set_bbox_to_anchor((1.02, 1.0), transform=ax.transAxes)  # beside the axes
    fig.canvas.draw()


def _move_text(fig: Any, ax: Any, text: Any, renderer: Any) -> None:
    for attempt in range(4):  # the corners, then with more head room above the data
        if attempt:
            _more_room(ax)
            fig.canvas.draw()
        pts, half = data_points(ax, renderer)
        for x, y, ha, va in TEXT_PLACES if attempt == 0 else TEXT_PLACES[:2]:
            text.set_transform(ax.transAxes)
            text.set_position((x, y))
            text.set_ha(ha)
            text.set_va(va)
            box = text.get_window_extent(renderer)
            if not covers(box, pts, half) and not _on_text(box, text, ax, renderer):
                return
