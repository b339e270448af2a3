"""Unit tier: contact forces along stored sweeps (report/fig_forces.py; paper SI
"Contact Forces" figure and Table S3's RMS column) on the synthetic results file."""

import numpy as np
import pytest
from results_factory import write_results

from knitsweep.analysis import fit_line
from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.report.fig_forces import (
    LINEAR_ELASTIC_SIGN,
    pair_forces_along,
    same_row_z_rms,
    sweeps_with_states,
)
from knitsweep.report.reduce import reduce_results
from knitsweep.stitches import TRANSLATION_CLASSES as CONTACT_CLASSES


@pytest.fixture(scope="module")
def red(tmp_path_factory):
    return reduce_results(write_results(tmp_path_factory.mktemp("f") / "r.h5", ks=(0.1,)))


def test_forces_along_a_sweep_are_the_models(red):
    e = sweeps_with_states(red)[0]
    strain, f = pair_forces_along(red, e)
    assert f.shape == (len(strain), len(CONTACT_CLASSES), 3)
    model = CellModel(StitchParams.from_flat(e.meta))
    for i in (0, len(strain) // 2, len(strain) - 1):
        assert np.array_equal(f[i], model.contact_pair_forces_by_class(e.record["states"][i]))


def test_paper_sign_convention():
    # pulled in x: extension along x and z assists, along y (Poisson) resists; in y the
    # in-plane roles swap and z flips (paper SI Fig. S11 caption, Fig. 6g, S12b)
    assert LINEAR_ELASTIC_SIGN["x"].tolist() == [1.0, -1.0, 1.0]
    assert LINEAR_ELASTIC_SIGN["y"].tolist() == [-1.0, 1.0, -1.0]


def test_table_s3_rms_is_a_line_through_the_first_20_steps(red):
    rms = same_row_z_rms(red)
    ys = [e for e in sweeps_with_states(red) if e.meta["direction"] == "y"]
    assert sorted(rms) == sorted(round(float(e.meta["L_mm"]), 6) for e in ys)
    e = ys[0]
    strain, f = pair_forces_along(red, e)
    fz = f[:20, CONTACT_CLASSES.index("same_row"), 2]
    want = np.sqrt(np.mean((fz - np.polyval(np.polyfit(strain[:20], fz, 1), strain[:20])) ** 2))
    assert rms[round(float(e.meta["L_mm"]), 6)] == pytest.approx(want, rel=1e-9, abs=1e-15)
    assert np.sqrt(fit_line(strain[:20], fz).mse) == pytest.approx(want, rel=1e-9, abs=1e-15)


@pytest.fixture(scope="module")
def patterns(tmp_path_factory):
    out = tmp_path_factory.mktemp("p") / "r.h5"
    return reduce_results(write_results(out, ks=(0.1,), stitches=("stockinette", "rib", "seed")))


def test_a_patterns_forces_along_a_sweep_are_its_classes(patterns):
    """A pattern's sweeps count (docs/model.md §11): their pair forces are the model's over
    the mirrored images, rows its classes; figS11 draws each stitch's two rows, each
    stitch's classes in a legend; Table S3's RMS column stays stockinette's."""
    from knitsweep.kernels.mirrored import MIRROR_CLASSES
    from knitsweep.report.fig_forces import figS11_contact_forces_strain
    from knitsweep.report.fig_mechanics import CLASS_LABEL

    entries = sweeps_with_states(patterns)
    by_stitch = {e.meta.get("stitch", "stockinette") for e in entries}
    assert by_stitch == {"stockinette", "rib", "seed"}
    e = next(e for e in entries if e.meta.get("stitch") == "rib")
    _, f = pair_forces_along(patterns, e)
    model = CellModel(StitchParams.from_flat(e.meta))
    assert model.stitch.contact_classes == MIRROR_CLASSES
    assert np.array_equal(f[0], model.contact_pair_forces_by_class(e.record["states"][0]))
    assert f[:, MIRROR_CLASSES.index("mirrored")].any()
    fig = figS11_contact_forces_strain(patterns, [])
    assert len(fig.axes) == 3 * 3 * 2  # three stitches, pulled in x and y
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    labels = [tuple(t.get_text() for t in leg.get_texts()) for leg in legends]
    assert labels == [tuple(CLASS_LABEL[c] for c in CONTACT_CLASSES),
                      tuple(CLASS_LABEL[c] for c in MIRROR_CLASSES)]  # fmt: skip
    rms = same_row_z_rms(patterns)
    ys = [e for e in entries if e.meta["direction"] == "y" and "stitch" not in e.meta]
    assert sorted(rms) == sorted(round(float(e.meta["L_mm"]), 6) for e in ys)
