"""Contact forces and energies by contact class (docs/model.md §9; paper SI "Contact
Forces", Table S3), on the contact kernel's own pair potential and pair list.

A contact's class is set by the image offset (m, n) of its pair: self (0, 0), same
row (n = 0, m != 0), nearest and next-nearest same column (m = 0, |n| = 1, 2) and
other (diagonal or farther images), for a fabric of translated cells; a stitch names
the rows in this order (``Stitch.contact_classes``).

Two kinds of force per class:

* ``contact_forces_by_class``: generalised forces on the cell periods, -dE_c(class)/da
  at fixed shape (what the envelope stress is made of);
* ``contact_pair_forces_by_class``: the pair forces f = -dV/dR between sampled yarn
  points, projected on x, y, z (the paper's Table S3 and Fig. 6h quantity); their rule,
  ``pair_forces``, is shared with the patterns' (``mirrored.mirrored_pair_forces_by_class``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .contact import find_contacts, pair_potential

N_CLASSES = 5


@njit(cache=True, inline="always")
def contact_class(m, n):
    """Row of ``CONTACT_CLASSES`` for image offset (m, n)."""
    if m == 0 and n == 0:
        return 0
    if n == 0:
        return 1
    if m == 0 and (n == 1 or n == -1):
        return 2
    if m == 0 and (n == 2 or n == -2):
        return 3
    return 4


@njit(cache=True)
def polygon_height(cp, r):
    """Δz of the out-of-plane push: the control polygon's height plus 2r (mm)."""
    z_lo = cp[0, 0, 2]
    z_hi = z_lo
    for s in range(cp.shape[0]):
        for c in range(6):
            z_lo = min(z_lo, cp[s, c, 2])
            z_hi = max(z_hi, cp[s, c, 2])
    return z_hi - z_lo + 2.0 * r


@njit(cache=True)
def contact_forces_by_class(cp, dcp, tab, ax, ay, r, rc, k, p, mode, forces, energies):
    """Each class's generalised forces on the cell periods and its contact energy.

    cp (S, 6, 3): control points (mm); dcp (S, 6, 3, 2): their derivatives with
    respect to (a_x, a_y) at fixed shape parameters (the last two columns of the state
    Jacobian); tab (2, N, 6): contact sample tables; periods, radii, k and p as in
    ``contact.contact_energy``. Writes

    * ``forces`` (5, 3), N: columns x, y are F_a = -dE_c(class)/da (through the
      crossover positions, the connector shifts and the image offsets; positive
      pushes the cell to extend along a), column z the class's push out of plane,
      -dE_c(class)/dλ / Δz under the dilation z -> λ z, with Δz the control
      polygon's height plus 2r;
    * ``energies`` (5,), N mm: E_c(class), which add up to E_c.

    Each physical contact counts twice, as in E_c.
    """
    n = tab.shape[1]
    dt2 = 1.0 / (n * n)
    _, r1, speed, idx, sep = find_contacts(cp, tab, ax, ay, r, mode)
    ns = speed.shape[0]
    # samples' motion with each period: dp/da (ns, 3, 2) and dv/da (ns, 2)
    dp = np.zeros((ns, 3, 2))
    dspeed = np.zeros((ns, 2))
    for s in range(cp.shape[0]):
        for jj in range(n):
            i = s * n + jj
            for col in range(2):
                acc = 0.0
                for d in range(3):
                    x = 0.0
                    y = 0.0
                    for c in range(6):
                        x += tab[0, jj, c] * dcp[s, c, d, col]
                        y += tab[1, jj, c] * dcp[s, c, d, col]
                    dp[i, d, col] = x
                    acc += r1[i, d] * y
                dspeed[i, col] = acc / speed[i]
    dz = polygon_height(cp, r)
    forces[:] = 0.0
    energies[:] = 0.0
    for q in range(idx.shape[0]):
        i, j, m, nn = idx[q, 0], idx[q, 1], idx[q, 2], idx[q, 3]
        dist = sep[q, 3]
        v, dv = pair_potential(dist, r, rc, k, p)
        cls = contact_class(m, nn)
        si = speed[i]
        sj = speed[j]
        energies[cls] += 2.0 * dt2 * v * si * sj
        for col in range(2):
            dR = 0.0
            for d in range(3):
                dd = dp[i, d, col] - dp[j, d, col]
                if d == col:
                    dd -= m if col == 0 else nn
                dR += sep[q, d] * dd
            dR /= dist
            dE = 2.0 * dt2 * (dv * dR * si * sj + v * (dspeed[i, col] * sj + si * dspeed[j, col]))
            forces[cls, col] -= dE
        forces[cls, 2] -= 2.0 * dt2 * dv * sep[q, 2] ** 2 / dist * si * sj / dz


