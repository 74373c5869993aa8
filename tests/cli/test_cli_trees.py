"""phloem trees: variations with sidecars and a contact sheet; bad libraries."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phloem import io
from phloem.cli import main


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
    args = ["trees", str(lib), "--n-variations", "3", "--out-dir", str(out), "--size", "128", "--seed", "4", "-q"]
    assert main([*args, "--sheet", str(sheet)]) == 0
    files = sorted(p.name for p in out.iterdir())
    assert files == [f"tree_{i:04d}.png{s}" for i in range(3) for s in ("", ".json")]
    meta = json.loads((out / "tree_0001.png.json").read_text())
    assert meta["seed"] == 4 and meta["parameters"]["n_sources"] == 2
    assert len(meta["details"]["exemplars"]) == 2 and set(meta["details"]["exemplars"]) <= {
        "t0.png",
        "t1.png",
        "t2.png",
    }
    img = io.read_image(out / "tree_0001.png")
    assert img.shape == (128, 128, 4)
    # The sidecar's variation seed reproduces the file through the Python API.
    from phloem import trees

    library = trees.Library.load(lib, size=128)
    v = trees.variation(library, seed=meta["details"]["variation_seed"])
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
                "--n-variations",
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
    assert meta["details"]["exemplars"][0] == str(like) and meta["parameters"]["colors"] == "contour"
    assert 0.6 <= meta["details"]["weights"][0] <= 0.9


def test_trees_bad_library_is_a_clean_error(tmp_path, capsys):
    rgb = tmp_path / "rgb.png"
    io.write_image(rgb, np.ones((40, 40, 3), np.float32))
    assert main(["trees", str(rgb), "--n-variations", "1", "--out-dir", str(tmp_path / "o"), "-q"]) == 2
    assert "rgb.png: expected an RGBA image (trees need an alpha channel)" in capsys.readouterr().err
    one = tmp_path / "one"
    one.mkdir()
    _tree_png(one / "t.png", 30, 4)
    assert (
        main(["trees", str(one), "--n-variations", "1", "--out-dir", str(tmp_path / "o2"), "--size", "96", "-q"]) == 2
    )
    assert "LIBRARY: has 1 tree(s) but --n-sources=2" in capsys.readouterr().err
    assert not list((tmp_path / "o2").glob("*.png"))


def test_old_count_and_sources_flags_warn_and_give_the_same_trees(tmp_path, capsys):
    lib = tmp_path / "lib"
    lib.mkdir()
    for i, (c, t) in enumerate([(30, 4), (40, 6), (25, 3)]):
        _tree_png(lib / f"t{i}.png", c, t)
    outs = {}
    for name, flags in (
        ("old", ["--count", "1", "--sources", "3"]),
        ("new", ["--n-variations", "1", "--n-sources", "3"]),
    ):
        outs[name] = tmp_path / name
        assert main(["trees", str(lib), "--out-dir", str(outs[name]), "--size", "96", "-q", *flags]) == 0
        err = capsys.readouterr().err
        if name == "old":
            assert "--count is deprecated and goes in the next release; use --n-variations" in err
            assert "--sources is deprecated and goes in the next release; use --n-sources" in err
        else:
            assert err == ""
    assert (outs["old"] / "tree_0000.png").read_bytes() == (outs["new"] / "tree_0000.png").read_bytes()
    with pytest.raises(SystemExit) as e:  # one of --n-variations (or the old --count) is required
        main(["trees", str(lib), "--out-dir", str(tmp_path / "none"), "-q"])
    assert e.value.code == 2 and "--n-variations" in capsys.readouterr().err
