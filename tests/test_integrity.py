"""Checksums and recovery: a results file whose bytes changed is never used (every
reader names the damaged task, a resume recomputes it), files without checksums
still read and say so, and ``knitsweep recover`` rebuilds a truncated file from what
is intact so that a resume completes it identically to a clean run (integration)."""

import hashlib
import io
import json
import os
import shutil
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest
from conftest import DATA, TINY, assert_same_results

import knitsweep
from knitsweep import service
from knitsweep.errors import DamagedResultsWarning, InputError
from knitsweep.quantities import OBSERVABLE_REGISTRY
from knitsweep.store.checksum import GROUP_DIGEST, ROOT_DIGEST, FileCheck, seal_root
from knitsweep.store.format import journal_dir
from knitsweep.store.journal import MAGIC, Malformed, decode
from knitsweep.store.read import iter_entries, read_root


def knitsweep_cli(*args, timeout=600):
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "knitsweep", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, env=env)  # fmt: skip


def flip(path, offset, n=64, mask=0x5A):
    with open(path, "r+b") as fh:
        fh.seek(offset)
        data = fh.read(n)
        fh.seek(offset)
        fh.write(bytes(b ^ mask for b in data))


def data_offset(ds) -> int:
    return ds.id.get_offset() if ds.chunks is None else ds.id.get_chunk_info(0).byte_offset


def row_offset(f, kind: str, tid: str, column: str) -> int:
    """Where in the file the row of task ``tid`` starts in ``column`` (uncompressed)."""
    row = list(f[f"{kind}/task"].asstr()).index(tid)
    ds = f[f"{kind}/{column}"]
    assert ds.compression is None
    start = row - row % ds.chunks[0]
    info = ds.id.get_chunk_info_by_coord((start,) + (0,) * (ds.ndim - 1))
    return info.byte_offset + (row - start) * int(np.prod(ds.chunks[1:])) * ds.dtype.itemsize


@pytest.fixture
def damaged(tiny_reference, tmp_path):
    """A copy of the tiny reference with 64 bytes of one sweep's total_energy flipped."""
    out = tmp_path / "d.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "r") as f:
        tid = sorted(f["sweeps/task"].asstr())[0]
        offset = row_offset(f, "sweeps", tid, "total_energy")
    flip(out, offset)
    return out, tid


@pytest.fixture
def schema2(tmp_path):
    """A copy of the tiny job's results as the previous version wrote them (results
    schema 2: one group per task)."""
    out = tmp_path / "v2.h5"
    shutil.copy(DATA / "schema2_tiny.h5", out)
    return out


INPUTS = {
    "B_mN_mm2",
    "L_mm",
    "L_over_r",
    "k_mN_per_mm2",
    "p",
    "r_core_mm",
    "r_mm",
    "regularization_mN_mm4",
    "twist_bound",
    "seed",
    "direction",
    "point_id",
    "status",
}
"""A task's scalars that its inputs decide, not the numbers it computed.

schema2_tiny.h5 was computed on another machine, and numbers from the kernels and LAPACK differ from CPU to CPU in their
last bits; a relaxation converged to its tolerance amplifies that (benchmarks/
cpu_spread.py, the tiny job with the kernels compiled for this host, an AMD EPYC with
AVX-512, against NUMBA_CPU_NAME=generic: relaxed states 2.5e-5 apart relative to their
size, stresses along a sweep up to 6e-2, one sweep a step shorter). So no tolerance
makes a shipped file's numbers a fresh run's: the file is compared with itself read
raw, and with a fresh run only in what no CPU changes (tasks, parameters, seeds, the
names and kinds of the stored arrays)."""


def test_a_file_of_schema_2_reads_as_the_same_results(schema2, tiny_reference):
    assert read_root(schema2)["schema_version"] == 2
    fresh = {(e.kind, e.task_id): e for e in iter_entries(tiny_reference, with_data=True)}
    old = {(e.kind, e.task_id): e for e in iter_entries(schema2, with_data=True)}
    assert old.keys() == fresh.keys()
    compared = 0
    with h5py.File(schema2, "r") as f:
        for key, e in old.items():
            # observables registered since, and the stress components stored since the load
            # paths and shear (knitsweep.paths)
            added = fresh[key].record.keys() - e.record.keys()
            assert e.record.keys() <= fresh[key].record.keys(), key
            stresses = {"stress_xx", "stress_yy", "stress_xy"}
            assert added <= {o.name for o in OBSERVABLE_REGISTRY} | stresses, (key, added)
            group = f[key[0]][key[1]]
            for name, value in e.record.items():  # as stored, bit for bit
                raw = group[name][()]
                raw = raw.astype(str) if raw.dtype.kind == "O" else raw
                assert np.array_equal(np.asarray(value), raw), (key, name)
                assert (
                    np.asarray(value).dtype.kind == np.asarray(fresh[key].record[name]).dtype.kind
                )
                compared += 1
            same = {k: v for k, v in fresh[key].meta.items() if k in INPUTS}
            assert {k: e.meta[k] for k in same} == same and len(same) >= 10, key
    assert compared > 100


