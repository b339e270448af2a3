"""Unit tier: every relative link and anchor in README.md and the documentation site's
pages (docs/, the generated CLI reference included) points somewhere (a file of the
repository; a heading of the target, by GitHub's anchor rule), and no section of the
README as it was before the site (tests/data/readme_before_site.md) was lost in the move."""

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), ROOT / "slurm" / "README.md"]
OLD_README = Path(__file__).parent / "data" / "readme_before_site.md"


def cli_reference():
    """docs/hooks/cli_reference.py, the MkDocs hook that generates the CLI page."""
    spec = importlib.util.spec_from_file_location(
        "cli_reference", ROOT / "docs/hooks/cli_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """The pages the site generates at build time, written out as the site has them."""
    hook = cli_reference()
    page = ROOT / "docs" / hook.PAGE
    assert not page.exists(), f"{page} is generated at build time and must not be committed"
    out = tmp_path_factory.mktemp("generated") / hook.PAGE
    out.write_text(hook.render())
    return {page: out}


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


SNIPPET = re.compile(r'^--8<-- "([^"]+)"$', re.M)


def page_text(path: Path) -> str:
    """A page as the site has it: the files it includes (``--8<-- "path"``, paths from
    the repository's root, as mkdocs.yml's snippets base_path says) in their place."""
    return SNIPPET.sub(lambda m: (ROOT / m.group(1)).read_text(), path.read_text())


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(page_text(path)).splitlines():
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
def test_links_and_anchors_resolve(doc, generated):
    bad = broken_links(doc, doc, generated)
    assert not bad, "\n".join(bad)


def test_the_generated_cli_page_links_resolve(generated):
    ((page, text),) = generated.items()
    assert "### knitsweep run" in text.read_text()
    bad = broken_links(text, page, generated)
    assert not bad, "\n".join(bad)


def test_the_cli_page_has_every_command_and_option(generated):
    """The generated reference holds every command of the CLI, nested groups included,
    and every option of each as ``-h`` shows it."""
    hook = cli_reference()
    text = next(iter(generated.values())).read_text()
    root = hook.root_command()
    ctx = hook._click().Context(root, info_name="knitsweep")

    def walk(cmd, ctx):
        yield cmd, ctx
        for name in getattr(cmd, "list_commands", lambda ctx: [])(ctx):
            sub = cmd.get_command(ctx, name)
            yield from walk(sub, hook._click().Context(sub, info_name=name, parent=ctx))

    commands = list(walk(root, ctx))
    assert len(commands) >= 14  # 13 commands and the slurm group's render
    for cmd, ctx in commands:
        heading = f"# {ctx.command_path}\n"
        assert heading in text, f"no section for {ctx.command_path}"
        section = text.split(heading, 1)[1].split("\n#", 1)[0]
        for param in cmd.get_params(ctx):
            for opt in param.opts if param.param_type_name == "option" else []:
                assert f"{opt}" in section, f"{ctx.command_path}: {opt} missing"


def broken_links(doc: Path, at: Path, generated: dict[Path, Path]) -> list[str]:
    """The relative links of ``doc`` (read as if it stood at ``at``) that point nowhere."""
    bad = []
    for target in links(doc):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        dest = (at.parent / file).resolve() if file else at
        dest = generated.get(dest, dest)
        if not dest.exists():
            bad.append(
                f"{target}: no file {dest.relative_to(ROOT) if dest.is_relative_to(ROOT) else dest}"
            )
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with anchor #{anchor} in {dest.name}")
    return bad


def test_the_check_fails_on_a_broken_link(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text(
        "# Title\n\n[ok](#title) [bad](#nowhere) [gone](missing.md)\n```\n[code](#no)\n```\n"
    )
    assert links(doc) == ["#title", "#nowhere", "missing.md"]
    assert anchors(doc) == {"title"}


# ---- nothing of the old README lost --------------------------------------------------
def normalised(text: str) -> str:
    """Markdown reduced to what a reader reads: links to their text, emphasis marks,
    table pipes and line breaks gone, whitespace collapsed."""
    text = re.sub(r"!?\[((?:[^\]\[]|\[[^\]]*\])*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"\*\*|(?<!\w)\*(?=\S)|(?<=\S)\*(?!\w)", "", text)
    text = text.replace("|", " ")
    return " ".join(text.split())


def sections(text: str) -> dict[str, str]:
    """The text under each heading (outside code fences), by heading."""
    out: dict[str, list[str]] = {}
    current, fenced = "", False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
        m = None if fenced else re.match(r"^#{1,6}\s+(.*?)\s*$", line)
        if m:
            current = m.group(1)
            out[current] = []
        elif current:
            out[current].append(line)
    return {k: "\n".join(v) for k, v in out.items()}


def pieces(section: str) -> list[str]:
    """A section's sentences, table rows and code lines, normalised, of 30 characters
    or more (shorter ones, such as a table's rule, say nothing on their own)."""
    out = []
    for block in re.split(r"\n\s*\n", section):
        if block.lstrip().startswith(("|", "```")):
            out += [normalised(line) for line in block.splitlines()]
        else:
            out += re.split(r"(?<=[.;])\s+(?=[A-Z(`*])", normalised(block))
    return [p for p in out if len(p) >= 30 and not set(p) <= set("-: `")]


OLD_SECTIONS = sections(OLD_README.read_text())

# Sentences of the old README rewritten on purpose in the move, and where what they said
# went (each must still be a sentence of its section: a stale entry fails).
PATTERNS_TABLE = (
    "docs/patterns.md: the table run again with stockinette_free, the shifts against it and the "
    "fabric's thickness (issue 34)"
)
PATTERNS_REMEASURED = (
    "docs/patterns.md: the patterns job, its costs and the resolution check as "
    "measured again with the free yarns sampled along themselves and gauged "
    "(issue 34; the superseded figures stay in docs/model.md §11)"
)
REWRITTEN = {
    (
        "Install and run the main job (a small example: 4 s on 2 cores, plus ~15–30 s to "
        "compile the kernels the first time), then draw its figures:"
    ): "README.md, set-up: the run and compile times as measured again (issue 38)",
    (
        "`.ci/run` (what CI runs) installs everything as above, also starts a two-node "
        "cluster for the `multihost` tests (below), and runs exactly that (the `multihost` "
        "tests start that cluster themselves, as root, if it is not up, and remove it "
        "afterwards)."
    ): "docs/how-to/tests.md, with 'below' a link to docs/multi-node.md",
    "pattern (L/r)_trans x (L/r)_trans y a_x, a_y (mm) a_y/a_x thickness (mm) E (mJ) Y_sec x, y (N/mm)": PATTERNS_TABLE,
    "stockinette 15.535 15.530 2.882, 2.214 0.77 2.36 0.3605 0.127, 0.414": PATTERNS_TABLE,
    "garter 14.166 unjammed from 12.74 (L = 9.425 mm) on 3.266, 1.462 0.45 4.60 0.3092 0.146, 0.016": PATTERNS_TABLE,
    "1×1 rib 13.542 12.223 1.583, 2.268 1.43 3.19 0.2476 0.066, 0.133": PATTERNS_TABLE,
    "seed 15.045 15.270 2.766, 1.676 0.61 3.43 0.3533 0.095, 0.254": PATTERNS_TABLE,
    "`jobs/patterns_k0.1.toml`: stockinette, garter, 1×1 rib and seed, each found adaptively in L in x and y (156 tasks, 29 s of wall time under `mpirun -n 3` on this project's 2 cores).": PATTERNS_REMEASURED,
    "(a) the unjamming transition (L/r)_trans, the bar its bracket (▼: garter pulled in y is unjammed wherever it can be knitted, from L = 9.425 mm);": PATTERNS_REMEASURED,
    "(c) the zero-force stitch's a_y/a_x. a_x and a_y are the course and wale spacing per stitch for every pattern, and the strain is the fabric's, so the patterns compare directly.": PATTERNS_REMEASURED,
    "Starts come from the authors' Init files: garter's tilted out of the plane, rib's as they are, seed's cut at the middle of the sinker loop and tilted (each with the pattern's crossing signs and the cores apart; a start whose cores overlap is refused, naming the segments).": PATTERNS_REMEASURED,
    "Its resolution: the free yarn's contact samples sit at fixed curve parameters, so the segment speeds are bounded to [0.05, 0.3] L and a state whose contact energy moves by more than 25 % with twice the samples is not converged; where the cores overlap with twice the samples it is too tight to knit.": PATTERNS_REMEASURED,
    "(Before these bounds rib's relaxations had shortened segments to 0.05 mm and let hard cores pass between sparse samples: E_c 0.008 mJ at 10 samples per segment, 23 mJ at 40.)": PATTERNS_REMEASURED,
    "And they unjam at shorter yarn: stockinette at (L/r)_trans = 15.5 in both directions (the paper's 15.54), seed at 15.0–15.3, garter at 14.2 across the course, rib at 13.5 and 12.2: mixing knit and purl stitches frees room that a stockinette stitch of the same yarn does not have. knitsweep's verdicts per pattern (transitions, figures, tables, the adaptive search, the HTML report) are the stockinette study's own functions with a `stitch` column;": PATTERNS_REMEASURED,
    "`benchmarks/bench_pattern_pipeline.py` measures a pattern's point (zero force and both sweeps, one start, median of 3, two rounds alternately) at 1.0–2.0 CPU s, 9.7–12.4× stockinette's at L = 10.5 mm and 8.0–17× at 11.6 and 12.2 mm, where stockinette's own costs 0.08–0.19 s (before the new step 1.3–5.0 s, 12.5–32× and 9.4–30×; 19–42× and 17–69× before the checks were compiled; 32–378× before the grid); the patterns job 59–67 → 43–45 CPU s.": PATTERNS_REMEASURED,
    "The step's rounding moves the patterns' minima by up to ~10⁻⁴ mJ either way, as much as a change of a few ulps in the old step's Hessian does (docs/model.md §11).": PATTERNS_REMEASURED,
    "A minimum that SLSQP ended at (it stops when E stops changing) is relaxed once more by Newton, kept if no higher: rib's minimum at 11.6 mm fell by 4·10⁻⁶ mJ, and its sweeps' first steps no longer crawl (373 and 380 Newton iterations → 2–3) along the near-flat modes of a free yarn, its joints sliding along it (rib's point there 0.99–1.05 → 0.87–0.90 CPU s; the others within noise).": PATTERNS_REMEASURED,
    "What is left is the zero-force descents (Newton walking back from the last continuation stage with bounds taken and let go one at a time; garter's 30 SLSQP stages) and SLSQP; spacing the joints evenly along the yarn (a penalty) stops the crawl but raises the minima by up to 7·10⁻⁴ mJ and slowed garter's sweeps at 12.2 mm 9× (docs/model.md §11).": PATTERNS_REMEASURED,
    "A pattern's point stays 6–15× stockinette's at 11.6 and 12.2 mm (2× was the aim).": PATTERNS_REMEASURED,
}


def test_the_old_readme_had_its_sections():
    assert len(OLD_SECTIONS) == 20
    assert "Crash safety, the journal and checkpoints" in OLD_SECTIONS
    every = {p for text in OLD_SECTIONS.values() for p in pieces(text)}
    assert set(REWRITTEN) <= every, set(REWRITTEN) - every


@pytest.mark.parametrize("heading", list(OLD_SECTIONS))
def test_no_section_of_the_old_readme_is_lost(heading):
    """Each section of the README before the documentation site stands, nearly word for
    word, in README.md or a page of docs/ (or slurm/README.md, which the site includes).
    Edited since: a fifth of a section's sentences (at least one) may differ, so that the
    docs can be kept up to date; a section moved away and lost fails."""
    corpus = " ".join(normalised(d.read_text()) for d in DOCS)
    wanted = pieces(OLD_SECTIONS[heading])
    missing = [p for p in wanted if p not in corpus and p not in REWRITTEN]
    assert len(missing) <= max(1, len(wanted) // 5), (
        f"{len(missing)} of {len(wanted)} sentences of the old README's section "
        f"{heading!r} are nowhere in README.md or docs/:\n" + "\n".join(missing)
    )


def test_the_lost_section_check_fails_on_a_missing_sentence():
    section = "A sentence that stands here, long enough. Another one, thirty characters long."
    assert pieces(section) == [
        "A sentence that stands here, long enough.",
        "Another one, thirty characters long.",
    ]
    assert normalised("[a **link**](x.md) | `code` |") == "a link `code`"


def test_the_readme_quotes_the_ci_test_command():
    """.ci/run runs the test command that README.md's set-up quotes (its comment says so)."""
    ci = (ROOT / ".ci" / "run").read_text()
    (command,) = re.findall(r"^run_tests\(\) \{ (.+); \}$", ci, re.M)
    readme = (ROOT / "README.md").read_text()
    assert f"&& {command}\n```" in readme and f"`{command}`" in readme
