"""Faults: full and read-only disks, damaged or foreign files, a journal that must not
run code. Each bad thing is one line and exit code 2 before any compute (or exit 3
if it happens mid-run), and nothing already written is lost (integration tier).

The disk tests mount small tmpfs file systems, so they need root (as CI has)."""

import os
import pickle
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import (
    SHIPPED,
    TINY,
    assert_same_results,
    drop_tasks,
    one_error_line,
    stored,
    stored_meta,
)
from conftest import run_knitsweep as knitsweep

from knitsweep import service
from knitsweep.config import InputError
from knitsweep.store.checksum import seal_root
from knitsweep.store.format import RESULTS_SCHEMA_VERSION, journal_dir
from knitsweep.store.journal import (
    Entry,
    Malformed,
    decode,
    decode_batch,
    encode,
    encode_batch,
    scan,
    write_batch,
    write_entry,
)
from knitsweep.store.read import iter_entries, read_entry, read_root


@pytest.fixture
def tmpfs(tmp_path):
    """Mount a small tmpfs: ``tmpfs(size, ro=False) -> Path``; unmounted afterwards."""
    mounts = []

    def mount(size: str, ro: bool = False) -> Path:
        d = tmp_path / f"mnt{len(mounts)}"
        d.mkdir()
        opts = f"size={size}" + (",ro" if ro else "")
        proc = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(d)],
                              capture_output=True, text=True)  # fmt: skip
        if proc.returncode != 0:
            pytest.fail(f"cannot mount a tmpfs (these tests need root, as CI has): {proc.stderr}")
        mounts.append(d)
        return d

    yield mount
    for d in reversed(mounts):
        subprocess.run(["umount", "-l", str(d)], check=False)


def leftovers(d: Path) -> list[str]:
    """Temporary, shadow and spare files a writer must never leave behind."""
    return sorted(p.name for p in d.rglob(".*") if p.is_file())


# ---- the journal ------------------------------------------------------------------


def sample_entry() -> Entry:
    record = {"x": np.arange(12.0).reshape(3, 4), "labels": np.array(["a", "bé"], dtype=object),
              "winner": np.array([1, 2], dtype=np.int32)}  # fmt: skip
    meta = {"status": "done", "L_mm": 11.6, "seed": 2**62, "converged": True, "nan": float("nan"),
            "where": {"rank": 1}, "n": np.int64(3), "f": np.float32(0.5)}  # fmt: skip
    return Entry("sweeps", "abc123", record, meta)


def test_journal_entry_round_trip_keeps_values_and_types():
    e = sample_entry()
    back = decode(encode(e))
    assert (back.kind, back.task_id) == (e.kind, e.task_id)
    assert back.record.keys() == e.record.keys()
    for k, v in e.record.items():
        assert back.record[k].dtype == v.dtype and np.array_equal(back.record[k], v)
    assert back.meta["seed"] == 2**62 and back.meta["converged"] is True
    assert back.meta["where"] == {"rank": 1} and back.meta["n"] == 3 and back.meta["f"] == 0.5
    assert np.isnan(back.meta["nan"])
    meta_only = decode(encode(e), with_data=False)
    assert meta_only.record == {} and meta_only.meta["status"] == "done"


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda b: b[: len(b) // 2], "checksum"),
        (lambda b: b[:40] + bytes([b[40] ^ 1]) + b[41:], "checksum"),
        (lambda b: b"", "not a knitsweep journal entry"),
        (lambda b: b"\x00" * 100, "not a knitsweep journal entry"),
    ],
)
def test_damaged_entries_are_malformed(damage, why):
    with pytest.raises(Malformed, match=why):
        decode(damage(encode(sample_entry())))


