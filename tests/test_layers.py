"""Unit tier: the package's layers, read from its imports (docs/architecture.md, "How it is built").

Each module may import only from its own layer or the layers below it, lazy imports
inside functions included; the light commands and the config floor load neither
numba nor scipy.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "knitsweep"

# bottom to top, one package (or top-level module) a layer; a module belongs to the
# first entry that is a prefix of its name
LAYERS = [
    ["_version"],
    ["errors"],
    ["util"],  # small helpers: plain values, forked helpers, safe file I/O
    ["kernels"],  # generic numba: knows no stitch, no settings
    ["stitches"],  # geometries behind one interface; their kernels call down into kernels
    ["paths"],  # the load paths' registry: plain data
    ["config"],
    ["presets"],  # the presets: settings of every layer in one word
    ["quantities"],
    ["analysis"],
    ["formats"],
    ["store"],  # the results store: below both service and report
    ["model"],
    ["compilation"],  # compiling the kernels a command uses
    ["relax"],
    ["zero_force"],  # the deprecated re-export of relax.zero_force (the documented API)
    ["strain_sweep"],
    ["studies"],
    ["service"],
    ["report"],
    ["cli"],
    ["__main__"],
]

# inside each subpackage, its modules bottom to top (a module may import those before it);
# the package's __init__ sits on top of its modules
MODULE_ORDER = {
    "util": ["plain_values", "forking", "safe_files"],
    "kernels": ["bezier", "elementary", "arclength", "partition", "bending", "contact",
                "neighbours", "forces", "cell", "kkt", "kkt_rows", "mirrored", "pattern_cell",
                "checks", "raster"],
    "stitches": ["base", "topology", "patterns", "images", "stockinette", "stockinette_free",
                 "garter", "rib", "seed", "chart"],
    "stitches.stockinette": ["layout", "crossover", "geometry", "data"],
    "stitches.stockinette_free": ["layout", "geometry", "ansatz", "gauge", "data"],
    "stitches.garter": ["layout", "geometry", "data"],
    "stitches.chart": ["geometry"],
    "analysis": ["_common", "fitting", "stress_strain", "metrics", "transitions", "paper",
                 "volumes", "energy_density"],
    "analysis.volumes": ["_nearest", "geometry", "estimators"],
    "store": ["checksum", "format", "journal", "provenance", "columns", "table", "sealed", "read",
              "compatible", "failed_writes", "writer", "salvage", "sweep_file"],
    "relax": ["problem", "slsqp", "newton", "result", "relaxer", "chains", "continuation",
              "zero_force"],
    "strain_sweep": ["result", "schedule", "rest_skew", "sweep"],
    "studies": ["accuracy"],
    "service": ["signals", "grid", "id_forms", "jobs", "run_plan", "progress", "retry", "spread", "worker",
                "adaptive", "executors", "slurm", "master", "runs", "recovery"],
    "report": ["force_columns", "series", "reduce", "tidy", "results", "tables", "declutter", "path_style", "plotting",
               "fig_energy", "fig_mechanics", "fig_volumes", "fig_forces", "fig_patterns",
               "fig_inplane", "fig_energy_density", "figures", "html", "tile", "sources", "tube_mesh", "raster", "export3d", "render",
               "contact_volumes"],
    "service.executors": ["protocol", "local", "mpi"],
    "cli": ["common", "model_commands", "run_commands", "analysis_commands", "application"],
}  # fmt: skip


def _layer(module: str) -> int:
    for i, names in enumerate(LAYERS):
        if any(module == n or module.startswith(n + ".") for n in names):
            return i
    raise AssertionError(f"module knitsweep.{module} is in no layer of this test")


def _rank(package: str, module: str) -> int:
    """Position of ``module`` (relative name, e.g. ``kernels.cell``) in its package's
    order; the package's own __init__ ranks above every module of it."""
    if module == package:
        return len(MODULE_ORDER[package])
    child = module.removeprefix(package + ".").split(".")[0]
    order = MODULE_ORDER[package]
    assert child in order, f"knitsweep.{module} is not in MODULE_ORDER[{package!r}]"
    return order.index(child)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported knitsweep module relative to the package) of every import."""
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    package = list(parts[:-1])  # the package holding the module (or the __init__)
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] if node.module else [f"{target}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for name in names:
            if name == "knitsweep" or name.startswith("knitsweep."):
                rel = name.removeprefix("knitsweep").lstrip(".")
                if rel:
                    out.append((node.lineno, rel))
    return out


MODULES = sorted(p for p in PKG.rglob("*.py"))


def _name(path: Path) -> str:
    return ".".join(path.relative_to(PKG).with_suffix("").parts).removesuffix(".__init__")


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_imports_only_go_down(path):
    here = _name(path)
    if here == "__init__":  # the root: only the version and, lazily, the top (load)
        for line, target in _imports(path):
            assert target.split(".")[0] in ("_version", "report", "analysis"), (
                f"__init__.py:{line} imports {target}: the root imports only what load() needs"
            )
        return
    mine = _layer(here)
    for line, target in _imports(path):
        there = _layer(target)
        where = f"{path.relative_to(PKG)}:{line} imports {target}"
        assert there <= mine, f"{where} (a layer up)"
        if there == mine:  # inside one package: only modules before this one
            package = next(p for p in sorted(MODULE_ORDER, key=len, reverse=True)
                           if here.startswith(p + ".") or here == p
                           if target.startswith(p + ".") or target == p)  # fmt: skip
            assert _rank(package, target) <= _rank(package, here), f"{where} (up its package)"


def test_every_module_has_a_place():
    """Every module of a subpackage is in MODULE_ORDER, so the order test sees it."""
    for path in MODULES:
        here = _name(path)
        package = next((p for p in sorted(MODULE_ORDER, key=len, reverse=True)
                        if here.startswith(p + ".")), None)  # fmt: skip
        if package is not None:
            _rank(package, here)


def test_kernels_know_no_settings_and_no_stitch():
    for path in (PKG / "kernels").rglob("*.py"):
        for line, target in _imports(path):
            assert target.startswith("kernels"), f"kernels/{path.name}:{line} imports {target}"


def _imported_modules(args: list[str], cwd: Path) -> set[str]:
    out = subprocess.run([sys.executable, "-X", "importtime", *args], capture_output=True,
                         text=True, cwd=cwd, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    names = set()
    for line in out.stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            names.add(line.rsplit("|", 1)[1].strip())
    return names


def test_config_floor_loads_neither_numba_nor_scipy(tmp_path):
    names = _imported_modules(["-c", "import knitsweep.config, knitsweep.stitches"], tmp_path)
    assert "knitsweep.config" in names
    assert not {n for n in names if n.split(".")[0] in ("numba", "scipy", "h5py")}


def test_status_loads_neither_numba_nor_scipy(tiny_reference, tmp_path):
    names = _imported_modules(["-m", "knitsweep", "status", str(tiny_reference)], tmp_path)
    assert "knitsweep.service.runs" in names
    assert not {n for n in names if n.split(".")[0] in ("numba", "scipy")}


def test_one_definition_of_the_gap_threshold():
    hits = [
        f"{p.relative_to(PKG)}:{i}"
        for p in MODULES
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if "5e-5" in line or "5e-05" in line
    ]
    assert len(hits) == 1 and hits[0].startswith("analysis/transitions.py:"), hits


def test_a_run_with_nothing_to_compute_loads_no_kernels(tiny_reference, tmp_path):
    """Resuming a finished file starts no executor: numba is not even imported."""
    import shutil

    from conftest import TINY

    done = tmp_path / "done.h5"
    shutil.copy(tiny_reference, done)
    names = _imported_modules(["-m", "knitsweep", "run", str(TINY), "--out", str(done),
                               "--quiet"], tmp_path)  # fmt: skip
    assert "knitsweep.service.master" in names
    assert not {n for n in names if n.split(".")[0] in ("numba", "scipy")}


def test_only_stitches_and_kernels_name_the_image_groups():
    """Above stitches/ and kernels/ nothing branches on which image group a stitch has:
    the groups' names appear in no string there (the model calls ``stitches.images``)."""
    hits = []
    for path in MODULES:
        if path.relative_to(PKG).parts[0] in ("stitches", "kernels"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value in ("glides", "translations"):
                hits.append(f"{path.relative_to(PKG)}:{node.lineno}")
    assert hits == []


def test_the_old_zero_force_path_warns_and_is_the_same_api():
    """``knitsweep.zero_force`` (the documented path before the move into relax/) is a
    thin re-export that warns."""
    import importlib

    from knitsweep.relax import zero_force as moved

    sys.modules.pop("knitsweep.zero_force", None)
    with pytest.warns(DeprecationWarning, match="knitsweep.relax.zero_force"):
        old = importlib.import_module("knitsweep.zero_force")
    assert old.zero_force is moved.zero_force and old.ZeroForce is moved.ZeroForce
