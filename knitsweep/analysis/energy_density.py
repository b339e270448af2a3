"""The fabric's in-plane energy density W(ε_xx, ε_yy) from one point's sweeps, fitted by
a smooth function a cloth simulator can evaluate (docs/energy-density.md).

Every step of a sweep is a relaxed state of the cell at periods (a_x, a_y): a sample of
the energy per unit area of the undeformed fabric,

    W = (E - E_0) / (a_x0 a_y0)   (mJ/mm² = N/mm),   ε_xx = a_x/a_x0 - 1, ε_yy = a_y/a_y0 - 1,

with its exact gradient, the sweep's stresses (``paths``): σ_xx = F_x / a_y0 = ∂W/∂ε_xx
and σ_yy = F_y / a_x0 = ∂W/∂ε_yy (first Piola–Kirchhoff, N/mm). A fan of rays in
(ε_xx, ε_yy) (``jobs/energy_density_*.toml``) samples a star-shaped region around the
zero-force state; the uniaxial sweeps sample the curve where the transverse stress is 0.
The cell's periods are its only in-plane controls here (its lattice has no shear entry
yet), so W is a function of the two normal strains.

The fit (``fit_energy_density``) is a bicubic tensor-product B-spline on uniform knots,
W(ε) = Σ_ij c_ij B_i(ε_xx) B_j(ε_yy), whose coefficients minimise the squared misfit of
the sampled energies *and* stresses (each scaled by its range) plus a small penalty on the
coefficients' second differences (a P-spline: it fixes the coefficients the samples do not
reach and damps wiggles between rays). Why this model: it is C², so its stress and tangent
are continuous, which an implicit simulator needs; its stress and tangent are its exact
derivatives (``EnergyDensity.stress``, ``tangent``; tested against differences); it is
linear in its coefficients (one least-squares solve, no iteration); it makes no assumption
of a functional form, which matters because jamming puts a knee into every stress–strain
curve that polynomials in the invariants smooth away; and it is the model HYLC (Sperl et
al. 2020) fits per term, here over the plane at once, which the two strains allow.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..paths import load_path
from ..stitches import DEFAULT_STITCH

FORMAT = "knitsweep-energy-density"
VERSION = 1
DEGREE = 3
KNOTS = (64, 48)
"""Default number of knot intervals along ε_xx and ε_yy (checked on the shipped job:
docs/energy-density.md)."""
SMOOTHING = 1e-2
"""Default weight of the second-difference penalty, relative to the data's."""
MARGIN = 0.1
"""The spline's box reaches this fraction of the samples' range beyond them on each side
(with knots at the same spacing): a clamped spline's curvature is poorly fixed at its
box's edge, so the samples keep off it (a known convex W's fit: not convex on 2 % of
the sampled region without the margin, 0.06 % with it, 16 x 16 knots)."""
CONVEX_TOLERANCE = 1e-3
"""A tangent's smallest eigenvalue below -this × the largest over the domain counts as
not convex (``EnergyDensity.convexity``)."""
POINT_KEYS = ("stitch", "L_mm", "k_mN_per_mm2", "B_mN_mm2", "r_mm", "r_core_mm", "p")


@dataclass(frozen=True)
class DensitySamples:
    """One point's relaxed states as samples of W: strains (n, 2), W (n,) N/mm, stresses
    (n, 2) N/mm, the sweep (direction) of each, the end of each sweep in strain, and the
    point (its parameters, zero-force periods a_x0_mm, a_y0_mm and energy E0_mJ)."""

    eps: np.ndarray
    W: np.ndarray
    stress: np.ndarray
    direction: np.ndarray
    ends: dict[str, tuple[float, float]]
    point: dict[str, Any]
    left_out: dict[str, str] = field(default_factory=dict)


