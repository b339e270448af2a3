"""Integration tier: one entry of the observable registry (``quantities.OBSERVABLE_REGISTRY``)
puts an observable in the results file, the tables, the CSV files and the report; files
written before it was registered still read."""

import shutil

import h5py
import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.quantities import (
    COLUMN_QUANTITY,
    OBSERVABLE_REGISTRY,
    SCALARS,
    column_name,
    dataset_quantity,
    registered,
)


def test_every_registered_observable_is_computable_and_named():
    for o in OBSERVABLE_REGISTRY:
        column_name(o.name, o.units)  # a unit with a table suffix
        if o.kind == "sweep":
            assert o.from_steps is not None and COLUMN_QUANTITY[o.column].units == o.units
        else:
            assert callable(getattr(CellModel, o.method)), o.name
        if o.kind == "step":
            assert dataset_quantity("sweeps", o.name) == o.quantity
        if o.kind == "point":
            assert SCALARS[o.name] == o.quantity
    names = [(o.kind, o.name) for o in OBSERVABLE_REGISTRY]
    assert len(set(names)) == len(names)


def test_max_curvature_is_the_sampled_yarns_turning_rate():
    """Against the circumradius of three consecutive points of the centre-line sampled
    finely (a curvature measured without derivatives)."""
    model = CellModel(StitchParams(stitch="rib"))
    x = model.stitch.start(1)
    cp = model.control_points(x)
    t = np.linspace(0.0, 1.0, 4001)
    from math import comb

    basis = np.stack([comb(5, i) * t**i * (1 - t) ** (5 - i) for i in range(6)], axis=1)
    pts = np.einsum("ti,sic->stc", basis, cp)
    a, b, c = pts[:, :-2], pts[:, 1:-1], pts[:, 2:]
    ab, bc, ca = (np.linalg.norm(v, axis=-1) for v in (b - a, c - b, a - c))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=-1)
    kappa = float(np.max(2 * area2 / (ab * bc * ca)))
    assert model.max_curvature(x, samples=4001) == pytest.approx(kappa, rel=1e-5)
    assert model.max_curvature(x) == pytest.approx(kappa, rel=2e-3)  # 64 samples


def test_a_run_stores_and_tabulates_every_registered_observable(tiny_reference, tmp_path):
    import knitsweep
    from knitsweep.report.html import header
    from knitsweep.report.tables import write_tables

    with h5py.File(tiny_reference, "r") as f:
        sweeps = f["sweeps"]
        for o in registered("step"):
            col = next(k for k in sweeps if k == o.name or k.startswith(o.name))
            assert sweeps[col].attrs["units"] == o.units
    res = knitsweep.load(tiny_reference)
    for o in registered("point"):
        assert np.all(np.isfinite(res.points[o.column].astype(float))), o.column
    for o in registered("step"):
        assert np.all(np.isfinite(res.curves[column_name(o.name, o.units)])), o.name
    peak = res.curves.groupby("task_id")["max_curvature_per_mm"].max()
    got = res.sweeps.set_index("task_id")["peak_curvature_per_mm"]
    np.testing.assert_array_equal(got.loc[peak.index].to_numpy(), peak.to_numpy())
    assert header("peak_curvature_per_mm") == "largest curvature (1/mm)"
    written = {p.name: p for p in write_tables(res, tmp_path / "tables")}
    assert "peak_curvature_per_mm" in written["sweeps.csv"].read_text().splitlines()[0]
    pytest.importorskip("xarray")
    ds = res.to_xarray()
    assert ds["peak_curvature_per_mm"].attrs["units"] == "1/mm"


def test_a_file_written_before_an_observable_reads_without_it(data_dir, tmp_path):
    import knitsweep

    old = tmp_path / "old.h5"
    shutil.copy(data_dir / "schema2_tiny.h5", old)
    res = knitsweep.load(old)
    assert len(res.sweeps) and res.sweeps["peak_curvature_per_mm"].isna().all()
    assert res.points["max_curvature0_per_mm"].isna().all()
    assert "max_curvature_per_mm" not in res.curves and len(res.curves)


def test_the_secant_poisson_ratio_of_a_known_deformation():
    """ν = −ε_⊥/ε at strain 0.02, between steps that bracket it; None short of it."""
    from knitsweep.quantities import secant_poisson_ratio

    strain = np.array([0.0, 0.007, 0.015, 0.026, 0.04])
    across = 2.2 * (1.0 - 0.37 * strain)  # a linear contraction: ν = 0.37 at every strain
    assert secant_poisson_ratio(strain, across) == pytest.approx(0.37, rel=1e-12)
    bent = 2.2 * (1.0 - 0.5 * strain - 10.0 * strain**2)  # ε_⊥(0.02) by the chord 0.015-0.026
    lo, hi = bent[2] / 2.2 - 1, bent[3] / 2.2 - 1
    chord = lo + (hi - lo) * (0.02 - 0.015) / (0.026 - 0.015)
    assert secant_poisson_ratio(strain, bent) == pytest.approx(-chord / 0.02, rel=1e-12)
    assert secant_poisson_ratio(strain[:3], across[:3]) is None


def test_the_tables_poisson_ratios_come_from_the_transverse_period(tiny_reference):
    """ν_xy of the x sweeps from a_y, ν_yx of the y sweeps from a_x, read off the curves
    table; knitted stockinette contracts across when pulled (0 < ν)."""
    import html

    import knitsweep
    from knitsweep.report.html import header

    res = knitsweep.load(tiny_reference)
    nu = res.sweeps.set_index("task_id")["poisson_ratio"]
    assert html.unescape(header("poisson_ratio")) == "Poisson's ratio"  # (unit 1: none shown)
    for task, g in res.curves.groupby("task_id"):
        across = g["a_y_mm" if g["direction"].iloc[0] == "x" else "a_x_mm"].to_numpy()
        eps, e_perp = g["strain"].to_numpy(), across / across[0] - 1
        j = int(np.searchsorted(eps, 0.02))
        w = (0.02 - eps[j - 1]) / (eps[j] - eps[j - 1])
        expect = -((1 - w) * e_perp[j - 1] + w * e_perp[j]) / 0.02
        assert nu[task] == pytest.approx(expect, rel=1e-12) and 0 < nu[task] < 2


def test_the_poisson_curve_is_the_tables_ratio_at_the_secant_strain(tiny_reference):
    """The report's ν(ε) of each uniaxial sweep (figure fig5c) is −ε_⊥/ε of the free
    period at every step, NaN at rest, and its chord at ε = 0.02 is the tables' value."""
    from knitsweep.report import reduce_results

    red = reduce_results(tiny_reference)
    nu = {row["task_id"]: row["poisson_ratio"] for row in red.sweeps}
    assert red.curves and all(c.direction in ("x", "y") for c in red.curves)
    for c in red.curves:
        assert np.isnan(c.poisson_ratio[0]) and np.all(np.isfinite(c.poisson_ratio[1:]))
        np.testing.assert_allclose(c.poisson_ratio[1:] * c.strain[1:], -c.transverse_strain[1:],
                                   rtol=1e-12)  # fmt: skip
        chord = -np.interp(0.02, c.strain, c.transverse_strain) / 0.02
        assert nu[c.task_id] == pytest.approx(chord, rel=1e-12)
