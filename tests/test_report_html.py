"""Integration tier: the self-contained HTML report, rendered in a real headless
Chromium (Debian's package; `.ci/run` installs it)."""

import re
import shutil
import subprocess
import sys

import pytest

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync")  # fmt: skip


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.fail("headless Chromium is needed (apt-get install chromium; .ci/run does)")
    return exe


def _browse(tmp_path, url, *args):
    cmd = [_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", *args, url]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.browser
def test_report_renders_with_figures_and_transitions(tiny_reference, tmp_path):
    page = tmp_path / "report.html"
    out = subprocess.run([sys.executable, "-m", "knitsweep", "report", str(tiny_reference),
                          "--out", str(page)], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    text = page.read_text()
    assert "http://" not in text and "https://" not in text  # nothing to fetch: reads offline
    dom = _browse(tmp_path, page.as_uri(), "--virtual-time-budget=10000", "--dump-dom")
    loaded = re.search(r'data-figures-loaded="(\d+)/(\d+)"', dom)
    assert loaded is not None, "the page's load handler did not run"
    ok, total = map(int, loaded.groups())
    assert ok == total >= 5, loaded.group(0)
    table = re.search(r'<table id="transitions-table">.*?</table>', dom, re.S)
    assert table is not None
    assert len(re.findall(r"<tr>", table.group(0))) == 1 + 2  # header + the 2 series
    assert "16.22" in table.group(0)  # (L/r)_trans of the tiny job's series, 4 digits
    assert 'id="problems-table"' in dom and 'id="provenance"' in dom
    shot = tmp_path / "report.png"
    _browse(tmp_path, page.as_uri(), "--window-size=1280,2000", f"--screenshot={shot}")
    assert shot.stat().st_size > 50_000


def test_report_refuses_a_page_that_is_not_html(tiny_reference, tmp_path):
    out = subprocess.run([sys.executable, "-m", "knitsweep", "report", str(tiny_reference),
                          "--out", str(tmp_path / "r.pdf")], capture_output=True, text=True,
                         timeout=120)  # fmt: skip
    assert out.returncode == 2 and "the report is an .html file" in out.stderr


LEAKS = (":func:", ":class:", ":data:", "``", "SMALL_STRAIN", "functools", "partial(",
         "Create a new function", "Args:", "Returns:", "Raises:", "self.", "__")  # fmt: skip


def _visible_text(page: str) -> str:
    body = re.sub(r"<(script|style)[^>]*>.*?</\1>", " ", page, flags=re.S)
    body = re.sub(r"<[^>]+>", " ", body)  # tags; attributes (data URIs) go with them
    import html

    return re.sub(r"\s+", " ", html.unescape(body))


def test_report_is_written_for_readers(tiny_reference, tmp_path):
    import json

    import h5py
    import tomllib

    from knitsweep.report.figures import CAPTIONS, FIGURES
    from knitsweep.report.html import write_report

    page = write_report([tiny_reference], tmp_path / "r.html").read_text()
    text = _visible_text(page)
    leaks = [w for w in LEAKS if w in text]
    assert not leaks, leaks
    assert set(CAPTIONS) == set(FIGURES)
    assert CAPTIONS["fig3_energy_gaps.png"] in text
    # headers name the unit; numbers have four significant digits, no e-notation
    assert "Y sec (N/mm)" in text and "k (mN/mm²)" in text and "ΔE c (mJ)" in text
    cells = re.findall(r"<td>([^<]*)</td>", page)
    numbers = [c for c in cells if re.fullmatch(r"-?[\d.]+(×10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)?", c)]
    assert numbers and all(len(n.split("×")[0].lstrip("-0.").replace(".", "")) <= 4
                           for n in numbers), numbers  # fmt: skip
    assert not any(re.search(r"\de[-+]\d", c) for c in cells)
    # the job as a TOML job file, the same spec as the file's
    toml = re.search(r"<pre class='toml'>(.*?)</pre>", page, re.S)
    assert toml is not None
    import html

    with h5py.File(tiny_reference, "r") as f:
        spec = json.loads(f.attrs["job_json"])
    assert tomllib.loads(html.unescape(toml.group(1))) == _no_none(spec)


def _no_none(d):
    return {k: _no_none(v) if isinstance(v, dict) else v for k, v in d.items() if v is not None}


@pytest.mark.browser
def test_no_element_overflows_the_page(tiny_reference, tmp_path):
    from knitsweep.report.html import write_report

    page = write_report([tiny_reference], tmp_path / "r.html")
    for width in (700, 1280):
        dom = _browse(tmp_path, page.as_uri(), f"--window-size={width},900",
                      "--virtual-time-budget=10000", "--dump-dom")  # fmt: skip
        wide = re.search(r'data-overflowing="([^"]*)"', dom)
        assert wide is not None, "the page's load handler did not run"
        assert wide.group(1) == "", (width, wide.group(1))
