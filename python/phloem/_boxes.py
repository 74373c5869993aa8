"""Bounding boxes of masks and of point sets, as the slices that crop an array to them."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["bounding_box", "points_box"]


def points_box(rows: NDArray[Any], cols: NDArray[Any], shape: tuple[int, ...], margin: int = 0) -> tuple[slice, slice]:
    """``(rows, cols)`` slices of the box around the pixels ``(rows[i], cols[i])`` grown by
    ``margin`` and clipped to an array of ``shape``; the whole array when there are none."""
    h, w = shape[0], shape[1]
    if len(rows) == 0:
        return slice(0, h), slice(0, w)
    y0, y1 = max(int(rows.min()) - margin, 0), min(int(rows.max()) + margin + 1, h)
    x0, x1 = max(int(cols.min()) - margin, 0), min(int(cols.max()) + margin + 1, w)
    return slice(y0, y1), slice(x0, x1)


def bounding_box(mask: NDArray[np.bool_], margin: int = 0) -> tuple[slice, slice]:
    """The :func:`points_box` of the True pixels of ``mask``."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return slice(0, mask.shape[0]), slice(0, mask.shape[1])
    return points_box(rows[[0, -1]], cols[[0, -1]], mask.shape, margin)
