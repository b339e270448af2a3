"""The one naming scheme of stored and tabulated quantities: name, unit, long name.

A quantity has a base name (``bending_energy``) and a unit (``mJ``). HDF5 datasets
use the base name and carry ``units`` and ``long_name`` attributes; tables (CSV files,
pandas DataFrames) append the unit to the name: ``bending_energy_mJ``,
``stress_N_per_mm``, ``thickness_mm``. Dimensionless quantities have unit "1" and no
suffix. The stitch parameters keep their job-file names, which carry their units
already (``L_mm``, ``k_mN_per_mm2``). The table of names in docs/units.md is this module's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .paths import LoadPath, load_path
from .stitches import DEFAULT_STITCH, TRANSLATION_CLASSES, get_stitch


@dataclass(frozen=True)
class Quantity:
    """One quantity: base ``name``, ``units`` (UDUNITS-style; "1" if dimensionless)
    and a ``long_name`` (what it is, in words)."""

    name: str
    units: str
    long_name: str

    @property
    def column(self) -> str:
        """The name of its column in a table: the base name plus the unit suffix."""
        return column_name(self.name, self.units)


_SUFFIX = {
    "1": "",
    "mm": "mm",
    "mJ": "mJ",
    "N": "N",
    "N/mm": "N_per_mm",
    "mJ/mm": "mJ_per_mm",
    "1/mm": "per_mm",
    "s": "s",
    "rad": "rad",
    "mN/mm2": "mN_per_mm2",
    "mN mm2": "mN_mm2",
    "mN mm4": "mN_mm4",
}


_UNIT_OF_SUFFIX = sorted(((f"_{s}", u) for u, s in _SUFFIX.items() if s),
                         key=lambda su: -len(su[0]))  # fmt: skip
"""(column suffix, units), longest suffix first."""


def units_of_column(column: str) -> str:
    """The unit a table column's suffix names ("1" without one)."""
    return next((units for suffix, units in _UNIT_OF_SUFFIX if column.endswith(suffix)), "1")


def column_name(name: str, units: str) -> str:
    """``name`` with the suffix of ``units`` (unless it already ends with it)."""
    suffix = _SUFFIX[units]
    if not suffix or name.endswith("_" + suffix) or (units == "s" and name.endswith("seconds")):
        return name
    return f"{name}_{suffix}"


def _q(name: str, units: str, long_name: str) -> tuple[str, Quantity]:
    return name, Quantity(name, units, long_name)


SECANT_STRAIN = 0.02
"""The strain at which the paper measures Y_sec, for simulations and experiments (and
knitsweep its secant Poisson's ratio)."""

ObservableKind = Literal["point", "step", "sweep"]


@dataclass(frozen=True)
class Observable:
    """One computed observable of the observable registry (``OBSERVABLE_REGISTRY``; not
    the protocol's ``config.OBSERVABLES``, what a sweep must determine before it stops), in the spirit
    of ASE's ``implemented_properties``: its entry alone puts it in the results file (a
    dataset or attribute with ``units`` and ``long_name``), the pandas and xarray tables,
    the CSV files and the report.

    ``kind``: ``"point"`` (of a point's winning zero-force state: a points attribute,
    the points table), ``"step"`` (of every step's state: a sweeps dataset, the curves
    table, ``knitsweep sweep``'s CSV), ``"sweep"`` (one number a sweep, reduced from its
    step arrays: the sweeps table). ``method``: the ``model.CellModel`` method that
    computes a point or step observable from a state ``x``; ``from_steps``: for a sweep
    observable, the function of a sweep's step arrays (by name) and its direction
    (``"x"`` or ``"y"``) that gives it. ``stored``:
    computed and written by every run (False: listed, not computed). ``label``: its name
    in the report's headers (HTML); ``table_name``: its name in the tables where that is
    not ``name`` (a point's ``thickness`` is the points table's ``thickness0``)."""

    name: str
    kind: ObservableKind
    units: str
    long_name: str
    method: str = ""
    from_steps: Callable[[Mapping[str, np.ndarray], str], float | None] | None = None
    stored: bool = True
    label: str = ""
    table_name: str = ""

    @property
    def quantity(self) -> Quantity:
        """The stored name's quantity (HDF5 dataset or attribute)."""
        return Quantity(self.name, self.units, self.long_name)

    @property
    def column(self) -> str:
        """Its column in the tables (the table name with the unit suffix)."""
        return column_name(self.table_name or self.name, self.units)


