"""Unit tier: every relative link and anchor in README.md and docs/*.md points somewhere
(a file of the repository; a heading of the target, by GitHub's anchor rule)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "slurm" / "README.md"]
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~)")


def _prose(text: str) -> str:
    """The text outside fenced code blocks and inline code spans."""
    out, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
            continue
        if not fenced:
            out.append(re.sub(r"`[^`]*`", "", line))
    return "\n".join(out)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped (letters, digits,
    spaces, hyphens and underscores kept), spaces to hyphens."""
    text = re.sub(r"`([^`]*)`", r"\1", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(path.read_text()).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        s = slug(m.group(1))
        n = seen.get(s, 0)
        seen[s] = n + 1
        out.add(s if n == 0 else f"{s}-{n}")
    return out


def links(path: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(_prose(path.read_text()))]


def test_slug_rule():
    assert (
        slug("Contact forces (Table S3, Table 2, Fig. 6h)")
        == "contact-forces-table-s3-table-2-fig-6h"
    )
    assert slug("Against the paper") == "against-the-paper"
    assert (
        slug("The results file (HDF5, `schema_version` 2)")
        == "the-results-file-hdf5-schema_version-2"
    )


@pytest.mark.parametrize(
    "doc", [d for d in DOCS if d.exists()], ids=lambda p: str(p.relative_to(ROOT))
)
def test_links_and_anchors_resolve(doc):
    bad = []
    for target in links(doc):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        dest = (doc.parent / file).resolve() if file else doc
        if not dest.exists():
            bad.append(
                f"{target}: no file {dest.relative_to(ROOT) if dest.is_relative_to(ROOT) else dest}"
            )
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with anchor #{anchor} in {dest.name}")
    assert not bad, "\n".join(bad)


def test_the_check_fails_on_a_broken_link(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text(
        "# Title\n\n[ok](#title) [bad](#nowhere) [gone](missing.md)\n```\n[code](#no)\n```\n"
    )
    assert links(doc) == ["#title", "#nowhere", "missing.md"]
    assert anchors(doc) == {"title"}
