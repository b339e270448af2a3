"""Pictures of a relaxed stitch: a patch of fabric like the paper's Fig. 1a.

The yarn centre-line of one cell is the quintic Bézier segments of
:meth:`knitsweep.model.CellModel.control_points` (docs/model.md §3–4) in the stitch's
drawing order (``Stitch.path_order``); the last segment ends where the first starts,
shifted by the stitch's ``closing_shift`` in periods (stockinette: the course period
t_c = (a_x, 0, 0)), so one row's yarn is the cell's path repeated by that shift, and
the rows repeat along the wale period t_w = (0, a_y, 0). The copies are the stitch's
images (``Stitch.images``, docs/model.md §11): the copy at lattice offset (m, n) is
g p = M^μ p + m t_c + n t_w with M = diag(1, 1, −1) (the mirror z → −z through the
fabric plane) and μ = (pm m + pn n) mod 2, (pm, pn) the stitch's ``mirror_parity``
((0, 0) for a pattern of translations: stockinette; (0, 1) garter, whose odd rows are
purl rows; (1, 0) rib; (1, 1) seed). Each row is drawn as a tube of radius r around
its centre-line, seen along a tilted direction in orthographic projection, shaded
(Lambert + specular) and depth-sorted face by face (painter's algorithm), so that
interlocking loops hide each other correctly. Lengths in mm.

matplotlib is imported lazily, with the Agg canvas and no pyplot.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from ..config import StitchParams
from ..errors import InputError
from ..formats import check_writable, replace_file
from .tile import Stitch, cell_path, copy_mirrored, dense_cell_path, frames, row_path, unit_cell

ROW_COLOURS = ("#c8553d", "#3a7ca5", "#d9a21b", "#6a994e", "#8e5572")
"""Base colour of each row (course) of yarn, cycling."""
PATTERN_COLOURS = {False: ("#c8553d", "#d9a21b"), True: ("#3a7ca5", "#6a994e")}
"""With mirrored images (a knit/purl pattern): warm colours (red, gold) for the cell's
unmirrored copies, cool ones (blue, green) for the mirrored copies, alternating every
second row within each, so that the knit and the purl rows (garter), columns (rib) or
checkerboard squares (seed) tell apart at a glance."""

OUT_SUFFIXES = (".png", ".pdf", ".svg")

BACKGROUND = np.array([0.17, 0.17, 0.19])
"""What shows through the holes between the loops: shadow, so that a hole reads as
one (a white background made the small holes at the cell corners look like defects)."""


SIDES = ("face", "back")
"""Which side of the fabric faces the viewer: 'face' (the knit side, its V-shaped legs;
seen from −z in this model's frame) or 'back' (the purl side, seen from +z)."""


def _view_matrix(elevation_deg: float, azimuth_deg: float, side: str = "face") -> np.ndarray:
    """Rotation taking fabric coordinates to (screen right, screen up, towards viewer):
    the fabric seen from ``side`` with the wale (y) up, turned by ``azimuth`` about
    its normal and tilted by 90° − ``elevation`` about the screen's horizontal axis."""
    a = np.radians(azimuth_deg)
    rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    flip = np.diag([-1.0, 1.0, -1.0]) if side == "face" else np.eye(3)
    tilt = np.radians(90.0 - elevation_deg)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(tilt), -np.sin(tilt)],
                   [0.0, np.sin(tilt), np.cos(tilt)]])  # fmt: skip
    return rx @ flip @ rz


