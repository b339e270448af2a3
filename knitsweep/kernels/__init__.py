"""Generic numba kernels: plain ndarrays and scalars in and out, nothing above
numpy/numba, and nothing that knows which stitch it computes (a stitch's geometry
kernel, state -> control points + Jacobian, lives in ``knitsweep.stitches``).

Pipeline: bezier (basis tables) -> bending, contact (energies + gradients on control
points; contact's candidate search in partition, its vectorisable pow in elementary,
an optional Verlet list in neighbours) -> cell (their composition with a stitch's
Jacobian); forces (by contact class); kkt (the trust-region Newton step of the
relaxations, on plain arrays).

Compiled kernels are cached on disk (``cache=True``). Numba keys a cached
function on its own source file only, so a kernel that inlines another would
keep stale code after an upgrade that changes only the callee. The cache
directory is therefore keyed on every kernel source, numba's and Python's
version: ``$NUMBA_CACHE_DIR/knitsweep-kernels-<hash>`` if ``NUMBA_CACHE_DIR`` is
set (e.g. node-local on a cluster), else ``~/.cache/knitsweep/kernels-<hash>``.
"""

import hashlib
import os
import platform
from pathlib import Path

import numba


def _cache_dir() -> str:
    digest = hashlib.sha256(f"{numba.__version__} {platform.python_version()}".encode())
    package = Path(__file__).parent.parent
    # every compiled source: these generic kernels and the stitches' geometry kernels
    # (which import this package first, so that their cache lands here too)
    sources = [*Path(__file__).parent.glob("*.py"), *(package / "stitches").rglob("*.py")]
    for src in sorted(sources):
        digest.update(str(src.relative_to(package)).encode())
        digest.update(src.read_bytes())
    tag = digest.hexdigest()[:16]
    if os.environ.get("NUMBA_CACHE_DIR"):
        return os.path.join(os.environ["NUMBA_CACHE_DIR"], f"knitsweep-kernels-{tag}")
    cache_home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(cache_home, "knitsweep", f"kernels-{tag}")


numba.config.CACHE_DIR = _cache_dir()

ENTRY_POINTS = tuple(f"knitsweep.kernels.{name}" for name in (
    "cell.cell_energy_listed", "contact.find_contacts", "forces.contact_forces_by_class",
    "kkt.kkt_step"))  # fmt: skip
"""The kernels every task calls, by module path and name (``kernel``); the stitch's own
ones are added by ``compilation.kernel_entry_points``."""


def kernel(name: str):
    """The numba dispatcher called ``name`` ("knitsweep.kernels.cell.cell_energy_listed"):
    importing its module compiles nothing."""
    import importlib

    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def in_cache(dispatcher) -> bool:
    """Whether numba's on-disk cache holds a compiled version of ``dispatcher`` that
    numba would load here: its index for this source file (numba keys the index on the
    file's path and content, so another checkout's kernels do not count) has an entry
    for this CPU and this bytecode (the key numba looks up), and that entry's data file
    is there."""
    import os

    cache = getattr(dispatcher, "_cache", None)
    index_file = getattr(cache, "_cache_file", None)
    if index_file is None:  # caching off, or no writable cache directory
        return False
    try:
        index = index_file._load_index()
        codegen = dispatcher.targetctx.codegen()
        return any(cache._index_key(key[0], codegen) == key
                   and os.path.exists(index_file._data_path(name))
                   for key, name in index.items())  # fmt: skip
    except Exception:  # an unreadable index, or a numba whose cache looks otherwise
        return False


def cached(entry_points: tuple[str, ...] = ENTRY_POINTS) -> bool:
    """Whether numba's on-disk cache holds every kernel of ``entry_points`` (names as in
    ``ENTRY_POINTS``; by default the ones every task calls) compiled from this
    checkout's sources for this CPU (``in_cache``); if not, the first call compiles
    them (``compilation.compile_notice`` says how long that usually takes)."""
    return all(in_cache(kernel(name)) for name in entry_points)
