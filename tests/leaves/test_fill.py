"""Filling regions of a leaf: only enclosed holes are found, and filling them leaves the rest alone."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.leaves._fill import fill_holes, interior_holes


def _leaf() -> np.ndarray:
    img = np.zeros((80, 60, 4), np.float32)
    cv2.ellipse(img, (30, 40), (24, 36), 0, 0, 360, (0.2, 0.5, 0.1, 1.0), -1)
    img[..., 1] += np.random.default_rng(0).normal(0, 0.02, img.shape[:2]).astype(np.float32) * img[..., 3]
    return img


def test_only_enclosed_background_is_a_hole() -> None:
    leaf = _leaf()
    leaf[30:38, 25:33, 3] = 0.0  # an enclosed hole
    leaf[38:42, 0:10, 3] = 0.0  # a bite from the margin (touches the outside)
    holes = interior_holes(leaf[..., 3] > 0.5)
    assert holes[30:38, 25:33].all()
    assert holes.sum() == 64
    assert not holes[38:42, 0:10].any()


def test_fill_makes_the_leaf_whole_and_keeps_every_other_pixel() -> None:
    leaf = _leaf()
    hole = np.zeros(leaf.shape[:2], bool)
    hole[30:38, 25:33] = True
    leaf[hole] = (1.0, 1.0, 1.0, 0.0)  # scanner white seen through the hole
    out = fill_holes(leaf, seed=0, threads=1)
    assert (out[..., 3][hole] == 1.0).all()
    assert not interior_holes(out[..., 3] > 0.5).any()
    # the fill takes the blade's colours, not the white of the hole
    assert np.abs(out[hole][:, :3] - (0.2, 0.5, 0.1)).max() < 0.1
    far = ~(cv2.dilate(hole.astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool))
    assert np.array_equal(out[far], leaf[far])


def test_a_leaf_without_holes_is_returned_as_is() -> None:
    leaf = _leaf()
    assert fill_holes(leaf, seed=0, threads=1) is leaf


def test_fill_is_the_same_for_any_number_of_threads() -> None:
    leaf = _leaf()
    leaf[30:38, 25:33, 3] = 0.0
    assert np.array_equal(fill_holes(leaf, seed=3, threads=1), fill_holes(leaf, seed=3, threads=2))


def test_analysis_fills_the_backgrounds_holes_unless_asked_to_keep_them() -> None:
    import phloem

    def leaf(w: int) -> np.ndarray:
        img = np.zeros((90, 60, 4), np.float32)
        cv2.ellipse(img, (30, 45), (w, 40), 0, 0, 360, (0.2, 0.5, 0.1, 1.0), -1)
        cv2.line(img, (30, 8), (30, 82), (0.6, 0.7, 0.3, 1.0), 2)
        return img

    bitten = leaf(22)
    bitten[55:63, 12:20] = 0.0  # an insect hole, away from the midrib
    scribbles = np.zeros((90, 60), np.int32)
    scribbles[20:70, 30] = 1
    scribbles[40:50, 15] = 2
    filled = phloem.leaves.analyze([leaf(20), bitten], scribbles, points=40, epsilon=8)
    kept = phloem.leaves.analyze([leaf(20), bitten], scribbles, points=40, epsilon=8, keep_holes=True)
    assert interior_holes(kept.background[1][..., 3] > 0.5).sum() > 20  # the hole, as registered
    assert not interior_holes(filled.background[1][..., 3] > 0.5).any()
    for model in (filled, kept):  # everything but the backgrounds is the same
        assert np.array_equal(model.aligned[1], kept.aligned[1])
    with pytest.raises(TypeError, match="keep_holes: expected True or False"):
        phloem.leaves.analyze([leaf(20), bitten], scribbles, points=40, epsilon=8, keep_holes="yes")  # type: ignore[arg-type]
