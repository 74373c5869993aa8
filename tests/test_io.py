"""phloem.io: round trips, corrupt input, pixel limit, atomic no-overwrite writes, sidecars."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest

import phloem
from phloem.io import ImageReadError, read_image, sidecar_path, write_image, write_result


@pytest.mark.parametrize("ext", [".png", ".tif"])
@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("bits", [8, 16])
def test_lossless_round_trip(tmp_path, ext, channels, bits):
    rng = np.random.default_rng(channels * bits)
    levels = 2**bits - 1
    img = (rng.integers(0, levels + 1, (13, 17, channels)) / levels).astype(np.float32)
    path = tmp_path / f"img{ext}"
    write_image(path, img, bit_depth=bits)
    back = read_image(path)
    expected = img[..., 0] if channels == 1 else img
    assert back.shape == expected.shape and back.dtype == np.float32
    np.testing.assert_allclose(back, expected, atol=0.5 / levels)


def test_channel_order_is_rgb(tmp_path):
    img = np.zeros((4, 4, 3), np.float32)
    img[..., 0] = 1.0  # pure red
    write_image(tmp_path / "red.png", img)
    import cv2

    bgr = cv2.imread(str(tmp_path / "red.png"))
    assert (bgr[..., 2] == 255).all() and (bgr[..., :2] == 0).all()
    assert (read_image(tmp_path / "red.png")[..., 0] == 1.0).all()


def test_jpeg_round_trip_is_close(tmp_path, bark):
    write_image(tmp_path / "b.jpg", bark)
    assert np.abs(read_image(tmp_path / "b.jpg") - bark).mean() < 0.03


def test_refuses_to_overwrite_and_leaves_no_temporary_files(tmp_path):
    p = tmp_path / "a.png"
    write_image(p, np.zeros((4, 4), np.float32))
    before = p.read_bytes()
    with pytest.raises(FileExistsError, match="already exists"):
        write_image(p, np.ones((4, 4), np.float32))
    assert p.read_bytes() == before
    write_image(p, np.ones((4, 4), np.float32), overwrite=True)
    assert read_image(p).min() == 1.0
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.png"]


def test_write_result_writes_sidecar_and_checks_both_first(tmp_path):
    p = tmp_path / "out.png"
    side = write_result(p, np.zeros((4, 4, 3), np.float32), command="test", parameters={"k": 3}, seed=7)
    meta = json.loads(side.read_text())
    assert side == sidecar_path(p) and meta["seed"] == 7 and meta["parameters"] == {"k": 3}
    assert meta["phloem_version"] == phloem.__version__
    p2 = tmp_path / "other.png"
    sidecar_path(p2).write_text("{}")
    with pytest.raises(FileExistsError):
        write_result(p2, np.zeros((4, 4), np.float32), command="t", parameters={}, seed=0)
    assert not p2.exists()  # refused before anything was written


@pytest.mark.parametrize(
    ("image", "kwargs", "err", "match"),
    [
        (np.zeros((4, 4, 2), np.float32), {}, ValueError, "channels"),
        (np.full((4, 4), np.nan, np.float32), {}, ValueError, "finite"),
        (np.zeros((4, 4), np.float32), {"bit_depth": 12}, ValueError, "bit_depth"),
        (np.zeros((0, 4), np.float32), {}, ValueError, "image"),
    ],
)
def test_write_bad_input(tmp_path, image, kwargs, err, match):
    with pytest.raises(err, match=match):
        write_image(tmp_path / "x.png", image, **kwargs)
    assert not (tmp_path / "x.png").exists()


def test_write_bad_destination(tmp_path):
    with pytest.raises(ValueError, match="extension"):
        write_image(tmp_path / "x.bmp", np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="bit_depth"):
        write_image(tmp_path / "x.jpg", np.zeros((2, 2), np.float32), bit_depth=16)
    with pytest.raises(FileNotFoundError, match="folder"):
        write_image(tmp_path / "missing" / "x.png", np.zeros((2, 2), np.float32))


def test_missing_and_non_image_files(tmp_path):
    with pytest.raises(ImageReadError, match="no such file"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "t.png").write_text("not an image")
    with pytest.raises(ImageReadError, match="not a readable"):
        read_image(tmp_path / "t.png")


def test_truncated_png_and_jpeg(tmp_path, bark):
    for ext in (".png", ".jpg"):
        good = tmp_path / f"good{ext}"
        write_image(good, bark)
        bad = tmp_path / f"bad{ext}"
        bad.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
        with pytest.raises(ImageReadError):
            read_image(bad)


def test_corrupt_png_chunk(tmp_path, bark):
    good = tmp_path / "good.png"
    write_image(good, bark)
    data = bytearray(good.read_bytes())
    data[len(data) // 2] ^= 0xFF  # flip bits inside the image data: CRC mismatch
    (tmp_path / "bad.png").write_bytes(bytes(data))
    with pytest.raises(ImageReadError):
        read_image(tmp_path / "bad.png")


def _png_header_only(width: int, height: int) -> bytes:
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 16)) + chunk(b"IEND", b"")
    )


def test_decompression_bomb_is_refused_before_decoding(tmp_path):
    p = tmp_path / "bomb.png"
    p.write_bytes(_png_header_only(100_000, 100_000))  # 10^10 pixels declared in 60 bytes
    with pytest.raises(ImageReadError, match="pixel limit|over the limit"):
        read_image(p)


def test_configurable_pixel_limit(tmp_path):
    p = tmp_path / "a.png"
    write_image(p, np.zeros((100, 100), np.float32))
    with pytest.raises(ImageReadError, match="over the limit"):
        read_image(p, max_pixels=5000)
    assert read_image(p, max_pixels=10_000).shape == (100, 100)


def test_embedded_data():
    assert phloem.data.bark().shape == (256, 256, 4)
    assert phloem.data.brick().shape == (512, 512)
    with pytest.raises(ValueError, match="name"):
        phloem.data.path("nothing.png")


def test_written_files_get_the_umask_mode(tmp_path):
    import os

    mask = os.umask(0o022)
    try:
        write_image(tmp_path / "m.png", np.zeros((2, 2), np.float32))
        assert (tmp_path / "m.png").stat().st_mode & 0o777 == 0o644
    finally:
        os.umask(mask)
