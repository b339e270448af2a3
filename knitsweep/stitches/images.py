"""Image groups: the symmetry operations that generate a fabric from one cell, each an
object that owns the compiled contact kernels summing over its images (docs/model.md §6,
§9, §11).

``Stitch.images`` declares a stitch's group by name; ``image_group(stitch)`` makes the
object, which ``CellModel`` and the compile step call instead of asking which group
it is. Every group has one interface:

* ``energy(m, cp, jac, x, with_grad) -> (E_b, E_c, length)``: the cell's energies and
  length (mJ, mm), the gradients into ``m``'s buffers when ``with_grad``;
* ``lists_neighbours``: whether a Verlet list (``energy_listed``) serves its contact sum;
* ``min_zeta(m, cp, x)``: the smallest compression over its images;
* ``forces_by_class(m, cp, dcp, x, forces, energies)`` and
  ``pair_forces_by_class(m, cp, x, weighted, forces)``: forces (5, 3) N by its
  ``contact_classes``;
* ``topology_change(m, x)``: "" or what changed in the crossings (a group whose yarn can
  change its crossings in a relaxation checks them; translations of the crossover ansatz
  cannot); ``checks_resolution``: whether the contact sum's sampling is checked
  (``CellModel.resolution_change``);
* ``entry_points``: its kernels' names in numba's cache beyond every task's, and
  ``energy_entry_points`` those of its energy alone (``compilation.kernel_entry_points``);
  ``compile_seconds``: about how long compiling them takes; ``compile(m, what, tick)``:
  compile them for ``m``'s argument types without running them.

``m`` is a ``CellModel`` (its parameters ``ip``, tables ``_qtab``, ``_qw``, ``_ctab``,
weights ``_seg_w``, image mode ``_mode`` and gradient buffers). The argument lists of the
kernels are spelled once, here (``*_args``), for the calls and for their compilation.
Translations: the fabric is the cell at m t_c + n t_w. Glides: the image (m, n) is
mirrored through z = 0 when pm m + pn n is odd (``mirror_parity``; garter, rib, seed).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from ..kernels.cell import cell_energy, cell_energy_listed
from ..kernels.checks import compile_checks
from ..kernels.contact import find_contacts, min_zeta
from ..kernels.forces import N_CLASSES, contact_forces_by_class, contact_pair_forces_by_class
from ..kernels.mirrored import (
    N_MIRROR_CLASSES,
    mirrored_contact_energy,
    mirrored_forces_by_class,
    mirrored_pair_forces_by_class,
)
from ..kernels.neighbours import NO_LIST, build_neighbour_list
from ..kernels.pattern_cell import pattern_cell_energy
from .patterns import min_zeta_where
from .topology import TOPOLOGY_CHANGED, stitch_topology


def _nothing() -> None:
    pass


def _signature(args: tuple, tick: Callable[[], None]) -> tuple:
    """numba's types of a kernel's ``args``, built just before it compiles (``tick``
    first: the caller's hook, e.g. to take a signal between kernels)."""
    import numba

    tick()
    return tuple(numba.typeof(a) for a in args)


class Translations:
    """The fabric as the cell translated by the course and wale periods (stockinette):
    the contact kernels of ``kernels.cell``, ``contact`` and ``forces``, with or without
    a Verlet list."""

    name = "translations"
    lists_neighbours = True
    checks_resolution = False
    entry_points: tuple[str, ...] = ()
    energy_entry_points = ("knitsweep.kernels.cell.cell_energy_listed",)
    compile_seconds: ClassVar[dict[str, float]] = {"run": 29, "energy": 17}
    """About how long compiling a task's kernels (``run``) or one energy's takes once on an
    idle machine, s (``compilation.COMPILE_SECONDS``, where the measurement is told)."""
    parity = (0, 0)

    shears = False
    """Whether its kernels take a skewed wale vector (``CellModel.skew``, a sheared cell)."""

    def energy_args(self, m, cp, jac, x, with_grad) -> tuple:
        """The arguments of ``cell_energy`` (the first ones of ``cell_energy_listed``)."""
        if m.skew != 0.0:
            raise ValueError(f"stitch {m.stitch.name}: its images are translations of a "
                             "mirror-symmetric ansatz, which cannot shear")  # fmt: skip
        ip = m.ip
        return (cp, jac, x[-2], x[-1], m._qtab, m._qw, m._ctab, m._seg_w, ip.bend, ip.reg,
                ip.r, ip.rc, ip.k, ip.p, m._mode, with_grad, m._grad_e, m._grad_l)  # fmt: skip

    def energy(self, m, cp, jac, x, with_grad) -> tuple[float, float, float, float]:
        """(E_b, E_c, length, gauge penalty: none here) with the gradients (``energy_args``)."""
        return (*cell_energy(*self.energy_args(m, cp, jac, x, with_grad)), 0.0)

    def energy_listed(self, m, cp, jac, x, arrays) -> tuple[float, float, float, bool]:
        """The energies and gradients over a neighbour list's pairs (``arrays``), and
        whether the list was still valid."""
        return cell_energy_listed(*self.energy_args(m, cp, jac, x, True), *arrays)

    def neighbour_args(self, m, cp, x, skin) -> tuple:
        return (cp, m._ctab, x[-2], x[-1], m.ip.r, m._mode, skin)

    def min_zeta(self, m, cp, x) -> float:
        ip = m.ip
        return min_zeta(cp, m._ctab, x[-2], x[-1], ip.r, ip.rc, m._mode)

    def forces_args(self, m, cp, dcp, x, forces, energies) -> tuple:
        ip = m.ip
        return (cp, dcp, m._ctab, x[-2], x[-1], ip.r, ip.rc, ip.k, ip.p, m._mode, forces,
                energies)  # fmt: skip

    def forces_by_class(self, m, cp, dcp, x, forces, energies) -> None:
        contact_forces_by_class(*self.forces_args(m, cp, dcp, x, forces, energies))

    def pair_forces_args(self, m, cp, x, weighted, forces) -> tuple:
        ip = m.ip
        return (cp, m._ctab, x[-2], x[-1], ip.r, ip.rc, ip.k, ip.p, m._mode, weighted, forces)

    def pair_forces_by_class(self, m, cp, x, weighted, forces) -> None:
        contact_pair_forces_by_class(*self.pair_forces_args(m, cp, x, weighted, forces))

    def topology_change(self, m, x) -> str:
        return ""

    def skew_force(self, m, cp, x) -> float:
        """dE/ds_x: translations of a mirror-symmetric ansatz do not shear (0 at s_x = 0)."""
        self.energy_args(m, cp, m._jac, x, False)  # refuses a skew
        return 0.0

    def compile(self, m, what: str, tick: Callable[[], None] = _nothing) -> None:
        """Compile (or load) this group's kernels for ``m``'s argument types: with or
        without a neighbour list (``cell_energy`` is that kernel with ``NO_LIST``); the
        checks and forces unless ``what == "energy"``; the pair forces with "all".
        ``tick`` is called before each kernel compiles."""
        x = m.stitch.start(1)
        cp, jac = m.stitch.buffers()
        args = self.energy_args(m, cp, jac, x, True) + NO_LIST
        cell_energy_listed.compile(_signature(args, tick))
        if what == "energy":
            return
        build_neighbour_list.compile(_signature(self.neighbour_args(m, cp, x, 0.1), tick))
        find_contacts.compile(_signature((cp, m._ctab, x[-2], x[-1], m.ip.r, m._mode), tick))
        dcp = np.ascontiguousarray(jac[..., -2:])
        forces, energies = np.empty((N_CLASSES, 3)), np.empty(N_CLASSES)
        contact_forces_by_class.compile(
            _signature(self.forces_args(m, cp, dcp, x, forces, energies), tick)
        )
        if what == "all":  # the post-processing's pair forces: no task calls them
            contact_pair_forces_by_class.compile(
                _signature(self.pair_forces_args(m, cp, x, False, forces), tick)
            )


class Glides(Translations):
    """Translations and glide reflections (knit/purl patterns): the image (m, n) is the
    cell mirrored through z = 0 when pm m + pn n is odd (``parity``), summed by class in
    ``kernels.pattern_cell`` and ``kernels.mirrored``; no neighbour list. A relaxation of
    its free yarn is checked for its crossings and its contact sampling (§11)."""

    name = "glides"
    shears = True
    lists_neighbours = False
    checks_resolution = True
    entry_points = ("knitsweep.kernels.pattern_cell.pattern_cell_energy",)
    energy_entry_points = entry_points
    compile_seconds: ClassVar[dict[str, float]] = {"run": 53, "energy": 20}

    def __init__(self, parity: tuple[int, int]) -> None:
        self.parity = (int(parity[0]), int(parity[1]))

    def energy_args(self, m, cp, jac, x, with_grad) -> tuple:
        ip = m.ip
        ax, ay = m.stitch.cell_periods(x)
        return (cp, jac, ax, ay, m.skew, float(m.stitch.cell_stitches), m._qtab, m._qw,
                m._ctab, m._aq, m._seg_w, ip.bend, ip.reg, ip.r, ip.rc, ip.k, ip.p, *self.parity,
                *m.gauge_penalty_args(), with_grad, m._grad_e, m._grad_l)  # fmt: skip

    def energy(self, m, cp, jac, x, with_grad) -> tuple[float, float, float, float]:
        """(E_b, E_c, length, gauge penalty) per stitch: a cell of several stitches (a
        chart's row) divides its sums and their gradients by their number."""
        out = pattern_cell_energy(*self.energy_args(m, cp, jac, x, with_grad))
        c = m.stitch.cell_stitches
        if c == 1:
            return out
        if with_grad:
            m._grad_e /= c
            m._grad_l /= c
        return out[0] / c, out[1] / c, out[2] / c, out[3] / c

    def energy_listed(self, m, cp, jac, x, arrays):
        raise TypeError("a pattern's contact sum takes no neighbour list")

    def min_zeta(self, m, cp, x) -> float:
        ip = m.ip
        return min_zeta_where(cp, *m.stitch.cell_periods(x), ip.r, ip.rc, self.parity,
                              m.fidelity.samples_per_segment, m._aq, m.skew)[0]  # fmt: skip

    def forces_args(self, m, cp, dcp, x, forces, energies) -> tuple:
        ip = m.ip
        return (cp, dcp, m._ctab, m._aq, *m.stitch.cell_periods(x), m.skew, ip.r, ip.rc, ip.k,
                ip.p, *self.parity, forces, energies)  # fmt: skip

    def forces_by_class(self, m, cp, dcp, x, forces, energies) -> None:
        """Per stitch: in a cell of c stitches the force on a_x is the cell's on its period
        c a_x (``dcp``'s a_x column divided by c), the others and the energies the
        cell's divided by c."""
        c = m.stitch.cell_stitches
        if c > 1:
            dcp = dcp.copy()
            dcp[..., 0] /= c
        mirrored_forces_by_class(*self.forces_args(m, cp, dcp, x, forces, energies))
        if c > 1:
            forces[:, 1:] /= c
            energies /= c

    def pair_forces_args(self, m, cp, x, weighted, forces) -> tuple:
        ip = m.ip
        return (cp, m._ctab, m._aq, *m.stitch.cell_periods(x), m.skew, ip.r, ip.rc, ip.k, ip.p,
                *self.parity, weighted, forces)  # fmt: skip

    def pair_forces_by_class(self, m, cp, x, weighted, forces) -> None:
        mirrored_pair_forces_by_class(*self.pair_forces_args(m, cp, x, weighted, forces))
        forces /= m.stitch.cell_stitches  # per stitch

    def skew_force(self, m, cp, x) -> float:
        """dE/ds_x (N) at the model's skew: the contact sum's explicit derivative (per
        stitch)."""
        ip = m.ip
        gcell, ce = np.zeros(3), np.zeros(N_MIRROR_CLASSES)
        mirrored_contact_energy(cp, m._ctab, m._aq, *m.stitch.cell_periods(x), m.skew, ip.r,
                                ip.rc, ip.k, ip.p, *self.parity, -1, True, np.empty(cp.shape),
                                gcell, ce)  # fmt: skip
        return float(gcell[2]) / m.stitch.cell_stitches

    def topology_change(self, m, x) -> str:
        """ "" if state ``x`` shows the crossings of the stitch's first shipped start
        (``topology.stitch_topology``: their order for garter, the rows' interlocking for
        rib, the linking of the rows for a chart whose knit ribs fold over its purl ribs;
        docs/model.md §11), else what changed."""
        stitch = m.stitch
        ref = stitch._loaded.get("topology_word")
        if ref is None:
            x1 = stitch.start(1)
            ref = stitch_topology(stitch, m.control_points(x1), x1)
            stitch._loaded["topology_word"] = ref
        got = stitch_topology(stitch, m.control_points(x), x, m.skew)
        if got == ref:
            return ""
        if stitch.keeps_linking:
            return (f"{TOPOLOGY_CHANGED}: the oriented crossings with the other rows sum to "
                    f"{_sums(got)} (row offset: sum), the {stitch.name} stitch's to "
                    f"{_sums(ref)}: a yarn passed through another")  # fmt: skip
        count = sum(len(signs) for _, signs in ref)
        return (f"{TOPOLOGY_CHANGED}: the rows cross in projection as {_runs(got)} (row offset: "
                f"signs), the {stitch.name} stitch has {count} crossings as "
                f"{_runs(ref)}")  # fmt: skip

    def compile(self, m, what: str, tick: Callable[[], None] = _nothing) -> None:
        """This group's kernels, then the translations' as well: ``kernels.cached``
        looks for them, so a cache filled by a job of patterns alone must hold them
        too."""
        x = m.stitch.start(1)
        cp, jac = m.stitch.buffers()
        pattern_cell_energy.compile(_signature(self.energy_args(m, cp, jac, x, True), tick))
        if what != "energy":
            tick()
            compile_checks()  # the checks after every relaxation
            forces, energies = np.empty((N_CLASSES, 3)), np.empty(N_CLASSES)
            dcp = np.ascontiguousarray(jac[..., -2:])
            mirrored_forces_by_class.compile(
                _signature(self.forces_args(m, cp, dcp, x, forces, energies), tick)
            )
            if what == "all":  # the post-processing's pair forces
                mirrored_pair_forces_by_class.compile(
                    _signature(self.pair_forces_args(m, cp, x, False, forces), tick)
                )
        Translations.compile(TRANSLATIONS, m, what, tick)


TRANSLATIONS = Translations()


def image_group(stitch) -> Translations:
    """The image group object of a ``Stitch`` (its ``images`` and ``mirror_parity``)."""
    if stitch.images == "translations":
        return TRANSLATIONS
    if stitch.images == "glides":
        return Glides(stitch.mirror_parity)
    raise ValueError(f"stitch {stitch.name}: images = {stitch.images!r}, not an image group")


def _sums(sums) -> str:
    """``topology.linking_sums`` in one line."""
    return " ".join(f"{n:+d}:{v:+d}" for n, v in sums) or "0 with every row"


def _runs(word) -> str:
    """A ``topology_word`` in one line: runs as ``n:+-`` (sign +1 over, -1 under)."""
    if not word:
        return "no crossings"
    return " ".join(f"{n:+d}:" + "".join("+" if s > 0 else "-" for s in signs)
                    for n, signs in word)  # fmt: skip
