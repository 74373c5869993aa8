"""Exemplar ingest: an atlas cut into single trees, and each tree normalised (Argudo et al. 2017 §4.1).

:func:`split_atlas` is phloem's own (the paper's library holds one tree per image; atlases such as
FlightGear's hold many); :func:`normalize` is §4.1.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import check_int
from ._checks import F32, as_rgba, check_alpha_threshold

__all__ = ["normalize", "split_atlas"]


def normalize(rgba: Any, *, size: int = 1024, alpha_threshold: float = 0.5) -> F32:
    """Normalise a tree exemplar to a square image of fixed size (paper §4.1).

    Pixels whose alpha is below ``alpha_threshold`` count as transparent and are set to black
    (alpha 0). The image is cropped to the bounding box of the opaque pixels, padded with a
    black transparent border to a square, and resized to ``size`` x ``size``. The paper does not
    say where the padding goes; phloem keeps the tree standing on the bottom edge and centred
    horizontally (a wide tree gets its padding on top, a tall one on both sides).

    Parameters
    ----------
    rgba : (M, N, 4) ndarray
        RGBA exemplar, any real dtype (integers are scaled to [0, 1]).
    size : int, optional
        Side of the output (the paper used 1024).
    alpha_threshold : float, optional
        Alpha below this is transparent (the paper's 0.5).

    Returns
    -------
    (size, size, 4) float32 ndarray
        The normalised RGBA image; transparent pixels are exactly 0 in all channels.

    Raises
    ------
    ValueError
        If ``rgba`` has no alpha channel or no opaque pixel.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((40, 30, 4), np.float32)
    >>> img[10:30, 12:17] = 1.0          # a 20 x 5 opaque bar
    >>> out = phloem.trees.normalize(img, size=64)
    >>> out.shape, out.dtype
    ((64, 64, 4), dtype('float32'))
    >>> ys, xs = np.nonzero(out[..., 3] >= 0.5)
    >>> int(ys.min()), int(ys.max()), int(xs.min()), int(xs.max())
    (0, 63, 22, 37)
    """
    img = as_rgba(rgba)
    size = check_int(size, "size", 2)
    t = check_alpha_threshold(alpha_threshold)
    opaque = img[..., 3] >= t
    if not opaque.any():
        raise ValueError(f"rgba: expected some pixels with alpha >= {t}, the image is fully transparent")
    img = img.copy()
    img[~opaque] = 0.0
    ys, xs = np.nonzero(opaque)
    crop = img[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    h, w = crop.shape[:2]
    side = max(h, w)
    square = np.zeros((side, side, 4), np.float32)
    x0 = (side - w) // 2
    square[side - h :, x0 : x0 + w] = crop
    interp = cv2.INTER_AREA if side > size else cv2.INTER_LINEAR
    out = cv2.resize(square, (size, size), interpolation=interp)
    out = np.clip(out, 0.0, 1.0).astype(np.float32)
    out[out[..., 3] < t] = 0.0
    return np.ascontiguousarray(out)


def split_atlas(
    rgba: Any, *, min_area: int = 64, alpha_threshold: float = 0.5, gap: int = 1, join: int = 8
) -> list[F32]:
    """Cut an atlas of several tree billboards into single trees.

    The alpha mask (after a 3 x 3 closing) is split recursively into bands of rows and columns
    separated by fully transparent lines at least ``gap`` pixels wide (an X-Y cut), first
    across the rows, then across the columns of each band, until no cut remains. Each piece is
    one tree, so branches that the mask shows disconnected from their tree stay with it. A piece
    with fewer than ``min_area`` opaque pixels (a twig cut off by a transparent line) joins the
    nearest tree at most ``join`` pixels away, or is dropped.

    Parameters
    ----------
    rgba : (M, N, 4) ndarray
        The atlas, any real dtype.
    min_area : int, optional
        Smallest number of opaque pixels of a tree.
    alpha_threshold : float, optional
        Alpha below this is transparent.
    gap : int, optional
        Smallest width of a transparent line that separates two trees.
    join : int, optional
        Largest distance (between bounding boxes) over which a small piece joins a tree.

    Returns
    -------
    list of (H, W, 4) float32 ndarray
        The trees in reading order (top to bottom, then left to right), each cropped to its
        opaque bounding box. Trees that touch each other in the atlas (no transparent line
        between them) come out as one piece: split those by hand.

    Raises
    ------
    ValueError
        If ``rgba`` has no alpha channel or no piece reaches ``min_area``.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> atlas = np.zeros((20, 30, 4), np.float32)
    >>> atlas[2:8, 2:8] = atlas[2:8, 20:26] = atlas[12:18, 5:9] = 1.0
    >>> [t.shape[:2] for t in phloem.trees.split_atlas(atlas, min_area=4)]
    [(6, 6), (6, 6), (6, 4)]
    """
    img = as_rgba(rgba)
    min_area = check_int(min_area, "min_area", 1)
    gap = check_int(gap, "gap", 1)
    join = check_int(join, "join", 0)
    t = check_alpha_threshold(alpha_threshold)
    opaque = img[..., 3] >= t
    closed = cv2.morphologyEx(opaque.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)) > 0
    closed |= opaque

    def runs(profile: NDArray[np.bool_]) -> list[tuple[int, int]]:
        # Maximal runs of occupied lines, merging those separated by fewer than `gap` empty lines.
        idx = np.flatnonzero(profile)
        if idx.size == 0:
            return []
        breaks = np.flatnonzero(np.diff(idx) > gap)
        starts = np.concatenate([[idx[0]], idx[breaks + 1]])
        ends = np.concatenate([idx[breaks], [idx[-1]]]) + 1
        return list(zip(starts.tolist(), ends.tolist(), strict=True))

    boxes: list[tuple[int, int, int, int]] = []

    def cut(y0: int, y1: int, x0: int, x1: int, axis: int) -> None:
        sub = closed[y0:y1, x0:x1]
        parts = runs(np.asarray(sub.any(axis=1 - axis)))
        if len(parts) <= 1:
            other = runs(np.asarray(sub.any(axis=axis)))
            if len(other) <= 1:
                ys, xs = np.nonzero(sub)
                if ys.size:
                    boxes.append(
                        (y0 + int(ys.min()), y0 + int(ys.max()) + 1, x0 + int(xs.min()), x0 + int(xs.max()) + 1)
                    )
                return
            return cut(y0, y1, x0, x1, 1 - axis)
        for a, b in parts:
            if axis == 0:
                cut(y0 + a, y0 + b, x0, x1, 1)
            else:
                cut(y0, y1, x0 + a, x0 + b, 0)

    cut(0, closed.shape[0], 0, closed.shape[1], 0)
    area = [int(opaque[y0:y1, x0:x1].sum()) for y0, y1, x0, x1 in boxes]
    big = [i for i, a in enumerate(area) if a >= min_area]
    merged = {i: list(boxes[i]) for i in big}
    for i, (y0, y1, x0, x1) in enumerate(boxes):
        if area[i] >= min_area or not big:
            continue
        # A small piece (a twig cut off by a transparent line) joins the nearest tree within `join`.
        dist = [max(by0 - y1, y0 - by1, bx0 - x1, x0 - bx1, 0) for by0, by1, bx0, bx1 in (boxes[j] for j in big)]
        j = big[int(np.argmin(dist))]
        if min(dist) <= join:
            box = merged[j]
            merged[j] = [min(box[0], y0), max(box[1], y1), min(box[2], x0), max(box[3], x1)]
    trees = []
    for i in big:
        y0, y1, x0, x1 = merged[i]
        piece = img[y0:y1, x0:x1].copy()
        piece[~opaque[y0:y1, x0:x1]] = 0.0
        trees.append(piece)
    if not trees:
        raise ValueError(f"rgba: found no tree with at least min_area={min_area} opaque pixels")
    return trees
