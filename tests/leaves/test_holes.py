"""Interior holes of a leaf: only enclosed ones are found, and filling them leaves the rest alone."""

from __future__ import annotations

import cv2
import numpy as np

from phloem.leaves._holes import fill_holes, interior_holes


def _leaf() -> np.ndarray:
    img = np.zeros((80, 60, 4), np.float32)
    cv2.ellipse(img, (30, 40), (24, 36), 0, 0, 360, (0.2, 0.5, 0.1, 1.0), -1)
    img[..., 1] += np.random.default_rng(0).normal(0, 0.02, img.shape[:2]).astype(np.float32) * img[..., 3]
    return img


def test_only_enclosed_background_is_a_hole() -> None:
    leaf = _leaf()
    leaf[30:38, 25:33, 3] = 0.0  # an enclosed hole
    leaf[38:42, 0:10, 3] = 0.0  # a bite from the margin (touches the outside)
    holes = interior_holes(leaf[..., 3])
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
    assert not interior_holes(out[..., 3]).any()
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
