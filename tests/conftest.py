import json
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
SHIPPED = (Path(__file__).resolve().parents[1] / "knitsweep" / "stitches" / "stockinette"
           / "data")  # the authors' Init_*.dat  # fmt: skip
TINY = DATA / "jobs" / "tiny.toml"  # 2 points, 4 sweeps, coarse numerics: ~2 s serially
VOLATILE = {"seconds", "relax_seconds", "wall_seconds", "rank", "host"}


def golden_cases():
    return json.loads((DATA / "golden_energy.json").read_text())


def golden_params(case):
    from knitsweep.config import StitchParams

    P = case["params"]
    return StitchParams.from_internal(P["L"], P["bend"], P["reg"], P["r"], P["rc"], P["k"], P["p"])


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def init1() -> np.ndarray:
    from knitsweep.formats import read_state

    return read_state(SHIPPED / "Init_1.dat")


def physics(path):
    """Every task's stored arrays and status, minus timings and placement."""
    import h5py

    out = {}
    with h5py.File(path, "r") as f:
        for kind in ("points", "sweeps"):
            for tid, g in f[kind].items():
                rec = {k: g[k][()] for k in g if k not in VOLATILE}
                rec["status"] = g.attrs["status"]
                out[(kind, tid)] = rec
    return out


def assert_same_results(a, b):
    """Two results files hold the same tasks with bit-identical arrays."""
    pa, pb = physics(a), physics(b)
    assert pa.keys() == pb.keys()
    for key in pa:
        assert pa[key].keys() == pb[key].keys(), key
        for name in pa[key]:
            assert np.array_equal(pa[key][name], pb[key][name]), (key, name)


@pytest.fixture(scope="session")
def tiny_reference(tmp_path_factory):
    """The tiny job, run serially and uninterrupted (do not modify the file)."""
    from knitsweep import service

    out = tmp_path_factory.mktemp("tiny_reference") / "tiny.h5"
    summary = service.run(TINY, out, executor="serial", show_progress=False)
    assert summary.counts["done"] == summary.total == 6
    return out
