"""The stitch interface: one geometry as a bundle of plain arrays and functions.

In the spirit of a JAX-MD ``space``: a ``Stitch`` is what the generic kernels and
every layer above them consume, so that a new stitch pattern is a new bundle, not a
change to the kernels, the relaxation, the sweeps, the store or the renderer
(docs/adding-a-stitch.md). Its contract:

* **state layout**: a state ``x`` is a float64 vector (``n_state``,); its last two
  entries are the cell periods ``a_x`` (along the course) and ``a_y`` (along the
  wale), mm; the others are shape parameters named by ``state_names``.
* **geometry**: ``control_points(x, cp, jac)`` (a numba function) fills the control
  points ``cp`` (``n_segments``, 6, 3), mm, of the cell's quintic Bézier segments in
  path order, and their exact Jacobian ``jac`` (``n_segments``, 6, 3, ``n_state``),
  ``jac[s, i, c, k] = d cp[s, i, c] / d x[k]``. Consecutive segments join with C2
  continuity; the last one ends where the first starts, shifted by the periods in
  ``closing_shift``.
* **bending**: ``segment_weights`` (``n_segments``,): how many times each segment's
  elastica energy counts in the cell (symmetric copies counted once, weighted).
* **images**: ``images`` names the operations that generate the fabric from the
  cell. ``"translations"``: images at m t_c + n t_w (t_c = (a_x, 0, 0),
  t_w = (0, a_y, 0)) for all integers m, n, which the contact kernel enumerates;
  patterns with reflections (purl stitches: z -> -z plus a shift) declare
  ``"glides"`` and their ``mirror_parity`` (docs/model.md §11).
* **contact classes**: ``contact_classes`` names the rows of the contact forces by
  class, in the contact kernel's order of image offsets.
* **starts**: ``start(i)`` is the i-th shipped starting state (1-based) of the
  ``n_starts``; ``bounds(L, r)`` gives generous physical (lower, upper) arrays
  (``n_state``,), ±inf where free; ``twist_index`` is the entry bounded by the
  twist constraint cos(x[i]) >= c_tw (None: no such constraint).
* **drawing**: the renderer draws the segments in ``path_order`` as one yarn and
  repeats it by ``closing_shift`` (in periods) along a row, each copy mirrored where
  ``images`` and ``mirror_parity`` say so.

Geometry kernels load on first use (``control_points``), so that reading a stitch's
layout (the store's dimension labels, ``knitsweep status``) imports no numba.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from typing import Literal

import numpy as np

from ..errors import InputError

ImageGroup = Literal["translations", "glides"]
"""The symmetry operations that generate the fabric from one cell."""

TRANSLATION_CLASSES = ("self", "same_row", "nn_column", "nnn_column", "other")
"""Contact classes of a fabric of translated cells, by image offset (m, n): self (0, 0),
same row (n = 0, m != 0), nearest and next-nearest same column (m = 0, |n| = 1, 2),
other; the contact kernel's order (``kernels.forces.contact_class``, docs/model.md §9)."""


MIRROR_CLASSES = ("self", "same_row", "same_column", "mirrored", "other")
"""Contact classes of a fabric of translated and mirrored cells (garter, rib, seed): as
``kernels.mirrored.MIRROR_CLASSES`` (the mirrored class: the images mirrored through the
fabric plane)."""


def is_mirrored(parity: tuple[int, int], m: int, n: int) -> bool:
    """Whether the image at lattice offset (m, n) is mirrored (z -> -z) for mirror
    parity (pm, pn): pm m + pn n odd (docs/model.md §11; the compiled kernels' twin is
    ``kernels.mirrored.is_mirrored``)."""
    return bool((parity[0] * m + parity[1] * n) % 2)


MIRROR = np.array([1.0, 1.0, -1.0])
"""M = diag(1, 1, -1): the mirror z -> -z through the fabric plane z = 0."""


