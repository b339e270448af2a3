"""The trust-region SQP step of ``newton`` for many unknowns (the free yarn's 86–88: the
patterns, docs/model.md §11), compiled: ``kkt.kkt_step``'s step, equal to round-off.

There the dense step's O(m³) products and its eigendecomposition took half of a pattern's
time. Here the reflection is applied implicitly (O(m²)), the Cholesky factor is LAPACK's,
and an indefinite reduced Hessian goes through its tridiagonal form (eigenvalues without
vectors, inverse iteration for the few modes at or below the flat threshold, O(m) shifted
solves for the rest), the full eigendecomposition (``kkt._eigen_step``) the fallback. In
exact arithmetic both steps compute the same step, multiplier, decrement and negative mode
(tested to 1e-10 on the patterns' Hessians); in floating point they differ by round-off.
"""

from __future__ import annotations

import math

import numba.np.linalg  # noqa: F401  (registers numba's LAPACK helpers)
import numpy as np
from numba import njit, types

from .kkt import (
    ROWS_FROM,
    _eigen_step,
    _gather,
    flat_threshold,
    kkt_step,
    more_sorensen,
    sr1_update,
)


def _lapack(name: str, n_args: int):
    """SciPy's LAPACK routine ``name`` (Fortran calling convention: every argument a
    pointer, integers 32-bit) as a function numba can call and cache: its address is
    registered under a name of ours, which the compiled code links by."""
    import llvmlite.binding as llvm
    from numba.extending import get_cython_function_address

    symbol = f"knitsweep_lapack_{name}"
    llvm.add_symbol(symbol, get_cython_function_address("scipy.linalg.cython_lapack", name))
    return types.ExternalFunction(symbol, types.void(*([types.voidptr] * n_args)))


_DSYTRD = _lapack("dsytrd", 10)  # uplo, n, a, lda, d, e, tau, work, lwork, info
_DSTERF = _lapack("dsterf", 4)  # n, d, e, info
_DSTEIN = _lapack("dstein", 13)  # n, d, e, m, w, iblock, isplit, z, ldz, work, iwork, ifail, info
_DGTSV = _lapack("dgtsv", 8)  # n, nrhs, dl, d, du, b, ldb, info


@njit(cache=True)
def _apply_q(a, tau, x, transpose):
    """x = Q x, or Qᵀ x if ``transpose``, in place: Q = H_0 H_1 … H_{k−2} the orthogonal
    factor of DSYTRD's A = Q T Qᵀ (uplo 'L' as LAPACK sees the array), H_i = I − τ_i v vᵀ
    with v = (0 … 0, 1, a[i, i+2:]) from position i + 1 (row i of the C array)."""
    k = a.shape[0]
    for t in range(k - 1):
        i = t if transpose else k - 2 - t
        ai = a[i]
        s = x[i + 1]
        for j in range(i + 2, k):
            s += ai[j] * x[j]
        s *= tau[i]
        x[i + 1] -= s
        for j in range(i + 2, k):
            x[j] -= s * ai[j]


@njit(cache=True)
def _shifted_solve(d, e, nu, r, out, piv):
    """out = (T + νI)⁻¹ r for the tridiagonal T (diagonal d, off-diagonal e) by its LDLᵀ
    factorisation (``piv`` scratch: D); False if T + νI is not positive definite."""
    k = d.size
    dj = d[0] + nu
    if not dj > 0.0:
        return False
    piv[0] = dj
    out[0] = r[0]
    for j in range(1, k):  # L y = r, with l_j = e_{j-1} / D_{j-1}
        lj = e[j - 1] / piv[j - 1]
        dj = d[j] + nu - lj * e[j - 1]
        if not dj > 0.0:
            return False
        piv[j] = dj
        out[j] = r[j] - lj * out[j - 1]
    out[k - 1] /= piv[k - 1]
    for j in range(k - 2, -1, -1):  # D Lᵀ x = y
        out[j] = out[j] / piv[j] - (e[j] / piv[j]) * out[j + 1]
    return True


@njit(cache=True)
def _deflate(y, s, n_low):
    """y minus its components along the first ``n_low`` rows of s (orthonormal)."""
    for i in range(n_low):
        c = np.dot(s[i], y)
        for j in range(y.size):
            y[j] -= c * s[i, j]


@njit(cache=True)
def _shifted_norm(dg, e, nu, r_high, y_high, piv, s, b_low, wl):
    """‖y(ν)‖ of the shifted step: y_high = (T + νI)⁻¹ r_high with the low modes ``s``
    deflated (written into y_high), the low modes' share b/(w + ν) explicitly; −1.0 if
    the tridiagonal solve fails."""
    if not _shifted_solve(dg, e, nu, r_high, y_high, piv):
        return -1.0
    n_low = wl.size
    _deflate(y_high, s, n_low)
    sq = 0.0
    for i in range(n_low):
        yi = b_low[i] / (wl[i] + nu)
        sq += yi * yi
    return math.sqrt(sq + np.dot(y_high, y_high))


