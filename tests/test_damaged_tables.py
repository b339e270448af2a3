"""Byte flips of the fault campaign (docs/fault-campaign.md) that once made a command
print a traceback or a message that did not say how to recover: a table's link to a
column renamed (h5py's KeyError on resume), a row's entry left without UTF-8
(UnicodeDecodeError in ``status``), and a column's chunk index spoilt (a write error
"fix the cause" that rerunning does not fix). Each now reads the intact part, or
refuses with one ``error:`` line naming ``knitsweep recover F.h5``, and recovery
plus resume give the uninterrupted run's results."""

from __future__ import annotations

import re
import shutil

import h5py
import pytest
from conftest import TINY, assert_same_results
from test_integrity import flip, knitsweep_cli

from knitsweep.store.checksum import FileCheck
from knitsweep.store.read import iter_entries


def xor(path, offset: int, n: int) -> None:
    """The campaign's flip: ``n`` bytes at ``offset`` XOR 0xA5."""
    flip(path, offset, n, mask=0xA5)


def assert_refused(out) -> None:
    """``run`` refuses ``out`` (unchanged) with one error line naming recover."""
    run = knitsweep_cli("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    errors = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and f"`knitsweep recover {out}`" in errors[0], run.stderr
    assert "damaged /sweeps" in errors[0] or "damaged /points" in errors[0], errors


def assert_recovers(out, tiny_reference) -> None:
    """``status``, ``recover`` and the resume succeed and give the reference."""
    for command in (("status", out), ("recover", out, "--job", TINY),
                    ("run", TINY, "--out", out, "--quiet")):  # fmt: skip
        r = knitsweep_cli(*command)
        assert r.returncode == 0 and "Traceback" not in r.stderr, (command, r.stderr)
    assert_same_results(tiny_reference, out)


def test_a_column_whose_link_name_is_flipped_is_refused_naming_recover(tiny_reference,
                                                                       tmp_path):  # fmt: skip
    out = tmp_path / "f.h5"
    shutil.copy(tiny_reference, out)
    data = out.read_bytes()
    # the link names of a group's members lie NUL-padded in its local heap
    names = [m.start() + 1 for m in re.finditer(rb"\0merged_at\0", data)]
    assert names
    for at in names:
        xor(out, at, 8)
    assert_refused(out)
    check = FileCheck()
    list(iter_entries(out, check=check))
    assert any("column merged_at unreadable (KeyError)" in s for s in check.structure)
    assert_recovers(out, tiny_reference)


def test_an_entry_left_without_utf8_is_a_damaged_row(tiny_reference, tmp_path):
    out = tmp_path / "f.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "r") as f:
        tid = f["points/task"].asstr()[0]
        entry = f["points/entry"][0]
    data = out.read_bytes()
    at = [m.start() for m in re.finditer(re.escape(entry), data)]
    assert at
    for start in at:  # one byte of the entry (every stored copy): 0xA5 ^ ASCII is no UTF-8
        xor(out, start + len(entry) // 2, 1)
    status = knitsweep_cli("status", out)
    assert status.returncode == 0 and "Traceback" not in status.stderr, status.stderr
    assert f"damaged point {tid}" in status.stdout and "knitsweep recover" in status.stdout
    check = FileCheck()
    assert tid not in {e.task_id for e in iter_entries(out, check=check)}
    assert [(k, t) for k, t, _ in check.damaged] == [("points", tid)]
    assert "UnicodeDecodeError" in check.damaged[0][2] and not check.structure
    run = knitsweep_cli("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 0 and "(5 already finished)" in run.stderr, run.stderr
    assert_same_results(tiny_reference, out)


def chunk_index_node(path, name: str) -> int:
    """The file offset of the v1 B-tree node ("TREE", type 1: chunks) whose first child
    is chunk 0 of dataset ``name``."""
    with h5py.File(path, "r") as f:
        ds = f[name]
        first, rank = ds.id.get_chunk_info(0).byte_offset, ds.ndim
    data = path.read_bytes()
    child = 24 + 8 + 8 * (rank + 1)  # header, then key 0 (size, mask, offsets), then child 0
    nodes = [m.start() for m in re.finditer(rb"TREE\x01\x00", data)
             if int.from_bytes(data[m.start() + child : m.start() + child + 8], "little")
             == first]  # fmt: skip
    assert len(nodes) == 1, nodes
    return nodes[0]


@pytest.mark.parametrize("column", ["direction", "merged_at"])
def test_a_spoilt_chunk_index_is_refused_naming_recover(tiny_reference, tmp_path, column):
    out = tmp_path / "f.h5"
    shutil.copy(tiny_reference, out)
    xor(out, chunk_index_node(out, f"sweeps/{column}"), 64)
    assert_refused(out)
    check = FileCheck()
    kept = list(iter_entries(out, check=check))
    assert f"/sweeps: column {column} unreadable (OSError)" in check.structure
    assert len([e for e in kept if e.kind == "points"]) == 2  # the other table reads
    assert_recovers(out, tiny_reference)


def test_a_write_that_meets_damaged_metadata_names_recover(tiny_reference, tmp_path,
                                                           monkeypatch, capsys):  # fmt: skip
    """Damage that reading did not see but a write meets (HDF5's "wrong B-tree
    signature" while a recomputed row is written) names ``knitsweep recover``, not
    "fix the cause" (rerunning alone meets it again)."""
    from knitsweep import service
    from knitsweep.store import writer

    out = tmp_path / "f.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "r+") as f:  # one row's entry changed: that sweep is recomputed
        f["sweeps/entry"][0] = f["sweeps/entry"][0].decode().replace("{", "{ ", 1)

    def put(*args):
        raise RuntimeError("Can't synchronously write data (wrong B-tree signature)")

    monkeypatch.setattr(writer, "_put", put)
    summary = service.run(TINY, out, executor="serial", show_progress=False)
    assert summary.interrupted and "the file is damaged" in summary.storage_error
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and f"run `knitsweep recover {out}`" in errors[0], errors
    assert "fix the cause" not in errors[0]


def test_a_string_column_left_without_utf8_is_a_damaged_row(tiny_reference, tmp_path):
    out = tmp_path / "f.h5"
    shutil.copy(tiny_reference, out)
    with h5py.File(out, "r") as f:
        tid, message = f["sweeps/task"].asstr()[0], f["sweeps/message"][0]
    data = out.read_bytes()
    # the column's cell in its heap (not the copy inside the entry's JSON, in quotes)
    at = [m.start() for m in re.finditer(re.escape(message) + rb"\0", data)
          if data[m.start() - 1 : m.start()] != b'"']  # fmt: skip
    assert len(at) == 1
    xor(out, at[0] + len(message) // 2, 1)
    status = knitsweep_cli("status", out)
    assert status.returncode == 0 and "Traceback" not in status.stderr, status.stderr
    assert f"damaged sweep {tid}: its message column disagrees" in status.stdout
    run = knitsweep_cli("run", TINY, "--out", out, "--quiet")
    assert run.returncode == 0 and "(5 already finished)" in run.stderr, run.stderr
    assert_same_results(tiny_reference, out)
