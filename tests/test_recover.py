"""``knitsweep recover`` of files cut short, damaged or holding nothing, and the claims
a run makes about the disk after a fault (integration; docs/crash-safety.md).

A file cut at any length gives back every row whose sealed frame lies wholly before
the cut, bit for bit, without ever hanging (HDF5 loops for ever on a global heap cut
short: the view that recover shows it closes such heaps, and a reader that stalls
anyway is abandoned); recover answers SIGTERM and SIGINT at once and leaves no
temporary file after any kill; a damaged column description is named by every
reader and rebuilt from the rows; a 0-byte or foreign file is kept aside and started
anew only with the job file."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import TINY, assert_same_results, one_error_line
from conftest import run_knitsweep as knitsweep

import knitsweep as ks
from knitsweep import service
from knitsweep.errors import DamagedResultsWarning, InputError, StorageError
from knitsweep.store import salvage as salvage_module
from knitsweep.store import sealed
from knitsweep.store.format import journal_dir
from knitsweep.store.read import iter_entries, read_root

_SMALL = """
import sys
import numpy as np
from pathlib import Path
from knitsweep.service.jobs import load_job
from knitsweep.store.writer import ResultWriter
rng = np.random.default_rng(3)
w = ResultWriter(Path(sys.argv[1]), load_job(sys.argv[2]), {"n_points": 2, "n_sweeps": 4})
for i in range(24):
    n = 20 + 7 * i
    record = {"stress": rng.random(n), "converged": rng.random(n) > 0.5,
              "winner": np.arange(n, dtype=np.int32) % 3,
              "labels": np.array(["a", "b\\u00e9"], dtype=object)}
    meta = {"status": "failed" if i % 7 == 6 else "done", "message": f"m{i}",
            "L_mm": 11.0 + i / 10, "where": {"rank": i}}
    w.add("points" if i % 3 == 0 else "sweeps", f"t{i:02d}", record, meta)
    if i % 5 == 4:
        w.checkpoint()  # in place into the shadow, as a run does
w.close("complete")
"""


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A results file of 24 rows (strings, booleans, integers, failures) written over
    five checkpoints, as a run writes it."""
    out = tmp_path_factory.mktemp("small") / "s.h5"
    proc = subprocess.run([sys.executable, "-c", _SMALL, str(out), str(TINY)],
                          capture_output=True, text=True)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return out


def _rows(path):
    """(kind, task id) -> (meta, arrays) of a file's verified rows, as knitsweep reads them."""
    return {(e.kind, e.task_id): (e.meta, e.record) for e in iter_entries(path, with_data=True)}


def _same(a, b) -> bool:
    (meta_a, rec_a), (meta_b, rec_b) = a, b
    drop = {"file"}
    return ({k: v for k, v in meta_a.items() if k not in drop}
            == {k: v for k, v in meta_b.items() if k not in drop}
            and rec_a.keys() == rec_b.keys()
            and all(rec_a[k].dtype == rec_b[k].dtype and np.array_equal(rec_a[k], rec_b[k])
                    for k in rec_a))  # fmt: skip


_SWEEP = """
import json, os, shutil, sys, time
from pathlib import Path
from knitsweep.errors import InputError
from knitsweep.service.recovery import recover
src, work, step = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
cuts = json.loads(sys.argv[4]) if len(sys.argv) > 4 else None
size = src.stat().st_size
for cut in cuts or range(1, size + 1, step):
    d = work / f"cut{cut}"
    d.mkdir()
    f = d / "x.h5"
    shutil.copy(src, f)
    os.truncate(f, size - cut)
    t = time.monotonic()
    try:
        r = recover(f)
        why = ""
    except InputError as e:
        r, why = None, str(e)
    print(json.dumps({"cut": cut, "keep": size - cut, "dir": str(d), "error": why,
                      "seconds": time.monotonic() - t,
                      "notes": r and r["sources"].get(str(f), "")}), flush=True)
"""


def _sweep(src, tmp_path, step=4096, cuts=None, timeout=600):
    """Recover copies of ``src`` cut short by ``cuts`` bytes (default: 1 B to the
    whole file in ``step``s), in one process (a hang fails by the timeout)."""
    args = [sys.executable, "-c", _SWEEP, str(src), str(tmp_path), str(step)]
    proc = subprocess.run(args + ([json.dumps(cuts)] if cuts else []), capture_output=True,
                          text=True, timeout=timeout)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return [json.loads(line) for line in proc.stdout.splitlines()]


