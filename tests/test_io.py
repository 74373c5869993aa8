"""phloem.io: round trips, corrupt input, pixel limit, atomic no-overwrite writes, sidecars."""

from __future__ import annotations

import hashlib
import json
import os
import struct
import subprocess
import sys
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
from PIL import Image, ImageOps

import phloem
from phloem.io import (
    IMAGE_SUFFIXES,
    ImageReadError,
    RescaledImageWarning,
    image_size,
    read_image,
    sidecar_path,
    write_image,
    write_result,
)


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


def test_write_result_records_threads_input_hashes_and_details(tmp_path):
    src = tmp_path / "in.png"
    write_image(src, np.ones((4, 4), np.float32))
    folder = tmp_path / "lib"
    folder.mkdir()
    (folder / "a.txt").write_text("a")
    side = write_result(tmp_path / "o.png", np.zeros((4, 4), np.float32), command="t", parameters={}, seed=None,
                        threads=3, inputs=[src, folder], details={"found": 1})  # fmt: skip
    meta = json.loads(side.read_text())
    assert meta["sidecar_version"] == phloem.io.SIDECAR_VERSION and meta["threads"] == 3
    assert meta["details"] == {"found": 1} and meta["output"] == "o.png"
    assert meta["inputs"][0] == {"path": str(src), "sha256": hashlib.sha256(src.read_bytes()).hexdigest()}
    before = meta["inputs"][1]["sha256"]
    (folder / "b.txt").write_text("")  # a file added to a folder input changes its digest
    assert phloem.io.file_digest(folder) != before
    (folder / "b.txt").unlink()
    assert phloem.io.file_digest(folder) == before


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


# --- issue 16: reading -----------------------------------------------------------------------

CLI_ENV = {**os.environ, "PYTHONPATH": str(Path(phloem.__file__).resolve().parents[1])}


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phloem", *args], capture_output=True, text=True, env=CLI_ENV, timeout=120
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_float_tiff_in_range_is_read_as_is(tmp_path, dtype, channels):
    rng = np.random.default_rng(channels)
    img = rng.random((9, 11, channels)).astype(dtype)
    img[0, 0] = 0.0
    p = tmp_path / "f.tif"
    tifffile.imwrite(p, img[..., 0] if channels == 1 else img, photometric="minisblack" if channels == 1 else "rgb")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning for values already in [0, 1]
        back = read_image(p)
    expected = img[..., 0] if channels == 1 else img
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, expected.astype(np.float32))  # channel order RGB(A), no scaling


@pytest.mark.parametrize("channels", [1, 3])
def test_float_tiff_out_of_range_is_rescaled_with_a_warning(tmp_path, channels):
    img = np.linspace(-5.0, 705.0, 8 * 10 * channels, dtype=np.float32).reshape(8, 10, channels)
    p = tmp_path / "f.tif"
    tifffile.imwrite(p, img[..., 0] if channels == 1 else img, photometric="minisblack" if channels == 1 else "rgb")
    with pytest.warns(RescaledImageWarning, match=r"\[-5, 705\], outside \[0, 1\]") as rec:
        back = read_image(p)
    assert len(rec) == 1 and "\n" not in str(rec[0].message)
    expected = (img - img.min()) / (img.max() - img.min())
    np.testing.assert_allclose(back, expected[..., 0] if channels == 1 else expected, atol=1e-6)
    assert back.min() == 0.0 and back.max() == 1.0


def test_float_tiff_with_nan_is_refused(tmp_path):
    img = np.full((6, 7, 3), 0.5, np.float32)
    img[2, 3, 1] = np.nan
    img[4, 4, 0] = np.inf
    tifffile.imwrite(tmp_path / "n.tif", img, photometric="rgb")
    with pytest.raises(ImageReadError, match=r"^path: .*n\.tif has 2 NaN or infinite samples; expected finite values$"):
        read_image(tmp_path / "n.tif")


def test_float_tiff_cli_warns_in_one_line(tmp_path):
    img = np.random.default_rng(0).random((32, 32), np.float32) * 705
    tifffile.imwrite(tmp_path / "f.tif", img)
    r = _cli("synthesize", str(tmp_path / "f.tif"), "--size", "8x8", "--out", str(tmp_path / "o.png"), "-q")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("phloem synthesize: warning: ") and "rescaled" in lines[0], r.stderr


@pytest.mark.parametrize(
    ("photometric", "kwargs", "match"),
    [
        ("separated", {}, "photometric SEPARATED"),  # CMYK: OpenCV would hand it over as BGRA
        ("minisblack", {"extrasamples": [2]}, "gray \\+ alpha"),  # OpenCV would drop the alpha
    ],
)
def test_tiff_layouts_opencv_misreads_are_refused(tmp_path, photometric, kwargs, match):
    data = np.zeros((5, 6, 4 if photometric == "separated" else 2), np.uint8)
    tifffile.imwrite(tmp_path / "t.tif", data, photometric=photometric, **kwargs)
    with pytest.raises(ImageReadError, match=match):
        read_image(tmp_path / "t.tif")