def test_a_flipped_byte_in_a_table_spoils_its_row_only(tiny_reference, tmp_path):
    out = tmp_path / "one.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "r") as f:
        tids = sorted(f["sweeps/task"].asstr())
        offset = row_offset(f, "sweeps", tids[1], "stress") + 8  # its second value
    flip(out, offset, n=1)
    check = FileCheck()
    assert sorted(e.task_id for e in iter_entries(out, check=check) if e.kind == "sweeps") == [
        t for t in tids if t != tids[1]]  # fmt: skip
    assert [(k, t) for k, t, _ in check.damaged] == [("sweeps", tids[1])]


def test_flipped_bytes_are_found_by_every_reader_and_recomputed(damaged, tiny_reference, tmp_path):
    out, tid = damaged
    s = service.status(out)
    assert s["done"] == 5 and s["verified"] == 5
    assert [d.split(":")[0] for d in s["damaged"]] == [f"sweep {tid}"]
    shown = knitsweep_cli("status", out)
    assert shown.returncode == 0 and f"damaged sweep {tid}" in shown.stdout
    assert "knitsweep recover" in shown.stdout
    with pytest.warns(DamagedResultsWarning, match=rf"1 damaged task\(s\) skipped \(sweep {tid}\)"):
        res = knitsweep.load(out)
    assert res.partial and tid not in set(res.sweeps["task_id"])
    damaged_rows = res.problems.query("status == 'damaged'")
    assert list(damaged_rows["task_id"]) == [tid] and list(damaged_rows["file"]) == [str(out)]
    pd = knitsweep_cli("phase-diagram", out, "--out", tmp_path / "pd", "--no-figures")
    assert pd.returncode == 0 and f"damaged: sweep {tid}" in pd.stdout, pd.stdout + pd.stderr
    merged = knitsweep_cli("merge", tmp_path / "m.h5", out)
    assert merged.returncode == 0 and "partial: 5 of 6" in merged.stdout
    assert f"damaged sweep {tid}" in merged.stderr
    rep = knitsweep_cli("report", out, "--out", tmp_path / "r.html")
    assert rep.returncode == 0 and tid in (tmp_path / "r.html").read_text()
    run = knitsweep_cli("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 0 and f"sweep {tid} is damaged" in run.stderr
    assert "(5 already finished)" in run.stderr
    assert_same_results(tiny_reference, out)
    assert service.status(out)["damaged"] == []


def test_helpers_read_a_file_as_this_process_does(schema2, monkeypatch):
    """A large file of task groups (schema 2) is read by forked helpers (here: every
    file): the same entries in the same order, the same damage found, the same counts."""
    from knitsweep.store import read

    out = schema2
    with h5py.File(out, "r") as f:
        tid = sorted(f["sweeps"])[0]
        offset = data_offset(f[f"sweeps/{tid}/total_energy"])
    flip(out, offset)

    def entries_and_check():
        check = FileCheck()
        got = [(e.kind, e.task_id, sorted(e.meta.items()), {k: np.asarray(v).tolist() for k, v in e.record.items()})
               for e in iter_entries(out, with_data=True, check=check)]  # fmt: skip
        return got, (check.damaged, check.verified, check.unverified, check.structure)

    serial = entries_and_check()
    assert [d[1] for d in serial[1][0]] == [tid] and serial[1][1] == 5
    monkeypatch.setattr(read, "PARALLEL_FROM", 1)
    forked = []
    import knitsweep.util.forking as processes

    real_map = processes.forked_map

    def counting_map(workers, fn, items):
        forked.append(workers)
        return real_map(workers, fn, items)

    monkeypatch.setattr(processes, "fork_workers", lambda limit=4: 2)
    monkeypatch.setattr(processes, "forked_map", counting_map)
    parallel = entries_and_check()
    assert forked == [2], "the helpers did not read"
    assert parallel == serial


def test_a_changed_attribute_or_root_is_damage(tiny_reference, tmp_path):
    out = tmp_path / "a.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "a") as f:
        tids = list(f["points/task"].asstr())
        f["points/L_mm"][0] = 99.0  # the column other readers see
        entry = json.loads(f["points/entry"][1])
        entry["attrs"]["L_mm"] = 99.0
        f["points/entry"][1] = json.dumps(entry, sort_keys=True, separators=(",", ":"))
    check = FileCheck()
    assert not set(tids) & {e.task_id for e in iter_entries(out, check=check)}
    assert [d[:2] for d in check.damaged] == [("points", tids[0]), ("points", tids[1])]
    assert "L_mm column disagrees" in check.damaged[0][2] and "checksum" in check.damaged[1][2]
    with h5py.File(out, "a") as f:
        f.attrs["job_name"] = "other"
    for args in (("status", out), ("phase-diagram", out, "--out", tmp_path / "pd"),
                 ("report", out, "--out", tmp_path / "r.html"),
                 ("merge", tmp_path / "m.h5", out), ("run", TINY, "--out", out)):  # fmt: skip
        proc = knitsweep_cli(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "root attributes fail their checksum" in proc.stderr, proc.stderr
        assert "knitsweep recover" in proc.stderr and "Traceback" not in proc.stderr


def test_files_without_checksums_read_unverified(schema2):
    out = schema2
    with h5py.File(out, "a") as f:
        del f.attrs[ROOT_DIGEST]
        for kind in ("points", "sweeps"):
            for g in f[kind].values():
                del g.attrs[GROUP_DIGEST]
    s = service.status(out)
    assert s["done"] == 6 and s["unverified"] == 6 and s["verified"] == 0
    assert any("without checksums" in line for line in s["check"])
    assert any("without checksums" in n for n in knitsweep.load(out).reduction.notes)


def test_digests_cover_scalars_empty_arrays_strings_and_attributes(tmp_path):
    from knitsweep.service.jobs import JobSpec
    from knitsweep.store.writer import ResultWriter

    out = tmp_path / "s.h5"
    writer = ResultWriter(out, JobSpec(schema_version=1, name="s", grid={"L_mm": 11.6}))
    record = {"empty": np.zeros(0), "labels": np.array(["a", "bé"], dtype=object),
              "one": np.array([2.5]), "flag": True, "n": 3, "text": "x"}  # fmt: skip
    for i in range(4):
        writer.add("sweeps", f"s{i}", record, {"status": "done", "where": {"rank": 1}})
    writer.close("complete")

    with h5py.File(out, "a") as f:
        g = f["sweeps"]
        assert list(g["task"].asstr()) == ["s0", "s1", "s2", "s3"]
        g["labels"][0, 1] = "bx"  # a string array
        g["text"][1] = "y"  # a string scalar's column
        g["flag"][2] = 0.0  # a boolean scalar's column
    check = FileCheck()
    assert [e.task_id for e in iter_entries(out, check=check)] == ["s3"]
    assert sorted(t for _, t, _ in check.damaged) == ["s0", "s1", "s2"]


def test_a_journal_entry_with_an_object_array_is_malformed_for_every_reader():
    """``status`` (metadata only) and resume (data) agree on an unreadable entry."""
    header = {"format": 1, "kind": "sweeps", "task_id": "t",
              "scalars": {"record": {}, "meta": {"status": "done"}},
              "layout": {"record": ["x"], "meta": [], "object": []}}  # fmt: skip
    buffer = io.BytesIO()
    np.savez(buffer, __entry__=np.frombuffer(json.dumps(header).encode(), np.uint8),
             a0=np.array([{"a": 1}], dtype=object))  # fmt: skip
    payload = buffer.getvalue()
    data = MAGIC + hashlib.sha256(payload).digest() + payload
    for with_data in (False, True):
        with pytest.raises(Malformed):
            decode(data, with_data=with_data)


# ---- recovery ----------------------------------------------------------------------

_MID_RUN = """
import os, signal, sys
from knitsweep.service.jobs import load_job
from knitsweep.store.read import iter_entries
from knitsweep.store.writer import ResultWriter
ref, out = sys.argv[1], sys.argv[2]
entries = sorted(iter_entries(ref, with_data=True), key=lambda e: (e.kind, e.task_id))
writer = ResultWriter(out, load_job({job!r}), {{"n_points": 2, "n_sweeps": 4}})
for e in entries[:2]:
    writer.add(e.kind, e.task_id, e.record, e.meta)
writer.checkpoint()  # version 1
for e in entries[2:4]:
    writer.add(e.kind, e.task_id, e.record, e.meta)
writer.checkpoint()  # version 2; version 1 is the shadow
writer.add(entries[4].kind, entries[4].task_id, entries[4].record, entries[4].meta)
writer.commit()  # durable in the journal
os.kill(os.getpid(), signal.SIGKILL)  # the journal holds the fifth task
"""


@pytest.fixture
def killed_mid_run(tiny_reference, tmp_path):
    out = tmp_path / "k.h5"
    script = textwrap.dedent(_MID_RUN.format(job=str(TINY)))
    proc = subprocess.run([sys.executable, "-c", script, str(tiny_reference), str(out)],
                          capture_output=True, text=True)  # fmt: skip
    assert proc.returncode == -9, proc.stderr
    assert (tmp_path / ".k.h5.shadow").exists() and len(list(journal_dir(out).iterdir())) == 1
    return out


@pytest.mark.parametrize("cut", ["half", "1 byte", "4 KiB", "0 bytes"])
def test_recover_a_truncated_file_then_resume_identically(killed_mid_run, tiny_reference, cut):
    out = killed_mid_run
    size = out.stat().st_size
    keep = {"half": size // 2, "1 byte": size - 1, "4 KiB": size - 4096, "0 bytes": 0}[cut]
    os.truncate(out, keep)
    for args in (("status", out), ("run", TINY, "--out", out)):
        refused = knitsweep_cli(*args)
        assert refused.returncode == 2 and f"knitsweep recover {out}" in refused.stderr
    proc = knitsweep_cli("recover", out)
    assert proc.returncode == 0, proc.stderr
    assert "recovered" in proc.stdout and f"kept as {out}.damaged" in proc.stdout, proc.stdout
    assert "from the journal" in proc.stdout  # the fifth task
    assert out.with_name(out.name + ".damaged").stat().st_size == keep  # nothing deleted
    assert read_root(out)["run_status"] == "recovered"
    s = service.status(out)
    assert s["done"] >= 3, proc.stdout  # at least the shadow's two and the journal's one
    assert s["damaged"] == []
    run = knitsweep_cli("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 0, run.stderr
    assert_same_results(tiny_reference, out)


def test_recover_an_intact_file_changes_nothing(tiny_reference, tmp_path):
    out = tmp_path / "i.h5"
    shutil.copy(tiny_reference, out)
    before = out.read_bytes()
    proc = knitsweep_cli("recover", out)
    assert proc.returncode == 0 and "intact (6 tasks verified" in proc.stdout
    assert out.read_bytes() == before


def test_recover_takes_a_damaged_root_from_its_sealed_frame(tiny_reference, tmp_path):
    out = tmp_path / "j.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "a") as f:
        f.attrs["job_json"] = "{}"
    r = service.recover(out)
    assert r["recovered"] == 6 and "root attributes from its sealed frame" in r["sources"][str(out)]
    assert read_root(out)["job_json"] == read_root(tiny_reference)["job_json"]
    assert service.status(out)["done"] == 6


def test_recover_needs_the_job_when_no_root_is_intact(tiny_reference, tmp_path):
    out = tmp_path / "j.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "a") as f:
        f.attrs["job_json"] = "{}"
    data = out.read_bytes()
    at = data.find(b"KSRT")
    assert at > 0
    while at >= 0:  # and every sealed copy of the root
        flip(out, at + 60, n=1)
        at = data.find(b"KSRT", at + 4)
    with pytest.raises(InputError, match="--job"):
        service.recover(out)
    r = service.recover(out, TINY)
    assert r["recovered"] == 6 and r["recompute"] == 0
    with h5py.File(out, "a") as f:
        seal_root(f)  # (the test's own edit, resealed: still a valid file)
    assert service.status(out)["done"] == 6


def test_a_file_of_schema_2_merges_into_one_this_version_resumes(schema2, tiny_reference, tmp_path):
    with pytest.raises(InputError, match=r"knitsweep merge NEW.h5 .*v2.h5"):
        service.run(TINY, schema2, executor="serial", show_progress=False)
    new = tmp_path / "v3.h5"
    merged = knitsweep_cli("merge", new, schema2)
    assert merged.returncode == 0, merged.stderr
    assert read_root(new)["schema_version"] == 3
    assert service.run(TINY, new, executor="serial", show_progress=False).skipped == 6
    assert_same_results(schema2, new)  # what the merge copied, bit for bit (INPUTS)