OBSERVABLE_REGISTRY: tuple[Observable, ...] = (
    Observable("thickness", "point", "mm", "fabric thickness at zero force (all images)",
               "thickness",
               label="thickness at rest", table_name="thickness0"),
    Observable("thickness", "step", "mm", "fabric thickness z_max - z_min + 2r of the "
               "centre-line, all images", "thickness"),
    Observable("max_curvature", "point", "1/mm", "largest curvature of the yarn centre-line "
               "at zero force (above 1/r the tube folds on itself)", "max_curvature",
               label="largest curvature at rest", table_name="max_curvature0"),
    Observable("max_curvature", "step", "1/mm", "largest curvature of the yarn centre-line "
               "(above 1/r the tube folds on itself)", "max_curvature"),
    Observable("peak_curvature", "sweep", "1/mm", "largest curvature of the yarn centre-line "
               "along the sweep", from_steps=lambda a, _direction: np.max(a["max_curvature"]),
               label="largest curvature"),
    Observable("poisson_ratio", "sweep", "1", "Poisson's ratio -e_perp/e at strain 0.02 (secant; "
               "the transverse period relaxed to zero force; uniaxial paths)", from_steps=lambda
               a, d: secant_poisson_ratio(a["strain"], a["a_" + load_path(d).transverse])
               if load_path(d).uniaxial else None, label="Poisson's ratio"),
    Observable("transverse_stress_ratio", "sweep", "1", "sigma_perp/sigma_lead at strain 0.02 "
               "(secant; paths that hold or pull the transverse period)", from_steps=lambda a, d:
               secant_stress_ratio(a, load_path(d)), label="transverse stress ratio"),
)  # fmt: skip
"""The observable registry: every observable computed from a state or a sweep, one entry
each (adding one is an entry here and, for a new computation, a ``CellModel`` method)."""


def secant_poisson_ratio(strain: np.ndarray, across: np.ndarray,
                         at: float = SECANT_STRAIN) -> float | None:  # fmt: skip
    """Poisson's ratio of a uniaxial sweep, secant at strain ``at`` (as Y_sec is):
    ν = −ε_⊥(at)/at, ε_⊥ = a_⊥/a_⊥0 − 1 the strain of the transverse period (relaxed to
    zero force at every step), both linearly interpolated between the neighbouring
    steps; None when the sweep stops short of ``at``. Pulled in x it is ν_xy, in y ν_yx."""
    strain = np.asarray(strain, dtype=float)
    across = np.asarray(across, dtype=float)
    if strain.size < 2 or not strain[-1] >= at:
        return None
    return float(-np.interp(at, strain, across / across[0] - 1.0) / at)


def secant_stress_ratio(arrays: Mapping[str, np.ndarray], path: LoadPath,
                        at: float = SECANT_STRAIN) -> float | None:  # fmt: skip
    """σ_⊥/σ_∥ at strain ``at`` along a path that controls both periods (strip biaxial:
    the stress that holds the transverse period; equibiaxial: the anisotropy), both
    envelope stresses (``stress_xx``, ``stress_yy``) interpolated linearly; None on a
    uniaxial path, a sweep short of ``at`` or a file written before they were stored."""
    if path.uniaxial or "stress_xx" not in arrays:
        return None
    strain = np.asarray(arrays["strain"], dtype=float)
    if strain.size < 2 or not strain[-1] >= at:
        return None
    lead, across = (np.interp(at, strain, np.asarray(arrays[f"stress_{d}{d}"], dtype=float))
                    for d in (path.leading, path.transverse))  # fmt: skip
    return float(across / lead) if lead != 0.0 else None


def registered(kind: ObservableKind, stored_only: bool = True) -> tuple[Observable, ...]:
    """The registered observables of ``kind`` (those computed by every run, or all)."""
    return tuple(o for o in OBSERVABLE_REGISTRY if o.kind == kind and (o.stored or not stored_only))


def sweep_observables(arrays: Mapping[str, np.ndarray], direction: str) -> dict[str, float | None]:
    """Every stored sweep observable of a sweep's step ``arrays`` (by stored name) pulled
    in ``direction``, by table column; None where an array it needs is absent (a file
    of an earlier schema)."""
    out: dict[str, float | None] = {}
    for o in registered("sweep"):
        try:
            value = o.from_steps(arrays, direction)
        except KeyError:
            value = None
        out[o.column] = None if value is None else float(value)
    return out


def _registered(kind: ObservableKind) -> list[tuple[str, Quantity]]:
    return [(o.name, o.quantity) for o in registered(kind, stored_only=False)]


