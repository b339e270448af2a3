"""Load paths: how a sweep deforms the cell in its plane (docs/model.md §8).

A path names, for each of the two periods, how its strain follows the sweep's strain
ε (the strain of the path's *leading* period): ``rate`` ε for a controlled period,
``None`` for a free one (relaxed to zero force with the shape). So a step of a sweep
fixes a_i = a_i0 (1 + rate_i ε) for every controlled period i, and relaxes the rest.

* ``x``, ``y``: uniaxial, the paper's pulls (the other period free);
* ``biaxial``: equibiaxial, both periods pulled by the same strain;
* ``strip_x``, ``strip_y``: strip biaxial (pure shear in the fabric-testing sense),
  one period pulled, the other held at its zero-force value;
* ``shear``, ``shear_free``: simple shear γ of the cell, its wale vector tilted to
  t_w = (γ a_y0, a_y) (``CellModel.skew``), the periods held at their zero-force values
  (``shear``) or relaxed with the shape (``shear_free``); the sweep's strain is γ;
* ``ray:<rate_x>,<rate_y>[,<rate_xy>]``: any ray in (ε_x, ε_y) or (ε_x, ε_y, γ), e.g.
  ``ray:1,-0.3`` (x pulled, y pushed in at 0.3 of its rate) or ``ray:1,0,0.5`` (x pulled and
  the cell sheared at half its rate, a free yarn's); the largest |rate| leads (on a tie the
  positive one, x before y before γ) and is scaled to 1, and must be positive (a pull; the
  protocol's ``mode = "compression"`` reverses a whole sweep).

The stress a path reports (``stress``, ``stress_envelope``, N/mm) is the work
conjugate of ε per unit width: dE/dε / (a_lead0 a_perp0) = Σ_i rate_i σ_ii with
σ_xx = F_x / a_y0, σ_yy = F_y / a_x0 and F_i = dE*/da_i the period forces; for the
uniaxial paths that is the paper's stress; for the shear paths it is σ_xy = F_s / a_x0,
F_s = dE*/ds_x the force on the skew. Each sweep stores all three components as well
(``stress_xx``, ``stress_yy``, ``stress_xy``).

The gap that marks jamming (docs/model.md §9) is that of the path's leading period: ΔE_c
pulled in x, ΔE_b in y (the paper's), ΔE_c along ``strip_x`` and ``biaxial``, ΔE_b along
``strip_y`` (and along a ray, that of its leading period); ΔE_c in shear. The other gap
is no marker where a period is held or pulled too: holding or
pulling the transverse period makes a loose fabric straighten its yarn (fixed length,
larger cell) and give up the other energy without any contact being relieved (measured,
``jobs/inplane_k0.1.toml``: garter's ΔE_b along ``strip_x`` and ``biaxial`` is 3–7·10⁻⁵ mJ
from 10.9 to 13.3 mm, where its ΔE_c is 0 and it is unjammed pulled in x).

This module is the registry: a new path is one entry of ``PATHS``; the job file's
``directions``, the CLI's ``--direction`` and the analysis read the names from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache


@dataclass(frozen=True)
class LoadPath:
    """A named load path: the strain rate of each period (x, y) per unit of the sweep's
    strain, ``None`` for a free period; the gap that marks jamming along it."""

    name: str
    rate_x: float | None
    rate_y: float | None
    gap: str
    description: str
    rate_xy: float = 0.0
    """The rate of the shear γ = s_x / a_y0 (the wale vector's skew over its zero-force
    length); 0: the skew held at 0, as along every path but the shear ones."""

    @property
    def rates(self) -> dict[str, float | None]:
        return {"x": self.rate_x, "y": self.rate_y}

    @property
    def shears(self) -> bool:
        """The cell is sheared along the path (its skew moves)."""
        return self.rate_xy != 0.0

    @property
    def controlled(self) -> tuple[str, ...]:
        """The periods a step fixes ('x', 'y', both or none), a leading one first."""
        order = ("x", "y") if self.leading == "xy" else self._order
        return tuple(d for d in order if self.rates[d] is not None)

    @property
    def leading(self) -> str:
        """The period whose strain is the sweep's strain (its rate is 1); "xy" for the
        shear paths, whose strain is γ and whose coordinate is a_y0 (1 + γ) (the sweep's
        step in mm is a step of the skew)."""
        return self._order[0]

    @property
    def transverse(self) -> str:
        return self._order[1]

    @property
    def uniaxial(self) -> bool:
        """One period pulled, the other free (its Poisson contraction measured)."""
        return len(self.controlled) == 1

    @property
    def _order(self) -> tuple[str, str]:
        if self.rate_x == 1.0:
            return ("x", "y")
        if self.rate_y == 1.0:
            return ("y", "x")
        return ("xy", "x")  # shear leads: its coordinate a_y0 (1 + γ), per unit a_x0

    def targets(self, a0: dict[str, float], strain: float) -> dict[str, float]:
        """The controlled periods (mm) at the sweep's ``strain`` from the zero-force ones."""
        return {d: a0[d] * (1.0 + self.rates[d] * strain) for d in self.controlled}  # type: ignore[operator]

    def conjugate_stress(self, force_x, force_y, a_x0: float, a_y0: float, force_s=0.0):
        """dE/dε per unit width (N/mm) from the period forces and the force on the skew
        (N, numbers or arrays over steps): Σ rate_i σ_ii + rate_xy σ_xy."""
        return sum((self.rates[d] or 0.0) * s for d, s in
                   (("x", force_x / a_y0), ("y", force_y / a_x0))) + self.rate_xy * (
            force_s / a_x0)  # fmt: skip


