"""Quintic Bernstein basis tables and Gauss–Legendre rules (docs/model.md §3, §5, §6).

Plain numpy, evaluated once per fidelity setting; the numba kernels take the
tables as arguments so that no kernel recomputes a binomial in its hot loop.
"""

from __future__ import annotations

import functools
from math import comb

import numpy as np

DEGREE = 5
N_CTRL = DEGREE + 1


def _bernstein(n: int, t: np.ndarray) -> np.ndarray:
    """Bernstein polynomials of degree ``n`` at ``t``; shape (len(t), n + 1)."""
    k = np.arange(n + 1)
    c = np.array([comb(n, i) for i in k], dtype=float)
    t = np.asarray(t, dtype=float)[:, None]
    return c * t**k * (1.0 - t) ** (n - k)


def basis_tables(t: np.ndarray) -> np.ndarray:
    """Values and first three t-derivatives of the quintic Bernstein basis.

    Returns an array of shape (4, len(t), 6): ``[d][j, i]`` is d^d B_i/dt^d at
    ``t[j]``, so ``r^(d)(t_j) = sum_i table[d, j, i] * P_i``.
    """
    t = np.asarray(t, dtype=float)
    out = np.zeros((4, t.size, N_CTRL))
    out[0] = _bernstein(DEGREE, t)
    # d/dt of a degree-n Bernstein sum: n * sum (P_{i+1} - P_i) B_i^{n-1};
    # expressed on the original control points through forward differences.
    for d in range(1, 4):
        lower = _bernstein(DEGREE - d, t)  # (nt, 6 - d)
        # coefficients of the d-th forward difference operator
        fd = np.zeros((DEGREE - d + 1, N_CTRL))
        for i in range(DEGREE - d + 1):
            for j in range(d + 1):
                fd[i, i + j] = (-1) ** (d - j) * comb(d, j)
        scale = float(np.prod(np.arange(DEGREE - d + 1, DEGREE + 1)))
        out[d] = scale * lower @ fd
    return out


@functools.lru_cache(maxsize=8)
def even_tables(samples: int) -> np.ndarray:
    """``basis_tables`` at ``samples`` evenly spaced parameters in [0, 1] (ends included),
    shape (4, samples, 6), made once and read-only: the sampling of the thickness and the
    largest curvature of a centre-line."""
    table = basis_tables(np.linspace(0.0, 1.0, samples))
    table.setflags(write=False)
    return table


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights on [0, 1] with ``n`` nodes."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def midpoints(n: int) -> np.ndarray:
    """The contact sample parameters t_j = (j + 1/2)/n of docs/model.md §6."""
    return (np.arange(n) + 0.5) / n
