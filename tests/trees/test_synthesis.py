"""phloem.trees.synthesis: random variations from a library and of a user's tree (§3, §5)."""

from __future__ import annotations

import numpy as np
import pytest

import phloem
from phloem import trees


def test_variation_deterministic_for_seed_and_threads(library):
    a = trees.variation(library, seed=11, threads=1)
    b = trees.variation(library, seed=11, threads=2)
    c = trees.variation(library, seed=12)
    assert np.array_equal(a.image, b.image) and a.sources == b.sources
    assert not np.array_equal(a.image, c.image)
    assert len(set(a.sources)) == 2
    assert 0.3 <= a.weights[0] <= 0.7 and a.weights.sum() == pytest.approx(1.0)
    rec = a.describe(library)
    assert set(rec["exemplars"]) <= {"a", "b", "c", "d"}


@pytest.mark.parametrize("colors", ["random", "contour", "single"])
def test_variation_colour_weights(library, colors):
    v = trees.variation(library, seed=4, n_sources=3, colors=colors)
    assert len(v.sources) == 3 and v.color_weights.sum() == pytest.approx(1.0)
    if colors == "contour":
        assert np.array_equal(v.color_weights, v.weights)
    if colors == "single":
        assert sorted(v.color_weights.tolist()) == [0.0, 0.0, 1.0]


def test_variation_histogram_reference(library):
    v = trees.variation(library, seed=2, histogram=True)
    assert v.reference is not None and v.reference not in v.sources


def test_vary_gives_the_tree_the_higher_weight(library, ragged_tree):
    own = ragged_tree(9, crown=(75, 55))
    vs = trees.vary(own, library, n_variations=3, seed=5)
    assert len(vs) == 3
    for v in vs:
        assert 0.6 <= v.weights[0] <= 0.9 and v.weights.sum() == pytest.approx(1.0)
        assert np.array_equal(v.color_weights, v.weights)
        assert v.image.shape == (library.size, library.size, 4)
    again = trees.vary(own, library, n_variations=3, seed=5)
    assert all(np.array_equal(x.image, y.image) for x, y in zip(vs, again))


def test_vary_reports_each_finished_variation_and_stops_on_an_exception(library, ragged_tree):
    own = trees.prepare(ragged_tree(9, crown=(75, 55)), size=library.size)
    calls = []
    vs = trees.vary(own, library, n_variations=3, seed=5, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    plain = trees.vary(own, library, n_variations=3, seed=5)
    assert all(np.array_equal(x.image, y.image) for x, y in zip(vs, plain))

    class Stop(Exception):
        pass

    def stop(done, total):
        calls.append((done, total))
        raise Stop

    calls.clear()
    with pytest.raises(Stop):
        trees.vary(own, library, n_variations=3, seed=5, progress=stop)
    assert calls == [(1, 3)]


def test_variation_errors(library, ragged_tree):
    one = trees.Library([library[0]], ["only"])
    with pytest.raises(ValueError, match=r"^library: has 1 tree\(s\) but n_sources=2"):
        trees.variation(one)
    with pytest.raises(TypeError, match=r"^library: expected a phloem.trees.Library"):
        trees.variation([library[0]])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^colors"):
        trees.variation(library, colors="mean")
    with pytest.raises(ValueError, match=r"^n_sources: a variation of a tree"):
        trees.vary(ragged_tree(0), library, n_variations=1, n_sources=1)


@pytest.mark.shared
def test_flightgear_variations_are_tree_like():
    from phloem.testing import shared_file

    atlas = phloem.io.read_image(shared_file("trees", "flightgear_atlas_coniferous.png"))
    lib = trees.Library.from_images(trees.split_atlas(atlas)[:4], size=512)
    for seed in range(3):
        v = trees.variation(lib, seed=seed)
        a = v.image[..., 3] > 0.5
        srcs = [lib[i].image[..., 3] > 0.5 for i in v.sources]
        # Opaque area between the sources' (within 25 %), standing on the bottom edge.
        lo, hi = min(s.sum() for s in srcs), max(s.sum() for s in srcs)
        assert 0.75 * lo <= a.sum() <= 1.25 * hi
        assert a[-3:].any()


def test_degenerate_exemplars_give_valid_trees_or_clear_errors(library):
    size = library.size
    stick = np.zeros((120, 60, 4), np.float32)
    stick[5:118, 30] = (0.9, 0.9, 0.8, 1.0)  # a one-pixel stick: a contour without area
    t = trees.prepare(stick, size=size)
    assert np.isfinite(t.resampled).all() and len(t.resampled) == 2000
    lib = trees.Library([t, library[0]], ["stick", "a"])
    out = trees.variation(lib, seed=0).image
    assert np.isfinite(out).all() and out[..., 3].max() > 0
    with pytest.raises(ValueError, match=r"^rgba: expected some pixels with alpha"):
        trees.prepare(np.zeros((30, 30, 4), np.float32))
    with pytest.raises(ValueError, match=r"^rgba: expected an RGBA image"):
        trees.prepare(np.ones((30, 30, 3), np.float32))
    with pytest.raises(ValueError, match=r"^target: the contour is degenerate"):
        trees.cages(np.zeros((2000, 2)), [t], (size, size))
