"""Adaptive transition search: the pure controller, and adaptive jobs end to end."""

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import stored_meta

from knitsweep import service
from knitsweep.config import InputError
from knitsweep.service.adaptive import JAMMED_GAP, series_state

DATA = Path(__file__).parent / "data"
JOB = DATA / "jobs" / "tiny_adaptive.toml"
T, TOL = 5e-5, 0.005
COARSE = [10.5, 11.3, 12.1, 12.9]


def _drive(gap, coarse=COARSE, tol=TOL, limit=60):
    """Run the controller against a gap function; returns (state, evaluations)."""
    gaps = {L: gap(L) for L in coarse}
    for _ in range(limit):
        st = series_state(coarse, gaps, T, tol)
        if st.status != "refining":
            return st, gaps
        assert st.lo < st.next_L < st.hi and st.next_L not in gaps
        gaps[st.next_L] = gap(st.next_L)
    raise AssertionError("no convergence")


def _crossing(gap, lo=10.0, hi=13.0):
    for _ in range(200):  # bisection for the true crossing of a monotone gap
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if gap(mid) >= T else (lo, mid)
    return hi


@pytest.mark.parametrize(
    "name",
    ["linear", "convex", "kinked", "steep"],
)
def test_brackets_contain_the_crossing(name):
    gap = {
        "linear": lambda L: max(0.0, 0.016 * (11.52 - L)),
        "convex": lambda L: max(0.0, 0.02 * (11.55 - L)) ** 1.3 * 2.5,
        "kinked": lambda L: max(0.0, 0.016 * (11.4 - L)) + 4e-5 * math.exp(-8 * max(0, L - 11.4)),
        "steep": lambda L: max(0.0, 0.2 * (11.01 - L)),
    }[name]
    st, gaps = _drive(gap)
    truth = _crossing(gap)
    assert st.status == "done"
    assert st.hi - st.lo <= TOL * (1 + 1e-9)
    assert st.lo < truth <= st.hi + 1e-12
    # bisection from the 0.8 mm bracket would need 8; the secant does better
    assert len(gaps) - len(COARSE) <= 8


def test_far_fewer_evaluations_than_a_uniform_grid():
    gap = lambda L: max(0.0, 0.0165 * (11.52 - L)) ** 1.15 * 1.8  # noqa: E731
    _, gaps = _drive(gap)
    uniform = len(np.arange(10.5, 12.81, 0.1))  # the paper's 0.1 mm grid: 24 points
    assert uniform / len(gaps) >= 2.5


def test_noisy_gaps_still_bracket():
    rng = np.random.default_rng(3)
    for _ in range(20):

        def gap(L, noise={}):  # noqa: B006 - one noise draw per L within this series
            noise.setdefault(L, 2e-6 * rng.standard_normal())
            return max(0.0, 0.016 * (11.5 - L)) + noise[L]

        st, gaps = _drive(gap)
        assert st.status == "done" and st.hi - st.lo <= TOL * (1 + 1e-9)
        assert gaps[st.lo] >= T > gaps[st.hi]


def test_edge_cases():
    assert series_state(COARSE, {10.5: 1e-3}, T, TOL).status == "coarse"
    jammed = {L: 1e-3 for L in COARSE}
    assert series_state(COARSE, jammed, T, TOL).status == "jammed_throughout"
    loose = {L: 0.0 for L in COARSE}
    st = series_state(COARSE, loose, T, TOL)
    assert st.status == "unjammed_at_start" and st.hi == 10.5
    # a point without a gap before the first unjammed L could move it: the series fails;
    # one beyond it cannot (the transition is the first L below the threshold)
    broken = {10.5: 1e-3, 11.3: None, 12.1: 0.0, 12.9: 0.0}
    assert series_state(COARSE, broken, T, TOL).status == "failed"
    beyond = {10.5: 1e-3, 11.3: 2e-4, 12.1: 0.0, 12.9: None}
    st = series_state(COARSE, beyond, T, TOL)
    assert st.status == "refining" and (st.lo, st.hi) == (11.3, 12.1)
    assert series_state(COARSE, {**beyond, 10.5: None}, T, TOL).status == "failed"
    assert series_state(COARSE, {L: None for L in COARSE}, T, TOL).status == "failed"
    unknittable = {10.5: JAMMED_GAP, 11.3: 2e-4, 12.1: 0.0, 12.9: 0.0}
    st = series_state(COARSE, unknittable, T, TOL)
    assert st.status == "refining" and st.lo == 11.3 and st.hi == 12.1
    many = {**{L: 0.0 for L in COARSE}, 10.5: 1e-3}
    assert series_state(COARSE, many, T, TOL, max_refinements=0).status == "failed"


def test_proposals_depend_only_on_the_data():
    gaps = {10.5: 1.4e-3, 11.3: 2e-4, 12.1: 0.0, 12.9: 0.0, 11.45: 6e-5}
    a = series_state(COARSE, gaps, T, TOL)
    b = series_state(list(reversed(COARSE)), dict(reversed(list(gaps.items()))), T, TOL)
    assert a == b


@pytest.fixture(scope="module")
def adaptive_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("adaptive") / "a.h5"
    summary = service.run(JOB, out, executor="serial", show_progress=False)
    assert summary.counts["failed"] == 0
    return out


def _series(path):
    return stored_meta(path, "series")


