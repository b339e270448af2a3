"""Strain sweeps: the stitch pulled step by step in x or y (docs/model.md §8).

``sweep`` runs the protocol (its starts carried and merged as chains by
``knitsweep.relax.chains``), ``schedule`` chooses the steps and says when the observables asked for are determined, ``result``
holds a sweep and its lossless record.
"""

from .result import SweepResult, centred_stress, first_grid_value
from .sweep import NoRestState, strain_sweep, strain_sweep_from_rest

__all__ = ["NoRestState", "SweepResult", "centred_stress", "first_grid_value", "strain_sweep",
           "strain_sweep_from_rest"]  # fmt: skip
