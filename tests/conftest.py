import json
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"


def golden_cases():
    return json.loads((DATA / "golden_energy.json").read_text())


def golden_params(case):
    from knitsweep.params import StitchParams

    P = case["params"]
    return StitchParams.from_internal(P["L"], P["bend"], P["reg"], P["r"], P["rc"], P["k"], P["p"])


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def init1() -> np.ndarray:
    from knitsweep.formats import read_state

    return read_state(DATA / "init" / "Init_1.dat")
