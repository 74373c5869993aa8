"""Library.save / load_prepared and Library.load(cache=): a prepared library kept on disk, and
rebuilt when its images or options change (issue 21)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import phloem
from phloem import trees
from phloem.cli import main
from phloem.trees import library as library_module


def test_save_load_prepared_round_trip(library, tmp_path: Path):
    library.save(tmp_path / "lib", key="k1")
    back = trees.Library.load_prepared(tmp_path / "lib", key="k1")
    assert back.names == library.names
    for a, b in zip(back, library):
        for name in ("image", "trunk", "contour", "resampled", "simplified", "outline"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and np.array_equal(x, y), name
        assert (a.pins, a.split, a.dilation) == (b.pins, b.split, b.dilation)
    # the same variation from either
    v1 = trees.variation(library, seed=3)
    v2 = trees.variation(back, seed=3)
    assert np.array_equal(v1.image, v2.image)
    with pytest.raises(ValueError, match=r"^path: .*other images or options \(stale\)"):
        trees.Library.load_prepared(tmp_path / "lib", key="k2")
    with pytest.raises(FileExistsError, match=r"already exists"):
        library.save(tmp_path / "lib")
    (tmp_path / "lib" / "trees.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"^path: .*trees.npz cannot be read as a prepared tree library"):
        trees.Library.load_prepared(tmp_path / "lib")
    with pytest.raises(ValueError, match=r"^path: .* is not a folder written by Library.save"):
        trees.Library.load_prepared(tmp_path / "none")


def test_load_prepared_reads_only_the_trees_used(library, tmp_path: Path, monkeypatch):
    """A variation reads its two exemplars from the folder, not the whole library; a tree
    damaged in the archive raises a one-line error when it is first used."""
    import pickle
    import zipfile

    from phloem.trees import _stored

    library.save(tmp_path / "lib")
    back = trees.Library.load_prepared(tmp_path / "lib")
    read: list[int] = []
    real = _stored.StoredTrees._read

    def counting(self, i):
        read.append(i)
        return real(self, i)

    monkeypatch.setattr(_stored.StoredTrees, "_read", counting)
    v = trees.variation(back, seed=3)
    assert sorted(read) == sorted(i for i in v.sources if i != 0)  # tree 0 is read on load
    assert np.array_equal(v.image, trees.variation(library, seed=3).image)
    trees.variation(back, seed=3)
    assert len(read) == len([i for i in v.sources if i != 0])  # kept once read
    assert back[-1] is back.trees[3] and [t.pins for t in back.trees[1:3]] == [t.pins for t in library.trees[1:3]]
    # a pickled library (e.g. sent to another process) carries its trees
    again = pickle.loads(pickle.dumps(back))
    assert isinstance(again.trees, list) and all(np.array_equal(a.image, b.image) for a, b in zip(again, library))
    # the archive with tree 2's image replaced by one of another size
    src = zipfile.ZipFile(tmp_path / "lib" / "trees.npz")
    members = {n: src.read(n) for n in src.namelist()}
    src.close()
    members["image_2.npy"] = members["trunk_2.npy"]
    with zipfile.ZipFile(tmp_path / "lib" / "trees.npz", "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    damaged = trees.Library.load_prepared(tmp_path / "lib")
    assert damaged[1].pins == library[1].pins
    with pytest.raises(ValueError, match=r"^path: .*trees.npz cannot be read as a prepared tree library \(tree 2: "):
        damaged[2]
    # a tree missing from the archive is refused on load
    del members["outline_3.npy"]
    with zipfile.ZipFile(tmp_path / "lib" / "trees.npz", "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    with pytest.raises(ValueError, match=r"^path: .*trees.npz cannot be read as a prepared tree library \(KeyError\)"):
        trees.Library.load_prepared(tmp_path / "lib")


def test_cache_reused_then_rebuilt_when_stale(ragged_tree, tmp_path: Path, monkeypatch):
    src = tmp_path / "src"
    src.mkdir()
    for s in range(2):
        phloem.io.write_image(src / f"t{s}.png", ragged_tree(s))
    cache = tmp_path / "cache"
    prepared: list[int] = []
    real = trees.Library._prepare_files.__func__

    def counting(cls, files, *args, **kwargs):
        prepared.append(len(files))
        return real(cls, files, *args, **kwargs)

    monkeypatch.setattr(trees.Library, "_prepare_files", classmethod(counting))
    first = trees.Library.load(src, size=128, cache=cache)
    assert prepared == [2] and len(list(cache.iterdir())) == 1
    library_module._loaded.clear()  # as a new process would: read from the cache folder
    again = trees.Library.load(src, size=128, cache=cache)
    assert prepared == [2]
    assert all(np.array_equal(a.image, b.image) for a, b in zip(first, again))
    # same image count and names, other bytes: the stored hash no longer matches, so it is rebuilt
    phloem.io.write_image(src / "t1.png", ragged_tree(5), overwrite=True)
    library_module._loaded.clear()
    rebuilt = trees.Library.load(src, size=128, cache=cache)
    assert prepared == [2, 2]
    assert not np.array_equal(rebuilt[1].image, first[1].image)
    assert len(list(cache.iterdir())) == 1  # the stale entry was replaced, not kept beside
    # another option is another entry
    trees.Library.load(src, size=96, cache=cache)
    assert prepared == [2, 2, 2] and len(list(cache.iterdir())) == 2


def test_cli_library_cache_same_files(ragged_tree, tmp_path: Path):
    src = tmp_path / "src"
    src.mkdir()
    for s in range(2):
        phloem.io.write_image(src / f"t{s}.png", ragged_tree(s))
    args = [str(src), "--n-variations", "2", "--size", "96", "-q"]
    assert main(["trees", *args, "--out-dir", str(tmp_path / "a")]) == 0
    for out in ("b", "c"):  # b prepares and stores the library, c reads it
        assert main(["trees", *args, "--out-dir", str(tmp_path / out), "--library-cache", str(tmp_path / "k")]) == 0
        library_module._loaded.clear()
    for name in ("tree_0000.png", "tree_0001.png"):
        data = (tmp_path / "a" / name).read_bytes()
        assert data == (tmp_path / "b" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()
    side = (tmp_path / "b" / "tree_0000.png.json").read_text()
    assert '"library_cache"' not in side  # where a library was kept says nothing about the trees


def test_cache_read_once_per_process(ragged_tree, tmp_path: Path, monkeypatch):
    """A batch worker runs many items on one library: it reads the cache folder once."""
    src = tmp_path / "src"
    src.mkdir()
    phloem.io.write_image(src / "t0.png", ragged_tree(0))
    cache = tmp_path / "cache"
    trees.Library.load(src, size=96, cache=cache)
    library_module._loaded.clear()
    reads: list[Path] = []
    real = trees.Library.load_prepared.__func__

    def counting(cls, path, **kwargs):
        reads.append(Path(path))
        return real(cls, path, **kwargs)

    monkeypatch.setattr(trees.Library, "load_prepared", classmethod(counting))
    libs = [trees.Library.load(src, size=96, cache=cache) for _ in range(3)]
    assert len(reads) == 1 and libs[0] is libs[1] is libs[2]
    # a touched image is looked at again (its bytes decide whether the entry is stale)
    os.utime(src / "t0.png", ns=(1, 1))
    trees.Library.load(src, size=96, cache=cache)
    assert len(reads) == 2
