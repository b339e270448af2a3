"""The stitch-cell model: energies, length and exact gradients of a state vector.

``CellModel`` binds validated parameters and a fidelity to the numba kernels
(MODEL.md §2–6); it is what relaxation, sweeps and the CLI call. States are
numpy arrays of shape (30,), see ``knitsweep.kernels.geometry``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels.bending import SEGMENT_WEIGHTS
from .kernels.bezier import basis_tables, gauss_legendre, midpoints
from .kernels.cell import cell_energy
from .kernels.contact import (
    CORE_EPS,
    CORE_PENALTY,
    IMAGES_CUTOFF,
    IMAGES_REFERENCE,
    find_contacts,
    min_zeta,
)
from .kernels.geometry import IDX_AX, IDX_AY, N_STATE, state_to_control_points
from .params import Fidelity, InternalParams, StitchParams

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

    def energy_and_gradients(self, x: np.ndarray) -> tuple[Energies, np.ndarray, np.ndarray]:
        """Energies plus the exact gradients dE/dx and dl/dx, each shape (30,)."""
        eb, ec, length = self._call(x, True)
        return Energies(eb, ec, length), self._grad_e.copy(), self._grad_l.copy()

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
        """Contact forces on the cell's yarn by class of image offset (m, n), N.

        Rows: self (0, 0), same row (n = 0, m != 0), nearest same column (m = 0,
        |n| = 1), next-nearest same column (m = 0, |n| = 2), other (diagonal or
        farther images). Columns: the sums over every ordered contact pair of the
        absolute x, y, z components of the pair force -dV/dR (d/R) v_i v_j dt^2
        (paper SI "Contact Forces"; each physical contact counted twice, as in E_c).
        """
        ip = self.ip
        x = _as_state(x)
        cp = self.control_points(x)
        _, _, speed, idx, sep = find_contacts(cp, self._ctab, x[IDX_AX], x[IDX_AY], ip.r,
                                              self._mode)  # fmt: skip
        out = np.zeros((len(CONTACT_CLASSES), 3))
        if len(idx) == 0:
            return out
        dist = sep[:, 3]
        d = 2.0 * ip.r - 2.0 * ip.rc
        zeta = (dist - 2.0 * ip.rc) / d
        r_eps = 2.0 * ip.rc + CORE_EPS * d
        with np.errstate(divide="ignore", invalid="ignore"):
            soft = ip.k * d / ip.p * (1.0 - np.maximum(zeta, CORE_EPS) ** -ip.p)
        dv = np.where(zeta >= CORE_EPS, soft, 2.0 * CORE_PENALTY * (dist - r_eps) / r_eps**2)
        n = self.fidelity.samples_per_segment
        w = 2.0 * speed[idx[:, 0]] * speed[idx[:, 1]] / (n * n)  # both orders of the pair
        comp = np.abs(dv * w / dist)[:, None] * np.abs(sep[:, :3])
        m, nn = idx[:, 2], np.abs(idx[:, 3])
        cls = np.full(len(idx), 4)
        cls[(m == 0) & (nn == 0)] = 0
        cls[(m != 0) & (nn == 0)] = 1
        cls[(m == 0) & (nn == 1)] = 2
        cls[(m == 0) & (nn == 2)] = 3
        np.add.at(out, cls, comp)
        return out

    def thickness(self, x: np.ndarray, samples: int = 64) -> float:
        """Cell thickness dz = z_max - z_min + 2r of the centre-line (paper SI S4), mm."""
        cp = self.control_points(x)
        b = basis_tables(np.linspace(0.0, 1.0, samples))[0]
        z = np.einsum("ti,si->st", b, cp[:, :, 2])
        return float(z.max() - z.min() + 2.0 * self.ip.r)


def _as_state(x: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (N_STATE,):
        raise ValueError(f"a state has {N_STATE} entries, got shape {x.shape}")
    if x[IDX_AX] <= 0.0 or x[IDX_AY] <= 0.0:
        raise ValueError(f"cell periods must be > 0, got a_x = {x[IDX_AX]}, a_y = {x[IDX_AY]}")
    return x