@njit(cache=True, inline="always")
def _side(c):
    """Sign of a coordinate relative to the stitch's mid-plane through the origin."""
    if c > 0.0:
        return 1.0
    if c < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def contact_pair_forces_by_class(cp, tab, ax, ay, r, rc, k, p, mode, weighted, forces):
    """Each class's pair forces between sampled yarn points, projected on x, y, z
    (docs/model.md §9; paper SI "Contact Forces", Fig. S11, Table S3, Fig. 6h).

    cp (S, 6, 3): control points (mm); tab (2, N, 6): contact sample tables; periods,
    radii, k and p as in ``contact.contact_energy``; ``weighted``: multiply each pair
    force by ds ds' = v_i v_j dt^2 (mm^2) as in E_c, else the bare pair force (the
    paper's Table S3 magnitudes; then the sums grow with N^2). Writes ``forces``
    (5, 3), N (N mm^2 when weighted).

    Every counted contact (i, j, m, n) pushes sample i with F = f d/R, f = -dV/dR >= 0,
    d = p_i - p_j - m t_c - n t_w, and the partner sample with -F. Both samples count
    (each contact twice, as in E_c). Component a of a sample's force counts positive
    when it extends the fabric along a:

    * along an axis on which the partner stitch is offset (x with m != 0, y with
      n != 0), when it pushes the two stitches apart: 2 f (-d_a/R) sign(offset_a);
    * otherwise (self contacts, x of column contacts, y of same-row contacts, and
      every z), when it pushes the sample away from its own stitch's mid-plane
      a = 0 (x = 0 is the plane between the two crossovers, y = 0 and z = 0 the
      plane of their centres): F_a (sign(a_i) - sign(a_j)), coordinates in each
      sample's own cell, so that only pairs across the mid-plane count.
    """
    n = tab.shape[1]
    pts, _, speed, idx, sep = find_contacts(cp, tab, ax, ay, r, mode)
    classes = np.empty(idx.shape[0], dtype=np.int64)
    for q in range(idx.shape[0]):
        classes[q] = contact_class(idx[q, 2], idx[q, 3])
    pair_forces(pts, speed, idx, sep, classes, 1.0 / (n * n), r, rc, k, p, weighted, forces)


@njit(cache=True)
def pair_forces(pts, speed, idx, sep, classes, dt2, r, rc, k, p, weighted, forces):
    """The rule of ``contact_pair_forces_by_class`` on a list of contacts, into
    ``forces`` (rows of ``classes``, 3), N (N mm^2 when ``weighted``).

    idx (c, 4) = (i, j, m, n) and sep (c, 4) = (dx, dy, dz, R) as from
    ``contact.find_contacts``; ``classes`` (c,): each contact's row; ``pts`` (M, 3) and
    ``speed`` (M,): the samples i and j index, each as it sits in its own cell (the
    partner in a mirrored image, ``kernels.mirrored.mirrored_contacts``, z -> -z);
    dt2 = 1 / N^2.
    """
    forces[:] = 0.0
    for q in range(idx.shape[0]):
        i, j, m, nn = idx[q, 0], idx[q, 1], idx[q, 2], idx[q, 3]
        dist = sep[q, 3]
        _, dv = pair_potential(dist, r, rc, k, p)
        f = -dv / dist
        if weighted:
            f *= speed[i] * speed[j] * dt2
        cls = classes[q]
        for a in range(3):
            fa = f * sep[q, a]  # force on sample i along a
            offset = m if a == 0 else (nn if a == 1 else 0)
            if offset > 0:
                forces[cls, a] -= 2.0 * fa
            elif offset < 0:
                forces[cls, a] += 2.0 * fa
            else:
                forces[cls, a] += fa * (_side(pts[i, a]) - _side(pts[j, a]))
