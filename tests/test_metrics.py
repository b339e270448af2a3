"""Unit tests of knitsweep.analysis.metrics / stress_strain (docs/model.md §9).

Every expected value is constructed analytically; tolerances are a few ulps of the
numbers involved unless a statistical bound is stated.
"""

import json
import math

import numpy as np
import pytest

from knitsweep.analysis import (
    EnergyGaps,
    area_strain,
    aspect_ratio,
    energy_gaps,
    fit_line,
    offset_stress,
    secant_modulus,
    stress_drops,
    sweep_metrics,
    tangent_modulus,
    thickness_strain,
)
from knitsweep.analysis.metrics import JAMMING_GAP

# A jammed x-sweep in the shape of the reference protocol (docs/model.md §8): a fine strain
# step up to ε = 0.05, then a coarse one.
H_FINE = 0.0005
H_COARSE = 0.005
EPS_KINK = 0.01  # end of the steep jammed rise
EPS_STIFF = 0.05  # start of the quadratic strain stiffening
SIGMA0 = 0.02  # N/mm, the intercept of the softened line
Y_SOFT = 0.5  # N/mm, the softened slope
Y_STEEP = Y_SOFT + SIGMA0 / EPS_KINK  # continuity at the kink: 2.5 N/mm
BAND = 0.25


def jammed_grid(n_coarse: int = 12) -> np.ndarray:
    fine = np.arange(round(EPS_STIFF / H_FINE) + 1) * H_FINE
    return np.concatenate([fine, EPS_STIFF + H_COARSE * np.arange(1, n_coarse + 1)])


def jammed_curve(eps: np.ndarray, c: float) -> np.ndarray:
    """Steep slope to ε = 0.01, then σ0 + Y ε, then + c (ε − 0.05)² (N/mm)."""
    line = np.where(eps <= EPS_KINK, Y_STEEP * eps, SIGMA0 + Y_SOFT * eps)
    return line + np.where(eps > EPS_STIFF, c * (eps - EPS_STIFF) ** 2, 0.0)


def assert_plain(d: dict) -> None:
    """as_dict() output is JSON with no NaN/inf (allow_nan=False raises otherwise)."""
    json.dumps(d, allow_nan=False)


# ---------------------------------------------------------------- secant modulus


def test_secant_modulus_two_slope_curve_is_exact():
    eps = jammed_grid()
    sig = jammed_curve(eps, c=100.0)
    res = secant_modulus(eps, sig)
    # σ(0.02) lies on the softened line: Y_sec = σ0/0.02 + Y = 1.5 N/mm.
    assert res.at == 0.02
    assert res.stress_at == pytest.approx(SIGMA0 + Y_SOFT * 0.02, rel=1e-15)
    assert res.Y_sec == pytest.approx(SIGMA0 / 0.02 + Y_SOFT, rel=1e-15)
    assert res.reason is None
    assert_plain(res.as_dict())


def test_secant_modulus_interpolates_between_steps():
    eps = jammed_grid()
    sig = jammed_curve(eps, c=100.0)
    at = 0.02 + 0.3 * H_FINE  # not a grid point; the curve is linear there
    res = secant_modulus(eps, sig, at=at)
    assert res.Y_sec == pytest.approx(SIGMA0 / at + Y_SOFT, rel=1e-14)


def test_secant_modulus_none_when_sweep_too_short():
    eps = np.linspace(0.0, 0.015, 16)
    res = secant_modulus(eps, 3.0 * eps)
    assert res.Y_sec is None and res.stress_at is None
    assert "0.015" in res.reason
    d = res.as_dict()
    assert d["Y_sec"] is None
    assert_plain(d)


def test_secant_modulus_input_errors():
    eps = np.linspace(0.0, 0.05, 11)
    with pytest.raises(ValueError, match="stress"):
        secant_modulus(eps, np.where(eps > 0.02, np.nan, eps))
    with pytest.raises(ValueError, match="strain"):
        secant_modulus(eps[::-1], eps)
    with pytest.raises(ValueError, match="same length"):
        secant_modulus(eps, eps[:-1])
    with pytest.raises(ValueError, match="at"):
        secant_modulus(eps, eps, at=0.0)


# ---------------------------------------------------------------- offset stress


