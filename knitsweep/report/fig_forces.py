"""Contact forces by class along a strain sweep (paper SI "Contact Forces", the figure
of forces against strain, panels a–e; docs/model.md §9), from the states a job stores
with ``[store] states = true``, and the RMS column of Table S3 from the same forces.
A knit/purl pattern's (garter, rib, seed) rows are its own classes, over its mirrored
images too (``kernels.mirrored.MIRROR_CLASSES``, docs/model.md §11).

The forces are the paper's pair forces between sampled yarn points
(``CellModel.contact_pair_forces_by_class``, N; both contacts of a class added), with
the paper's sign convention for that figure: positive assists linear elastic
behaviour when the fabric is stretched in the given direction. Linear elastic
behaviour is extension along the pulled axis, Poisson contraction across it, and out
of plane the unjammed response: expansion under x pulls, contraction under y pulls
(paper Fig. 6g, Fig. S12b). So a force that extends the fabric along a counts with
the sign ``LINEAR_ELASTIC_SIGN[direction][a]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..analysis import fit_line
from ..config import StitchParams
from ..stitches import DEFAULT_STITCH, STITCH_NAMES
from ..stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from ..store.format import SWEEPS
from .fig_mechanics import CLASS_COLOUR, CLASS_LABEL
from .force_columns import contact_classes, job_fidelity
from .path_style import STRAIN
from .plotting import SkipFigure, label_of, new_figure, title
from .reduce import Reduction
from .series import series_key

LINEAR_ELASTIC_SIGN = {"x": np.array([1.0, -1.0, 1.0]), "y": np.array([-1.0, 1.0, -1.0])}
"""Sign that turns 'extends the fabric along x, y, z' into the paper's 'assists linear
elastic behaviour' for a pull in x or y (module docstring)."""

PAPER_L_MM = 10.5
"""The paper's contact-force sweeps: L = 10.5 mm (jammed in both directions)."""


def sweeps_with_states(red: Reduction) -> list[Any]:
    """Done sweeps of the reduction that store every step's state, of every stitch (a
    pattern's pair forces by class include its mirrored images)."""
    return [e for e in red.entries if e.kind == SWEEPS and e.meta.get("status") == "done"
            and "states" in e.record]  # fmt: skip


def pair_forces_along(red: Reduction, entry: Any) -> tuple[np.ndarray, np.ndarray]:
    """(strain (n,), pair forces by class (n, 5, 3) N, rows the stitch's
    ``contact_classes``, positive extends the fabric) of one stored sweep, from its
    states."""
    from ..model import CellModel  # numba: only for files that store the states

    model = CellModel(StitchParams.from_flat(entry.meta), job_fidelity(red.roots[0]))
    states = np.asarray(entry.record["states"], dtype=float)
    return (np.asarray(entry.record["strain"], dtype=float),
            np.array([model.contact_pair_forces_by_class(x) for x in states]))  # fmt: skip


def _nearest_L(entries: list[Any], direction: str, L_mm: float) -> Any | None:
    pulls = [e for e in entries if e.meta.get("direction") == direction]
    return min(pulls, key=lambda e: abs(float(e.meta["L_mm"]) - L_mm), default=None)


def figS11_contact_forces_strain(red: Reduction, notes: list[str],
                                 upto: float | None = None) -> Any:  # fmt: skip
    """Pair forces by class against strain at the L nearest 10.5 mm, pulled in x (top)
    and y (bottom), components x, y, z (columns), in the paper's sign convention
    (positive assists linear elastic behaviour); ``upto``: strains up to it only (the
    forces grow by two orders of magnitude towards the end of a sweep). Each stitch
    whose sweeps store their states has its two rows (stitches in ``STITCH_NAMES``
    order), a pattern's with its own classes."""
    entries = sweeps_with_states(red)
    if not entries:
        raise SkipFigure("needs sweeps that store their states ([store] states = true)")
    picked = []  # (direction, sweep) of each row; the series label names the stitch
    for stitch in STITCH_NAMES:
        mine = [e for e in entries if e.meta.get("stitch", DEFAULT_STITCH) == stitch]
        for d in "xy":
            e = _nearest_L(mine, d, PAPER_L_MM)
            if e is not None:
                picked.append((d, e))
    fig = new_figure(13.0, 3.4 * len(picked) + 1.0, wide=True)
    sweep_rows = {r["task_id"]: r for r in red.sweeps}
    axes = np.atleast_2d(fig.subplots(len(picked), 3, squeeze=False))
    legends = set()
    for row, (d, e) in enumerate(picked):
        classes = contact_classes(e.meta)
        strain, f = pair_forces_along(red, e)
        signed = f * LINEAR_ELASTIC_SIGN[d][None, None, :]
        if upto is not None:
            keep = strain <= upto * (1.0 + 1e-9)
            strain, signed = strain[keep], signed[keep]
        for col, a in enumerate("xyz"):
            ax = axes[row, col]
            for j, cls in enumerate(classes):
                ax.plot(strain, signed[:, j, col], color=CLASS_COLOUR[cls], lw=1.5,
                        label=CLASS_LABEL[cls])  # fmt: skip
            ax.axhline(0.0, color="0.6", lw=0.8)
            ax.set_xlabel(STRAIN[d])
            if col == 0:  # which sweep: its L, and its series when several are stored
                sweep = sweep_rows.get(e.task_id)
                lab = label_of(red, series_key(sweep), chars=28) if sweep else ""
                ax.set_ylabel("\n".join(filter(None, (
                    f"pulled in {d}, L = {float(e.meta['L_mm']):g} mm", lab, "force (N)"))))  # fmt: skip
            if row == 0:
                ax.set_title(f"{a} component")
        if classes not in legends:  # a legend where a stitch's classes first appear
            legends.add(classes)
            axes[row, 0].legend(frameon=True, framealpha=0.9)
    title(
        fig,
        red,
        "Contact (pair) forces by class along the sweeps (positive assists "
        "linear elastic extension)",
    )
    return fig


def same_row_z_rms(red: Reduction, points: int = 20) -> dict[float, float]:
    """Paper Table S3's RMS column: for each y pull that stores its states, the RMS
    (N) of the residuals of a straight line fitted to the z pair force of the
    same-row contacts against strain over the first ``points`` steps (stitches of
    translated images alone: the paper's classes)."""
    out = {}
    for e in sweeps_with_states(red):
        if (e.meta.get("direction") != "y" or len(e.record["strain"]) < points
                or contact_classes(e.meta) != tuple(CONTACT_CLASSES)):  # fmt: skip
            continue
        strain, f = pair_forces_along(red, e)
        fz = f[:points, CONTACT_CLASSES.index("same_row"), 2]
        out[round(float(e.meta["L_mm"]), 6)] = float(np.sqrt(fit_line(strain[:points], fz).mse))
    return dict(sorted(out.items()))
