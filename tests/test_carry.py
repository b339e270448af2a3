"""``[starts] carry``: along a series each point starts from its neighbour's zero-force
state (docs/model.md §7): the chain in the plan, its ids, what a carried point records,
its minimum against the shipped starts', the same results serially and in processes,
by shards, and in an adaptive job's refinements."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import DATA, TINY, assert_same_results, drop_tasks, stored, stored_meta

from knitsweep import service
from knitsweep.service.jobs import load_job, plan

ADAPTIVE = DATA / "jobs" / "tiny_adaptive.toml"


def _carrying(tmp_path, source, name, extra=""):
    text = source.read_text().replace("[starts]\ncount = 1", f"[starts]\ncount = 4\n{extra}")
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace("L_mm = [11.4, 12.0]", "L_mm = [11.2, 11.4, 11.6, 11.8]"))
    return path


def _zero(path):
    out = {}
    for e in stored(path, "points", with_data=True).values():
        labels = [str(s) for s in e.record["labels"]]
        energy = e.record["bending_energy"] + e.record["contact_energy"]
        out[e.meta["L_mm"]] = (labels, float(energy[int(e.meta["winner"])]))
    return out


@pytest.fixture(scope="module")
def jobs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("carry")
    return _carrying(tmp, TINY, "carried", "carry = true"), _carrying(tmp, TINY, "shipped")


def test_the_plan_chains_each_series_from_its_largest_L(jobs):
    carried, shipped = (load_job(p) for p in jobs)
    points, _ = plan(carried)
    by_L = {p.params.L_mm: p for p in points}
    assert by_L[11.8].carried_from is None
    for L, above in ((11.6, 11.8), (11.4, 11.6), (11.2, 11.4)):
        assert by_L[L].carried_from == by_L[above].task_id
    plain, _ = plan(shipped)  # carrying off: the ids of the plain job, none carried
    assert all(p.carried_from is None for p in plain)
    assert {p.task_id for p in plain}.isdisjoint(by_L[L].task_id for L in by_L)
    assert "carry" not in shipped.canonical()["starts"] and carried.job_hash != shipped.job_hash


def test_carried_points_walk_one_start_to_a_minimum_no_higher(jobs, tmp_path):
    carried, shipped = tmp_path / "c.h5", tmp_path / "s.h5"
    service.run(jobs[0], carried, executor="serial", show_progress=False)
    service.run(jobs[1], shipped, executor="serial", show_progress=False)
    c, s = _zero(carried), _zero(shipped)
    assert len(c[11.8][0]) == 4  # the series' first point: the shipped starts
    for L, above in ((11.6, 11.8), (11.4, 11.6), (11.2, 11.4)):
        assert c[L][0] == [f"carried from L = {above:g} mm"]
        # draft's Newton tolerance is 1e-5 mJ: the same minimum to within it
        assert c[L][1] <= s[L][1] + 1e-6, (L, c[L][1], s[L][1])
    assert service.status(carried)["done"] == service.status(carried)["total"]
    # in processes (results arrive in any order) the same, bit for bit
    parallel = tmp_path / "p.h5"
    service.run(jobs[0], parallel, executor="processes", workers=2, show_progress=False)
    assert_same_results(carried, parallel)
    # by shards (whole series per shard), merged: the same
    shards = [tmp_path / f"{i}.h5" for i in range(2)]
    for i, path in enumerate(shards):
        service.run(jobs[0], path, executor="serial", shard=f"{i}/2", show_progress=False)
    service.merge(tmp_path / "m.h5", shards)
    assert_same_results(carried, tmp_path / "m.h5")


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory):
    """tiny_adaptive carrying, to 0.01 mm (whole curves at fixed steps: long enough to
    interrupt)."""
    tmp = tmp_path_factory.mktemp("adaptive_carry")
    job = tmp / "a.toml"
    text = ADAPTIVE.read_text().replace("[starts]\ncount = 1", "[starts]\ncount = 1\ncarry = true")
    # 0.01 mm: the last refinements carry from earlier refinements (upper bracket ends)
    job.write_text(text.replace("tolerance_mm = 0.02", "tolerance_mm = 0.01"))
    out = tmp / "a.h5"
    service.run(job, out, executor="serial", show_progress=False)
    return job, out


def test_an_adaptive_job_carries_into_its_refinements(adaptive):
    job, out = adaptive
    zero = _zero(out)
    carried = [L for L, (labels, _) in zero.items() if labels[0].startswith("carried from")]
    assert len(carried) == len(zero) - 1 > 4  # all but the largest L, refinements too
    series = list(stored_meta(out, "series").values())
    assert [s["status"] for s in series] == ["done", "done"]
    assert all(s["hi_mm"] - s["lo_mm"] <= 0.01 + 1e-9 for s in series)
    again = service.run(job, out, executor="serial", show_progress=False)  # nothing new
    assert again.skipped == again.total
    assert np.isfinite(list(v[1] for v in zero.values())).all()


def test_a_carried_refinement_resumed_mid_way_is_the_uninterrupted_one(adaptive, tmp_path):
    """SIGTERM once the refinement has started, then resume: the same ids and results as
    the uninterrupted run. (The resumed master reads where refinements carry from off
    the file's sweeps; this interruption, timed by the progress file, does not always
    fall where a refinement carries from an earlier refinement.)"""
    job, whole = adaptive
    out = tmp_path / "resumed.h5"
    cmd = [sys.executable, "-m", "knitsweep", "run", str(job), "--out", str(out), "--quiet"]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env=env)
    progress = out.with_name(out.name + ".progress.json")
    while proc.poll() is None:
        try:
            if json.loads(progress.read_text())["done"] >= 16:
                break
        except (FileNotFoundError, ValueError):
            pass
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=120)
    assert proc.returncode == 3
    assert subprocess.run(cmd, env=env, capture_output=True, timeout=600).returncode == 0
    assert_same_results(whole, out)


def _refinements_in_order(job, path, direction):
    """One series' refined L values in the order the master asked for them (replayed
    from the stored gaps), each with its point id and the point it carried from."""
    from knitsweep.service.adaptive import Refiner

    sweeps = list(stored_meta(path, "sweeps").values())
    mine = {float(s["L_mm"]): s for s in sweeps if s["direction"] == direction}
    refiner = Refiner(load_job(job))
    coarse = set(refiner.coarse)
    for L in coarse:
        refiner.observe(mine[L])
    order, by_L = [], {L: str(mine[L]["point_id"]) for L in mine}
    while True:
        ((_, state),) = [(k, s) for k, s in refiner.states()
                         if refiner.series[k]["direction"] == direction]  # fmt: skip
        if state.status != "refining":
            return order, coarse
        order.append((state.next_L, by_L[state.next_L], state.hi))
        refiner.observe(mine[state.next_L])


def test_a_resumed_refinement_carries_from_a_refinement_of_the_run_before(adaptive, tmp_path):
    """Deterministic twin of the SIGTERM test above: the file of the uninterrupted run
    with one series' last refinements removed, from the first one whose bracket's upper
    end is itself a refinement. The resumed master must carry from that stored
    refinement (a point it never requested), with the uninterrupted run's ids."""
    job, whole = adaptive
    order, coarse = _refinements_in_order(job, whole, "x")
    cut = next(i for i, (_, _, hi) in enumerate(order) if hi not in coarse)
    out = tmp_path / "cut.h5"
    out.write_bytes(whole.read_bytes())
    removed = {pid for _, pid, _ in order[cut:]}
    drop_tasks(out, {("sweeps", s) for s, m in stored_meta(out, "sweeps").items()
                     if m["point_id"] in removed}
               | {("points", pid) for pid in removed}
               | {("series", k) for k, m in stored_meta(out, "series").items()
                  if m["direction"] == "x"})  # fmt: skip
    summary = service.run(job, out, executor="serial", show_progress=False)
    assert summary.total - summary.skipped == 2 * len(removed)  # each point and its x sweep
    assert_same_results(whole, out)
