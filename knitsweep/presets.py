"""The presets: the speed/accuracy trade in one word (``PRESETS``), and ``Numerics``,
a preset's settings of every layer with explicit overrides field by field."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel

from .config import STRICT, Fidelity, SolverSettings, SweepProtocol
from .errors import InputError

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "draft": {
        "fidelity": {"samples_per_segment": 10, "quadrature_nodes": 32},
        "solver": {
            "method": "newton",
            "ftol": 1e-5,
            "substep_mm": 0.05,
            "continuation_dL_mm": 0.3,
        },
        "protocol": {
            "step_mm": 0.002,
            "step_control": "adaptive",
            "stress_rtol": 0.05,
            "energy_tolerance_mJ": 1e-6,
            "max_step_mm": 0.01,
            "observables": ("energy_gaps", "secant_modulus"),
        },
    },
    "paper": {
        "fidelity": {"samples_per_segment": 10, "quadrature_nodes": 32},
        "solver": {"method": "slsqp", "ftol": 1e-6},
        "protocol": {"step_mm": 0.001},
    },
    "converged": {
        "fidelity": {"samples_per_segment": 10, "quadrature_nodes": 32},
        "solver": {"method": "newton", "ftol": 1e-10},
        "protocol": {"step_mm": 0.001},
    },
    "fine": {
        "fidelity": {"samples_per_segment": 20, "quadrature_nodes": 32},
        "solver": {"method": "newton", "ftol": 1e-12},
        "protocol": {"step_mm": 0.0005, "merge_tolerance_mJ": 0.0},
    },
}
"""Named fidelity presets: the numerical knobs of every layer in one word, chosen
from the measured speed/accuracy front (docs/how-to/presets.md, ``knitsweep accuracy``).

* ``draft``: what a survey needs: the same contact sampling (fewer samples err by
  several per cent in the energy gaps) and quadrature, a looser Newton tolerance
  (1e-5), continuation in 0.3 mm stages of L, adaptive strain steps of at most 0.01 mm,
  and sweeps that stop once Y_sec and the energy gaps (to 1e-6 mJ, so the transition)
  are known: within 1 % of ``converged`` on those over the k = 0.1 series around the
  transition, 4.9x cheaper per point with 4 starts, 9.4x with one
  (benchmarks/bench_draft.py, docs/how-to/presets.md); no offset stress.
* ``paper``: the authors' numerical settings exactly (10 samples per segment, SLSQP
  with the SciPy default tolerance 1e-6 that their script ends up using, 0.001 mm
  steps), with exact quadrature: their numbers, noise included.
* ``converged`` (default): the paper's discretisation and steps with the Newton
  solver driven to a true constrained minimum (decrement 1e-10 mJ).
* ``fine``: twice the contact samples, tighter tolerance, half the step, and no
  merging of chains.

Jobs and sweeps take the preset's observables; ``knitsweep sweep`` computes the whole
curve unless told otherwise."""
DEFAULT_PRESET = "converged"
SECTIONS = {"fidelity": Fidelity, "solver": SolverSettings, "protocol": SweepProtocol}
"""The settings a preset fixes, by section name."""


def check_preset(name: Any) -> str:
    """``name`` if it is a preset; InputError listing the presets otherwise."""
    if not isinstance(name, str) or name not in PRESETS:
        raise InputError(f"preset = {name!r}: must be one of {', '.join(PRESETS)}")
    return name


def preset_sections(name: str, given: Mapping[str, Any] | None = None) -> dict[str, dict[str, Any]]:
    """The preset's fields per section, with the fields of ``given`` (section name ->
    {field: value}, as in a job file) on top. Sections of ``given`` that are not
    mappings are passed through for the validator to report."""
    check_preset(name)
    out: dict[str, Any] = {}
    for section in SECTIONS:
        extra = (given or {}).get(section, {})
        out[section] = {**PRESETS[name][section], **extra} if isinstance(extra, Mapping) else extra
    return out


class Numerics(BaseModel):
    """The numerical settings of every layer: a preset plus explicit overrides."""

    model_config = STRICT

    preset: str = DEFAULT_PRESET
    fidelity: Fidelity
    solver: SolverSettings
    protocol: SweepProtocol

    @classmethod
    def from_preset(cls, name: str | None = None, **overrides: Any) -> Numerics:
        """The preset ``name`` (default ``converged``) with fields overridden by name
        (``samples_per_segment=6``, ``ftol=1e-8``, ``step_mm=0.005`` …; None leaves a
        field at the preset's value). Unknown fields are refused by name."""
        name = DEFAULT_PRESET if name is None else check_preset(name)
        given: dict[str, dict[str, Any]] = {s: {} for s in SECTIONS}
        for field, value in overrides.items():
            if value is None:
                continue
            section = next((s for s, m in SECTIONS.items() if field in m.model_fields), None)
            if section is None:
                known = sorted(f for m in SECTIONS.values() for f in m.model_fields)
                raise InputError(f"{field}: unknown setting (known: {', '.join(known)})")
            given[section][field] = value
        sections = preset_sections(name, given)
        return cls(preset=name, **{s: SECTIONS[s](**v) for s, v in sections.items()})
