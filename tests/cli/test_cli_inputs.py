"""Bad JSON inputs on the command line (issue 16): skeleton files with far-away coordinates,
deep nesting, binary files and malformed trunk models are refused in one line, quickly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import io

_ENV = {**os.environ, "PYTHONPATH": str(Path(phloem.__file__).resolve().parents[1])}


def _phloem(*args: object, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phloem", *map(str, args)], env=_ENV, capture_output=True, text=True, timeout=timeout
    )


def _one_line_error(res: subprocess.CompletedProcess[str], *parts: str) -> str:
    err = res.stderr.strip()
    assert res.returncode == 2, res.stderr
    assert "\n" not in err and "Traceback" not in err, err
    for part in parts:
        assert part in err, err
    return err


@pytest.fixture()
def river(tmp_path):
    p = tmp_path / "river.png"
    img = np.full((48, 48), 0.8, np.float32)
    img[20:26, 4:44] = 0.1
    io.write_image(p, img)
    return p


def test_run_refuses_far_away_coordinates_in_seconds(tmp_path, river):
    # Before: no "shape" and coordinates of 1e12 made resampling walk ~1e12 vertices (minutes).
    sk = tmp_path / "far.json"
    sk.write_text('{"branches": [{"points": [[1, 1], [1e12, 3e11]], "thickness": 2}]}')
    res = _phloem("branching", "run", river, "--skeleton", sk, "--out", tmp_path / "o.png", timeout=30)
    _one_line_error(
        res,
        "--skeleton: ",
        "far.json: branches[0].points[1]: coordinates must be finite (no NaN or infinity) and within",
    )
    assert not (tmp_path / "o.png").exists()


def test_run_checks_a_shapeless_skeleton_against_the_image(tmp_path, river):
    sk = tmp_path / "big.json"
    sk.write_text('{"branches": [{"points": [[1, 1], [500000, 30]], "thickness": 2}]}')
    res = _phloem("branching", "run", river, "--skeleton", sk, "--out", tmp_path / "o.png", timeout=30)
    _one_line_error(res, "--skeleton: branches[0].points[1] = (500000.0, 30.0) is outside the 48x48 image")


def test_grow_bounds_the_resampling(tmp_path):
    sk = tmp_path / "long.json"
    sk.write_text('{"branches": [{"points": [[0, 0], [1000000, 0], [0, 1]], "thickness": 0.5}]}')
    res = _phloem("branching", "grow", sk, "--out", tmp_path / "n.json", "--size", "64", "--h", "0.5", timeout=30)
    _one_line_error(res, "--h: resampling 2e+06 px of branches at h=0.5 would make about 4e+06 vertices")


def test_huge_thickness_is_refused_before_drawing(tmp_path, river):
    # Before: OpenCV's "thickness <= MAX_THICKNESS" assertion from the render.
    sk = tmp_path / "thick.json"
    sk.write_text('{"shape": [48, 48], "branches": [{"points": [[4, 22], [44, 22]], "thickness": 50000}]}')
    res = _phloem("branching", "render", river, sk, sk, "--out", tmp_path / "o.png", timeout=30)
    err = _one_line_error(res, "thick.json: branches[0].thickness[0]: expected a radius in [0, 8192] px, got 50000.0")
    assert "MAX_THICKNESS" not in err


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"[" * 100_000, "line 1 column 65: nested more than 64 levels deep"),
        (b'{"branches": ' + b"[" * 5000 + b"]" * 5000 + b"}", "line 1 column 77: nested more than 64 levels deep"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "is not a JSON file (binary data at byte 0)"),
        (b'{"a": 1}\x00\x00', "is not a JSON file (binary data at byte 8)"),
        (b'{"branches": [\n  {"points": [[0, 0], [1, 1]],}\n]}', "line 2 column 31: Expecting property name"),
        (b'{"branches": [{"points": [[0, 0], [1, NaN]]}]}', "line 1 column 39: NaN is not a JSON number"),
    ],
)
def test_skeleton_files_that_are_not_json(tmp_path, content, message):
    sk = tmp_path / "sk.json"
    sk.write_bytes(content)
    res = _phloem("branching", "grow", sk, "--out", tmp_path / "n.json", timeout=30)
    err = _one_line_error(res, "SKEL.json: ", f"sk.json {message}")
    assert "RecursionError" not in err and "codec" not in err


def test_guide_json_is_read_with_the_same_checks(tmp_path):
    from phloem.branching import synthetic_skeleton

    sk = tmp_path / "sk.json"
    synthetic_skeleton(0).save(sk)
    guide = tmp_path / "g.json"
    for content, message in [
        (b"\xff\xfe[", "g.json is not a JSON file (binary data at byte 0)"),
        (b"[[1, 2], [3]]", "g.json: point [1] must be [x, y] with two numbers"),
        (b"[[1, 2]", "g.json line 1 column 8: Expecting ',' delimiter"),
    ]:
        guide.write_bytes(content)
        res = _phloem("branching", "grow", sk, "--out", tmp_path / "n.json", "--guide", guide, timeout=60)
        _one_line_error(res, "--guide: ", message)


def test_trunk_model_files(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    model = tmp_path / "m.json"
    for content, message in [
        (b"\x00\x01binary", "--trunk-model: " + str(model) + " is not a JSON file (binary data at byte 0)"),
        (b"{" * 3000, "line 1 column 65: nested more than 64 levels deep"),
        (b'{"format": "phloem.trees.TrunkClassifier", "coef": [1]}', "m.json: 'coef' must hold 78 numbers, got 1"),
        (b"[1, 2]", "m.json: not a phloem.trees.TrunkClassifier record"),
    ]:
        model.write_bytes(content)
        res = _phloem(
            "trees", lib, "--n-variations", 1, "--out-dir", tmp_path / "out", "--trunk-model", model, timeout=60
        )
        _one_line_error(res, "--trunk-model: ", message)
