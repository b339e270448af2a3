"""The stitch's yarn volume and packing fraction, two ways (paper SI "Contact Volumes";
docs/model.md §9).

The paper's quantity: V_uncomp is the volume within one yarn radius r of the stitch's
centre-line, V_comp the part of it also within r of a neighbouring stitch's, and

    V_total = V_uncomp − V_comp / 2,   φ = V_total / V_cell,   V_cell = a_x a_y Δz,

with Δz = z_max − z_min + 2r of the centre-line.

* :func:`voxel_volumes` is the paper's three-step voxel method as the SI defines it:
  voxels of side l fill the stitch's box, those whose centre is within r of the
  centre-line are V_uncomp, those of them also within r of another stitch's
  centre-line are V_comp. Its error is a discretisation error that does not fall
  smoothly with l (benchmarks/bench_volumes.py).
* :func:`qmc_volumes` integrates the same quantity over the tube itself, in tube
  coordinates (t, ρ, θ) around the centre-line with the exact volume element
  |c'(t)| ρ (1 − ρ κ·u) dt dρ dθ, by scrambled Sobol points; the overlap-free part is
  exact (π r² times the arc length), so only the overlaps are sampled. Independent
  scrambles give the standard error. With a fixed seed the same tube coordinates are
  used for every state, so φ varies smoothly with the state where voxels jump.

Both count a region where the stitch's tube overlaps itself once (V_uncomp is a volume
of space). The tube estimator tells a point's own branch of the tube from another part
of the yarn by arc length, within ``EXCLUSION_FACTOR`` r as the contact energy does;
the voxel method's caps at the two ends of the stitch's piece of yarn (within r of its
end points, inside the neighbouring stitch's yarn) add as much to V_uncomp as half of
them and of the neighbour's caps take from it through V_comp, so the two agree.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ...kernels.bezier import basis_tables
from ...kernels.contact import EXCLUSION_FACTOR
from ...kernels.mirrored import MIRROR_CLASSES, is_mirrored, mirror_class
from ...stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from .geometry import Pieces, arc_length, build_pieces, distances, fabric_depth

VOXEL_BATCH = 1 << 18
"""Voxel centres tested per batch (bounds the memory of the voxel method)."""


@dataclass(frozen=True)
class Volumes:
    """One estimate of the stitch's volumes (mm³) and packing fraction.

    ``method``: "voxel" or "qmc"; ``resolution``: voxel side (mm) or points per
    scramble; ``*_error``: one standard error (qmc; None for voxels, whose error is
    not statistical); ``compressed_by_class``: V_comp split by the class of the
    nearest other stitch (``contact_classes(parity)`` without self), and the self-overlap
    volume (counted once in V_uncomp, qmc only) under "self".
    """

    method: str
    resolution: float
    V_uncomp: float
    V_comp: float
    V_total: float
    V_cell: float
    phi: float
    V_total_error: float | None
    phi_error: float | None
    compressed_by_class: dict[str, float]

    def as_dict(self) -> dict:
        return asdict(self)


def contact_classes(parity: tuple[int, int] = (0, 0)) -> tuple[str, ...]:
    """The contact classes of a fabric whose images are mirrored by ``parity``: those of
    translations (``CONTACT_CLASSES``, docs/model.md §9) for (0, 0), else a knit/purl
    pattern's (``kernels.mirrored.MIRROR_CLASSES``, §11), as the stitches name them."""
    return MIRROR_CLASSES if any(parity) else tuple(CONTACT_CLASSES)


def contact_class(m: int, n: int, parity: tuple[int, int] = (0, 0)) -> str:
    """Name in ``contact_classes(parity)`` of image offset (m, n) (docs/model.md §9;
    a pattern's by the mirrored kernel's ``mirror_class``, §11)."""
    if any(parity):
        return MIRROR_CLASSES[mirror_class(m, n, is_mirrored(m, n, *parity))]
    if (m, n) == (0, 0):
        return "self"
    if n == 0:
        return "same_row"
    if m == 0 and abs(n) == 1:
        return "nn_column"
    if m == 0 and abs(n) == 2:
        return "nnn_column"
    return "other"


def _by_class(pieces: Pieces, who: np.ndarray, weights: np.ndarray) -> dict[str, float]:
    out = dict.fromkeys(contact_classes(pieces.parity), 0.0)
    hit = who >= 0
    for p in np.unique(who[hit]):
        cls = contact_class(*map(int, pieces.offsets[p]), pieces.parity)
        out[cls] += float(weights[hit][who[hit] == p].sum())
    return out


