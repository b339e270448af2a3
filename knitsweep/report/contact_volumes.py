"""Pictures of a stitch's contact volumes, like the paper's Fig. 6a–f: the parts of the
stitch's yarn tube that overlap another part of the yarn, as semi-transparent clouds of
points, by contact class (self green, same row magenta, NN same column above lavender
and below cyan, NNN same column yellow), around the stitch's centre-line.

A knit/purl pattern (garter, rib, seed: images mirrored through the fabric plane,
docs/model.md §11) has its own classes (``kernels.mirrored.MIRROR_CLASSES``): self,
same row, same column, mirrored and other; its mirrored contacts are drawn by where the
mirror image sits: beside in the row (n = 0), in a row above or below.

The points are the tube estimator's (``analysis.volumes.tube_samples``: scrambled Sobol
points in tube coordinates, seed 0) that lie in an overlap; their density follows the
tube's volume element, so a cloud shows the volume it stands for (docs/model.md §9).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import StitchParams
from ..errors import InputError
from .render import OUT_SUFFIXES
from .sources import stitch_to_draw, title
from .tile import Stitch, cell_path

VOLUME_COLOUR = {  # paper Fig. 6a–d; the patterns' classes after them
    "self": "#2ca02c",
    "same_row": "#c51bd6",
    "nn_above": "#9a8ee6",
    "nn_below": "#17becf",
    "nnn_column": "#d4a20f",
    "same_column": "#9a8ee6",
    "mirrored_beside": "#d62728",
    "mirrored_above": "#1f5fbf",
    "mirrored_below": "#17becf",
    "other": "#888888",
}
VOLUME_LABEL = {
    "self": "self",
    "same_row": "same row",
    "nn_above": "NN same column, row above",
    "nn_below": "NN same column, row below",
    "nnn_column": "NNN same column",
    "same_column": "same column",
    "mirrored_beside": "mirrored, same row",
    "mirrored_above": "mirrored, row above",
    "mirrored_below": "mirrored, row below",
    "other": "other",
}
KINDS = {
    False: ("self", "same_row", "nn_above", "nn_below", "nnn_column", "other"),
    True: ("self", "same_row", "same_column", "mirrored_beside", "mirrored_above",
           "mirrored_below", "other"),
}  # fmt: skip
"""The kinds drawn, for a fabric of translations (False) and a knit/purl pattern (True)."""
PANELS = {
    False: (
        ("(a) self contact", ("self",)),
        ("(b) same-row contacts", ("same_row",)),
        ("(c) NN same-column contacts", ("nn_above", "nn_below")),
        ("(d) NNN same-column contacts", ("nnn_column",)),
        ("(e) all contact volumes", KINDS[False]),
    ),
    True: (
        ("(a) self contact", ("self",)),
        ("(b) same-row contacts", ("same_row",)),
        ("(c) same-column contacts", ("same_column",)),
        ("(d) mirrored contacts", ("mirrored_beside", "mirrored_above", "mirrored_below")),
        ("(e) all contact volumes", KINDS[True]),
    ),
}
MAX_SAMPLES = 1 << 20


def volume_kind(m: int, n: int, parity: tuple[int, int] = (0, 0)) -> str:
    """The kind (a key of :data:`VOLUME_COLOUR`) of a contact with the image (m, n): its
    contact class (``analysis.volumes.contact_class``), NN same column and mirrored
    split by where the image sits."""
    from ..analysis.volumes import contact_class

    cls = contact_class(m, n, parity)
    if cls == "nn_column":
        return "nn_above" if n > 0 else "nn_below"
    if cls == "mirrored":
        return "mirrored_beside" if n == 0 else ("mirrored_above" if n > 0 else "mirrored_below")
    return cls


def contact_volume_points(stitch: Stitch, samples: int = 1 << 15) -> dict[str, np.ndarray]:
    """Kind → points (n, 3), mm, of the stitch's tube that lie in a contact volume of
    that kind (``KINDS[stitch.mirrors]``; a point in several is drawn in the kind of its
    nearest other stitch, a self overlap first). A pattern's other stitches include its
    mirrored images (``stitch.mirror_parity``)."""
    from scipy.stats import qmc

    from ..analysis.volumes import build_pieces, tube_samples

    cp = np.asarray(stitch.control_points, dtype=float)
    parity = tuple(stitch.mirror_parity)
    pieces = build_pieces(cp, stitch.a_x, stitch.a_y, stitch.r_mm, parity=parity)
    u = qmc.Sobol(3, scramble=True, seed=np.random.default_rng(0)).random(samples)
    ts = tube_samples(cp, pieces, stitch.r_mm, u)
    labels = np.full(len(u), "", dtype=object)
    for p in np.unique(ts.other[ts.other >= 0]):
        labels[ts.other == p] = volume_kind(*(int(v) for v in pieces.offsets[p]), parity)
    labels[ts.self_overlap] = "self"
    return {k: ts.x[labels == k] for k in KINDS[stitch.mirrors]}


def draw_contact_volumes(stitch: Stitch, out: str | Path, samples: int = 1 << 15) -> Path:
    """Five panels (a–e as the paper's Fig. 6a–e) of the stitch's contact volumes to
    ``out`` (.png, .pdf, .svg); ``samples`` tube points in all (a power of 2)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    clouds = contact_volume_points(stitch, samples)
    path = cell_path(stitch.control_points, 24)
    fig = Figure(figsize=(16.0, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    lo, hi = path.min(axis=0) - stitch.r_mm, path.max(axis=0) + stitch.r_mm
    panels = PANELS[stitch.mirrors]
    for i, (name, kinds) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1, projection="3d")
        ax.plot(*path.T, color="0.25", lw=1.2)
        for k in kinds:
            pts = clouds[k]
            if len(pts):
                ax.scatter(*pts.T, s=3.0, color=VOLUME_COLOUR[k], alpha=0.3, linewidths=0,
                           label=VOLUME_LABEL[k] if len(kinds) > 1 else None)  # fmt: skip
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(tuple(hi - lo))
        ax.view_init(elev=50, azim=-75)
        ax.set_title(name, fontsize=10)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("x (mm)", fontsize=8)
        ax.set_ylabel("y (mm)", fontsize=8)
        ax.set_zlabel("z (mm)", fontsize=8)
    handles = [fig.axes[-1].plot([], [], "o", color=VOLUME_COLOUR[k], label=VOLUME_LABEL[k])[0]
               for k in clouds if len(clouds[k])]  # fmt: skip
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), frameon=False,
               fontsize=9)  # fmt: skip
    fig.suptitle(f"contact volumes of {title(stitch)}", fontsize=11)
    out = Path(out)
    fig.savefig(out, dpi=150, facecolor="white")
    return out


