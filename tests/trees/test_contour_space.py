"""phloem.trees.contour_space: convex combinations of contours and the preliminary alpha (§5.1)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import trees


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


def test_contour_synthesis_convex_combination_is_a_tree(disk_tree):
    # §5.1: a convex combination of two resampled contours keeps B, L, R in place.
    a = trees.prepare(disk_tree(crown_r=70)[0], size=256)
    b = trees.prepare(disk_tree(crown_r=50, trunk_h=150)[0], size=256)
    mix = 0.5 * a.resampled + 0.5 * b.resampled
    assert trees.signed_area(mix) > 0
    assert mix[1800, 1] == pytest.approx(255.0)  # both B rows are the bottom edge
