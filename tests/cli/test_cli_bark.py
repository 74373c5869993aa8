"""phloem bark: texture, label maps, preview and sidecar; resuming; stand-ins; errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phloem import io
from phloem.cli import main


def test_bark_writes_texture_maps_preview_and_sidecar(tmp_path, exemplar_png):
    out = tmp_path / "b.png"
    hm = tmp_path / "hm.png"
    io.write_image(hm, io.read_image(exemplar_png).mean(axis=2))
    prev = tmp_path / "trunk.png"
    args = ["bark", str(exemplar_png), "--size", "56x40", "--out", str(out), "--height-map", str(hm),
            "--keep-intermediates", "--cylinder-preview", str(prev), "--seed", "3", "-q"]  # fmt: skip
    assert main(args) == 0
    assert io.read_image(out).shape == (40, 56, 3)
    maps = {name: io.read_image(tmp_path / f"b_{name}.png") for name in ("labels_in", "labels_out", "height")}
    assert maps["labels_in"].shape == (64, 64) and len(np.unique(maps["labels_in"])) == 2
    assert maps["labels_out"].shape == (40, 56) and maps["height"].shape == (40, 56)
    assert io.read_image(prev).shape[0] == 40
    meta = json.loads(io.sidecar_path(out).read_text())
    assert meta["command"] == "bark" and meta["seed"] == 3 and meta["parameters"]["n_labels"] == 2
    assert set(meta["details"]["files"]) == {"labels_in", "labels_out", "height", "cylinder"}
    # everything exists now: a second run refuses before computing, and leaves the files alone
    before = out.stat().st_mtime_ns
    assert main(args) == 2
    assert out.stat().st_mtime_ns == before


def test_bark_resumes_from_an_edited_label_map(tmp_path, exemplar_png):
    first = tmp_path / "first.png"
    assert main(["bark", str(exemplar_png), "--size", "48x32", "--out", str(first), "--keep-intermediates", "-q"]) == 0
    edited = io.read_image(tmp_path / "first_labels_out.png")
    edited[:, :20] = 0.0  # paint the left part with the darker region
    io.write_image(tmp_path / "edited.png", edited)
    out = tmp_path / "second.png"
    args = ["bark", str(exemplar_png), "--labels-in", str(tmp_path / "first_labels_in.png"),
            "--labels-out", str(tmp_path / "edited.png"), "--out", str(out), "-q"]  # fmt: skip
    assert main(args) == 0
    assert io.read_image(out).shape == (32, 48, 3)


def test_bark_stand_in_options_reach_the_library(tmp_path, exemplar_png):
    from phloem import bark

    photo = io.read_image(exemplar_png)
    outs = {}
    for name, extra in (("strict", ["--stand-in-weight", "none"]), ("weight", ["--stand-in-weight", "2"])):
        outs[name] = tmp_path / f"{name}.png"
        argv = ["bark", str(exemplar_png), "--size", "48x32", "--out", str(outs[name]), "--seed", "1", "-q", *extra]
        assert main(argv) == 0
    for name, weight in (("strict", None), ("weight", 2.0)):
        expected = bark.generate(photo, (32, 48), seed=1, stand_in_weight=weight)
        np.testing.assert_allclose(io.read_image(outs[name]), expected, atol=0.5 / 255 + 1e-6)
    meta = json.loads(io.sidecar_path(outs["strict"]).read_text())
    assert meta["parameters"]["stand_in_weight"] is None
    with pytest.raises(SystemExit) as exc:
        main(
            ["bark", str(exemplar_png), "--size", "32x32", "--stand-in-weight", "-1", "--out", str(tmp_path / "o.png")]
        )
    assert exc.value.code == 2


def test_bark_errors_name_the_problem(tmp_path, exemplar_png, capsys):
    io.write_image(tmp_path / "noisy.png", np.random.default_rng(0).random((20, 20)).astype(np.float32))
    cases = [
        (["bark", str(exemplar_png), "--out", str(tmp_path / "o.png")], "size: required"),
        (
            ["bark", str(exemplar_png), "--labels-out", str(tmp_path / "noisy.png"), "--out", str(tmp_path / "o.png")],
            "distinct colours",
        ),
        (
            [
                "bark",
                str(exemplar_png),
                "--size",
                "32x32",
                "--out",
                str(tmp_path / "o.png"),
                "--cylinder-preview",
                str(tmp_path / "o.png"),
            ],
            "different files",
        ),
    ]
    for argv, message in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize(
    ("old", "new", "use"),
    [
        (["--labels", "3"], ["--n-labels", "3"], "--n-labels"),
        (["--strict-labels"], ["--stand-in-weight", "none"], "--stand-in-weight none"),
    ],
)
def test_old_flags_warn_and_give_the_same_file(tmp_path, exemplar_png, capsys, old, new, use):
    outs = {}
    for name, flags in (("old", old), ("new", new)):
        outs[name] = tmp_path / f"{name}.png"
        argv = ["bark", str(exemplar_png), "--size", "40x32", "--out", str(outs[name]), "--seed", "1", "-q", *flags]
        assert main(argv) == 0
        expected = f"phloem bark: warning: {old[0]} is deprecated and goes in the next release; use {use}\n"
        assert capsys.readouterr().err == (expected if name == "old" else "")
    assert io.read_image(outs["old"]).tobytes() == io.read_image(outs["new"]).tobytes()
    old_meta, new_meta = (json.loads(io.sidecar_path(p).read_text())["parameters"] for p in outs.values())
    assert {**old_meta, "out": None} == {**new_meta, "out": None}


def test_rotations_words_are_the_python_values(tmp_path, exemplar_png):
    from phloem import bark, shapes
    from phloem.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    rot = next(a for a in sub.choices["bark"]._actions if a.dest == "rotations")
    assert tuple(rot.choices) == shapes.ROTATIONS
    out = tmp_path / "all.png"
    assert main(["bark", str(exemplar_png), "--size", "40x32", "--rotations", "all", "--out", str(out), "-q"]) == 0
    expected = bark.generate(io.read_image(exemplar_png), (32, 40), rotations="all")
    np.testing.assert_allclose(io.read_image(out), expected, atol=0.5 / 255 + 1e-6)
