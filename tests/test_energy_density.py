"""The in-plane energy density (knitsweep.analysis.energy_density, docs/energy-density.md):
the fit against a known W, its stress and tangent as its exact derivatives, the file
round trip, the sampled region, and a real job's fit from the command line."""

import json

import numpy as np
import pytest
from conftest import one_error_line, run_knitsweep

import knitsweep
from knitsweep.analysis.energy_density import (
    DensitySamples,
    fit_energy_density,
    held_out_errors,
    load_energy_density,
    sampled_domain,
)


def _known(e):
    """A smooth convex W (N/mm) that stiffens like a jamming fabric, its gradient."""
    x, y = e[..., 0], e[..., 1]
    w = 0.05 * x**2 + 0.3 * y**2 + 0.04 * x * y + 2.0 * x**4 + 3.0 * y**4
    g = np.stack([0.1 * x + 0.04 * y + 8.0 * x**3, 0.6 * y + 0.04 * x + 12.0 * y**3], -1)
    return w, g


def _fan(angles_deg=range(-45, 136, 15), n=40, reach=0.3):
    """Samples of ``_known`` along rays from the origin (as a sweep's steps), and the two
    'uniaxial' curves (here rays too)."""
    units = [np.array([np.cos(np.radians(a)), np.sin(np.radians(a))]) for a in angles_deg]
    return _along(units, _known, n, reach)


def _along(units, known, n, reach):
    """Samples of ``known`` along rays from the origin in the unit directions ``units``, n
    steps to ``reach`` each, each ray named as the jobs name it."""
    eps, names, ends = [], [], {}
    for u in units:
        name = "ray:" + ",".join(f"{v:.6g}" for v in u / np.abs(u).max())
        t = np.linspace(0.0, reach, n)[:, None] * u
        eps.append(t)
        names += [name] * n
        ends[name] = tuple(t[-1])
    eps = np.concatenate(eps)
    w, g = known(eps)
    point = {"stitch": "test", "L_mm": 1.0, "k_mN_per_mm2": 0.1, "a_x0_mm": 1.0, "a_y0_mm": 1.0}
    return DensitySamples(eps, w, g, np.array(names, dtype=object), ends, point)


@pytest.fixture(scope="module")
def known_fit():
    s = _fan()
    return s, fit_energy_density(s, (16, 16), 1e-4)


def test_fit_reproduces_a_known_density(known_fit):
    s, f = known_fit
    assert max(f.fit["stress_error"].values()) < 5e-3
    assert f.fit["energy_error"] < 5e-3
    # between the rays too: inside the sampled region, off every ray
    rng = np.random.default_rng(1)
    a, r = np.radians(rng.uniform(-40, 130, 400)), rng.uniform(0.0, 0.27, 400)
    p = np.stack([r * np.cos(a), r * np.sin(a)], -1)
    assert f.in_domain(p[:, 0], p[:, 1]).all()
    _w, g = _known(p)
    peak = np.abs(s.stress).max()
    assert np.abs(f.stress(p[:, 0], p[:, 1]) - g).max() < 0.02 * peak
    c = f.fit["convexity"]  # the known W is convex; its fit nearly everywhere
    assert (
        c["fraction"] < 5e-3 and c["min_eigenvalue_N_per_mm"] > -0.02 * c["max_eigenvalue_N_per_mm"]
    )


def test_stress_and_tangent_are_exact_derivatives(known_fit):
    _, f = known_fit
    rng = np.random.default_rng(2)
    p = rng.uniform(-0.1, 0.2, (50, 2))
    h = 1e-6
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    fd_stress = np.stack([(f.W(*(p + ex).T) - f.W(*(p - ex).T)) / (2 * h),
                          (f.W(*(p + ey).T) - f.W(*(p - ey).T)) / (2 * h)], -1)  # fmt: skip
    scale = np.abs(f.stress(*p.T)).max()
    assert np.abs(fd_stress - f.stress(*p.T)).max() < 1e-7 * scale
    fd_tangent = np.stack([(f.stress(*(p + ex).T) - f.stress(*(p - ex).T)) / (2 * h),
                           (f.stress(*(p + ey).T) - f.stress(*(p - ey).T)) / (2 * h)], -1)  # fmt: skip
    K = f.tangent(*p.T)
    assert np.abs(fd_tangent - K).max() < 1e-6 * np.abs(K).max()
    assert np.array_equal(K, np.swapaxes(K, -1, -2))
    assert K.shape == (50, 2, 2) and f.stress(0.1, 0.0).shape == (2,)
    # convexified: positive semi-definite, equal where the fit is convex
    C = f.tangent(*p.T, convexified=True)
    assert np.linalg.eigvalsh(C).min() > -1e-12
    convex = np.linalg.eigvalsh(K)[:, 0] >= 0
    assert np.allclose(C[convex], K[convex], rtol=0, atol=1e-12 * np.abs(K).max())


