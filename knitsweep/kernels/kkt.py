"""The trust-region SQP step of ``newton``, compiled (numba on plain arrays).

One step of the Newton–KKT iteration on a few dozen unknowns costs a few dozen small dense
operations; run from numpy they took ~5x the energy evaluation they serve, compiled
they take a fraction of it. Same algorithm as documented in ``newton``: a normal step
onto the linearised length constraint (at most ``normal_share`` of the radius), a
tangential step in the constraint's null space (Householder basis) minimising the
reduced quadratic model within the rest of the radius: Cholesky when the reduced
Hessian is positive definite, Moré–Sorensen shifts when the Newton step is too long,
eigenvalues when it is indefinite.

Two implementations of that one step: ``kkt_step`` here (dense: the null-space basis
formed, hand-written Cholesky, the full eigendecomposition) serves stockinette's 29–30
unknowns, whose results are its bits; ``kkt_rows.kkt_step_rows`` serves the free yarn's
86–88 (``ROWS_FROM``). Both run one Moré–Sorensen loop (``more_sorensen``), on the
hand-written factor or on LAPACK's (``_factor_shifted_rows``, here for that reason).
"""

from __future__ import annotations

import math

import numba.np.linalg  # noqa: F401  (registers numba's LAPACK helpers)
import numpy as np
from numba import njit, types
from numba.extending import overload


@njit(cache=True)
def _cholesky(h, r):
    """Upper Cholesky factor r of h (m, m) in place of r; False if h is not positive
    definite."""
    m = h.shape[0]
    for j in range(m):
        s = h[j, j]
        for k in range(j):
            s -= r[k, j] * r[k, j]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        r[j, j] = d
        for i in range(j + 1, m):
            t = h[j, i]
            for k in range(j):
                t -= r[k, j] * r[k, i]
            r[j, i] = t / d
    return True


@njit(cache=True)
def _solve_lower(r, b, out):
    """out = R⁻ᵀ b for the upper factor R (forward substitution)."""
    m = r.shape[0]
    for i in range(m):
        s = b[i]
        for k in range(i):
            s -= r[k, i] * out[k]
        out[i] = s / r[i, i]


@njit(cache=True)
def _solve_upper(r, b, out):
    """out = R⁻¹ b (back substitution)."""
    m = r.shape[0]
    for i in range(m - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, m):
            s -= r[i, k] * out[k]
        out[i] = s / r[i, i]


@njit(cache=True)
def _factor_shifted(hz, nu, r):
    """The upper Cholesky factor r of hz + νI (hand-written, ``_cholesky``); False if
    hz + νI is not positive definite."""
    hs = hz.copy()
    for i in range(hz.shape[0]):
        hs[i, i] += nu
    return _cholesky(hs, r)


_POTRF = types.ExternalFunction(
    "numba_xxpotrf", types.intc(types.char, types.char, types.intp, types.voidptr, types.intp)
)
"""LAPACK's Cholesky factorisation (xPOTRF) as numba's own ``np.linalg.cholesky`` calls it:
(kind, uplo, n, a, lda) -> info, > 0 where the matrix is not positive definite."""


@njit(cache=True)
def _forward(low, b, out):
    """out = L⁻¹ b (forward substitution, L lower)."""
    m = low.shape[0]
    for i in range(m):
        li = low[i]
        s = b[i]
        for k in range(i):
            s -= li[k] * out[k]
        out[i] = s / li[i]


@njit(cache=True)
def _backward(low, b, out):
    """out = L⁻ᵀ b (back substitution, L lower), by columns of Lᵀ: rows of L."""
    m = low.shape[0]
    for i in range(m):
        out[i] = b[i]
    for i in range(m - 1, -1, -1):
        li = low[i]
        out[i] /= li[i]
        oi = out[i]
        for k in range(i):
            out[k] -= li[k] * oi