def test_min_is_white_tiff_is_inverted(tmp_path):
    img = np.arange(30, dtype=np.uint16).reshape(5, 6) * 2000
    tifffile.imwrite(tmp_path / "w.tif", img, photometric="miniswhite")
    np.testing.assert_allclose(read_image(tmp_path / "w.tif"), 1.0 - img / 65535.0, atol=1e-6)


def test_jpeg_with_trailing_bytes_is_read(tmp_path, bark):
    write_image(tmp_path / "b.jpg", bark)
    data = (tmp_path / "b.jpg").read_bytes()
    (tmp_path / "t.jpg").write_bytes(data + bytes(range(200)))  # as cameras append thumbnails / MPF / padding
    np.testing.assert_array_equal(read_image(tmp_path / "t.jpg"), read_image(tmp_path / "b.jpg"))


@pytest.mark.parametrize("cut", [2, 100, 5000])
def test_truncated_jpeg_is_still_refused(tmp_path, bark, cut):
    write_image(tmp_path / "b.jpg", bark)
    data = (tmp_path / "b.jpg").read_bytes()
    (tmp_path / "u.jpg").write_bytes(data[:-cut])  # cut inside the scan (2: just the EOI marker)
    with pytest.raises(ImageReadError, match=r"^path: .*u\.jpg is a truncated JPEG \(the data ends before"):
        read_image(tmp_path / "u.jpg")


def test_jpeg_end_is_found_past_an_exif_thumbnail(tmp_path, bark):
    # A camera file: an EXIF thumbnail (with its own EOI) before the main image; cut the main
    # image and the thumbnail's EOI must not count as the end.
    write_image(tmp_path / "thumb.jpg", bark[:16, :16])
    thumb = (tmp_path / "thumb.jpg").read_bytes()
    app1 = b"\xff\xe1" + (len(thumb) + 8).to_bytes(2, "big") + b"Exif\x00\x00" + thumb
    write_image(tmp_path / "b.jpg", bark)
    data = (tmp_path / "b.jpg").read_bytes()
    whole = data[:2] + app1 + data[2:]
    (tmp_path / "whole.jpg").write_bytes(whole + b"\x00" * 100)
    assert read_image(tmp_path / "whole.jpg").shape == bark.shape
    (tmp_path / "cut.jpg").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(ImageReadError, match="truncated JPEG"):
        read_image(tmp_path / "cut.jpg")


@pytest.mark.parametrize("orientation", range(1, 9))
def test_jpeg_exif_orientation_is_applied(tmp_path, orientation):
    rng = np.random.default_rng(orientation)
    pixels = (rng.random((24, 40, 3)) * 255).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.fromarray(pixels).save(tmp_path / "plain.jpg", quality=95)
    Image.fromarray(pixels).save(tmp_path / "o.jpg", quality=95, exif=exif)
    plain = read_image(tmp_path / "plain.jpg")
    upright = {1: plain, 3: np.rot90(plain, 2), 6: np.rot90(plain, -1), 8: np.rot90(plain, 1)}
    got = read_image(tmp_path / "o.jpg")
    if orientation in upright:
        np.testing.assert_array_equal(got, upright[orientation])
    with Image.open(tmp_path / "o.jpg") as im:  # the same as Pillow shows it
        pil = np.asarray(ImageOps.exif_transpose(im), np.float32) / 255.0
    assert got.shape == pil.shape
    np.testing.assert_array_equal(got, np.asarray(_orient_like_pil(plain, orientation)))
    assert np.abs(got - pil).max() < 0.1  # different JPEG decoders: close, not equal


