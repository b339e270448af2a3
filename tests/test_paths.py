"""Load paths (knitsweep.paths, docs/model.md §8): uniaxial as before, equibiaxial and strip
biaxial with both periods controlled, the stress tensor's normal components against the
energy's differences, and the path's observables."""

import numpy as np
import pytest
from conftest import one_error_line, run_knitsweep

from knitsweep.analysis.metrics import JAMMING_GAP
from knitsweep.config import StartSettings, StitchParams, SweepProtocol
from knitsweep.paths import PATH_NAMES, PATHS, load_path
from knitsweep.quantities import sweep_observables
from knitsweep.relax.zero_force import zero_force
from knitsweep.strain_sweep import strain_sweep

PAPER = StitchParams(L_mm=11.6, k_mN_per_mm2=0.1)
PROTOCOL = SweepProtocol(step_mm=0.002, max_strain=0.025)


@pytest.fixture(scope="module")
def zero():
    return zero_force(PAPER, starts=StartSettings(count=1))


RAY = "ray:1,-0.2"  # x pulled, y pushed in at a fifth of its rate


@pytest.fixture(scope="module")
def sweeps(zero):
    return {d: strain_sweep(PAPER, zero, d, PROTOCOL) for d in ("x", "y", "biaxial", "strip_x",
                                                                 "strip_y", RAY)}  # fmt: skip


def test_registry():
    assert PATH_NAMES == ("x", "y", "biaxial", "strip_x", "strip_y", "shear", "shear_free")
    assert JAMMING_GAP["x"] == "delta_E_c" and JAMMING_GAP["y"] == "delta_E_b"
    assert PATHS["strip_y"].leading == "y" and PATHS["strip_y"].controlled == ("y", "x")
    assert PATHS["x"].uniaxial and not PATHS["biaxial"].uniaxial
    assert PATHS["biaxial"].targets({"x": 2.0, "y": 4.0}, 0.5) == {"x": 3.0, "y": 6.0}
    assert PATHS["strip_x"].targets({"x": 2.0, "y": 4.0}, 0.5) == {"x": 3.0, "y": 4.0}
    # dE/dε per unit area: F_x a_x0 / (a_x0 a_y0) + F_y a_y0 / (a_x0 a_y0)
    assert PATHS["biaxial"].conjugate_stress(3.0, 5.0, 2.0, 4.0) == pytest.approx(3 / 4 + 5 / 2)
    assert PATHS["y"].conjugate_stress(3.0, 5.0, 2.0, 4.0) == 5 / 2
    with pytest.raises(ValueError, match="must be one of x, y, biaxial, strip_x, strip_y, shear, "
                       r"shear_free or ray:<rate_x>,<rate_y>\[,<rate_xy>\]"):  # fmt: skip
        load_path("twist")
    # a ray: its larger rate leads, scaled to 1; the other period follows
    ray = load_path("ray:-0.5,2")
    assert (ray.leading, ray.rate_x, ray.rate_y, ray.gap) == ("y", -0.25, 1.0, "delta_E_b")
    assert ray.targets({"x": 2.0, "y": 4.0}, 0.1) == {"y": 4.4, "x": 2.0 * (1 - 0.025)}
    assert load_path("ray:2,2").rates == PATHS["biaxial"].rates
    tie = load_path("ray:-1,1")  # a tie: the pull leads
    assert (tie.leading, tie.rate_x, tie.rate_y) == ("y", -1.0, 1.0)
    assert load_path("ray:1,-1").leading == "x"
    # three rates: (ε_x, ε_y, γ), the largest leads; a shear that leads moves the skew
    r3 = load_path("ray:0.5,-0.25,2")
    assert (r3.leading, r3.rate_x, r3.rate_y, r3.rate_xy, r3.shears) == ("xy", 0.25, -0.125, 1.0,
                                                                          True)  # fmt: skip
    assert r3.controlled == ("x", "y") and r3.gap == "delta_E_c"
    r3 = load_path("ray:1,0,-0.5")
    assert (r3.leading, r3.rate_xy, r3.controlled) == ("x", -0.5, ("x", "y"))
    assert load_path("ray:1,0.5,0").rates == load_path("ray:1,0.5").rates
    assert not load_path("ray:1,0.5,0").shears
    for bad, why in (("ray:-1,0.5", "the largest rate must be positive"), ("ray:-1,-1", "positive"),
                     ("ray:0,0", "not all 0"), ("ray:1", "two or three numbers"),
                     ("ray:1,nan", "finite"), ("ray:1,2,3,4", "two or three"),
                     ("ray:0,0,-1", "positive")):  # fmt: skip
        with pytest.raises(ValueError, match=why):
            load_path(bad)


