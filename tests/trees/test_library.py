"""phloem.trees.library: the library of prepared exemplars, from images, folders and atlases (§3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import trees


def test_library_errors_and_folders(library, ragged_tree, tmp_path: Path):
    with pytest.raises(ValueError, match=r"^trees: a library needs at least one tree"):
        trees.Library([])
    other = trees.prepare(ragged_tree(0), size=128)
    with pytest.raises(ValueError, match=r"another size"):
        trees.Library([library[0], other])
    # Folders: an RGB image, a fully transparent one, a good one.
    phloem.io.write_image(tmp_path / "rgb.png", np.ones((50, 40, 3), np.float32))
    phloem.io.write_image(tmp_path / "empty.png", np.zeros((50, 40, 4), np.float32))
    phloem.io.write_image(tmp_path / "tree.png", ragged_tree(0))
    with pytest.raises(ValueError, match=r"empty.png: "):
        trees.Library.load(tmp_path, size=128)
    lib = trees.Library.load(tmp_path, size=128, skip_bad=True)
    assert lib.names == ["tree.png"]
    with pytest.raises(ValueError, match=r"^path: .* does not exist"):
        trees.Library.load(tmp_path / "none")
    assert trees.Library.load(tmp_path / "tree.png", size=128).names == ["tree.png"]  # one image


def test_library_load_splits_atlases(ragged_tree, tmp_path: Path):
    atlas = np.zeros((300, 460, 4), np.float32)
    atlas[:, :220] = ragged_tree(0)
    atlas[:, 240:] = ragged_tree(1)
    phloem.io.write_image(tmp_path / "atlas.png", atlas)
    lib = trees.Library.load(tmp_path, size=128)
    assert lib.names == ["atlas.png[0]", "atlas.png[1]"]
    whole = trees.Library.load(tmp_path, size=128, atlas="no")
    assert whole.names == ["atlas.png"]


def test_library_load_collects_only_what_read_image_reads(ragged_tree, tmp_path: Path):
    from PIL import Image

    tree = (np.clip(ragged_tree(0), 0, 1) * 255).round().astype(np.uint8)
    Image.fromarray(tree, "RGBA").save(tmp_path / "a.webp", lossless=True, exact=True)  # read, not refused
    phloem.io.write_image(tmp_path / "b.png", ragged_tree(1))
    phloem.io.write_image(tmp_path / "c.jpg", ragged_tree(1)[..., :3])  # no alpha: not collected
    (tmp_path / "d.bmp").write_bytes(b"BM")  # not an image we read: not collected
    lib = trees.Library.load(tmp_path, size=128, atlas="no")
    assert lib.names == ["a.webp", "b.png"]
    np.testing.assert_allclose(lib[0].image, trees.prepare(tree / np.float32(255), size=128).image)
