"""Pictures of a relaxed stitch: a patch of fabric like the paper's Fig. 1a.

The yarn centre-line of one cell is the quintic Bézier segments of
:meth:`knitsweep.model.CellModel.control_points` (docs/model.md §3–4) in the stitch's
drawing order (``Stitch.path_order``); the last segment ends where the first starts,
shifted by the stitch's ``closing_shift`` in periods (stockinette: the course period
t_c = (a_x, 0, 0)), so one row's yarn is the cell's path repeated by that shift, and
the rows repeat along the wale period t_w = (0, a_y, 0). The copies are the stitch's
images (``Stitch.images``, docs/model.md §11): the copy at lattice offset (m, n) is
g p = M^μ p + m t_c + n t_w with M = diag(1, 1, −1) (the mirror z → −z through the
fabric plane) and μ = (pm m + pn n) mod 2, (pm, pn) the stitch's ``mirror_parity``.

Each row's yarn is one tube of radius ρ (default the yarn's radius r) around one curve
through the whole tile (``tube_mesh``: continuous frames and normals across the cells),
seen along a tilted direction in orthographic projection, rasterised with a depth
buffer (``raster``: interlocking and pressed-together tubes hide each other along their
true intersection) at ``SUPERSAMPLE``² samples per pixel, averaged (anti-aliasing), and
shaded per pixel from the interpolated normals: a key and a fill light (Lambert +
Blinn–Phong), a relief cue (yarn further back in the fabric darker) and the occlusion
of the depth buffer's neighbourhood (crevices darker). Each row (course) has one colour
along its whole yarn. Lengths in mm.

matplotlib is imported lazily, with the Agg canvas and no pyplot.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from ..config import StitchParams
from ..errors import InputError
from ..util.safe_files import check_writable, replace_file
from .sources import FROM_FILE, drawn, stitch_from_results, stitch_from_state, stitch_to_draw, title
from .tile import ROW_COLOURS, Stitch, cell_path, copy_mirrored, row_path, unit_cell

__all__ = ["ROW_COLOURS", "cell_path", "copy_mirrored", "drawn", "render", "row_path", "stitch_from_results",
           "stitch_from_state", "stitch_to_draw", "title", "unit_cell"]  # fmt: skip

OUT_SUFFIXES = (".png", ".pdf", ".svg")
MESH_SUFFIXES = (".vtp", ".vtu", ".ply", ".obj")
"""3D files of the tile's yarn (``export3d``)."""

BACKGROUND = np.array([0.17, 0.17, 0.19])
"""What shows through the holes between the loops: shadow, so that a hole reads as
one (a white background made the small holes at the cell corners look like defects)."""

SIDES = ("face", "back")
"""Which side of the fabric faces the viewer: 'face' (the knit side, its V-shaped legs;
seen from −z in this model's frame) or 'back' (the purl side, seen from +z)."""

SUPERSAMPLE = 2
"""Samples per pixel along each axis (anti-aliasing)."""
AROUND = 48
"""Vertices per ring of the tube mesh."""
MAX_RADIUS = 10.0
"""Largest tube radius (mm) a picture may ask for."""
MAX_CELLS = 12


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


