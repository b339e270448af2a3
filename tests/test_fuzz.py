"""Property tier: fuzzed job files and command-line values are refused with one line
naming the field and exit code 2, never a traceback, and nothing is computed.

Job files are a valid job with one field replaced by a value of the wrong type or
out of its physical range (or by random bytes); command-line values are outside
each option's documented range. Most examples run in process (``load_job``, the
CLI's ``main``); a few go through a real ``knitsweep`` process."""

import math
import os
import subprocess
import sys

import pytest
from conftest import SHIPPED
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from knitsweep.cli.application import main as cli_main
from knitsweep.config import InputError
from knitsweep.service.jobs import load_job

BASE = {
    "schema_version": 1,
    "name": "fuzz",
    "seed": 1,
    "directions": ["x"],
    "preset": "draft",
    "grid": {"L_mm": [11.4], "k_mN_per_mm2": 0.1, "B_mN_mm2": 90.0, "r_mm": 0.74,
             "r_core_mm": 0.325, "p": 2.4, "regularization_mN_mm4": 2.0, "twist_bound": 0.9},
    "fidelity": {"samples_per_segment": 6, "quadrature_nodes": 12, "images": "cutoff"},
    "solver": {"ftol": 1e-8, "maxiter": 100},
    "protocol": {"step_mm": 0.01, "switch_strain": 0.05, "large_step_x_mm": 0.1,
                 "large_step_y_mm": 0.05, "stop_stress_N_per_mm": 0.1, "max_strain": 0.5,
                 "max_steps": 100, "mode": "tension"},
    "starts": {"count": 1, "source": "shipped", "perturbation": 0.02},
    "store": {"states": False, "contact_forces": False, "geometry": False},
    "run": {"task_timeout_s": 60.0, "checkpoint_s": 1.0, "stop_grace_s": 5.0},
}  # fmt: skip
NUMBERS = [(s, k) for s, t in BASE.items() if isinstance(t, dict) for k, v in t.items()
           if isinstance(v, (int, float)) and not isinstance(v, bool)]  # fmt: skip
FLAGS = [(s, k) for s, t in BASE.items() if isinstance(t, dict) for k, v in t.items()
         if isinstance(v, bool)]  # fmt: skip
TOP = ["schema_version", "seed", "name", "directions", "preset"]


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f'"{k}" = {toml_value(x)}' for k, x in v.items()) + "}"
    raise TypeError(v)


def toml(job: dict) -> str:
    top = [f"{k} = {toml_value(v)}" for k, v in job.items() if not isinstance(v, dict)]
    tables = [f"[{k}]\n" + "\n".join(f'"{f}" = {toml_value(x)}' for f, x in v.items())
              for k, v in job.items() if isinstance(v, dict)]  # fmt: skip
    return "\n".join(top) + "\n" + "\n".join(tables) + "\n"


strings = st.text(min_size=0, max_size=8)
wrong_for_number = st.one_of(
    strings,
    st.from_regex(r"\A-?[0-9]{1,3}(\.[0-9]{1,3})?\Z"),  # a number, but as a string
    st.booleans(),
    st.lists(st.floats(allow_nan=False), max_size=3).filter(bool),
    st.dictionaries(st.sampled_from(["a", "start"]), st.integers(), min_size=1, max_size=2),
    st.sampled_from([1e300, -1e300, 1e308, -1.0, 0.0, math.inf, -math.inf, math.nan, 10**30]),
)
wrong_for_flag = st.one_of(strings, st.integers(), st.floats(), st.lists(st.booleans(), max_size=2))


@st.composite
def bad_jobs(draw):
    job = {k: (dict(v) if isinstance(v, dict) else v) for k, v in BASE.items()}
    kind = draw(st.sampled_from(["number", "flag", "top", "unknown", "axis", "name"]))
    if kind == "number":
        section, field = draw(st.sampled_from(NUMBERS))
        value = draw(wrong_for_number)
        if field == "twist_bound" and value in (0.0, -1.0):
            value = 1.0  # -1 <= twist_bound < 1 is allowed
        job[section][field] = value
    elif kind == "flag":
        section, field = draw(st.sampled_from(FLAGS))
        job[section][field] = draw(wrong_for_flag)
    elif kind == "top":
        field = draw(st.sampled_from(TOP))
        not_text = st.one_of(st.booleans(), st.floats(), st.integers(),
                             st.lists(st.integers(), min_size=1, max_size=2))  # fmt: skip
        if field == "schema_version":
            job[field] = draw(st.one_of(not_text.filter(lambda v: v != 1 or isinstance(v, bool)),
                                        st.just("1")))  # fmt: skip
        elif field == "seed":
            job[field] = draw(st.one_of(st.booleans(), st.floats(), st.integers(max_value=-1),
                                        st.integers(min_value=2**63), st.just("1")))  # fmt: skip
        elif field == "preset":
            job[field] = draw(st.one_of(not_text, st.just(""), st.just("ultra")))
        else:
            job[field] = draw(not_text)
    elif kind == "unknown":
        section = draw(st.sampled_from([s for s, v in BASE.items() if isinstance(v, dict)]))
        known = set(BASE[section])
        job[section][draw(st.from_regex(r"\A[a-z_]{1,12}\Z").filter(lambda k: k not in known))] = 1
    elif kind == "axis":
        job["grid"]["L_mm"] = draw(st.one_of(
            st.just([]), st.just([11.0, 11.0]),
            st.fixed_dictionaries({"start": wrong_for_number, "stop": st.just(12.0),
                                   "step": st.just(0.1)}),
            st.fixed_dictionaries({"start": st.just(11.0), "stop": st.just(12.0),
                                   "step": st.sampled_from([0.0, -0.1, 1e-300, math.inf])}),
        ))  # fmt: skip
    else:
        job["name"] = draw(st.sampled_from(["", "../../escape", "a/b", "/abs", ".hidden",
                                            "nul\x00", "sp ace", "x" * 201]))  # fmt: skip
    return job