PARAMETERS = dict(
    (
        _q("stitch", "1", "stitch pattern (knitsweep.stitches.STITCH_NAMES)"),
        _q("L_mm", "mm", "yarn length per stitch L"),
        _q("k_mN_per_mm2", "mN/mm2", "compression constant k"),
        _q("B_mN_mm2", "mN mm2", "bending modulus B"),
        _q("r_mm", "mm", "yarn radius r"),
        _q("r_core_mm", "mm", "incompressible core radius r_core"),
        _q("p", "1", "contact exponent p"),
        _q("regularization_mN_mm4", "mN mm4", "curvature-derivative regularisation"),
        _q("twist_bound", "1", "bound c_tw on the crossover twist, cos(tw) >= c_tw"),
        _q("L_over_r", "1", "stitch density L/r"),
    )
)
"""The stitch parameters, named as in job files (``stitch``: the pattern's name, text; in
a results file absent for the default stitch, in tables always written out)."""

SERIES_PARAMS = ("stitch", "k_mN_per_mm2", "B_mN_mm2", "r_core_mm", "r_mm", "p",
                 "regularization_mN_mm4", "twist_bound")  # fmt: skip
"""The parameters held fixed along a series in L (the stitch, the paper's k, B, r_core, r,
p, and the regularisation and twist bound, which files of different jobs may differ in):
two stitches are never one series."""
NUMERIC_SERIES_PARAMS = SERIES_PARAMS[1:]
"""The series parameters that are numbers (all but ``stitch``)."""


def value_text(value: object) -> str:
    """A parameter's value as text: a number as ``:g`` (0.1, 90), a stitch as its name."""
    return format(value, "g") if isinstance(value, (int, float)) else str(value)


@dataclass(frozen=True)
class Parameter:
    """Every name of one stitch parameter: its field (job files, tables, HDF5
    attributes), plain-text ``symbol`` and display ``unit`` (tables, progress lines),
    ``math`` symbol (figures, TeX math mode), command-line ``flag`` ("" if none), and
    the authors' config key ("" if none) with the factor from their units to
    knitsweep's (docs/model.md §10)."""

    field: str
    symbol: str
    unit: str
    math: str
    flag: str
    authors_key: str
    authors_factor: float = 1.0


PARAMETER_NAMES = {
    p.field: p
    for p in (
        Parameter("stitch", "stitch", "", r"{\rm stitch}", "--stitch", ""),
        Parameter("L_mm", "L", "mm", "L", "--L", "stitch_length"),
        Parameter("k_mN_per_mm2", "k", "mN/mm²", "k", "--k", "contact_rigidity", 1e3),
        Parameter("B_mN_mm2", "B", "mN·mm²", "B", "--B", "bending_modulus", 2e3),  # from B/2
        Parameter("r_mm", "r", "mm", "r", "--r", "yarn_radius"),
        Parameter("r_core_mm", "r_core", "mm", r"r_{\rm core}", "--r-core", "core_radius"),
        Parameter("p", "p", "", "p", "--p", "contact_exponent"),
        Parameter("regularization_mN_mm4", "reg", "mN·mm⁴", r"{\rm reg}", "--regularization",
                  "regularization", 1e3),
        Parameter("twist_bound", "c_tw", "", r"c_{\rm tw}", "", "max_twist_constraint"),
    )
}  # fmt: skip
"""The one table of the stitch parameters' names, by field."""

PARAM_SYMBOLS = {name: (PARAMETER_NAMES[name].symbol, PARAMETER_NAMES[name].unit)
                 for name in SERIES_PARAMS}  # fmt: skip
"""Plain-text symbol and unit of every series parameter (table headers, labels)."""

_RELAXATION = dict(
    (
        _q("bending_energy", "mJ", "bending energy E_b"),
        _q("contact_energy", "mJ", "contact energy E_c"),
        _q("iterations", "1", "minimiser iterations"),
        _q("evaluations", "1", "energy and gradient evaluations"),
        _q("length_residual", "mm", "yarn length minus L"),
        _q("min_zeta", "1", "smallest compression zeta of any contact (1: none)"),
        _q("kkt_residual", "mJ", "largest stationarity residual |dE - lambda dl| per state entry"),
        _q("relax_seconds", "s", "wall time of the relaxation"),
    )
)
"""What every relaxation reports, per step of a sweep and per start of a point."""


def _shared(name: str) -> tuple[str, Quantity]:
    return name, _RELAXATION[name]


