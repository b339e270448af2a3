"""What every ``knitsweep`` command shares: the app, the parameter options in
paper units, one-line errors (exit code 2) and the entry point."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

from ..stitches import DEFAULT_STITCH, STITCH_CHOICES

HELP = {"help_option_names": ["-h", "--help"]}
"""Every command takes -h as well as --help."""


app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    context_settings=HELP,
    help="Simulate knitted fabric as a periodic unit cell of yarn: stockinette and knit/purl "
    f"patterns (stitches: {STITCH_CHOICES}). Energies, relaxations, strain sweeps, MPI "
    "parameter sweeps, jamming phase diagrams and pictures (Gonzalez et al. 2025, "
    "docs/model.md).",
)


def _version(value: bool) -> None:
    if value:
        from .._version import __version__

        typer.echo(f"knitsweep {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", "-V", callback=_version, is_eager=True,
                       help="print the version and exit")] = False,
) -> None:  # fmt: skip
    """knitsweep: knitted-fabric unit-cell simulations (docs/model.md)."""


def option(*names: str, help: str, default: str | None = None, **kw):
    """A typer option whose help ends in ``[default: …]`` the way typer shows a real
    default, for options whose default is None (taken from a preset, a config file
    or paper Table 1). Conventions of every option: a lower-case description, the
    unit in parentheses in the paper's notation (mm, mN/mm², mN·mm², N/mm, mJ, s)."""
    text = help if default is None else f"{help} \\[default: {default}]"
    return typer.Option(*names, help=text, show_default=default is None, **kw)


def flag(name: str, help: str, **kw):
    """A boolean option that reads ``--name`` on and ``--no-name`` off, shown so in the
    help (``--quiet/--no-quiet``); its default is the parameter's."""
    return typer.Option(f"{name}/--no-{name.removeprefix('--')}", help=help, **kw)


def _flags_show_no_type() -> None:
    """typer (0.29) writes a ``<bool>`` type beside every flag in its rich help, where
    click writes none: a flag takes no value, so none is shown."""
    from typer.core import TyperOption

    shown = getattr(TyperOption, "display_type_rich", None)
    if shown is None or getattr(shown, "flags_show_no_type", False):
        return

    def display_type_rich(self, ctx):
        return None if self.is_flag else shown(self, ctx)

    display_type_rich.flags_show_no_type = True
    TyperOption.display_type_rich = display_type_rich


_flags_show_no_type()


# ---- shared options (paper units; defaults: paper Table 1) --------------------------
LOpt = Annotated[float | None, option("--L", help="yarn length per stitch L (mm)",
                                      default="11.6")]  # fmt: skip
BOpt = Annotated[float | None, option("--B", help="bending modulus B (mN·mm²)", default="90")]
KOpt = Annotated[float | None, option("--k", help="compression constant k (mN/mm²)",
                                      default="0.6")]  # fmt: skip
POpt = Annotated[float | None, option("--p", help="contact exponent p > 1", default="2.4")]
ROpt = Annotated[float | None, option("--r", help="yarn radius r (mm)", default="0.74")]
RcOpt = Annotated[float | None, option("--r-core", help="core radius r_core < r (mm)",
                                       default="0.325")]  # fmt: skip
RegOpt = Annotated[float | None, option("--regularization", help="curvature-derivative "
                                        "regularisation (mN·mm⁴)", default="2")]  # fmt: skip
SamplesOpt = Annotated[int | None, option("--samples", help="contact samples per segment N",
                                          default="10")]  # fmt: skip
NodesOpt = Annotated[int | None, option("--quadrature-nodes", help="Gauss–Legendre nodes per "
                                        "segment", default="32")]  # fmt: skip
ImagesOpt = Annotated[str | None, option("--images", help="periodic images: cutoff (all that "
                                         "touch) or reference", default="cutoff")]  # fmt: skip
STITCH_HELP = f"stitch pattern: {STITCH_CHOICES}, or a knit/purl chart as chart:KKPP"
"""The help of every --stitch option, built from the stitch registry."""
StitchOpt = Annotated[str | None, option("--stitch", help=STITCH_HELP,
                                         default=DEFAULT_STITCH)]  # fmt: skip
ChartOpt = Annotated[str | None, option(
    "--chart", help="a knit/purl chart instead of --stitch: rows of K and P, bottom row first, "
    "separated by / (KKPP: 2x2 rib; KP/PK: seed)", default="none")]  # fmt: skip


def with_chart(stitch: str | None, chart: str | None) -> str | None:
    """The stitch of a command given ``--stitch`` and ``--chart`` (a chart's stitch name,
    ``chart:KKPP``); InputError if both are given or the chart is not one."""
    if chart is None:
        return stitch
    from ..errors import InputError
    from ..stitches.chart import chart_stitch_names

    if stitch is not None:
        raise InputError(f"--chart {chart} and --stitch {stitch}: give one of them")
    return chart_stitch_names(chart, "--chart")[0]


