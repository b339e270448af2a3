"""A shear starts from the zero-force state with its skew relaxed (strain_sweep.rest_skew,
protocol.shear_rest; docs/inplane.md): rib's one-stitch cell leans, and upright it is
not at rest in shear."""

import numpy as np
import pytest

from knitsweep.config import StartSettings, StitchParams, SweepProtocol
from knitsweep.model import CellModel
from knitsweep.presets import Numerics
from knitsweep.relax.zero_force import zero_force
from knitsweep.strain_sweep import strain_sweep
from knitsweep.strain_sweep.rest_skew import relax_skew

NUMERICS = Numerics.from_preset("converged")
RIB = StitchParams(stitch="rib", L_mm=10.1, k_mN_per_mm2=0.1)
PROTOCOL = SweepProtocol(step_mm=0.004, max_strain=0.03)


@pytest.fixture(scope="module")
def rib():
    return zero_force(RIB, NUMERICS.fidelity, NUMERICS.solver, StartSettings(count=1))


def test_rib_upright_is_not_at_rest_in_shear_and_its_relaxed_skew_is(rib):
    model = CellModel(RIB, NUMERICS.fidelity)
    upright = model.skew_force(rib.best.x) / rib.best.a_x
    assert upright < -1e-3  # it leans: sheared one way its energy falls
    found = relax_skew(model, rib.best, NUMERICS.solver, 5e-6)
    assert found is not None and model.skew == 0.0
    assert found.gamma > 0.02 and found.fall_mJ > 5e-5  # (measured: 0.061, 2.0e-4 mJ)
    assert found.relaxation.total_energy == pytest.approx(rib.best.total_energy - found.fall_mJ)
    assert abs(found.sigma_xy) < 1e-5 and abs(found.sigma_xy) < 1e-2 * abs(upright)
    # the shear from there starts at rest and stiffens both ways (a minimum)
    sweeps = {}
    for mode in ("tension", "compression"):
        protocol = PROTOCOL.model_copy(update={"mode": mode})
        sweeps[mode] = strain_sweep(RIB, rib, "shear_free", protocol, NUMERICS.fidelity,
                                    NUMERICS.solver)  # fmt: skip
    for mode, sw in sweeps.items():
        assert sw.rest_skew == pytest.approx(found.gamma) and sw.rest is None, mode
        assert sw.total_energy[0] == pytest.approx(found.relaxation.total_energy, abs=1e-9)
        assert abs(sw.stress_xy[0]) < 1e-5
        assert np.all(sw.total_energy[1:] > sw.total_energy[0]), mode
        assert "skew relaxed at zero force" in sw.rest_found
    assert sweeps["tension"].stress_xy[-1] > 0 > sweeps["compression"].stress_xy[-1]
    held = strain_sweep(RIB, rib, "shear_free", PROTOCOL.model_copy(update={"shear_rest": "held"}),
                        NUMERICS.fidelity, NUMERICS.solver)  # fmt: skip
    assert held.rest_skew == 0.0 and held.stress_xy[0] == pytest.approx(upright)
    assert held.total_energy[-1] < held.total_energy[0]  # upright, it falls as it shears


def test_a_stitch_at_rest_in_shear_keeps_its_upright_state():
    free = StitchParams(stitch="stockinette_free", L_mm=11.0, k_mN_per_mm2=0.1)
    zero = zero_force(free, starts=StartSettings(count=1))
    model = CellModel(free)
    assert relax_skew(model, zero.best, tolerance_mJ=5e-6) is None
    assert model.skew == 0.0