def test_journal_batch_round_trip_keeps_values_types_and_order():
    a, b = sample_entry(), Entry("points", "p1", {}, {"status": "failed", "message": "x"})
    newer = Entry("sweeps", "abc123", {"x": np.zeros((0, 4))}, {"status": "done"})
    back = decode_batch(encode_batch([a, b, newer]))
    assert [(e.kind, e.task_id) for e in back] == [("sweeps", "abc123"), ("points", "p1"),
                                                   ("sweeps", "abc123")]  # fmt: skip
    for k, v in a.record.items():
        assert back[0].record[k].dtype == v.dtype and np.array_equal(back[0].record[k], v)
    assert back[0].meta["seed"] == 2**62 and back[0].meta["where"] == {"rank": 1}
    assert back[2].record["x"].shape == (0, 4) and back[1].meta["message"] == "x"
    assert decode_batch(encode_batch([a]), with_data=False)[0].record == {}
    data = encode_batch([a, b])
    for damaged in (data[: len(data) // 2], data[:50] + bytes([data[50] ^ 1]) + data[51:]):
        with pytest.raises(Malformed, match="checksum"):
            decode_batch(damaged)


def test_group_commit_writes_one_batch_per_commit_and_later_entries_win(tmp_path):
    """Results added are durable only at the commit: one batch file per commit, read
    back in sequence order; a damaged batch is one malformed file."""
    from knitsweep.service.jobs import load_job
    from knitsweep.store.writer import ResultWriter

    out = tmp_path / "g.h5"
    writer = ResultWriter(out, load_job(TINY))
    for i in range(3):
        writer.add("points", f"p{i}", {"E": np.arange(3.0)}, {"status": "failed"})
    assert list(journal_dir(out).glob("*.entry")) == [] and writer.uncommitted == 3
    assert writer.commit() == 3 and writer.uncommitted == 0
    writer.add("points", "p0", {}, {"status": "done"})
    writer.commit()
    batches = sorted(journal_dir(out).glob("batch-*.entry"))
    assert len(batches) == 2
    entries, problems = scan(journal_dir(out), with_data=True)
    assert problems == [] and [e.task_id for e in entries] == ["p0", "p1", "p2", "p0"]
    assert entries[-1].meta["status"] == "done"
    assert {e.task_id: e.meta["status"] for e in iter_entries(out)}["p0"] == "done"
    writer.close("interrupted")
    assert not journal_dir(out).exists()
    points = stored_meta(out, "points")
    assert sorted(points) == ["p0", "p1", "p2"] and points["p0"]["status"] == "done"
    journal = journal_dir(out)
    journal.mkdir()
    path = write_batch(journal, 1, [Entry("points", "p9", {}, {"status": "done"})])
    path.write_bytes(path.read_bytes()[:-3])
    assert len(scan(journal)[1]) == 1 and read_entry(out, "points", "p9") is None


def test_a_pickle_in_the_journal_is_never_unpickled(tmp_path):
    """Whoever can write into the journal must not run code in the master."""
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (Path.touch, (marker,))

    out = tmp_path / "r.h5"
    journal = journal_dir(out)
    journal.mkdir()
    (journal / "points-0000000000000000.pkl").write_bytes(pickle.dumps(Evil()))
    (journal / "points-1111111111111111.entry").write_bytes(pickle.dumps(Evil()))
    assert list(iter_entries(out)) == []
    assert read_entry(out, "points", "1111111111111111") is None
    assert not marker.exists()


def test_malformed_entries_are_reported_and_recomputed(tiny_reference, tmp_path):
    out = tmp_path / "m.h5"
    shutil.copy(tiny_reference, out)
    tid = sorted(stored(out, "sweeps"))[0]
    drop_tasks(out, {("sweeps", tid)})  # one sweep not yet checkpointed, and damaged
    with h5py.File(out, "a") as f:
        f.attrs["run_status"] = "interrupted"
        seal_root(f)  # as the writer does at a checkpoint
    journal = journal_dir(out)
    journal.mkdir()
    path = write_entry(journal, Entry("sweeps", tid, {}, {"status": "done"}))
    path.write_bytes(path.read_bytes()[:-7])  # truncated by a dying disk
    (journal / "points-zz.entry").write_bytes(os.urandom(300))
    s = service.status(out)
    assert len(s["journal_problems"]) == 2 and any("checksum" in p for p in s["journal_problems"])
    assert s["done"] == 5
    shown = knitsweep("status", out)
    assert shown.returncode == 0 and shown.stdout.count("malformed journal entry") == 2
    proc = knitsweep("run", TINY, "--out", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("warning: journal entry") == 2
    assert "1 already finished" not in proc.stderr and "(5 already finished)" in proc.stderr
    assert_same_results(tiny_reference, out)
    assert not journal.exists()


# ---- foreign and malformed results files -------------------------------------------


@pytest.mark.parametrize(
    ("attrs", "fragment"),
    [
        ({}, "not a knitsweep results file"),
        ({"schema_version": "1", "job_json": "{}"}, "schema_version '1' is not an integer"),
        ({"schema_version": True, "job_json": "{}"}, "is not an integer"),
        ({"schema_version": 2, "job_json": "{}"}, "no job_hash attribute"),
    ],
)
def test_foreign_hdf5_files_are_named_as_such(tmp_path, attrs, fragment):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.arange(3)
        f.attrs.update(attrs)
    with pytest.raises(InputError, match=fragment):
        read_root(path)
    for args in (["status", path], ["phase-diagram", path, "--out", tmp_path / "pd"],
                 ["merge", tmp_path / "m.h5", path], ["run", TINY, "--out", path]):  # fmt: skip
        one_error_line(knitsweep(*args), fragment)
    assert not (tmp_path / "pd").exists() and not (tmp_path / "m.h5").exists()


def test_merge_refuses_a_file_given_twice(tiny_reference, tmp_path):
    a = tmp_path / "a.h5"
    shutil.copy(tiny_reference, a)
    one_error_line(knitsweep("merge", tmp_path / "m.h5", a, tiny_reference, tiny_reference),
                   "is given twice")  # fmt: skip


# ---- outputs that cannot be written ------------------------------------------------


def test_outputs_are_checked_before_any_compute(tmp_path, tiny_reference):
    missing = tmp_path / "no" / "such" / "dir"
    one_error_line(knitsweep("run", TINY, "--out", missing / "r.h5"), "does not exist")
    one_error_line(knitsweep("sweep", "--direction", "x", "--out", missing / "s.csv"),
                   "does not exist")  # fmt: skip
    one_error_line(knitsweep("merge", missing / "m.h5", tiny_reference), "does not exist")
    a_file = tmp_path / "figures"
    a_file.write_text("not a directory")
    one_error_line(knitsweep("phase-diagram", tiny_reference, "--out", a_file),
                   "exists and is not a directory")  # fmt: skip
    assert a_file.read_text() == "not a directory"


def test_read_only_directory(tmpfs, tmp_path):
    ro = tmpfs("1m", ro=True)
    proc = knitsweep("run", TINY, "--out", ro / "r.h5")
    one_error_line(proc, "is not writable (Read-only file system)")
    one_error_line(knitsweep("sweep", "--direction", "y", "--out", ro / "s.csv"), "not writable")
    # a file that exists there can still be read
    assert not list(ro.iterdir())


@pytest.fixture(scope="module")
def six_stored(tmp_path_factory):
    """A 6-point job storing states and geometry, and its uninterrupted result."""
    d = tmp_path_factory.mktemp("six_stored")
    job = d / "six.toml"
    text = TINY.read_text().replace("[11.4, 12.0]", "[11.2, 11.4, 11.6, 11.8, 12.0, 12.2]")
    job.write_text(text + "\n[store]\nstates = true\ngeometry = true\n")
    reference = d / "reference.h5"
    assert knitsweep("run", job, "--out", reference, "--quiet").returncode == 0
    return job, reference


@pytest.mark.slow
@pytest.mark.parametrize("size", ["300k", "400k", "600k"])
def test_full_disk_mid_run_stops_cleanly_and_resumes(tmpfs, tmp_path, six_stored, size):
    """The disk fills during the run (at different moments for different sizes): one
    line, exit 3, no temporary file, the file still opens; moved to a roomy disk the
    run resumes to the uninterrupted result."""
    job, reference = six_stored
    full = tmpfs(size)
    out = full / "r.h5"
    proc = knitsweep("run", job, "--out", out, "--quiet")
    assert proc.returncode == 3, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "the disk is full" in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert leftovers(full) == [], "temporary files left on a full disk"
    kept = len({(e.kind, e.task_id) for e in iter_entries(out)})  # the file and its journal
    said = int(errors[0].split("; ")[1].split(" of ")[0])
    print(f"full disk ({size}) landed mid-run: {int(0 < kept < 18)} of 1 ({kept} of 18 tasks "
          f"kept, {said} said)")  # fmt: skip
    assert kept < 18
    assert said == kept, errors[0]  # the last line counts what is on disk
    roomy = tmp_path / "roomy"
    roomy.mkdir()
    shutil.copy(out, roomy / "r.h5")
    shutil.copytree(journal_dir(out), journal_dir(roomy / "r.h5"))
    again = knitsweep("run", job, "--out", roomy / "r.h5", "--quiet")
    assert again.returncode == 0, again.stderr
    assert_same_results(reference, roomy / "r.h5")


def test_h5py_reports_of_a_failed_flush_are_silenced_once_a_write_failed(monkeypatch, capsys):
    """An h5py object freed after a failed flush reports the failure again from its
    ``__dealloc__`` (Cython prints it through ``sys.excepthook`` and
    ``sys.unraisablehook``, whenever it is collected); after a failed write those
    reports are silent for the rest of the process, other errors are not."""
    from knitsweep.errors import StorageError
    from knitsweep.store import failed_writes as writes

    monkeypatch.setattr(sys, "excepthook", sys.excepthook)
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)
    monkeypatch.setattr(writes, "_HDF5_WRITE_FAILED", False)

    def raised_in(filename: str):
        code = compile('raise RuntimeError("Can\'t decrement id ref count")', filename, "exec")
        try:
            exec(code, {})
        except RuntimeError as e:
            return e

    with writes.hdf5_writes(Path("ok.h5")):  # nothing fails: the hooks come back
        pass
    assert not writes.hdf5_write_failed()
    with pytest.raises(StorageError, match=r"cannot write r\.h5: the disk is full"):
        with writes.hdf5_writes(Path("r.h5")):
            raise RuntimeError("Can't write data (file write failed: No space left on device)")
    assert writes.hdf5_write_failed()
    h5 = raised_in("h5py/_objects.pyx")
    sys.excepthook(RuntimeError, h5, h5.__traceback__)
    from types import SimpleNamespace

    report = dict(exc_type=RuntimeError, exc_value=h5, exc_traceback=h5.__traceback__)
    sys.unraisablehook(SimpleNamespace(**report, err_msg=None, object=None))
    assert capsys.readouterr().err == ""
    ours = raised_in("knitsweep_code.py")
    sys.excepthook(RuntimeError, ours, ours.__traceback__)
    assert "knitsweep_code.py" in capsys.readouterr().err


# ---- bad inputs on the command line ------------------------------------------------


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        ("schema_version = 1\n".encode("utf-16"), "not UTF-8 text"),
        (bytes(range(256)) * 4, "not UTF-8 text"),
        (b"a = " + b"[" * 3000 + b"]" * 3000 + b"\n", "nested too deeply"),
        (
            b'schema_version = 1\nname = "../../escape"\n[grid]\nL_mm = 11.6\n',
            "name = '../../escape'",
        ),
    ],
)
def test_bad_job_files(tmp_path, content, fragment):
    path = tmp_path / "job.toml"
    path.write_bytes(content)
    one_error_line(knitsweep("run", path), fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.toml"]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["relax", "--L", "1e308"], "L_mm = 1e+308: must be a finite number in (0, 100] mm"),
        (["relax", "--L", "1e300"], "L_mm = 1e+300"),
        (["relax", "--k", "1e300"], "k_mN_per_mm2 = 1e+300"),
        (["relax", "--regularization", "1e300"], "regularization_mN_mm4 = 1e+300"),
        (["relax", "--seed", "-1"], "seed = -1: must be an integer in [0, 2**63)"),
        (["relax", "--preset", ""], "preset = ''"),
        (["relax", "--starts", "0"], "count = 0"),
        (["sweep", "--direction", "x", "--step", "1e300"], "step_mm = 1e+300"),
        (["sweep", "--direction", "x", "--stop-stress", "1e300"], "stop_stress_N_per_mm = 1e+300"),
        (["energy", "--state", SHIPPED / "Init_1.dat", "--r", "1e300"], "r_mm = 1e+300"),
    ],
)
def test_bad_values_on_the_command_line(args, fragment):
    one_error_line(knitsweep(*args, timeout=120), fragment)


