"""Registration of a synthetic leaf to a known smooth warp of itself (TPS-RPM, §3)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.leaves import keypoints, register
from phloem.leaves import registration as reg_module

H, W = 240, 320


def leaf() -> np.ndarray:
    """An RGBA leaf: a pointed ellipse with a darker midrib and two side veins."""
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    poly = np.stack([160 + 120 * np.cos(t), 120 + 60 * (1 - 0.35 * np.cos(t)) * np.sin(t)], 1)
    img = np.zeros((H, W, 4), np.float32)
    cv2.fillPoly(img, [poly.round().astype(np.int32)], (0.3, 0.6, 0.2, 1.0))
    cv2.line(img, (50, 120), (275, 122), (0.1, 0.3, 0.05, 1.0), 3)
    cv2.line(img, (120, 121), (170, 80), (0.1, 0.3, 0.05, 1.0), 2)
    cv2.line(img, (180, 121), (220, 160), (0.1, 0.3, 0.05, 1.0), 2)
    return img


def known(xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A smooth non-rigid map from the moving frame to the fixed frame."""
    x, y = xs - 160.0, ys - 120.0
    return 160 + 0.95 * x + 6 * np.sin(y / 40) + 0.05 * y, 120 + 0.97 * y + 8 * (x / 150) ** 2 - 3


def pair() -> tuple[np.ndarray, np.ndarray]:
    fixed = leaf()
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    mx, my = known(xx, yy)
    moving = cv2.remap(fixed, mx.astype(np.float32), my.astype(np.float32), cv2.INTER_LINEAR, borderValue=0)
    return moving, fixed


@pytest.fixture(scope="module")
def reg():  # type: ignore[no-untyped-def]
    moving, fixed = pair()
    return moving, fixed, register(moving, fixed, seed=3)


def test_recovers_the_known_warp_inside_the_leaf(reg) -> None:  # type: ignore[no-untyped-def]
    _moving, fixed, r = reg
    inside = cv2.erode((fixed[..., 3] > 0.5).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    yy, xx = np.nonzero(inside)
    qx, qy = xx + r.forward[yy, xx, 0], yy + r.forward[yy, xx, 1]
    bx, by = known(qx, qy)  # back to the fixed frame through the true map
    err = np.hypot(bx - xx, by - yy)
    # Edge keypoints of the two images are different samples of the edges, so the dense error
    # is above the keypoints' own (figures in docs/pipelines/leaves/registration.md).
    assert err.mean() <= 3.0, err.mean()
    assert r.residual <= 3.0 and r.min_jacobian > 0


def test_forward_then_inverse_is_the_identity_inside_the_leaf(reg) -> None:  # type: ignore[no-untyped-def]
    _moving, fixed, r = reg
    inside = fixed[..., 3] > 0.5
    yy, xx = np.nonzero(inside)
    qx = (xx + r.forward[yy, xx, 0]).astype(np.float32)
    qy = (yy + r.forward[yy, xx, 1]).astype(np.float32)
    back = cv2.remap(r.inverse, qx[None], qy[None], cv2.INTER_LINEAR)[0]
    err = np.hypot(qx + back[:, 0] - xx, qy + back[:, 1] - yy)
    assert err.max() <= 1.0, err.max()


def test_warp_aligns_the_exemplar(reg) -> None:  # type: ignore[no-untyped-def]
    moving, fixed, r = reg
    aligned = r.warp(moving)
    before = np.mean((moving[..., 3] > 0.5) ^ (fixed[..., 3] > 0.5))
    after = np.mean((aligned[..., 3] > 0.5) ^ (fixed[..., 3] > 0.5))
    assert after < 0.3 * before, (before, after)
    assert r.warp_back(fixed).shape == moving.shape


def test_deterministic_for_a_seed_at_one_and_two_threads() -> None:
    moving, fixed = pair()
    a = register(moving, fixed, seed=5, threads=1)
    b = register(moving, fixed, seed=5, threads=2)
    assert np.array_equal(a.forward, b.forward) and np.array_equal(a.inverse, b.inverse)
    assert np.array_equal(a.matches, b.matches)


def test_bad_input_one_line_errors() -> None:
    moving, fixed = pair()
    with pytest.raises(ValueError, match=r"^fixed: the alpha channel is empty"):
        register(moving, np.zeros_like(fixed))
    blank = np.ones((H, W, 3), np.float32)
    with pytest.raises(ValueError, match=r"^moving: found no edges"):
        register(blank, fixed[..., :3])
    with pytest.raises(ValueError, match=r"^points: expected an integer >= 3, got 2"):
        register(moving, fixed, points=2)
    with pytest.raises(ValueError, match=r"^moving: expected 4 channels like fixed, got 3"):
        register(moving[..., :3], fixed)


def test_keypoints_do_not_depend_on_the_transparent_canvas_around_the_leaf() -> None:
    # The edge filters run on the box around the leaf; padding, and a faint pixel far away
    # that makes them run on the whole image, change nothing but the offset.
    fixed = leaf()
    big = np.zeros((H + 70, W + 90, 4), np.float32)
    big[30 : 30 + H, 50 : 50 + W] = fixed
    faint = big.copy()
    faint[-1, -1] = (1.0, 1.0, 1.0, 0.2)
    for seed in (0, 4):
        p = keypoints(fixed, seed=seed)
        assert np.array_equal(keypoints(big, seed=seed), p + [50, 30])
        assert np.array_equal(keypoints(faint, seed=seed), p + [50, 30])


def test_edges_on_the_box_around_the_leaf_equal_those_of_the_whole_image() -> None:
    big = np.zeros((H + 70, W + 90, 4), np.float32)
    big[30 : 30 + H, 50 : 50 + W] = leaf()
    faint = big.copy()
    faint[-1, -1] = (1.0, 1.0, 1.0, 0.2)  # not transparent outside the box: the whole image
    region = cv2.dilate((big[..., 3] > 0.5).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=2) > 0
    mag, box = reg_module._edges(big, region)
    full, whole = reg_module._edges(faint, region)
    assert mag.size < 0.8 * full.size and full.shape == region.shape
    assert np.array_equal(mag, full[box]) and full[region].any()
    assert not full[~region].any() and whole == (slice(0, H + 70), slice(0, W + 90))


def test_edges_fall_back_to_the_whole_image_when_the_box_holds_no_transparent_pixel() -> None:
    # A faint halo that fills the box exactly: the box's grey range would not start at 0.
    big = np.zeros((H + 70, W + 90, 4), np.float32)
    big[30 : 30 + H, 50 : 50 + W] = leaf()
    ys, xs = np.nonzero(big[..., 3] > 0.5)
    halo = big[ys.min() - 8 : ys.max() + 9, xs.min() - 8 : xs.max() + 9]
    halo[halo[..., 3] == 0] = (0.5, 0.5, 0.5, 0.4)
    faint = big.copy()
    faint[-1, -1] = (1.0, 1.0, 1.0, 0.2)
    region = cv2.dilate((big[..., 3] > 0.5).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=2) > 0
    mag = reg_module._edges(big, region)[0]
    assert mag.shape == region.shape
    assert np.array_equal(mag, reg_module._edges(faint, region)[0])