def test_offset_stress_two_slope_curve_recovers_construction():
    eps = jammed_grid()
    c = 100.0
    # Premise, from the math: past ε = 0.05 the tangent is Y + 2 c (ε − 0.05) (central
    # differences are exact for a quadratic), so its first sample, Y + 2 c H_COARSE, is
    # outside the ±25 % band and no stiffening point enters the fit. The kink sample at
    # ε = 0.01 has tangent (Y_steep + Y)/2, also outside the band.
    assert Y_SOFT + 2 * c * H_COARSE > (1 + BAND) * Y_SOFT
    assert (Y_STEEP + Y_SOFT) / 2 > (1 + BAND) * Y_SOFT
    res = offset_stress(jammed_grid(), jammed_curve(eps, c))
    assert res.has_linear_regime and res.method == "auto"
    # Only points on the line are fitted, so the fit is exact up to rounding.
    assert res.sigma0 == pytest.approx(SIGMA0, abs=1e-12)
    assert res.slope == pytest.approx(Y_SOFT, abs=1e-12)
    assert res.window == pytest.approx((EPS_KINK + H_FINE, EPS_STIFF), abs=1e-15)
    assert res.n_points == round((EPS_STIFF - EPS_KINK) / H_FINE)
    assert res.fit.max_abs_residual < 1e-15
    assert res.tangent_min == pytest.approx(Y_SOFT, rel=1e-12)
    assert res.reason is None
    assert_plain(res.as_dict())


def test_offset_stress_gentle_stiffening_window_follows_the_band():
    """With gentle stiffening the band admits stiffening samples: exactly those with
    Y + 2 c j H ≤ 1.25 Y, i.e. j ≤ 0.25 Y/(2 c H) = 6.25 → up to ε = 0.05 + 6 H."""
    eps = jammed_grid()
    c = 2.0
    sig = jammed_curve(eps, c)
    j_max = math.floor(BAND * Y_SOFT / (2 * c * H_COARSE))
    assert j_max == 6
    res = offset_stress(eps, sig)
    lo, hi = EPS_KINK + H_FINE, EPS_STIFF + j_max * H_COARSE
    assert res.window == pytest.approx((lo, hi), abs=1e-15)
    inside = (eps >= lo - 1e-12) & (eps <= hi + 1e-12)
    slope, intercept = np.polyfit(eps[inside], sig[inside], 1)
    assert res.sigma0 == pytest.approx(intercept, abs=1e-12)
    assert res.slope == pytest.approx(slope, abs=1e-10)
    # The admitted stiffening tilts the line up and lowers its intercept.
    assert res.sigma0 < SIGMA0 and res.slope > Y_SOFT


def test_offset_stress_smoothed_tangent_keeps_exactness():
    eps = jammed_grid()
    res = offset_stress(eps, jammed_curve(eps, 100.0), halfwidth=2)
    assert res.sigma0 == pytest.approx(SIGMA0, abs=1e-12)
    assert res.slope == pytest.approx(Y_SOFT, abs=1e-12)
    assert EPS_KINK < res.window[0] < res.window[1] <= EPS_STIFF


def test_offset_stress_noisy_curve_within_statistical_bound():
    """Stress noise η = 1e-4 N/mm (fixed seed); a 11-step smoothed tangent (noise on it
    ≈ η/(h √110) ≈ 0.02 N/mm ≪ 0.25 Y) finds the softened regime, and σ0 lies within
    5 standard errors η √(1/n + ε̄²/S_εε) of the construction."""
    rng = np.random.default_rng(20250117)
    eps = jammed_grid()
    eta = 1e-4
    sig = jammed_curve(eps, 100.0) + eta * rng.standard_normal(eps.size)
    sig[0] = 0.0
    res = offset_stress(eps, sig, halfwidth=5)
    assert res.has_linear_regime
    lo, hi = res.window
    assert EPS_KINK < lo < hi <= EPS_STIFF  # only softened samples
    assert hi - lo > 0.8 * (EPS_STIFF - EPS_KINK)
    x = eps[(eps >= lo) & (eps <= hi)]
    se = eta * math.sqrt(1 / x.size + x.mean() ** 2 / np.sum((x - x.mean()) ** 2))
    assert abs(res.sigma0 - SIGMA0) < 5 * se


def test_offset_stress_unjammed_straight_line_gives_zero():
    eps = np.linspace(0.0, 0.3, 61)
    res = offset_stress(eps, 0.2 * eps)
    assert res.has_linear_regime
    assert res.sigma0 == pytest.approx(0.0, abs=1e-15)
    assert res.slope == pytest.approx(0.2, rel=1e-14)
    assert res.window == (0.0, 0.3)
    assert res.n_points == eps.size


