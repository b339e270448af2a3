"""Optional Verlet neighbour list for the contact sum (docs/model.md §6).

A relaxation evaluates the energy at thousands of nearby states. The list holds
every sample pair (i, j, m, n) closer than 2r + skin at the state where it was
built, in the search order of ``partition`` (image, segment a, segment b, i, j),
as rows (i, j_lo, j_hi, m, n): sample i against the run j_lo <= j < j_hi of one
segment that covers its listed partners. An evaluation tests those runs instead
of searching (no box tests). It is exact:

* A pair's separation d = p_i - p_j - m t_c - n t_w changes by at most
  2 max_i |dp_i| + |m| |da_x| + |n| |da_y| since the build. While that bound is
  below the skin, every pair with R < 2r now was listed (cutoff mode builds its
  image list for the reach 2r + skin, so no image is missing either).
* The same-row exclusion (arclength along the yarn) and R < 2r are tested at
  the current state, in list order, with the same arithmetic as the search.

So while the list is valid, ``contact_energy_listed`` adds exactly the numbers
``contact.contact_energy`` adds, in the same order: the sums are identical, not
just close (tests/test_neighbour_list.py). When the bound is not met it falls
back to the search and says so, and the caller builds a new list. Nothing is
kept between calls: the caller owns the list (three arrays) and passes it in.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .contact import (
    accumulate_pairs,
    collect_pairs,
    contact_energy,
    finish_pairs,
    pair_sum_start,
    sample_cell,
)
from .partition import search_row

# meta layout: a_x, a_y, skin, max |m|, max |n|, r, image mode at the build
_META = 7

NO_LIST = (np.empty((0, 5), dtype=np.int64), np.empty((3, 0)), np.empty(0))
"""The three arrays of an empty neighbour list: ``contact_energy_listed`` (and
``cell.cell_energy_listed``) then sum over the full search, as ``contact_energy``.
(Writable, as the arrays of a built list: a read-only array is another type to numba,
so another specialisation.)"""


@njit(cache=True)
def build_neighbour_list(cp, tab, ax, ay, r, mode, skin):
    """Every sample pair closer than 2r + ``skin`` (mm), each unordered pair once.

    cp (S, 6, 3), tab (2, N, 6), periods a_x, a_y (mm), yarn radius r, image
    ``mode`` as in ``contact_energy``. Returns (rows (k, 5) int64 =
    (i, j_lo, j_hi, m, n), ref_pos (3, 8N) sample positions, meta (7,) float64);
    pass all three to ``contact_energy_listed``.
    """
    n = tab.shape[1]
    pts, pos, _, _, s_mid, s_tot = sample_cell(cp, tab)
    # s_excl < 0: no pair is excluded here, the exclusion is tested per call
    ib, _, c = collect_pairs(pts, pos, s_mid, s_tot, n, ax, ay, 2.0 * r + skin, -1.0, mode)
    # runs of one i against one segment in one image (consecutive in search order)
    rows = np.empty((c, 5), dtype=np.int64)
    k = 0
    for q in range(c):
        i, j, m, nn = ib[0, q], ib[1, q], ib[2, q], ib[3, q]
        if k > 0:
            prev = rows[k - 1]
            if prev[0] == i and prev[3] == m and prev[4] == nn and (prev[2] - 1) // n == j // n:
                prev[2] = j + 1
                continue
        rows[k, 0] = i
        rows[k, 1] = j
        rows[k, 2] = j + 1
        rows[k, 3] = m
        rows[k, 4] = nn
        k += 1
    meta = np.empty(_META)
    meta[0], meta[1], meta[2], meta[5], meta[6] = ax, ay, skin, r, mode
    mmax = 0  # max |m|, |n| over the pairs (0 if none), in a plain loop
    nmax = 0
    for q in range(c):
        mmax = max(mmax, abs(ib[2, q]))
        nmax = max(nmax, abs(ib[3, q]))
    meta[3] = mmax
    meta[4] = nmax
    return rows[:k].copy(), pos, meta


@njit(cache=True)
def neighbour_list_valid(pos, ax, ay, r, mode, ref_pos, meta):
    """True if the list built at (``ref_pos``, ``meta``) still holds every pair
    closer than 2r for samples ``pos`` (3, 8N) and periods a_x, a_y."""
    if pos.shape != ref_pos.shape or meta.shape[0] != _META:
        return False
    if meta[5] != r or meta[6] != mode:
        return False
    d2max = 0.0
    for i in range(pos.shape[1]):
        dx = pos[0, i] - ref_pos[0, i]
        dy = pos[1, i] - ref_pos[1, i]
        dz = pos[2, i] - ref_pos[2, i]
        d2max = max(d2max, dx * dx + dy * dy + dz * dz)
    drift = 2.0 * np.sqrt(d2max) + meta[3] * abs(ax - meta[0]) + meta[4] * abs(ay - meta[1])
    skin = meta[2]
    # margin: distances at the build were computed in floating point
    return drift < skin - 1e-9 * (1.0 + 2.0 * r + skin)


@njit(cache=True)
def contact_energy_listed(cp, tab, ax, ay, r, rc, k, p, mode, with_grad, grad_cp, grad_cell,
                          rows, ref_pos, meta):  # fmt: skip
    """``contact.contact_energy`` over a neighbour list; returns (E_c, valid).

    Arguments as in ``contact_energy``, plus the three arrays of
    ``build_neighbour_list``. If the list no longer covers the state (``valid`` is
    False), the energy comes from the full search instead: the result is always
    the exact one, and the caller should build a new list.
    """
    if meta.shape[0] != _META:  # no list (``NO_LIST``): the search, at once
        e = contact_energy(cp, tab, ax, ay, r, rc, k, p, mode, with_grad, grad_cp, grad_cell)
        return e, False
    n = tab.shape[1]
    _, pos, r1, speed, s_mid, s_tot = sample_cell(cp, tab)
    if not neighbour_list_valid(pos, ax, ay, r, mode, ref_pos, meta):
        e = contact_energy(cp, tab, ax, ay, r, rc, k, p, mode, with_grad, grad_cp, grad_cell)
        return e, False
    dt2, cut, s_excl, ib, fb, work, g = pair_sum_start(n, speed.shape[0], r)
    cut2 = cut * cut
    energy = 0.0
    gax = 0.0
    gay = 0.0
    c = np.int64(0)  # not the literal 0: no extra specialisation of the callees
    for q in range(rows.shape[0]):
        i, j0, j1, m, nn = rows[q, 0], rows[q, 1], rows[q, 2], rows[q, 3], rows[q, 4]
        if c + n > ib.shape[1]:
            energy, gax, gay = accumulate_pairs(ib, fb, c, speed, dt2, r, rc, k, p, with_grad,
                                                work, g, energy, gax, gay)  # fmt: skip
            c = np.int64(0)
        c = search_row(pos, s_mid, i, j0, j1, m, nn, m * ax, nn * ay, m * s_tot, cut2, s_excl,
                       ib, fb, c)  # fmt: skip
    energy = finish_pairs(ib, fb, c, speed, r1, tab, dt2, r, rc, k, p, with_grad, work, g, energy,
                          gax, gay, grad_cp, grad_cell)  # fmt: skip
    return energy, True
