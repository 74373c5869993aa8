"""leaves.pose: the similarity that puts an exemplar on the training leaf before TPS-RPM."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.leaves import pose


def _leaf(size: int = 240) -> np.ndarray:
    """An asymmetric leaf: an ellipse, a petiole at the bottom and a lobe on its left side."""
    img = np.zeros((size, size, 4), np.float32)
    c = size // 2
    cv2.ellipse(img, (c, c), (size // 8, size // 3), 0, 0, 360, (0.2, 0.5, 0.1, 1.0), -1)
    cv2.line(img, (c, c + size // 3), (c, c + size // 3 + size // 10), (0.4, 0.3, 0.1, 1.0), 3)
    cv2.circle(img, (c - size // 8, c - size // 8), size // 12, (0.2, 0.5, 0.1, 1.0), -1)
    return img


def _transform(img: np.ndarray, angle: float, scale: float, mirror: bool, out: int = 320) -> np.ndarray:
    src = img[:, ::-1].copy() if mirror else img
    h, w = src.shape[:2]
    m = cv2.getRotationMatrix2D((w / 2, h / 2), angle, scale)
    m[:, 2] += (out - w) / 2, (out - h) / 2
    return cv2.warpAffine(src, m, (out, out), flags=cv2.INTER_LINEAR)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum()) / float((a | b).sum())


@pytest.mark.parametrize(
    ("angle", "scale", "mirror"),
    [
        (0.0, 1.0, False),
        (37.0, 0.7, False),
        (90.0, 1.3, False),
        (180.0, 1.0, False),
        (-120.0, 0.8, True),
        (15.0, 1.0, True),
    ],
)
def test_pose_undoes_a_similarity(angle: float, scale: float, mirror: bool) -> None:
    train = _leaf()
    moved = _transform(train, angle, scale, mirror)
    m, s = pose(moved, train)
    back = cv2.warpAffine(moved[..., 3], m, (train.shape[1], train.shape[0])) > 0.5
    assert _iou(back, train[..., 3] > 0.5) > 0.93
    assert s == pytest.approx(1.0 / scale, rel=0.05)


def test_pose_chooses_the_half_turn_by_overlap() -> None:
    # the petiole and lobe make the leaf asymmetric: only the right one of the four candidates
    # overlaps well, a wrong half turn or mirror image would leave the lobe on the wrong side
    train = _leaf()
    moved = _transform(train, 180.0, 1.0, False)
    m, _ = pose(moved, train)
    assert np.allclose(m[:, :2], [[-1, 0], [0, -1]], atol=0.05)


def test_pose_of_an_empty_leaf() -> None:
    with pytest.raises(ValueError, match="alpha channel is empty"):
        pose(np.zeros((10, 10, 4), np.float32), _leaf())


def test_the_canvas_holds_the_whole_training_image_and_every_posed_leaf() -> None:
    from phloem.leaves.pose import CANVAS_MARGIN, canvas

    train = np.zeros((300, 200, 4), np.float32)
    train[100:200, 50:150] = _leaf(100)  # a small leaf in a large transparent image
    big = _transform(_leaf(), 70.0, 1.0, False, out=400)
    mats, scales, (h, w) = canvas([train, big], 0)
    assert np.allclose(mats[0][:, :2], np.eye(2)) and np.allclose(mats[0][:, 2], np.round(mats[0][:, 2]))
    ty, tx = int(mats[0][1, 2]), int(mats[0][0, 2])
    assert ty >= CANVAS_MARGIN and tx >= CANVAS_MARGIN and ty + 300 <= h and tx + 200 <= w
    posed = cv2.warpAffine(big[..., 3], mats[1], (w, h)) > 0.5
    assert posed.sum() == pytest.approx((big[..., 3] > 0.5).sum() * scales[1] ** 2, rel=0.05)  # nothing cut off
    assert not posed[:CANVAS_MARGIN].any() and not posed[:, -CANVAS_MARGIN:].any()