def test_offset_stress_unjammed_stiffening_starts_at_zero():
    """σ = Y ε + c ε² has no initial rise: E_0 = Y + c h (one-sided) is the minimum,
    and the band keeps interior steps with Y + 2 c ε ≤ 1.25 (Y + c h)."""
    h, Y, c = 0.0005, 0.1, 2.0
    eps = np.arange(401) * h
    sig = Y * eps + c * eps**2
    res = offset_stress(eps, sig)
    e_hi = (1.25 * (Y + c * h) - Y) / (2 * c)
    inside = eps <= e_hi
    assert res.window == (0.0, eps[inside][-1])
    slope, intercept = np.polyfit(eps[inside], sig[inside], 1)
    assert res.sigma0 == pytest.approx(intercept, abs=1e-14)
    assert res.slope == pytest.approx(slope, rel=1e-10)
    # Least squares of j² on j = 0..k has intercept −k (k − 1)/6, so σ0 = −c h² k (k − 1)/6.
    k = np.count_nonzero(inside) - 1
    assert k == 13
    assert res.sigma0 == pytest.approx(-c * h**2 * k * (k - 1) / 6, rel=1e-9)


def test_offset_stress_ignores_toe_before_the_jammed_rise():
    """A low-tangent toe before the steep rise would hold the global tangent minimum;
    the search starts after the first local maximum of the tangent, so the softened
    regime is found instead."""
    h, et, e1, e2, c = 0.0005, 0.004, 0.012, 0.04, 300.0
    eps = np.arange(121) * h
    s1 = Y_STEEP * et / 2 + Y_STEEP * (e1 - et)
    sig = np.where(eps <= et, Y_STEEP * eps**2 / (2 * et), Y_STEEP * et / 2 + Y_STEEP * (eps - et))
    soft = s1 + Y_SOFT * (eps - e1) + np.where(eps > e2, c * (eps - e2) ** 2, 0.0)
    sig = np.where(eps > e1, soft, sig)
    assert Y_SOFT + 2 * c * h > (1 + BAND) * Y_SOFT  # no stiffening sample in the band
    res = offset_stress(eps, sig)
    assert res.search_start > et
    assert res.sigma0 == pytest.approx(s1 - Y_SOFT * e1, abs=1e-12)
    assert res.window == pytest.approx((e1 + h, e2), abs=1e-15)


def test_offset_stress_flags_cubic_without_linear_regime():
    """σ = a ε + b ε³: central-difference tangent a + b h² (3 i² + 1) at step i, a + b h²
    at step 0; with a = 0.01, b = 100, h = 0.001 only steps 0, 1, 2 are within 25 % of
    the minimum — fewer than 4."""
    a, b, h = 0.01, 100.0, 0.001
    eps = np.arange(201) * h
    sig = a * eps + b * eps**3
    E = tangent_modulus(eps, sig)
    i = np.arange(1, 6)
    np.testing.assert_allclose(E[1:6], a + b * h**2 * (3 * i**2 + 1), rtol=1e-9)
    assert np.count_nonzero(E <= 1.25 * E.min()) == 3
    res = offset_stress(eps, sig)
    assert not res.has_linear_regime
    assert res.sigma0 is None and res.slope is None and res.window is None and res.fit is None
    assert res.n_points == 0 and "min" in res.reason
    d = res.as_dict()
    assert d["sigma0"] is None and d["has_linear_regime"] is False
    assert_plain(d)
    # The flag comes from the point count: with min_points = 3 those steps are fitted.
    assert offset_stress(eps, sig, min_points=3).has_linear_regime


def test_offset_stress_flags_jammed_curve_going_straight_to_stiffening():
    """Paper SI "Disappearing Linear Elasticity": steep rise, then a + 3 b δ² with no
    plateau (a = 0.05, b = 2e4): the central-difference tangent past the kink,
    a + b h² (3 j² + 1), grows from 0.07 to 0.115 within one step, so only one step is
    in the band."""
    h, a, b = 0.0005, 0.05, 2e4
    eps = np.arange(71) * h
    d = np.clip(eps - EPS_KINK, 0.0, None)
    sig = np.where(eps <= EPS_KINK, Y_STEEP * eps, Y_STEEP * EPS_KINK + a * d + b * d**3)
    res = offset_stress(eps, sig)
    assert not res.has_linear_regime and res.sigma0 is None
    # Central differences of the cubic one step past the kink: a + b h² (3·1² + 1).
    assert res.tangent_min == pytest.approx(a + 4 * b * h**2, rel=1e-9)