def image_points(points: np.ndarray, m: int, n: int, a_x: float, a_y: float,
                 parity: tuple[int, int] = (0, 0), skew: float = 0.0) -> np.ndarray:  # fmt: skip
    """The cell's ``points`` (..., 3), mm, in its image at lattice offset (m, n):
    g p = M^mu p + m t_c + n t_w, t_c = (a_x, 0), t_w = (skew, a_y) (``skew`` 0 but in a
    sheared cell), mirrored (M) when ``is_mirrored(parity, m, n)``
    (docs/model.md §11; the compiled kernels' twin is the sign sz = -1 of a mirrored
    partner's z in ``kernels.mirrored``). A new array."""
    if is_mirrored(parity, m, n):
        points = points * MIRROR
    return points + np.array([m * a_x + n * skew, n * a_y, 0.0])


@dataclass(frozen=True, eq=False)
class Gauge:
    """How a free yarn fixes its parametrisation (``stitches.stockinette_free.gauge``):
    the ``entries`` a relaxation holds at L / n_segments (its end speeds), ``regauge(x,
    control_points, L)`` bringing any state into the gauge with its curve kept, and the
    weak term on the joints' slides that a relaxation minimises with the energy,
    ``stiffness`` (mJ/mm²) × Σ_s (ℓ_s − ℓ̄)² over the segments' lengths ℓ_s by the
    quadrature ``rule`` (2, K) (nodes, weights on [0, 1]), which the pattern kernel sums
    with the energy (``kernels.pattern_cell``)."""

    entries: tuple[int, ...]
    regauge: Callable[[np.ndarray, np.ndarray, float], np.ndarray]
    stiffness: float
    rule: np.ndarray


