"""The contour space: convex combinations of resampled contours and the alpha they enclose (Argudo et al. 2017 §5.1)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from .._api import Size, renamed
from .._validate import check_convex_weights, check_size
from ._checks import F64, Mask, as_points

__all__ = ["combine_contours", "fill_contour"]


@renamed(shape="size")
def fill_contour(points: Any, size: Size) -> Mask:
    """Preliminary alpha of a synthesised contour: draw it, then clear from outside (§5.1).

    The closed polyline is drawn onto an all-opaque canvas, and a flood fill from outside the
    image clears everything reachable without crossing it. Unlike a polygon fill this stays
    correct where a combined contour intersects itself: every pixel enclosed by some part of
    the curve is kept.

    Parameters
    ----------
    points : (K, 2) ndarray
        Closed contour, ``(x, y)``.
    size : int or (int, int)
        ``(H, W)`` of the mask (``shape`` before, deprecated).

    Returns
    -------
    (H, W) bool ndarray
        ``True`` inside (and on) the contour.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> bowtie = [(2, 2), (12, 12), (12, 2), (2, 12)]     # self-intersecting
    >>> m = phloem.trees.fill_contour(bowtie, (15, 15))
    >>> bool(m[7, 3]), bool(m[7, 11]), bool(m[3, 7]), bool(m[0, 0])
    (True, True, False, False)
    """
    p = as_points(points, "points")
    h, w = check_size(size)
    # A one-pixel margin joins every outside region to the seed; the canvas also holds the curve's
    # parts outside the image (clamped at one image size beyond), so no gap lets the fill in.
    lim = np.array([w, h], np.float64)
    p = np.clip(p, -lim, 2 * lim - 1)
    x0, y0 = (min(0, int(np.floor(v))) - 1 for v in p.min(axis=0))
    x1, y1 = (max(n - 1, int(np.ceil(v))) + 1 for n, v in zip((w, h), p.max(axis=0)))
    canvas = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    pts = np.round((p - [x0, y0]) * 16).astype(np.int32)
    cv2.polylines(canvas, [pts], True, 1, thickness=1, lineType=cv2.LINE_8, shift=4)
    flood = np.zeros((canvas.shape[0] + 2, canvas.shape[1] + 2), np.uint8)
    cv2.floodFill(canvas, flood, (0, 0), 2, loDiff=0, upDiff=0, flags=4 | (1 << 8))
    reached = flood[1 - y0 : 1 - y0 + h, 1 - x0 : 1 - x0 + w] > 0
    return np.asarray(~reached)


def combine_contours(contours: Sequence[Any], weights: Any) -> F64:
    """A convex combination ``Σ w_i C_i`` of resampled contours (paper §5.1).

    The paper combines the mean-subtracted vectors ``u_i``; combining the contours themselves
    gives the same shape, placed at the combined centroid, so a tree standing on the bottom
    edge of every exemplar still stands there.

    Parameters
    ----------
    contours : sequence of (N, 2) ndarray
        Resampled contours ``C_r`` with the same number of points (:attr:`Tree.resampled`).
    weights : (len(contours),) array_like
        Non-negative, summing to 1 (negative weights would mirror shapes).

    Returns
    -------
    (N, 2) float64 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]); b = a * 2
    >>> phloem.trees.combine_contours([a, b], [0.5, 0.5]).tolist()
    [[0.0, 0.0], [6.0, 0.0], [6.0, 6.0]]
    """
    if len(contours) < 1:
        raise ValueError("contours: expected at least one contour")
    cs = [as_points(c, f"contours[{i}]") for i, c in enumerate(contours)]
    if len({c.shape for c in cs}) != 1:
        raise ValueError(f"contours: expected the same number of points in each, got {[len(c) for c in cs]}")
    w = check_convex_weights(weights, len(cs), "weights")
    return np.asarray(np.tensordot(w, np.stack(cs), axes=1), dtype=np.float64)
