"""Unit tier: the package's layers, read from its imports (README "How it is built").

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

# bottom to top; a module belongs to the first entry that is a prefix of its name
LAYERS = [
    ["state"],
    ["errors"],
    ["config", "kernels", "quantities"],
    ["analysis", "formats"],
    ["store"],
    ["model"],
    ["relax"],
    ["zero_force"],
    ["strain_sweep"],
    ["service", "studies"],
    ["report"],
    ["cli", "__main__"],
]


def _layer(module: str) -> int:
    for i, names in enumerate(LAYERS):
        if any(module == n or module.startswith(n + ".") for n in names):
            return i
    raise AssertionError(f"module knitsweep.{module} is in no layer of this test")


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


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_imports_only_go_down(path):
    here = ".".join(path.relative_to(PKG).with_suffix("").parts).removesuffix(".__init__")
    if here == "__init__":
        return
    mine = _layer(here)
    for line, target in _imports(path):
        top = target.split(".")[0]
        if top in ("__version__",):
            continue
        assert _layer(target) <= mine, f"{path.relative_to(PKG)}:{line} imports {target} (upwards)"


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
    names = _imported_modules(["-c", "import knitsweep.config, knitsweep.state"], tmp_path)
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
