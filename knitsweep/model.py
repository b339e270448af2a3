"""The stitch-cell model: energies, length and exact gradients of a state vector.

``CellModel`` binds validated parameters, a fidelity and a stitch geometry
(``knitsweep.stitches``, chosen by ``params.stitch``) to the numba kernels
(docs/model.md §2–6, §9); it is what relaxation, sweeps and the CLI call. States
are numpy arrays of shape (n,), laid out as the stitch says (stockinette: n = 30,
``stitches.stockinette.layout``); their last two entries are the periods a_x, a_y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .analysis.volumes.geometry import fabric_depth
from .config import Fidelity, InternalParams, StitchParams
from .kernels.arclength import arclength_rule
from .kernels.bezier import basis_tables, even_tables, gauss_legendre, midpoints
from .kernels.contact import CORE_EPS, IMAGES_CUTOFF, IMAGES_REFERENCE
from .kernels.forces import N_CLASSES
from .kernels.neighbours import build_neighbour_list
from .stitches import Stitch, get_stitch
from .stitches.images import image_group
from .stitches.patterns import check_start


class NeighbourList:
    """A caller-owned Verlet list for ``CellModel.energy_and_gradients``
    (kernels.neighbours): exact while valid, rebuilt when the state moves more than
    the skin allows."""

    def __init__(self, skin: float) -> None:
        self.skin = skin
        self.arrays: tuple = ()
        self.rebuilds = 0


@dataclass(frozen=True)
class Energies:
    """Energies in mJ (= N mm) and yarn length in mm of one state."""

    bending_energy: float
    contact_energy: float
    length: float
    gauge_energy: float = 0.0
    """A free yarn's gauge penalty on its joints' slides (mJ; ``CellModel.gauge``): what a
    relaxation minimises besides the energy, never part of it (``total_energy``)."""

    @property
    def total_energy(self) -> float:
        return self.bending_energy + self.contact_energy

    @property
    def objective(self) -> float:
        """What a relaxation minimises (mJ): the energy plus a free yarn's gauge penalty;
        ``CellModel.energy_and_gradients``'s dE/dx is its gradient."""
        return self.total_energy + self.gauge_energy

    def as_dict(self) -> dict[str, float]:
        return {
            "bending_energy": self.bending_energy,
            "contact_energy": self.contact_energy,
            "total_energy": self.total_energy,
            "length": self.length,
        }


CORES_OVERLAP = "hard cores overlap"
"""How every verdict of overlapping hard cores begins (a state that cannot be knitted)."""
RESOLUTION_RTOL = 0.25
"""A free yarn's contact sum holds if, with twice the samples per segment, E_c differs by
at most this fraction (measured at relaxed states with speeds within
``stockinette_free.layout.SPEED_BOUNDS``: 4–9 %; a yarn whose cores pass between sparse
samples: 12-fold, docs/model.md §11)."""
GAUGE_RTOL = 1e-9
"""End speeds this close (relative) count as one gauge's (``CellModel.gauged``): the
copies of a state perturbed by 1e-15 or 1e-12 (``[starts] spread``, ``retries``) stay
copies of it, not re-interpolations."""
ARC_PANELS, ARC_NODES = 2, 8
"""The composite Gauss rule (panels, nodes per panel) of a segment's arclength S(t) when
the contact samples are placed by arclength (``kernels.arclength``)."""
_NO_RULE = np.zeros((2, 0))
"""The gauge rule passed where there is no gauge penalty (the kernel reads none)."""


