"""Perspective (Sibbing et al. 2010, Fig. 8): rectify, render in the frontal frame, unrectify."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.branching import rectify, render, unrectify
from phloem.testing import channel_scene


def test_perspective_rectify_render_unrectify_round_trip() -> None:
    """Fig. 8: rectify a slanted view, synthesise in the frontal frame, distort back."""
    img, sk = channel_scene()
    h, w = sk.shape
    src_q = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    dst_q = np.float32([[20, 0], [w - 20, 10], [w, h], [0, h - 5]])
    Hm = cv2.getPerspectiveTransform(src_q, dst_q)
    rect, rsk, H2, valid = rectify(img, sk, Hm)
    assert valid.shape == rect.shape[:2] and 0.5 < valid.mean() < 1.0
    # The skeleton follows the homography, and the structure stays under it.
    p = np.c_[sk.branches[0].points, np.ones(len(sk.branches[0]))] @ H2.T
    assert np.allclose(rsk.branches[0].points, p[:, :2] / p[:, 2:], atol=1e-6)
    core = rsk.mask() & (cv2.distanceTransform(rsk.mask().astype(np.uint8), cv2.DIST_L2, 3) > 1.5)
    assert float(np.median(rect[..., 0][core])) < 0.3
    out = render(rect, rsk, rsk, seed=0, complete=False)
    back = unrectify(out, H2, sk.shape)
    m = cv2.erode(sk.mask().astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    assert float(np.abs(back[..., 0] - img)[m].mean()) < 0.05
    with pytest.raises(ValueError, match="homography"):
        rectify(img, sk, np.zeros((3, 3)))
