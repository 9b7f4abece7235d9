"""gcdt.paths: atomic writes that respect the umask, write_if_changed, check_writable."""

from __future__ import annotations

import os

import pytest
import torch

from gcdt.checkpoint import save_checkpoint
from gcdt.errors import GcdtError
from gcdt.paths import (
    atomic_write,
    check_writable,
    swap_dirs,
    write_if_changed,
    write_json_atomic,
)
from gcdt.training import _write_log


class _Unpicklable:
    def __reduce__(self):
        raise RuntimeError("cannot pickle this")


@pytest.fixture
def umask():
    """`umask(mask)` sets the process umask; the old one is restored after the test."""
    old = os.umask(0o022)
    os.umask(old)
    try:
        yield os.umask
    finally:
        os.umask(old)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_every_writer_respects_the_umask(umask, make_dataset, tmp_path, mask, mode):
    umask(mask)
    written = [
        write_json_atomic(tmp_path / "json" / "result.json", {"a": 1}),
        make_dataset("reach", lengths=(3, 4)).save(tmp_path / "data" / "d.npz"),
    ]
    run = tmp_path / "run"
    save_checkpoint(run / "checkpoint.pt", {"w": torch.zeros(2)})
    _write_log(run / "train_log.csv", [{"step": 1, "loss": 0.5, "lr": 1e-4, "seconds": 0.1}])
    written += [run / "checkpoint.pt", run / "train_log.csv"]
    assert write_if_changed(tmp_path / "table.md", "| a |\n")
    written.append(tmp_path / "table.md")
    for path in written:
        assert path.stat().st_mode & 0o777 == mode, path
    # Overwriting gives the new file the same mode, and no temp file stays behind.
    write_json_atomic(tmp_path / "json" / "result.json", {"a": 2})
    assert (tmp_path / "json" / "result.json").stat().st_mode & 0o777 == mode
    assert sorted(p.name for p in run.iterdir()) == ["checkpoint.pt", "train_log.csv"]


def test_write_if_changed_leaves_identical_files_alone(tmp_path):
    path = tmp_path / "sub" / "table.md"
    assert write_if_changed(path, "same\n") is True
    os.utime(path, ns=(1_000_000_000, 1_000_000_000))  # an old mtime: any rewrite would show
    assert write_if_changed(path, "same\n") is False
    assert write_if_changed(path, b"same\n") is False
    assert path.stat().st_mtime_ns == 1_000_000_000
    assert write_if_changed(path, "other\n") is True
    assert path.read_text() == "other\n" and path.stat().st_mtime_ns != 1_000_000_000
    assert write_if_changed(path, "other, longer\n") is True  # another size
    assert path.read_text() == "other, longer\n"
    assert [p.name for p in path.parent.iterdir()] == ["table.md"]


@pytest.mark.parametrize("exists", [False, True])
def test_failed_write_leaves_no_temp_file_and_the_old_file(tmp_path, exists):
    path = tmp_path / "result.json"
    if exists:
        path.write_text("old\n")
    with pytest.raises(RuntimeError, match="disk on fire"):
        with atomic_write(path) as f:
            f.write("half a ")
            raise RuntimeError("disk on fire")
    assert [p.name for p in tmp_path.iterdir()] == (["result.json"] if exists else [])
    if exists:
        assert path.read_text() == "old\n"
    with pytest.raises(RuntimeError, match="cannot pickle"):  # fails half-way through torch.save
        save_checkpoint(tmp_path / "c.pt", {"w": torch.zeros(1000), "x": _Unpicklable()})
    assert not (tmp_path / "c.pt").exists()
    assert [p.name for p in tmp_path.iterdir()] == (["result.json"] if exists else [])


def test_atomic_write_text_and_binary(tmp_path):
    with atomic_write(tmp_path / "a" / "b" / "t.csv") as f:
        f.write("x,y\r\nü\n")  # written as given: no newline translation, UTF-8
    assert (tmp_path / "a" / "b" / "t.csv").read_bytes() == "x,y\r\nü\n".encode()
    with atomic_write(tmp_path / "bin", binary=True) as f:
        f.write(b"\x00\x01")
    assert (tmp_path / "bin").read_bytes() == b"\x00\x01"


def test_check_writable_creates_nothing(tmp_path):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "folder").mkdir()
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    check_writable(tmp_path / "new" / "deeper" / "out.npz")  # missing folders are made later
    check_writable(tmp_path / "file.txt")  # replaced atomically
    check_writable(tmp_path / "folder", folder=True)
    check_writable(tmp_path / "new" / "run", folder=True)
    for path, folder, message in [
        (tmp_path / "file.txt" / "out.npz", False, "file.txt is not a folder; choose another"),
        (tmp_path / "file.txt" / "a" / "run", True, "file.txt is not a folder"),
        (tmp_path / "folder", False, "it is a folder, not a file; choose another --out"),
        (tmp_path / "file.txt", True, "it is a file, not a folder"),
    ]:
        with pytest.raises(GcdtError, match=message) as err:
            check_writable(path, folder=folder)
        assert str(err.value).startswith(f"cannot write {path}: ")
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root bypasses file permissions")
def test_check_writable_refuses_read_only_folders_and_files(tmp_path):
    locked, ro_file = tmp_path / "locked", tmp_path / "ro.json"
    locked.mkdir()
    ro_file.write_text("{}")
    locked.chmod(0o555)
    ro_file.chmod(0o444)
    try:
        with pytest.raises(GcdtError, match=r"locked is not writable \(permission denied"):
            check_writable(locked / "sub" / "out.npz")
        with pytest.raises(GcdtError, match=r"locked: it is not writable \(permission denied"):
            check_writable(locked, folder=True)
        with pytest.raises(GcdtError, match=r"ro\.json: it is not writable"):
            check_writable(ro_file)
    finally:
        locked.chmod(0o755)


@pytest.mark.parametrize("exchange", [True, False], ids=["renameat2", "three-renames"])
def test_swap_dirs_exchanges_two_folders_whole(tmp_path, monkeypatch, exchange):
    import gcdt.paths

    if not exchange:  # another OS, or a file system without RENAME_EXCHANGE
        monkeypatch.setattr(gcdt.paths, "_exchange", lambda a, b: False)
    (old := tmp_path / "agent").mkdir()
    (new := tmp_path / ".agent.new").mkdir()
    (old / "model.zip").write_text("old")
    (new / "model.zip").write_text("new")
    (new / "eval.csv").write_text("curve")
    swap_dirs(new, old)
    assert sorted(p.name for p in old.iterdir()) == ["eval.csv", "model.zip"]
    assert (old / "model.zip").read_text() == "new"
    assert [p.name for p in new.iterdir()] == ["model.zip"]
    assert (new / "model.zip").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".agent.new", "agent"]


def test_swap_dirs_puts_the_old_folder_back_when_the_new_cannot_move(tmp_path, monkeypatch):
    import gcdt.paths

    monkeypatch.setattr(gcdt.paths, "_exchange", lambda a, b: False)
    (old := tmp_path / "agent").mkdir()
    (old / "model.zip").write_text("old")
    with pytest.raises(FileNotFoundError):
        swap_dirs(tmp_path / "missing", old)
    assert [p.name for p in tmp_path.iterdir()] == ["agent"]
    assert (old / "model.zip").read_text() == "old"
