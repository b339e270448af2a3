"""Named fidelity presets: the speed/accuracy trade in one word.

A preset fixes the numerical knobs of every layer: contact samples and
quadrature nodes (``Fidelity``), the optimiser tolerance (``SolverSettings``)
and the small strain step (``SweepProtocol.step_mm``). Explicit settings in a
job file or on the command line override the preset field by field.

* ``draft``: coarse and fast, for exploring a parameter space.
* ``paper``: the authors' numerical settings exactly (10 samples per segment,
  SciPy's default SLSQP tolerance 1e-6 that their script ends up using, 0.001 mm
  steps), with exact quadrature.
* ``converged`` (default): the paper's discretisation with the optimiser driven
  to a true constrained minimum (tolerance 1e-10).
* ``fine``: twice the contact samples, tighter tolerance, half the step.

The measured cost and error of each are in the README (``knitsweep accuracy``).
"""

from __future__ import annotations

from typing import Any

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "draft": {
        "fidelity": {"samples_per_segment": 6, "quadrature_nodes": 12},
        "solver": {"ftol": 1e-8},
        "protocol": {"step_mm": 0.005},
    },
    "paper": {
        "fidelity": {"samples_per_segment": 10, "quadrature_nodes": 32},
        "solver": {"ftol": 1e-6},
        "protocol": {"step_mm": 0.001},
    },
    "converged": {
        "fidelity": {"samples_per_segment": 10, "quadrature_nodes": 32},
        "solver": {"ftol": 1e-10},
        "protocol": {"step_mm": 0.001},
    },
    "fine": {
        "fidelity": {"samples_per_segment": 20, "quadrature_nodes": 32},
        "solver": {"ftol": 1e-12},
        "protocol": {"step_mm": 0.0005},
    },
}
DEFAULT_PRESET = "converged"


def preset_settings(name: str, section: str) -> dict[str, Any]:
    """The preset's values for one section ('fidelity', 'solver' or 'protocol')."""
    if name not in PRESETS:
        from .config import InputError

        raise InputError(f"preset = {name!r}: must be one of {', '.join(PRESETS)}")
    return dict(PRESETS[name][section])
