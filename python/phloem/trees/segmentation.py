"""Training-free crown/trunk segmentation and the crown baseline (Argudo et al. 2017 §4.3).

The paper fine-tunes an FCN-8s on 55 hand-segmented trees; its weights cannot be shipped, so
:func:`segment` reads the width profile of the opaque mask instead (and
:class:`~phloem.trees.TrunkClassifier` learns from a few labelled trees where that fails).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from .._validate import as_mask, check_float
from ._checks import Mask, as_alpha_mask, as_rgba, check_alpha_threshold

__all__ = ["crown_baseline", "segment"]


def segment(
    rgba: Any,
    *,
    alpha_threshold: float = 0.5,
    jump: float = 2.5,
    min_crown_width: float = 0.2,
    taper: float = 3.0,
    smooth: float = 0.01,
) -> Mask:
    """Segment the trunk from the crown without training (replaces the paper's FCN, §4.3).

    The paper fine-tuned an FCN on 55 hand-segmented trees; its weights cannot be shipped. This
    classical segmenter reads the width profile of the opaque mask: the number of opaque pixels
    on each row, median-filtered over ``smooth`` x height rows. The trunk width is the median
    width over the lowest 2 % of the tree. Climbing from the bottom, the crown starts (the
    *crown baseline*) at the first row wider than ``jump`` times the trunk width and wider than
    ``min_crown_width`` times the widest row. Opaque pixels below the baseline that are connected
    to the bottom row are trunk. A tree whose bottom is already that wide (a shrub, a conifer
    with branches to the ground) has no trunk. Trunk parts seen through the crown are not
    labelled: only the baseline matters for the pin points (§4.4).

    Parameters
    ----------
    rgba : (M, N, 4) ndarray
        A normalised exemplar (see :func:`normalize`); works at any size.
    alpha_threshold : float, optional
        Alpha at or above this is opaque.
    jump : float, optional
        How many times wider than the trunk a row must be to belong to the crown.
    min_crown_width : float, optional
        Smallest crown row width, as a fraction of the widest row.
    taper : float, optional
        Below the jump, rows wider than ``taper`` times the trunk width still belong to the
        crown (its underside narrowing into the trunk).
    smooth : float, optional
        Median filter length as a fraction of the image height.

    Returns
    -------
    (M, N) bool ndarray
        True on trunk pixels.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((100, 100, 4), np.float32)
    >>> img[20:60, 20:80] = 1.0            # crown
    >>> img[60:100, 45:55] = 1.0           # trunk
    >>> trunk = phloem.trees.segment(img)
    >>> int(trunk.sum()), bool(trunk[60:, 45:55].all())
    (400, True)
    """
    img = as_rgba(rgba)
    t = check_alpha_threshold(alpha_threshold)
    jump = check_float(jump, "jump", 1.0, inclusive=False)
    taper = check_float(taper, "taper", 1.0)
    min_crown_width = check_float(min_crown_width, "min_crown_width", 0.0)
    smooth = check_float(smooth, "smooth", 0.0)
    opaque = img[..., 3] >= t
    trunk = np.zeros(opaque.shape, np.bool_)
    rows = np.flatnonzero(opaque.any(axis=1))
    if rows.size < 3:
        return trunk
    top, bottom = int(rows[0]), int(rows[-1])
    width = opaque.sum(axis=1).astype(np.float64)
    k = max(1, round(smooth * opaque.shape[0]))
    k += 1 - k % 2
    if k > 1:
        padded = np.pad(width, k // 2, mode="edge")
        width = np.median(np.lib.stride_tricks.sliding_window_view(padded, k), axis=1)
    height = bottom - top + 1
    # A low quantile over the lowest tenth ignores a flared foot and the crown rows it may hold.
    base = width[max(top, bottom - max(1, int(0.1 * height)) + 1) : bottom + 1]
    trunk_width = float(np.quantile(base, 0.3))
    widest = float(width[top : bottom + 1].max())
    if trunk_width >= min_crown_width * widest:
        return trunk  # the bottom is already crown-wide: no visible trunk
    limit = max(jump * trunk_width, min_crown_width * widest)
    # Climb from the bottom: past the foot into the trunk, then up to the first crown-wide row.
    y = bottom
    while y > top and width[y] > 1.5 * trunk_width:
        y -= 1
    while y > top and width[y] <= limit:
        y -= 1
    if y <= top:
        return trunk
    # The crown's underside tapers into the trunk: step down through rows still clearly wider
    # than the trunk so that the baseline is the lowest crown row, not the row of the jump.
    while y < bottom and width[y + 1] > taper * trunk_width:
        y += 1
    baseline = y  # lowest crown row
    below = opaque.copy()
    below[: baseline + 1] = False
    _, labels = cv2.connectedComponents(below.astype(np.uint8), connectivity=8)
    keep = np.unique(labels[bottom][below[bottom]])
    trunk = np.isin(labels, keep[keep > 0])
    return np.ascontiguousarray(trunk)


def crown_baseline(trunk: Any, alpha: Any, *, alpha_threshold: float = 0.5) -> int:
    """Row of the crown baseline: the lowest row holding an opaque non-trunk pixel."""
    t = check_alpha_threshold(alpha_threshold)
    opaque = as_alpha_mask(alpha, t)
    tm = as_mask(trunk, "trunk", opaque.shape)
    rows = np.flatnonzero((opaque & ~tm).any(axis=1))
    if rows.size == 0:
        raise ValueError("trunk: expected some crown pixels, every opaque pixel is trunk")
    return int(rows[-1])
