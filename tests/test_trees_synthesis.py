"""Tree synthesis (Argudo et al. 2017 §5): contour space, preliminary alpha, matching cages,
MVC colour transfer from several exemplars, histogram transfer, the library and variations."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

import phloem
from phloem import trees

SIZE = 256


def _tree(seed: int, *, crown=(70, 60), trunk_w: int = 16, trunk_h: int = 90) -> np.ndarray:
    """A synthetic RGBA tree: a ragged ellipse crown of leafy noise on a brown trunk."""
    rng = np.random.default_rng(seed)
    h, w = 300, 220
    img = np.zeros((h, w, 4), np.float32)
    cx, bottom = w // 2, h - 5
    top = bottom - trunk_h
    img[top:bottom, cx - trunk_w // 2 : cx + trunk_w // 2] = (0.45, 0.3, 0.15, 1.0)
    crown_mask = np.zeros((h, w), np.uint8)
    cv2.ellipse(crown_mask, (cx, top - crown[1] + 15), crown, 0, 0, 360, 1, -1)
    for _ in range(40):  # ragged outline
        a = rng.uniform(0, 2 * np.pi)
        x, y = cx + crown[0] * np.cos(a), top - crown[1] + 15 + crown[1] * np.sin(a)
        cv2.circle(crown_mask, (int(x), int(y)), int(rng.integers(4, 12)), 1, -1)
    leaf = rng.uniform(0.3, 0.8, (h, w)).astype(np.float32)
    on = crown_mask > 0
    img[on, 0] = 0.1 * leaf[on]
    img[on, 1] = leaf[on]
    img[on, 2] = 0.2 * leaf[on]
    img[on, 3] = 1.0
    return img


@pytest.fixture(scope="module")
def library() -> trees.Library:
    imgs = [
        _tree(0),
        _tree(1, crown=(50, 80), trunk_h=70),
        _tree(2, crown=(90, 45), trunk_w=24),
        _tree(3, crown=(60, 60)),
    ]
    return trees.Library.from_images(imgs, names=["a", "b", "c", "d"], size=SIZE)


# --- contour space (§5.1) --------------------------------------------------------------------


def test_fill_contour_matches_polygon_fill_and_handles_self_intersection():
    rng = np.random.default_rng(1)
    a = np.sort(rng.uniform(0, 2 * np.pi, 30))
    r = rng.uniform(20, 40, 30)
    poly = np.stack([50 + r * np.cos(a), 50 + r * np.sin(a)], axis=1)
    got = trees.fill_contour(poly, (100, 100))
    ref = np.zeros((100, 100), np.uint8)
    cv2.fillPoly(ref, [np.round(poly).astype(np.int32)], 1)
    # The same pixels up to the rasterisation of the outline itself.
    assert (got != (ref > 0)).sum() < 0.03 * ref.sum()
    assert got[50, 50] and not got[0, 0]
    # A figure eight: both lobes kept, the notch between them (outside) cleared.
    eight = [(10, 10), (40, 40), (40, 10), (10, 40)]
    m = trees.fill_contour(eight, (50, 50))
    assert m[25, 12] and m[25, 38] and not m[12, 25] and not m[38, 25]
    # A contour partly outside the image.
    big = trees.fill_contour([(-20, -20), (30, -20), (30, 30), (-20, 30)], (50, 50))
    assert big[:30, :30].all() and not big[35:, 35:].any()


def test_combine_contours_endpoints_and_errors(library):
    a, b = library[0].resampled, library[1].resampled
    # A morph at t = 0 and t = 1 reproduces the two exemplars' contours exactly.
    assert np.array_equal(trees.combine_contours([a, b], [1.0, 0.0]), a)
    assert np.array_equal(trees.combine_contours([a, b], [0.0, 1.0]), b)
    mid = trees.combine_contours([a, b], [0.3, 0.7])
    np.testing.assert_allclose(mid, 0.3 * a + 0.7 * b)
    with pytest.raises(ValueError, match=r"^weights: expected finite non-negative"):
        trees.combine_contours([a, b], [1.5, -0.5])
    with pytest.raises(ValueError, match=r"^weights: expected weights summing to 1"):
        trees.combine_contours([a, b], [0.5, 0.6])
    with pytest.raises(ValueError, match=r"^contours: expected the same number"):
        trees.combine_contours([a, b[:-1]], [0.5, 0.5])


# --- cages and colour transfer (§4.6, §5.2) --------------------------------------------------


def test_cages_correspond_and_are_valid(library):
    target = trees.combine_contours([library[0].resampled, library[2].resampled], [0.4, 0.6])
    tc, (s0, s2) = trees.cages(target, [library[0], library[2]], (SIZE, SIZE), m=100)
    for cage in (tc, s0, s2):
        assert cage.shape == (100, 2)
        assert trees.signed_area(cage) > 0  # counter-clockwise
        assert np.linalg.norm(np.diff(np.vstack([cage, cage[:1]]), axis=0), axis=1).min() > 0.1
    # Corresponding points: every cage point is near its own tree's contour at the same places
    # (within the dilation, more where the dilation fills a notch), and the point nearest to
    # each tree's B pin has the same index in every cage.
    bottoms = []
    for cage, cr in ((tc, target), (s0, library[0].resampled), (s2, library[2].resampled)):
        near = np.sqrt(((cage[:, None] - cr[None]) ** 2).sum(axis=2)).min(axis=1)
        assert np.median(near) < 8 * 1.5 and near.max() < 30
        bottoms.append(int(np.argmin(np.linalg.norm(cage - cr[1800], axis=1))))
    assert max(bottoms) - min(bottoms) <= 1
    # The target cage is near uniform: no chord over three times the median.
    ch = np.linalg.norm(np.diff(np.vstack([tc, tc[:1]]), axis=0), axis=1)
    assert ch.max() < 3 * np.median(ch)


def test_cage_of_a_tree_without_trunk_has_no_repeated_points():
    shrub = np.zeros((200, 200, 4), np.float32)
    cv2.circle(shrub, (100, 120), 80, (0.2, 0.6, 0.2, 1.0), -1)
    shrub[190:, 40:160] = (0.2, 0.6, 0.2, 1.0)  # foliage on the ground: R = L = B
    t = trees.prepare(shrub, size=SIZE)
    assert len(set(t.pins)) == 1
    tc, (sc,) = trees.cages(t.resampled, [t], (SIZE, SIZE))
    assert np.linalg.norm(np.diff(np.vstack([sc, sc[:1]]), axis=0), axis=1).min() > 0.1
    np.testing.assert_allclose(tc, sc)


def test_morph_of_one_tree_is_the_identity(library):
    t = library[0]
    out = trees.morph([t], [1.0])
    side = 2 * 8 + 1
    region = cv2.dilate(trees.fill_contour(t.resampled, (SIZE, SIZE)).astype(np.uint8), np.ones((side, side))) > 0
    # Identical cages: the warp is the identity up to float32 round-off in the positions.
    assert np.abs(out[region] - t.image[region]).max() < 0.02
    assert not out[~region].any()


def test_morph_is_valid_rgba_inside_the_dilated_contour(library):
    ts = [library[1], library[2]]
    w = np.array([0.35, 0.65])
    out = trees.morph(ts, w, color_weights=[0.5, 0.5])
    assert out.shape == (SIZE, SIZE, 4) and out.dtype == np.float32
    assert np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0
    contour = trees.combine_contours([t.resampled for t in ts], w)
    dilated = cv2.dilate(trees.fill_contour(contour, (SIZE, SIZE)).astype(np.uint8), np.ones((17, 17))) > 0
    assert not (out[..., 3] > 0)[~dilated].any()
    # Most of the preliminary alpha gets opaque colour (the crowns are solid).
    inside = trees.fill_contour(contour, (SIZE, SIZE))
    assert (out[..., 3][inside] > 0.5).mean() > 0.9
    # Transparent pixels are black (§4.1 convention kept by the warp).
    assert not out[out[..., 3] == 0][:, :3].any()


def test_morph_colour_comes_from_the_weighted_sources():
    a = np.zeros((200, 200, 4), np.float32)
    a[20:150, 30:170] = (1.0, 0.0, 0.0, 1.0)
    a[150:200, 90:110] = (1.0, 0.0, 0.0, 1.0)
    b = a.copy()
    b[..., :3] = np.where(b[..., 3:] > 0, np.array([0.0, 0.0, 1.0], np.float32), 0.0)
    ta, tb = (trees.prepare(x, size=128, split=(160, 20, 20), m=40) for x in (a, b))
    out = trees.morph([ta, tb], [0.5, 0.5], color_weights=[0.25, 0.75], m=40)
    opaque = out[..., 3] > 0.99
    np.testing.assert_allclose(out[opaque][:, [0, 2]], np.tile([0.25, 0.75], (int(opaque.sum()), 1)), atol=1e-5)


# --- histogram transfer (§5.3) ---------------------------------------------------------------


def test_match_histograms_matches_reference_cdf_and_ignores_transparent():
    rng = np.random.default_rng(3)
    img = np.zeros((120, 100, 4), np.float32)
    img[..., :3] = rng.beta(2, 5, (120, 100, 3))
    img[..., 3] = rng.random((120, 100)) > 0.3
    ref = np.zeros((90, 140, 4), np.float32)
    ref[..., :3] = rng.beta(5, 2, (90, 140, 3))
    ref[..., 3] = 1.0
    ref[:30, :, :3] = 0.0  # transparent pixels with a colour that must not count
    ref[:30, :, 3] = 0.0
    out = trees.match_histograms(img, ref)
    on = img[..., 3] > 0
    q = np.linspace(0.02, 0.98, 49)
    for ch in range(3):
        got = np.quantile(out[..., ch][on], q)
        want = np.quantile(ref[..., ch][ref[..., 3] > 0], q)
        assert np.abs(got - want).max() < 0.01
        # The map is monotone: the order of the pixel values is kept.
        order = np.argsort(img[..., ch][on], kind="stable")
        assert (np.diff(out[..., ch][on][order]) >= 0).all()
    assert np.array_equal(out[..., 3], img[..., 3])
    assert np.array_equal(out[~on], img[~on])
    with pytest.raises(ValueError, match=r"^reference: every pixel is transparent"):
        trees.match_histograms(img, np.zeros((4, 4, 4), np.float32))


# --- library, variation, vary ----------------------------------------------------------------


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
    v = trees.variation(library, seed=4, sources=3, colors=colors)
    assert len(v.sources) == 3 and v.color_weights.sum() == pytest.approx(1.0)
    if colors == "contour":
        assert np.array_equal(v.color_weights, v.weights)
    if colors == "single":
        assert sorted(v.color_weights.tolist()) == [0.0, 0.0, 1.0]


def test_variation_histogram_reference(library):
    v = trees.variation(library, seed=2, histogram=True)
    assert v.reference is not None and v.reference not in v.sources


def test_vary_gives_the_tree_the_higher_weight(library):
    own = _tree(9, crown=(75, 55))
    vs = trees.vary(own, library, n=3, seed=5)
    assert len(vs) == 3
    for v in vs:
        assert 0.6 <= v.weights[0] <= 0.9 and v.weights.sum() == pytest.approx(1.0)
        assert np.array_equal(v.color_weights, v.weights)
        assert v.image.shape == (SIZE, SIZE, 4)
    again = trees.vary(own, library, n=3, seed=5)
    assert all(np.array_equal(x.image, y.image) for x, y in zip(vs, again))


def test_variation_and_library_errors(library, tmp_path: Path):
    one = trees.Library([library[0]], ["only"])
    with pytest.raises(ValueError, match=r"^library: has 1 tree\(s\) but sources=2"):
        trees.variation(one)
    with pytest.raises(TypeError, match=r"^library: expected a phloem.trees.Library"):
        trees.variation([library[0]])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^colors"):
        trees.variation(library, colors="mean")
    with pytest.raises(ValueError, match=r"^sources: a variation of a tree"):
        trees.vary(_tree(0), library, n=1, sources=1)
    with pytest.raises(ValueError, match=r"^trees: a library needs at least one tree"):
        trees.Library([])
    other = trees.prepare(_tree(0), size=128)
    with pytest.raises(ValueError, match=r"another size"):
        trees.Library([library[0], other])
    # Folders: an RGB image, a fully transparent one, a good one.
    phloem.io.write_image(tmp_path / "rgb.png", np.ones((50, 40, 3), np.float32))
    phloem.io.write_image(tmp_path / "empty.png", np.zeros((50, 40, 4), np.float32))
    phloem.io.write_image(tmp_path / "tree.png", _tree(0))
    with pytest.raises(ValueError, match=r"empty.png: "):
        trees.Library.load(tmp_path, size=128)
    lib = trees.Library.load(tmp_path, size=128, skip_bad=True)
    assert lib.names == ["tree.png"]
    with pytest.raises(ValueError, match=r"^path: .* does not exist"):
        trees.Library.load(tmp_path / "none")
    assert trees.Library.load(tmp_path / "tree.png", size=128).names == ["tree.png"]  # one image


def test_library_load_splits_atlases(tmp_path: Path):
    atlas = np.zeros((300, 460, 4), np.float32)
    atlas[:, :220] = _tree(0)
    atlas[:, 240:] = _tree(1)
    phloem.io.write_image(tmp_path / "atlas.png", atlas)
    lib = trees.Library.load(tmp_path, size=128)
    assert lib.names == ["atlas.png[0]", "atlas.png[1]"]
    whole = trees.Library.load(tmp_path, size=128, atlas=False)
    assert whole.names == ["atlas.png"]


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
    stick = np.zeros((120, 60, 4), np.float32)
    stick[5:118, 30] = (0.9, 0.9, 0.8, 1.0)  # a one-pixel stick: a contour without area
    t = trees.prepare(stick, size=SIZE)
    assert np.isfinite(t.resampled).all() and len(t.resampled) == 2000
    lib = trees.Library([t, library[0]], ["stick", "a"])
    out = trees.variation(lib, seed=0).image
    assert np.isfinite(out).all() and out[..., 3].max() > 0
    with pytest.raises(ValueError, match=r"^rgba: expected some pixels with alpha"):
        trees.prepare(np.zeros((30, 30, 4), np.float32))
    with pytest.raises(ValueError, match=r"^rgba: expected an RGBA image"):
        trees.prepare(np.ones((30, 30, 3), np.float32))
    with pytest.raises(ValueError, match=r"^target: the contour is degenerate"):
        trees.cages(np.zeros((2000, 2)), [t], (SIZE, SIZE))