@njit(cache=True)
def _factor_shifted_rows(hz, nu, low):
    """The lower Cholesky factor of hz + νI in the lower triangle of ``low`` (LAPACK's);
    False if hz + νI is not positive definite."""
    m = hz.shape[0]
    for i in range(m):
        for j in range(m):
            low[i, j] = hz[i, j]
        low[i, i] += nu
    # LAPACK reads the C array as its transpose: its upper factor U (UᵀU = hz + νI) is
    # the lower factor L = Uᵀ here, in the lower triangle
    return _POTRF(ord("d"), ord("U"), m, low.ctypes, m) == 0


def _by_factor(lapack_kernel, dense_kernel):
    """f(lapack, a, b, c) = ``lapack_kernel(a, b, c)`` if ``lapack`` else ``dense_kernel(a, b,
    c)``: the hand-written upper factor's kernel or LAPACK's lower factor's. Compiled, a
    constant ``lapack`` picks one kernel when numba types the call (an overload on its
    literal type), so that a step compiles its own factorisation alone; a value known at
    run time alone (a call from Python) compiles both behind a branch."""

    def by_factor(lapack, a, b, c):
        return (lapack_kernel if lapack else dense_kernel)(a, b, c)

    @overload(by_factor, prefer_literal=True, inline="always")
    def _typed(lapack, a, b, c):
        if isinstance(lapack, types.BooleanLiteral):
            kernel = lapack_kernel if lapack.literal_value else dense_kernel
            return lambda lapack, a, b, c: kernel(a, b, c)
        return lambda lapack, a, b, c: (
            lapack_kernel(a, b, c) if lapack else dense_kernel(a, b, c))  # fmt: skip

    return by_factor


_factor = _by_factor(_factor_shifted_rows, _factor_shifted)
"""(lapack, hz, ν, factor) -> whether hz + νI is positive definite, its factor written."""
_solve_l = _by_factor(_forward, _solve_lower)
"""(lapack, factor, b, out): out = L⁻¹ b, L the lower factor (the upper one's Rᵀ)."""
_solve_lt = _by_factor(_backward, _solve_upper)
"""(lapack, factor, b, out): out = L⁻ᵀ b (the upper one's R⁻¹ b)."""


@njit(cache=True)
def _shifted(hz, rz, nu, lapack, factor, q, u):
    """u = −(hz + νI)⁻¹ rz by the Cholesky factor ``factor`` of hz + νI (q = L⁻¹ rz):
    the hand-written upper one, or LAPACK's lower one if ``lapack`` (``_by_factor``);
    False if hz + νI is not positive definite."""
    if not _factor(lapack, hz, nu, factor):
        return False
    _solve_l(lapack, factor, rz, q)
    _solve_lt(lapack, factor, q, u)
    for i in range(hz.shape[0]):
        u[i] = -u[i]
    return True


@njit(cache=True)
def more_sorensen(hz, rz, radius, lapack, factor, q, u, w):
    """The tangential step of ``tangential_step`` and ``kkt_rows.tangential_step_rows`` where
    hz is positive definite: u = −hz⁻¹ rz, or the shifted −(hz + νI)⁻¹ rz with ‖u‖ within
    [Δ, 1.01 Δ] (scaled back onto Δ) by Moré–Sorensen's Newton iteration on ν, written into
    u; factor (m, m), q, w (m,) scratch, the Cholesky factor of ``_shifted``. Returns (the
    Newton decrement ½ rzᵀ hz⁻¹ rz, whether u is the step); not the step where hz is not
    positive definite or the iteration fails (then the caller's eigen path).

    One loop for both steps, the factorisation chosen by the constant ``lapack`` when
    numba types the call (``_by_factor``), so that each step compiles its own
    factorisation alone: numba caches no kernel that takes a compiled function as an
    argument or closes over one (a new cache entry in every process, numba 0.68), and a
    branch at run time compiled the other factorisation into every step (stockinette's
    solver kernels: 5.3 -> 6.3 s cold, ``benchmarks/bench_compile.py --group solver``).
    What one loop costs, against two (CPU s of the solver group's cold compile, medians of
    3 alternated runs at load ~5, docs/performance.md): stockinette 6.1 -> 6.7, garter
    12.6 -> 14.2, of a cold ``run`` compile of ~29 s and ~53 s."""
    if not _shifted(hz, rz, 0.0, lapack, factor, q, u):
        return 0.0, False
    decrement = 0.5 * np.dot(q, q)
    norm = math.sqrt(np.dot(u, u))
    if norm <= radius:
        return decrement, True
    m = hz.shape[0]
    nu = 0.0
    for _ in range(20):  # Moré–Sorensen on ν: ‖u(ν)‖ = radius
        _solve_l(lapack, factor, u, w)  # L w = u
        nu += (norm / math.sqrt(np.dot(w, w))) ** 2 * (norm - radius) / radius
        if not _shifted(hz, rz, nu, lapack, factor, q, u):
            break
        norm = math.sqrt(np.dot(u, u))
        if norm <= 1.01 * radius:
            if norm > radius:
                for i in range(m):
                    u[i] *= radius / norm
            return decrement, True
    return decrement, False


