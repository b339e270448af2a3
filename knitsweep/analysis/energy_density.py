"""The fabric's in-plane energy density W(ε_xx, ε_yy[, γ]) from one point's sweeps, fitted
by a smooth function a cloth simulator can evaluate (docs/energy-density.md).

Every step of a sweep is a relaxed state of the cell at periods (a_x, a_y) and skew s_x
(``paths``: the deformation gradient F = [[1 + ε_xx, γ], [0, 1 + ε_yy]] up to a rotation):
a sample of the energy per unit area of the undeformed fabric,

    W = (E - E_0) / (a_x0 a_y0)   (mJ/mm² = N/mm),
    ε_xx = a_x/a_x0 - 1,   ε_yy = a_y/a_y0 - 1,   γ = s_x/a_y0,

with its exact gradient, the sweep's stresses: σ_xx = F_x / a_y0 = ∂W/∂ε_xx,
σ_yy = F_y / a_x0 = ∂W/∂ε_yy and σ_xy = F_s / a_x0 = ∂W/∂γ (first Piola–Kirchhoff, N/mm).
A fan of rays (``jobs/energy_density_*.toml``) samples a star-shaped region around the
zero-force state; the uniaxial sweeps sample where the transverse stress is 0. Where no
sweep shears, W is a function of (ε_xx, ε_yy); with sweeps that shear (rays with a γ rate,
``shear``) of (ε_xx, ε_yy, γ).

The fit (``fit_energy_density``) is a tensor-product cubic B-spline on uniform knots,
W(ε) = Σ c_ij(k) B_i(ε_xx) B_j(ε_yy) (B_k(γ)), whose coefficients minimise the squared
misfit of the sampled energies *and* stresses (each scaled by its range) plus a small
penalty on the coefficients' second differences (a P-spline: it fixes the coefficients the
samples do not reach and damps wiggles between rays). Why this model: it is C², so its
stress and tangent are continuous, which an implicit simulator needs; its stress and
tangent are its exact derivatives (``EnergyDensity.stress``, ``tangent``; tested against
differences); it is linear in its coefficients (one sparse least-squares solve, no
iteration); it assumes no functional form, which matters because jamming puts a knee into
every stress–strain curve that polynomials in the invariants smooth away; and it is the
model HYLC (Sperl et al. 2020) fits per term, here over all the strains at once.
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
VARIABLES = ("eps_xx", "eps_yy", "gamma")
"""The strains, in order: a density of two has the first two."""
KNOTS = {2: (64, 48), 3: (32, 24, 16)}
"""Default knot intervals per variable across the samples' range (checked on the shipped
jobs: docs/energy-density.md)."""
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
POINT_KEYS = ("L_mm", "k_mN_per_mm2", "B_mN_mm2", "r_mm", "r_core_mm", "p")


@dataclass(frozen=True)
class DensitySamples:
    """One point's relaxed states as samples of W: strains (n, d) (``VARIABLES[:d]``), W
    (n,) N/mm, stresses (n, d) N/mm, the sweep (direction) of each, the end of each sweep in
    strain, and the point (its parameters, zero-force periods a_x0_mm, a_y0_mm and energy
    E0_mJ)."""

    eps: np.ndarray
    W: np.ndarray
    stress: np.ndarray
    direction: np.ndarray
    ends: dict[str, tuple[float, ...]]
    point: dict[str, Any]
    left_out: dict[str, str] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return self.eps.shape[1]


def density_samples(sweeps, stitch: str | None = None, L_mm: float | None = None
                    ) -> DensitySamples:  # fmt: skip
    """The samples of W of the one point among ``sweeps`` ((meta, record) pairs of stored
    sweeps, e.g. ``Results.energy_density_samples``'s) that ``stitch`` and ``L_mm``
    select: the converged steps of its sweeps, also those of a sweep that ended not
    knittable (its steps up to there are valid states); γ a variable if any sweep shears.
    ValueError naming the points if the selection is not one point."""

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
        raise ValueError(f"select one point (--point-stitch, --point-L): the sweeps' points are "
                         f"{listed}")  # fmt: skip
    (entries,) = by_point.values()
    shears = any(load_path(meta["direction"]).shears for meta, _ in entries)
    # every sweep starts at the point's zero-force state; one that found a lower one
    # (its rest_restarts) starts there: the lowest is the reference, the others left out;
    # a shear that relaxed its skew at rest (rest_skew) starts from its own rest, never
    # the reference (its strains are not the point's)
    e0 = [float(rec["total_energy"][0]) for _, rec in entries]
    upright = [i for i, (meta, _) in enumerate(entries) if not meta.get("rest_skew")]
    i_ref = min(upright or range(len(entries)), key=lambda i: e0[i])
    ref_meta, ref = entries[i_ref]
    a_x0, a_y0, E0 = float(ref["a_x"][0]), float(ref["a_y"][0]), e0[i_ref]
    parts, ends, left_out = [], {}, {}
    for (meta, rec), e_start in sorted(zip(entries, e0, strict=True),
                                       key=lambda me: me[0][0]["direction"]):  # fmt: skip
        d = meta["direction"]
        if meta.get("rest_skew") and upright:
            left_out[d] = (f"starts from its rest sheared by gamma0 = {meta['rest_skew']:.4g} "
                           f"({e_start - E0:+.3g} mJ)")  # fmt: skip
            continue
        if abs(e_start - E0) > 1e-12 or rec["a_x"][0] != a_x0 or rec["a_y"][0] != a_y0:
            left_out[d] = f"starts from another zero-force state ({e_start - E0:+.3g} mJ)"
            continue
        if shears and rec.get("stress_xy") is None:
            raise ValueError(f"the {d} sweep stores no shear stress (stress_xy): a file of an "
                             "earlier version; run the job again")  # fmt: skip
        ok = np.asarray(rec["converged"], dtype=bool)
        cols = [np.asarray(rec["a_x"])[ok] / a_x0 - 1.0, np.asarray(rec["a_y"])[ok] / a_y0 - 1.0]
        sig = [np.asarray(rec["stress_xx"])[ok], np.asarray(rec["stress_yy"])[ok]]
        if shears:  # the skew follows the path's shear rate: γ = rate_xy × the sweep's strain
            cols.append(load_path(d).rate_xy * np.asarray(rec["strain"])[ok])
            sig.append(np.asarray(rec["stress_xy"])[ok])
        w = (np.asarray(rec["total_energy"])[ok] - E0) / (a_x0 * a_y0)
        parts.append((np.stack(cols, 1), w, np.stack(sig, 1), np.full(ok.sum(), d, dtype=object)))
        ends[d] = tuple(float(c[-1]) for c in cols)
    if not parts:
        raise ValueError("no sweep of the point has steps to sample")
    eps, w, s, d = (np.concatenate(p) for p in zip(*parts, strict=True))
    point = {"stitch": stitch_of(ref_meta)} | {k: ref_meta[k] for k in POINT_KEYS}
    point |= {"a_x0_mm": a_x0, "a_y0_mm": a_y0, "E0_mJ": E0}
    return DensitySamples(eps, w, s, d, ends, point, left_out)


def _local(t: np.ndarray, x: np.ndarray, nu: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The cubic B-splines of knots ``t`` that do not vanish at each ``x`` (its ``nu``-th
    derivative): (first index (m,), values (m, 4)); beyond the knots, the end ones."""
    from scipy.interpolate import BSpline

    n = len(t) - DEGREE - 1
    x = np.asarray(x, dtype=float).ravel()
    start = np.clip(np.searchsorted(t, x, side="right") - DEGREE - 1, 0, n - DEGREE - 1)
    b = BSpline(t, np.eye(n), DEGREE, extrapolate=True)
    dense = (b.derivative(nu) if nu else b)(x)
    return start, np.take_along_axis(dense, start[:, None] + np.arange(DEGREE + 1), axis=1)


def _knots(lo: float, hi: float, intervals: int) -> np.ndarray:
    """Clamped uniform knots over [lo, hi]."""
    return np.concatenate([[lo] * DEGREE, np.linspace(lo, hi, intervals + 1), [hi] * DEGREE])


def _tensor(knots, eps: np.ndarray, orders) -> tuple[np.ndarray, np.ndarray]:
    """The tensor-product basis's non-zero entries at the points ``eps`` (m, d) with the
    derivative ``orders[a]`` along each axis a: (flat coefficient indices, values), each
    (m, 4^d)."""
    m, d = eps.shape
    sizes = [len(t) - DEGREE - 1 for t in knots]
    index, value = np.zeros((m, 1), dtype=np.int64), np.ones((m, 1))
    for a in range(d):
        start, vals = _local(knots[a], eps[:, a], orders[a])
        cols = start[:, None] + np.arange(DEGREE + 1)
        index = (index[:, :, None] * sizes[a] + cols[:, None, :]).reshape(m, -1)
        value = (value[:, :, None] * vals[:, None, :]).reshape(m, -1)
    return index, value


class EnergyDensity:
    """W(ε) (N/mm) as a tensor-product cubic B-spline over ``variables`` (``VARIABLES[:d]``):
    ``knots`` one knot vector each, coefficients ``coef`` (one axis each); ``domain`` the
    sweeps' ends (k, d) (in two variables the sampled region's polygon); ``point`` and
    ``fit`` its provenance and the fit's measured errors. Strains are the deformation's
    (module docstring) from the zero-force state; W is the energy per unit area of the
    undeformed fabric; ``stress`` = ∂W/∂ε and ``tangent`` = ∂²W/∂ε∂ε are the spline's exact
    derivatives."""

    def __init__(self, knots, coef, domain, point: dict, fit: dict) -> None:
        self.knots = [np.asarray(t, dtype=float) for t in knots]
        self.coef = np.asarray(coef, dtype=float)
        self.domain = np.asarray(domain, dtype=float)
        self.point, self.fit = dict(point), dict(fit)

    @property
    def dim(self) -> int:
        return len(self.knots)

    @property
    def variables(self) -> tuple[str, ...]:
        return VARIABLES[: self.dim]

    def _points(self, eps) -> tuple[np.ndarray, tuple[int, ...]]:
        e = np.asarray(eps, dtype=float)
        if e.shape[-1] != self.dim:
            raise ValueError(f"strains of shape {e.shape}: the last axis holds "
                             f"{', '.join(self.variables)}")  # fmt: skip
        return e.reshape(-1, self.dim), e.shape[:-1]

    def _d(self, eps, orders) -> np.ndarray:
        e, shape = self._points(eps)
        index, value = _tensor(self.knots, e, orders)
        return (self.coef.ravel()[index] * value).sum(1).reshape(shape)

    def W(self, *eps) -> np.ndarray:
        """Energy per unit undeformed area (N/mm = mJ/mm²) at strains given as ``d``
        arrays (ε_xx, ε_yy[, γ]) or one array (..., d)."""
        return self._d(_stacked(eps), (0,) * self.dim)

    def stress(self, *eps) -> np.ndarray:
        """∂W/∂ε (N/mm): (σ_xx, σ_yy[, σ_xy]), shape (..., d)."""
        e = _stacked(eps)
        return np.stack([self._d(e, tuple(int(a == b) for b in range(self.dim)))
                         for a in range(self.dim)], -1)  # fmt: skip

    def tangent(self, *eps, convexified: bool = False) -> np.ndarray:
        """∂²W/∂ε_i∂ε_j (N/mm), shape (..., d, d), symmetric. ``convexified``: its negative
        eigenvalues set to 0 (the nearest positive semi-definite matrix), for a simulator's
        Newton solve where the fit is not convex (``convexity``); then no longer the
        derivative of ``stress``."""
        e, d = _stacked(eps), self.dim
        K = np.empty((*np.shape(e)[:-1], d, d))
        for a in range(d):
            for b in range(a, d):
                orders = tuple((c == a) + (c == b) for c in range(d))
                K[..., a, b] = K[..., b, a] = self._d(e, orders)
        if not convexified:
            return K
        lam, vec = np.linalg.eigh(K)
        return np.einsum("...ik,...k,...jk->...ij", vec, np.maximum(lam, 0.0), vec)

    def in_domain(self, *eps) -> np.ndarray:
        """True where the strains lie in the sampled region; outside, W is the spline's
        extension, fixed by its smoothing only: not a prediction. In two variables the
        polygon ``domain``; in three, within the nearest sweeps' reach (``_within_fan``)."""
        e, shape = self._points(_stacked(eps))
        if self.dim == 2:
            return _inside(self.domain, e[:, 0], e[:, 1]).reshape(shape)
        return _within_fan(self.domain, e).reshape(shape)

    def convexity(self, n: int | None = None) -> dict[str, float]:
        """Where the fit is not convex: on a grid (n per variable; 101 in two, 25 in three)
        over the sweeps' box, the fraction of in-domain nodes whose tangent's smallest
        eigenvalue is below -``CONVEX_TOLERANCE`` × the largest found, that eigenvalue's
        minimum and the largest, and the box of those nodes (NaN if none)."""
        n = n or (101 if self.dim == 2 else 25)
        lo, hi = self.domain.min(0), self.domain.max(0)
        axes = [np.linspace(lo[a], hi[a], n) for a in range(self.dim)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, self.dim)
        grid = grid[self.in_domain(grid)]
        eig = np.linalg.eigvalsh(self.tangent(grid))
        bad = eig[:, 0] < -CONVEX_TOLERANCE * eig[:, -1].max()
        out = {"fraction": float(bad.mean()), "min_eigenvalue_N_per_mm": float(eig[:, 0].min()),
               "max_eigenvalue_N_per_mm": float(eig[:, -1].max())}  # fmt: skip
        for a, name in enumerate(self.variables):
            where = grid[bad, a]
            out[f"{name}_min"] = float(where.min()) if bad.any() else float("nan")
            out[f"{name}_max"] = float(where.max()) if bad.any() else float("nan")
        return out

    def to_dict(self) -> dict[str, Any]:
        """The file's content (docs/energy-density.md)."""
        return {"format": FORMAT, "version": VERSION,
                "model": "tensor-product cubic B-spline", "variables": list(self.variables),
                "units": {"W": "N/mm (mJ/mm^2, per undeformed area)", "strain": "1",
                          "stress": "N/mm"},
                "degree": DEGREE, "knots": [t.tolist() for t in self.knots],
                "coefficients": self.coef.tolist(), "domain": self.domain.tolist(),
                "point": self.point, "fit": self.fit}  # fmt: skip

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EnergyDensity:
        if d.get("format") != FORMAT or d.get("version") != VERSION:
            raise ValueError(f"not a {FORMAT} file of version {VERSION}: format = "
                             f"{d.get('format')!r}, version = {d.get('version')!r}")  # fmt: skip
        return cls(d["knots"], d["coefficients"], d["domain"], d["point"], d["fit"])


def _stacked(eps: tuple) -> np.ndarray:
    """One array (..., d) from the strains given as d arrays or as one."""
    if len(eps) == 1:
        return np.asarray(eps[0], dtype=float)
    return np.stack(np.broadcast_arrays(*(np.asarray(e, dtype=float) for e in eps)), -1)


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


def _within_fan(ends: np.ndarray, e: np.ndarray) -> np.ndarray:
    """In three variables: a strain lies in the sampled region if its direction is within
    the fan's resolution of a sweep's (the largest angle from any end to its nearest) and
    it reaches no farther than the nearest such sweep went (the origin counts)."""
    r_end = np.linalg.norm(ends, axis=1)
    u_end = ends / np.maximum(r_end, 1e-300)[:, None]
    near = u_end @ u_end.T
    np.fill_diagonal(near, -1.0)
    resolution = float(np.arccos(np.clip(near.max(1), -1.0, 1.0)).max())
    r = np.linalg.norm(e, axis=1)
    ang = np.arccos(np.clip((e / np.maximum(r, 1e-300)[:, None]) @ u_end.T, -1.0, 1.0))
    best = ang.argmin(1)
    ok = ang[np.arange(len(e)), best] <= resolution + 1e-12
    return (r == 0.0) | (ok & (r <= r_end[best] * (1.0 + 1e-12)))


def sampled_domain(s: DensitySamples) -> np.ndarray:
    """The sampled region: in two variables the polygon through the origin and the sweeps'
    ends, by angle (star-shaped about the zero-force state, which every ray starts from);
    in three the ends themselves (``_within_fan``)."""
    ends = np.array(list(s.ends.values()))
    if s.dim == 3:
        return ends
    ang = np.arctan2(ends[:, 1], ends[:, 0])
    order = np.argsort(ang)
    ends, ang = ends[order], ang[order]
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))  # gaps[i]: from end i to i+1
    k = int(np.argmax(gaps))
    if gaps[k] < np.pi - 1e-9:  # the ends go round the origin
        return ends
    # a fan of at most a half-turn: start after its widest gap, close through the origin
    return np.concatenate([np.roll(ends, -(k + 1), axis=0), [[0.0, 0.0]]])


