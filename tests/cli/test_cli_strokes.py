"""phloem strokes edit|draw: files, sidecars, the contact sheet, no silent overwrite, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phloem import io, strokes
from phloem.cli import main
from phloem.strokes import StrokeSet


@pytest.fixture()
def files(tmp_path):
    img = np.zeros((60, 160, 4), np.float32)
    img[20:41, 10:150] = [0.5, 0.4, 0.3, 1.0]
    img[20:41, 10:150:6, :3] = 0.2
    io.write_image(tmp_path / "bar.png", img)
    sset = StrokeSet.from_lists([[[12, 30], [147, 30]]], [[[20, 100], [90, 30], [150, 90]]], target_size=(120, 170))
    sset.save(tmp_path / "strokes.json")
    svg = tmp_path / "strokes.svg"
    svg.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="160" height="60">'
        '<g id="source"><path d="M12 30 L147 30" stroke="red"/></g>'
        '<g id="target"><path d="M20 50 L150 50" stroke="blue"/></g></svg>'
    )
    return img, sset, tmp_path


def test_edit_writes_the_result_its_sidecar_and_a_sheet(files) -> None:
    img, sset, d = files
    out, sheet = d / "out.png", d / "sheet.png"
    args = ["strokes", "edit", str(d / "bar.png"), str(d / "strokes.json"), "--out", str(out), "--sheet", str(sheet)]
    assert main([*args, "-q"]) == 0
    got = io.read_image(out)
    want = strokes.edit(img, sset)
    assert got.shape == (120, 170, 4)
    assert np.abs(got - want).max() <= 1 / 255 + 1e-6  # the API's result, as 8-bit PNG
    meta = json.loads((d / "out.png.json").read_text())
    assert meta["command"] == "strokes edit" and meta["parameters"]["sampling"] == "dp"
    assert io.read_image(sheet).shape[:2] == (320, 5 * 320)


def test_edit_reads_svg_layers_and_a_mask(files, tmp_path) -> None:
    img, _, d = files
    rgb = img[..., :3] * img[..., 3:] + 0.9 * (1 - img[..., 3:])
    io.write_image(d / "photo.png", rgb)
    io.write_image(d / "mask.png", img[..., 3])
    out = d / "svg.png"
    args = ["strokes", "edit", str(d / "photo.png"), str(d / "strokes.svg"), "--mask", str(d / "mask.png"), "--out", str(out), "-q"]  # fmt: skip
    assert main(args) == 0
    got = io.read_image(out)
    assert got.shape == (60, 160, 4) and got[50, 80, 3] == 1.0 and got[20, 80, 3] == 0.0


def test_edit_takes_target_widths_from_the_svg_when_asked(files) -> None:
    _, _, d = files
    svg = d / "wide.svg"
    svg.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="160" height="100">'
        '<g id="source"><path d="M12 30 L147 30"/></g>'
        '<g id="target" style="stroke-width:42"><path d="M20 50 L150 50"/></g></svg>'
    )
    heights = []
    for extra in ([], ["--svg-widths"]):
        out = d / f"w{len(extra)}.png"
        assert main(["strokes", "edit", str(d / "bar.png"), str(svg), "--size", "160x100", "--out", str(out), *extra, "-q"]) == 0  # fmt: skip
        heights.append(int((io.read_image(out)[:, 60:100, 3] > 0.5).all(axis=1).sum()))
    assert 18 <= heights[0] <= 23 and 38 <= heights[1] <= 44  # the bar's 21 px, then the drawn 42
    assert main(["strokes", "edit", str(d / "bar.png"), str(d / "strokes.json"), "--out", str(d / "j.png"), "--svg-widths", "-q"]) == 2  # fmt: skip


def test_draw_marks_the_strokes(files) -> None:
    _, _, d = files
    for side in ("source", "target"):
        out = d / f"{side}.png"
        assert main(["strokes", "draw", str(d / "bar.png"), str(d / "strokes.json"), "--side", side, "--out", str(out), "-q"]) == 0  # fmt: skip
        pic = io.read_image(out)
        assert pic.shape[:2] == ((60, 160) if side == "source" else (120, 170))
        assert (pic[..., 0] > 0.8).any() and (pic[..., 1] < 0.3).any()  # the first stroke is red


@pytest.mark.parametrize(
    ("extra", "content", "message"),
    [
        ([], '{"format": "phloem.strokes", "version": 1, "pairs": []}', "'pairs' must be a non-empty list"),
        ([], "{not json", "strokes"),
        (["--stretch", "0.5"], None, "stretch"),
        (["--mask", "MISSING.png"], None, "MISSING.png"),
    ],
)
def test_bad_input_is_a_one_line_error(files, capsys, extra, content, message) -> None:
    _, _, d = files
    path = d / "strokes.json"
    if content is not None:
        path = d / "bad.json"
        path.write_text(content)
    args = ["strokes", "edit", str(d / "bar.png"), str(path), "--out", str(d / "x.png"), *extra, "-q"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (d / "x.png").exists() and not (d / "x.png.json").exists()


def test_nothing_is_overwritten_without_force(files, capsys) -> None:
    _, _, d = files
    (d / "out.png").write_bytes(b"keep")
    args = ["strokes", "edit", str(d / "bar.png"), str(d / "strokes.json"), "--out", str(d / "out.png"), "-q"]
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err and (d / "out.png").read_bytes() == b"keep"
    assert main([*args, "--force"]) == 0 and (d / "out.png").read_bytes() != b"keep"


def test_edit_pastes_into_a_background(files) -> None:
    _, _, d = files
    io.write_image(d / "scene.png", np.full((120, 170, 3), 0.3, np.float32))
    out = d / "scene_out.png"
    args = ["strokes", "edit", str(d / "bar.png"), str(d / "strokes.json"), "--background", str(d / "scene.png")]
    assert main([*args, "--out", str(out), "-q"]) == 0
    got = io.read_image(out)
    assert got.shape[:2] == (120, 170) and (got.shape[2] == 3 or np.all(got[..., 3] == 1.0))
    assert abs(float(got[5, 5, 0]) - 0.3) < 1 / 255 + 1e-6