def test_controlled_periods_follow_the_path(sweeps, zero):
    ax0, ay0 = zero.best.a_x, zero.best.a_y
    for d, s in sweeps.items():
        assert s.status == "done" and s.converged.all(), (d, s.stop_reason)
        assert s.strain[-1] >= 0.02
    b, sx, sy = sweeps["biaxial"], sweeps["strip_x"], sweeps["strip_y"]
    assert np.allclose(b.a_y, ay0 * (1 + b.strain), rtol=1e-14)
    assert np.array_equal(b.a_x, b.a_fixed)
    assert np.all(sx.a_y == ay0) and np.array_equal(sx.a_x, sx.a_fixed)
    assert np.all(sy.a_x == ax0) and np.array_equal(sy.a_y, sy.a_fixed)
    r = sweeps[RAY]
    assert np.allclose(r.a_y, ay0 * (1 - 0.2 * r.strain), rtol=1e-14)
    # a free period stays force-free; a held one carries a stress
    assert np.max(np.abs(sweeps["x"].stress_yy)) < 1e-5
    assert np.max(np.abs(sweeps["y"].stress_xx)) < 1e-5
    assert sx.stress_yy[-1] != 0.0 and sy.stress_xx[-1] != 0.0


def test_stress_components_are_the_energy_derivatives(sweeps):
    """Along strip_x only a_x moves, so dE/dε / (a_x0 a_y0) (the centred differences of the
    energy, ``stress``) is σ_xx from the period force; along strip_y σ_yy; along the
    equibiaxial path their sum; along x the paper's stress, σ_xx. (As in the uniaxial
    sweeps' test, a step where the chain hops to a slightly lower basin breaks the
    differences: at 11.6 mm up to 7e-4 N/mm at one or two steps of 38.)"""
    b, r = sweeps["biaxial"], sweeps[RAY]
    assert np.allclose(b.stress_envelope, b.stress_xx + b.stress_yy, rtol=1e-12, atol=1e-15)
    assert np.allclose(r.stress_envelope, r.stress_xx - 0.2 * r.stress_yy, rtol=1e-12,
                       atol=1e-15)  # fmt: skip
    for d, component in (("strip_x", "stress_xx"), ("strip_y", "stress_yy"), ("x", "stress_xx"),
                         ("biaxial", "stress_envelope"), (RAY, "stress_envelope")):  # fmt: skip
        s = sweeps[d]
        inner = slice(2, -1)
        agree = np.isclose(s.stress[inner], getattr(s, component)[inner], rtol=0.02, atol=1e-5)
        assert agree.mean() >= 0.9, d
        assert np.array_equal(s.stress_envelope, getattr(s, component))
    # the equibiaxial stiffness exceeds either uniaxial one
    assert b.stress_envelope[-1] > max(sweeps["x"].stress_envelope[-1],
                                       sweeps["y"].stress_envelope[-1])  # fmt: skip


def test_path_observables(sweeps):
    obs = {d: sweep_observables(s.arrays(), d) for d, s in sweeps.items()}
    assert obs["x"]["poisson_ratio"] is not None and obs["y"]["poisson_ratio"] is not None
    assert obs["x"]["transverse_stress_ratio"] is None
    for d in ("biaxial", "strip_x", "strip_y", RAY):
        assert obs[d]["poisson_ratio"] is None
        assert np.isfinite(obs[d]["transverse_stress_ratio"]), d
    assert obs["strip_x"]["transverse_stress_ratio"] > 0  # holding a_y takes tension
    for d, gap in (("biaxial", "delta_E_c"), ("strip_x", "delta_E_c"), ("strip_y", "delta_E_b")):
        rec = sweeps[d].to_record()
        assert JAMMING_GAP[d] == gap and rec["jamming_gap"] == getattr(sweeps[d].energy_gaps, gap)


def test_bad_direction_is_one_line(tmp_path):
    proc = run_knitsweep("sweep", "--direction", "twist", "--L", "11.6")
    one_error_line(proc, "direction = 'twist': must be one of x, y, biaxial, strip_x, strip_y")
    proc = run_knitsweep("sweep", "--direction", "ray:0,0", "--L", "11.6")
    one_error_line(proc, "direction = 'ray:0,0': a ray's rates must be finite and not all 0")
    job = tmp_path / "job.toml"
    job.write_text('schema_version = 1\nname = "j"\ndirections = ["x", "twist"]\n'
                   "[grid]\nL_mm = [11.6]\n")  # fmt: skip
    proc = run_knitsweep("run", job, "--out", tmp_path / "j.h5")
    one_error_line(proc, "directions.1 = 'twist': must be one of x, y, biaxial, strip_x, "
                   "strip_y, shear, shear_free or ray:<rate_x>,<rate_y>[,<rate_xy>]")  # fmt: skip
    assert not (tmp_path / "j.h5").exists()
