"""phloem._files.Transaction: several output files, all or none."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from phloem import _files


def test_a_file_that_appears_before_the_commit_is_not_replaced_and_nothing_is_written(tmp_path):
    tx = _files.Transaction()
    tx.reserve(tmp_path / "a.png")
    tx.reserve(tmp_path / "b.png")
    tx.stage(tmp_path / "a.png", b"new a")
    tx.stage(tmp_path / "b.png", b"new b")
    (tmp_path / "b.png").write_bytes(b"someone else's")  # after the check, before the commit
    with pytest.raises(FileExistsError, match="b.png already exists"):
        tx.commit()
    assert sorted(os.listdir(tmp_path)) == ["b.png"]
    assert (tmp_path / "b.png").read_bytes() == b"someone else's"


def test_leaving_the_block_by_an_exception_removes_the_temporaries_and_only_them(tmp_path):
    (tmp_path / "user.txt").write_text("mine")
    with pytest.raises(RuntimeError), _files.Transaction() as tx:
        tx.stage(tmp_path / "a.png", b"a")
        assert len(os.listdir(tmp_path)) == 2  # user.txt and a hidden temporary
        raise RuntimeError
    assert os.listdir(tmp_path) == ["user.txt"]


def test_a_target_staged_twice_is_refused(tmp_path):
    with _files.Transaction() as tx:
        tx.stage(tmp_path / "a.png", b"a")
        with pytest.raises(ValueError, match="must be different files"):
            tx.stage(tmp_path / "x" / ".." / "a.png", b"b")


def test_temporaries_are_named_with_the_writer_pid(tmp_path):
    with _files.Transaction() as tx:
        tx.stage(tmp_path / "a.png", b"a")
        (name,) = os.listdir(tmp_path)
        assert name.startswith(f".a.png.{os.getpid()}.") and name.endswith(".tmp")


def test_stale_cleanup_leaves_folders_and_links_of_matching_names_alone(tmp_path):
    (tmp_path / ".a.png.1.abcdefgh.tmp").mkdir()  # pid 1 is alive, but it is a folder anyway
    (tmp_path / "target").write_text("x")
    (tmp_path / ".a.png.zzzzzzzz.tmp").symlink_to(tmp_path / "target")
    old = time.time() - 7200
    os.utime(tmp_path / ".a.png.zzzzzzzz.tmp", (old, old), follow_symlinks=False)
    assert _files.remove_stale_temporaries(tmp_path / "a.png") == []
    assert sorted(os.listdir(tmp_path)) == [".a.png.1.abcdefgh.tmp", ".a.png.zzzzzzzz.tmp", "target"]


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="zombies are read from /proc")
def test_a_zombie_writers_temporary_is_stale_and_a_live_writers_is_not(tmp_path):
    # a killed batch's worker that nothing reaps stays a zombie: it answers signal 0 but is dead
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    try:
        deadline = time.monotonic() + 10
        while Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
            assert time.monotonic() < deadline
            time.sleep(0.01)
        (tmp_path / f".a.png.{pid}.abcdefgh.tmp").write_bytes(b"half")
        (tmp_path / f".a.png.{os.getppid()}.abcdefgh.tmp").write_bytes(b"live")
        removed = _files.remove_stale_temporaries(tmp_path / "a.png")
        assert [p.name for p in removed] == [f".a.png.{pid}.abcdefgh.tmp"]
        assert os.listdir(tmp_path) == [f".a.png.{os.getppid()}.abcdefgh.tmp"]
    finally:
        os.waitpid(pid, 0)
