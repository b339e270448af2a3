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
    assert "16.2162" in table.group(0)  # (L/r)_trans of the tiny job's series
    assert 'id="problems-table"' in dom and 'id="provenance"' in dom
    shot = tmp_path / "report.png"
    _browse(tmp_path, page.as_uri(), "--window-size=1280,2000", f"--screenshot={shot}")
    assert shot.stat().st_size > 50_000


def test_report_refuses_a_page_that_is_not_html(tiny_reference, tmp_path):
    out = subprocess.run([sys.executable, "-m", "knitsweep", "report", str(tiny_reference),
                          "--out", str(tmp_path / "r.pdf")], capture_output=True, text=True,
                         timeout=120)  # fmt: skip
    assert out.returncode == 2 and "the report is an .html file" in out.stderr