@dataclass(frozen=True, eq=False)
class Stitch:
    """One stitch geometry (the module docstring states the contract)."""

    name: str
    description: str
    state_names: tuple[str, ...]
    n_segments: int
    segment_weights: np.ndarray
    bounds: Callable[[float, float], tuple[np.ndarray, np.ndarray]]
    twist_index: int | None
    starts: tuple[str, ...]
    data_package: str
    geometry_module: str
    images: ImageGroup = "translations"
    contact_classes: tuple[str, ...] = TRANSLATION_CLASSES
    path_order: tuple[int, ...] = ()
    closing_shift: tuple[int, int] = (1, 0)
    mirror_parity: tuple[int, int] = (0, 0)
    """With ``images = "glides"``: image (m, n) is mirrored (z -> -z) when
    pm m + pn n is odd (docs/model.md §11; garter (0, 1), rib (1, 0), seed (1, 1))."""
    rough: bool = False
    """Whether the zero-force energy has shallow local minima that a relaxation lands in
    by the path it takes (the patterns' free yarns, docs/model.md §11: Newton crawls on
    their indefinite 87 × 87 Hessians, and Newton and SLSQP end in different minima). Then
    ``relax.walk_starts`` relaxes the intermediate stages of a continuation with SLSQP
    and the last one with two minimisers, keeping the lower minimum
    (``relax.continuation.relax_rough``). False for every stitch of translations alone:
    their relaxations are unchanged."""
    stage_dL_mm: float | None = None
    """Largest change of L (mm) per continuation stage for this stitch, at least
    ``SolverSettings.continuation_dL_mm`` (None: that setting). Rib's shipped starts
    (11.28 mm) reach 9.3–13.3 mm in one stage of 2 mm; garter's rows come apart in
    stages of 0.5 mm, so it keeps the setting."""
    gauge: Gauge | None = None
    """A free yarn's parametrisation gauge, used when its contact samples sit along the
    yarn by arclength (docs/model.md §11); None for a stitch without one (the ansatz)."""
    cell_stitches: int = 1
    """Stitches in the cell along the course (a chart's row, ``stitches.charts``; 1 for one
    stitch): the state's periods are per stitch, the cell's course period is this many
    times a_x, and its energies and length are reported per stitch (``cell_periods``)."""
    _loaded: dict = field(default_factory=dict, repr=False)  # kernels, starts: loaded once

    def __post_init__(self) -> None:
        if len(self.segment_weights) != self.n_segments:
            raise ValueError(f"{self.name}: {len(self.segment_weights)} segment weights for "
                             f"{self.n_segments} segments")  # fmt: skip
        if self.state_names[-2:] != ("a_x", "a_y"):
            raise ValueError(f"{self.name}: a state must end with the periods a_x, a_y")
        if self.images == "translations" and any(self.mirror_parity):
            raise ValueError(f"{self.name}: a fabric of translations mirrors no image "
                             f"(mirror_parity {self.mirror_parity})")  # fmt: skip
        if not self.path_order:
            object.__setattr__(self, "path_order", tuple(range(self.n_segments)))

    # ---- layout -------------------------------------------------------------------
    @property
    def n_state(self) -> int:
        """Entries of a state vector."""
        return len(self.state_names)

    @property
    def n_shape(self) -> int:
        """Shape parameters: every entry but the two periods."""
        return self.n_state - 2

    @property
    def idx_ax(self) -> int:
        return self.n_state - 2

    @property
    def idx_ay(self) -> int:
        return self.n_state - 1

    @property
    def segment_names(self) -> tuple[str, ...] | None:
        """What a message calls each segment (None: "segment s"; a chart names its
        stitch)."""
        return None

    @property
    def keeps_linking(self) -> bool:
        """Whether a relaxation keeps the rows' linking rather than their crossings
        (``topology.stitch_topology``): a chart's row of knit and purl stitches with two
        of a kind side by side, whose knit ribs fold over its purl ribs."""
        return False

    @property
    def mixes_row(self) -> bool:
        """Whether a row of the fabric holds knit and purl stitches (its columns mirrored:
        rib, seed; a chart's row of both), whose columns slide behind one another
        (``topology.topology_word``)."""
        return bool(self.mirror_parity[0])

    def cell_periods(self, x: np.ndarray) -> tuple[float, float]:
        """The cell's periods (course, wale), mm, of state ``x``: ``cell_stitches`` a_x and
        a_y (the images' lattice, which the contact sums and checks take)."""
        return float(x[-2]) * self.cell_stitches, float(x[-1])

    def period_index(self, direction: str) -> int:
        """The state entry of the period a pull in ``direction`` ('x' or 'y') fixes."""
        return {"x": self.idx_ax, "y": self.idx_ay}[direction]

    # ---- geometry -----------------------------------------------------------------
    @property
    def control_points(self) -> Callable[[np.ndarray, np.ndarray, np.ndarray], None]:
        """The compiled ``control_points(x, cp, jac)`` kernel (imported on first use)."""
        fn = self._loaded.get("control_points")
        if fn is None:
            fn = importlib.import_module(self.geometry_module).state_to_control_points
            self._loaded["control_points"] = fn
        return fn

    def buffers(self) -> tuple[np.ndarray, np.ndarray]:
        """Fresh (cp, jac) arrays of this stitch's shapes, for ``control_points``."""
        return (np.empty((self.n_segments, 6, 3)),
                np.empty((self.n_segments, 6, 3, self.n_state)))  # fmt: skip

    # ---- starts -------------------------------------------------------------------
    @property
    def n_starts(self) -> int:
        return len(self.starts)

    def start(self, index: int = 1) -> np.ndarray:
        """The ``index``-th shipped starting state (1-based), shape (``n_state``,)."""
        if not 1 <= index <= self.n_starts:
            raise InputError(f"shipped state index = {index}: must be in 1..{self.n_starts}")
        return self.shipped_starts()[index - 1].copy()

    def shipped_starts(self) -> tuple[np.ndarray, ...]:
        """Every shipped starting state, read from the package once and kept: a task
        then opens no file, so that its wall-time budget (a signal) cannot cut one
        off half-opened (``service.worker.prepare`` reads them before any task)."""
        starts = self._loaded.get("starts")
        if starts is None:
            starts = tuple(self._read_start(i) for i in range(1, self.n_starts + 1))
            self._loaded["starts"] = starts
        return starts

    def _read_start(self, index: int) -> np.ndarray:
        text = (resources.files(self.data_package) / self.starts[index - 1]).read_text()
        x = np.array([float(v) for v in text.split()])  # as formats.read_state parses
        if x.shape != (self.n_state,):
            raise ValueError(f"{self.name} start {index}: {x.size} numbers, not {self.n_state}")
        x.setflags(write=False)
        return x