def test_file_round_trip(known_fit, tmp_path):
    _, f = known_fit
    path = f.save(tmp_path / "w.json")
    g = knitsweep.load_energy_density(path)
    p = np.random.default_rng(3).uniform(-0.1, 0.2, (20, 2))
    assert np.array_equal(g.W(*p.T), f.W(*p.T))
    assert np.array_equal(g.tangent(*p.T), f.tangent(*p.T))
    assert g.point == f.point and g.fit == json.loads(json.dumps(f.fit))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "other", "version": 1}))
    with pytest.raises(ValueError, match="not a knitsweep-energy-density file"):
        load_energy_density(bad)


def test_sampled_region():
    # a fan of at most a half-turn: closed through the origin
    s = _fan(range(-45, 136, 45), n=5)
    poly = sampled_domain(s)
    assert poly.shape == (6, 2) and np.array_equal(poly[-1], [0.0, 0.0])
    f = fit_energy_density(s, (4, 4))
    assert f.in_domain(0.05, 0.0) and f.in_domain(0.0, 0.0)
    assert not f.in_domain(-0.1, -0.1) and not f.in_domain(0.5, 0.0)
    # rays all round: the ends alone
    assert sampled_domain(_fan(range(0, 360, 45), n=5)).shape == (8, 2)


def test_held_out_rays_and_bad_settings(known_fit):
    s, _ = known_fit
    h = held_out_errors(s, (16, 16), 1e-4)
    assert set(h) == set(s.ends) - {"ray:1,-1", "ray:-1,1"}  # the outermost are kept
    assert max(h.values()) < 0.05
    with pytest.raises(ValueError, match="knots"):
        fit_energy_density(s, (1, 24))
    with pytest.raises(ValueError, match="smoothing"):
        fit_energy_density(s, (8, 8), -1.0)


JOB = """schema_version = 1
name = "w_small"
description = "a few rays"
seed = 1
preset = "draft"
mode = "grid"
directions = ["x", "y", "ray:1,-0.5", "ray:1,0", "ray:1,1", "ray:0,1", "ray:-0.5,1"]

[grid]
L_mm = 11.6
k_mN_per_mm2 = 0.1

[protocol]
observables = ["curve"]
step_mm = 0.003
max_strain = 0.04

[starts]
count = 1
"""


def test_a_job_fitted_from_the_command_line(tmp_path):
    job = tmp_path / "w.toml"
    job.write_text(JOB)
    h5 = tmp_path / "w.h5"
    got = run_knitsweep("run", job, "--out", h5, "--quiet")
    assert got.returncode == 0, got.stderr
    out = tmp_path / "w.json"
    got = run_knitsweep("energy-density", h5, "--out", out, "--knots", "16,16")
    assert got.returncode == 0, got.stderr
    assert "W(eps_xx, eps_yy) from" in got.stdout and "states of 7 sweeps" in got.stdout
    assert "between rays" in got.stdout
    f = knitsweep.load_energy_density(out)
    assert (tmp_path / "w.png").stat().st_size > 10_000
    assert f.fit["stress_error"]["x"] < 0.02 and f.fit["stress_error"]["y"] < 0.02
    # the samples are the sweeps' own steps: W and stresses at the x sweep's states
    res = knitsweep.load(h5)
    c = res.curves[res.curves.direction == "x"]
    a_x0, a_y0 = f.point["a_x0_mm"], f.point["a_y0_mm"]
    e = np.stack([c.a_x_mm / a_x0 - 1, c.a_y_mm / a_y0 - 1], -1)
    w = (c.total_energy_mJ - c.total_energy_mJ.iloc[0]) / (a_x0 * a_y0)
    assert np.abs(f.W(*e.T) - w).max() < 0.02 * w.max()
    assert np.abs(f.stress(*e.T)[:, 1]).max() < 0.02 * c.stress_xx_N_per_mm.max()  # σ_yy = 0
    # bad input: one line naming the option, before any work
    one_error_line(run_knitsweep("energy-density", h5, "--knots", "1,8"), "knots")
    one_error_line(run_knitsweep("energy-density", h5, "--knots", "8,8,8"), "2 numbers")
    one_error_line(run_knitsweep("energy-density", h5, "--out", tmp_path / "w.txt"), ".json")
    one_error_line(run_knitsweep("energy-density", h5, "--point-L", "9.0"), "select one point")
    # the report carries the same fit: its figure and errors (the defaults: 64 x 48 knots)
    from knitsweep.report.html import report_html

    page = report_html(res)
    section = page[page.index("<h2 id='energy-density'>") : page.index("<h2>Sweeps</h2>")]
    assert "data:image/png;base64," in section and "states of 7 sweeps, knots 64x48" in section
    assert "<h2 id='energy-density'>" not in report_html(res.select(direction=["x", "y"]))


