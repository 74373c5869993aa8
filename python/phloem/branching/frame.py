"""Where a photo shows its subject: everything but a flat frame around it.

Fundus photos sit in a black disc frame, scans and crops are padded with a constant colour.
The frame's rim is a strong edge that tracing takes for structure, and its colour is what gap
completion would copy; :func:`valid_region` finds it so that ``trace`` and ``render`` can
leave it out (their ``valid=``).
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import as_image, check_float
from ._pixels import two_level

__all__ = ["valid_region"]

#: Smallest share of its convex hull that the picture inside a frame fills: a frame surrounds a
#: disc or a quadrilateral (measurements in docs/pipelines/branching/quality.md).
MIN_SOLIDITY = 0.75
#: Smallest share of the image's border along which a frame runs for a new image to keep it: a
#: side of the image (the short side of a 2:1 photo is a sixth), as padding, a disc's surround
#: or a tree line along the bottom run; a flat patch of dark ground is left to the gaps.
KEEP_MIN_BORDER = 1 / 6
#: Pixels over which a kept frame fades in from the new picture's side (see ``_keep_frame``).
FEATHER = 4.0
#: Gaussian scale (px) over which a kept frame's rim is smoothed before it is put back: the
#: flat-region test follows a JPEG's noise, a staircase of 1-3 px teeth along a disc's rim.
RIM_SMOOTH = 3.0


def valid_region(image: Any, *, tolerance: float = 0.01, min_share: float = 0.01, margin: int = 2) -> NDArray[np.bool_]:
    """The pixels of ``image`` that are not part of a flat frame touching its border.

    A frame is a region connected to the image border that is flat (no pixel differs
    from a 4-neighbour in it by more than ``tolerance``, relative to the image's value range),
    less its pixels farther than ``2 tolerance`` from its median colour, which must vary by at
    most ``tolerance / 2`` (standard deviation) and at least
    ``min_share`` of the image. It is widened by ``margin`` pixels, for the rim's blur. A
    two-level image (a mask) has no frame: its background is content. Nor has an image whose
    flat border regions would leave a picture far from convex (its largest piece under
    :data:`MIN_SOLIDITY` of its convex hull): a frame surrounds a disc or a quadrilateral, while
    a flat background between a leaf's veins or a river's channels reaches deep into them.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The photo; integer images are scaled to [0, 1].
    tolerance : float, optional
        Largest step between neighbouring frame pixels, as a share of the image's value range
        (default 0.01, about 2.5 8-bit levels on a full-range photo).
    min_share : float, optional
        Smallest frame, as a share of the image (default 0.01).
    margin : int, optional
        Pixels added around the frame (default 2).

    Returns
    -------
    (H, W) ndarray of bool
        True where the image shows content.

    Examples
    --------
    >>> img = np.zeros((100, 100), np.float32)
    >>> yy, xx = np.mgrid[:100, :100]
    >>> disc = (yy - 50) ** 2 + (xx - 50) ** 2 < 45**2
    >>> img[disc] = 0.5 + 0.2 * np.sin(xx[disc] / 3.0)
    >>> ok = valid_region(img)
    >>> bool(ok[50, 50]), bool(ok[0, 0]), bool(abs(ok.mean() - disc.mean()) < 0.05)
    (True, False, True)
    """
    img = as_image(image, "image")
    tol = check_float(tolerance, "tolerance", 0.0)
    share = check_float(min_share, "min_share", 0.0)
    if isinstance(margin, bool) or not isinstance(margin, int) or margin < 0:
        raise ValueError(f"margin: expected a non-negative integer, got {margin!r}")
    H, W, _ = img.shape
    lo = img.reshape(-1, img.shape[2]).min(axis=0)
    hi = img.reshape(-1, img.shape[2]).max(axis=0)
    if two_level(img, lo, hi):
        return np.ones((H, W), bool)
    # tolerances relative to the image's own range (a 16-bit elevation model spans 1 % of it)
    tol *= float((hi - lo).max())
    # flat: every 4-neighbour within the tolerance
    step = np.zeros((H, W), np.float32)
    dy = np.abs(np.diff(img, axis=0)).max(axis=2)
    dx = np.abs(np.diff(img, axis=1)).max(axis=2)
    step[:-1] = np.maximum(step[:-1], dy)
    step[1:] = np.maximum(step[1:], dy)
    step[:, :-1] = np.maximum(step[:, :-1], dx)
    step[:, 1:] = np.maximum(step[:, 1:], dx)
    flat = (step <= tol).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(flat, connectivity=4)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    frame = np.zeros((H, W), bool)
    for lab in border:
        if lab == 0 or stats[lab, cv2.CC_STAT_AREA] < share * H * W:
            continue
        region = labels == lab
        # a frame is one colour (give or take the noise), not a smooth plateau that happens to
        # be flat step by step: the pixels near its median value, if they vary by little
        vals = img[region]
        near = (np.abs(vals - np.median(vals, axis=0)) <= 2 * tol).all(axis=1)
        if near.sum() >= share * H * W and float(vals[near].std(axis=0).max()) <= 0.5 * tol:
            part = np.zeros((H, W), bool)
            part[region] = near
            frame |= part
    if frame.any() and _solidity(~frame) < MIN_SOLIDITY:
        return np.ones((H, W), bool)
    if margin and frame.any():
        frame = cv2.dilate(frame.astype(np.uint8), np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)).astype(bool)
    return np.asarray(~frame)


def _solidity(inside: NDArray[np.bool_]) -> float:
    """The area of ``inside``'s largest 8-connected piece over that of its convex hull."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(inside.astype(np.uint8), connectivity=8)
    if n < 2:
        return 1.0
    big = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    ys, xs = np.nonzero(labels == big)
    hull = cv2.convexHull(np.stack([xs, ys], axis=1).astype(np.int32))
    # pixel centres: the hull of a w x h block is (w - 1) x (h - 1); count its rim too
    return float(min(1.0, len(ys) / max(cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1.0, 1.0)))


def _stretched(valid: NDArray[np.bool_], shape: tuple[int, int]) -> NDArray[np.bool_]:
    """``valid`` stretched to ``shape`` (nearest pixel): where a new image of that size shows content."""
    if valid.shape == tuple(shape):
        return valid
    H, W = shape
    return np.asarray(cv2.resize(valid.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST), bool)


def _kept_inside(valid: NDArray[np.bool_], shape: tuple[int, int]) -> NDArray[np.bool_] | None:
    """Where a new image of ``shape`` shows its picture inside the input's kept frame:
    ``valid`` stretched to it, when the frame outside ``valid`` runs along at least
    :data:`KEEP_MIN_BORDER` of the image's border; None when no frame is kept."""
    frame = ~valid
    border = np.concatenate([frame[0], frame[-1], frame[1:-1, 0], frame[1:-1, -1]])
    if border.mean() < KEEP_MIN_BORDER:
        return None
    inside = _stretched(valid, shape)
    return None if inside.all() else inside


def _keep_frame(canvas: NDArray[np.float32], image: NDArray[np.float32], valid: NDArray[np.bool_]) -> None:
    """Put ``image``'s kept frame (outside ``valid``, see :func:`_kept_inside`), stretched to
    ``canvas``'s size, into ``canvas``."""
    H, W = canvas.shape[:2]
    inside = _kept_inside(valid, (H, W))
    if inside is None:
        return
    inside = cv2.GaussianBlur(inside.astype(np.float32), (0, 0), RIM_SMOOTH, borderType=cv2.BORDER_REPLICATE) >= 0.5
    frame = image
    if image.shape[:2] != (H, W):
        frame = np.asarray(cv2.resize(image, (W, H), interpolation=cv2.INTER_LINEAR), np.float32).reshape(H, W, -1)
    # faded in over its first FEATHER px: its rim (widened by valid_region's margin, a square)
    # holds some of the input's background, which need not match the new picture beside it
    d = cv2.distanceTransform((~inside).astype(np.uint8), cv2.DIST_L2, 5)
    alpha = np.clip((d - 0.5) / FEATHER, 0.0, 1.0)[..., None]
    out = ~inside
    canvas[out] = (alpha * frame + (1.0 - alpha) * canvas)[out]