@njit(cache=True)
def tangential_step(hz, rz, radius, flat_mode, u, negative):
    """u = argmin rzᵀu + ½ uᵀ hz u over ‖u‖ <= radius (written into u); returns the
    Newton decrement ½ rzᵀ hz⁻¹ rz (flat modes floored) and whether hz has a negative
    mode, whose direction is then written into ``negative``."""
    m = hz.shape[0]
    decrement, done = more_sorensen(hz, rz, radius, False, np.zeros((m, m)), np.empty(m), u,
                                    np.empty(m))  # fmt: skip
    if done:
        return decrement, False
    return _eigen_step(hz, rz, radius, flat_mode, u, negative)


@njit(cache=True)
def _gather(b_full, free, held, g, a):
    """The entries a step moves: ``cols`` (m,), the positions in ``free`` of the entries
    not ``held``, and the Hessian (m, m), ∇E and ∇ℓ (m,) over them."""
    n = free.size
    cols = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if not held[i]:
            cols[m] = i
            m += 1
    cols = cols[:m]
    bf = np.empty((m, m))
    gf = np.empty(m)
    af = np.empty(m)
    for i in range(m):
        gf[i] = g[cols[i]]
        af[i] = a[cols[i]]
        fi = free[cols[i]]
        for j in range(m):
            bf[i, j] = b_full[fi, free[cols[j]]]
    return cols, bf, gf, af


@njit(cache=True)
def kkt_step(b_full, free, held, g, a, c, radius, normal_share, flat_mode, p, kappa, negative):
    """The trust-region SQP step over the free entries with the ``held`` bounds fixed.

    b_full (n_state, n_state): the Lagrangian's Hessian; free (n,): the free state entries; held
    (n,) bool; g, a (n,): ∇E and ∇ℓ over them; c = ℓ − L. Writes the step p (n,), the
    multipliers of the held bounds kappa = (∇E + B p − λ∇ℓ) (n,) and, if the reduced
    Hessian has a negative mode, its direction (n,) into ``negative``. Returns
    (λ, decrement, has a negative mode).
    """
    n = free.size
    cols, bf, gf, af = _gather(b_full, free, held, g, a)
    m = cols.size
    aa = np.dot(af, af)
    pn = (-c / aa) * af
    nn = math.sqrt(np.dot(pn, pn))
    if nn > normal_share * radius:
        pn *= normal_share * radius / nn
        nn = normal_share * radius
    # Householder: the last m-1 columns of I − 2vvᵀ/vᵀv, with v = af + sign ‖af‖ e0
    vh = af.copy()
    vh[0] += math.copysign(math.sqrt(aa), af[0] if af[0] != 0.0 else 1.0)
    beta = 2.0 / np.dot(vh, vh)
    zb = np.empty((m, m - 1))
    for i in range(m):
        for j in range(m - 1):
            zb[i, j] = (1.0 if i == j + 1 else 0.0) - beta * vh[i] * vh[j + 1]
    bz = bf @ zb
    hz = zb.T @ bz
    rz = zb.T @ (gf + bf @ pn)
    u = np.empty(m - 1)
    neg_u = np.zeros(m - 1)
    decrement, has_negative = tangential_step(
        hz, rz, math.sqrt(max(radius * radius - nn * nn, 0.0)), flat_mode, u, neg_u
    )
    pf = pn + zb @ u
    bp = bf @ pf
    lam = np.dot(af, gf + bp) / aa
    p[:] = 0.0
    negative[:] = 0.0
    for i in range(m):
        p[cols[i]] = pf[i]
    if has_negative:
        nf = zb @ neg_u
        for i in range(m):
            negative[cols[i]] = nf[i]
    for i in range(n):
        s = g[i] - lam * a[i]
        for j in range(m):
            s += b_full[free[i], free[cols[j]]] * pf[j]
        kappa[i] = s
    return lam, decrement, has_negative


