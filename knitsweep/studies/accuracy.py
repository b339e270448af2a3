"""The speed/accuracy trade, measured: ``knitsweep accuracy``.

The same point is computed at rising fidelity (by default the presets draft,
paper, converged and fine); for each setting the study records the cost (CPU seconds
of its zero-force relaxation, of a sweep, and of the point: zero-force state plus x
and y sweeps; the computation is single-threaded, so CPU time is its cost whatever
else the machine runs) and the error against the finest setting (or a named one)
in the zero-force energy, a_x0, a_y0, Y_sec, sigma0, ΔE_c, ΔE_b, and (L/r)_trans
on a small series in L. On a grid the transition can only move in whole steps,
so the series reports the crossing of the gap through the threshold,
interpolated linearly between the last jammed and the first unjammed L: a
continuous (L/r)_trans whose error is measurable.
"""

from __future__ import annotations

import csv
import io
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis import offset_stress, secant_modulus
from ..analysis.stress_strain import FD_STRESS_SMOOTHING
from ..analysis.transitions import GAP_THRESHOLD, threshold_crossing
from ..compilation import compile_kernels
from ..config import (
    Fidelity,
    InputError,
    SolverSettings,
    StartSettings,
    StitchParams,
    SweepProtocol,
)
from ..presets import PRESETS, Numerics
from ..relax.zero_force import zero_force
from ..strain_sweep import strain_sweep

# around the k = 0.1 mN/mm^2 transition (L = 11.4-11.5 mm in x and y, paper Fig. 3)
DEFAULT_SERIES = [11.3, 11.4, 11.5, 11.6, 11.7]
METRICS = ("E0", "a_x0", "a_y0", "Y_sec_x", "Y_sec_y", "sigma0_x", "sigma0_y", "dEc_x", "dEb_y",
           "L_over_r_trans_x")  # fmt: skip
LABELS = {"E0": "zero-force energy", "a_x0": "$a_{x0}$", "a_y0": "$a_{y0}$",
          "Y_sec_x": "$Y_{sec}$ (x)", "Y_sec_y": "$Y_{sec}$ (y)", "sigma0_x": r"$\sigma_0$ (x)",
          "sigma0_y": r"$\sigma_0$ (y)", "dEc_x": r"$\Delta E_c$ (x)", "dEb_y": r"$\Delta E_b$ (y)",
          "L_over_r_trans_x": "$(L/r)_{trans}$ (x)"}  # fmt: skip


@dataclass(frozen=True)
class Setting:
    name: str
    fidelity: Fidelity
    solver: SolverSettings
    protocol: SweepProtocol


def setting(spec: str) -> Setting:
    """'converged' or 'converged:samples_per_segment=6+ftol=1e-8' -> Setting; a list
    field takes its values separated by '|' (``observables=energy_gaps|secant_modulus``)."""
    name, _, overrides = spec.partition(":")
    fields: dict[str, Any] = {}
    for item in filter(None, overrides.split("+")):
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"setting {spec!r}: {item!r} is not field=value")
        fields[key] = tuple(value.split("|")) if key == "observables" else _number(value)
    n = Numerics.from_preset(name, **fields)
    return Setting(spec, n.fidelity, n.solver, n.protocol)


