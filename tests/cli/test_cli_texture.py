"""phloem synthesize, quilt and complete: outputs with sidecars, no silent overwrite, clean errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phloem import io
from phloem.cli import main


def test_synthesize_writes_image_and_sidecar(tmp_path, exemplar_png):
    out = tmp_path / "out.png"
    assert main(["synthesize", str(exemplar_png), "--size", "80x48", "--out", str(out), "--seed", "4", "-q"]) == 0
    img = io.read_image(out)
    assert img.shape == (48, 80, 3)
    meta = json.loads(io.sidecar_path(out).read_text())
    assert meta["seed"] == 4 and meta["parameters"]["size"] == [48, 80] and meta["command"] == "synthesize"


def test_quilt_writes_exemplar_pixels_and_sidecar(tmp_path, exemplar_png):
    out = tmp_path / "q.png"
    args = ["quilt", str(exemplar_png), "--size", "90x70", "--block", "24", "--out", str(out), "--seed", "2", "-q"]
    assert main(args) == 0
    img = io.read_image(out)
    ex = io.read_image(exemplar_png)
    assert img.shape == (70, 90, 3)
    # Every output colour occurs in the exemplar (8-bit PNG round trip on both sides).
    colours = {tuple(c) for c in (ex.reshape(-1, 3) * 255).round().astype(int)}
    assert all(tuple(c) in colours for c in (img.reshape(-1, 3) * 255).round().astype(int))
    meta = json.loads(io.sidecar_path(out).read_text())
    assert meta["command"] == "quilt" and meta["parameters"]["block"] == 24 and meta["seed"] == 2
    assert main(args) == 2, "no silent overwrite"


def test_same_seed_same_file(tmp_path, exemplar_png):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    for p, threads in ((a, "1"), (b, "2")):
        main(["synthesize", str(exemplar_png), "--size", "40x40", "--out", str(p), "--threads", threads, "-q"])
    assert np.array_equal(io.read_image(a), io.read_image(b))


def test_no_silent_overwrite(tmp_path, exemplar_png, capsys):
    out = tmp_path / "out.png"
    args = ["synthesize", str(exemplar_png), "--size", "32x32", "--out", str(out), "-q"]
    assert main(args) == 0
    before = out.read_bytes()
    assert main([*args, "--seed", "9"]) == 2
    assert "already exists" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main([*args, "--seed", "9", "--force"]) == 0
    assert out.read_bytes() != before


def test_complete_from_mask_file(tmp_path, bark):
    img = tmp_path / "img.png"
    io.write_image(img, bark[:96, :96])
    mask = np.zeros((96, 96), np.float32)
    mask[40:60, 30:50] = 1
    io.write_image(tmp_path / "mask.png", mask)
    out = tmp_path / "done.png"
    assert main(["complete", str(img), str(tmp_path / "mask.png"), "--out", str(out), "-q"]) == 0
    res = io.read_image(out)
    assert np.abs(res - io.read_image(img))[mask == 0].max() < 1e-6
    varied = tmp_path / "varied.png"
    assert main(["complete", str(img), str(tmp_path / "mask.png"), "--out", str(varied), "--diversity", "1", "-q"]) == 0
    assert json.loads(io.sidecar_path(varied).read_text())["parameters"]["diversity"] == 1.0
    assert not np.array_equal(io.read_image(varied), res)
    copied = tmp_path / "copied.png"
    assert main(["complete", str(img), str(tmp_path / "mask.png"), "--out", str(copied), "--finest", "copy", "-q"]) == 0
    assert json.loads(io.sidecar_path(copied).read_text())["parameters"]["finest"] == "copy"
    hole = io.read_image(copied)[mask > 0]
    assert np.isin(hole, io.read_image(img)[mask == 0]).all()  # every filled pixel is a known one
    blocks = tmp_path / "blocks.png"
    flags = ["--finest", "copy", "--start", "blocks", "-q"]
    assert main(["complete", str(img), str(tmp_path / "mask.png"), "--out", str(blocks), *flags]) == 0
    assert json.loads(io.sidecar_path(blocks).read_text())["parameters"]["start"] == "blocks"
    assert not np.array_equal(io.read_image(blocks), io.read_image(copied))
    assert np.isin(io.read_image(blocks)[mask > 0], io.read_image(img)[mask == 0]).all()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.bmp"], "extension"),
        (["synthesize", "{tmp}/missing.png", "--size", "32x32", "--out", "{tmp}/o.png"], "no such file"),
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.png", "--patch-size", "4"], "--patch-size"),
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.png", "--max-pixels", "100"], "over the limit"),
        (["complete", "{ex}", "{white}", "--out", "{tmp}/o.png"], "MASK"),
        (["complete", "{ex}", "{small}", "--out", "{tmp}/o.png"], "MASK"),
    ],
)
def test_errors_are_clean_and_write_nothing(tmp_path, exemplar_png, capsys, args, message):
    io.write_image(tmp_path / "white.png", np.ones((64, 64), np.float32))  # everything to fill
    io.write_image(tmp_path / "small.png", np.ones((32, 64), np.float32))  # wrong size
    paths = dict(ex=exemplar_png, tmp=tmp_path, white=tmp_path / "white.png", small=tmp_path / "small.png")
    argv = [a.format(**paths) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "o.png").exists() and not (tmp_path / "o.bmp").exists()


@pytest.mark.parametrize("command", ["synthesize", "quilt"])
def test_tileable_flag_makes_the_output_tile(tmp_path, bark, command):
    ex = tmp_path / "ex.png"
    io.write_image(ex, bark[:96, :96])
    out = tmp_path / "t.png"
    extra = ["--block", "24"] if command == "quilt" else []
    assert main([command, str(ex), "--size", "72x64", "--out", str(out), "--tileable", "-q", *extra]) == 0
    from phloem.metrics import wrap_seam

    assert wrap_seam(io.read_image(out)) <= 1.5
    assert json.loads(io.sidecar_path(out).read_text())["parameters"]["tileable"] is True


def test_complete_tileable_flag(tmp_path, bark):
    img, mask, out = tmp_path / "img.png", tmp_path / "mask.png", tmp_path / "out.png"
    io.write_image(img, bark[:64, :64])
    m = np.zeros((64, 64), np.float32)
    m[20:40, :6] = m[20:40, -6:] = 1.0  # across the left/right border
    io.write_image(mask, m)
    assert main(["complete", str(img), str(mask), "--out", str(out), "--tileable", "-q"]) == 0
    assert io.read_image(out).shape == (64, 64, 3)


def test_quilt_tileable_too_small_is_a_clean_error(tmp_path, exemplar_png, capsys):
    out = tmp_path / "q.png"
    assert main(["quilt", str(exemplar_png), "--size", "20x20", "--block", "24", "--tileable", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "size: a tileable quilt needs" in err and "Traceback" not in err
    assert not out.exists()


def test_complete_refuses_a_negative_diversity(tmp_path, exemplar_png, capsys):
    with pytest.raises(SystemExit) as e:
        main(["complete", str(exemplar_png), str(exemplar_png), "--out", str(tmp_path / "o.png"), "--diversity", "-1"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--diversity: expected a finite number >= 0, got -1" in err and "Traceback" not in err
    assert not (tmp_path / "o.png").exists()


def test_synthesize_diversity_flag(tmp_path, exemplar_png):
    outs = {}
    for d in ("0", "1"):
        outs[d] = tmp_path / f"d{d}.png"
        assert main(["synthesize", str(exemplar_png), "--size", "40x40", "--out", str(outs[d]), "--diversity", d,
                     "-q"]) == 0  # fmt: skip
    assert json.loads(io.sidecar_path(outs["1"]).read_text())["parameters"]["diversity"] == 1.0
    assert not np.array_equal(io.read_image(outs["0"]), io.read_image(outs["1"]))
    # the default is the API's
    again = tmp_path / "default.png"
    assert main(["synthesize", str(exemplar_png), "--size", "40x40", "--out", str(again), "-q"]) == 0
    assert np.array_equal(io.read_image(again), io.read_image(outs["1"]))
