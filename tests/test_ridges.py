"""The ridge filter shared by the branching trace and the leaves' scribbles (phloem._ridges)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem._ridges import ridge_response

SIGMAS = (1.0, 2.0, 3.0)


def _line(centre: float) -> np.ndarray:
    """A bright horizontal line 1 px wide (a Gaussian profile of 0.5 px) at row ``centre``."""
    y = np.arange(41, dtype=np.float32)[:, None] * np.ones((1, 60), np.float32)
    return (0.2 + 0.5 * np.exp(-((y - centre) ** 2) / (2 * 0.5**2))).astype(np.float32)


@pytest.mark.parametrize("sigmas", [(1.0,), SIGMAS])
def test_subpixel_response_does_not_depend_on_where_the_line_falls(sigmas):
    # On the pixel grid the edge term sees the gradient at the pixel centre, which is not the
    # line's centre when the line falls between two rows: at sigma 1 it loses everything.
    def peak(centre: float, subpixel: bool) -> float:
        return float(ridge_response(_line(centre), sigmas, "bright", subpixel=subpixel)[15:26, 30].max())

    on, off = peak(20.0, True), peak(20.5, True)
    assert off > 0.85 * on > 0
    if sigmas == (1.0,):
        assert peak(20.5, False) == 0.0 < peak(20.0, False)


def test_subpixel_response_keeps_step_edges_out():
    y = np.arange(41, dtype=np.float32)[:, None] * np.ones((1, 60), np.float32)
    step = cv2.GaussianBlur(np.where(y > 20.3, 0.8, 0.2).astype(np.float32), (0, 0), 0.7)
    line = float(ridge_response(_line(20.5), SIGMAS, "bright", subpixel=True).max())
    for subpixel in (False, True):
        assert float(ridge_response(step, SIGMAS, "bright", subpixel=subpixel).max()) < 0.1 * line