def _shade(base: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lambert + Blinn–Phong shading of face colours (m, 3) for view-space normals (m, 3)."""
    light = np.array([-0.45, 0.55, 1.0])
    light /= np.linalg.norm(light)
    half = light + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half)
    diffuse = np.clip(normals @ light, 0.0, 1.0)[:, None]
    spec = np.clip(normals @ half, 0.0, 1.0)[:, None] ** 40
    rgb = base * (0.3 + 0.7 * diffuse) + 0.35 * spec
    return np.clip(rgb, 0.0, 1.0)


def _cell_tint(row: int, column: int, centre: tuple[int, int] | None,
               mirrored: bool | None = None) -> np.ndarray:  # fmt: skip
    """The row's hue, the same along the whole yarn (no seams where cells meet); with
    ``mirrored`` (a pattern with mirrored images: whether this copy is one), the hue of
    :data:`PATTERN_COLOURS`; with a ``centre`` cell, the others washed towards grey so
    that it stands out."""
    from matplotlib.colors import to_rgb

    if mirrored is None:
        rgb = np.array(to_rgb(ROW_COLOURS[row % len(ROW_COLOURS)]))
    else:
        rgb = np.array(to_rgb(PATTERN_COLOURS[mirrored][(row // 2) % 2]))
    if centre is not None and (row, column) != centre:
        rgb = 0.55 * rgb + 0.45 * np.array([0.78, 0.76, 0.72])
    return np.clip(rgb, 0.0, 1.0)


RADIUS_FRACTION = 0.5 / 0.74
"""Default tube radius as a fraction of the yarn radius r: the paper drew its Fig. 1a
with 0.5 mm for r = 0.74 mm "to better display the yarn structure" (a tube of the full
radius, whose compressible shells overlap, looks like a solid wall)."""
MAX_RADIUS = 10.0
"""Largest tube radius (mm) a picture may ask for."""


def window(stitch: Stitch, cells: int, view: np.ndarray) -> np.ndarray:
    """Screen box (x_lo, x_hi, y_lo, y_hi), mm, of ``cells`` × ``cells`` cell periods
    centred on the patch."""
    mid = cell_path(stitch.control_points, 8).mean(axis=0)
    if stitch.mirrors:  # the fabric's middle is the mirror plane z = 0
        mid[2] = 0.0
    t_c = stitch.t_c
    t_w = np.array([0.0, stitch.a_y, 0.0])
    corners = np.array([mid + (i - 0.5) * t_c + (j - 0.5) * t_w
                        for i in (0, cells) for j in (0, cells)]) @ view.T  # fmt: skip
    return np.array([corners[:, 0].min(), corners[:, 0].max(),
                     corners[:, 1].min(), corners[:, 1].max()])  # fmt: skip


def rasterize(stitch: Stitch, cells: int, radius: float, view: np.ndarray, box: np.ndarray,
              width_px: int, highlight: bool = False) -> np.ndarray:  # fmt: skip
    """The fabric seen through ``box`` as an RGB image (H, width_px, 3) in [0, 1].

    The tube surfaces are sampled more finely than a pixel and drawn with a depth
    buffer, so that yarns pressed into each other (the model's compressible shell)
    meet along their true intersection. ``cells`` × ``cells`` stitches plus a ring of
    neighbours are drawn, so the window shows a continuous fabric.
    """
    px = (box[1] - box[0]) / width_px
    height_px = int(np.ceil((box[3] - box[2]) / px))
    zbuf = np.full(height_px * width_px, -np.inf)
    image = np.tile(BACKGROUND, (height_px * width_px, 1))
    step = px / 1.6
    one = dense_cell_path(stitch.control_points, step)
    per_cell = len(one) - 1
    eye = view[2]  # unit vector towards the viewer, fabric coordinates
    offsets = np.linspace(-0.56 * np.pi, 0.56 * np.pi, int(np.ceil(1.12 * np.pi * radius / step)))
    centre = unit_cell(stitch, cells) if highlight else None
    reach = radius + 2.0 * px
    for row in range(-1, cells + 1):
        path = row_path(stitch, one, row, range(-1, cells + 1))
        screen = path @ view.T
        near = ((screen[:, 0] > box[0] - reach) & (screen[:, 0] < box[1] + reach)
                & (screen[:, 1] > box[2] - reach) & (screen[:, 1] < box[3] + reach))  # fmt: skip
        if not near.any():
            continue
        _, normal, binormal = frames(path)
        tints = np.array([_cell_tint(row, c, centre, copy_mirrored(stitch, row, c))
                          for c in range(-1, cells + 1)])  # fmt: skip
        column = np.minimum(np.arange(len(path)) // per_cell, cells + 1)
        idx = np.flatnonzero(near)
        for chunk in np.array_split(idx, max(1, len(idx) // 1500)):
            phi0 = np.arctan2(binormal[chunk] @ eye, normal[chunk] @ eye)
            phi = phi0[:, None] + offsets[None, :]
            ring = (np.cos(phi)[..., None] * normal[chunk, None, :]
                    + np.sin(phi)[..., None] * binormal[chunk, None, :]).reshape(-1, 3)  # fmt: skip
            pts = (np.repeat(path[chunk], len(offsets), axis=0) + radius * ring) @ view.T
            ix = np.floor((pts[:, 0] - box[0]) / px).astype(np.int64)
            iy = np.floor((box[3] - pts[:, 1]) / px).astype(np.int64)
            ok = (ix >= 0) & (ix < width_px) & (iy >= 0) & (iy < height_px)
            pix = (iy * width_px + ix)[ok]
            depth = pts[ok, 2]
            order = np.lexsort((depth, pix))
            last = np.r_[pix[order][1:] != pix[order][:-1], True]
            sel = order[last]
            nearer = depth[sel] > zbuf[pix[sel]]
            sel = sel[nearer]
            zbuf[pix[sel]] = depth[sel]
            base = tints[np.repeat(column[chunk], len(offsets))[ok][sel]]
            image[pix[sel]] = _shade(base, ring[ok][sel] @ view.T)
    image = image.reshape(height_px, width_px, 3)
    return _fill_holes(image, zbuf.reshape(height_px, width_px))


def _fill_holes(image: np.ndarray, zbuf: np.ndarray) -> np.ndarray:
    """Pixels the sampling missed inside a surface (≥ 3 of 4 neighbours drawn) take
    the mean colour of their drawn neighbours."""
    empty = ~np.isfinite(zbuf)
    pad_e = np.pad(~empty, 1, constant_values=False)
    pad_i = np.pad(image, ((1, 1), (1, 1), (0, 0)))
    shifts = ((0, 1), (2, 1), (1, 0), (1, 2))
    count = sum(pad_e[a : a + empty.shape[0], b : b + empty.shape[1]] for a, b in shifts)
    total = sum(pad_i[a:a + empty.shape[0], b:b + empty.shape[1]]
                * pad_e[a:a + empty.shape[0], b:b + empty.shape[1], None] for a, b in shifts)  # fmt: skip
    fill = empty & (count >= 3)
    image[fill] = total[fill] / count[fill, None]
    return image


def draw_stitch(stitch: Stitch, out: str | Path, cells: int = 3, radius: float | None = None,
                elevation_deg: float = 72.0, azimuth_deg: float = 0.0, side: str = "face",
                width_px: int = 1100, highlight: bool = False) -> Path:  # fmt: skip
    """Draw a window onto ``cells`` × ``cells`` stitches to ``out`` (.png, .pdf, .svg).

    Args:
        stitch: the cell to repeat.
        cells: stitches per side of the window (the paper's Fig. 1a look: 3).
        radius: tube radius, mm [``RADIUS_FRACTION`` × r, the paper's 0.5 mm for
            r = 0.74 mm, which shows the stitches].
        elevation_deg: angle between the viewing direction and the fabric plane
            (90: straight onto the fabric).
        azimuth_deg: rotation of the fabric about its normal.
        side: 'face' (knit side) or 'back' (purl side), see :data:`SIDES`.
        width_px: resolution of the rendering, pixels across (the saved figure is
            7 inches wide at 160 dpi either way).
        highlight: wash out every stitch but the central one (the unit cell).
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if side not in SIDES:
        raise InputError(f"side = {side!r}: must be one of {', '.join(SIDES)}")
    r = RADIUS_FRACTION * stitch.r_mm if radius is None else radius
    view = _view_matrix(elevation_deg, azimuth_deg, side)
    box = window(stitch, cells, view)
    image = rasterize(stitch, cells, r, view, box, width_px, highlight)
    out = Path(out)
    width = 7.0  # inches at 160 dpi: the picture is shown 1120 px wide whatever width_px is
    height = width * image.shape[0] / image.shape[1] + (1.0 if stitch.mirrors else 0.8)
    with matplotlib.rc_context({"font.size": 11, "font.family": "DejaVu Sans"}):
        fig = Figure(figsize=(width + 0.3, height), layout="constrained")
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        ax.imshow(image, extent=tuple(box), interpolation="antialiased")
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        for spine in ax.spines.values():
            spine.set_color("0.6")
        ax.set_title(stitch.label, fontsize=11)
        note = f"{cells} × {cells} stitches, {side} side; tube radius {r:.3g} mm (yarn r = "
        note += f"{stitch.r_mm:g} mm)" + ("; saturated: one unit cell" if highlight else "")
        if stitch.mirrors:
            note += "\nwarm colours: the cell's copies; cool: its mirror images (z → −z)"
        ax.text(1.0, -0.01, note, transform=ax.transAxes, ha="right", va="top", fontsize=10,
                color="0.35")  # fmt: skip
        buf = io.BytesIO()
        fig.savefig(buf, format=Path(out).suffix.lstrip(".").lower(), dpi=160, facecolor="white")
    return replace_file(out, buf.getvalue())  # never through a symbolic link


# ---- where the stitch comes from ---------------------------------------------------


def stitch_from_state(x: np.ndarray, params: StitchParams, label: str = "") -> Stitch:
    """The picture of a state vector of the stitch ``params.stitch`` (docs/model.md §2)."""
    from ..model import CellModel

    model = CellModel(params)
    return drawn(model.control_points(x), float(x[-2]), float(x[-1]), params,
                 label or f"L = {params.L_mm:g} mm, r = {params.r_mm:g} mm")  # fmt: skip


def drawn(cp: np.ndarray, a_x: float, a_y: float, params: StitchParams, label: str) -> Stitch:
    """The picture of control points (S, 6, 3) of the stitch ``params.stitch``, in its
    drawing order, with its images as the stitch declares them (``images``: translations,
    or glides with its ``mirror_parity``)."""
    from ..stitches import get_stitch

    geometry = get_stitch(params.stitch)
    order = list(geometry.path_order)
    parity = tuple(geometry.mirror_parity)  # (0, 0) for translations alone
    return Stitch(np.asarray(cp, dtype=float)[order], a_x, a_y, params.r_mm, label,
                  geometry.closing_shift, parity)  # fmt: skip


def _find_task(results: Path, task: str) -> Any:
    from ..store.read import iter_entries, read_root

    read_root(results)
    matches = [e for e in iter_entries(results, with_data=True) if e.task_id.startswith(task)]
    if not matches:
        raise InputError(f"task = {task!r}: no point or sweep with this id in {results}")
    if len(matches) > 1:
        raise InputError(f"task = {task!r}: matches {len(matches)} tasks; give more characters")
    return matches[0]


def stitch_from_results(results: str | Path, task: str, step: int | None = None) -> Stitch:
    """The stitch of one task of a results file.

    A point id gives its zero-force state (the lowest-energy start). A sweep id gives
    the state at ``step`` (default 0, the zero-force state); steps other than 0 need
    the sweep's stored ``states`` or ``control_points`` ([store] states or geometry).
    Ids may be abbreviated to a unique prefix.
    """
    from ..store.format import POINTS
    from ..store.read import iter_entries

    results = Path(results)
    e = _find_task(results, task)
    meta, rec = e.meta, e.record
    if meta.get("status") != "done":
        raise InputError(f"task {e.task_id} has status {meta.get('status')!r}: nothing to draw")
    params = StitchParams.from_flat(meta)
    what = f"L = {params.L_mm:g} mm, k = {params.k_mN_per_mm2:g} mN/mm², B = {params.B_mN_mm2:g} mN·mm²"
    if e.kind == POINTS:
        if step not in (None, 0):
            raise InputError(
                f"strain_step = {step}: a point has only its zero-force state (step 0)"
            )
        x = np.asarray(rec["x"][int(meta.get("winner", 0))], dtype=float)
        return stitch_from_state(x, params, f"zero-force stitch, {what}")
    step = 0 if step is None else step
    n = len(rec.get("strain", []))
    if not 0 <= step < n:
        raise InputError(f"strain_step = {step}: sweep {e.task_id} has steps 0..{n - 1}")
    label = (f"pulled in {meta['direction']}, step {step} (strain {rec['strain'][step]:.3f}), "
             f"{what}")  # fmt: skip
    if "control_points" in rec:
        cp = np.asarray(rec["control_points"][step], dtype=float)
        return drawn(cp, float(rec["a_x"][step]), float(rec["a_y"][step]), params, label)
    if "states" in rec:
        return stitch_from_state(np.asarray(rec["states"][step], dtype=float), params, label)
    if step == 0:
        point = next((p for p in iter_entries(results, with_data=True)
                      if p.kind == POINTS and p.task_id == meta.get("point_id")), None)  # fmt: skip
        if point is not None:
            x = np.asarray(point.record["x"][int(point.meta.get("winner", 0))], dtype=float)
            return stitch_from_state(x, params, label)
    raise InputError(
        f"sweep {e.task_id} stores no states or control points; only step 0 can be drawn "
        "(set [store] states = true or geometry = true in the job to keep every step)"
    )


def render(
    out: str | Path,
    *,
    results: str | Path | None = None,
    task: str | None = None,
    step: int | None = None,
    state: str | Path | None = None,
    params: StitchParams | None = None,
    radius: float | None = None,
    cells: int = 3,
    side: str = "face",
    elevation_deg: float = 72.0,
    width_px: int = 1100,
    highlight: bool = False,
) -> tuple[Path, Stitch]:
    """Draw a stitch from a results-file task or from a state file (``knitsweep render``).

    Give either ``results`` and ``task`` (and optionally ``step``), or ``state`` and
    ``params`` (default parameters if None). Returns the file written and the stitch.

    Raises:
        InputError: both or neither source, unknown task, bad step, bad output suffix,
            cells outside 1..8, radius ≤ 0 or > MAX_RADIUS, elevation outside (0, 90], unknown side.
    """
    out = Path(out)
    if out.suffix.lower() not in OUT_SUFFIXES:
        raise InputError(f"out = '{out}': must end in {', '.join(OUT_SUFFIXES)}")
    if not 1 <= cells <= 8:
        raise InputError(f"cells = {cells}: must be in 1..8")
    if radius is not None and not radius > 0.0:
        raise InputError(f"radius = {radius}: must be > 0 (mm)")
    if radius is not None and radius > MAX_RADIUS:
        raise InputError(f"radius = {radius}: must be <= {MAX_RADIUS:g} (mm)")
    if not 0.0 < elevation_deg <= 90.0:
        raise InputError(f"elevation = {elevation_deg}: must be in (0, 90] degrees")
    if side not in SIDES:
        raise InputError(f"side = {side!r}: must be one of {', '.join(SIDES)}")
    if not 100 <= width_px <= 6000:
        raise InputError(f"pixels = {width_px}: must be in 100..6000")
    if (results is None) == (state is None):
        raise InputError("give either --results FILE --task ID, or --state FILE")
    check_writable(out, "--out")  # before any compute, as in every command
    stitch = stitch_to_draw(results, task, step, state, params)
    path = draw_stitch(stitch, out, cells, radius, elevation_deg=elevation_deg, side=side,
                       width_px=width_px, highlight=highlight)  # fmt: skip
    return path, stitch


def stitch_to_draw(
    results: Path | None,
    task: str | None,
    step: int | None,
    state: Path | None,
    params: StitchParams | None,
) -> Stitch:
    """The picture's stitch: a task of a results file (at a sweep's ``step``), or a state
    file at ``params`` (default paper Table 1); exactly one of ``results`` and ``state``."""
    if results is not None:
        if task is None:
            raise InputError("--results needs --task ID (a point or sweep id)")
        return stitch_from_results(results, task, step)
    from ..formats import read_state

    if step is not None:
        raise InputError("--strain-step applies to a sweep of a results file, not to --state")
    params = params or StitchParams()
    return stitch_from_state(read_state(state, params.stitch), params,
                             f"state {Path(state).name}")  # fmt: skip