def density_samples(sweeps, stitch: str | None = None, L_mm: float | None = None
                    ) -> DensitySamples:  # fmt: skip
    """The samples of W of the one point among ``sweeps`` ((meta, record) pairs of stored
    sweeps, e.g. ``Results.energy_density_samples``'s) that ``stitch`` and ``L_mm``
    select: the converged steps of its sweeps, also those of a sweep that ended not
    knittable (its steps up to there are valid states). ValueError naming the points if
    the selection is not one point."""

    def stitch_of(meta) -> str:  # the paper's stitch is stored without its name
        return meta.get("stitch", DEFAULT_STITCH)

    by_point: dict[str, list] = {}
    for meta, record in sweeps:
        if meta.get("status") not in ("done", "not_knittable"):
            continue
        if stitch is not None and stitch_of(meta) != stitch:
            continue
        if L_mm is not None and not math.isclose(meta["L_mm"], L_mm, abs_tol=1e-9):
            continue
        by_point.setdefault(meta["point_id"], []).append((meta, record))
    if len(by_point) != 1:
        found = sorted({(stitch_of(es[0][0]), es[0][0]["L_mm"]) for es in by_point.values()})
        listed = ", ".join(f"{s} L = {L:g} mm" for s, L in found) or "none"
        raise ValueError(
            f"select one point (--point-stitch, --point-L): the sweeps' points are {listed}"
        )
    (entries,) = by_point.values()
    # every sweep starts at the point's zero-force state; one that found a lower one
    # (its rest_restarts) starts there: the lowest is the reference, the others left out
    e0 = [float(rec["total_energy"][0]) for _, rec in entries]
    ref_meta, ref = entries[int(np.argmin(e0))]
    a_x0, a_y0, E0 = float(ref["a_x"][0]), float(ref["a_y"][0]), min(e0)
    parts, ends, left_out = [], {}, {}
    for (meta, rec), e_start in sorted(zip(entries, e0, strict=True),
                                       key=lambda me: me[0][0]["direction"]):  # fmt: skip
        d = meta["direction"]
        if abs(e_start - E0) > 1e-12 or rec["a_x"][0] != a_x0 or rec["a_y"][0] != a_y0:
            left_out[d] = f"starts from another zero-force state ({e_start - E0:+.3g} mJ)"
            continue
        ok = np.asarray(rec["converged"], dtype=bool)
        ex = np.asarray(rec["a_x"])[ok] / a_x0 - 1.0
        ey = np.asarray(rec["a_y"])[ok] / a_y0 - 1.0
        w = (np.asarray(rec["total_energy"])[ok] - E0) / (a_x0 * a_y0)
        s = np.stack([np.asarray(rec["stress_xx"])[ok], np.asarray(rec["stress_yy"])[ok]], 1)
        parts.append((ex, ey, w, s, np.full(ok.sum(), d, dtype=object)))
        ends[d] = (float(ex[-1]), float(ey[-1]))
    if not parts:
        raise ValueError("no sweep of the point has steps to sample")
    ex, ey, w, s, d = (np.concatenate(p) for p in zip(*parts, strict=True))
    point = {k: ref_meta[k] for k in POINT_KEYS[1:]} | {"stitch": stitch_of(ref_meta)}
    point |= {"a_x0_mm": a_x0, "a_y0_mm": a_y0, "E0_mJ": E0}
    return DensitySamples(np.stack([ex, ey], 1), w, s, d, ends, point, left_out)


def _basis(t: np.ndarray, x: np.ndarray, nu: int = 0) -> np.ndarray:
    """The B-spline basis (len(x), n) of knots ``t`` (degree 3) or its ``nu``-th derivative."""
    from scipy.interpolate import BSpline

    n = len(t) - DEGREE - 1
    b = BSpline(t, np.eye(n), DEGREE, extrapolate=True)
    return (b.derivative(nu) if nu else b)(np.asarray(x, dtype=float))


def _knots(x: np.ndarray, intervals: int, lo: float | None = None, hi: float | None = None
           ) -> np.ndarray:  # fmt: skip
    """Clamped uniform knots over [lo, hi] (default ``x``'s range)."""
    lo = float(x.min()) - 1e-6 if lo is None else lo
    hi = float(x.max()) + 1e-6 if hi is None else hi
    return np.concatenate([[lo] * DEGREE, np.linspace(lo, hi, intervals + 1), [hi] * DEGREE])


