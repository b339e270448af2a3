"""The stitch-cell model: energies, length and exact gradients of a state vector.

``CellModel`` binds validated parameters and a fidelity to the numba kernels
(MODEL.md §2–6); it is what relaxation, sweeps and the CLI call. States are
numpy arrays of shape (30,), see ``knitsweep.kernels.geometry``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import Fidelity, InternalParams, StitchParams
from .kernels.bending import SEGMENT_WEIGHTS
from .kernels.bezier import basis_tables, gauss_legendre, midpoints
from .kernels.cell import cell_energy, cell_energy_listed
from .kernels.contact import (
    CORE_EPS,
    CORE_PENALTY,
    IMAGES_CUTOFF,
    IMAGES_REFERENCE,
    find_contacts,
    min_zeta,
)
from .kernels.geometry import IDX_AX, IDX_AY, N_STATE, state_to_control_points
from .kernels.neighbours import build_neighbour_list


class NeighbourList:
    """A caller-owned Verlet list for ``CellModel.energy_and_gradients``
    (kernels.neighbours): exact while valid, rebuilt when the state moves more than
    the skin allows."""

    def __init__(self, skin: float) -> None:
        self.skin = skin
        self.arrays: tuple = ()
        self.rebuilds = 0


CONTACT_CLASSES = ("self", "same_row", "nn_column", "nnn_column", "other")


@dataclass(frozen=True)
class Energies:
    """Energies in mJ (= N mm) and yarn length in mm of one state."""

    bending_energy: float
    contact_energy: float
    length: float

    @property
    def total_energy(self) -> float:
        return self.bending_energy + self.contact_energy

    def as_dict(self) -> dict[str, float]:
        return {
            "bending_energy": self.bending_energy,
            "contact_energy": self.contact_energy,
            "total_energy": self.total_energy,
            "length": self.length,
        }


class CellModel:
    """Energy of one periodic stockinette cell at given parameters and fidelity."""

    def __init__(self, params: StitchParams, fidelity: Fidelity | None = None) -> None:
        self.params = params
        self.fidelity = fidelity or Fidelity()
        self.ip: InternalParams = params.internal()
        nodes, weights = gauss_legendre(self.fidelity.quadrature_nodes)
        self._qtab = basis_tables(nodes)
        self._qw = weights
        self._ctab = np.ascontiguousarray(
            basis_tables(midpoints(self.fidelity.samples_per_segment))[:2]
        )
        self._mode = IMAGES_CUTOFF if self.fidelity.images == "cutoff" else IMAGES_REFERENCE
        self._grad_e = np.empty(N_STATE)
        self._grad_l = np.empty(N_STATE)

    def _call(self, x: np.ndarray, with_grad: bool) -> tuple[float, float, float]:
        ip = self.ip
        x = _as_state(x)
        return cell_energy(
            x, self._qtab, self._qw, self._ctab, SEGMENT_WEIGHTS, ip.bend, ip.reg, ip.r,
            ip.rc, ip.k, ip.p, self._mode, with_grad, self._grad_e, self._grad_l,
        )  # fmt: skip

    def energies(self, x: np.ndarray) -> Energies:
        """Bending and contact energy (mJ) and yarn length (mm) of state ``x``."""
        eb, ec, length = self._call(x, False)
        return Energies(eb, ec, length)

    def energy_and_gradients(
        self, x: np.ndarray, neighbours: NeighbourList | None = None
    ) -> tuple[Energies, np.ndarray, np.ndarray]:
        """Energies plus the exact gradients dE/dx and dl/dx, each shape (30,).

        With a ``NeighbourList`` (from ``neighbour_list``) the contact sum runs over
        its pairs: the same numbers, bit for bit, faster; the list rebuilds itself
        when the state has moved too far for it.
        """
        if neighbours is None:
            eb, ec, length = self._call(x, True)
        else:
            eb, ec, length = self._call_listed(_as_state(x), neighbours)
        return Energies(eb, ec, length), self._grad_e.copy(), self._grad_l.copy()

    def neighbour_list(self, x: np.ndarray, skin: float = 0.1) -> NeighbourList:
        """A Verlet list of the contact candidates around state ``x`` (skin in mm)."""
        nl = NeighbourList(skin)
        self._rebuild(_as_state(x), nl)
        return nl

    def _rebuild(self, x: np.ndarray, nl: NeighbourList) -> None:
        cp = self.control_points(x)
        nl.arrays = build_neighbour_list(cp, self._ctab, x[IDX_AX], x[IDX_AY], self.ip.r,
                                         self._mode, nl.skin)  # fmt: skip
        nl.rebuilds += 1

    def _call_listed(self, x: np.ndarray, nl: NeighbourList) -> tuple[float, float, float]:
        ip = self.ip
        eb, ec, length, valid = cell_energy_listed(
            x, self._qtab, self._qw, self._ctab, SEGMENT_WEIGHTS, ip.bend, ip.reg, ip.r,
            ip.rc, ip.k, ip.p, self._mode, True, self._grad_e, self._grad_l, *nl.arrays,
        )  # fmt: skip
        if not valid:  # the sums came from the full search; refresh the list here
            self._rebuild(x, nl)
        return eb, ec, length

    def control_points(self, x: np.ndarray) -> np.ndarray:
        """The 8 segments' control points in path order, shape (8, 6, 3), mm."""
        cp = np.empty((8, 6, 3))
        state_to_control_points(_as_state(x), cp, np.empty((8, 6, 3, N_STATE)))
        return cp

    def control_points_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Control points (8, 6, 3) and d(control points)/dx, shape (8, 6, 3, 30)."""
        cp = np.empty((8, 6, 3))
        jac = np.empty((8, 6, 3, N_STATE))
        state_to_control_points(_as_state(x), cp, jac)
        return cp, jac

    def min_zeta(self, x: np.ndarray) -> float:
        """Smallest compression zeta over all counted contacts (1.0 if none);
        below 1e-5 the hard cores overlap (MODEL.md §6)."""
        ip = self.ip
        x = _as_state(x)
        return min_zeta(self.control_points(x), self._ctab, x[IDX_AX], x[IDX_AY], ip.r, ip.rc,
                        self._mode)  # fmt: skip

    def contact_forces_by_class(self, x: np.ndarray) -> np.ndarray:
        """Contact forces on the cell by class of image offset (m, n), N.

        Rows: self (0, 0), same row (n = 0, m != 0), nearest same column (m = 0,
        |n| = 1), next-nearest same column (m = 0, |n| = 2), other (diagonal or
        farther images). Columns:

        * x, y: the class's generalised force on the cell period,
          F_a = -dE_c(class)/da at fixed shape parameters (through the crossover
          positions, the connector shifts and the image offsets). Positive: the
          contacts push the cell to extend along a; negative: they pull it
          together (interlocked loops). Over all classes, and with the bending
          term, these add up to the cell's total force, zero at zero force.
        * z: the push out of plane, -dE_c(class)/dlambda / dz under a uniform
          dilation z -> lambda z of the cell (dz its thickness); >= 0.

        Each physical contact counts twice, as in E_c (paper SI "Contact Forces").
        """
        ip = self.ip
        x = _as_state(x)
        cp, jac = self.control_points_and_jacobian(x)
        _, r1, speed, idx, sep = find_contacts(cp, self._ctab, x[IDX_AX], x[IDX_AY], ip.r,
                                               self._mode)  # fmt: skip
        out = np.zeros((len(CONTACT_CLASSES), 3))
        if len(idx) == 0:
            return out
        n = self.fidelity.samples_per_segment
        dt2 = 1.0 / (n * n)
        i, j, m, nn = idx[:, 0], idx[:, 1], idx[:, 2], idx[:, 3]
        dist, d = sep[:, 3], sep[:, :3]
        v, dv = _pair_potential_arrays(dist, ip)
        # samples' motion with each period: dp/da (ns, 3) and dv/da (ns,)
        b0, b1 = self._ctab[0], self._ctab[1]  # (N, 6)
        forces = np.empty((len(idx), 2))
        for col, k in enumerate((IDX_AX, IDX_AY)):
            dp = np.einsum("jc,scd->sjd", b0, jac[..., k]).reshape(-1, 3)
            dr1 = np.einsum("jc,scd->sjd", b1, jac[..., k]).reshape(-1, 3)
            dspeed = np.einsum("id,id->i", r1, dr1) / speed
            dd = dp[i] - dp[j]
            dd[:, col] -= m if col == 0 else nn
            dR = np.einsum("pd,pd->p", d, dd) / dist
            dE = 2.0 * dt2 * (dv * dR * speed[i] * speed[j]
                              + v * (dspeed[i] * speed[j] + speed[i] * dspeed[j]))  # fmt: skip
            forces[:, col] = -dE
        z = self.control_points(x)[:, :, 2]
        dz = float(z.max() - z.min() + 2.0 * ip.r)
        fz = -2.0 * dt2 * dv * d[:, 2] ** 2 / dist * speed[i] * speed[j] / dz
        cls = np.full(len(idx), 4)
        cls[(m == 0) & (nn == 0)] = 0
        cls[(m != 0) & (nn == 0)] = 1
        cls[(m == 0) & (np.abs(nn) == 1)] = 2
        cls[(m == 0) & (np.abs(nn) == 2)] = 3
        np.add.at(out, (cls, 0), forces[:, 0])
        np.add.at(out, (cls, 1), forces[:, 1])
        np.add.at(out, (cls, 2), fz)
        return out

    def thickness(self, x: np.ndarray, samples: int = 64) -> float:
        """Cell thickness dz = z_max - z_min + 2r of the centre-line (paper SI S4), mm."""
        cp = self.control_points(x)
        b = basis_tables(np.linspace(0.0, 1.0, samples))[0]
        z = np.einsum("ti,si->st", b, cp[:, :, 2])
        return float(z.max() - z.min() + 2.0 * self.ip.r)


def _pair_potential_arrays(dist: np.ndarray, ip: InternalParams) -> tuple[np.ndarray, np.ndarray]:
    """V(R) and dV/dR of MODEL.md §6 for arrays of distances (all below 2r)."""
    d = 2.0 * ip.r - 2.0 * ip.rc
    pref = ip.k * d * d / (ip.p * (ip.p - 1.0))
    zeta = (dist - 2.0 * ip.rc) / d
    soft = zeta >= CORE_EPS
    zs = np.where(soft, zeta, 1.0)
    zp = zs ** (1.0 - ip.p)
    v_soft = pref * (zp - 1.0 - (ip.p - 1.0) * (1.0 - zs))
    dv_soft = pref * (ip.p - 1.0) * (1.0 - zp / zs) / d
    v_eps = pref * (CORE_EPS ** (1.0 - ip.p) - 1.0 - (ip.p - 1.0) * (1.0 - CORE_EPS))
    r_eps = 2.0 * ip.rc + CORE_EPS * d
    xh = (dist - r_eps) / r_eps
    v = np.where(soft, v_soft, v_eps + CORE_PENALTY * xh * xh)
    dv = np.where(soft, dv_soft, 2.0 * CORE_PENALTY * xh / r_eps)
    return v, dv


def _as_state(x: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (N_STATE,):
        raise ValueError(f"a state has {N_STATE} entries, got shape {x.shape}")
    if x[IDX_AX] <= 0.0 or x[IDX_AY] <= 0.0:
        raise ValueError(f"cell periods must be > 0, got a_x = {x[IDX_AX]}, a_y = {x[IDX_AY]}")
    return x