FAST = settings(max_examples=300, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip


def test_the_base_job_is_valid(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(toml(BASE))
    assert load_job(path).name == "fuzz"


@FAST
@given(job=bad_jobs())
def test_fuzzed_job_files_are_refused_naming_the_field(tmp_path, job):
    path = tmp_path / "job.toml"
    path.write_text(toml(job), encoding="utf-8", errors="surrogatepass")
    with pytest.raises(InputError) as e:
        load_job(path)
    message = str(e.value)
    assert "\n" not in message and "Traceback" not in message
    assert message.startswith(f"job file {path}: ")


@FAST
@given(content=st.binary(max_size=400))
def test_random_bytes_are_refused(tmp_path, content):
    path = tmp_path / "job.toml"
    path.write_bytes(content)
    with pytest.raises(InputError):
        load_job(path)


# ---- command-line values ---------------------------------------------------------

# option -> (low, high, low open?, integer?): the documented ranges
RANGES = {
    "--L": (0.0, 100.0, True, False), "--k": (1e-6, 1e4, False, False),
    "--B": (1e-3, 1e6, False, False), "--r": (0.01, 10.0, False, False),
    "--p": (1.0, 20.0, True, False), "--regularization": (0.0, 1e4, False, False),
    "--samples": (2, 200, False, True), "--quadrature-nodes": (2, 256, False, True),
    "--ftol": (1e-16, 1e-2, False, False), "--starts": (1, 64, False, True),
    "--seed": (0, 2**63 - 1, False, True),
}  # fmt: skip
SWEEP_ONLY = {"--step": (0.0, 1.0, True, False), "--stop-stress": (0.0, 1000.0, True, False),
              "--max-strain": (0.0, 10.0, True, False)}  # fmt: skip


@st.composite
def bad_values(draw, ranges):
    option = draw(st.sampled_from(sorted(ranges)))
    lo, hi, open_lo, integer = ranges[option]
    if integer:
        value = draw(st.one_of(st.integers(max_value=lo - 1), st.integers(min_value=hi + 1),
                               st.sampled_from(["1.5", "abc", "", "true", "1e3"])))  # fmt: skip
    else:
        below = st.floats(max_value=lo, exclude_max=not open_lo, allow_nan=False)
        above = st.floats(min_value=hi, exclude_min=True, allow_nan=False)
        value = draw(st.one_of(below, above, st.sampled_from(["nan", "abc", "", "true", "1e400"])))
    return option, str(value)


def run_cli(monkeypatch, capsys, *args) -> tuple[int, str]:
    monkeypatch.setattr(sys, "argv", ["knitsweep", *map(str, args)])
    rc = cli_main()
    return rc, capsys.readouterr().err


@FAST
@given(bad=bad_values({**RANGES, **SWEEP_ONLY}))
def test_fuzzed_sweep_values_are_refused(monkeypatch, capsys, bad):
    rc, err = run_cli(monkeypatch, capsys, "sweep", "--direction", "x", *bad)
    assert rc == 2, (bad, err)
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err


@FAST
@given(bad=bad_values(RANGES))
def test_fuzzed_relax_values_are_refused(monkeypatch, capsys, bad):
    rc, err = run_cli(monkeypatch, capsys, "relax", *bad)
    assert rc == 2, (bad, err)
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err


@settings(max_examples=12, deadline=None, derandomize=True)
@given(bad=bad_values({k: v for k, v in RANGES.items() if k != "--seed" and k != "--starts"}))
def test_fuzzed_values_through_a_real_process(bad):
    """The console entry point itself (signals installed first, lazy imports)."""
    proc = subprocess.run(
        [sys.executable, "-m", "knitsweep", "energy", "--state", str(SHIPPED / "Init_1.dat"), *bad],
        capture_output=True, text=True, timeout=120, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )  # fmt: skip
    assert proc.returncode == 2, (bad, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in proc.stderr