PATHS: dict[str, LoadPath] = {
    p.name: p
    for p in (
        LoadPath("x", 1.0, None, "delta_E_c", "uniaxial along the course (x), a_y free"),
        LoadPath("y", None, 1.0, "delta_E_b", "uniaxial along the wale (y), a_x free"),
        LoadPath("biaxial", 1.0, 1.0, "delta_E_c", "equibiaxial: both periods by ε"),
        LoadPath("strip_x", 1.0, 0.0, "delta_E_c", "strip biaxial: x by ε, a_y held at a_y0"),
        LoadPath("strip_y", 0.0, 1.0, "delta_E_b", "strip biaxial: y by ε, a_x held at a_x0"),
        LoadPath("shear", 0.0, 0.0, "delta_E_c", "simple shear γ = ε, both periods held", 1.0),
        LoadPath(
            "shear_free", None, None, "delta_E_c", "simple shear γ = ε, both periods relaxed", 1.0
        ),
    )
}
"""The registered load paths by name (the values of ``Direction``)."""
PATH_NAMES: tuple[str, ...] = tuple(PATHS)
RAY = "ray:"
"""The prefix of a ray's name: ``ray:<rate_x>,<rate_y>[,<rate_xy>]``."""
CHOICES = f"{', '.join(PATH_NAMES)} or {RAY}<rate_x>,<rate_y>[,<rate_xy>]"


def load_path(name: str) -> LoadPath:
    """The registered path ``name`` or the ray it names; ValueError naming the choices
    otherwise."""
    if isinstance(name, str) and name in PATHS:
        return PATHS[name]
    if isinstance(name, str) and name.startswith(RAY):
        return _ray(name)
    raise PathError(name, f"must be one of {CHOICES}")


@lru_cache(maxsize=256)
def _ray(name: str) -> LoadPath:
    """The ray ``ray:<rate_x>,<rate_y>[,<rate_xy>]``, its largest |rate| scaled to 1."""
    try:
        rates = [float(v) for v in name[len(RAY) :].split(",")]
    except ValueError:
        rates = []
    if len(rates) not in (2, 3):
        raise PathError(name, f"a ray is {RAY}<rate_x>,<rate_y>[,<rate_xy>] (two or three "
                        "numbers, e.g. ray:1,-0.3 or ray:1,0,0.5)")  # fmt: skip
    if not all(math.isfinite(v) for v in rates) or not any(rates):
        raise PathError(name, "a ray's rates must be finite and not all 0")
    rates += [0.0] * (3 - len(rates))
    top = max(abs(v) for v in rates)
    lead = next((i for i, v in enumerate(rates) if v == top), None)  # a tie: a pull, x first
    if lead is None:
        raise PathError(name, 'the largest rate must be positive (a pull); mode = "compression" '
                        "in [protocol] reverses a whole sweep")  # fmt: skip
    rx, ry, rxy = (v / top for v in rates)
    gap = "delta_E_b" if lead == 1 else "delta_E_c"
    shear = f" : γ = {rx:g} : {ry:g} : {rxy:g}" if rxy else f" = {rx:g} : {ry:g}"
    return LoadPath(name, rx, ry, gap, f"ray: ε_x : ε_y{shear}", rxy)


def check_path(name: str) -> str:
    """``name`` if it names a load path (``load_path``); ValueError saying why otherwise
    (for a validator that names the field and the value itself)."""
    try:
        load_path(name)
    except PathError as e:
        raise ValueError(e.why) from None
    return name


def check_path_for_stitch(direction: str, stitch: str) -> None:
    """ValueError if the load path ``direction`` shears the cell and ``stitch`` cannot (the
    paper's crossover ansatz is mirror-symmetric by construction: its images are
    translations of a stitch with no skew, ``stitches.images``)."""
    if not load_path(direction).shears:
        return
    from .stitches import get_stitch
    from .stitches.images import image_group

    if not image_group(get_stitch(stitch)).shears:
        raise ValueError(f"direction {direction!r} shears the cell, which stitch {stitch!r} "
                         "cannot (the paper's ansatz is mirror-symmetric by construction): "
                         "shear the free yarn, stitch = 'stockinette_free'")  # fmt: skip


class PathError(ValueError):
    """Not a load path: ``direction = '<name>': <why>``."""

    def __init__(self, name: object, why: str) -> None:
        super().__init__(f"direction = {name!r}: {why}")
        self.why = why


def path_rank(name: str) -> tuple[int, str]:
    """A sort key: the registered paths in their order, then the rays by name."""
    return (PATH_NAMES.index(name), "") if name in PATHS else (len(PATH_NAMES), name)