def test_binary_and_utf16_state_files(tmp_path):
    for name, content in (("b.dat", bytes(range(256))), ("u.dat", "1.0\n".encode("utf-16"))):
        path = tmp_path / name
        path.write_bytes(content)
        one_error_line(knitsweep("energy", "--state", path), "not UTF-8 text")


# ---- checkpoints -------------------------------------------------------------------


def test_checkpoints_append_in_place_and_never_touch_a_file_a_reader_holds(tmp_path):
    """Each checkpoint publishes a whole file; the retired version becomes the next
    shadow only if no reader still has it open (then the shadow is copied afresh)."""
    from knitsweep.service.jobs import JobSpec
    from knitsweep.store.writer import ResultWriter

    job = JobSpec(schema_version=1, name="c", grid={"L_mm": 11.6})
    out = tmp_path / "c.h5"
    writer = ResultWriter(out, job)
    rng = np.random.default_rng(0)

    def add(n0, n):
        for i in range(n0, n0 + n):
            writer.add("sweeps", f"s{i}", {"stress": rng.random(300)}, {"status": "done", "i": i})

    add(0, 3)
    assert writer.checkpoint() == 3
    reader = h5py.File(out, "r")  # holds version 1 open
    inode = os.stat(out).st_ino
    add(3, 2)
    assert writer.checkpoint() == 2  # version 2; version 1 (the reader's) is the spare shadow
    assert os.stat(out).st_ino != inode
    add(5, 2)
    assert writer.checkpoint() == 2  # the reader still holds version 1: copied, not reused
    assert list(reader["sweeps/task"].asstr()) == ["s0", "s1", "s2"]  # the reader's never changed
    reader.close()
    add(7, 1)
    writer.checkpoint()
    writer.close("complete")
    sweeps = stored_meta(out, "sweeps")
    assert list(sweeps) == [f"s{i}" for i in range(8)]
    assert [sweeps[f"s{i}"]["i"] for i in range(8)] == list(range(8))
    assert leftovers(tmp_path) == [] and not journal_dir(out).exists()