class CellModel:
    """Energy of one periodic cell of the stitch ``params.stitch`` at given parameters
    and fidelity."""

    def __init__(self, params: StitchParams, fidelity: Fidelity | None = None) -> None:
        self.params = params
        self.fidelity = fidelity or Fidelity()
        self.stitch: Stitch = get_stitch(params.stitch)
        if len(self.stitch.contact_classes) != N_CLASSES:
            raise ValueError(f"stitch {self.stitch.name}: {len(self.stitch.contact_classes)} "
                             f"contact classes, the contact kernel sorts into {N_CLASSES}")  # fmt: skip
        self.image_group = image_group(self.stitch)
        """The stitch's image group (``stitches.images``): the contact kernels over its
        images."""
        self._geometry = self.stitch.control_points
        self._seg_w = self.stitch.segment_weights
        self._cp, self._jac = self.stitch.buffers()
        self.ip: InternalParams = params.internal()
        nodes, weights = gauss_legendre(self.fidelity.quadrature_nodes)
        self._qtab = basis_tables(nodes)
        self._qw = weights
        self._ctab = np.ascontiguousarray(
            basis_tables(midpoints(self.fidelity.samples_per_segment))[:2]
        )
        self._aq = np.empty((2, 0))
        """The arclength rule of contact samples placed by arclength (a free yarn's,
        ``Fidelity.contact_sampling``, ``kernels.arclength``); empty: the samples sit at
        the curve parameters of ``_ctab``."""
        free_yarn = self.stitch.gauge is not None and self.image_group.checks_resolution
        sampling = self.fidelity.sampling_for(free_yarn)
        if sampling != "parameter":
            self._aq = arclength_rule(ARC_PANELS, ARC_NODES)
            if sampling == "yarn_arclength":  # a third row asks for the whole yarn's
                self._aq = np.ascontiguousarray(np.vstack([self._aq, self._aq[:1]]))
        self.sampling = sampling
        """Where this model's contact samples sit: "parameter", "arclength" or
        "yarn_arclength" (its state bounds follow, ``relax.problem``)."""
        gauged = free_yarn and sampling == "yarn_arclength"
        self._gauge = self.stitch.gauge if gauged else None
        self.gauge = np.array(self._gauge.entries if self._gauge else (), dtype=np.int64)
        """The entries a relaxation holds fixed (``gauged``): a free yarn's end speeds
        when its samples sit along the yarn (docs/model.md §11, "The speeds as a
        gauge"); empty otherwise. With them, the energy's gradient holds the gauge's
        penalty on the joints' slides (``Energies.gauge_energy``)."""
        self._mode = IMAGES_CUTOFF if self.fidelity.images == "cutoff" else IMAGES_REFERENCE
        self._grad_e = np.empty(self.stitch.n_state)
        self._grad_l = np.empty(self.stitch.n_state)
        self._finer: CellModel | None = None  # twice the samples (resolution_change)
        self.skew = 0.0
        """The wale vector's x component s_x (mm): the cell's lattice is t_c = (a_x, 0),
        t_w = (s_x, a_y), so s_x = γ a_y0 is a prescribed simple shear γ (a sweep along a
        shear path sets it, ``paths``; 0 otherwise). Not a state entry: the yarn's shape
        relaxes at each skew. Only an image group that ``shears`` takes one."""

    def _geometry_of(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The stitch's control points and Jacobian of state ``x``, in this model's
        buffers (overwritten by the next call)."""
        self._geometry(x, self._cp, self._jac)
        return self._cp, self._jac

    def _call(self, x: np.ndarray, with_grad: bool) -> tuple[float, float, float, float]:
        x = self._as_state(x)
        cp, jac = self._geometry_of(x)
        return self.image_group.energy(self, cp, jac, x, with_grad)

    def gauge_penalty_args(self) -> tuple[np.ndarray, float]:
        """(the rule of the segments' lengths, the stiffness in mJ/mm²) of the gauge's
        penalty that the pattern kernel sums with the energy; stiffness 0 without a gauge
        or with it released (``gauge`` emptied: benchmarks, tests)."""
        if self._gauge is None or not self.gauge.size:
            return _NO_RULE, 0.0
        return self._gauge.rule, self._gauge.stiffness

    def energies(self, x: np.ndarray) -> Energies:
        """Bending and contact energy (mJ) and yarn length (mm) of state ``x``."""
        return Energies(*self._call(x, False))

    def energy_and_gradients(
        self, x: np.ndarray, neighbours: NeighbourList | None = None
    ) -> tuple[Energies, np.ndarray, np.ndarray]:
        """Energies plus the exact gradients dE/dx and dl/dx, each shape (n,); with a
        gauge (``gauge``) dE/dx is that of ``Energies.objective``, E plus the gauge's
        penalty, what a relaxation minimises.

        With a ``NeighbourList`` (from ``neighbour_list``) the contact sum runs over
        its pairs: the same numbers, bit for bit, faster; the list rebuilds itself
        when the state has moved too far for it.
        """
        if neighbours is None or not self.image_group.lists_neighbours:
            energies = Energies(*self._call(x, True))
        else:
            energies = Energies(*self._call_listed(self._as_state(x), neighbours))
        return energies, self._grad_e.copy(), self._grad_l.copy()

    def neighbour_list(self, x: np.ndarray, skin: float = 0.1) -> NeighbourList:
        """A Verlet list of the contact candidates around state ``x`` (skin in mm)."""
        nl = NeighbourList(skin)
        self._rebuild(self._as_state(x), nl)
        return nl

    def _rebuild(self, x: np.ndarray, nl: NeighbourList) -> None:
        cp = self.control_points(x)
        nl.arrays = build_neighbour_list(*self.image_group.neighbour_args(self, cp, x, nl.skin))
        nl.rebuilds += 1

    def _call_listed(self, x: np.ndarray, nl: NeighbourList) -> tuple[float, float, float, float]:
        cp, jac = self._geometry_of(x)
        eb, ec, length, valid = self.image_group.energy_listed(self, cp, jac, x, nl.arrays)
        if not valid:  # the sums came from the full search; refresh the list here
            self._rebuild(x, nl)
        return eb, ec, length, 0.0  # a listed sum's stitch has no gauge

    def gauged(self, x: np.ndarray) -> np.ndarray:
        """State ``x`` in this model's gauge (``gauge``): unchanged where there is none
        or it holds already; a gauged state (its end speeds equal to within
        ``GAUGE_RTOL``: of another yarn length, or a copy perturbed by round-off, whose
        perturbation of the other entries is kept) with its end speeds set to this one's
        L/8; any other state (a shipped start, a state sampled by parameter)
        re-interpolated at equal fractions of its arclength (``Gauge.regauge``). A new
        array where it changes."""
        if not self.gauge.size:
            return x
        x = self._as_state(x)
        speeds = x[self.gauge]
        speed = self.ip.L * self.stitch.cell_stitches / self.stitch.n_segments
        if np.all(speeds == speed):
            return x
        if np.ptp(speeds) <= GAUGE_RTOL * abs(speeds[0]):
            out = x.copy()
            out[self.gauge] = speed
            return out
        assert self._gauge is not None
        return self._gauge.regauge(x, self.control_points(x), self.ip.L)

    def control_points(self, x: np.ndarray) -> np.ndarray:
        """The S segments' control points in path order, shape (S, 6, 3), mm (a new
        array)."""
        return self.control_points_and_jacobian(x)[0]

    def control_points_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Control points (S, 6, 3) and d(control points)/dx, shape (S, 6, 3, n) (new
        arrays)."""
        cp, jac = self.stitch.buffers()
        self._geometry(self._as_state(x), cp, jac)
        return cp, jac

    def check_start(self, x: np.ndarray, label: str = "start") -> float:
        """min ζ of a start ``x`` of this stitch (at this model's samples, where they sit),
        or InputError naming the segment of the cell and the image where the hard cores
        overlap (``stitches.patterns.check_start``; numpy where the samples sit by
        parameter, so that a command can check a start before any kernel compiles; a free
        yarn's samples along it are placed by the compiled check). The same ζ as
        ``min_zeta``, for every stitch."""
        ip = self.ip
        x = self._as_state(x)
        return check_start(self.control_points(x), *self.stitch.cell_periods(x), ip.r, ip.rc,
                           self.stitch.mirror_parity, label, self.fidelity.samples_per_segment,
                           compiled=False, arc_rule=self._aq,
                           segment_names=self.stitch.segment_names)  # fmt: skip

    def min_zeta(self, x: np.ndarray) -> float:
        """Smallest compression zeta over all counted contacts (1.0 if none);
        below 1e-5 the hard cores overlap (docs/model.md §6)."""
        x = self._as_state(x)
        return self.image_group.min_zeta(self, self.control_points(x), x)

    def resolution_change(self, x: np.ndarray, contact_energy: float | None = None) -> str:
        """For a stitch with mirrored images (a free yarn): "" if the contact sum of state
        ``x`` holds with twice the samples per segment (no hard-core overlap there, and
        E_c within ``RESOLUTION_RTOL`` of this model's), else what it finds. By default
        the samples sit at fixed curve parameters, so a free yarn can space them out where
        it crosses itself and let hard cores pass between them (docs/model.md §11,
        "Resolution"); the finer model keeps this one's ``contact_sampling``. Where the cores overlap with twice the samples the answer starts
        with ``CORES_OVERLAP`` (a state too tight to knit, as one whose cores overlap
        at the model's samples). Stitches of translations alone are not checked ("")."""
        if not self.image_group.checks_resolution:
            return ""
        fine = self._finer
        if fine is None:
            twice = 2 * self.fidelity.samples_per_segment
            fine = self._finer = CellModel(self.params, self.fidelity.model_copy(
                update={"samples_per_segment": twice}))  # fmt: skip
        fine.skew = self.skew
        x = self._as_state(x)
        if contact_energy is None:
            contact_energy = self.energies(x).contact_energy
        ec = fine.energies(x).contact_energy
        if abs(ec - contact_energy) <= RESOLUTION_RTOL * contact_energy:
            # resolved; overlapping cores would have raised E_c by far more (a pair with
            # zeta below CORE_EPS alone adds V(CORE_EPS) ~ 10^2 mJ, §6)
            return ""
        zeta = fine.min_zeta(x)
        n = fine.fidelity.samples_per_segment
        if zeta < CORE_EPS:
            return (f"{CORES_OVERLAP} with {n} samples per segment (smallest zeta {zeta:.3g}), "
                    f"apart only between the {n // 2} of the model")  # fmt: skip
        return (f"contact under-resolved: E_c = {contact_energy:.4g} mJ, with {n} samples "
                f"per segment {ec:.4g} mJ")  # fmt: skip

    def skew_force(self, x: np.ndarray) -> float:
        """dE/ds_x at state ``x`` (N): the energy's derivative with respect to the wale
        vector's skew at fixed shape, exact (the contact sum's image offsets; the bending
        energy does not depend on it). At a relaxed state it is the derivative of the
        relaxed energy (the shape is stationary, the length constraint does not involve
        s_x), so the shear stress σ_xy = F_s / a_x0 (N/mm)."""
        x = self._as_state(x)
        return self.image_group.skew_force(self, self.control_points(x), x)

    def topology_change(self, x: np.ndarray) -> str:
        """For a stitch with mirrored images: "" if state ``x`` shows the crossings of
        the stitch's first shipped start (``topology.topology_word``: their order for
        garter, the rows' interlocking for rib; docs/model.md §11), else what changed
        (the image group's check, ``stitches.images``). Stitches of translations alone
        are not checked ("")."""
        return self.image_group.topology_change(self, self._as_state(x))

    def contact_forces_by_class(self, x: np.ndarray) -> np.ndarray:
        """Contact forces on the cell by class of image offset, shape (5, 3), N.

        Rows: the stitch's ``contact_classes`` (stockinette: self, same row, nearest and
        next-nearest same column, other; a pattern with mirrored images: self, same
        row, same column, mirrored, other, ``kernels.mirrored``). Columns x, y: the
        class's generalised force on the cell period, F_a = -dE_c(class)/da at fixed
        shape parameters (positive: the contacts push the cell to extend along a;
        negative: they pull it together). Summed over the classes they are -dE_c/da; adding the bending
        term and the length constraint's share gives the cell's total force on a
        (``Relaxation.period_forces``), zero at zero force. Column z: the push out
        of plane (>= 0). Each physical contact counts twice, as in E_c (paper SI
        "Contact Forces").
        """
        return self.contacts_by_class(x)[0]

    def contacts_by_class(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(forces (5, 3) N as in ``contact_forces_by_class``, energies (5,) mJ):
        the contact energy of each class; the five add up to E_c."""
        x = self._as_state(x)
        cp, jac = self.control_points_and_jacobian(x)
        dcp = np.ascontiguousarray(jac[..., -2:])
        forces = np.empty((N_CLASSES, 3))
        energies = np.empty(N_CLASSES)
        self.image_group.forces_by_class(self, cp, dcp, x, forces, energies)
        return forces, energies

    def contact_pair_forces_by_class(self, x: np.ndarray, weighted: bool = False) -> np.ndarray:
        """Pair forces between sampled yarn points by contact class, shape (5, 3), N.

        The paper's contact forces (SI "Contact Forces", Table 2, Table S3, Fig. 6h;
        docs/model.md §9): every contact's pair force f = -dV/dR along the
        separation, on both of its samples, projected on x, y, z; positive extends
        the fabric (pushes the two stitches apart along an axis on which they are
        offset, else pushes the sample away from its own stitch's mid-plane).
        Rows: the stitch's ``contact_classes`` (a pattern's over its mirrored images too,
        ``kernels.mirrored.mirrored_pair_forces_by_class``). Unweighted, the bare force
        between two samples, whose sums depend on the sampling (the paper's 10 samples per
        segment); ``weighted=True`` multiplies each pair by ds ds' as in E_c (N mm^2), the
        sampling-independent integral.
        """
        x = self._as_state(x)
        forces = np.empty((N_CLASSES, 3))
        self.image_group.pair_forces_by_class(self, self.control_points(x), x, weighted, forces)
        return forces

    def _as_state(self, x: np.ndarray) -> np.ndarray:
        return as_state(x, self.stitch)

    def thickness(self, x: np.ndarray, samples: int = 64) -> float:
        """The fabric's thickness dz = z_max - z_min + 2r of the centre-line over the
        cell and all its images (paper SI S4; ``analysis.volumes.fabric_depth``: the
        cell's own z-range for a fabric of translations, that of the cell and its mirror
        image for a pattern with purl stitches), mm."""
        return fabric_depth(self.control_points(x), self.ip.r, self.stitch.mirror_parity,
                            samples)  # fmt: skip

    def max_curvature(self, x: np.ndarray, samples: int = 64) -> float:
        """Largest curvature |r' x r''| / |r'|^3 of the centre-line (1/mm), sampled at
        ``samples`` evenly spaced parameters of every segment (ends included); above
        1/r the yarn's tube folds on itself."""
        cp = self.control_points(x)
        d1, d2 = np.einsum("dti,sic->dstc", even_tables(samples)[1:3], cp)
        speed = np.linalg.norm(d1, axis=-1)
        return float(np.max(np.linalg.norm(np.cross(d1, d2), axis=-1) / speed**3))


def as_state(x: np.ndarray, stitch: Stitch) -> np.ndarray:
    """``x`` as a contiguous float64 state of ``stitch``; ValueError if it has the wrong
    shape or a period that is not > 0."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (stitch.n_state,):
        raise ValueError(f"a {stitch.name} state has {stitch.n_state} entries, got shape "
                         f"{x.shape}")  # fmt: skip
    if x[-2] <= 0.0 or x[-1] <= 0.0:
        raise ValueError(f"cell periods must be > 0, got a_x = {x[-2]}, a_y = {x[-1]}")
    return x
