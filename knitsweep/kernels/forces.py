"""Contact forces and energies by contact class (docs/model.md §9; paper SI "Contact
Forces"), on the contact kernel's own pair potential and pair list.

A contact's class is set by the image offset (m, n) of its pair: self (0, 0), same
row (n = 0, m != 0), nearest and next-nearest same column (m = 0, |n| = 1, 2) and
other (diagonal or farther images); the order is ``knitsweep.state.CONTACT_CLASSES``.
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
def contact_forces_by_class(cp, dcp, tab, ax, ay, r, rc, k, p, mode, forces, energies):
    """Each class's generalised forces on the cell periods and its contact energy.

    cp (8, 6, 3): control points (mm); dcp (8, 6, 3, 2): their derivatives with
    respect to (a_x, a_y) at fixed shape parameters (columns 28 and 29 of the state
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
    z_lo = cp[0, 0, 2]
    z_hi = z_lo
    for s in range(cp.shape[0]):
        for c in range(6):
            z_lo = min(z_lo, cp[s, c, 2])
            z_hi = max(z_hi, cp[s, c, 2])
    dz = z_hi - z_lo + 2.0 * r
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