PresetOpt = Annotated[str | None, option("--preset", help="fidelity preset: draft, paper, "
                                         "converged or fine", default="converged")]  # fmt: skip
ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", help="an authors' *key value config file (jammed-knits format)"),
]
JsonOpt = Annotated[bool, flag("--json", help="print one JSON object")]


@contextlib.contextmanager
def user_errors():
    """Turn bad input, and outputs that cannot be written, into one line on stderr and
    exit code 2, never a traceback."""
    from ..errors import InputError, describe_validation_error
    from ..store.journal import StorageError

    try:
        yield
    except (InputError, ValidationError) as e:
        typer.echo(f"error: {describe_validation_error(e)}", err=True)
        raise typer.Exit(2) from None
    except StorageError as e:
        typer.echo(f"error: {e.strerror or e}", err=True)
        raise typer.Exit(2) from None
    except (OverflowError, RecursionError) as e:  # a value past every bound slipped through
        typer.echo(f"error: a value is out of range ({type(e).__name__}: {e})", err=True)
        raise typer.Exit(2) from None


def check_range(name: str, value, lo, hi, unit: str = "") -> None:
    """InputError unless ``lo <= value <= hi`` (a finite number): for the options that
    no settings model covers (picture sizes, thresholds, worker counts)."""
    import math

    from ..errors import InputError

    if not (math.isfinite(value) and lo <= value <= hi):
        raise InputError(
            f"{name} = {value!r}: must be in [{lo:g}, {hi:g}]{' ' + unit if unit else ''}"
        )


def compile_notice(stitch: str | None = None, energy_only: bool = False) -> None:
    """Tell the user when this command will first compile the numerical kernels of
    ``stitch`` (its pattern's own ones included), and how long that usually takes."""
    from ..compilation import compile_notice as notice
    from ..stitches import DEFAULT_STITCH

    message = notice((stitch or DEFAULT_STITCH,), "energy" if energy_only else "run")
    if message:
        typer.echo(message, err=True)


def stitch_inputs(config, **flags):
    """(StitchParams, Fidelity) from defaults < an authors' config < explicit flags."""
    from ..config import Fidelity, StitchParams
    from ..formats import read_authors_config
    from ..quantities import PARAMETER_NAMES

    # the flags' keyword names ("--r-core" -> r_core) -> the fields
    names = {p.flag.lstrip("-").replace("-", "_"): p.field for p in PARAMETER_NAMES.values()
             if p.flag}  # fmt: skip
    names["stitch"] = "stitch"
    phys: dict = {}
    fid: dict = {}
    if config is not None:
        cfg = read_authors_config(config)
        phys.update(cfg.params.model_dump())
        if cfg.samples_per_segment is not None:
            fid["samples_per_segment"] = cfg.samples_per_segment
    for flag, field in names.items():
        if flags.get(flag) is not None:
            phys[field] = flags[flag]
    for flag, field in (("samples", "samples_per_segment"), ("quadrature_nodes", "quadrature_nodes"),
                        ("images", "images")):  # fmt: skip
        if flags.get(flag) is not None:
            fid[field] = flags[flag]
    return StitchParams(**phys), Fidelity(**fid)


def _print_result(result: dict, as_json: bool, units: dict[str, str]) -> None:
    """One JSON object, or one line a key with its unit (``units``; a dict of inputs
    as ``name=value`` pairs, nested ones dotted; a ``units`` entry is not printed)."""
    if as_json:
        typer.echo(json.dumps(result))
        return
    shown = {k: v for k, v in result.items() if k != "units"}
    width = max(len(k) for k in shown)
    for key, value in shown.items():
        unit = units.get(key, "")
        if isinstance(value, dict):
            text = " ".join(f"{k}={_text(v)}" for k, v in _dotted(value).items())
        else:
            text = _text(value)
        typer.echo(f"{key:<{width}}  {text} {unit}".rstrip())


def _text(value) -> str:
    return f"{value:.12g}" if isinstance(value, float) else str(value)


def _dotted(values: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in values.items():
        out |= _dotted(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v}
    return out


ENERGY_UNITS = {
    "bending_energy": "mJ",
    "contact_energy": "mJ",
    "total_energy": "mJ",
    "length": "mm",
    "a_x": "mm",
    "a_y": "mm",
    "seconds": "s",
}


def _relax_units() -> dict[str, str]:
    from ..quantities import PARAMETERS

    return {**ENERGY_UNITS, "min_zeta": "1", "compile_seconds": "s",
            **{name: q.units for name, q in PARAMETERS.items()}}  # fmt: skip


RELAX_UNITS = _relax_units()
"""The units of ``relax``'s numbers (its JSON's ``units``): energies mJ, lengths mm,
times s, and the parameters' (their names carry them too: ``L_mm``, ``k_mN_per_mm2``)."""
