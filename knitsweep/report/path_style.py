"""How the figures tell load paths apart (``knitsweep.paths``): a dict by path whose rays
get a default, the strain axis of each path, and the paths' order in panels and tables."""

from __future__ import annotations

from typing import Any

from ..paths import PATH_NAMES, load_path, path_rank


class PerPath(dict):
    """A dict by load path whose missing entries (rays, ``knitsweep.paths``) come from
    ``default(path)``."""

    def __init__(self, entries: dict[str, Any], default: Any) -> None:
        super().__init__(entries)
        self._default = default

    def __missing__(self, path: str) -> Any:
        return self._default(path)


RAY_COLOUR = "#555555"
"""The colour of a ray (``ray:<rate_x>,<rate_y>[,<rate_xy>]``) in the figures."""


def _ray_strain(path: str) -> str:
    p = load_path(path)
    if p.shears:
        return (rf"strain along the ray $\varepsilon_x : \varepsilon_y : \gamma$ = "
                rf"{p.rate_x:g} : {p.rate_y:g} : {p.rate_xy:g}")  # fmt: skip
    lead, across = p.leading, p.transverse
    return (rf"strain $\varepsilon_{lead}$ ($\varepsilon_{across}$ = "
            rf"{p.rates[across]:g} $\varepsilon_{lead}$)")  # fmt: skip


STRAIN = PerPath(
    {
        "x": r"strain $\varepsilon_x$",
        "y": r"strain $\varepsilon_y$",
        "biaxial": r"strain $\varepsilon_x = \varepsilon_y$",
        "strip_x": r"strain $\varepsilon_x$ ($\varepsilon_y = 0$)",
        "strip_y": r"strain $\varepsilon_y$ ($\varepsilon_x = 0$)",
        "shear": r"shear $\gamma$ (periods held)",
        "shear_free": r"shear $\gamma$ (periods free)",
    },
    _ray_strain,
)
"""The strain axis of each load path (``knitsweep.paths``; a ray's from its rates)."""
if set(STRAIN) != set(PATH_NAMES):
    raise ImportError(f"STRAIN labels {sorted(STRAIN)} != the load paths {PATH_NAMES}")


def path_order(directions: Any) -> list[str]:
    """The load paths among ``directions`` in the registry's order (x, y, the biaxial
    ones), then the rays by name."""
    return sorted(set(directions), key=path_rank)