def test_offset_stress_min_span_rejects_short_plateau():
    eps = jammed_grid()
    sig = jammed_curve(eps, 100.0)
    assert offset_stress(eps, sig, min_span=0.039).has_linear_regime
    res = offset_stress(eps, sig, min_span=0.041)  # the plateau spans 0.0395
    assert not res.has_linear_regime and "0.041" in res.reason


def test_offset_stress_user_window_is_honoured():
    eps = jammed_grid()
    sig = jammed_curve(eps, 100.0)
    res = offset_stress(eps, sig, window=(0.02, 0.04))
    assert res.method == "window" and res.window == (0.02, 0.04)
    assert res.n_points == 41
    assert res.sigma0 == pytest.approx(SIGMA0, abs=1e-12)
    assert res.tangent_min is None and res.search_start is None
    # A window in the stiffening part fits exactly the samples inside it.
    res = offset_stress(eps, sig, window=(0.06, 0.09))
    inside = (eps >= 0.06) & (eps <= 0.09)
    ref = fit_line(eps[inside], sig[inside])
    assert res.n_points == np.count_nonzero(inside)
    assert res.sigma0 == ref.intercept and res.slope == ref.slope


@pytest.mark.parametrize(
    "window, match",
    [((0.04, 0.02), "eps_lo < eps_hi"), ((0.0101, 0.0102), "holds 0"), ((0.0, math.nan), "window")],
)
def test_offset_stress_bad_window(window, match):
    eps = jammed_grid()
    with pytest.raises(ValueError, match=match):
        offset_stress(eps, jammed_curve(eps, 100.0), window=window)


def test_offset_stress_bad_parameters_and_inputs():
    eps = jammed_grid()
    sig = jammed_curve(eps, 100.0)
    with pytest.raises(ValueError, match="min_points"):
        offset_stress(eps, sig, min_points=1)
    with pytest.raises(ValueError, match="band"):
        offset_stress(eps, sig, band=0.0)
    with pytest.raises(ValueError, match="halfwidth"):
        offset_stress(eps, sig, halfwidth=-1)
    bad = sig.copy()
    bad[7] = np.nan
    with pytest.raises(ValueError, match=r"stress: entry 7"):
        offset_stress(eps, bad)
    with pytest.raises(ValueError, match="strain"):
        offset_stress(np.r_[eps[:5], eps[3]], sig[:6])


def test_offset_stress_short_or_falling_curve_is_flagged_not_raised():
    res = offset_stress([0.0, 0.01, 0.02], [0.0, 0.01, 0.02])
    assert not res.has_linear_regime and "fewer than min_points" in res.reason
    eps = np.linspace(0.0, 0.1, 21)
    res = offset_stress(eps, 0.1 * eps - eps**2)  # softens all the way, tangent reaches < 0
    assert not res.has_linear_regime and res.sigma0 is None
    res = offset_stress(eps, -eps)  # falls from the start
    assert not res.has_linear_regime and "not positive" in res.reason


def test_offset_stress_stops_at_a_stress_drop():
    """A rearrangement (stress drop) after the softened regime ends the search: the
    line is fitted before it, not abandoned (seen in x pulls at k = 0.1)."""
    eps = np.linspace(0.0, 0.3, 61)
    sig = np.where(eps < 0.01, 2.5 * eps, 0.02 + 0.5 * eps)
    sig[eps > 0.2] -= 0.03  # a drop at 20 % strain
    res = offset_stress(eps, sig)
    assert res.has_linear_regime
    assert res.sigma0 == pytest.approx(0.02, abs=1e-9)
    assert res.window[1] < 0.2


def test_tangent_modulus_smoothed_is_local_least_squares():
    rng = np.random.default_rng(7)
    eps = np.sort(rng.uniform(0.0, 0.2, 30))
    sig = rng.normal(size=30)
    E = tangent_modulus(eps, sig, halfwidth=3)
    for i in (0, 2, 15, 29):
        sl = slice(max(0, i - 3), i + 4)
        assert E[i] == pytest.approx(np.polyfit(eps[sl], sig[sl], 1)[0], rel=1e-9)


# ---------------------------------------------------------------- energy gaps etc.