def render_contact_volumes(out: str | Path, *, results: str | Path | None = None,
                           task: str | None = None, step: int | None = None,
                           state: str | Path | None = None, params: StitchParams | None = None,
                           samples: int = 1 << 15, preset: str | None = None,
                           starts: int = 1) -> tuple[Path, Stitch]:  # fmt: skip
    """``knitsweep render --contact-volumes``: the stitch of a results-file task (point,
    or sweep at ``step``), of a state file, or with neither of ``params`` relaxed
    (``preset``, ``starts``), its contact volumes drawn to ``out``.

    Raises:
        InputError: bad output suffix, samples not a power of 2 in 2^10..2^20, both
            sources, unknown task or bad step.
    """
    out = Path(out)
    if out.suffix.lower() not in OUT_SUFFIXES:
        raise InputError(f"out = '{out}': must end in {', '.join(OUT_SUFFIXES)}")
    if not (1 << 10 <= samples <= MAX_SAMPLES and samples & (samples - 1) == 0):
        raise InputError(f"samples = {samples}: must be a power of 2 in 1024..{MAX_SAMPLES}")
    if results is not None and state is not None:
        raise InputError("give either --results FILE --task ID, or --state FILE, or neither "
                         "(the stitch relaxed at the parameters given)")  # fmt: skip
    stitch = stitch_to_draw(results, task, step, state, params, preset, starts)
    return draw_contact_volumes(stitch, out, samples), stitch