def _check_cuts(src, results):
    """Every row whose frame lies wholly before the cut is back, bit for bit; nothing
    but the rebuilt file and the damaged one is left; no reader stalled."""
    frames = {(e.kind, e.task_id): end for _, end, e in sealed.scan(src)[0]}
    whole = _rows(src)
    assert frames.keys() == whole.keys()
    for r in results:
        d, keep = Path(r["dir"]), r["keep"]
        assert sorted(p.name for p in d.iterdir()) == (["x.h5"] if r["error"] else
                                                        ["x.h5", "x.h5.damaged"]), r  # fmt: skip
        want = {key for key, end in frames.items() if end <= keep}
        if r["error"]:
            assert not want, r
            assert "--job" in r["error"] or "nothing to recover" in r["error"], r
            continue
        assert "no progress" not in r["notes"], r
        got = _rows(d / "x.h5")
        assert want <= got.keys(), (r, sorted(want - got.keys()))
        for key in got:
            assert _same(got[key], whole[key]), (r, key)


def _heap_cuts(path, n=6):
    """Cuts (bytes removed) that end inside a global heap, past its header: where HDF5
    alone loops for ever on the zeros after the cut."""
    data = path.read_bytes()
    cuts, at = [], data.find(b"GCOL")
    while at >= 0 and len(cuts) < n:
        extent = int.from_bytes(data[at + 8 : at + 16], "little")
        cuts.append(len(data) - (at + min(extent - 8, 200)))
        at = data.find(b"GCOL", at + 4)
    return cuts