def default_cells(stitch: Stitch) -> tuple[int, int]:
    """(cells across, rows): two repeats of the pattern (``Stitch.repeat``) each
    way, at least 3 stitches (the paper's Fig. 1a: 3 × 3 stockinette stitches; a chart's
    cell holds a row of several)."""
    along, rows = stitch.repeat
    return max(-(-3 // stitch.closing_shift[0]), 2 * along), max(3, 2 * rows)


def _cells(cells: int | tuple[int, int]) -> tuple[int, int]:
    return (cells, cells) if isinstance(cells, int) else (int(cells[0]), int(cells[1]))


def window(stitch: Stitch, cells: int | tuple[int, int], view: np.ndarray) -> np.ndarray:
    """Screen box (x_lo, x_hi, y_lo, y_hi), mm, of ``cells`` (across, rows) cell periods
    centred on the patch."""
    nx, ny = _cells(cells)
    mid = cell_path(stitch.control_points, 8).mean(axis=0)
    if stitch.mirrors:  # the fabric's middle is the mirror plane z = 0
        mid[2] = 0.0
    t_w = np.array([0.0, stitch.a_y, 0.0])
    corners = np.array([mid + (i - 0.5) * stitch.t_c + (j - 0.5) * t_w
                        for i in (0, nx) for j in (0, ny)]) @ view.T  # fmt: skip
    return np.array([corners[:, 0].min(), corners[:, 0].max(),
                     corners[:, 1].min(), corners[:, 1].max()])  # fmt: skip


def copies_in_view(stitch: Stitch, view: np.ndarray, box: np.ndarray,
                   reach: float) -> dict[int, range]:  # fmt: skip
    """Row → the consecutive copies of it whose yarn (widened by ``reach`` mm) can be
    seen through the screen box ``box``."""
    one = cell_path(stitch.control_points, 6)
    t_w = np.array([0.0, stitch.a_y, 0.0])
    steps = np.column_stack([stitch.t_c @ view.T, t_w @ view.T])[:2]  # screen (2, 2)
    middle = np.array([box[0] + box[1], box[2] + box[3]]) / 2.0 - (one.mean(axis=0) @ view.T)[:2]
    c0, r0 = np.rint(np.linalg.solve(steps, middle)).astype(int)  # the copy at the centre
    extent = np.hypot(box[1] - box[0], box[3] - box[2]) + np.ptp(one @ view.T, axis=0)[:2].sum()
    lim_c = int(np.ceil(extent / np.linalg.norm(steps[:, 0]))) + 2
    lim_w = int(np.ceil(extent / np.linalg.norm(steps[:, 1]))) + 2
    out = {}
    for row in range(r0 - lim_w, r0 + lim_w + 1):
        seen = []
        for c in range(c0 - lim_c, c0 + lim_c + 1):
            pts = row_path(stitch, one, row, range(c, c + 1)) @ view.T
            if (pts[:, 0].max() + reach >= box[0] and pts[:, 0].min() - reach <= box[1]
                    and pts[:, 1].max() + reach >= box[2] and pts[:, 1].min() - reach <= box[3]):  # fmt: skip
                seen.append(c)
        if seen:
            out[row] = range(min(seen), max(seen) + 1)
    return out


def _shade(normals: np.ndarray) -> np.ndarray:
    """Light (H, W, 1) on view-space unit normals (H, W, 3): a key light from the upper
    left and a weak fill from the right (Lambert), and the key's Blinn–Phong highlight
    returned separately (H, W, 1)."""
    key = np.array([-0.45, 0.55, 1.0])
    key /= np.linalg.norm(key)
    fill = np.array([0.7, -0.2, 0.7])
    fill /= np.linalg.norm(fill)
    half = key + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half)
    diffuse = 0.75 * np.clip(normals @ key, 0.0, 1.0) + 0.2 * np.clip(normals @ fill, 0.0, 1.0)
    spec = np.clip(normals @ half, 0.0, 1.0) ** 40
    return diffuse[..., None], spec[..., None]


def _tints(stitch: Stitch, rows: np.ndarray, columns: np.ndarray,
           centre: tuple[int, int] | None) -> np.ndarray:  # fmt: skip
    """Base colours (K, 3) of centre vertices by their row; with a ``centre`` copy, the
    others washed towards grey so that it stands out."""
    from matplotlib.colors import to_rgb

    palette = np.array([to_rgb(c) for c in ROW_COLOURS])
    rgb = palette[np.mod(rows, len(ROW_COLOURS))]
    if centre is not None:
        other = (rows != centre[0]) | (columns != centre[1])
        rgb[other] = 0.55 * rgb[other] + 0.45 * np.array([0.78, 0.76, 0.72])
    return rgb


def shade_tile(stitch: Stitch, cells: int | tuple[int, int], radius: float, view: np.ndarray,
               box: np.ndarray, width_px: int, highlight: bool = False,
               supersample: int = SUPERSAMPLE) -> np.ndarray:  # fmt: skip
    """The fabric seen through ``box`` as an RGB image (H, width_px, 3) in [0, 1]
    (module docstring); ``cells`` only says which copy ``highlight`` saturates."""
    from scipy.ndimage import uniform_filter

    from .raster import rasterize
    from .tube_mesh import tube_mesh

    px = (box[1] - box[0]) / width_px
    height_px = int(np.ceil((box[3] - box[2]) / px - 1e-9))
    fine = px / supersample
    sigma = 0.4 * radius / fine  # the occlusion's neighbourhood
    pad = int(np.ceil(2.0 * sigma))
    shape = (height_px * supersample + 2 * pad, width_px * supersample + 2 * pad)
    padded = box + fine * pad * np.array([-1.0, 1.0, -1.0, 1.0])
    copies = copies_in_view(stitch, view, padded, radius + fine)
    centre = unit_cell(stitch, _cells(cells)[1]) if highlight else None
    zs = cell_path(stitch.control_points, 16)[:, 2]  # the fabric's depth, mirrors included
    zs = np.concatenate([zs, -zs]) if stitch.mirrors else zs
    z_lo, z_hi = float(zs.min()) - radius, float(zs.max()) + radius
    towards = -1.0 if view[2, 2] < 0 else 1.0  # the fabric's z that points at the viewer
    spacing = min(2.0 * np.pi * radius / AROUND, 0.1)
    mesh = tube_mesh(stitch, copies, radius, spacing, AROUND)
    screen = mesh.points @ view.T
    xy = np.column_stack([(screen[:, 0] - padded[0]) / fine, (padded[3] - screen[:, 1]) / fine])
    frags = rasterize(xy, screen[:, 2], mesh.triangles, shape)
    covered = frags.covered
    tint = _tints(stitch, mesh.centre_row, mesh.centre_column, centre)[mesh.ring]
    near = mesh.points[:, 2] - z_lo if towards > 0 else z_hi - mesh.points[:, 2]
    relief = np.clip(near / (z_hi - z_lo), 0.0, 1.0)
    values = np.column_stack([mesh.normals @ view.T, tint, relief])
    at = frags.interpolate(values, mesh.triangles, 1.0)  # (H, W, 7)
    n = at[..., :3] / np.linalg.norm(at[..., :3], axis=-1)[..., None]
    diffuse, spec = _shade(n)
    image = at[..., 3:6] * (0.22 + diffuse) * (0.55 + 0.45 * at[..., 6:7]) + 0.3 * spec
    depth = frags.depth
    if covered.any():  # occlusion: neighbours nearer the viewer than a pixel shade it
        far = depth[covered].min() - 2.0 * radius
        filled = np.where(covered, depth, far)
        around = filled
        width = round(np.sqrt(4.0 * sigma**2 + 1.0))  # three box passes ~ a Gaussian
        for _ in range(3):
            around = uniform_filter(around, width, mode="nearest")
        occlusion = np.clip((around - filled) / radius, 0.0, 1.0)
        image *= (1.0 - 0.55 * occlusion)[..., None]
    image[~covered] = BACKGROUND
    image = np.clip(image, 0.0, 1.0)[pad : shape[0] - pad, pad : shape[1] - pad]
    return image.reshape(height_px, supersample, width_px, supersample, 3).mean(axis=(1, 3))


def draw_stitch(stitch: Stitch, out: str | Path, cells: int | tuple[int, int] | None = None,
                radius: float | None = None, elevation_deg: float = 72.0,
                azimuth_deg: float = 0.0, side: str = "face", width_px: int = 1100,
                highlight: bool = False, core: bool = False) -> Path:  # fmt: skip
    """Draw a window onto ``cells`` (across, rows; one int: square) stitches to ``out``
    (.png, .pdf, .svg).

    Args:
        stitch: the cell to repeat.
        cells: cells across (a chart's holds its row's stitches) and rows
            [``default_cells``: two repeats of the pattern, at least 3 × 3 stitches].
        radius: tube radius, mm [the yarn radius r; with ``core``, r_core].
        elevation_deg: angle between the viewing direction and the fabric plane
            (90: straight onto the fabric).
        azimuth_deg: rotation of the fabric about its normal.
        side: 'face' (knit side) or 'back' (purl side), see :data:`SIDES`.
        width_px: resolution of the rendering, pixels across (the saved figure is
            7 inches wide at 160 dpi either way).
        highlight: wash out every stitch but the central one (the unit cell).
        core: draw the incompressible cores (radius r_core) instead of the yarn.
    """
    import matplotlib

    if side not in SIDES:
        raise InputError(f"side = {side!r}: must be one of {', '.join(SIDES)}")
    nx, ny = default_cells(stitch) if cells is None else _cells(cells)
    r = tube_radius(stitch, radius, core)
    view = _view_matrix(elevation_deg, azimuth_deg, side)
    box = window(stitch, (nx, ny), view)
    image = shade_tile(stitch, (nx, ny), r, view, box, width_px, highlight)
    what = "cores (r_core)" if core and radius is None else "yarn"
    note = (f"{nx * stitch.closing_shift[0]} × {ny} stitches, {side} side; {what} drawn at radius {r:.3g} mm; "
            "one colour per row") + ("; saturated: one unit cell" if highlight else "")  # fmt: skip
    if stitch.label.startswith(FROM_FILE):
        note = f"{stitch.label}\n{note}"
    out = Path(out)
    with matplotlib.rc_context({"font.size": 11, "font.family": "DejaVu Sans"}):
        fig = stitch_figure(image, box, title(stitch), note)
        buf = io.BytesIO()
        fig.savefig(buf, format=Path(out).suffix.lstrip(".").lower(), dpi=160, facecolor="white")
    return replace_file(out, buf.getvalue())  # never through a symbolic link


def stitch_figure(image: np.ndarray, box: np.ndarray, head: str, note: str) -> Any:
    """The picture ``image`` (H, W, 3) of the screen box ``box`` in a figure 7.3 inches
    wide (1168 px at 160 dpi, whatever the image's resolution), ``head`` above it and
    ``note`` below, the figure as tall as they need."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width = 7.0
    lines = head.count("\n") + 1 + note.count("\n") + 1
    height = width * image.shape[0] / image.shape[1] + 0.25 + 0.21 * lines
    fig = Figure(figsize=(width + 0.3, height), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.imshow(image, extent=tuple(box), interpolation="antialiased")
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_color("0.6")
    ax.set_title(head, fontsize=11)
    ax.set_xlabel(note, fontsize=10, color="0.35", loc="right")  # in the layout, not over it
    return fig


def tube_radius(stitch: Stitch, radius: float | None, core: bool) -> float:
    """The radius drawn: ``radius`` if given, else the core radius r_core (``core``) or
    the yarn radius r."""
    if radius is not None:
        return radius
    if core:
        if stitch.params is None:
            raise InputError("--core: the stitch's r_core is not known")
        return stitch.params.r_core_mm
    return stitch.r_mm


def render(
    out: str | Path,
    *,
    results: str | Path | None = None,
    task: str | None = None,
    step: int | None = None,
    state: str | Path | None = None,
    params: StitchParams | None = None,
    radius: float | None = None,
    cells: int | tuple[int, int] | None = None,
    side: str = "face",
    elevation_deg: float = 72.0,
    width_px: int = 1100,
    highlight: bool = False,
    core: bool = False,
    preset: str | None = None,
    starts: int = 1,
) -> tuple[Path, Stitch]:
    """Draw a stitch (``knitsweep render``): a results-file task, a state file, or, with
    neither, the stitch of ``params`` relaxed (``preset``, ``starts``). ``out`` ending in
    .vtp, .vtu, .ply or .obj writes the tile's yarn as a 3D file instead (``export3d``).
    Returns the file written and the stitch.

    Raises:
        InputError: both sources, unknown task, bad step, bad output suffix, cells outside
            1..MAX_CELLS, radius ≤ 0 or > MAX_RADIUS, elevation outside (0, 90], unknown side.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in OUT_SUFFIXES + MESH_SUFFIXES:
        raise InputError(f"out = '{out}': must end in {', '.join(OUT_SUFFIXES + MESH_SUFFIXES)}")
    if cells is not None and not all(1 <= c <= MAX_CELLS for c in _cells(cells)):
        nx, ny = _cells(cells)
        given = f"{nx}" if nx == ny else f"{nx}x{ny}"
        raise InputError(f"cells = {given}: must be in 1..{MAX_CELLS} (each way)")
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
    if results is not None and state is not None:
        raise InputError("give either --results FILE --task ID, or --state FILE, or neither "
                         "(the stitch relaxed at the parameters given)")  # fmt: skip
    check_writable(out, "--out")  # before any compute, as in every command
    stitch = stitch_to_draw(results, task, step, state, params, preset, starts)
    if suffix in MESH_SUFFIXES:
        from .export3d import write_tile

        nx, ny = default_cells(stitch) if cells is None else _cells(cells)
        return write_tile(stitch, out, (nx, ny), tube_radius(stitch, radius, core)), stitch
    path = draw_stitch(stitch, out, cells, radius, elevation_deg=elevation_deg, side=side,
                       width_px=width_px, highlight=highlight, core=core)  # fmt: skip
    return path, stitch
