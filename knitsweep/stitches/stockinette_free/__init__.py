"""The free periodic yarn of one stockinette cell (docs/model.md §11).

Every control point of the cell's 8 quintic segments is free, subject only to G2 at
every joint (continuity by construction) and the yarn length; it contains the paper's
ansatz exactly (``ansatz.to_free``) and measures how much that ansatz restricts.

* ``layout``: the 87 entries, bounds, bending weights (all 1), starts;
* ``geometry``: state -> control points with their exact Jacobian (numba);
* ``ansatz``: a stockinette state's control points -> the free state.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from ..base import MIRROR_CLASSES, Gauge, Stitch
from . import gauge, layout

GAUGE = Gauge(gauge.SPEED_ENTRIES, gauge.regauge, gauge.JOINT_STIFFNESS, gauge.JOINT_RULE)
"""The free yarn's gauge: end speeds at L/8, joints near equal fractions of the yarn."""


def free_yarn_stitch(name: str, description: str, package: str, *,
                     mirror_parity: tuple[int, int] = (0, 0), geometry_module: str = "",
                     state: ModuleType = layout, **options: Any) -> Stitch:  # fmt: skip
    """A stitch of the free periodic yarn (this package's 8 segments, each counted once,
    no twist entry): the state, bounds and starts of the layout module ``state`` (this
    package's ``layout``; garter's adds z0), its starts in ``package + ".data"``, its
    geometry kernel in ``package + ".geometry"`` (or ``geometry_module``), its end speeds
    the gauge (``gauge``). Every free yarn sums its contacts over the glide group's
    kernels, which take samples placed along the yarn by arclength; with
    ``mirror_parity`` (0, 0) (no image mirrored) they sum the translations' images. A
    ``mirror_parity`` other than (0, 0) makes it a knit/purl pattern, relaxed as a rough
    stitch (``Stitch.rough``). ``options``: the rest of ``Stitch``'s fields
    (``stage_dL_mm``)."""
    return Stitch(
        name=name,
        description=description,
        state_names=state.STATE_NAMES,
        n_segments=state.N_SEGMENTS,
        segment_weights=layout.SEGMENT_WEIGHTS,
        bounds=state.state_bounds,
        twist_index=None,
        starts=state.STARTS,
        data_package=f"{package}.data",
        geometry_module=geometry_module or f"{package}.geometry",
        images="glides",
        contact_classes=MIRROR_CLASSES,
        path_order=tuple(range(state.N_SEGMENTS)),
        closing_shift=(1, 0),
        mirror_parity=mirror_parity,
        rough=any(mirror_parity),
        gauge=GAUGE,
        **options,
    )


STITCH = free_yarn_stitch(
    "stockinette_free",
    "stockinette as a free periodic yarn (every control point free, G2 joints)",
    __name__,
)
"""The free stockinette yarn: stockinette's path and images, no crossover ansatz."""