STEP_QUANTITIES = dict(
    (
        _q(
            "a_fixed",
            "mm",
            "the path's leading period (a_x in x pulls, a_y in y pulls; a_y0 + the skew in shear)",
        ),
        _q("a_x", "mm", "cell period along the course, a_x"),
        _q("a_y", "mm", "cell period along the wale, a_y"),
        _q("strain", "1", "strain of the leading period, (a - a0)/a0 (the shear γ in shear)"),
        _q("stress", "N/mm", "2D stress along the path, energy differences / a_perp0"),
        _q("stress_envelope", "N/mm", "2D stress along the path from the length multiplier"),
        _q("stress_xx", "N/mm", "sigma_xx = dE*/da_x / a_y0 (0 where a_x is free)"),
        _q("stress_yy", "N/mm", "sigma_yy = dE*/da_y / a_x0 (0 where a_y is free)"),
        _q("stress_xy", "N/mm", "sigma_xy = dE*/ds_x / a_x0, s_x the wale vector's skew"),
        _shared("bending_energy"),
        _shared("contact_energy"),
        _q("total_energy", "mJ", "total energy E = E_b + E_c"),
        *_registered("step"),
        _q("winner", "1", "start (chain) whose relaxation has the lowest energy"),
        _q("converged", "1", "the winning relaxation converged"),
        _shared("iterations"),
        _shared("evaluations"),
        _shared("min_zeta"),
        _shared("length_residual"),
        _shared("kkt_residual"),
        _shared("relax_seconds"),
        _q("states", "1", "state vector (lengths mm, angles rad; see state_entry)"),
        _q("control_points", "mm", "Bézier control points of the 8 segments"),
        _q("contact_forces", "N", "contact forces by class: -dE_c/da_x, -dE_c/da_y, z push"),
        _q("packing_fraction", "1", "packing fraction V_total/V_cell (tube quasi-Monte Carlo)"),
        _q("packing_fraction_error", "1", "standard error of the packing fraction"),
    )
)
"""Per-step datasets of a sweep (the first dimension is ``step``)."""

START_QUANTITIES = dict(
    (
        _q("x", "1", "relaxed state of each start (lengths mm, angles rad)"),
        _shared("bending_energy"),
        _shared("contact_energy"),
        _q("length", "mm", "yarn length"),
        _q("start_status", "1", "how the relaxation ended"),
        _q("start_message", "1", "the minimiser's message"),
        _shared("iterations"),
        _shared("evaluations"),
        _shared("length_residual"),
        _q("twist_margin", "1", "cos(tw) - c_tw (>= 0: the twist bound holds)"),
        _q("twist_active", "1", "the twist bound is active"),
        _shared("min_zeta"),
        _shared("kkt_residual"),
        _q("length_multiplier", "mJ/mm", "Lagrange multiplier of the length constraint"),
        _q("period_forces", "N", "dE*/da_x, dE*/da_y at the relaxed state (0 at zero force)"),
        _shared("relax_seconds"),
        _q("labels", "1", "where the start came from"),
        _q("stages", "1", "continuation stages from the start's parameters"),
        _q("merged_into", "1", "the start whose continuation this one joined (-1: none)"),
        _q("merged_at", "1", "the continuation stage where it joined (-1: never)"),
        _q("contact_forces", "N", "contact forces by class of the winner"),
        _q("packing_fraction", "1", "packing fraction V_total/V_cell of each start's state"),
        _q("packing_fraction_error", "1", "standard error of the packing fraction"),
    )
)
"""Per-start datasets of a point (the first dimension is ``start``)."""

SWEEP_START_QUANTITIES = dict(
    (
        _q("carried", "1", "the start reached a zero-force state and was pulled as a chain"),
        _q("merged_into", "1", "the start whose chain this one joined (-1: none)"),
        _q("merged_at", "1", "the step where it joined (0: at zero force; -1: never)"),
    )
)
"""Per-start datasets of a sweep (their first dimension is ``start``, not ``step``)."""

AXES = {
    "control_point": tuple(f"P{i}" for i in range(6)),
    "axis": ("x", "y", "z"),
    "contact_class": TRANSLATION_CLASSES,  # a stitch's own: ``axis_labels``
    "component": ("x", "y", "z"),
    "period": ("a_x", "a_y"),
}
"""Labelled trailing dimensions of multi-dimensional datasets that every stitch shares
(``axis_labels`` adds the stitch's own)."""


def axis_labels(dim: str, stitch: str = DEFAULT_STITCH) -> tuple[str, ...] | None:
    """Labels of a trailing dimension (None for a leading one: 0 … n-1): the state
    entries and segments are the stitch's."""
    if dim == "state_entry":
        return get_stitch(stitch).state_names
    if dim == "segment":
        return tuple(f"segment_{i}" for i in range(get_stitch(stitch).n_segments))
    if dim == "contact_class":
        return get_stitch(stitch).contact_classes
    return AXES.get(dim)


