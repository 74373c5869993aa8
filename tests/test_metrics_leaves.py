"""The layer and leaf-set measures of phloem.metrics (Assa & Cohen-Or: Eq. 4 as implemented,
agreement of an induced layer, diversity of a set of leaves)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import metrics


def _ellipse(h: int, w: int, ay: float, ax: float, rgba: bool = True) -> np.ndarray:
    yy, xx = np.mgrid[:h, :w]
    m = ((yy - h / 2) / ay) ** 2 + ((xx - w / 2) / ax) ** 2 <= 1
    if not rgba:
        return m
    out = np.zeros((h, w, 4), np.float32)
    out[m] = (0.2, 0.5, 0.1, 1.0)
    return out


def test_layer_iou_counts_intersection_over_union() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.random((30, 40)) < 0.3, rng.random((30, 40)) < 0.5
    assert metrics.layer_iou(a, b) == pytest.approx((a & b).sum() / (a | b).sum())
    assert metrics.layer_iou(a, a) == 1.0
    assert metrics.layer_iou(a, ~a) == 0.0
    assert metrics.layer_iou(np.zeros((3, 3), bool), np.zeros((3, 3), int)) == 1.0  # both empty: agree


def test_layer_objective_is_the_iou_of_the_thresholded_layer() -> None:
    rng = np.random.default_rng(1)
    d = rng.random((20, 25)).astype(np.float32)
    d[0, :5] = np.nan  # off the leaf: never in the layer, even for a huge delta
    c = rng.random((20, 25)) < 0.4
    for delta in (0.0, 0.2, 0.5, 0.99, 10.0):
        want = metrics.layer_iou(np.nan_to_num(d, nan=np.inf) < delta, c)
        assert metrics.layer_objective(d, c, delta) == pytest.approx(want)
    c2 = np.zeros_like(c)
    c2[0, :5] = True  # a layer entirely where D is NaN cannot be reproduced
    assert metrics.layer_objective(d, c2, 10.0) == 0.0
    # D < delta is strict: a pixel at exactly delta is out.
    one = np.array([[0.5]], np.float32)
    assert metrics.layer_objective(one, [[True]], 0.5) == 0.0
    assert metrics.layer_objective(one, [[True]], 0.5000001) == 1.0


def test_leaf_diversity_ignores_translation_and_scores_shape() -> None:
    a = _ellipse(60, 80, 25, 35)
    shifted = np.zeros((90, 100, 4), np.float32)
    shifted[27:87, 13:93] = a  # the same leaf elsewhere on a larger canvas
    assert metrics.leaf_diversity([a, shifted]) == 0.0
    thin = _ellipse(60, 80, 25, 17)
    d = metrics.leaf_diversity([a, thin])
    # A half-width ellipse centred on the other covers half of it: 1 - IoU ≈ 0.5.
    assert 0.45 <= d <= 0.55, d
    # Three leaves: the mean over the three pairs.
    round_ = _ellipse(60, 80, 25, 25, rgba=False)
    pairs = [metrics.leaf_diversity([x, y]) for x, y in ((a, thin), (a, round_), (thin, round_))]
    assert metrics.leaf_diversity([a, thin, round_]) == pytest.approx(np.mean(pairs))
    # More varied sets score higher than less varied ones.
    assert metrics.leaf_diversity([a, _ellipse(60, 80, 24, 33)]) < d


def test_leaf_diversity_reads_alpha_of_rgba_and_gray_alpha() -> None:
    a = _ellipse(40, 40, 15, 18)
    ga = np.stack([a[..., 0], a[..., 3]], axis=-1)
    m = a[..., 3] > 0.5
    soft = a.copy()
    soft[..., 3] *= 0.4  # alpha <= 0.5 everywhere: no leaf
    assert metrics.leaf_diversity([a, ga, m, (m * 255).astype(np.uint8)]) == 0.0
    with pytest.raises(ValueError, match=r"^leaves\[1\]: the leaf has no pixels"):
        metrics.leaf_diversity([a, soft])
    rot = cv2.rotate(a, cv2.ROTATE_90_CLOCKWISE)
    assert metrics.leaf_diversity([a, rot]) > 0.05  # only translation is removed


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: metrics.layer_iou(np.zeros((3, 3)), np.zeros((3, 4))), ValueError, r"^reference: expected shape"),
        (lambda: metrics.layer_iou(np.zeros(3), np.zeros(3)), ValueError, r"^induced: expected a 2-D mask"),
        (lambda: metrics.layer_objective(np.zeros((3, 3), int), np.zeros((3, 3)), 0.5), ValueError, r"^dissimilarity:"),
        (
            lambda: metrics.layer_objective(np.zeros((3, 3)), np.zeros((2, 3)), 0.5),
            ValueError,
            r"^layer: expected shape",
        ),
        (lambda: metrics.layer_objective(np.zeros((3, 3)), np.zeros((3, 3)), "a"), TypeError, r"^delta:"),
        (lambda: metrics.layer_objective(np.zeros((3, 3)), np.zeros((3, 3)), float("nan")), ValueError, r"^delta:"),
        (lambda: metrics.leaf_diversity([np.ones((4, 4))]), ValueError, r"^leaves: expected at least 2"),
        (lambda: metrics.leaf_diversity(np.ones((2, 4, 4))), TypeError, r"^leaves: expected a list"),
        (
            lambda: metrics.leaf_diversity([np.ones((4, 4, 3)), np.ones((4, 4))]),
            ValueError,
            r"^leaves\[0\]: expected RGBA",
        ),
    ],
)
def test_bad_input_gives_one_line_errors(call: object, error: type, message: str) -> None:
    with pytest.raises(error, match=message) as info:
        call()  # type: ignore[operator]
    assert "\n" not in str(info.value)
