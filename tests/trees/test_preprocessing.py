"""phloem.trees.preprocessing: one exemplar end to end (§4) into a Tree (§4.7)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import trees


def test_prepare_end_to_end_and_user_trunk(disk_tree):
    img, _ = disk_tree()
    tree = trees.prepare(img, size=256)
    assert tree.image.shape == (256, 256, 4)
    assert tree.resampled.shape == (2000, 2) and tree.simplified.shape == (100, 2)
    assert tree.vector.shape == (4000,) and abs(tree.vector.reshape(-1, 2).mean(axis=0)).max() < 1e-9
    # The simplified contour encloses every opaque pixel of the tree.
    ys, xs = np.nonzero(tree.image[..., 3] >= 0.5)
    poly = tree.simplified.astype(np.float32).reshape(-1, 1, 2)
    inside = [
        cv2.pointPolygonTest(poly, (float(x), float(y)), False) >= 0 for x, y in zip(xs[::50], ys[::50], strict=True)
    ]
    assert all(inside)
    # A user mask with no trunk: all pins at the bottom.
    tree2 = trees.prepare(tree.image, trunk=np.zeros((256, 256), bool), normalized=True)
    assert len(set(tree2.pins)) == 1
    with pytest.raises(ValueError, match=r"^trunk"):
        trees.prepare(img, size=256, trunk=np.zeros((10, 10), bool))
