"""phloem.trees.transfer: matching cages, MVC colour transfer (§4.6, §5.2) and histogram transfer (§5.3)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import trees


def test_cages_correspond_and_are_valid(library):
    size = library.size
    target = trees.combine_contours([library[0].resampled, library[2].resampled], [0.4, 0.6])
    tc, (s0, s2) = trees.cages(target, [library[0], library[2]], (size, size), m=100)
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
    size = 256
    shrub = np.zeros((200, 200, 4), np.float32)
    cv2.circle(shrub, (100, 120), 80, (0.2, 0.6, 0.2, 1.0), -1)
    shrub[190:, 40:160] = (0.2, 0.6, 0.2, 1.0)  # foliage on the ground: R = L = B
    t = trees.prepare(shrub, size=size)
    assert len(set(t.pins)) == 1
    tc, (sc,) = trees.cages(t.resampled, [t], (size, size))
    assert np.linalg.norm(np.diff(np.vstack([sc, sc[:1]]), axis=0), axis=1).min() > 0.1
    np.testing.assert_allclose(tc, sc)


def test_morph_of_one_tree_is_the_identity(library):
    size = library.size
    t = library[0]
    out = trees.morph([t], [1.0])
    side = 2 * 8 + 1
    region = cv2.dilate(trees.fill_contour(t.resampled, (size, size)).astype(np.uint8), np.ones((side, side))) > 0
    # Identical cages: the warp is the identity up to float32 round-off in the positions.
    assert np.abs(out[region] - t.image[region]).max() < 0.02
    assert not out[~region].any()


def test_morph_is_valid_rgba_inside_the_dilated_contour(library):
    size = library.size
    ts = [library[1], library[2]]
    w = np.array([0.35, 0.65])
    out = trees.morph(ts, w, color_weights=[0.5, 0.5])
    assert out.shape == (size, size, 4) and out.dtype == np.float32
    assert np.isfinite(out).all() and out.min() >= 0.0 and out.max() <= 1.0
    contour = trees.combine_contours([t.resampled for t in ts], w)
    dilated = cv2.dilate(trees.fill_contour(contour, (size, size)).astype(np.uint8), np.ones((17, 17))) > 0
    assert not (out[..., 3] > 0)[~dilated].any()
    # Most of the preliminary alpha gets opaque colour (the crowns are solid).
    inside = trees.fill_contour(contour, (size, size))
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