def test_jpeg_with_damaged_exif_is_read_without_a_warning(tmp_path):
    Image.fromarray(np.full((8, 8, 3), 200, np.uint8)).save(
        tmp_path / "e.jpg", exif=b"Exif\x00\x00MM\x00*\x00\x00\x00\x08\xff\xff"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_image(tmp_path / "e.jpg").shape == (8, 8, 3)


def _orient_like_pil(plain: np.ndarray, orientation: int) -> np.ndarray:
    im = Image.fromarray((plain * 255).round().astype(np.uint8))
    transpose = {2: 0, 3: 3, 4: 1, 5: 5, 6: 4, 7: 6, 8: 2}.get(orientation)
    out = im if transpose is None else im.transpose(Image.Transpose(transpose))
    return np.asarray(out, np.float32) / 255.0


def test_webp_is_read(tmp_path):
    rng = np.random.default_rng(5)
    pixels = (rng.random((10, 12, 4)) * 255).astype(np.uint8)
    Image.fromarray(pixels, "RGBA").save(tmp_path / "a.webp", lossless=True, exact=True)
    np.testing.assert_array_equal(read_image(tmp_path / "a.webp"), pixels / np.float32(255))
    assert ".webp" in IMAGE_SUFFIXES


def _png_of(width: int, height: int) -> bytes:
    return _png_header_only(width, height)


@pytest.mark.parametrize(("width", "height"), [(10_000, 10_000), (15_000, 15_000), (16_384, 16_384), (15_000, 20_000)])
def test_one_pixel_limit_ours_with_the_true_size(tmp_path, width, height):
    # 100, 225, 256 and 300 Mpx declared in 60 bytes: Pillow's own ceiling (89 Mpx warning,
    # 179 Mpx error) must not apply, only max_pixels, and the message says the true size.
    p = tmp_path / "big.png"
    p.write_bytes(_png_of(width, height))
    n = width * height
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no DecompressionBombWarning
        with pytest.raises(ImageReadError) as exc:
            read_image(p)
        if n > phloem.io.DEFAULT_MAX_PIXELS:
            assert str(exc.value) == (
                f"path: {p} is {width}×{height} = {n} pixels, over the limit of {2**28}"
                " (pass a larger max_pixels / --max-pixels if you trust this file)"
            )
        else:  # under the limit: the header passes, the missing pixel data is what is wrong
            assert "could not be decoded" in str(exc.value), exc.value
        with pytest.raises(ImageReadError, match=f"is {width}×{height} = {n} pixels, over the limit of {n - 1} "):
            read_image(p, max_pixels=n - 1)
        with pytest.raises(ImageReadError, match="could not be decoded"):
            read_image(p, max_pixels=n)


def test_pillow_limit_is_left_as_it_was(tmp_path):
    p = tmp_path / "big.png"
    p.write_bytes(_png_of(15_000, 15_000))
    before = Image.MAX_IMAGE_PIXELS
    with pytest.raises(ImageReadError):
        read_image(p)
    assert before == Image.MAX_IMAGE_PIXELS
    with pytest.raises(Image.DecompressionBombError):  # the user's own Pillow calls keep Pillow's guard
        Image.open(p)


@pytest.mark.parametrize(
    ("width", "height", "flags", "expect"),
    [
        (15_000, 20_000, [], "is 15000×20000 = 300000000 pixels, over the limit of 268435456"),
        (15_000, 15_000, [], "could not be decoded as a PNG image"),
        (15_000, 20_000, ["--max-pixels", str(2**29)], "could not be decoded as a PNG image"),
        (10_000, 10_000, ["--max-pixels", "1000"], "is 10000×10000 = 100000000 pixels, over the limit of 1000"),
    ],
)
def test_cli_pixel_limit_message_is_one_true_line(tmp_path, width, height, flags, expect):
    big = tmp_path / "BIG.png"
    big.write_bytes(_png_of(width, height))
    r = _cli("synthesize", str(big), "--size", "8x8", "--out", str(tmp_path / "o.png"), *flags)
    assert r.returncode == 2
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr  # no Pillow warning, no libpng / OpenCV lines
    assert lines[0].startswith("phloem synthesize: error: IN: ") and expect in lines[0], r.stderr


def test_decoder_messages_do_not_leak(tmp_path, bark, capfd):
    p = tmp_path / "short.png"
    p.write_bytes(_png_of(300, 200))  # a valid header, too little pixel data: libpng complains
    with pytest.raises(ImageReadError, match="could not be decoded"):
        read_image(p)
    out, err = capfd.readouterr()
    assert err == "" and out == ""
    print("stderr works again", file=sys.stderr)
    assert "works again" in capfd.readouterr().err


def test_damaged_tiff_pages_print_nothing(tmp_path):
    # tifffile logs "invalid circular reference to IFD" while its pages load, after the header;
    # a subprocess, because pytest's log capture would hide it
    p = tmp_path / "circular.tif"
    p.write_bytes(b"II*\x00" + struct.pack("<IHI", 8, 0, 8))  # an empty IFD whose next IFD is itself
    code = f"import phloem\ntry:\n    phloem.io.read_image({str(p)!r})\nexcept phloem.io.ImageReadError as e:\n    print(e)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=CLI_ENV, timeout=60)
    assert "circular.tif" in r.stdout and r.stderr == ""


def test_image_size_reads_the_header_as_read_image_would(tmp_path: Path) -> None:
    img = (np.arange(6 * 10 * 3) % 251).astype(np.uint8).reshape(6, 10, 3)
    plain = tmp_path / "plain.png"
    write_image(plain, img.astype(np.float32) / 255)
    assert image_size(plain) == read_image(plain).shape[:2] == (6, 10)
    turned = tmp_path / "turned.jpg"
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90° clockwise: a portrait photo stored landscape
    Image.fromarray(img).save(turned, exif=exif.tobytes())
    assert image_size(turned) == read_image(turned).shape[:2] == (10, 6)
    with pytest.raises(ImageReadError, match="over the limit of 10"):
        image_size(plain, max_pixels=10)


def test_file_digest_sees_a_rewrite_that_keeps_size_and_mtime(tmp_path):
    """Digests are kept per process (a batch worker hashes the same inputs for every item), but a
    file rewritten in place to the same size, with its mtime set back, is hashed again."""
    f = tmp_path / "a.bin"
    f.write_bytes(b"abcd")
    st = f.stat()
    first = phloem.io.file_digest(f)
    assert phloem.io.file_digest(f) == first
    f.write_bytes(b"abce")
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert f.stat().st_size == st.st_size and f.stat().st_mtime_ns == st.st_mtime_ns
    assert phloem.io.file_digest(f) != first
    assert phloem.io.file_digest(tmp_path) != ""  # a folder's digest goes through its files'