class EnergyDensity:
    """W(ε_xx, ε_yy) (N/mm) as a bicubic tensor-product B-spline: knots ``tx``, ``ty``,
    coefficients ``coef`` (nx, ny); ``domain`` the sampled region's polygon (k, 2) of
    strains; ``point`` and ``fit`` its provenance and the fit's measured errors. Strains
    are engineering strains of the periods from the zero-force state; W is the energy per
    unit area of the undeformed fabric; ``stress`` = ∂W/∂ε (σ_xx, σ_yy) and ``tangent`` =
    ∂²W/∂ε∂ε, the spline's exact derivatives."""

    def __init__(self, tx, ty, coef, domain, point: dict, fit: dict) -> None:
        self.tx, self.ty = np.asarray(tx, dtype=float), np.asarray(ty, dtype=float)
        self.coef = np.asarray(coef, dtype=float)
        self.domain = np.asarray(domain, dtype=float)
        self.point, self.fit = dict(point), dict(fit)

    def _d(self, exx, eyy, nx: int, ny: int) -> np.ndarray:
        exx, eyy = np.broadcast_arrays(np.asarray(exx, dtype=float), np.asarray(eyy, dtype=float))
        bx = _basis(self.tx, exx.ravel(), nx)
        by = _basis(self.ty, eyy.ravel(), ny)
        return np.einsum("pi,ij,pj->p", bx, self.coef, by).reshape(exx.shape)

    def W(self, exx, eyy) -> np.ndarray:
        """Energy per unit undeformed area (N/mm = mJ/mm²) at strains (ε_xx, ε_yy)."""
        return self._d(exx, eyy, 0, 0)

    def stress(self, exx, eyy) -> np.ndarray:
        """(σ_xx, σ_yy) = ∂W/∂ε (N/mm), shape (..., 2)."""
        return np.stack([self._d(exx, eyy, 1, 0), self._d(exx, eyy, 0, 1)], -1)

    def tangent(self, exx, eyy, convexified: bool = False) -> np.ndarray:
        """∂²W/∂ε_i∂ε_j (N/mm), shape (..., 2, 2), symmetric. ``convexified``: its negative
        eigenvalues set to 0 (the nearest positive semi-definite matrix), for a simulator's
        Newton solve where the fit is not convex (``convexity``); then no longer the
        derivative of ``stress``."""
        xx, xy, yy = self._d(exx, eyy, 2, 0), self._d(exx, eyy, 1, 1), self._d(exx, eyy, 0, 2)
        K = np.stack([np.stack([xx, xy], -1), np.stack([xy, yy], -1)], -2)
        if not convexified:
            return K
        lam, vec = np.linalg.eigh(K)
        return np.einsum("...ik,...k,...jk->...ij", vec, np.maximum(lam, 0.0), vec)

    def in_domain(self, exx, eyy) -> np.ndarray:
        """True where (ε_xx, ε_yy) lies in the sampled region (``domain``); outside, W is
        the spline's extension, fixed by its smoothing only: not a prediction."""
        return _inside(self.domain, np.asarray(exx, dtype=float), np.asarray(eyy, dtype=float))

    def convexity(self, n: int = 101) -> dict[str, float]:
        """Where the fit is not convex: on an n × n grid over the domain's box, the
        fraction of in-domain nodes whose tangent's smallest eigenvalue is below
        -``CONVEX_TOLERANCE`` × the largest found, that eigenvalue's minimum, and the box
        (strains) of those nodes (NaN if none)."""
        lo, hi = self.domain.min(0), self.domain.max(0)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
        inside = self.in_domain(gx, gy)
        eig = np.linalg.eigvalsh(self.tangent(gx[inside], gy[inside]))
        bad = eig[:, 0] < -CONVEX_TOLERANCE * eig[:, 1].max()
        out = {"fraction": float(bad.mean()), "min_eigenvalue_N_per_mm": float(eig[:, 0].min()),
               "max_eigenvalue_N_per_mm": float(eig[:, 1].max())}  # fmt: skip
        box = [float("nan")] * 4
        if bad.any():
            bx, by = gx[inside][bad], gy[inside][bad]
            box = [float(bx.min()), float(bx.max()), float(by.min()), float(by.max())]
        return out | dict(zip(("eps_xx_min", "eps_xx_max", "eps_yy_min", "eps_yy_max"), box,
                              strict=True))  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """The file's content (docs/energy-density.md)."""
        return {"format": FORMAT, "version": VERSION, "model": "bicubic tensor-product B-spline",
                "variables": ["eps_xx", "eps_yy"],
                "units": {"W": "N/mm (mJ/mm^2, per undeformed area)", "strain": "1",
                          "stress": "N/mm"},
                "degree": [DEGREE, DEGREE], "knots_eps_xx": self.tx.tolist(),
                "knots_eps_yy": self.ty.tolist(), "coefficients": self.coef.tolist(),
                "domain": self.domain.tolist(), "point": self.point,
                "fit": self.fit}  # fmt: skip

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EnergyDensity:
        if d.get("format") != FORMAT or d.get("version") != VERSION:
            raise ValueError(f"not a {FORMAT} file of version {VERSION}: format = "
                             f"{d.get('format')!r}, version = {d.get('version')!r}")  # fmt: skip
        return cls(d["knots_eps_xx"], d["knots_eps_yy"], d["coefficients"], d["domain"],
                   d["point"], d["fit"])  # fmt: skip