# ---------------------------------------------------------------- with a shear


def _known3(e):
    """A smooth convex W(ε_xx, ε_yy, γ), even in γ (a left–right mirror), its gradient."""
    w, g = _known(e[..., :2])
    x, gam = e[..., 0], e[..., 2]
    w = w + 0.03 * gam**2 + 1.5 * gam**4 + 0.05 * x * gam**2
    g = np.concatenate([g, (0.06 * gam + 6.0 * gam**3 + 0.1 * x * gam)[..., None]], -1)
    g[..., 0] += 0.05 * gam**2
    return w, g


def _fan3(n=25, reach=0.25):
    """Rays in (ε_xx, ε_yy, γ): azimuths every 30° from -45° to 135° at elevations 0 and
    ±35° (their mirror images), named as the jobs name them."""
    units = [np.array([np.cos(np.radians(el)) * np.cos(np.radians(az)),
                       np.cos(np.radians(el)) * np.sin(np.radians(az)),
                       np.sin(np.radians(el))])
             for el in (0, 35, -35) for az in range(-45, 136, 30)]  # fmt: skip
    return _along(units, _known3, n, reach)


@pytest.fixture(scope="module")
def known3():
    s = _fan3()
    return s, fit_energy_density(s, (10, 10, 10), 1e-4)


def test_a_density_with_shear(known3, tmp_path):
    s, f = known3
    assert f.dim == 3 and f.variables == ("eps_xx", "eps_yy", "gamma")
    assert max(f.fit["stress_error"].values()) < 0.01 and f.fit["energy_error"] < 0.01
    m = f.fit["mirror_asymmetry"]  # the known W is even in γ, so nearly is its fit
    assert m["samples"] > 0 and m["energy"] < 0.01 and m["shear_stress"] < 0.02
    # exact derivatives in three variables
    p = np.random.default_rng(4).uniform(-0.05, 0.12, (30, 3))
    h = 1e-6
    for a in range(3):
        step = np.eye(3)[a] * h
        fd = (f.W(p + step) - f.W(p - step)) / (2 * h)
        assert np.abs(fd - f.stress(p)[:, a]).max() < 1e-7 * np.abs(f.stress(p)).max()
        fd = (f.stress(p + step) - f.stress(p - step)) / (2 * h)
        assert np.abs(fd - f.tangent(p)[:, :, a]).max() < 1e-6 * np.abs(f.tangent(p)).max()
    # the sampled region: along the rays, not beyond them nor far between them
    assert f.in_domain(np.array(list(s.ends.values())) * 0.9).all()
    assert not f.in_domain([0.5, 0.0, 0.0]) and not f.in_domain([-0.2, -0.2, 0.0])
    g = knitsweep.load_energy_density(f.save(tmp_path / "w3.json"))
    assert np.array_equal(g.tangent(p), f.tangent(p)) and g.dim == 3
    with pytest.raises(ValueError, match="eps_xx, eps_yy, gamma"):
        f.W(0.1, 0.0)  # two strains for a density of three
