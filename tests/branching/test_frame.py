"""The frame of a photo (``valid_region``) and what trace and synthesize do with it (issue 19)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem.branching import synthesize, trace, valid_region
from phloem.branching.frame import MIN_SOLIDITY, _keep_frame, _solidity


def _fundus(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A lit disc with dark vessels in a black frame, like a fundus photo, and the disc."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:160, :160]
    disc = (yy - 80) ** 2 + (xx - 80) ** 2 < 70**2
    img = 0.6 + 0.03 * cv2.GaussianBlur(rng.normal(size=(160, 160)).astype(np.float32), (0, 0), 1.5) / 0.1
    cv2.line(img, (30, 80), (130, 70), 0.25, 3)
    cv2.line(img, (80, 75), (100, 130), 0.25, 2)
    cv2.circle(img, (80, 80), 66, 0.3, 2)  # the darker halo along a fundus photo's rim
    img = np.where(disc, img, 0.0).astype(np.float32)
    return np.repeat(img[..., None], 3, axis=2), disc


def test_a_black_frame_is_found_and_nothing_else() -> None:
    img, disc = _fundus()
    ok = valid_region(img)
    assert ok[80, 80] and not ok[0, 0] and not ok[159, 159]
    assert (ok & ~disc).sum() == 0  # the frame and its margin are out
    assert (disc & ~ok).sum() < 0.05 * disc.sum()  # the disc, less a rim of 2 px, is in
    # no frame: a mask's background, a smooth 16-bit field, a textured photo
    mask = disc.astype(np.float32)
    assert valid_region(mask).all()
    smooth = cv2.GaussianBlur(np.random.default_rng(1).normal(size=(100, 120)), (0, 0), 12.0)
    field = (1000 + 300 * smooth / np.abs(smooth).max()).astype(np.uint16)  # an elevation model
    assert valid_region(field).all()
    noise = np.random.default_rng(0).random((80, 80)).astype(np.float32)
    assert valid_region(noise).all()
    # constant padding on one side only
    padded = np.pad(noise, ((0, 0), (0, 20)), constant_values=1.0)
    ok = valid_region(padded)
    assert ok[:, :78].all() and not ok[:, 82:].any()


def _venation(seed: int = 0) -> np.ndarray:
    """White veins with spurs on a flat black background, blurred and noisy as a resized JPEG:
    not two-level, and the black touches the border between every pair of veins."""
    rng = np.random.default_rng(seed)
    img = np.zeros((160, 220), np.float32)
    for y0 in (20, 70, 120):
        a, b = (0, y0 + 30), (220, y0 - 10)
        cv2.line(img, a, b, 1.0, 5)
        for t in np.linspace(0.1, 0.9, 9):
            x, y = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
            side = 1 if rng.random() < 0.5 else -1
            cv2.line(img, (int(x), int(y)), (int(x + 8), int(y + side * 14)), 1.0, 2)
    img = cv2.GaussianBlur(img, (0, 0), 0.8)
    return np.clip(np.where(img > 0.02, img + rng.normal(0, 0.03, img.shape), 0.0), 0, 1).astype(np.float32)


def test_a_flat_background_between_veins_is_no_frame() -> None:
    # issue 19: a venation mask saved as a JPEG is not two-level, and its black background is
    # flat and touches the border. Taken for a frame, it left a quarter of the image to trace
    # (three pieces of vein) and the gaps had no background to copy.
    img = _venation()
    ok = valid_region(img)
    assert ok.all()
    # its picture would be far from convex; a fundus photo's disc is not
    assert _solidity(img > 0.02) < 0.5 < MIN_SOLIDITY
    fundus, disc = _fundus()
    assert _solidity(disc) > 0.95 and not valid_region(fundus).all()


def test_trace_leaves_the_frame_rim_alone() -> None:
    img, disc = _fundus()
    ring = disc & ~cv2.erode(disc.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)

    def on_rim(sk) -> int:
        pts = np.concatenate([b.points for b in sk.branches])
        return int(ring[np.rint(pts[:, 1]).astype(int), np.rint(pts[:, 0]).astype(int)].sum())

    plain = trace(img, kind="dark", sigmas=(1.5, 2.5))
    framed = trace(img, kind="dark", sigmas=(1.5, 2.5), valid=valid_region(img))
    assert on_rim(plain) > 20  # the rim reads as a dark ridge
    assert on_rim(framed) == 0
    # the vessels are still there: most of their length
    assert framed.total_length() > 0.7 * (100 + 58)
    with pytest.raises(ValueError, match="^valid:"):
        trace(img, valid=np.ones((10, 10), bool))


def test_synthesize_keeps_the_frame_out_of_the_picture() -> None:
    img, disc = _fundus()
    ring = disc & ~cv2.erode(disc.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    opts = {"kind": "dark", "sigmas": (1.5, 2.5)}

    inner = cv2.erode(disc.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)

    def run(valid, seed: int) -> tuple[float, float, int]:
        # without the structure paste, which lifts black fragments to the level of the gaps
        res = synthesize(img, seed=seed, trace_options=opts, valid=valid, render_options={"paste_structure": False})
        pts = np.concatenate([b.points for b in res.source.branches])
        rim = int(ring[np.rint(pts[:, 1]).astype(int), np.rint(pts[:, 0]).astype(int)].sum())
        # the frame is 0; a vessel (0.25 in the input) matched to darker surroundings reaches 0.1
        black = res.image.max(axis=2) < 0.05
        return float(black[inner].mean()), float(black[~disc].mean()), rim

    # Without `valid` the frame is part of the background: the rim is traced as a branch (its
    # fragments, half black frame, are outliers of the fragments' surroundings and not pasted)
    # and no black reaches the disc (the gaps' layout keeps the frame's dark surround in place,
    # its rim being an edge of the background, so the surround's darkness says nothing here).
    # With `valid="auto"` the rim is not traced, the gaps come from the disc only (no black
    # inside) and the output keeps the input's frame around it.
    for s in range(3):
        inside, _, rim = run(None, s)
        assert rim > 20 and inside < 0.001
        inside, outside, rim = run("auto", s)
        assert inside == 0.0 and rim == 0 and outside > 0.9  # black but for the fade at its rim
    with pytest.raises(ValueError, match="^valid:"):
        synthesize(img, valid="frame")


def test_a_kept_frame_s_rim_is_put_back_smooth() -> None:
    # A JPEG's noise makes the flat-frame test follow a staircase of teeth along a disc's rim;
    # the new picture's rim follows the disc, not the teeth. The radius at which the kept frame
    # begins, per direction, varies by a fraction of a pixel around the circle, where the teeth
    # vary by two pixels (by 0.9 px in the fade's middle without the smoothing).
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:200, :200]
    radius = np.hypot(yy - 100.0, xx - 100.0)
    teeth = rng.integers(-2, 3, size=360)[(np.degrees(np.arctan2(yy - 100.0, xx - 100.0)).astype(int) + 360) % 360]
    valid = radius < 80 + teeth
    image = np.where(valid, 0.6, 0.0).astype(np.float32)[..., None]
    canvas = np.full((200, 200, 1), 0.6, np.float32)

    def rim_spread(inside: np.ndarray) -> float:
        angle = np.degrees(np.arctan2(yy - 100.0, xx - 100.0)).astype(int) % 360
        first = np.full(360, np.inf)
        np.minimum.at(first, angle[~inside], radius[~inside])
        return float(np.std(first))

    _keep_frame(canvas, image, valid)
    assert rim_spread(valid) > 1.0
    assert rim_spread(canvas[..., 0] > 0.3) < 0.65
    assert float(canvas[radius > 90].max()) == 0.0 and float(canvas[radius < 70].min()) == pytest.approx(0.6)
