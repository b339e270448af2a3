"""Contact volumes and the packing fraction of a stitch (paper SI "Contact Volumes",
Figs. 6a–f; docs/model.md §9): the paper's voxel method and a quasi-Monte-Carlo
estimator over the tube with an error estimate. Inputs are a state's control points
(``CellModel.control_points``, (n_segments, 6, 3) mm), its periods and the yarn radius.

Uses numba (the distance search) and scipy (Sobol points); not imported by
``knitsweep.analysis`` itself.
"""

from .estimators import (
    STORED_SAMPLES,
    STORED_SCRAMBLES,
    TubeSamples,
    Volumes,
    contact_class,
    contact_classes,
    packing_fraction,
    qmc_volumes,
    tube_samples,
    voxel_volumes,
)
from .geometry import Pieces, arc_length, build_pieces, centre_line, fabric_depth

__all__ = [
    "STORED_SAMPLES",
    "STORED_SCRAMBLES",
    "Pieces",
    "TubeSamples",
    "Volumes",
    "arc_length",
    "build_pieces",
    "centre_line",
    "contact_class",
    "contact_classes",
    "fabric_depth",
    "packing_fraction",
    "qmc_volumes",
    "tube_samples",
    "voxel_volumes",
]
