"""Image selection: 'cutoff' visits every image that can touch, 'reference' the
authors' fixed box; they agree wherever the box is large enough (docs/model.md §6)."""

import numpy as np
import pytest
from conftest import golden_cases, golden_params

from knitsweep.config import Fidelity
from knitsweep.kernels.contact import IMAGES_CUTOFF, IMAGES_REFERENCE, image_list
from knitsweep.model import CellModel


def _models(case):
    p = golden_params(case)
    return CellModel(p, Fidelity(images="cutoff")), CellModel(p, Fidelity(images="reference"))


def test_small_cell_needs_images_beyond_the_box(init1):
    """Squeeze the wale period so that rows four apart overlap: the box (|n| <= 3)
    misses those contacts, the cutoff search does not."""
    cut, ref = _models(golden_cases()[0])
    x = init1.copy()
    x[29] = 0.55
    pts = cut.control_points(x).reshape(-1, 3)
    assert np.abs(image_list(pts, x[28], x[29], 0.74, IMAGES_CUTOFF)[:, 1]).max() >= 4
    assert cut.energies(x).contact_energy > ref.energies(x).contact_energy > 0


def test_large_cell_visits_fewer_images(init1):
    cut, ref = _models(golden_cases()[0])
    x = init1.copy()
    x[28] *= 3.0
    x[29] *= 3.0
    pts = cut.control_points(x).reshape(-1, 3)
    n_cut = len(image_list(pts, x[28], x[29], 0.74, IMAGES_CUTOFF))
    n_ref = len(image_list(pts, x[28], x[29], 0.74, IMAGES_REFERENCE))
    assert n_cut < n_ref == 10
    assert cut.energies(x).contact_energy == pytest.approx(
        ref.energies(x).contact_energy, rel=1e-13
    )


@pytest.mark.parametrize("scale", [0.9, 1.0, 1.2])
def test_modes_agree_where_the_box_suffices(init1, scale):
    cut, ref = _models(golden_cases()[0])
    x = init1.copy()
    x[28:] *= scale
    e_cut, g_cut = cut.energy_and_gradients(x)[:2]
    e_ref, g_ref = ref.energy_and_gradients(x)[:2]
    assert e_cut.contact_energy == pytest.approx(e_ref.contact_energy, rel=1e-13)
    np.testing.assert_allclose(g_cut, g_ref, rtol=1e-12, atol=1e-15)
