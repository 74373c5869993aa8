"""--bit-depth's default follows the input: a 16-bit elevation model stays 16-bit."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from phloem import io
from phloem.cli import main


@pytest.fixture
def field(tmp_path: Path) -> tuple[Path, Path]:
    """A smooth 16-bit field whose levels span 1400 of 65535 (an elevation model's few
    metres), and a hole in it."""
    yy, xx = np.mgrid[:48, :64]
    z = (1000 + 300 * np.sin(xx / 9.0) + 400 * np.cos(yy / 7.0)).astype(np.uint16)
    img, mask = tmp_path / "dem.png", tmp_path / "hole.png"
    cv2.imwrite(str(img), z)
    hole = np.zeros((48, 64), np.uint8)
    hole[18:30, 24:40] = 255
    cv2.imwrite(str(mask), hole)
    return img, mask


def _complete(img: Path, mask: Path, out: Path, *flags: str) -> tuple[np.ndarray, int]:
    assert main(["complete", str(img), str(mask), "--out", str(out), "-q", *flags]) == 0
    sidecar = json.loads(io.sidecar_path(out).read_text())
    return cv2.imread(str(out), cv2.IMREAD_UNCHANGED), sidecar["parameters"]["bit_depth"]


def test_a_16_bit_input_gives_a_16_bit_output(field: tuple[Path, Path], tmp_path: Path) -> None:
    img, mask = field
    out, depth = _complete(img, mask, tmp_path / "out.png")
    assert out.dtype == np.uint16 and depth == 16
    assert len(np.unique(out)) > 200  # its levels kept; at 8 bits there are 7
    eight, depth = _complete(img, mask, tmp_path / "eight.png", "--bit-depth", "8")
    assert eight.dtype == np.uint8 and depth == 8 and len(np.unique(eight)) <= 8
    jpeg, depth = _complete(img, mask, tmp_path / "out.jpg")
    assert jpeg.dtype == np.uint8 and depth == 8  # a JPEG holds 8


def test_an_8_bit_input_gives_an_8_bit_output(field: tuple[Path, Path], tmp_path: Path) -> None:
    _, mask = field
    img = tmp_path / "photo.png"
    cv2.imwrite(str(img), np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8))
    out, depth = _complete(img, mask, tmp_path / "out.png")
    assert out.dtype == np.uint8 and depth == 8


def test_stored_bit_depth_reads_the_header(field: tuple[Path, Path], tmp_path: Path) -> None:
    img, mask = field
    assert io.stored_bit_depth(img) == 16 and io.stored_bit_depth(mask) == 8
    tif = tmp_path / "dem.tif"
    cv2.imwrite(str(tif), cv2.imread(str(img), cv2.IMREAD_UNCHANGED))
    assert io.stored_bit_depth(tif) == 16
    (tmp_path / "junk.png").write_bytes(b"not an image")
    assert io.stored_bit_depth(tmp_path / "junk.png") == 8
