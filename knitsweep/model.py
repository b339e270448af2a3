"""The stitch-cell model: energies, length and exact gradients of a state vector.

``CellModel`` binds validated parameters and a fidelity to the numba kernels
(docs/model.md §2–6, §9); it is what relaxation, sweeps and the CLI call. States
are numpy arrays of shape (30,), laid out as in ``knitsweep.state``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import Fidelity, InternalParams, StitchParams
from .kernels.bending import SEGMENT_WEIGHTS
from .kernels.bezier import basis_tables, gauss_legendre, midpoints
from .kernels.cell import cell_energy, cell_energy_listed
from .kernels.contact import IMAGES_CUTOFF, IMAGES_REFERENCE, min_zeta
from .kernels.forces import N_CLASSES
from .kernels.forces import contact_forces_by_class as _forces_by_class
from .kernels.forces import contact_pair_forces_by_class as _pair_forces_by_class
from .kernels.geometry import state_to_control_points
from .kernels.neighbours import build_neighbour_list
from .state import CONTACT_CLASSES, IDX_AX, IDX_AY, N_STATE


class NeighbourList:
    """A caller-owned Verlet list for ``CellModel.energy_and_gradients``
    (kernels.neighbours): exact while valid, rebuilt when the state moves more than
    the skin allows."""

    def __init__(self, skin: float) -> None:
        self.skin = skin
        self.arrays: tuple = ()
        self.rebuilds = 0


assert len(CONTACT_CLASSES) == N_CLASSES


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
        below 1e-5 the hard cores overlap (docs/model.md §6)."""
        ip = self.ip
        x = _as_state(x)
        return min_zeta(self.control_points(x), self._ctab, x[IDX_AX], x[IDX_AY], ip.r, ip.rc,
                        self._mode)  # fmt: skip

    def contact_forces_by_class(self, x: np.ndarray) -> np.ndarray:
        """Contact forces on the cell by class of image offset, shape (5, 3), N.

        Rows: ``knitsweep.state.CONTACT_CLASSES`` (self, same row, nearest and
        next-nearest same column, other). Columns x, y: the class's generalised
        force on the cell period, F_a = -dE_c(class)/da at fixed shape parameters
        (positive: the contacts push the cell to extend along a; negative: they pull
        it together). Summed over the classes they are -dE_c/da; adding the bending
        term and the length constraint's share gives the cell's total force on a
        (``Relaxation.period_forces``), zero at zero force. Column z: the push out
        of plane (>= 0). Each physical contact counts twice, as in E_c (paper SI
        "Contact Forces").
        """
        return self.contacts_by_class(x)[0]

    def contacts_by_class(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(forces (5, 3) N as in ``contact_forces_by_class``, energies (5,) mJ):
        the contact energy of each class; the five add up to E_c."""
        ip = self.ip
        x = _as_state(x)
        cp, jac = self.control_points_and_jacobian(x)
        dcp = np.ascontiguousarray(jac[..., [IDX_AX, IDX_AY]])
        forces = np.empty((N_CLASSES, 3))
        energies = np.empty(N_CLASSES)
        _forces_by_class(cp, dcp, self._ctab, x[IDX_AX], x[IDX_AY], ip.r, ip.rc, ip.k, ip.p,
                         self._mode, forces, energies)  # fmt: skip
        return forces, energies

    def contact_pair_forces_by_class(self, x: np.ndarray, weighted: bool = False) -> np.ndarray:
        """Pair forces between sampled yarn points by contact class, shape (5, 3), N.

        The paper's contact forces (SI "Contact Forces", Table 2, Table S3, Fig. 6h;
        docs/model.md §9): every contact's pair force f = -dV/dR along the
        separation, on both of its samples, projected on x, y, z; positive extends
        the fabric (pushes the two stitches apart along an axis on which they are
        offset, else pushes the sample away from its own stitch's mid-plane).
        Rows ``CONTACT_CLASSES``. Unweighted, the bare force between two samples,
        whose sums depend on the sampling (the paper's 10 samples per segment);
        ``weighted=True`` multiplies each pair by ds ds' as in E_c (N mm^2), the
        sampling-independent integral.
        """
        ip = self.ip
        x = _as_state(x)
        forces = np.empty((N_CLASSES, 3))
        _pair_forces_by_class(self.control_points(x), self._ctab, x[IDX_AX], x[IDX_AY], ip.r,
                              ip.rc, ip.k, ip.p, self._mode, weighted, forces)  # fmt: skip
        return forces

    def thickness(self, x: np.ndarray, samples: int = 64) -> float:
        """Cell thickness dz = z_max - z_min + 2r of the centre-line (paper SI S4), mm."""
        cp = self.control_points(x)
        z = np.einsum("ti,si->st", _thickness_basis(samples), cp[:, :, 2])
        return float(z.max() - z.min() + 2.0 * self.ip.r)


@functools.lru_cache(maxsize=8)
def _thickness_basis(samples: int) -> np.ndarray:
    """Bernstein basis (samples, 6) at evenly spaced parameters in [0, 1], made once."""
    b = basis_tables(np.linspace(0.0, 1.0, samples))[0]
    b.setflags(write=False)
    return b


def compile_kernels(
    fidelity: Fidelity | None = None, notice: Callable[[str], None] | None = None
) -> None:
    """Compile (or load from numba's cache) every kernel a task uses, once, before
    work fans out to other processes. ``notice`` is told first when the kernels are
    not cached yet, so that a user knows why the first run waits."""
    from . import kernels
    from .formats import shipped_state
    from .kernels.kkt import compile_solver

    message = kernels.compile_notice() if notice is not None else None
    if message:
        notice(message)
    model = CellModel(StitchParams(), fidelity)
    x = shipped_state(1)
    model.energy_and_gradients(x)
    model.energy_and_gradients(x, model.neighbour_list(x))
    model.min_zeta(x)
    model.thickness(x)
    model.contacts_by_class(x)
    model.contact_pair_forces_by_class(x)
    compile_solver()  # the Newton step of the relaxations


def _as_state(x: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (N_STATE,):
        raise ValueError(f"a state has {N_STATE} entries, got shape {x.shape}")
    if x[IDX_AX] <= 0.0 or x[IDX_AY] <= 0.0:
        raise ValueError(f"cell periods must be > 0, got a_x = {x[IDX_AX]}, a_y = {x[IDX_AY]}")
    return x
