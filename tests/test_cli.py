"""The phloem command: help, outputs with sidecars, no silent overwrite, clean errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from phloem import io
from phloem.cli import build_parser, main


@pytest.fixture()
def exemplar_png(tmp_path, bark):
    p = tmp_path / "ex.png"
    io.write_image(p, bark[:64, :64])
    return p


@pytest.mark.parametrize("cmd", [[], ["synthesize"], ["quilt"], ["complete"], ["nnf"], ["bark"], ["demo"]])
def test_help_explains_every_option(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        main([*cmd, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "usage: phloem" in text
    for action in build_parser()._actions:
        assert action.help  # no undocumented option at the top level


def test_every_subcommand_option_has_help():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        for action in p._actions:
            assert action.help, f"{name}: {action.dest} has no help"
            if action.dest == "action":  # nested sub-commands (phloem branching ...)
                for inner, q in action.choices.items():
                    for a in q._actions:
                        assert a.help, f"{name} {inner}: {a.dest} has no help"


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


def test_nnf_writes_npz(tmp_path, exemplar_png):
    out = tmp_path / "f.npz"
    assert main(["nnf", str(exemplar_png), str(exemplar_png), "--out", str(out), "--patch-size", "5", "-q"]) == 0
    with np.load(out) as z:
        assert z["field"].shape == (64, 64, 2) and z["distance"].shape == (64, 64)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.bmp"], "extension"),
        (["synthesize", "{tmp}/missing.png", "--size", "32x32", "--out", "{tmp}/o.png"], "no such file"),
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.png", "--patch-size", "4"], "patch_size"),
        (["synthesize", "{ex}", "--size", "32x32", "--out", "{tmp}/o.png", "--max-pixels", "100"], "over the limit"),
        (["complete", "{ex}", "{white}", "--out", "{tmp}/o.png"], "mask"),
        (["complete", "{ex}", "{small}", "--out", "{tmp}/o.png"], "mask"),
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


def test_bad_size_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["synthesize", "x.png", "--size", "big", "--out", "o.png"])
    assert e.value.code == 2 and "WIDTHxHEIGHT" in capsys.readouterr().err


def test_console_script_is_installed(tmp_path):
    r = subprocess.run([sys.executable, "-m", "phloem.cli", "--version"], capture_output=True, text=True, check=True)
    assert r.stdout.startswith("phloem ")


def test_demo_runs_on_embedded_data(tmp_path):
    out = tmp_path / "bark.png"
    assert main(["demo", "--out", str(out), "--size", "64x64", "-q"]) == 0
    assert io.read_image(out).shape == (64, 64, 3)


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
    assert meta["command"] == "bark" and meta["seed"] == 3 and meta["parameters"]["labels"] == 2
    assert set(meta["parameters"]["files"]) == {"labels_in", "labels_out", "height", "cylinder"}
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
    for name, extra in (("strict", ["--strict-labels"]), ("weight", ["--stand-in-weight", "2"])):
        outs[name] = tmp_path / f"{name}.png"
        argv = ["bark", str(exemplar_png), "--size", "48x32", "--out", str(outs[name]), "--seed", "1", "-q", *extra]
        assert main(argv) == 0
    for name, weight in (("strict", None), ("weight", 2.0)):
        expected = bark.generate(photo, (32, 48), seed=1, stand_in_weight=weight)
        np.testing.assert_allclose(io.read_image(outs[name]), expected, atol=0.5 / 255 + 1e-6)
    meta = json.loads(io.sidecar_path(outs["strict"]).read_text())
    assert meta["parameters"]["strict_labels"] is True
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


def _tree_png(path, crown: int, trunk: int) -> None:
    img = np.zeros((120, 100, 4), np.float32)
    yy, xx = np.mgrid[:120, :100]
    img[(yy - 45) ** 2 + (xx - 50) ** 2 < crown**2] = (0.1, 0.6, 0.2, 1.0)
    img[70:118, 50 - trunk : 50 + trunk] = (0.4, 0.3, 0.1, 1.0)
    io.write_image(path, img)


def test_trees_writes_variations_sidecars_and_sheet(tmp_path, capsys):
    lib = tmp_path / "lib"
    lib.mkdir()
    for i, (c, t) in enumerate([(30, 4), (40, 6), (25, 3)]):
        _tree_png(lib / f"t{i}.png", c, t)
    out = tmp_path / "out"
    sheet = tmp_path / "sheet.png"
    args = ["trees", str(lib), "--count", "3", "--out-dir", str(out), "--size", "128", "--seed", "4", "-q"]
    assert main([*args, "--sheet", str(sheet)]) == 0
    files = sorted(p.name for p in out.iterdir())
    assert files == [f"tree_{i:04d}.png{s}" for i in range(3) for s in ("", ".json")]
    meta = json.loads((out / "tree_0001.png.json").read_text())
    assert meta["seed"] == 4 and meta["parameters"]["sources"] == 2
    assert len(meta["parameters"]["exemplars"]) == 2 and set(meta["parameters"]["exemplars"]) <= {
        "t0.png",
        "t1.png",
        "t2.png",
    }
    img = io.read_image(out / "tree_0001.png")
    assert img.shape == (128, 128, 4)
    # The sidecar's variation seed reproduces the file through the Python API.
    from phloem import trees

    library = trees.Library.load(lib, size=128)
    v = trees.variation(library, seed=meta["parameters"]["variation_seed"])
    assert np.abs(v.image - img).max() <= 1 / 255 + 1e-6
    assert io.read_image(sheet).shape[2] == 3
    # No silent overwrite, and nothing half-written on refusal.
    before = (out / "tree_0000.png").read_bytes()
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert (out / "tree_0000.png").read_bytes() == before
    # Variations of a given tree.
    like = tmp_path / "mine.png"
    _tree_png(like, 35, 5)
    assert (
        main(
            [
                "trees",
                str(lib),
                "--count",
                "2",
                "--out-dir",
                str(tmp_path / "like"),
                "--size",
                "128",
                "--like",
                str(like),
                "-q",
            ]
        )
        == 0
    )
    meta = json.loads((tmp_path / "like" / "tree_0000.png.json").read_text())
    assert meta["parameters"]["exemplars"][0] == str(like) and meta["parameters"]["colors"] == "contour"
    assert 0.6 <= meta["parameters"]["weights"][0] <= 0.9


def test_trees_bad_library_is_a_clean_error(tmp_path, capsys):
    rgb = tmp_path / "rgb.png"
    io.write_image(rgb, np.ones((40, 40, 3), np.float32))
    assert main(["trees", str(rgb), "--count", "1", "--out-dir", str(tmp_path / "o"), "-q"]) == 2
    assert "rgb.png: expected an RGBA image (trees need an alpha channel)" in capsys.readouterr().err
    one = tmp_path / "one"
    one.mkdir()
    _tree_png(one / "t.png", 30, 4)
    assert main(["trees", str(one), "--count", "1", "--out-dir", str(tmp_path / "o2"), "--size", "96", "-q"]) == 2
    assert "library: has 1 tree(s) but sources=2" in capsys.readouterr().err
    assert not list((tmp_path / "o2").glob("*.png"))


def _river_png(path) -> None:
    import cv2

    img = np.zeros((160, 200), np.uint8)
    cv2.line(img, (10, 150), (100, 80), 255, 9)
    cv2.line(img, (100, 80), (190, 20), 255, 7)
    cv2.line(img, (100, 80), (120, 150), 255, 5)
    cv2.line(img, (60, 112), (30, 60), 255, 5)
    io.write_image(path, img.astype(np.float32) / 255)


def test_branching_trace_and_grow_write_skeletons_with_sidecars(tmp_path, capsys):
    from phloem.branching import Skeleton

    _river_png(tmp_path / "river.png")
    skel = tmp_path / "river.json"
    assert main(["branching", "trace", str(tmp_path / "river.png"), "--kind", "mask", "--out", str(skel),
                 "--overlay", str(tmp_path / "overlay.png"), "-q"]) == 0  # fmt: skip
    sk = Skeleton.load(skel)
    assert sk.shape == (160, 200) and len(sk.branches) >= 3
    assert json.loads((tmp_path / "river.json.json").read_text())["command"] == "branching trace"
    assert io.read_image(tmp_path / "overlay.png").shape == (160, 200, 3)
    new = tmp_path / "new.json"
    args = [
        "branching",
        "grow",
        str(skel),
        "--out",
        str(new),
        "--seed",
        "5",
        "--histograms",
        str(tmp_path / "h.png"),
        "-q",
    ]
    assert main(args) == 0
    grown = Skeleton.load(new)
    assert grown.shape == (160, 200) and len(grown.branches) >= 1
    assert json.loads((tmp_path / "new.json.json").read_text())["seed"] == 5
    # Same seed, same skeleton; no silent overwrite.
    assert main(["branching", "grow", str(skel), "--out", str(tmp_path / "again.json"), "--seed", "5", "-q"]) == 0
    assert Skeleton.load(tmp_path / "again.json") == grown
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err


def test_branching_errors_name_the_problem(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"branches": [{"points": [[1, 2]]}]}')
    assert main(["branching", "grow", str(bad), "--out", str(tmp_path / "x.json"), "-q"]) == 2
    assert "branches[0]: a branch needs at least 2 points" in capsys.readouterr().err
    bad.write_text("{not json")
    assert main(["branching", "grow", str(bad), "--out", str(tmp_path / "x.json"), "-q"]) == 2
    assert "not a valid JSON skeleton" in capsys.readouterr().err
    io.write_image(tmp_path / "blank.png", np.zeros((40, 40), np.float32))
    assert main(["branching", "trace", str(tmp_path / "blank.png"), "--out", str(tmp_path / "y.json"), "-q"]) == 2
    assert "nothing to trace" in capsys.readouterr().err
    assert main(["branching", "trace", str(tmp_path / "blank.png"), "--out", str(tmp_path / "y.png"), "-q"]) == 2
    assert "expected a .json file" in capsys.readouterr().err
    assert not list(tmp_path.glob("x.json*")) and not list(tmp_path.glob("y.*"))


def _dark_river_png(path) -> None:
    import cv2

    img = np.full((120, 160, 3), (0.55, 0.6, 0.35), np.float32)
    rng = np.random.default_rng(0)
    img += rng.normal(0, 0.03, img.shape).astype(np.float32)
    for a, b, t in [((5, 110), (80, 60), 7), ((80, 60), (155, 10), 5), ((80, 60), (100, 115), 4)]:
        cv2.line(img, a, b, (0.1, 0.15, 0.4), t)
    io.write_image(path, img.clip(0, 1))


def test_branching_run_writes_image_skeleton_histograms_and_sidecar(tmp_path):
    from phloem.branching import Skeleton

    _dark_river_png(tmp_path / "river.png")
    out = tmp_path / "new.png"
    args = ["branching", "run", str(tmp_path / "river.png"), "--kind", "dark", "--sigmas", "2", "3",
            "--out", str(out), "--seed", "2", "--fragment-map", str(tmp_path / "fm.png"), "-q"]  # fmt: skip
    assert main(args) == 0
    img = io.read_image(out)
    assert img.shape == (120, 160, 3)
    target = Skeleton.load(tmp_path / "new_skeleton.json")
    assert target.shape == (120, 160) and target.branches
    assert io.read_image(tmp_path / "new_histograms.png").shape[2] == 3
    meta = json.loads((tmp_path / "new.png.json").read_text())
    assert meta["seed"] == 2 and meta["parameters"]["max_length"] == "input"
    # The painted structure is dark like the input's river; the rest keeps the land's colour.
    river = target.mask()
    assert img[river].mean() < img[~river].mean() - 0.1
    # render from the written skeletons reproduces the run's image (same seed).
    sk = tmp_path / "src.json"
    assert (
        main(
            [
                "branching",
                "trace",
                str(tmp_path / "river.png"),
                "--kind",
                "dark",
                "--sigmas",
                "2",
                "3",
                "--out",
                str(sk),
                "-q",
            ]
        )
        == 0
    )
    again = tmp_path / "again.png"
    assert main(["branching", "render", str(tmp_path / "river.png"), str(sk), str(tmp_path / "new_skeleton.json"),
                 "--out", str(again), "--seed", "2", "-q"]) == 0  # fmt: skip
    assert np.abs(io.read_image(again) - img).max() <= 1 / 255 + 1e-6
    assert main(args) == 2  # no silent overwrite