@njit(cache=True)
def flat_threshold(w, flat_mode):
    """(max |w|, the flat threshold flat_mode · max |w|) of eigenvalues ``w``; a NaN
    eigenvalue makes both NaN (np.max(np.abs(w)) as a plain loop: the same operations in
    the same order)."""
    wmax = abs(w[0])
    for i in range(1, w.size):
        wi = abs(w[i])
        wmax = wi if wi > wmax or wi != wi else wmax
    return wmax, flat_mode * max(wmax, 1e-300)


@njit(cache=True)
def _eigen_step(hz, rz, radius, flat_mode, u, negative):
    """``tangential_step``'s branch for an indefinite (or singular) hz, by its
    eigendecomposition (also ``kkt_step_rows``'s fallback)."""
    m = hz.shape[0]
    w, v = np.linalg.eigh(hz)
    b = v.T @ rz
    flat = flat_threshold(w, flat_mode)[1]
    # np.sum(b * b / np.maximum(w, flat)) as a plain loop (the same operations in the
    # same order; numpy's reductions compile to far more)
    total = 0.0
    for i in range(m):
        wi = w[i]
        total += b[i] * b[i] / (wi if wi > flat or wi != wi else flat)
    decrement = 0.5 * total
    lo = max(0.0, -w[0]) + flat
    y = -b / (w + lo)
    norm = math.sqrt(np.dot(y, y))
    if norm <= radius:
        # the hard case: even the least shift stays inside; reach the boundary along
        # the lowest mode, downhill
        y[0] += math.sqrt(max(radius * radius - norm * norm, 0.0)) * (1.0 if b[0] <= 0 else -1.0)
    else:
        nu = lo
        for _ in range(40):  # Newton on 1/‖y(ν)‖ − 1/Δ, monotone from the left
            d = w + nu
            y = -b / d
            norm = math.sqrt(np.dot(y, y))
            if norm <= 1.01 * radius:
                break
            nu += (norm / radius - 1.0) * norm * norm / np.sum(b * b / d**3)
    vy = v @ y
    for i in range(m):  # element by element: no slice assignment of an array (its
        u[i] = vy[i]  # shape-mismatch error path costs ~1.5 s of compile time)
    is_negative = w[0] < -flat
    if is_negative:
        for i in range(m):
            negative[i] = v[i, 0]
    return decrement, is_negative


@njit(cache=True)
def sr1_update(h, s, y, skip):
    """h += vvᵀ/(vᵀs), v = y − h s (symmetric rank one), in place; skipped when
    |vᵀs| <= skip ‖v‖ ‖s‖. Returns whether it was applied."""
    n = s.size
    v = y - h @ s
    d = np.dot(v, s)
    if not abs(d) > skip * math.sqrt(np.dot(v, v) * np.dot(s, s)):
        return False
    for i in range(n):
        vi = v[i] / d
        for j in range(n):
            h[i, j] += vi * v[j]
    return True


ROWS_FROM = 60
"""From this many free entries (the free yarn's patterns: 86–88) the relaxation's step is
``kkt_step_rows`` (O(m²) outside LAPACK's factorisations, equal to the dense step to
round-off); below (stockinette: 29–30) the dense ``kkt_step``, whose bits its results
are (``relax.newton``)."""