@njit(cache=True)
def _tridiagonal_step(hz, rz, radius, flat_mode, u, negative):
    """``_eigen_step`` (the step, the floored decrement, the negative mode) without the
    full eigendecomposition: hz = Q T Qᵀ (LAPACK's tridiagonalisation, DSYTRD), T's
    eigenvalues without vectors (DSTERF, O(m²)), the eigenvectors of the modes at or below
    the flat threshold alone by inverse iteration (DSTEIN), and every other mode's share
    through solves with T + νI (O(m) each): y(ν) = −(T + νI)⁻¹ Qᵀrz, the same quantities
    as the eigendecomposition's in exact arithmetic. Returns (decrement, has a negative
    mode, ok); not ok where LAPACK fails, T splits or no mode is low (the caller then
    takes the eigendecomposition)."""
    k = hz.shape[0]
    if k < 2:
        return 0.0, False, False
    a = hz.copy()
    dg = np.empty(k)
    e = np.empty(k - 1)
    tau = np.empty(k - 1)
    work = np.empty(64 * k)
    iwork = np.empty(k, dtype=np.int32)
    ints = np.zeros(6, dtype=np.int32)
    chars = np.array([ord("L")], dtype=np.uint8)
    ints[0] = k
    ints[2] = work.size
    _DSYTRD(chars.ctypes, ints[0:].ctypes, a.ctypes, ints[0:].ctypes, dg.ctypes, e.ctypes,
            tau.ctypes, work.ctypes, ints[2:].ctypes, ints[3:].ctypes)  # fmt: skip
    if ints[3] != 0:
        return 0.0, False, False
    for i in range(k):
        if not math.isfinite(dg[i]):
            return 0.0, False, False
    # T must not split (dstein then needs no blocks): DSTEBZ's test, ULP = 2⁻⁵²
    for j in range(1, k):
        if abs(dg[j] * dg[j - 1]) * 4.930380657631324e-32 + 2.2250738585072014e-308 > e[j - 1] ** 2:
            return 0.0, False, False
    w = dg.copy()
    ew = e.copy()
    ints[0] = k
    ints[3] = 0
    _DSTERF(ints[0:].ctypes, w.ctypes, ew.ctypes, ints[3:].ctypes)  # all eigenvalues, ascending
    if ints[3] != 0:
        return 0.0, False, False
    w0 = w[0]
    wmax, flat = flat_threshold(w, flat_mode)
    n_low = 0
    while n_low < k and not w[n_low] > flat:
        n_low += 1
    if n_low < 1 or n_low == k or not math.isfinite(wmax):
        return 0.0, False, False
    wl = w[:n_low].copy()
    iblock = np.ones(n_low, dtype=np.int32)
    isplit = np.full(1, k, dtype=np.int32)
    s = np.zeros((n_low, k))
    ifail = np.empty(n_low, dtype=np.int32)
    ints[0] = k
    ints[1] = n_low
    ints[3] = 0
    _DSTEIN(ints[0:].ctypes, dg.ctypes, e.ctypes, ints[1:].ctypes, wl.ctypes, iblock.ctypes,
            isplit.ctypes, s.ctypes, ints[0:].ctypes, work.ctypes, iwork.ctypes, ifail.ctypes,
            ints[3:].ctypes)  # fmt: skip
    if ints[3] != 0:
        return 0.0, False, False
    lowest = 0  # wl ascends
    rt = rz.copy()
    _apply_q(a, tau, rt, True)
    b_low = np.empty(n_low)
    for i in range(n_low):
        b_low[i] = np.dot(s[i], rt)
    r_high = rt.copy()
    _deflate(r_high, s, n_low)
    # the decrement: the low modes floored to flat, the others Σ b²/w = r_highᵀ T⁻¹ r_high
    # (T indefinite: LAPACK's tridiagonal solve with partial pivoting, DGTSV)
    x = r_high.copy()
    lower = e.copy()
    diag = dg.copy()
    upper = e.copy()
    ints[0] = k
    ints[1] = 1
    ints[3] = 0
    _DGTSV(ints[0:].ctypes, ints[1:].ctypes, lower.ctypes, diag.ctypes, upper.ctypes, x.ctypes,
           ints[0:].ctypes, ints[3:].ctypes)  # fmt: skip
    if ints[3] != 0:
        return 0.0, False, False
    _deflate(x, s, n_low)
    total = 0.0
    for i in range(n_low):
        total += b_low[i] * b_low[i] / flat
    decrement = 0.5 * (total + np.dot(r_high, x))
    lo = max(0.0, -w0) + flat
    y_high = np.empty(k)  # (T + νI)⁻¹ r_high, the other modes' share of −y
    z = np.empty(k)
    piv = np.empty(k)

    nu = lo
    norm = _shifted_norm(dg, e, nu, r_high, y_high, piv, s, b_low, wl)
    if norm < 0.0:
        return 0.0, False, False
    hard = norm <= radius
    if not hard:
        for _ in range(40):  # Newton on 1/‖y(ν)‖ − 1/Δ, monotone from the left
            if norm <= 1.01 * radius:
                break
            # Σ b²/(w + ν)³: the low modes explicitly, the others y_highᵀ (T + νI)⁻¹ y_high
            cubes = 0.0
            for i in range(n_low):
                di = wl[i] + nu
                cubes += b_low[i] * b_low[i] / (di * di * di)
            if not _shifted_solve(dg, e, nu, y_high, z, piv):
                return 0.0, False, False
            _deflate(z, s, n_low)
            cubes += np.dot(y_high, z)
            nu += (norm / radius - 1.0) * norm * norm / cubes
            norm = _shifted_norm(dg, e, nu, r_high, y_high, piv, s, b_low, wl)
            if norm < 0.0:
                return 0.0, False, False
    y = -y_high
    for i in range(n_low):
        c = -b_low[i] / (wl[i] + nu)
        for j in range(k):
            y[j] += c * s[i, j]
    if hard:
        # even the least shift stays inside: reach the boundary along the lowest mode,
        # downhill
        t = math.sqrt(max(radius * radius - norm * norm, 0.0))
        t *= 1.0 if b_low[lowest] <= 0 else -1.0
        for j in range(k):
            y[j] += t * s[lowest, j]
    _apply_q(a, tau, y, False)
    is_negative = w0 < -flat
    v0 = s[lowest].copy()
    if is_negative:
        _apply_q(a, tau, v0, False)
    for i in range(k):
        u[i] = y[i]
    if is_negative:
        for i in range(k):
            negative[i] = v0[i]
    return decrement, is_negative, True


