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

COMPILE_SECONDS = 30
"""About how long compiling every kernel takes once (benchmarks/bench_compile.py on the
idle 2-core project VM: 21 s in one process, 14 s with the groups side by side, which
``compilation.compile_kernels`` does when cores are idle; a loaded machine takes longer)."""
ENTRY_POINTS = ("cell.cell_energy_listed-", "contact.find_contacts-",
                 "forces.contact_forces_by_class-", "kkt.kkt_step-")  # fmt: skip


def cached(entry_points: tuple[str, ...] = ENTRY_POINTS) -> bool:
    """Whether numba's on-disk cache holds this version's kernels (by default the
    ones every task uses; ``("cell.cell_energy_listed-",)`` for one energy) already; if not,
    the first call compiles them: up to ``COMPILE_SECONDS``."""
    indexes = [p.name for p in Path(numba.config.CACHE_DIR).glob("**/*.nbi")]
    return all(any(n.startswith(entry) for n in indexes) for entry in entry_points)


def compile_notice(entry_points: tuple[str, ...] = ENTRY_POINTS) -> str | None:
    """What to tell a user before the first call compiles these kernels (None if
    they are cached)."""
    if cached(entry_points):
        return None
    return (f"compiling numerical kernels, once per install: ~{COMPILE_SECONDS} s "
            f"(cached in {numba.config.CACHE_DIR})")  # fmt: skip
