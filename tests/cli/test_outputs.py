"""Every output of a command, or none: faults and Ctrl-C after the first file, write errors in one
line, every name checked before computing, stale temporaries of a killed run, no empty --out-dir."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import io
from phloem.cli import main

BRICK = Path(phloem.__file__).parent / "data" / "brick.png"
ENV = {**os.environ, "PYTHONPATH": str(Path(phloem.__file__).parents[1])}


def _phloem(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phloem", *argv], env=ENV, capture_output=True, text=True, timeout=timeout
    )


def _one_line(err: str, command: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"phloem {command}: "), err
    assert "Traceback" not in err
    return lines[0]


def _tree_png(path: Path, crown: int, trunk: int) -> None:
    img = np.zeros((120, 100, 4), np.float32)
    yy, xx = np.mgrid[:120, :100]
    img[(yy - 45) ** 2 + (xx - 50) ** 2 < crown**2] = (0.1, 0.6, 0.2, 1.0)
    img[70:118, 50 - trunk : 50 + trunk] = (0.4, 0.3, 0.1, 1.0)
    io.write_image(path, img)


@pytest.fixture()
def library(tmp_path: Path) -> Path:
    lib = tmp_path / "lib"
    lib.mkdir()
    for i, (c, t) in enumerate([(30, 4), (40, 6), (25, 3)]):
        _tree_png(lib / f"t{i}.png", c, t)
    return lib


def _commands(tmp_path: Path, library: Path) -> dict[str, list[str]]:
    """Multi-file commands, each writing into tmp_path/o (files) or tmp_path/o/trees (trees)."""
    o = tmp_path / "o"
    return {
        "demo": ["demo", "--size", "32", "--out", str(o / "d.png")],
        "bark": ["bark", "--size", "32", "--out", str(o / "b.png"), "--keep-intermediates",
                 "--cylinder-preview", str(o / "cyl.png")],
        "branching run": ["branching", "run", str(BRICK), "--size", "48", "--out", str(o / "r.png"),
                          "--fragment-map", str(o / "frag.png")],
        "trees": ["trees", str(library), "--n-variations", "2", "--size", "128", "--out-dir", str(o / "trees"),
                  "--sheet", str(o / "sheet.png")],
    }  # fmt: skip


def _fail_at(monkeypatch: pytest.MonkeyPatch, name: str, n: int, exc: BaseException) -> list[int]:
    """Make the ``n``-th call of ``os.<name>`` raise ``exc``; returns the call counter."""
    real = getattr(os, name)
    calls = [0]

    def fake(*a: object, **k: object) -> object:
        if name == "write" and a and a[0] in (1, 2):  # the terminal, not a file
            return real(*a, **k)
        calls[0] += 1
        if calls[0] == n:
            raise exc
        return real(*a, **k)

    monkeypatch.setattr(os, name, fake)
    return calls


FAULTS = {
    "disk full at the second rename": ("link", 2, OSError(errno.ENOSPC, "No space left on device")),
    "disk full at the second write": ("write", 2, OSError(errno.ENOSPC, "No space left on device")),
    "Ctrl-C at the second rename": ("link", 2, KeyboardInterrupt()),
}


@pytest.mark.parametrize("fault", list(FAULTS))
@pytest.mark.parametrize("command", ["demo", "bark", "branching run", "trees"])
def test_a_fault_after_the_first_file_leaves_nothing(tmp_path, library, capsys, monkeypatch, command, fault):
    (tmp_path / "o").mkdir()
    argv = [*_commands(tmp_path, library)[command], "-q"]
    name, n, exc = FAULTS[fault]
    calls = _fail_at(monkeypatch, name, n, exc)
    status = main(argv)
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert calls[0] >= n, "the fault was not reached"
    if isinstance(exc, KeyboardInterrupt):
        assert status == 130 and _one_line(err, command.split()[0]).endswith("interrupted; nothing was written")
    else:
        assert status == 2 and "No space left on device" in _one_line(err, command)
        assert "cannot write" in err and str(tmp_path / "o") in err  # names the file
    assert sorted(os.listdir(tmp_path / "o")) == []  # no file, no temporary, no --out-dir
    # and a rerun without --force is not refused
    assert main(argv) == 0, capsys.readouterr().err
    assert len([f for f in (tmp_path / "o").rglob("*") if f.is_file()]) >= 2


def test_with_force_a_failed_commit_puts_the_old_files_back(tmp_path, library, capsys, monkeypatch):
    argv = [*_commands(tmp_path, library)["bark"], "-q"]
    (tmp_path / "o").mkdir()
    assert main(argv) == 0
    before = {p.name: p.read_bytes() for p in (tmp_path / "o").iterdir()}
    _fail_at(monkeypatch, "replace", 3, OSError(errno.ENOSPC, "No space left on device"))
    assert main([*argv, "--force", "--seed", "5"]) == 2
    monkeypatch.undo()
    assert "No space left on device" in _one_line(capsys.readouterr().err, "bark")
    assert {p.name: p.read_bytes() for p in (tmp_path / "o").iterdir()} == before


def test_an_image_is_never_left_without_its_sidecar(tmp_path, monkeypatch):
    # phloem.io.write_result on a disk that fills up after the image
    _fail_at(monkeypatch, "link", 2, OSError(errno.ENOSPC, "No space left on device"))
    with pytest.raises(OSError, match="No space left on device"):
        io.write_result(tmp_path / "o.png", np.zeros((4, 4), np.float32), command="t", parameters={}, seed=0)
    monkeypatch.undo()
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(("folder", "reason"), [("/proc", "it takes no new files"), ("/sys", "Permission denied")])
def test_an_unwritable_folder_is_one_line_before_computing(folder, reason):
    # (We run as root, where chmod does not stop writes: /proc and /sys refuse new files to root too.)
    r = _phloem("demo", "--size", "32", "--out", f"{folder}/o.png", "-q")
    assert r.returncode == 2
    assert _one_line(r.stderr, "demo") == f"phloem demo: error: --out: cannot write into folder {folder}: {reason}"


def test_a_read_only_file_system_is_found_before_computing(tmp_path, capsys, monkeypatch):
    real_open = os.open

    def read_only(path: object, *a: object, **k: object) -> int:
        if str(path).startswith(str(tmp_path)) and a and isinstance(a[0], int) and a[0] & os.O_CREAT:
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_open(path, *a, **k)  # type: ignore[arg-type]

    def never(*a: object, **k: object) -> None:
        raise AssertionError("computed before the output was checked")

    monkeypatch.setattr(os, "open", read_only)
    monkeypatch.setattr(phloem.bark, "generate", never)
    assert main(["demo", "--size", "32", "--out", str(tmp_path / "o.png"), "-q"]) == 2
    line = _one_line(capsys.readouterr().err, "demo")
    assert line == f"phloem demo: error: --out: cannot write into folder {tmp_path}: Read-only file system"


def test_force_onto_a_folder_is_refused_up_front(tmp_path):
    (tmp_path / "d.png").mkdir()
    r = _phloem("demo", "--size", "64", "--out", str(tmp_path / "d.png"), "--force", "-q")
    assert r.returncode == 2, r.stderr
    assert _one_line(r.stderr, "demo").endswith(f"--out: {tmp_path / 'd.png'} is a folder; expected a file name")
    assert sorted(os.listdir(tmp_path)) == ["d.png"] and os.listdir(tmp_path / "d.png") == []


@pytest.mark.parametrize(
    ("command", "argv"),
    [
        ("branching run", ["branching", "run", str(BRICK), "--out", "{o}/r.png", "--fragment-map", "{o}/r_histograms.png"]),
        ("branching run", ["branching", "run", str(BRICK), "--out", "{o}/r.png", "--fragment-map", "{o}/r.png"]),
        ("branching run", ["branching", "run", str(BRICK), "--out", "{o}/r.png", "--fragment-map", "{o}/../o/r.png"]),
        ("branching grow", ["branching", "grow", "{skel}", "--out", "{o}/n.json", "--preview", "{o}/p.png",
                            "--histograms", "{o}/p.png"]),
        ("bark", ["bark", "--size", "32", "--out", "{o}/b.png", "--keep-intermediates",
                  "--cylinder-preview", "{o}/b_labels_out.png"]),
        ("trees", ["trees", "{lib}", "--n-variations", "2", "--out-dir", "{o}", "--sheet", "{o}/tree_0001.png"]),
    ],
)  # fmt: skip
def test_two_outputs_of_one_name_are_refused_before_computing(tmp_path, library, capsys, monkeypatch, command, argv):
    o = tmp_path / "o"
    o.mkdir()

    def never(*a: object, **k: object) -> None:
        raise AssertionError("computed before the output names were checked")

    skel = tmp_path / "s.json"
    skel.write_text("{}")  # never read: the names are checked first
    for mod, fn in (
        (phloem.branching, "synthesize"),
        (phloem.branching.Skeleton, "load"),
        (phloem.bark, "generate"),
        (phloem.trees.Library, "load"),
    ):
        monkeypatch.setattr(mod, fn, never)
    status = main([a.format(o=o, lib=library, skel=skel) for a in argv] + ["-q"])
    assert status == 2
    assert "must be different files" in _one_line(capsys.readouterr().err, command)
    assert os.listdir(o) == []


def test_a_failed_trees_run_leaves_no_empty_out_dir(tmp_path):
    r = _phloem("trees", str(tmp_path / "missing"), "--n-variations", "1", "--out-dir", str(tmp_path / "new" / "dir"))
    assert r.returncode == 2
    _one_line(r.stderr, "trees")
    assert os.listdir(tmp_path) == []


_KILLED_IN_COMMIT = """
import os, signal, sys
import phloem.cli
real = os.link
def link(src, dst, *a, **k):
    real(src, dst, *a, **k)
    os.kill(os.getpid(), signal.SIGKILL)  # killed after the first file took its name
