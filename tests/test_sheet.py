"""The contact-sheet tiles shared by the pipelines' sheets."""

from __future__ import annotations

import numpy as np

from phloem._sheet import PAPER, caption, fit_tile


def test_fit_tile_centres_and_composites_over_the_paper() -> None:
    wide = np.zeros((50, 100, 3), np.float32)
    t = fit_tile(wide, 40)
    assert t.shape == (40, 40, 3)
    assert np.allclose(t[20, :], 0.0) and np.allclose(t[0, :], PAPER) and np.allclose(t[-1, :], PAPER)
    rgba = np.zeros((30, 30, 4), np.float32)
    rgba[..., 0] = 1.0
    rgba[:, 15:, 3] = 1.0  # right half opaque red, left half transparent
    t = fit_tile(rgba, 30)
    assert np.allclose(t[10, 2], PAPER) and np.allclose(t[10, 27], (1.0, 0.0, 0.0))


def test_caption_writes_dark_text_at_the_top_left_only() -> None:
    img = np.full((40, 120, 3), PAPER, np.float32)
    out = caption(img, "seam")
    changed = np.abs(out - img).max(axis=2) > 0.1
    assert changed[:18, :60].any() and not changed[20:].any()
    assert out.min() < 0.3