def load_energy_density(path: str | Path) -> EnergyDensity:
    """Read an energy density written by ``knitsweep energy-density`` (or
    ``EnergyDensity.save``): W, its stress and tangent at any strain."""
    return EnergyDensity.from_dict(json.loads(Path(path).read_text()))


def _inside(poly: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Even–odd rule: points (x, y) inside polygon ``poly`` (k, 2); on an edge counts."""
    x, y = np.broadcast_arrays(x, y)
    inside = np.zeros(x.shape, dtype=bool)
    on_edge = np.zeros(x.shape, dtype=bool)
    for (x1, y1), (x2, y2) in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        crosses = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < xc)
        cross = (x2 - x1) * (y - y1) - (y2 - y1) * (x - x1)
        seg = np.hypot(x2 - x1, y2 - y1)
        t = ((x - x1) * (x2 - x1) + (y - y1) * (y2 - y1)) / max(seg**2, 1e-300)
        on_edge |= (np.abs(cross) <= 1e-12 * max(seg, 1e-300)) & (t >= 0) & (t <= 1)
    return inside | on_edge


def sampled_domain(s: DensitySamples) -> np.ndarray:
    """The sampled region: the polygon through the origin and the sweeps' ends, by angle
    (star-shaped about the zero-force state, which every ray starts from)."""
    ends = np.array(list(s.ends.values()))
    ang = np.arctan2(ends[:, 1], ends[:, 0])
    order = np.argsort(ang)
    ends, ang = ends[order], ang[order]
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))  # gaps[i]: from end i to i+1
    k = int(np.argmax(gaps))
    if gaps[k] < np.pi - 1e-9:  # the ends go round the origin
        return ends
    # a fan of at most a half-turn: start after its widest gap, close through the origin
    return np.concatenate([np.roll(ends, -(k + 1), axis=0), [[0.0, 0.0]]])


def fit_energy_density(s: DensitySamples, knots: tuple[int, int] = KNOTS,
                       smoothing: float = SMOOTHING, box: np.ndarray | None = None
                       ) -> EnergyDensity:  # fmt: skip
    """The least-squares bicubic spline of the samples' energies and stresses (module
    docstring) on uniform knots, ``knots`` intervals across the samples' range, over
    ``box`` ((2, 2): the strains' lower and upper corners; default the samples' range
    widened by ``MARGIN``), with its errors against them in ``fit``: per
    sweep the largest stress error relative to that sweep's largest |stress|
    (``stress_error``), the energies' largest error relative to the largest W, and the
    convexity check. The normal equations are sparse (each sample touches 16
    coefficients) and solved directly."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    for v in knots:
        if not (isinstance(v, int | np.integer) and 2 <= v <= 400):
            raise ValueError(f"knots = {tuple(knots)}: each from 2 to 400 intervals")
    if not smoothing >= 0.0:
        raise ValueError(f"smoothing = {smoothing}: must be >= 0")
    if box is None:
        box = _box(s)
    lo, hi = box
    span = s.eps.max(0) - s.eps.min(0)
    n = [max(round(k * (h - l) / max(w, 1e-12)), 2) for k, l, h, w in zip(knots, lo, hi, span,
                                                                           strict=True)]  # fmt: skip
    tx = _knots(s.eps[:, 0], n[0], lo[0], hi[0])
    ty = _knots(s.eps[:, 1], n[1], lo[1], hi[1])
    bx, by = _basis(tx, s.eps[:, 0]), _basis(ty, s.eps[:, 1])
    dbx, dby = _basis(tx, s.eps[:, 0], 1), _basis(ty, s.eps[:, 1], 1)
    nx, ny = bx.shape[1], by.shape[1]
    sig_scale = max(float(np.abs(s.stress).max()), 1e-12)
    w_scale = sig_scale * float(np.abs(s.eps).max())

    def rows(a, b):  # the design rows of Σ c_ij a_i b_j, one per sample
        return sp.csr_matrix((a[:, :, None] * b[:, None, :]).reshape(len(a), nx * ny))

    A = sp.vstack([rows(bx, by) / w_scale, rows(dbx, by) / sig_scale,
                   rows(bx, dby) / sig_scale]).tocsr()  # fmt: skip
    rhs = np.concatenate([s.W / w_scale, s.stress[:, 0] / sig_scale, s.stress[:, 1] / sig_scale])

    def diff(n, order):
        return sp.diags_array([[1.0, -1.0], [1.0, -2.0, 1.0]][order - 1], offsets=range(order + 1),
                              shape=(n - order, n))  # fmt: skip

    ix, iy = sp.eye_array(nx), sp.eye_array(ny)
    penalty = sp.vstack([sp.kron(diff(nx, 2), iy), math.sqrt(2.0) * sp.kron(diff(nx, 1), diff(ny, 1)),
                         sp.kron(ix, diff(ny, 2))]) / w_scale  # fmt: skip
    lam = smoothing * A.shape[0] / penalty.shape[0]
    coef = spsolve(sp.csc_matrix(A.T @ A + lam * (penalty.T @ penalty)), A.T @ rhs)
    out = EnergyDensity(tx, ty, coef.reshape(nx, ny), sampled_domain(s), s.point, {})
    got_w, got_s = out.W(s.eps[:, 0], s.eps[:, 1]), out.stress(s.eps[:, 0], s.eps[:, 1])
    out.fit.update({
        "knots": [int(k) for k in knots], "smoothing": smoothing, "samples": len(s.W),
        "sweeps": sorted(s.ends), "left_out": s.left_out,
        "stress_error": _stress_errors(s, got_s),
        "energy_error": float(np.abs(got_w - s.W).max() / max(float(np.abs(s.W).max()), 1e-300)),
    })  # fmt: skip
    out.fit["convexity"] = out.convexity()
    return out