os.link = link
phloem.cli.main(sys.argv[1:])
"""


def test_stale_temporaries_of_a_killed_run_are_removed_and_nothing_else(tmp_path):
    out = tmp_path / "o.png"
    argv = ["bark", "--size", "32", "--out", str(out), "--keep-intermediates", "-q"]
    r = subprocess.run(
        [sys.executable, "-c", _KILLED_IN_COMMIT, *argv], env=ENV, capture_output=True, text=True, timeout=120
    )
    assert r.returncode == -signal.SIGKILL, r.stderr
    left = sorted(p for p in os.listdir(tmp_path) if p.endswith(".tmp"))
    assert len(left) == 4, left  # the staged o.png, o.png.json and two label maps
    out.unlink()  # the one file that took its name before the kill
    # Not ours, or not stale: a user's file, a temporary of a writer that is alive (this test),
    # and one of the older pid-less form that is fresh. An old pid-less one is stale.
    keep = [f".o.png.{os.getpid()}.abcd1234.tmp", ".o.png.mine.tmp", ".o.png.abcd1234.tmp", "o.png.1.abcd1234.tmp"]
    for name in keep:
        (tmp_path / name).write_text("keep")
    old = tmp_path / ".o.png.zz99yy88.tmp"
    old.write_text("stale")
    os.utime(old, (time.time() - 3600, time.time() - 3600))
    r = _phloem(*argv)
    assert r.returncode == 0, r.stderr
    names = sorted(os.listdir(tmp_path))
    assert names == sorted(["o.png", "o.png.json", "o_labels_in.png", "o_labels_out.png", *keep]), names