def test_adaptive_job_writes_brackets(adaptive_run):
    series = _series(adaptive_run)
    assert sorted(s["direction"] for s in series.values()) == ["x", "y"]
    sweeps = stored_meta(adaptive_run, "sweeps").values()
    for s in series.values():
        assert s["status"] == "done" and s["hi_mm"] - s["lo_mm"] <= 0.02 + 1e-9
        gaps = {g["L_mm"]: g["jamming_gap"] for g in sweeps if g["direction"] == s["direction"]}
        assert gaps[s["lo_mm"]] >= 5e-5 > gaps[s["hi_mm"]]
        assert all(g < 5e-5 for L, g in gaps.items() if L > s["hi_mm"])
        assert s["L_over_r_trans"] == pytest.approx(s["hi_mm"] / 0.74)
    status = service.status(adaptive_run)
    assert status["series"] == {"done": 2, "total": 2} and status["pending"] == 0


def test_adaptive_resume_after_sigterm(adaptive_run, tmp_path):
    """SIGTERM as the 15th task starts (the coarse grid's 12 are done: the refinement has
    begun; the run sends it itself, so that it arrives there however fast the tasks are);
    the resumed run finds the same brackets."""
    out = tmp_path / "resumed.h5"
    cmd = [sys.executable, "-m", "knitsweep", "run", str(JOB), "--out", str(out), "--quiet",
           "--executor", "serial"]  # fmt: skip
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    signalled = {**env, "KNITSWEEP_TEST_SIGNAL_AT": "handout#15"}
    proc = subprocess.run(cmd, env=signalled, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 3, proc.stderr
    assert 0 < len(stored_meta(out, "sweeps")) <= 14  # tasks 1-14 kept, the 15th redone
    assert subprocess.run(cmd, env=env, capture_output=True, timeout=600).returncode == 0
    a, b = _series(adaptive_run), _series(out)
    assert a.keys() == b.keys()
    for k in a:
        assert (a[k]["lo_mm"], a[k]["hi_mm"], a[k]["evaluations"]) == (
            b[k]["lo_mm"], b[k]["hi_mm"], b[k]["evaluations"])  # fmt: skip


def test_adaptive_jobs_cannot_be_sharded(tmp_path):
    with pytest.raises(InputError, match="cannot be split into shards"):
        service.run(JOB, tmp_path / "s.h5", executor="serial", shard="0/2", show_progress=False)


def test_status_counts_add_up_while_an_adaptive_job_grows(tmp_path):
    """`knitsweep status` during an adaptive run: the total grows with the refinements,
    and finished + running + pending is always that total (it once read 39/30)."""
    out = tmp_path / "live.h5"
    cmd = [sys.executable, "-m", "knitsweep", "run", str(JOB), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    import time

    seen = []
    while proc.poll() is None:
        try:
            s = service.status(out)
        except InputError:  # the file does not exist yet
            time.sleep(0.05)
            continue
        finished = s["done"] + s["failed"] + s["not_knittable"]
        seen.append((s["live"], finished, s["running"], s["pending"], s["total"]))
        time.sleep(0.05)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    live = [row for row in seen if row[0]]
    planned = 12  # the coarse grid: 4 points, 8 sweeps
    assert live and max(row[4] for row in live) > planned  # the refinements were seen
    for _, finished, running, pending, total in seen:
        assert finished + running + pending == total and finished <= total
    s = service.status(out)
    assert not s["live"] and s["pending"] == 0 and s["done"] == s["total"] > planned


def test_the_last_crossing_of_a_re_entrant_series_is_refined_when_asked():
    """[adaptive] last_crossing: once the first crossing is bracketed, a series jammed again
    beyond it has its last crossing bisected to the tolerance; without it (the default)
    the series is done at the first, as before."""
    coarse = [8.5, 9.3, 10.1, 10.9, 11.7, 12.5]

    def gap(L):  # unjams at 9.2 mm, jammed again from 9.8 to 10.77 mm
        return 1e-3 if L < 9.2 else 0.0 if L < 9.8 else 1e-4 if L < 10.77 else 0.0

    gaps = {L: gap(L) for L in coarse}
    for _ in range(40):
        st = series_state(coarse, gaps, T, 0.02, last_crossing=True)
        if st.next_L is None:
            break
        assert st.status == "refining"
        gaps[st.next_L] = gap(st.next_L)
    assert st.status == "done" and st.lo < 9.2 <= st.hi and st.hi - st.lo <= 0.02
    assert st.last_lo < 10.77 <= st.last_hi and st.last_hi - st.last_lo <= 0.02
    first = series_state(coarse, gaps, T, 0.02)
    assert (
        first.status == "done" and first.last_lo is None and (first.lo, first.hi) == (st.lo, st.hi)
    )
    # jammed again up to the largest L: no last crossing to refine
    end = {**{L: gap(L) for L in coarse}, 11.7: 1e-4, 12.5: 1e-4}
    for _ in range(40):
        st = series_state(coarse, end, T, 0.02, last_crossing=True)
        if st.next_L is None:
            break
        end[st.next_L] = gap(st.next_L) if st.next_L < 11 else 1e-4
    assert st.status == "done" and st.last_hi is None and st.last_lo == 12.5
    assert "jammed again up to the largest L" in st.message


def test_a_series_unjammed_at_start_and_jammed_again_has_its_last_crossing_refined():
    coarse = [8.5, 9.3, 10.1, 10.9]

    def gap(L):  # unjammed at 8.5 mm, jammed at 9.3 mm alone (rib's equibiaxial series)
        return 2e-4 if 9.0 < L < 9.61 else 0.0

    gaps = {L: gap(L) for L in coarse}
    for _ in range(40):
        st = series_state(coarse, gaps, T, 0.02, last_crossing=True)
        if st.next_L is None:
            break
        assert st.status == "refining" and st.lo is None
        gaps[st.next_L] = gap(st.next_L)
    assert st.status == "unjammed_at_start" and st.hi == 8.5
    assert st.last_lo < 9.61 <= st.last_hi and st.last_hi - st.last_lo <= 0.02
    assert series_state(coarse, gaps, T, 0.02).last_lo is None
