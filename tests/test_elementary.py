"""Unit tier: the vectorisable log/exp/pow of ``kernels.elementary`` against libm.

The contact kernel takes zeta**(1 - p) from these (docs/model.md §6); their error is
measured here on the whole range the kernel uses, zeta in [CORE_EPS, 1).
"""

import numpy as np
import pytest
from numba import njit

from knitsweep.kernels.contact import CORE_EPS, _pow_inplace
from knitsweep.kernels.elementary import exp_finite, log_pos, pow_pos


@njit(error_model="numpy")
def _log(x, out):
    for i in range(x.size):
        out[i] = log_pos(x[i])


@njit(error_model="numpy")
def _exp(x, out):
    for i in range(x.size):
        out[i] = exp_finite(x[i])


@njit(error_model="numpy")
def _pow(x, y, out):
    for i in range(x.size):
        out[i] = pow_pos(x[i], y)


def _ulps(got, want):
    return np.max(np.abs(got - want) / np.spacing(np.abs(want)))


def test_log_is_within_one_ulp():
    rng = np.random.default_rng(0)
    x = np.concatenate([
        np.exp(rng.uniform(np.log(2.3e-308), np.log(1.7e308), 200_000)),
        rng.uniform(0.5, 2.0, 200_000),
        1.0 + rng.uniform(-1e-8, 1e-8, 20_000),
        [np.sqrt(0.5), np.sqrt(2.0), np.nextafter(np.sqrt(2.0), 2.0), 2.0, 0.5],
    ])  # fmt: skip
    got = np.empty_like(x)
    _log(x, got)
    want = np.log(x)
    assert _ulps(got, want) <= 1.0
    one = np.empty(1)
    _log(np.array([1.0]), one)
    assert one[0] == 0.0


def test_exp_is_within_one_ulp():
    rng = np.random.default_rng(1)
    y = np.concatenate([rng.uniform(-708, 708, 200_000), rng.uniform(-1, 1, 100_000),
                        [0.0, 1e-300, -1e-300, 708.0, -708.0]])  # fmt: skip
    got = np.empty_like(y)
    _exp(y, got)
    assert _ulps(got, np.exp(y)) <= 1.0


@pytest.mark.parametrize("p", [1.01, 1.5, 2.4, 3.0, 5.0, 10.0])
def test_pow_matches_libm_on_the_contact_range(p):
    """Relative error <= (|1-p| |log zeta| + 1) ulp, as exp(y log x) should."""
    rng = np.random.default_rng(2)
    z = np.concatenate([rng.uniform(CORE_EPS, 1.0, 200_000),
                        np.exp(rng.uniform(np.log(CORE_EPS), 0.0, 200_000)),
                        [CORE_EPS, 1.0 - 2**-53, 0.5]])  # fmt: skip
    want = z ** (1.0 - p)
    bound = (abs(1.0 - p) * abs(np.log(CORE_EPS)) + 2.0) * 2.0**-52
    got = np.empty_like(z)
    _pow(z, 1.0 - p, got)
    assert np.max(np.abs(got / want - 1.0)) <= bound
    # the kernel's own loop, compiled with FMA contraction
    fused = z.copy()
    _pow_inplace(fused, fused.size, 1.0 - p)
    assert np.max(np.abs(fused / want - 1.0)) <= bound
