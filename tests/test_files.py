"""Atomic writes (iloci.data.files.write_atomic): content, crash safety, permissions."""

from __future__ import annotations

import json
import math
import os
import stat

import pytest

from iloci.data.files import write_atomic, write_text_atomic
from iloci.evaluation.report import write_json_atomic

posix_only = pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")


@pytest.fixture
def umask():
    """Umask 0o022 for one test (``umask(m)`` sets another); the old one is restored."""
    old = os.umask(0o022)
    try:
        yield os.umask
    finally:
        os.umask(old)


def mode_of(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_write_atomic_writes_the_content(tmp_path):
    path = tmp_path / "out.bin"
    assert write_atomic(path, lambda fh: fh.write(b"\x00abc\n")) == path
    assert path.read_bytes() == b"\x00abc\n"
    write_atomic(str(path), lambda fh: (fh.write(b"new"), fh.write(b" content")))
    assert path.read_bytes() == b"new content"
    assert write_text_atomic(tmp_path / "t.md", "± µm\n").read_bytes() == "± µm\n".encode()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin", "t.md"]


@pytest.mark.parametrize("error", [RuntimeError("writer failed"), KeyboardInterrupt()])
def test_an_exception_in_the_writer_leaves_the_old_file(tmp_path, error):
    path = tmp_path / "m.npz"
    path.write_bytes(b"old content \x00\xff")
    before = path.read_bytes()

    def writer(fh):
        fh.write(b"half of the new")
        raise error

    with pytest.raises(type(error)):
        write_atomic(path, writer)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]  # no temporary file left


def test_a_failed_rename_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "f.json"
    path.write_text("{}")

    def crash(src, dst):
        raise OSError("simulated failure of the rename")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="simulated"):
        write_text_atomic(path, '{"new": 1}')
    monkeypatch.undo()
    assert path.read_text() == "{}"
    assert [p.name for p in tmp_path.iterdir()] == ["f.json"]


def test_a_missing_directory_is_created_only_when_asked(tmp_path):
    path = tmp_path / "a" / "b" / "f.txt"
    with pytest.raises(FileNotFoundError):
        write_text_atomic(path, "x")
    assert not (tmp_path / "a").exists()
    write_text_atomic(path, "x", mkdir=True)
    assert path.read_text() == "x"


@pytest.mark.parametrize("hard_links", [True, False])
def test_overwrite_false_writes_a_new_file_and_never_replaces_one(tmp_path, monkeypatch,
                                                                  hard_links):
    if not hard_links:  # a file system without them: check, then rename
        def no_link(src, dst):
            raise PermissionError(1, "Operation not permitted")

        monkeypatch.setattr(os, "link", no_link)
    path = tmp_path / "picture.png"
    assert write_atomic(path, lambda fh: fh.write(b"first"), overwrite=False) == path
    assert path.read_bytes() == b"first"
    with pytest.raises(FileExistsError) as info:
        write_atomic(path, lambda fh: fh.write(b"second"), overwrite=False)
    assert info.value.filename == str(path)
    assert path.read_bytes() == b"first"
    assert [p.name for p in tmp_path.iterdir()] == ["picture.png"]  # no temporary file left


@posix_only
def test_overwrite_false_gives_a_new_file_the_umask_mode(tmp_path, umask):
    umask(0o077)
    path = write_atomic(tmp_path / "new.bin", lambda fh: fh.write(b"x"), overwrite=False)
    assert mode_of(path) == 0o600


@posix_only
@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into read-only directories")
def test_an_unwritable_directory_raises_oserror(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    (d / "f.txt").write_text("old")
    d.chmod(0o555)
    try:
        with pytest.raises(PermissionError):
            write_text_atomic(d / "f.txt", "new")
        assert (d / "f.txt").read_text() == "old"
        assert [p.name for p in d.iterdir()] == ["f.txt"]
    finally:
        d.chmod(0o755)


@posix_only
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_a_new_file_gets_the_umask_mode(tmp_path, umask, mask):
    umask(mask)
    path = write_atomic(tmp_path / "new.bin", lambda fh: fh.write(b"x"))
    assert mode_of(path) == 0o666 & ~mask


@posix_only
def test_replacing_a_file_keeps_its_mode(tmp_path, umask):
    path = tmp_path / "private.npz"
    path.write_bytes(b"old")
    path.chmod(0o600)
    write_atomic(path, lambda fh: fh.write(b"new"))
    assert path.read_bytes() == b"new" and mode_of(path) == 0o600
    path.chmod(0o664)
    write_atomic(path, lambda fh: fh.write(b"newer"))
    assert mode_of(path) == 0o664


def test_write_json_atomic_delegates(tmp_path):
    path = write_json_atomic(tmp_path / "sub" / "r.json", {"a": [1, 2.5], "b": math.nan})
    text = path.read_text()
    assert text.endswith("\n") and '"a": [\n' in text  # indented
    back = json.loads(text)
    assert back["a"] == [1, 2.5] and math.isnan(back["b"])
    assert [p.name for p in path.parent.iterdir()] == ["r.json"]


@posix_only
@pytest.mark.parametrize("overwrite", [True, False])
def test_the_rename_is_made_durable(tmp_path, monkeypatch, overwrite):
    # After the commit the directory itself is fsync'ed: without it a power cut
    # can lose the new name although the file's data were synced.
    synced = []
    real_fsync = os.fsync

    def spy(fd):
        st = os.fstat(fd)
        synced.append(("dir" if stat.S_ISDIR(st.st_mode) else "file", st.st_ino))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    path = write_atomic(tmp_path / "m.npz", lambda fh: fh.write(b"x"), overwrite=overwrite)
    assert synced[0][0] == "file" and synced[-1] == ("dir", tmp_path.stat().st_ino)
    assert path.read_bytes() == b"x"


@posix_only
def test_a_directory_that_cannot_be_synced_is_no_error(tmp_path, monkeypatch):
    real_fsync = os.fsync

    def no_dir_sync(fd):
        if stat.S_ISDIR(os.fstat(fd).st_mode):
            raise OSError(22, "Invalid argument")   # e.g. some network file systems
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", no_dir_sync)
    assert write_atomic(tmp_path / "a.bin", lambda fh: fh.write(b"y")).read_bytes() == b"y"
