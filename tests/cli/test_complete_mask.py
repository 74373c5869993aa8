"""phloem complete's mask (issue 16): --mask-alpha without alpha used the colours silently, soft
alpha edges were kept (a pale ring around the fill), and there was no --invert-mask."""

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


def _phloem(*args: object) -> subprocess.CompletedProcess[str]:
    cmd = [sys.executable, "-m", "phloem", *map(str, args)]
    return subprocess.run(cmd, env=_ENV, capture_output=True, text=True, timeout=120)


@pytest.fixture()
def stripes(tmp_path):
    yy, xx = np.mgrid[:48, :48]
    img = np.stack([0.5 + 0.4 * np.sin(xx / 2.0), 0.5 + 0.4 * np.cos(yy / 3.0), np.full((48, 48), 0.3)], axis=2)
    return img.astype(np.float32)


def test_mask_alpha_needs_an_alpha_channel(tmp_path, stripes):
    io.write_image(tmp_path / "in.png", stripes)
    mask = np.zeros((48, 48, 3), np.float32)
    mask[16:32, 16:32] = 1.0
    io.write_image(tmp_path / "m.png", mask)
    res = _phloem("complete", tmp_path / "in.png", tmp_path / "m.png", "--mask-alpha", "--out", tmp_path / "o.png")
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip()
    assert "\n" not in err and err.startswith("phloem complete: error: --mask-alpha: ")
    assert "m.png has no alpha channel (3 channels)" in err
    assert not (tmp_path / "o.png").exists()


def test_soft_alpha_edges_are_filled_and_alpha_is_kept(tmp_path, stripes):
    rgba = np.concatenate([stripes, np.ones((48, 48, 1), np.float32)], axis=2)
    rgba[14:34, 14:34, 3] = 0.7  # a soft edge around ...
    rgba[16:32, 16:32, 3] = 0.0  # ... the transparent hole
    rgba[16:32, 16:32, :3] = 1.0
    rgba[14:34, 14:34, :3][rgba[14:34, 14:34, 3] == 0.7] = 0.95  # pale: what the ring looked like
    rgba[:4, :4, 3] = 0.0  # transparent outside the hole (and filled: not opaque)
    io.write_image(tmp_path / "in.png", rgba)
    res = _phloem("complete", tmp_path / "in.png", tmp_path / "in.png", "--mask-alpha", "--out", tmp_path / "o.png")
    assert res.returncode == 0, res.stderr
    out = io.read_image(tmp_path / "o.png")
    assert out.shape == (48, 48, 4)
    ring = np.zeros((48, 48), bool)
    ring[14:34, 14:34] = True
    ring[16:32, 16:32] = False
    # The ring was part of the hole: filled from the stripes (blue 0.3), not left pale (0.95).
    assert float(np.abs(out[ring, 2] - 0.3).max()) < 0.05
    keep = np.ones((48, 48), bool)
    keep[14:34, 14:34] = False
    keep[:4, :4] = False
    np.testing.assert_allclose(out[keep], io.read_image(tmp_path / "in.png")[keep], atol=1e-6)


def test_invert_mask_flips_plain_and_alpha_masks(tmp_path, stripes):
    io.write_image(tmp_path / "in.png", stripes)
    white = np.zeros((48, 48), np.float32)
    white[16:32, 16:32] = 1.0
    io.write_image(tmp_path / "white.png", white)
    io.write_image(tmp_path / "black.png", 1.0 - white)
    alpha = np.concatenate([stripes, white[..., None]], axis=2)  # opaque where the hole is
    io.write_image(tmp_path / "alpha.png", alpha)
    runs = {
        "a": ("white.png",),
        "b": ("black.png", "--invert-mask"),
        "c": ("alpha.png", "--mask-alpha", "--invert-mask"),
    }
    for name, (mask, *flags) in runs.items():
        res = _phloem(
            "complete", tmp_path / "in.png", tmp_path / mask, *flags, "--seed", 3, "--out", tmp_path / f"{name}.png"
        )
        assert res.returncode == 0, res.stderr
    a, b, c = (io.read_image(tmp_path / f"{n}.png") for n in "abc")
    assert not np.array_equal(a[16:32, 16:32], stripes[16:32, 16:32])
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