# ---- faults that once ended in a traceback -----------------------------------------


@pytest.mark.parametrize("attr", ["message", "L_mm", "status"])
def test_non_utf8_attributes_are_no_traceback(tmp_path, attr):
    from results_factory import write_results

    path = write_results(tmp_path / "u.h5", ks=(0.1,))
    with h5py.File(path, "a") as f:
        f[f"sweeps/{sorted(f['sweeps'])[0]}"].attrs[attr] = np.bytes_(b"\xff\xfe bad \xc3")
    for args in (("phase-diagram", path, "--out", tmp_path / "pd", "--no-figures"),
                 ("report", path, "--out", tmp_path / "r.html"), ("status", path)):  # fmt: skip
        proc = knitsweep(*args)
        assert proc.returncode in (0, 2), (args, proc.stderr)
        assert "Traceback" not in proc.stderr and "UnicodeDecodeError" not in proc.stderr
        if proc.returncode == 2:
            one_error_line(proc, "u.h5")


def test_render_to_a_missing_directory_is_refused_before_any_compute(tmp_path):
    proc = knitsweep("render", "--out", "/nonexistent/dir/r.png", "--state",
                     SHIPPED / "Init_1.dat")  # fmt: skip
    one_error_line(proc, "directory /nonexistent/dir does not exist")