def _box(s: DensitySamples) -> np.ndarray:
    """The spline's default box: the samples' range widened by ``MARGIN`` each side."""
    lo, hi = s.eps.min(0), s.eps.max(0)
    pad = MARGIN * (hi - lo) + 1e-6
    return np.stack([lo - pad, hi + pad])


def _stress_errors(s: DensitySamples, got: np.ndarray, sweeps=None) -> dict[str, float]:
    """Per sweep: the largest |fitted - sampled| stress over its steps / its largest |stress|."""
    out = {}
    for d in sweeps or s.ends:
        m = s.direction == d
        peak = max(float(np.abs(s.stress[m]).max()), 1e-12)
        out[d] = float(np.abs(got[m] - s.stress[m]).max() / peak)
    return out


def held_out_errors(s: DensitySamples, knots: tuple[int, int] = KNOTS,
                    smoothing: float = SMOOTHING) -> dict[str, float]:  # fmt: skip
    """How well the fit predicts between its rays: each ray in turn left out of the fit
    (same knots and box), its stresses predicted where it lies inside the region the other
    sweeps sampled, the error as in ``stress_error``. The uniaxial sweeps and the outermost
    rays by angle are kept (leaving them out extrapolates, not interpolates)."""
    box = _box(s)
    rays = {d: math.atan2(e[1], e[0]) for d, e in s.ends.items() if not load_path(d).uniaxial}
    outer = {min(rays, key=rays.get), max(rays, key=rays.get)} if rays else set()
    out = {}
    for d in sorted(set(rays) - outer):
        keep = s.direction != d
        rest = DensitySamples(s.eps[keep], s.W[keep], s.stress[keep], s.direction[keep],
                              {k: v for k, v in s.ends.items() if k != d}, s.point)  # fmt: skip
        f = fit_energy_density(rest, knots, smoothing, box)
        m = ~keep & f.in_domain(s.eps[:, 0], s.eps[:, 1])
        if m.any():
            got = f.stress(s.eps[m, 0], s.eps[m, 1])
            peak = max(float(np.abs(s.stress[~keep]).max()), 1e-12)
            out[d] = float(np.abs(got - s.stress[m]).max() / peak)
    return out