def voxel_volumes(cp: np.ndarray, a_x: float, a_y: float, r: float, voxel_mm: float,
                  spacing: float = 0.01, closed: bool = False,
                  offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  parity: tuple[int, int] = (0, 0)) -> Volumes:  # fmt: skip
    """The paper's voxel method (module docstring) with voxels of side ``voxel_mm``.

    cp (S, 6, 3): the stitch's control points, mm (``CellModel.control_points``);
    a_x, a_y: the cell periods, mm; r: the yarn radius, mm. The voxel lattice starts
    at the corner of the box of the centre-line widened by r, shifted by ``offset``
    (fractions of a voxel, each in [0, 1): the lattice's phase). ``spacing``: the
    centre-line is a polyline of chords at most this long (mm; its distance error is
    below spacing² κ / 8). ``closed``: the piece is a closed loop (test shapes).
    ``parity``: the images' mirror parity (a knit/purl pattern's ``mirror_parity``;
    (0, 0): translations only).
    """
    if not voxel_mm > 0.0:
        raise ValueError(f"voxel_mm = {voxel_mm}: must be > 0")
    cp = np.asarray(cp, dtype=float)
    pieces = build_pieces(cp, a_x, a_y, r, spacing, closed, parity)
    ends = np.concatenate([pieces.a[pieces.piece == 0], pieces.b[pieces.piece == 0][-1:]])
    lo = ends.min(axis=0) - r - np.asarray(offset, dtype=float) * voxel_mm
    counts = np.ceil((ends.max(axis=0) + r - lo) / voxel_mm).astype(int)
    axes = [lo[d] + (np.arange(counts[d]) + 0.5) * voxel_mm for d in range(3)]
    n_xy = counts[0] * counts[1]
    gx, gy = (g.ravel() for g in np.meshgrid(axes[0], axes[1], indexing="ij"))
    n_unc = n_comp = 0
    comp_by = dict.fromkeys(contact_classes(parity), 0.0)
    # z-slabs of whole (x, y) layers, about VOXEL_BATCH voxels each
    per = max(1, VOXEL_BATCH // n_xy)
    for z0 in range(0, counts[2], per):
        z = axes[2][z0 : z0 + per]
        x = np.column_stack([np.tile(gx, len(z)), np.tile(gy, len(z)), np.repeat(z, n_xy)])
        d_own, d_other, who = distances(pieces, x, None, r, 0.0)
        inside = d_own <= r
        comp = inside & (d_other <= r)
        n_unc += int(inside.sum())
        n_comp += int(comp.sum())
        for k, v in _by_class(pieces, np.where(comp, who, -1), np.ones(len(x))).items():
            comp_by[k] += v
    cell = voxel_mm**3
    v_unc, v_comp = n_unc * cell, n_comp * cell
    v_total = v_unc - 0.5 * v_comp
    v_cell = a_x * a_y * fabric_depth(cp, r, parity)
    return Volumes("voxel", voxel_mm, v_unc, v_comp, v_total, v_cell, v_total / v_cell, None,
                   None, {k: v * cell for k, v in comp_by.items()})  # fmt: skip


@dataclass(frozen=True)
class TubeSamples:
    """Points in the stitch's tube (tube coordinates mapped to space) for one scramble.

    x (N, 3) mm; weight (N,) mm³: each point's share of the tube's volume (the volume
    element; they add up to π r² times the arc length); self_overlap (N,) bool: also
    within r of another part of the stitch's own yarn; other (N,) int: the piece
    (``Pieces.offsets``) of the nearest other stitch within r, or -1.
    """

    x: np.ndarray
    weight: np.ndarray
    self_overlap: np.ndarray
    other: np.ndarray


def tube_samples(cp: np.ndarray, pieces: Pieces, r: float, u: np.ndarray) -> TubeSamples:
    """Map points u (N, 3) of the unit cube to the tube: t = S u₀ along the centre-line,
    ρ = r √u₁, θ = 2π u₂ about it (any normal frame: its twist does not enter the
    volume element), and classify them (module docstring)."""
    cp = np.asarray(cp, dtype=float)
    s_count = len(cp)
    tg = s_count * u[:, 0]
    seg = np.minimum(tg.astype(np.int64), s_count - 1)
    tab = basis_tables(tg - seg)  # (4, N, 6)
    c, d1, d2 = (np.einsum("ni,nik->nk", tab[k], cp[seg]) for k in range(3))
    speed = np.linalg.norm(d1, axis=1)
    tangent = d1 / speed[:, None]
    helper = np.where(np.abs(tangent[:, [2]]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(tangent, helper)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(tangent, e1)
    rho = r * np.sqrt(u[:, 1])
    theta = 2.0 * np.pi * u[:, 2]
    radial = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
    kappa = (d2 - np.sum(d2 * tangent, axis=1)[:, None] * tangent) / speed[:, None] ** 2
    jac = speed * (1.0 - rho * np.sum(kappa * radial, axis=1))
    x = c + rho[:, None] * radial
    s0 = np.interp(tg, pieces.arc_t, pieces.arc_s)
    d_own, d_other, who = distances(pieces, x, s0, r, EXCLUSION_FACTOR * r)
    weight = s_count * np.pi * r * r * jac / len(u)
    return TubeSamples(x, weight, d_own <= r, np.where(d_other <= r, who, -1))


def qmc_volumes(cp: np.ndarray, a_x: float, a_y: float, r: float, samples: int = 1 << 14,
                scrambles: int = 8, seed: int = 0, spacing: float = 0.01,
                closed: bool = False, parity: tuple[int, int] = (0, 0)) -> Volumes:  # fmt: skip
    """The same volumes by randomised quasi-Monte Carlo over the tube (module
    docstring): ``scrambles`` independent scrambled Sobol sequences of ``samples``
    points (a power of 2) each, seeded by ``seed``; the estimate is their mean and the
    error one standard error of it. Arguments otherwise as :func:`voxel_volumes`."""
    from scipy.stats import qmc

    if samples < 2 or samples & (samples - 1):
        raise ValueError(f"samples = {samples}: must be a power of 2")
    if scrambles < 2:
        raise ValueError(f"scrambles = {scrambles}: must be >= 2 (for the error estimate)")
    cp = np.asarray(cp, dtype=float)
    pieces = build_pieces(cp, a_x, a_y, r, spacing, closed, parity)
    tube = np.pi * r * r * arc_length(cp)
    rng = np.random.default_rng(seed)
    rows = []
    by_class = []
    for _ in range(scrambles):
        ts = tube_samples(cp, pieces, r, qmc.Sobol(3, scramble=True, seed=rng).random(samples))
        share = np.where(ts.self_overlap, 0.5, 1.0)  # a self-overlap is reached twice
        other = ts.other >= 0
        unc = tube - float(np.sum(ts.weight * (1.0 - share)))
        comp = float(np.sum(ts.weight * share * other))
        rows.append((unc, comp, unc - 0.5 * comp))
        cls = _by_class(pieces, ts.other, ts.weight * share)
        cls["self"] = float(np.sum(ts.weight * 0.5 * ts.self_overlap))
        by_class.append(cls)
    est = np.asarray(rows)
    mean = est.mean(axis=0)
    err = est.std(axis=0, ddof=1) / np.sqrt(scrambles)
    v_cell = a_x * a_y * fabric_depth(cp, r, parity)
    classes = {k: float(np.mean([c[k] for c in by_class])) for k in contact_classes(parity)}
    return Volumes("qmc", float(samples), float(mean[0]), float(mean[1]), float(mean[2]), v_cell,
                   float(mean[2] / v_cell), float(err[2]), float(err[2] / v_cell), classes)  # fmt: skip


STORED_SAMPLES = 1 << 12
"""Sobol points per scramble of the stored packing fraction ([store] packing_fraction)."""
STORED_SCRAMBLES = 4
"""Scrambles of the stored packing fraction (its error is one standard error)."""


def packing_fraction(cp: np.ndarray, a_x: float, a_y: float, r: float,
                     parity: tuple[int, int] = (0, 0)) -> tuple[float, float]:  # fmt: skip
    """(φ, its standard error) by :func:`qmc_volumes` at the stored resolution and seed
    0: what ``[store] packing_fraction = true`` writes for each state (``parity``: the
    images' mirror parity)."""
    v = qmc_volumes(cp, a_x, a_y, r, STORED_SAMPLES, STORED_SCRAMBLES, seed=0, parity=parity)
    return v.phi, float(v.phi_error)