def test_recover_of_cuts_inside_heaps_keeps_the_rows_before_them(small, tmp_path):
    cuts = [*_heap_cuts(small), 4096, small.stat().st_size // 2]
    _check_cuts(small, _sweep(small, tmp_path, cuts=cuts, timeout=300))


@pytest.mark.slow
def test_recover_of_a_cut_at_any_length_keeps_every_row_before_it(small, tmp_path):
    """Cut lengths from 1 B to the whole file in 4 KiB steps."""
    results = _sweep(small, tmp_path)
    assert len(results) == -(-small.stat().st_size // 4096)
    _check_cuts(small, results)
    print(f"recover of {len(results)} cuts: at most {max(r['seconds'] for r in results):.1f} s")


def test_a_stalled_hdf5_reader_is_abandoned_and_the_frames_still_read(small, tmp_path,
                                                                      monkeypatch):  # fmt: skip
    """Without the view's closed heaps HDF5 loops on a heap cut short: the reader is
    given up after ``STALL_S`` and the rows come from the sealed frames."""
    monkeypatch.setattr(salvage_module, "cut_heaps", lambda path, size: [])
    monkeypatch.setattr(salvage_module, "STALL_S", 1.0)
    data = small.read_bytes()
    frames = sealed.scan(small)[0]
    at = data.find(b"GCOL", frames[len(frames) // 2][0])  # a heap after some whole frames
    while at >= 0 and int.from_bytes(data[at + 8 : at + 16], "little") < 64:
        at = data.find(b"GCOL", at + 4)
    cut = tmp_path / "c.h5"
    cut.write_bytes(data[: at + 40])
    t = time.monotonic()
    found = salvage_module.salvage(cut)
    assert time.monotonic() - t < 30
    assert any("no progress" in s for s in found.check.structure), found.check.structure
    before = {(e.kind, e.task_id) for _, end, e in frames if end <= at + 40}
    assert before and before <= {(e.kind, e.task_id) for e in found.entries}


@pytest.mark.slow
@pytest.mark.parametrize("how", ["SIGTERM", "SIGINT", "SIGKILL"])
def test_recover_answers_signals_and_leaves_no_temporary_file(small, tmp_path, how):
    """A signal at instants through a recover (start-up, reading, rebuilding): SIGTERM
    and SIGINT end it within 2 s with exit 3 and the file as it was; after kill -9 the
    next recover deletes what the killed one left and completes."""
    size = small.stat().st_size
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    ended = []
    delays = (0.0, 0.05, 0.1, 0.2, 0.35, 0.5, 1.0)  # from when knitsweep catches the signals
    for delay in delays:
        d = tmp_path / f"{how}{delay}"
        d.mkdir()
        f = d / "x.h5"
        f.write_bytes(small.read_bytes()[: size - 4096 * 20])
        before = f.read_bytes()
        proc = subprocess.Popen([sys.executable, "-m", "knitsweep", "recover", str(f)], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
        _wait_until_it_catches_sigterm(proc)
        time.sleep(delay)
        sent = time.monotonic()
        proc.send_signal(getattr(signal, how))
        _out, err = proc.communicate(timeout=30)
        took = time.monotonic() - sent
        if proc.returncode == 0:  # it finished first
            assert sorted(p.name for p in d.iterdir()) == ["x.h5", "x.h5.damaged"]
            continue
        ended.append(delay)
        if how == "SIGKILL":
            again = knitsweep("recover", f)
            assert again.returncode == 0, again.stderr
            assert sorted(p.name for p in d.iterdir()) == ["x.h5", "x.h5.damaged"]
            continue
        assert took < 2.0, (delay, took)
        assert proc.returncode == 3 and "interrupted by" in err and "Traceback" not in err, err
        assert sorted(p.name for p in d.iterdir()) == ["x.h5"], (delay, list(d.iterdir()))
        assert f.read_bytes() == before
    assert ended, "every recover finished before its signal"
    print(f"{how}: {len(ended)} of {len(delays)} recovers interrupted, at {ended} s")


def _wait_until_it_catches_sigterm(proc) -> None:
    """Until the process's SIGTERM handler is installed (its caught-signal mask in
    /proc), so that the instants count from then on a fast machine as on a slow one:
    before it, the interpreter still starts and the promise is not yet made."""
    bit = 1 << (signal.SIGTERM - 1)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and proc.poll() is None:
        status = Path(f"/proc/{proc.pid}/status").read_text()
        caught = next(line for line in status.splitlines() if line.startswith("SigCgt:"))
        if int(caught.split()[1], 16) & bit:
            return
        time.sleep(0.002)
    raise AssertionError("recover never installed its SIGTERM handler")


# ---- a damaged column description ------------------------------------------------------


@pytest.fixture
def bad_columns(tiny_reference, tmp_path):
    """The tiny results with one byte of /sweeps' ``columns`` JSON changed: it no
    longer parses."""
    out = tmp_path / "c.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "a") as f:
        text = f["sweeps"].attrs["columns"]
        f["sweeps"].attrs["columns"] = text[:10] + "#" + text[11:]
    return out


def test_a_damaged_column_description_is_named_by_every_reader(bad_columns, tmp_path):
    out, named = bad_columns, "damaged /sweeps: column description unreadable"
    shown = knitsweep("status", out)
    assert shown.returncode == 0 and named in shown.stdout and "Traceback" not in shown.stderr
    pd = knitsweep("phase-diagram", out, "--out", tmp_path / "pd", "--no-figures")
    assert pd.returncode == 0 and named in pd.stdout and "Traceback" not in pd.stderr
    merged = knitsweep("merge", tmp_path / "m.h5", out)
    assert merged.returncode == 0 and named in merged.stderr, merged.stderr
    assert "2 points, 0 sweeps" in merged.stdout
    one_error_line(knitsweep("run", TINY, "--out", out), named)
    with pytest.warns(DamagedResultsWarning, match=named):
        res = ks.load(out)
    assert len(res.points) == 2 and res.sweeps.empty


def test_recover_rebuilds_a_damaged_column_description_from_the_rows(bad_columns, tiny_reference,
                                                                      monkeypatch):  # fmt: skip
    """From the rows' entries and the columns found (the sealed frames left out, as in a
    file written before them): every row back, the intact /points rows kept."""
    monkeypatch.setattr(sealed, "scan", lambda path: ([], None))
    r = service.recover(bad_columns)
    assert r["recovered"] == 6 and r["from"]["file"] == 6 and r["damaged_lost"] == []
    assert service.status(bad_columns)["damaged"] == []
    assert_same_results(tiny_reference, bad_columns)


# ---- files that hold nothing -----------------------------------------------------------


@pytest.mark.parametrize("content", [b"", b"a,b\n1,2\n"], ids=["0 bytes", "a CSV"])
def test_recover_of_a_file_that_holds_nothing_starts_it_anew_with_the_job(tiny_reference,
                                                                          tmp_path, content):  # fmt: skip
    out = tmp_path / "e.h5"
    out.write_bytes(content)
    what = "empty (0 bytes)" if not content else "not an HDF5 file"
    proc = knitsweep("recover", out)
    one_error_line(proc, what)
    assert f"knitsweep recover {out} --job JOB.toml" in proc.stderr
    assert out.read_bytes() == content
    refused = knitsweep("run", TINY, "--out", out, "--quiet")
    if content:  # someone's file: never replaced by a run
        one_error_line(refused, f"knitsweep recover {out} --job")
        assert out.read_bytes() == content
    else:  # 0 bytes hold nothing: the run keeps it aside and starts the file
        assert refused.returncode == 0, refused.stderr
        assert "kept as" in refused.stderr
        assert_same_results(tiny_reference, out)
        out.write_bytes(content)
    done = knitsweep("recover", out, "--job", TINY)
    assert done.returncode == 0, done.stderr
    kept = sorted(tmp_path.glob("e.h5.damaged*"))[-1]
    assert kept.read_bytes() == content and f"kept as {kept}" in done.stdout
    assert read_root(out)["run_status"] == "recovered"
    run = knitsweep("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 0, run.stderr
    assert_same_results(tiny_reference, out)


# ---- what a failed run says is on disk --------------------------------------------------


def test_the_last_line_after_a_write_error_counts_what_is_on_disk(tiny_reference, tmp_path):
    """The journal deleted under a run: the next commit fails; the last line says how
    many tasks the file and journal hold, not how many results arrived."""
    job = tmp_path / "slow_checkpoints.toml"
    job.write_text(TINY.read_text().replace("checkpoint_s = 0.5", "checkpoint_s = 3600"))
    out = tmp_path / "r.h5"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "knitsweep", "run", str(job), "--out", str(out),
                             "--quiet"], stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < 300:
        if list(journal_dir(out).glob("batch-*.entry")):
            for _ in range(50):
                try:
                    shutil.rmtree(journal_dir(out))
                    break
                except OSError:
                    continue
            break
        time.sleep(0.005)
    err = proc.communicate(timeout=300)[1]
    assert proc.returncode == 3, err
    (line,) = [x for x in err.splitlines() if x.startswith("error: ")]
    said = int(line.split("; ")[1].split(" of ")[0])
    on_disk = len({(e.kind, e.task_id) for e in iter_entries(out)})
    assert said == on_disk, (line, on_disk)
    again = knitsweep("run", job, "--out", out, "--quiet")
    assert again.returncode == 0, again.stderr
    assert_same_results(tiny_reference, out)


def test_a_link_swapped_in_for_the_shadow_is_named_and_never_renamed_in(tmp_path, monkeypatch):
    from knitsweep.service.jobs import JobSpec
    from knitsweep.store import writer as writer_module

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "c.h5"
    writer = writer_module.ResultWriter(out, JobSpec(schema_version=1, name="c",
                                                     grid={"L_mm": 11.6}))  # fmt: skip
    writer.add("sweeps", "s0", {"stress": np.arange(3.0)}, {"status": "done"})
    writer.checkpoint()
    real = writer_module._fsync_file

    def swapped(path):  # the shadow, written, is swapped for a link before it is published
        real(path)
        if path.name == ".c.h5.shadow":
            path.unlink()
            path.symlink_to(victim)

    monkeypatch.setattr(writer_module, "_fsync_file", swapped)
    writer.add("sweeps", "s1", {"stress": np.arange(3.0)}, {"status": "done"})
    with pytest.raises(StorageError) as caught:
        writer.checkpoint()
    message = str(caught.value.strerror)
    assert message.startswith(f"cannot write {tmp_path / '.c.h5.shadow'}: it is a symbolic link")
    assert not out.is_symlink() and victim.read_text() == "precious\n"
    monkeypatch.setattr(writer_module, "_fsync_file", real)
    writer.close("complete")
    assert sorted(e.task_id for e in iter_entries(out)) == ["s0", "s1"]
    assert victim.read_text() == "precious\n"


def test_load_warns_with_the_count_and_the_first_ids(tiny_reference, tmp_path):
    out = tmp_path / "w.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "a") as f:
        tids = sorted(f["sweeps/task"].asstr())
        f["sweeps/stress"][:, 1] += 1.0  # every sweep's second value
    with pytest.warns(DamagedResultsWarning) as caught:
        res = ks.load(out)
    (w,) = caught
    assert f"{len(tids)} damaged task(s) skipped" in str(w.message)
    assert all(f"sweep {t}" in str(w.message) for t in tids)
    assert w.filename == __file__  # the caller's line
    damaged = res.problems.query("status == 'damaged'")
    assert sorted(damaged["task_id"]) == tids and set(damaged["file"]) == {str(out)}
    with pytest.raises(InputError):
        ks.load(tmp_path / "missing.h5")