@njit(cache=True)
def tangential_step_rows(hz, rz, radius, flat_mode, u, negative):
    """``tangential_step`` with LAPACK's Cholesky factorisation (row-major lower factor,
    the same ``kkt.more_sorensen`` loop) and, where hz is indefinite, the tridiagonal
    form before the full eigendecomposition: the same step, equal to round-off."""
    m = hz.shape[0]
    decrement, done = more_sorensen(hz, rz, radius, True, np.empty((m, m)), np.empty(m), u,
                                    np.empty(m))  # fmt: skip
    if done:
        return decrement, False
    decrement, is_negative, ok = _tridiagonal_step(hz, rz, radius, flat_mode, u, negative)
    if ok:
        return decrement, is_negative
    return _eigen_step(hz, rz, radius, flat_mode, u, negative)


@njit(cache=True)
def _reflect(vh, beta, x, out):
    """out = (I − β vh vhᵀ) x: the Householder reflection, O(m)."""
    m = vh.size
    t = 0.0
    for i in range(m):
        t += vh[i] * x[i]
    t *= beta
    for i in range(m):
        out[i] = x[i] - t * vh[i]


@njit(cache=True)
def kkt_step_rows(b_full, free, held, g, a, c, radius, normal_share, flat_mode, p, kappa,
                  negative):  # fmt: skip
    """``kkt_step`` for many unknowns (the free yarn's 87–88): the same step, equal to
    round-off, in O(m²) operations outside the factorisation. The reduced Hessian
    ZᵀBZ with Z = the last m − 1 columns of the reflection H = I − β v vᵀ is (HBH)
    without its first row and column, HBH = B − β(v wᵀ + w vᵀ) + β²(vᵀw) v vᵀ with
    w = B v, instead of two dense products with Z; Z u = H (0, u) likewise."""
    n = free.size
    cols, bf, gf, af = _gather(b_full, free, held, g, a)
    m = cols.size
    aa = 0.0
    for i in range(m):
        aa += af[i] * af[i]
    pn = (-c / aa) * af
    nn = math.sqrt(np.dot(pn, pn))
    if nn > normal_share * radius:
        pn *= normal_share * radius / nn
        nn = normal_share * radius
    vh = af.copy()
    vh[0] += math.copysign(math.sqrt(aa), af[0] if af[0] != 0.0 else 1.0)
    vv = 0.0
    for i in range(m):
        vv += vh[i] * vh[i]
    beta = 2.0 / vv
    wv = np.zeros(m)  # B v
    t = gf.copy()  # ∇E + B pn
    for i in range(m):
        bi = bf[i]
        s1 = 0.0
        s2 = 0.0
        for j in range(m):
            s1 += bi[j] * vh[j]
            s2 += bi[j] * pn[j]
        wv[i] = s1
        t[i] += s2
    vw = 0.0
    for i in range(m):
        vw += vh[i] * wv[i]
    hz = np.empty((m - 1, m - 1))
    b2 = beta * beta * vw
    for i in range(1, m):
        ci = beta * vh[i]
        di = beta * wv[i] - b2 * vh[i]
        bi = bf[i]
        hi = hz[i - 1]
        for j in range(1, m):
            hi[j - 1] = bi[j] - ci * wv[j] - di * vh[j]
    # symmetric to the last bit (the formula's rounding need not be)
    for i in range(m - 1):
        for j in range(i + 1, m - 1):
            s = 0.5 * (hz[i, j] + hz[j, i])
            hz[i, j] = s
            hz[j, i] = s
    ht = np.empty(m)
    _reflect(vh, beta, t, ht)
    rz = ht[1:].copy()
    u = np.empty(m - 1)
    neg_u = np.zeros(m - 1)
    decrement, has_negative = tangential_step_rows(
        hz, rz, math.sqrt(max(radius * radius - nn * nn, 0.0)), flat_mode, u, neg_u
    )
    e = np.zeros(m)
    for i in range(m - 1):
        e[i + 1] = u[i]
    zu = np.empty(m)
    _reflect(vh, beta, e, zu)
    pf = pn + zu
    lam_num = 0.0
    for i in range(m):
        bi = bf[i]
        s = gf[i]
        for j in range(m):
            s += bi[j] * pf[j]
        lam_num += af[i] * s
    lam = lam_num / aa
    p[:] = 0.0
    negative[:] = 0.0
    for i in range(m):
        p[cols[i]] = pf[i]
    if has_negative:
        for i in range(m - 1):
            e[i + 1] = neg_u[i]
        e[0] = 0.0
        nf = np.empty(m)
        _reflect(vh, beta, e, nf)
        for i in range(m):
            negative[cols[i]] = nf[i]
    for i in range(n):
        s = g[i] - lam * a[i]
        bi = b_full[free[i]]
        for j in range(m):
            s += bi[free[cols[j]]] * pf[j]
        kappa[i] = s
    return lam, decrement, has_negative


