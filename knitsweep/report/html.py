"""``knitsweep report``: one self-contained HTML page of one or several results files.

Figures are inlined (PNG as data URIs), tables are HTML, nothing is fetched: the
page reads offline, can be mailed, and prints. It holds the transitions, the
per-sweep metrics, the zero-force states, every task that failed or could not be
knitted, each job's spec and the provenance of each file (versions, git commit,
host, times). A few lines of inline script count the figures that decoded into
``data-figures-loaded`` on the page, so a headless browser can check it.
"""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from .._version import __version__
from ..analysis.transitions import GAP_THRESHOLD
from ..config import FAILED
from ..errors import InputError
from ..quantities import OBSERVABLE_REGISTRY, registered
from ..util.plain_values import plain_value
from ..util.safe_files import check_writable, replace_file
from .plotting import FigureOptions
from .results import Results, load
from .tables import TRANSITION_SUMMARY

_STYLE = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1100px; padding: 0 1em; color: #222; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { margin-top: 2em; border-bottom: 1px solid #ddd; }
.meta { color: #555; } .partial { color: #b00020; font-weight: 600; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 12.5px; }
th, td { border: 1px solid #ddd; padding: 3px 7px; text-align: right; white-space: nowrap; }
th { background: #f4f4f4; position: sticky; top: 0; } td.text { text-align: left; }
.scroll { max-height: 28em; overflow: auto; border: 1px solid #eee; max-width: 100%; }
code { overflow-wrap: anywhere; } h3 { overflow-wrap: anywhere; }
figure { margin: 1.2em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { color: #555; font-size: 0.92em; } pre { background: #f7f7f7; padding: 0.8em;
overflow: auto; font-size: 12px; max-width: 100%; box-sizing: border-box; }
.skipped { color: #777; } li { overflow-wrap: anywhere; }
"""

_SCRIPT = """
window.addEventListener("load", function () {
  var imgs = document.querySelectorAll("figure img");
  var ok = 0;
  imgs.forEach(function (im) { if (im.complete && im.naturalWidth > 0) { ok += 1; } });
  document.body.setAttribute("data-figures-loaded", ok + "/" + imgs.length);
  // elements wider than the page (those inside a scrolling box scroll instead)
  var width = document.documentElement.clientWidth, wide = [];
  document.querySelectorAll("body *").forEach(function (el) {
    if (el.closest(".scroll") || el.closest("pre")) { return; }
    var r = el.getBoundingClientRect();
    if (r.right > width + 1 || r.left < -1) { wide.push(el.tagName.toLowerCase()); }
  });
  document.body.setAttribute("data-overflowing", wide.join(" "));
});
"""

_TRANSITION_COLUMNS = ("direction", "k_mN_per_mm2", "B_mN_mm2", "r_mm", "r_core_mm", "p",
                       *(f for c in TRANSITION_SUMMARY for f in c.fields))  # fmt: skip
_SWEEP_COLUMNS = ("direction", "L_mm", "L_over_r", "k_mN_per_mm2", "B_mN_mm2", "r_mm",
                  "r_core_mm", "Y_sec_N_per_mm", "sigma0_N_per_mm", "delta_E_b_mJ",
                  "delta_E_c_mJ", "jammed", "within_round_off", "regime", "n_steps", "max_strain",
                  *(o.column for o in registered("sweep")))  # fmt: skip
_POINT_COLUMNS = ("L_mm", "L_over_r", "k_mN_per_mm2", "B_mN_mm2", "r_mm", "r_core_mm",
                  "status", "a_x0_mm", "a_y0_mm", "aspect_ratio", "E_b_rest_mJ",
                  "E_c_rest_mJ", *(o.column for o in registered("point")), "rest_found_by",
                  "rest_fall_mJ", "regime")  # fmt: skip
_PROBLEM_COLUMNS = ("kind", "status", "direction", "L_mm", "k_mN_per_mm2", "message", "task_id")
_PROVENANCE = ("job_name", "run_status", "started_at", "finished_at", "run_seconds",
               "knitsweep_version", "git_commit", "host", "slurm_job_id", "python_version",
               "numpy_version", "scipy_version", "numba_version", "h5py_version",
               "hdf5_version", "mpi_library_version", "schema_version", "n_points",
               "n_sweeps")  # fmt: skip


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and value != value):
        return "<td>–</td>"
    if isinstance(value, bool):
        return f"<td class='text'>{'yes' if value else 'no'}</td>"
    if isinstance(value, int):
        return f"<td>{value}</td>"
    if isinstance(value, float):  # four significant digits (the CSV files keep them all)
        return f"<td>{_number(value)}</td>"
    return f"<td class='text'>{html.escape(str(value))}</td>"


def _number(value: float) -> str:
    """Four significant digits; powers of ten as ×10⁻⁵, never e-notation."""
    text = f"{value:.4g}"
    if "e" not in text:
        return text
    mantissa, exponent = text.split("e")
    sup = str(int(exponent)).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{mantissa}×10{sup}"


_NAMES = {"L_over_r": "L/r", "L_over_r_trans": "(L/r)<sub>trans</sub>", "delta_L_over_r": "ΔL/r",
          "delta_E_b": "ΔE<sub>b</sub>", "delta_E_c": "ΔE<sub>c</sub>", "sigma0": "σ<sub>0</sub>",
          "Y_sec": "Y<sub>sec</sub>", "k": "k", "B": "B", "r": "r", "r_core": "r<sub>core</sub>",
          "a_x0": "a<sub>x0</sub>", "a_y0": "a<sub>y0</sub>", "E_b_rest": "E<sub>b</sub> at rest",
          "E_c_rest": "E<sub>c</sub> at rest", "L_trans": "L<sub>trans</sub>", "L": "L",
          **{o.table_name or o.name: html.escape(o.label) for o in OBSERVABLE_REGISTRY
             if o.label}}  # fmt: skip
_UNITS = {"mN/mm2": "mN/mm²", "mN mm2": "mN·mm²", "mN mm4": "mN·mm⁴"}


def header(column: str) -> str:
    """A column's header for readers (HTML): its name in the paper's symbols and its
    unit in parentheses, e.g. 'Y<sub>sec</sub> (N/mm)' for ``Y_sec_N_per_mm``."""
    from ..quantities import column_name, units_of_column

    unit = units_of_column(column)
    base = column
    if unit != "1":
        suffix = column_name("x", unit)[1:]
        base = column[: -len(suffix)] if column.endswith(suffix) else column
    name = _NAMES.get(base, html.escape(base.replace("_", " ")))
    return name if unit == "1" else f"{name} ({html.escape(_UNITS.get(unit, unit))})"


def table(frame: Any, columns: Sequence[str], table_id: str) -> str:
    """An HTML table of ``frame``'s ``columns`` (those it has), ``id=table_id``;
    headers with units (:func:`header`), numbers to four significant digits."""
    cols = [c for c in columns if c in frame.columns]
    head = "".join(f"<th title='{html.escape(c)}'>{header(c)}</th>" for c in cols)
    rows = []
    for record in frame[cols].to_dict("records"):
        rows.append("<tr>" + "".join(_cell(_plain(record[c])) for c in cols) + "</tr>")
    body = "".join(rows) or f"<tr><td colspan='{len(cols)}' class='text'>none</td></tr>"
    return (f"<div class='scroll'><table id='{table_id}'><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table></div>")  # fmt: skip


def _plain(value: Any) -> Any:
    value = plain_value(value)
    try:
        import pandas as pd

        if not isinstance(value, (list, tuple)) and pd.isna(value):
            return None
    except (TypeError, ValueError):
        pass
    return value


def _figures(
    results: Results, options: FigureOptions, progress: Callable[[str], None] | None = None
) -> tuple[list[str], list[str]]:
    """(<figure> blocks with inline PNGs, lines for the figures that were skipped);
    ``progress`` hears each figure as it is drawn."""
    from .figures import CAPTIONS, FIGURES, render_figures

    blocks, skipped = [], []
    for i, (name, outcome, files) in enumerate(render_figures(results.reduction, options)):
        png = files.get("png")
        if progress is not None:
            what = "drew" if png is not None else "skipped"
            progress(f"[{i + 1}/{len(FIGURES)}] {what} {name}")
        if png is None:
            skipped.append(f"{html.escape(name)}: {html.escape(outcome.reason or '')}")
            continue
        data = base64.b64encode(png).decode()
        caption = html.escape(CAPTIONS[name])
        notes = "".join(f" ({html.escape(n)})" for n in outcome.notes)
        blocks.append(f"<figure><img alt='{html.escape(name)}' src='data:image/png;base64,"
                      f"{data}'><figcaption><b>{html.escape(name)}</b>: {caption}{notes}"
                      f"</figcaption></figure>")  # fmt: skip
    return blocks, skipped


def _energy_density(results: Results) -> str:
    """The energy density section, when the files sweep along rays
    (docs/energy-density.md): W fitted to the one point's states as ``knitsweep
    energy-density`` fits it by default (no held-out rays: that is a fit per ray), its
    figure and measured errors; why not, where the files hold several points."""
    import io

    from ..analysis.energy_density import fit_energy_density
    from .fig_energy_density import density_summary, energy_density_figure

    sweeps = results.sweeps
    if not len(sweeps) or not sweeps["direction"].astype(str).str.startswith("ray:").any():
        return ""
    head = "<h2 id='energy-density'>Energy density</h2>"
    try:
        samples = results.energy_density_samples()
    except ValueError as e:
        return (f"{head}<p>Not fitted: {html.escape(str(e))}; fit one point with "
                "<code>knitsweep energy-density</code>.</p>")  # fmt: skip
    fit = fit_energy_density(samples)
    png = energy_density_figure(fit, samples, io.BytesIO(), dpi=110)
    data = base64.b64encode(png.getvalue()).decode()
    return (f"{head}<p>W(ε) per undeformed area, fitted to the swept states and stresses "
            "by a tensor-product cubic B-spline, as <code>knitsweep energy-density</code> "
            "fits it (which also writes it for <code>knitsweep.load_energy_density</code> "
            "and measures the error between rays).</p>"
            f"<figure><img alt='energy density' src='data:image/png;base64,{data}'>"
            f"<figcaption><pre>{html.escape(density_summary(fit))}</pre></figcaption>"
            "</figure>")  # fmt: skip


def _headline(red: Any) -> str:
    """Whether the results are partial, and how many tasks failed and how many series
    they leave without a transition: a complete run can hold failed tasks."""
    failed = [p for p in red.problems if p["status"] == FAILED]
    series = [t for t in red.transitions if str(t["status"]).startswith("failed")]
    counts = ""
    if failed or series:
        counts = (f"{len(failed)} of {red.n_found} tasks failed and {len(series)} of "
                  f"{len(red.transitions)} series have no transition because of a failure "
                  "(<a href='#transitions'>Transitions</a>, <a href='#problems'>Failed and "
                  "not knittable</a>)")  # fmt: skip
    if red.partial:
        tail = f"; {counts}" if counts else ""
        return (f"<p class='partial'>PARTIAL RESULTS: {html.escape(red.partial_reason or '')}"
                f"{tail}.</p>")  # fmt: skip
    if counts:
        return f"<p class='partial'>Every run is complete, but {counts}.</p>"
    return "<p>All planned tasks are present; every run is complete; no task failed.</p>"


def report_html(
    results: Results, title: str | None = None, progress: Callable[[str], None] | None = None
) -> str:
    """The page for ``results`` (from ``knitsweep.load``); ``progress`` hears each
    figure as it is drawn."""
    red = results.reduction
    title = title or f"knitsweep report: {red.job_name}"

    options = FigureOptions(formats=("png",), style="knitsweep")
    blocks, skipped = _figures(results, options, progress)
    roots = red.roots
    status = _headline(red)
    files = "".join(f"<li><code>{html.escape(str(p))}</code></li>" for p in results.paths)
    jobs = "".join(
        f"<h3>{html.escape(r.get('job_name', ''))} (<code>{html.escape(r['file'])}</code>)</h3>"
        f"<pre class='toml'>{html.escape(job_toml(r.get('job_json', '{}')))}</pre>"
        for r in roots
    )
    prov_rows = "".join(
        "<tr><td class='text'>" + html.escape(key) + "</td>"
        + "".join(_cell(_plain(r.get(key))) for r in roots) + "</tr>"
        for key in _PROVENANCE
    )  # fmt: skip
    prov_head = "".join(f"<th>{html.escape(Path(r['file']).name)}</th>" for r in roots)
    skipped_html = "".join(f"<li class='skipped'>{s}</li>" for s in skipped)

    def cols(columns: tuple[str, ...]) -> tuple[str, ...]:  # the stitch, when it varies
        return ("stitch", *columns) if "stitch" in red.varying else columns

    sections = [
        f"<h1>{html.escape(title)}</h1>",
        f"<p class='meta'>{len(red.points)} points, {len(red.sweeps)} sweeps, "
        f"{len(red.transitions)} series; energy-gap threshold {red.threshold:g} mJ; made by "
        f"knitsweep {__version__} on {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC</p>",
        status,
        f"<ul>{files}</ul>",
        "<h2 id='transitions'>Transitions</h2>",
        "<p>The onset of unjamming (L/r)<sub>trans</sub> of each series: the first L/r whose "
        "jamming gap (ΔE<sub>c</sub> in x, ΔE<sub>b</sub> in y) falls below the threshold; "
        "the bracket is (last jammed, first unjammed].</p>",
        table(results.transitions, cols(_TRANSITION_COLUMNS), "transitions-table"),
        "<h2>Figures</h2>",
        *blocks,
        f"<ul>{skipped_html}</ul>" if skipped else "",
        _energy_density(results),
        "<h2>Sweeps</h2>",
        table(results.sweeps, cols(_SWEEP_COLUMNS), "sweeps-table"),
        "<h2>Zero-force states</h2>",
        table(results.points, cols(_POINT_COLUMNS), "points-table"),
        "<h2 id='problems'>Failed and not knittable</h2>",
        table(results.problems, cols(_PROBLEM_COLUMNS), "problems-table"),
        "<h2>Jobs</h2>",
        jobs,
        "<h2>Provenance</h2>",
        f"<div class='scroll'><table id='provenance'><thead><tr><th>attribute</th>{prov_head}"
        f"</tr></thead><tbody>{prov_rows}</tbody></table></div>",
    ]
    body = "\n".join(s for s in sections if s)
    return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>{html.escape(title)}</title><style>{_STYLE}</style>"
            f"<script>{_SCRIPT}</script></head>\n<body>\n{body}\n</body></html>\n")  # fmt: skip


def job_toml(job_json: str) -> str:
    """The job a file was run with, as a TOML job file (the effective spec, presets
    expanded; ``knitsweep run`` reads it back)."""
    try:
        spec = json.loads(job_json)
    except (TypeError, json.JSONDecodeError):
        return str(job_json)
    if not isinstance(spec, dict):
        return str(job_json)
    return _toml_table(spec, ())


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v) if v == v and v not in (float("inf"), float("-inf")) else (
            "nan" if v != v else ("inf" if v > 0 else "-inf"))  # fmt: skip
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()
                                if x is not None) + " }"  # fmt: skip
    return json.dumps(str(v), ensure_ascii=False)  # a TOML basic string


def _toml_key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)


def _toml_table(d: dict, path: tuple[str, ...]) -> str:
    scalars = [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in d.items()
               if v is not None and not (isinstance(v, dict) and v and not _inline(v))]  # fmt: skip
    out = ([f"[{'.'.join(map(_toml_key, path))}]"] if path and scalars else []) + scalars
    for k, v in d.items():
        if isinstance(v, dict) and v and not _inline(v):
            out += ["", _toml_table(v, (*path, k))]
    return "\n".join(out).strip("\n") + ("\n" if not path else "")


def _inline(v: dict) -> bool:
    """A small table of scalars (e.g. an L range) is written inline."""
    return path_free(v) and {"start", "stop", "step"} >= set(v)


def path_free(v: dict) -> bool:
    return all(not isinstance(x, dict) for x in v.values())


def write_report(
    paths: Sequence[str | Path],
    out: str | Path,
    threshold: float = GAP_THRESHOLD,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Read ``paths`` (``knitsweep.load``) and write the report page to ``out``;
    ``progress`` hears when the files are read and each figure as it is drawn.

    Raises:
        InputError: an unreadable results file, or ``out`` not ending in .html.
    """
    out = Path(out)
    if out.suffix.lower() not in (".html", ".htm"):
        raise InputError(f"out = '{out}': the report is an .html file")
    check_writable(out, "--out")
    results = load(*paths, threshold=threshold, warn=False)
    if progress is not None:
        progress(results.reduction.status_line)
    return replace_file(out, report_html(results, progress=progress).encode("utf-8"))


__all__ = ["report_html", "table", "write_report"]