TRAILING_DIMS = {
    "x": ("state_entry",),
    "states": ("state_entry",),
    "control_points": ("segment", "control_point", "axis"),
    "contact_forces": ("contact_class", "component"),
    "period_forces": ("period",),
}
"""Trailing dimensions of a dataset by name (after ``step`` or ``start``)."""

SCALARS = dict(
    (
        _q("delta_E_b", "mJ", "bending-energy gap E_b(zero force) - min E_b"),
        _q("delta_E_c", "mJ", "contact-energy gap E_c(zero force) - min E_c"),
        _q("jamming_gap", "mJ", "the pulling direction's jamming gap (x: delta_E_c, y: delta_E_b)"),
        _q("E_b_rest", "mJ", "bending energy at zero force"),
        _q("E_c_rest", "mJ", "contact energy at zero force"),
        _q("E_b_min", "mJ", "smallest bending energy of the sweep"),
        _q("E_c_min", "mJ", "smallest contact energy of the sweep"),
        *_registered("point"),
        _q("seconds", "s", "wall time of the task on its worker"),
        _q("wall_seconds", "s", "wall time of the sweep's computation"),
        _q("relaxations", "1", "relaxations the sweep computed"),
        _q("threshold", "mJ", "energy-gap threshold between jammed and unjammed"),
    )
)
"""Scalar attributes of task groups with units (attributes cannot carry attributes:
their units are these, and their table columns carry the suffix)."""

METRICS = dict(
    (
        _q("Y_sec", "N/mm", "secant modulus sigma(0.02)/0.02 (paper Eq. 1)"),
        _q("stress_at_secant", "N/mm", "stress at the secant strain 0.02"),
        _q("sigma0", "N/mm", "offset stress: zero-strain intercept of the softened regime"),
        _q("softened_slope", "N/mm", "tangent modulus of the softened linear regime"),
        _q("max_stress", "N/mm", "largest stress of the sweep"),
        _q("max_strain", "1", "last strain of the sweep"),
        _q("n_steps", "1", "steps of the sweep, zero force included"),
        _q("a_x0", "mm", "zero-force period a_x0"),
        _q("a_y0", "mm", "zero-force period a_y0"),
        _q("aspect_ratio", "1", "zero-force aspect ratio a_y0/a_x0"),
        _q("thickness0", "mm", "zero-force thickness"),
        _q("area_strain_min", "1", "smallest area strain a_x a_y/(a_x0 a_y0) - 1"),
        _q("area_strain_max", "1", "largest area strain"),
        _q("thickness_strain_min", "1", "smallest thickness strain"),
        _q("thickness_strain_max", "1", "largest thickness strain"),
        _q("thickness_strain_at_secant", "1", "thickness strain at strain 0.02"),
        _q(
            "force_ratio_xy",
            "1",
            "x force of self + same-row contacts over the y force of "
            "NN + NNN same-column contacts, zero strain (paper Fig. 6h)",
        ),
        _q("L_over_r_trans", "1", "onset of unjamming (L/r)_trans"),
        _q("L_trans", "mm", "onset of unjamming in L"),
        _q("bracket_lower", "1", "last jammed L/r below (L/r)_trans"),
        _q("bracket_upper", "1", "(L/r)_trans, the first unjammed L/r"),
        _q("delta_L_over_r", "1", "width of the transition, Delta L/r (paper Fig. 4a)"),
        *_registered("sweep"),
    )
)
"""Columns of the post-processor's tables (``knitsweep.report``) with units."""

KNOWN_UNITS = {
    name: q.units
    for table in (SCALARS, METRICS, STEP_QUANTITIES, PARAMETERS)
    for name, q in table.items()
}

COLUMN_QUANTITY = {
    q.column: q for table in (PARAMETERS, METRICS, SCALARS, STEP_QUANTITIES) for q in table.values()
}
"""Table column name -> its quantity (units, long name)."""


def table_column(name: str) -> str:
    """The table column of a stored name: with its unit suffix if it is a known
    quantity, unchanged otherwise (names that carry their unit already, flags, ids)."""
    units = KNOWN_UNITS.get(name)
    return name if units is None else column_name(name, units)


def dataset_quantity(kind: str, name: str) -> Quantity | None:
    """The quantity of dataset ``name`` in a ``points`` or ``sweeps`` group."""
    if kind == "sweeps":
        return STEP_QUANTITIES.get(name) or SWEEP_START_QUANTITIES.get(name)
    return START_QUANTITIES.get(name)


def leading_dimension(kind: str, name: str) -> str:
    """The first dimension of dataset ``name``: ``step`` in a sweep (``start`` for
    its per-start arrays), ``start`` in a point."""
    return "step" if kind == "sweeps" and name not in SWEEP_START_QUANTITIES else "start"