def test_energy_gaps_known_arrays():
    E_b = np.array([1.0, 0.8, 0.9, 0.8, 1.2])
    E_c = np.array([0.30, 0.31, 0.35, 0.40, 0.50])
    g = energy_gaps(E_b, E_c)
    assert g.delta_E_b == pytest.approx(0.2, rel=1e-15)
    assert g.delta_E_c == 0.0
    assert (g.index_min_b, g.index_min_c) == (1, 0)
    assert (g.E_b_rest, g.E_b_min, g.E_c_rest, g.E_c_min) == (1.0, 0.8, 0.30, 0.30)
    assert g.jamming_gap("x") == g.delta_E_c and g.jamming_gap("y") == g.delta_E_b
    assert JAMMING_GAP == {"x": "delta_E_c", "y": "delta_E_b", "biaxial": "delta_E_c",
                           "strip_x": "delta_E_c", "strip_y": "delta_E_b", "shear": "delta_E_c",
                           "shear_free": "delta_E_c"}  # fmt: skip
    d = g.as_dict()
    assert d["index_min_b"] == 1 and isinstance(d["delta_E_b"], float)
    assert_plain(d)


def test_energy_gaps_are_non_negative_for_random_sweeps():
    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(1, 40))
        g = energy_gaps(rng.normal(size=n), rng.normal(size=n))
        assert g.delta_E_b >= 0.0 and g.delta_E_c >= 0.0