def kkt_step_for(n: int):
    """The step kernel for ``n`` free entries: ``kkt_step_rows`` from ``ROWS_FROM`` on, else
    the dense ``kkt.kkt_step``."""
    return kkt_step_rows if n >= ROWS_FROM else kkt_step


def step_kernels(largest: int) -> tuple:
    """The step kernels that relaxing states of at most ``largest`` entries calls
    (``kkt_step_for`` of each size): what ``compile_solver`` compiles and
    ``compilation.kernel_entry_points`` looks for in numba's cache."""
    return (kkt_step, kkt_step_rows) if largest >= ROWS_FROM else (kkt_step,)


def solve_kkt(step, b_full, free, held, g, a, c, radius, normal_share, flat_mode) -> tuple:
    """``step`` (``kkt_step`` or ``kkt_step_rows``) into new output arrays: its argument
    list spelled once, for ``relax.newton``'s calls and for ``compile_solver``'s. Returns
    (p (n,), λ, decrement, the negative mode (n,) or None, kappa (n,))."""
    n = free.size
    p, kappa, negative = np.empty(n), np.empty(n), np.empty(n)
    lam, decrement, has_negative = step(b_full, free, held, g, a, c, radius, normal_share,
                                        flat_mode, p, kappa, negative)  # fmt: skip
    return p, lam, decrement, negative if has_negative else None, kappa


def compile_solver(largest: int = ROWS_FROM) -> None:
    """Compile (or load from numba's cache) these kernels, once, before work fans out:
    ``kkt_step_rows`` only if a state of ``largest`` entries needs it (its compile costs
    ~5 s that a stockinette run would spend for nothing)."""
    n = 3
    b = np.eye(n + 1)  # any size: numba compiles for the types
    free = np.arange(n)
    g, a = np.ones(n), np.array([1.0, 0.5, 0.25])
    for step in step_kernels(largest):
        solve_kkt(step, b, free, np.zeros(n, dtype=np.bool_), g, a, 0.0, 1.0, 0.8, 1e-12)
    sr1_update(np.eye(n), g, a, 1e-8)