@pytest.mark.slow
def test_directory_made_read_only_mid_run(tmpfs, six_stored):
    """The output directory refuses new files once the first result is journalled
    (``chattr +i``: even root cannot create files in it): one line naming the cause
    (permission, not a full disk), exit 3, no traceback (the lock's removal used to
    raise PermissionError), and the file still opens."""
    job, _ = six_stored
    d = tmpfs("64m") / "out"
    d.mkdir()
    out = d / "r.h5"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "knitsweep", "run", str(job), "--out",
                             str(out), "--quiet"], stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip
    landed = False
    t0 = time.monotonic()
    try:
        while proc.poll() is None and time.monotonic() - t0 < 300:
            if journal_dir(out).is_dir() and any(journal_dir(out).glob("*.entry")):
                subprocess.run(["chattr", "+i", str(d)], check=True)
                landed = proc.poll() is None
                break
            time.sleep(0.01)
        err = proc.communicate(timeout=300)[1]
    finally:
        subprocess.run(["chattr", "-i", str(d)], check=False)
    print(f"read-only fault landed mid-run: {int(landed)} of 1")
    assert landed, f"the run ended before the fault: {err}"
    assert proc.returncode == 3, err
    errors = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, err
    assert "permission denied" in errors[0] and "make the directory writable" in errors[0], err
    assert "make room" not in errors[0] and "Traceback" not in err, err
    with h5py.File(out) as f:
        assert f.attrs["schema_version"] == RESULTS_SCHEMA_VERSION


@pytest.mark.parametrize("command", ["run", "merge", "phase-diagram", "report", "render",
                                     "accuracy", "sweep"])  # fmt: skip
def test_out_into_a_missing_directory_is_refused_alike_by_every_command(tiny_reference, command):
    """``--out`` follows one rule in every command: its directory must exist
    (phase-diagram and accuracy make only their own output directory)."""
    out = "/nonexistent/dir/x"
    args = {
        "run": ("run", TINY, "--out", out + ".h5"),
        "merge": ("merge", out + ".h5", tiny_reference),
        "phase-diagram": ("phase-diagram", tiny_reference, "--out", out),
        "report": ("report", tiny_reference, "--out", out + ".html"),
        "render": ("render", "--out", out + ".png", "--state", SHIPPED / "Init_1.dat"),
        "accuracy": ("accuracy", "--out", out),
        "sweep": ("sweep", "--direction", "x", "--out", out + ".csv"),
    }[command]
    one_error_line(knitsweep(*args), "/nonexistent/dir does not exist")