def test_energy_gaps_errors_name_the_argument():
    with pytest.raises(ValueError, match="contact_energy"):
        energy_gaps([1.0, 2.0], [1.0, np.inf])
    with pytest.raises(ValueError, match="bending_energy"):
        energy_gaps([], [])
    with pytest.raises(ValueError, match="same length"):
        energy_gaps([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="1-D"):
        energy_gaps([[1.0, 2.0]], [[1.0, 2.0]])
    with pytest.raises(ValueError, match="must be one of x, y, biaxial, strip_x, strip_y"):
        EnergyGaps(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0).jamming_gap("z")


def test_aspect_area_thickness():
    assert aspect_ratio(2.0, 3.0) == 1.5
    with pytest.raises(ValueError, match="a_x0"):
        aspect_ratio(0.0, 3.0)
    a = area_strain([2.0, 2.2, 2.4], [3.0, 2.7, 2.75])
    np.testing.assert_allclose(a, [0.0, 2.2 * 2.7 / 6 - 1, 2.4 * 2.75 / 6 - 1], rtol=0, atol=1e-15)
    assert a[0] == 0.0
    t = thickness_strain([1.5, 1.47, 1.56])
    np.testing.assert_allclose(t, [0.0, -0.02, 0.04], rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="a_y"):
        area_strain([2.0, 2.1], [3.0, np.nan])
    with pytest.raises(ValueError, match="thickness"):
        thickness_strain([1.0, -1.0])


# ---------------------------------------------------------------- sweep_metrics


def make_sweep(n_coarse: int = 12):
    eps = jammed_grid(n_coarse)
    a_x0, a_y0, dz0 = 2.4, 3.6, 1.8
    return dict(
        strain=eps,
        stress=jammed_curve(eps, 100.0),
        bending_energy=0.05 + 0.001 * np.cos(40 * eps),  # minimum below the rest value
        contact_energy=0.01 + eps**2,  # minimum at rest
        a_x=a_x0 * (1 + eps),
        a_y=a_y0 * (1 - 2 * eps + 5 * eps**2),  # area (1 + ε)(1 − 2ε + 5ε²) dips below rest
        thickness=dz0 * (1 - 0.3 * eps),
    )


def test_sweep_metrics_bundles_everything():
    s = make_sweep()
    m = sweep_metrics("y", **s)
    eps = s["strain"]
    assert m.direction == "y" and m.n_steps == eps.size
    assert m.max_strain == eps[-1] and m.max_stress == s["stress"][-1]
    assert m.secant == secant_modulus(eps, s["stress"])
    assert m.offset == offset_stress(eps, s["stress"])
    assert m.gaps == energy_gaps(s["bending_energy"], s["contact_energy"])
    assert m.jamming_gap == m.gaps.delta_E_b > 0.0
    assert sweep_metrics("x", **s).jamming_gap == m.gaps.delta_E_c == 0.0
    assert (m.a_x0, m.a_y0, m.thickness0) == (2.4, 3.6, 1.8)
    assert m.aspect_ratio == pytest.approx(1.5, rel=1e-15)
    area = area_strain(s["a_x"], s["a_y"])
    assert m.area_strain_min == area.min() < 0.0
    assert m.area_strain_max == area.max() == 0.0
    assert m.min_area_at_zero_force is False
    assert sweep_metrics("y", **s, area_tol=-area.min()).min_area_at_zero_force is True
    assert m.thickness_strain_at == pytest.approx(-0.3 * 0.02, rel=1e-12)
    assert m.thickness_strain_min == pytest.approx(-0.3 * eps[-1], rel=1e-12)
    d = m.as_dict()
    assert d["secant"]["Y_sec"] == pytest.approx(1.5)
    assert d["offset"]["window"] == list(m.offset.window)
    assert_plain(d)


def test_sweep_metrics_short_sweep_reports_none():
    s = {k: v[:30] for k, v in make_sweep().items()}  # ends at ε = 0.0145
    m = sweep_metrics("x", **s)
    assert m.secant.Y_sec is None and m.thickness_strain_at is None
    d = m.as_dict()
    assert d["secant"]["Y_sec"] is None and d["thickness_strain_at"] is None
    assert_plain(d)


def test_sweep_metrics_errors():
    s = make_sweep()
    with pytest.raises(ValueError, match="direction"):
        sweep_metrics("z", **s)
    bad = dict(s, a_y=s["a_y"][:-1])
    with pytest.raises(ValueError, match=r"a_y: \d+"):
        sweep_metrics("x", **bad)
    nan = dict(s, thickness=np.where(s["strain"] > 0.03, np.nan, s["thickness"]))
    with pytest.raises(ValueError, match="thickness"):
        sweep_metrics("x", **nan)
    with pytest.raises(ValueError, match="area_tol"):
        sweep_metrics("x", **s, area_tol=-1.0)


# ---------------------------------------------------------------- start switches


def switching_sweep():
    """The jammed curve as two starts would give it: the envelope stress is the smooth
    curve, the finite-difference stress drops by 40 % at ε = 0.015, where the winning
    start changes (start 1 wins from step 30 on), as the relaxations' energy offsets
    between chains make it do."""
    s = make_sweep()
    eps = s["strain"]
    envelope = jammed_curve(eps, 100.0)
    winner = np.where(np.arange(eps.size) >= 30, 1, 0)
    fd = envelope.copy()
    fd[30] *= 0.6
    return dict(s, stress=fd), envelope, winner


def test_stress_drops_are_flagged_where_the_start_switches():
    s, envelope, winner = switching_sweep()
    d = stress_drops(s["strain"], s["stress"], winner)
    assert (d.n_switches, d.n_drops, d.n_switching_drops) == (1, 1, 1)
    assert d.discontinuous and d.first_drop_strain == s["strain"][30]
    # the same drop with no switch nearby is a drop, not a switching drop
    far = np.where(np.arange(winner.size) >= 60, 1, 0)
    d = stress_drops(s["strain"], s["stress"], far)
    assert (d.n_drops, d.n_switching_drops, d.discontinuous) == (1, 0, False)
    assert stress_drops(s["strain"], envelope, winner).n_drops == 0
    assert stress_drops(s["strain"], s["stress"]).n_switches == 0
    with pytest.raises(ValueError, match="winner"):
        stress_drops(s["strain"], s["stress"], winner[:-1])


def test_sigma0_is_fitted_to_the_envelope_stress_across_a_switch():
    s, envelope, winner = switching_sweep()
    # on the finite-difference stress the drop ends the softened-regime search
    fd = sweep_metrics("x", **s, halfwidth=5, min_span=0.01)
    assert fd.offset.sigma0 is None and fd.offset.reason and fd.sigma0_source == "stress"
    m = sweep_metrics("x", **s, stress_envelope=envelope, winner=winner, halfwidth=5,
                      min_span=0.01)  # fmt: skip
    assert m.sigma0_source == "envelope" and m.drops.discontinuous
    assert m.offset.has_linear_regime
    # only points on the softened line are fitted: σ0 exact up to rounding
    assert m.offset.sigma0 == pytest.approx(SIGMA0, abs=1e-12)
    assert m.offset.fit.max_abs_residual < 1e-15
    assert m.secant == secant_modulus(s["strain"], s["stress"])  # Y_sec stays on σ
    with pytest.raises(ValueError, match="stress_envelope"):
        sweep_metrics("x", **s, stress_envelope=envelope[:-1])
