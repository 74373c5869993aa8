"""Big requests on the command line: refused at once in one line (exit 2), under an address-space cap."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import branching, io

CAP = 4 * 2**30  # RLIMIT_AS: without the budget these runs abort ("memory allocation of ... failed") or die


def _cap() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def phloem_capped(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(Path(phloem.__file__).resolve().parents[1]), "PHLOEM_NUM_THREADS": "2"}
    return subprocess.run(
        [sys.executable, "-m", "phloem", *args, "-q"], cwd=cwd, env=env, preexec_fn=_cap,
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip


def _refused(p: subprocess.CompletedProcess[str], flag: str = "--size") -> str:
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert "memory allocation" not in p.stderr and "Traceback" not in p.stderr
    line = lines[0]
    assert f"error: {flag}: " in line and "needs about" in line and "over the memory limit of" in line
    assert "--max-memory" in line and "max_memory" not in line
    return line


@pytest.fixture()
def files(tmp_path, bark):
    io.write_image(tmp_path / "tex.png", bark[:96, :96])
    img = np.full((48, 64), 0.8, np.float32)
    img[20:26, :] = 0.1
    io.write_image(tmp_path / "river.png", img)
    sk = branching.Skeleton([branching.Branch([[2, 22.5], [61, 22.5]], 3.0)], (48, 64))
    (tmp_path / "river.json").write_text(json.dumps(sk.to_dict()))
    big = branching.Skeleton([branching.Branch([[2, 22.5], [61, 22.5]], 3.0)], (100_000, 100_000))
    (tmp_path / "big.json").write_text(json.dumps(big.to_dict()))
    trees = tmp_path / "trees"
    trees.mkdir()
    t = np.zeros((120, 80, 4), np.float32)
    t[..., 1] = 0.5
    t[10:70, 10:70, 3] = 1.0
    t[70:110, 35:45, 3] = 1.0
    for i in range(3):
        io.write_image(trees / f"t{i}.png", t)
    return tmp_path


@pytest.mark.parametrize(
    "args",
    [
        ["bark", "tex.png", "--size", "100000x100000", "--out", "o.png"],
        ["demo", "--size", "100000x100000", "--out", "o.png"],
        ["synthesize", "tex.png", "--size", "16000", "--out", "o.png"],  # 16000² is under --max-pixels
        ["quilt", "tex.png", "--size", "16000", "--out", "o.png"],
        ["branching", "run", "river.png", "--skeleton", "river.json", "--size", "100000x100000", "--out", "o.png"],
        ["branching", "grow", "river.json", "--size", "100000x100000", "--out", "new.json"],
        ["trees", "trees", "--size", "10000", "--n-variations", "1", "--out-dir", "out"],
    ],
    ids=lambda a: " ".join(a[:2]),
)
def test_a_huge_size_is_refused_in_one_line(files, args):
    line = _refused(phloem_capped(*args, cwd=files))
    assert "GiB" in line or "TiB" in line
    assert not (files / "o.png").exists()


def test_branching_render_of_a_huge_target_is_refused(files):
    line = _refused(phloem_capped("branching", "render", "river.png", "river.json", "big.json", "--out", "o.png",
                                  cwd=files), flag="NEW.json")  # fmt: skip
    assert "100000×100000" in line


def test_max_memory_too_small_refuses_and_enough_runs(files):
    line = _refused(phloem_capped("bark", "tex.png", "--size", "64", "--out", "o.png", "--max-memory", "1M", cwd=files))
    assert "over the memory limit of 1 MiB" in line
    p = phloem_capped("bark", "tex.png", "--size", "64", "--out", "o.png", "--max-memory", "2G", cwd=files)
    assert p.returncode == 0, p.stderr
    assert (files / "o.png").exists()
    assert "max_memory" not in json.loads((files / "o.png.json").read_text())["parameters"]


def test_patch_nnf_max_memory(files):
    _refused(phloem_capped("nnf", "tex.png", "tex.png", "--out", "f.npz", "--max-memory", "1000", cwd=files),
             flag="TARGET")  # fmt: skip


@pytest.mark.parametrize("bad", ["0", "-1", "abc", "nan", "8X"])
def test_bad_max_memory_is_refused(files, bad):
    p = phloem_capped("bark", "tex.png", "--size", "64", "--out", "o.png", f"--max-memory={bad}", cwd=files)
    assert p.returncode == 2
    assert "--max-memory: " in p.stderr and "expected a positive number of bytes" in p.stderr
    assert not (files / "o.png").exists()