def _number(text: str) -> int | float | str:
    """A value of a setting spec: an integer, a number, or the text itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


@dataclass
class SettingResult:
    name: str
    values: dict[str, float | None] = field(default_factory=dict)
    seconds_relax: float = 0.0
    seconds_sweep: float = 0.0
    seconds_point: float = 0.0
    relaxations_per_sweep: float = 0.0
    evaluations_per_sweep: float = 0.0
    errors: dict[str, float | None] = field(default_factory=dict)
    is_reference: bool = False


def run_setting(point: StitchParams, s: Setting, series: list[float], threshold: float,
                progress=None) -> SettingResult:  # fmt: skip
    """Every measurement of one setting (one start: Init_1, as the reference)."""
    starts = StartSettings(count=1)
    out = SettingResult(s.name)
    compile_kernels(s.fidelity)  # load the compiled kernels before the clock starts
    t = time.process_time()
    zf = zero_force(point, s.fidelity, s.solver, starts)
    out.seconds_relax = time.process_time() - t
    best = zf.best
    out.values |= {"E0": best.total_energy, "a_x0": best.a_x, "a_y0": best.a_y}
    sweep_times, relaxations, evaluations = [], [], []
    for d in ("x", "y"):
        t = time.process_time()
        sw = strain_sweep(point, zf, d, s.protocol, s.fidelity, s.solver)
        sweep_times.append(time.process_time() - t)
        relaxations.append(sw.relaxations)
        evaluations.append(sw.evaluations_total)
        out.values[f"Y_sec_{d}"] = secant_modulus(sw.strain, sw.stress).Y_sec
        # sigma0 is the longest softened regime of the whole curve (fitted to the envelope
        # stress, as the reports do): a sweep that stopped once its observables were
        # known has not determined it
        out.values[f"sigma0_{d}"] = (
            offset_stress(sw.strain, sw.stress_envelope, **FD_STRESS_SMOOTHING).sigma0
            if "curve" in s.protocol.observables
            else None
        )
        out.values[f"dEc_{d}" if d == "x" else f"dEb_{d}"] = sw.energy_gaps.jamming_gap(d)
        if progress:
            progress(f"{s.name}: {d} sweep {sweep_times[-1]:.2f} s")
    out.seconds_point = out.seconds_relax + sum(sweep_times)
    gap_series = []
    for L in series:
        p = point.model_copy(update={"L_mm": L})
        zl = zero_force(p, s.fidelity, s.solver, starts)
        t = time.process_time()
        sw = strain_sweep(p, zl, "x", s.protocol, s.fidelity, s.solver)
        sweep_times.append(time.process_time() - t)
        relaxations.append(sw.relaxations)
        evaluations.append(sw.evaluations_total)
        gap_series.append(sw.energy_gaps.delta_E_c)
    crossing = threshold_crossing(series, gap_series, threshold)
    out.values["L_over_r_trans_x"] = None if crossing is None else crossing / point.r_mm
    out.seconds_sweep = float(np.median(sweep_times))
    out.relaxations_per_sweep = float(np.mean(relaxations))
    out.evaluations_per_sweep = float(np.mean(evaluations))
    if progress:
        progress(f"{s.name}: done")
    return out


def accuracy_study(
    point: StitchParams,
    specs: list[str] | None = None,
    series: list[float] | None = None,
    threshold: float = GAP_THRESHOLD,
    workers: int = 1,
    progress=None,
    reference: str | None = None,
) -> list[SettingResult]:
    """Measure every setting; errors are against ``reference`` (one of ``specs``; by
    default the last, finest)."""
    specs = specs or list(PRESETS)
    settings = [setting(spec) for spec in specs]
    series = series or DEFAULT_SERIES
    if workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as ex:
            futures = [ex.submit(run_setting, point, s, series, threshold) for s in settings]
            results = [f.result() for f in futures]
    else:
        results = [run_setting(point, s, series, threshold, progress) for s in settings]
    if reference is not None and reference not in specs:
        raise InputError(f"reference = {reference!r}: must be one of the settings {specs}")
    ref_result = results[specs.index(reference) if reference is not None else -1]
    ref_result.is_reference = True
    ref = ref_result.values
    for r in results:
        for m in METRICS:
            a, b = r.values.get(m), ref.get(m)
            r.errors[m] = None if a is None or b is None else abs(a - b) / max(abs(b), 1e-300)
    return results


def write_report(results: list[SettingResult], out: Path) -> list[Path]:
    """accuracy.csv and accuracy.png (relative error against cost) in ``out``."""
    from ..util.safe_files import make_output_dir, replace_file

    out = make_output_dir(out)  # as every command's --out: its parent must exist
    csv_path = out / "accuracy.csv"
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(["setting", "cpu_seconds_per_relaxation", "cpu_seconds_per_sweep",
                "cpu_seconds_per_point", "relaxations_per_sweep", "evaluations_per_sweep",
                *METRICS, *(f"relerr_{m}" for m in METRICS)])  # fmt: skip
    for r in results:
        w.writerow([r.name, f"{r.seconds_relax:.4g}", f"{r.seconds_sweep:.4g}",
                    f"{r.seconds_point:.4g}", f"{r.relaxations_per_sweep:.4g}",
                    f"{r.evaluations_per_sweep:.4g}",
                    *(_fmt(r.values.get(m)) for m in METRICS),
                    *(_fmt(r.errors.get(m)) for m in METRICS)])  # fmt: skip
    replace_file(csv_path, f.getvalue().encode())
    png = out / "accuracy.png"
    _plot(results, png)
    return [csv_path, png]


def _fmt(v: Any) -> str:
    return "" if v is None else f"{v:.6g}"


def table(results: list[SettingResult]) -> str:
    """A plain-text table: CPU seconds, then relative error per metric (vs the reference)."""
    w = max(len("setting"), *(len(r.name) for r in results)) + 2
    head = f"{'setting':<{w}}{'s/relax':>9}{'s/sweep':>9}{'s/point':>9}" + "".join(
        f"{m:>17}" for m in METRICS
    )
    lines = [head, "-" * len(head)]
    for r in results:
        errs = "".join(f"{(f'{r.errors[m]:.1e}' if r.errors.get(m) is not None else '-'):>17}"
                       for m in METRICS)  # fmt: skip
        lines.append(f"{r.name:<{w}}{r.seconds_relax:9.3f}{r.seconds_sweep:9.3f}"
                     f"{r.seconds_point:9.3f}{errs}")  # fmt: skip
    return "\n".join(lines)


def _plot(results: list[SettingResult], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    reference = next(r for r in results if r.is_reference)
    others = sorted((r for r in results if not r.is_reference), key=lambda r: r.seconds_point)
    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=150)
    cost = [r.seconds_point for r in others]
    for m in METRICS:
        errs = [r.errors.get(m) for r in others]
        pts = [(c, max(e, 1e-12)) for c, e in zip(cost, errs, strict=True) if e is not None]
        if pts:
            xs, ys = zip(*pts, strict=True)
            ax.plot(xs, ys, marker="o", label=LABELS[m])
    ax.set_xscale("log")
    top = ax.secondary_xaxis("top")
    top.set_xticks(cost, labels=[r.name for r in others], fontsize=8, rotation=20)
    top.minorticks_off()
    ax.set_yscale("log")
    ax.set_xlabel("CPU seconds per point (zero-force state, x and y sweeps; one core)",
                  fontsize=11)  # fmt: skip
    ax.set_ylabel(f"relative error against '{reference.name}'", fontsize=11)
    ax.set_title("knitsweep: accuracy against cost", fontsize=12)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, ncol=2, loc="upper right")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    from ..util.safe_files import replace_file

    replace_file(path, buf.getvalue())