def fit_energy_density(s: DensitySamples, knots: tuple[int, ...] | None = None,
                       smoothing: float = SMOOTHING, box: np.ndarray | None = None,
                       checks: bool = True) -> EnergyDensity:  # fmt: skip
    """The least-squares tensor-product spline of the samples' energies and stresses
    (module docstring) on uniform knots, ``knots`` intervals per variable across the
    samples' range (default ``KNOTS``), over ``box`` ((2, d): the strains' lower and upper
    corners; default the samples' range widened by ``MARGIN``), with its errors against
    them in ``fit``: per sweep the largest stress error relative to that sweep's largest
    |stress| (``stress_error``), the energies' largest error relative to the largest W,
    and (``checks``) the convexity check and, with a shear, the mirror check
    (``mirror_asymmetry``). The
    normal equations are sparse (each sample touches 4^d coefficients) and solved
    directly."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    d = s.dim
    knots = tuple(knots or KNOTS[d])
    if len(knots) != d or not all(isinstance(v, int | np.integer) and 2 <= v <= 400
                                  for v in knots):  # fmt: skip
        raise ValueError(f"knots = {knots}: {d} numbers, each from 2 to 400 intervals")
    if not smoothing >= 0.0:
        raise ValueError(f"smoothing = {smoothing}: must be >= 0")
    lo, hi = _box(s) if box is None else box
    span = np.maximum(s.eps.max(0) - s.eps.min(0), 1e-12)
    tk = [_knots(lo[a], hi[a], max(round(knots[a] * (hi[a] - lo[a]) / span[a]), 2))
          for a in range(d)]  # fmt: skip
    sizes = [len(t) - DEGREE - 1 for t in tk]
    n_coef = int(np.prod(sizes))
    sig_scale = max(float(np.abs(s.stress).max()), 1e-12)
    w_scale = sig_scale * float(np.abs(s.eps).max())

    def rows(orders, scale):
        index, value = _tensor(tk, s.eps, orders)
        r = np.repeat(np.arange(len(s.W)), index.shape[1])
        return sp.csr_matrix((value.ravel() / scale, (r, index.ravel())), (len(s.W), n_coef))

    A = sp.vstack(
        [rows((0,) * d, w_scale)]
        + [rows(tuple(int(a == b) for b in range(d)), sig_scale) for a in range(d)]
    )
    rhs = np.concatenate([s.W / w_scale] + [s.stress[:, a] / sig_scale for a in range(d)])

    def diff(n, order):
        return sp.diags_array([[1.0, -1.0], [1.0, -2.0, 1.0]][order - 1], offsets=range(order + 1),
                              shape=(n - order, n))  # fmt: skip

    def along(ops):  # the Kronecker product of one operator per axis (identity elsewhere)
        out = sp.eye_array(1)
        for a in range(d):
            out = sp.kron(out, ops.get(a, sp.eye_array(sizes[a])))
        return out

    blocks = [along({a: diff(sizes[a], 2)}) for a in range(d)]
    blocks += [math.sqrt(2.0) * along({a: diff(sizes[a], 1), b: diff(sizes[b], 1)})
               for a in range(d) for b in range(a + 1, d)]  # fmt: skip
    penalty = sp.vstack(blocks) / w_scale
    lam = smoothing * A.shape[0] / penalty.shape[0]
    coef = spsolve(sp.csc_matrix(A.T @ A + lam * (penalty.T @ penalty)), A.T @ rhs)
    out = EnergyDensity(tk, coef.reshape(sizes), sampled_domain(s), s.point, {})
    got_w, got_s = out.W(s.eps), out.stress(s.eps)
    out.fit.update({
        "knots": [int(k) for k in knots], "smoothing": smoothing, "samples": len(s.W),
        "sweeps": sorted(s.ends), "left_out": s.left_out,
        "stress_error": _stress_errors(s, got_s),
        "energy_error": float(np.abs(got_w - s.W).max() / max(float(np.abs(s.W).max()), 1e-300)),
    })  # fmt: skip
    if checks:
        out.fit["convexity"] = out.convexity()
        if d == 3:
            out.fit["mirror_asymmetry"] = mirror_asymmetry(out, s)
    return out


def mirror_asymmetry(f: EnergyDensity, s: DensitySamples) -> dict[str, float]:
    """How far the fit is from the left–right mirror's W(ε_xx, ε_yy, γ) = W(ε_xx, ε_yy, -γ),
    at every sample whose mirror image also lies in the sampled region: the largest
    |W(γ) - W(-γ)| over the largest W and |σ_xy(γ) + σ_xy(-γ)| over the largest |σ_xy|, and
    how many samples were compared."""
    flip = s.eps * np.array([1.0, 1.0, -1.0])
    both = f.in_domain(flip) & (s.eps[:, 2] != 0.0)
    if not both.any():
        return {"samples": 0, "energy": float("nan"), "shear_stress": float("nan")}
    e, m = s.eps[both], flip[both]
    dw = np.abs(f.W(e) - f.W(m)).max() / max(float(np.abs(s.W).max()), 1e-300)
    ds = np.abs(f.stress(e)[:, 2] + f.stress(m)[:, 2]).max() / max(
        float(np.abs(s.stress[:, 2]).max()), 1e-300
    )
    return {"samples": int(both.sum()), "energy": float(dw), "shear_stress": float(ds)}


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


HELD_OUT_3D = 12
"""In three variables (a fit of tens of seconds), this many rays are left out in turn,
evenly among them by name."""


def held_out_errors(s: DensitySamples, knots: tuple[int, ...] | None = None,
                    smoothing: float = SMOOTHING) -> dict[str, float]:  # fmt: skip
    """How well the fit predicts between its rays: each ray in turn left out of the fit
    (same knots and box), its stresses predicted where it lies inside the region the other
    sweeps sampled, the error as in ``stress_error``. The uniaxial sweeps and, in two
    variables, the outermost rays by angle are kept (leaving them out extrapolates, not
    interpolates); in three, ``HELD_OUT_3D`` rays are left out."""
    box = _box(s)
    rays = {d: math.atan2(e[1], e[0]) for d, e in s.ends.items() if not load_path(d).uniaxial}
    outer = {min(rays, key=rays.get), max(rays, key=rays.get)} if rays and s.dim == 2 else set()
    chosen = sorted(set(rays) - outer)
    if s.dim == 3 and len(chosen) > HELD_OUT_3D:
        chosen = [chosen[i] for i in np.linspace(0, len(chosen) - 1, HELD_OUT_3D).astype(int)]
    out = {}
    for d in chosen:
        keep = s.direction != d
        rest = DensitySamples(s.eps[keep], s.W[keep], s.stress[keep], s.direction[keep],
                              {k: v for k, v in s.ends.items() if k != d}, s.point)  # fmt: skip
        f = fit_energy_density(rest, knots, smoothing, box, checks=False)
        m = ~keep & f.in_domain(s.eps)
        if m.any():
            got = f.stress(s.eps[m])
            peak = max(float(np.abs(s.stress[~keep]).max()), 1e-12)
            out[d] = float(np.abs(got - s.stress[m]).max() / peak)
    return out
