"""Tree billboards: the exemplar preprocessing of Argudo et al. 2017, *Tree Variations* (§4).

Each RGBA side view of a tree (an *exemplar*) becomes a fixed-length contour that can be
combined linearly with the contours of other exemplars (§5.1):

1. :func:`normalize` thresholds the alpha channel, blackens transparent pixels, crops to the
   opaque bounding box, pads to a square and resizes (§4.1);
2. :func:`contour` takes the longest exterior contour of the alpha mask, counter-clockwise (§4.2);
3. :func:`segment` separates the trunk from the crown (§4.3; the paper's fine-tuned FCN is
   replaced by a classical width-profile segmenter, and a user mask can be given instead);
4. :func:`pin_points` finds the tree bottom B and the trunk tops L and R (§4.4);
5. :func:`resample` resamples the contour to 2000 points, 1600 on the crown and 200 on each
   side of the trunk, with uniform chord lengths in each segment (§4.5);
6. :func:`simplify` makes the 100-point contour of the dilated interior used for mean value
   coordinates (§4.6).

:func:`prepare` runs all six and returns a :class:`Tree`. :func:`split_atlas` cuts an atlas of
several billboards (e.g. FlightGear's tree textures) into single trees first.

Coordinates are ``(x, y)`` pixel positions, origin top-left, ``y`` growing downwards (the
project's convention). *Counter-clockwise* means as seen on the screen, so the paper's "minimum
``y``" (its ``y`` grows upwards) is the *largest* row here.

References
----------
.. [1] O. Argudo, C. Andújar, A. Chica, "Tree Variations", CEIG 2017 (Eurographics
   Proceedings), doi:10.2312/ceig.20171218.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import io, warp
from .._validate import as_image, as_mask, check_convex_weights, check_float, check_int

__all__ = [
    "Library",
    "Tree",
    "TrunkClassifier",
    "Variation",
    "cages",
    "combine_contours",
    "contour",
    "fill_contour",
    "match_histograms",
    "morph",
    "morph_table",
    "normalize",
    "pin_points",
    "prepare",
    "resample",
    "segment",
    "signed_area",
    "simplify",
    "split_atlas",
    "variation",
    "vary",
]

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
Mask = NDArray[np.bool_]


def _rgba(rgba: Any, name: str = "rgba") -> F32:
    img = as_image(rgba, name)
    if img.shape[2] != 4:
        raise ValueError(f"{name}: expected an RGBA image with 4 channels, got {img.shape[2]}")
    return img


def _threshold(alpha_threshold: Any) -> float:
    t = check_float(alpha_threshold, "alpha_threshold", 0.0, inclusive=False)
    if t > 1.0:
        raise ValueError(f"alpha_threshold: expected a value in (0, 1], got {alpha_threshold}")
    return t


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
    img = _rgba(rgba)
    size = check_int(size, "size", 2)
    t = _threshold(alpha_threshold)
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
    img = _rgba(rgba)
    min_area = check_int(min_area, "min_area", 1)
    gap = check_int(gap, "gap", 1)
    join = check_int(join, "join", 0)
    t = _threshold(alpha_threshold)
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


def signed_area(points: Any) -> float:
    """Signed area of a closed polygon, positive when it runs counter-clockwise on screen.

    With image coordinates (``y`` down) this is minus the usual shoelace sum, so that the
    paper's counter-clockwise contours have a positive area.

    Examples
    --------
    >>> import phloem
    >>> phloem.trees.signed_area([(0, 0), (0, 2), (2, 2), (2, 0)])   # down, right, up on screen
    4.0
    """
    p = _points(points, "points")
    x, y = p[:, 0], p[:, 1]
    return float(-0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _points(points: Any, name: str) -> F64:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 1:
        raise ValueError(f"{name}: expected an (N, 2) array of (x, y) points, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{name}: expected finite coordinates")
    return np.ascontiguousarray(p)


def _alpha_mask(alpha: Any, alpha_threshold: float) -> Mask:
    arr = np.asarray(alpha)
    if arr.dtype == np.bool_:
        return as_mask(arr, "alpha", arr.shape[:2])
    img = as_image(arr, "alpha")
    if img.shape[2] == 4:
        img = img[..., 3:]
    if img.shape[2] != 1:
        raise ValueError(f"alpha: expected an (H, W) alpha channel or an RGBA image, got {img.shape[2]} channels")
    return np.ascontiguousarray(img[..., 0] >= alpha_threshold)


def contour(alpha: Any, *, alpha_threshold: float = 0.5) -> F64:
    """The overall tree contour: the longest exterior contour of the alpha mask (paper §4.2).

    All contours of the thresholded alpha are found by border following (Suzuki & Abe 1985,
    OpenCV's ``findContours`` with a two-level hierarchy); those not inside another contour are
    exterior, the rest interior (holes). The longest exterior contour is returned,
    counter-clockwise on screen (positive :func:`signed_area`), through the centres of its
    boundary pixels.

    Parameters
    ----------
    alpha : (M, N) ndarray or (M, N, 4) ndarray
        The alpha channel (bool, or real values compared with ``alpha_threshold``), or an RGBA
        image whose alpha is used.
    alpha_threshold : float, optional
        Alpha at or above this is opaque (the paper's 0.5).

    Returns
    -------
    (K, 2) float64 ndarray
        ``(x, y)`` of the contour pixels, in order, not repeating the first point.

    Raises
    ------
    ValueError
        If the mask is empty.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> m = np.zeros((8, 8), bool); m[2:5, 3:6] = True
    >>> c = phloem.trees.contour(m)
    >>> len(c), phloem.trees.signed_area(c) > 0
    (8, True)
    """
    t = _threshold(alpha_threshold)
    mask = _alpha_mask(alpha, t)
    if not mask.any():
        raise ValueError("alpha: expected some opaque pixels, the mask is empty")
    found, hierarchy = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    exterior = [c for c, h in zip(found, hierarchy[0], strict=True) if h[3] < 0]
    best = max(exterior, key=lambda c: cv2.arcLength(c, True))
    pts = best[:, 0, :].astype(np.float64)
    if len(pts) > 2 and signed_area(pts) < 0:
        pts = np.ascontiguousarray(pts[::-1])
    return pts


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
    img = _rgba(rgba)
    t = _threshold(alpha_threshold)
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


def _trunk_features(img: F32, opaque: Mask, prior: Mask) -> F64:
    """Per-pixel features of the opaque pixels (rows of the result, in ``np.nonzero`` order).

    Position (relative height, offset from the trunk's foot), the smoothed width profile (as a
    fraction of the widest row and against the foot's width), thickness (distance to the
    transparent background), CIELAB colour, local lightness contrast, and the training-free
    segmenter's answer with the signed height above its crown baseline.
    """
    h, w = opaque.shape
    ys, xs = np.nonzero(opaque)
    rows = np.flatnonzero(opaque.any(axis=1))
    top, bottom = int(rows[0]), int(rows[-1])
    height = float(bottom - top + 1)
    width = opaque.sum(axis=1).astype(np.float64)
    k = max(1, round(0.01 * h)) | 1
    padded = np.pad(width, k // 2, mode="edge")
    width = np.median(np.lib.stride_tricks.sliding_window_view(padded, k), axis=1)
    widest = max(float(width.max()), 1.0)
    base = width[max(top, bottom - max(1, int(0.1 * height)) + 1) : bottom + 1]
    foot = max(float(np.quantile(base, 0.3)), 1.0)
    low = ys >= bottom - max(1, int(0.02 * height))
    cx = float(np.median(xs[low])) if low.any() else w / 2
    dt = cv2.distanceTransform(opaque.astype(np.uint8), cv2.DIST_L2, 5)
    lab = cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2Lab)
    lum: F32 = np.ascontiguousarray(lab[..., 0] / 100.0, dtype=np.float32)
    mean = cv2.blur(lum, (7, 7))
    contrast = np.sqrt(np.maximum(cv2.blur(np.square(lum), (7, 7)) - mean * mean, 0.0))
    prows = np.flatnonzero((opaque & ~prior).any(axis=1))
    baseline = int(prows[-1]) if prows.size else bottom
    f = np.stack(
        [
            (ys - top) / height,
            np.abs(xs - cx) / widest,
            width[ys] / widest,
            np.log(np.maximum(width[ys], 1.0) / foot),
            dt[ys, xs] / widest,
            lum[ys, xs],
            lab[ys, xs, 1] / 128.0,
            lab[ys, xs, 2] / 128.0,
            contrast[ys, xs],
            prior[ys, xs].astype(np.float64),
            (ys - baseline) / height,
        ],
        axis=1,
    )
    return np.asarray(f, dtype=np.float64)


def _quadratic(f: F64) -> F64:
    iu = np.triu_indices(f.shape[1])
    return np.hstack([np.ones((len(f), 1)), f, f[:, iu[0]] * f[:, iu[1]]])


def _trunk_from_rows(opaque: Mask, raw: Mask) -> Mask:
    """The trunk as :func:`segment` defines it, from a per-pixel guess: climbing from the bottom,
    the crown baseline is the first row where under half of the opaque pixels are trunk; the
    trunk is the opaque part below it that touches the bottom row."""
    rows = np.flatnonzero(opaque.any(axis=1))
    bottom = int(rows[-1])
    n_op = opaque.sum(axis=1)
    n_tr = (raw & opaque).sum(axis=1)
    y = bottom
    while y >= rows[0] and n_op[y] > 0 and n_tr[y] * 2 >= n_op[y]:
        y -= 1
    out = np.zeros(opaque.shape, np.bool_)
    if y >= bottom:
        return out
    below = opaque.copy()
    below[: y + 1] = False
    _, labels = cv2.connectedComponents(below.astype(np.uint8), connectivity=8)
    keep = np.unique(labels[bottom][below[bottom]])
    return np.ascontiguousarray(np.isin(labels, keep[keep > 0]))


@dataclass(frozen=True)
class TrunkClassifier:
    """A small trunk/crown pixel classifier trained on a few user-labelled exemplars (§4.3).

    The paper fine-tuned an FCN on 55 hand-segmented trees. This is the light-weight
    counterpart: logistic regression on quadratic terms of a dozen per-pixel features
    (position, width profile, thickness, CIELAB colour, local contrast and the training-free
    :func:`segment`'s answer), fitted by Newton's method with a small L2 penalty. Its pixel
    guesses become a trunk the way :func:`segment` defines one: everything below the crown
    baseline that touches the bottom. Train it with :meth:`fit` on a few of your own trees
    when :func:`segment` fails on a library's style, and pass it to :func:`prepare` or
    :class:`Library`.

    Attributes
    ----------
    coef : (d,) float64 ndarray
        Weights of the quadratic features.
    mean, scale : (11,) float64 ndarray
        Feature standardisation.
    alpha_threshold : float
        Alpha at or above this is opaque.
    """

    coef: F64
    mean: F64
    scale: F64
    alpha_threshold: float = 0.5

    @classmethod
    def fit(
        cls,
        images: Sequence[Any],
        trunks: Sequence[Any],
        *,
        samples: int = 20000,
        l2: float = 1e-3,
        seed: int = 0,
        alpha_threshold: float = 0.5,
    ) -> TrunkClassifier:
        """Train on normalised exemplars and their trunk masks.

        Parameters
        ----------
        images : sequence of (S, S, 4) ndarray
            Normalised exemplars (see :func:`normalize`).
        trunks : sequence of (S, S) bool ndarray
            Their trunk masks (``True`` on trunk pixels).
        samples : int, optional
            Opaque pixels drawn per image, half trunk and half crown where possible.
        l2 : float, optional
            Ridge penalty on the weights.
        seed : int, optional
            Seed of the pixel sampling.
        alpha_threshold : float, optional

        Returns
        -------
        TrunkClassifier

        Examples
        --------
        >>> import numpy as np, phloem
        >>> img = np.zeros((100, 100, 4), np.float32); img[20:60, 20:80] = (0.1, 0.6, 0.1, 1.0)
        >>> img[60:100, 45:55] = (0.4, 0.3, 0.1, 1.0)
        >>> truth = np.zeros((100, 100), bool); truth[60:, 45:55] = True
        >>> clf = phloem.trees.TrunkClassifier.fit([img], [truth])
        >>> bool((clf.predict(img) == truth).all())
        True
        """
        imgs = list(images)
        masks = list(trunks)
        if not imgs or len(imgs) != len(masks):
            raise ValueError(f"trunks: expected one trunk mask per image, got {len(masks)} for {len(imgs)} images")
        samples = check_int(samples, "samples", 10)
        l2 = check_float(l2, "l2", 0.0)
        t = _threshold(alpha_threshold)
        rng = np.random.default_rng(check_int(seed, "seed", 0))
        xs_, ys_ = [], []
        for i, (im, tm) in enumerate(zip(imgs, masks)):
            img = _rgba(im, f"images[{i}]")
            opaque = img[..., 3] >= t
            if not opaque.any():
                raise ValueError(f"images[{i}]: every pixel is transparent")
            truth = as_mask(tm, f"trunks[{i}]", opaque.shape)[opaque]
            f = _trunk_features(img, opaque, segment(img, alpha_threshold=t))
            pick = []
            for cls_ in (True, False):
                idx = np.flatnonzero(truth == cls_)
                if idx.size:
                    pick.append(rng.choice(idx, size=min(idx.size, samples // 2), replace=False))
            sel = np.sort(np.concatenate(pick))
            xs_.append(f[sel])
            ys_.append(truth[sel].astype(np.float64))
        x = np.vstack(xs_)
        y = np.concatenate(ys_)
        mean = x.mean(axis=0)
        scale = x.std(axis=0)
        scale[scale < 1e-9] = 1.0
        q = _quadratic((x - mean) / scale)
        coef = np.zeros(q.shape[1])
        reg = l2 * len(y) * np.eye(q.shape[1])
        reg[0, 0] = 0.0
        for _ in range(30):
            p = 1.0 / (1.0 + np.exp(-np.clip(q @ coef, -30, 30)))
            grad = q.T @ (p - y) + reg @ coef
            hess = (q * (p * (1 - p))[:, None]).T @ q + reg + 1e-9 * np.eye(q.shape[1])
            step = np.linalg.solve(hess, grad)
            coef -= step
            if float(np.abs(step).max()) < 1e-6:
                break
        return cls(coef=coef, mean=mean, scale=scale, alpha_threshold=t)

    def probability(self, rgba: Any) -> F32:
        """Per-pixel trunk probability (0 on transparent pixels)."""
        img = _rgba(rgba)
        opaque = img[..., 3] >= self.alpha_threshold
        out = np.zeros(opaque.shape, np.float32)
        if not opaque.any():
            return out
        f = _trunk_features(img, opaque, segment(img, alpha_threshold=self.alpha_threshold))
        z = _quadratic((f - self.mean) / self.scale) @ self.coef
        out[opaque] = 1.0 / (1.0 + np.exp(-np.clip(z, -30, 30)))
        return out

    def predict(self, rgba: Any) -> Mask:
        """The trunk mask of a normalised exemplar, as :func:`segment` returns one."""
        img = _rgba(rgba)
        opaque = img[..., 3] >= self.alpha_threshold
        if not opaque.any():
            return np.zeros(opaque.shape, np.bool_)
        return _trunk_from_rows(opaque, self.probability(img) >= 0.5)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready parameters (see :meth:`from_dict`)."""
        return {
            "format": "phloem.trees.TrunkClassifier",
            "version": 1,
            "coef": self.coef.tolist(),
            "mean": self.mean.tolist(),
            "scale": self.scale.tolist(),
            "alpha_threshold": self.alpha_threshold,
        }

    @classmethod
    def from_dict(cls, data: Any) -> TrunkClassifier:
        """Rebuild a classifier saved with :meth:`to_dict`."""
        if not isinstance(data, dict) or data.get("format") != "phloem.trees.TrunkClassifier":
            raise ValueError("data: not a phloem.trees.TrunkClassifier record")
        coef = np.asarray(data["coef"], np.float64)
        mean = np.asarray(data["mean"], np.float64)
        scale = np.asarray(data["scale"], np.float64)
        d = mean.size
        if scale.shape != (d,) or coef.shape != (1 + d + d * (d + 1) // 2,):
            raise ValueError("data: coefficient sizes do not match")
        return cls(coef=coef, mean=mean, scale=scale, alpha_threshold=float(data["alpha_threshold"]))


def crown_baseline(trunk: Any, alpha: Any, *, alpha_threshold: float = 0.5) -> int:
    """Row of the crown baseline: the lowest row holding an opaque non-trunk pixel."""
    t = _threshold(alpha_threshold)
    opaque = _alpha_mask(alpha, t)
    tm = as_mask(trunk, "trunk", opaque.shape)
    rows = np.flatnonzero((opaque & ~tm).any(axis=1))
    if rows.size == 0:
        raise ValueError("trunk: expected some crown pixels, every opaque pixel is trunk")
    return int(rows[-1])


def pin_points(points: Any, trunk: Any) -> tuple[int, int, int]:
    """The pin points B, L, R of a counter-clockwise tree contour (paper §4.4).

    B, the tree bottom, is the contour point with the largest ``y`` (the paper's minimum with
    ``y`` up), the median one of several. Walking from B backwards (to the left on screen) and
    forwards (to the right) along the contour, L and R are the first points at or above the crown
    baseline, the lowest row of crown pixels (the lowest non-trunk row of the opaque mask, i.e.
    the row above the highest trunk row when ``trunk`` holds the trunk below the crown). With no
    trunk pixels, L = R = B.

    Parameters
    ----------
    points : (K, 2) ndarray
        Counter-clockwise contour, as from :func:`contour`.
    trunk : (M, N) bool ndarray
        Trunk mask, as from :func:`segment` or drawn by hand.

    Returns
    -------
    (b, l, r) : tuple of int
        Indices into ``points``. Counter-clockwise from B one meets R, then L.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((100, 100, 4), np.float32)
    >>> img[20:60, 20:80] = 1.0; img[60:100, 45:55] = 1.0
    >>> c = phloem.trees.contour(img)
    >>> b, l, r = phloem.trees.pin_points(c, phloem.trees.segment(img))
    >>> c[b].tolist(), c[l].tolist(), c[r].tolist()
    ([50.0, 99.0], [44.0, 59.0], [55.0, 59.0])
    """
    p = _points(points, "points")
    tm = np.asarray(trunk)
    if tm.ndim != 2:
        raise ValueError(f"trunk: expected an (H, W) mask, got shape {tm.shape}")
    tm = as_mask(tm, "trunk", tm.shape)
    n = len(p)
    ymax = p[:, 1].max()
    lows = np.flatnonzero(p[:, 1] == ymax)
    # Contour indices of the lowest points, taken as a run around the loop so the median is
    # the middle of the bottom edge even when the run wraps past index 0.
    if lows.size > 1:
        gaps = np.diff(np.concatenate([lows, [lows[0] + n]]))
        start = int(np.argmax(gaps)) + 1
        lows = np.roll(lows, -start)
    b = int(lows[len(lows) // 2])
    rows = np.flatnonzero(tm.any(axis=1))
    if rows.size == 0:
        return b, b, b
    baseline = int(rows[0]) - 1  # lowest crown row lies just above the trunk's top

    def walk(direction: int) -> int:
        i = b
        for _ in range(n):
            if p[i, 1] <= baseline:
                return i
            i = (i + direction) % n
        return b

    r = walk(+1)
    l_ = walk(-1)
    return b, l_, r


def _chord_walk(seg: F64, cum: list[float], count: int, step: float) -> list[float]:
    """Arc-length positions of points at chord distance ``step`` from each other along the
    polyline ``seg`` (``cum`` its cumulative arc length), at most ``count`` of them."""
    xs, ys = seg[:, 0].tolist(), seg[:, 1].tolist()
    px, py = xs[0], ys[0]
    out = [0.0]
    i, m, s2 = 1, len(xs), step * step
    while len(out) < count and i < m:
        qx, qy = xs[i], ys[i]
        if (qx - px) ** 2 + (qy - py) ** 2 < s2:
            i += 1
            continue
        # The circle of radius `step` around p leaves the polyline on segment (i-1, i): take the
        # larger root of |a + t d - p| = step, the crossing ahead of p.
        ax, ay = xs[i - 1], ys[i - 1]
        dx, dy, fx, fy = qx - ax, qy - ay, ax - px, ay - py
        qa = dx * dx + dy * dy
        qb = 2 * (fx * dx + fy * dy)
        qc = fx * fx + fy * fy - s2
        tt = (-qb + math.sqrt(max(qb * qb - 4 * qa * qc, 0.0))) / (2 * qa) if qa > 0 else 1.0
        tt = min(max(tt, 0.0), 1.0)
        px, py = ax + tt * dx, ay + tt * dy
        out.append(cum[i - 1] + tt * (cum[i] - cum[i - 1]))
    return out


def _at(seg: F64, cum: F64, u: Any) -> F64:
    return np.stack([np.interp(u, cum, seg[:, 0]), np.interp(u, cum, seg[:, 1])], axis=1)


def _segment_resample(seg: F64, count: int) -> F64:
    """``count`` points from ``seg[0]`` on with equal chords; the end point ``seg[-1]`` excluded.

    Bisection finds the smallest chord length that fits only ``count`` steps into the polyline,
    so the last gap (to the end point, the next segment's first sample) is close to the others.
    Where a jagged polyline makes the count jump past ``count`` (a chord skipping a narrow
    spike), the missing points go to the arc-length middles of the longest gaps.
    """
    cum = np.concatenate([[0.0], np.cumsum(np.sqrt((np.diff(seg, axis=0) ** 2).sum(axis=1)))])
    total = float(cum[-1])
    if total == 0 or count == 1:
        return _at(seg, cum, np.arange(count) * (total / count))
    cl = cum.tolist()
    lo, hi = 0.0, total / count * 1.0000001
    # hi must make the walk reach the end with at most `count` points: widen until it does.
    for _ in range(60):
        if len(_chord_walk(seg, cl, count + 1, hi)) <= count:
            break
        lo, hi = hi, hi * 1.5
    # Chords are barely shorter than arcs on a contour, so the answer is usually within 20 % of
    # hi: bracket it there first (half the bisection steps), else keep the whole interval.
    if lo == 0.0 and len(_chord_walk(seg, cl, count + 1, 0.8 * hi)) > count:
        lo = 0.8 * hi
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        if len(_chord_walk(seg, cl, count + 1, mid)) <= count:
            hi = mid
        else:
            lo = mid
    u = _chord_walk(seg, cl, count, hi)
    while len(u) < count:
        ends = [*u[1:], total]
        k = int(np.argmax(np.subtract(ends, u)))
        u.insert(k + 1, 0.5 * (u[k] + ends[k]))
    return _at(seg, cum, np.asarray(u))


def resample(points: Any, pins: tuple[int, int, int], *, split: tuple[int, int, int] = (1600, 200, 200)) -> F64:
    """Resample a contour to a fixed number of points between its pin points (paper §4.5).

    The counter-clockwise contour is cut at the pins into the crown (R to L, over the top), the
    left trunk side (L down to B) and the right trunk side (B up to R). Each gets a fixed number
    of points, placed with (near) equal chord lengths within the segment. The paper used
    N = 2000 points: 1600 on the crown and 200 on each trunk side.

    Parameters
    ----------
    points : (K, 2) ndarray
        Counter-clockwise contour.
    pins : (b, l, r)
        Pin indices into ``points``, as from :func:`pin_points`.
    split : (int, int, int), optional
        Points on the crown, the left and the right trunk side.

    Returns
    -------
    (sum(split), 2) float64 ndarray
        The resampled contour ``C_r``, counter-clockwise, starting at R: the crown occupies
        ``[0, split[0])`` (so row 0 is R and row ``split[0]`` is L), the left trunk side the
        next ``split[1]`` rows (row ``split[0] + split[1]`` is B), the right side the rest.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((100, 100, 4), np.float32)
    >>> img[20:60, 20:80] = 1.0; img[60:100, 45:55] = 1.0
    >>> c = phloem.trees.contour(img)
    >>> pins = phloem.trees.pin_points(c, phloem.trees.segment(img))
    >>> cr = phloem.trees.resample(c, pins, split=(80, 10, 10))
    >>> cr.shape, cr[80].tolist(), cr[90].tolist()
    ((100, 2), [44.0, 59.0], [50.0, 99.0])
    """
    p = _points(points, "points")
    n = len(p)
    try:
        b, l_, r = (int(i) for i in pins)
    except (TypeError, ValueError):
        raise TypeError(f"pins: expected three indices (b, l, r), got {pins!r}") from None
    for name, i in (("b", b), ("l", l_), ("r", r)):
        if not 0 <= i < n:
            raise ValueError(f"pins: {name}={i} is not an index into the {n} contour points")
    try:
        counts = tuple(int(c) for c in split)
    except (TypeError, ValueError):
        raise TypeError(f"split: expected three point counts, got {split!r}") from None
    if len(counts) != 3 or min(counts) < 1:
        raise ValueError(f"split: expected three counts >= 1, got {split!r}")

    return _resample_parts(p, (b, l_, r), counts, _segment_resample)


def _resample_parts(p: F64, pins: tuple[int, int, int], counts: tuple[int, ...], how: Any) -> F64:
    """Cut the closed contour at the pins into crown (R to L), left (L to B) and right (B to R)
    and resample each part with ``how(part, count)``."""
    b, l_, r = pins
    n = len(p)

    def path(i: int, j: int, full: bool) -> F64:
        # Contour from index i forwards to index j inclusive (the whole loop when i == j and full).
        k = (j - i) % n
        if k == 0 and full:
            k = n
        idx = (i + np.arange(k + 1)) % n
        return p[idx]

    parts = (path(r, l_, full=True), path(l_, b, full=False), path(b, r, full=False))
    return np.concatenate([how(part, c) for part, c in zip(parts, counts)])


def simplify(mask: Any, *, m: int = 100, dilation: int = 8) -> F64:
    """The simplified contour ``C_s`` for mean value coordinates (paper §4.6).

    The mask (the interior of ``C_r``, see :func:`prepare`) is dilated ``dilation`` times with a
    3 x 3 square, and its longest exterior contour resampled to ``m`` points of equal chord
    length, counter-clockwise, starting at its lowest point. Dilating keeps the tree's pixels
    away from the cage, where the warp distorts most.

    Parameters
    ----------
    mask : (M, N) bool ndarray
        The tree's interior.
    m : int, optional
        Number of points (the paper's M = 100).
    dilation : int, optional
        Dilation iterations (the paper used 8).

    Returns
    -------
    (m, 2) float64 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> mask = np.zeros((64, 64), bool); mask[20:40, 20:40] = True
    >>> cs = phloem.trees.simplify(mask, m=40, dilation=2)
    >>> cs.shape, float(cs[:, 0].min()), float(cs[:, 1].max())
    ((40, 2), 18.0, 41.0)
    """
    arr = np.asarray(mask)
    if arr.ndim != 2:
        raise ValueError(f"mask: expected an (H, W) mask, got shape {arr.shape}")
    mk = as_mask(arr, "mask", arr.shape)
    m = check_int(m, "m", 3)
    dilation = check_int(dilation, "dilation", 0)
    if not mk.any():
        raise ValueError("mask: expected some set pixels, the mask is empty")
    return _simplify_outline(_dilated_contour(mk, dilation), m)


def _simplify_outline(c: F64, m: int) -> F64:
    """``m`` points of equal chord along a closed outline, from its lowest point."""
    start = int(np.argmax(c[:, 1] + 1e-6 * np.abs(c[:, 0] - c[:, 0].mean()) * -1))
    loop = np.concatenate([c[start:], c[:start], c[start : start + 1]])
    return _segment_resample(loop, m)


@dataclass(frozen=True)
class Tree:
    """One preprocessed exemplar (paper §4.7).

    Attributes
    ----------
    image : (S, S, 4) float32 ndarray
        The normalised RGBA image.
    trunk : (S, S) bool ndarray
        The trunk mask.
    contour : (K, 2) float64 ndarray
        The longest exterior contour ``C``, counter-clockwise.
    pins : (b, l, r)
        Pin point indices into ``contour``.
    resampled : (N, 2) float64 ndarray
        ``C_r``: crown, left trunk side, right trunk side (see :func:`resample`).
    simplified : (M, 2) float64 ndarray
        ``C_s``: the dilated, simplified contour for mean value coordinates.
    split : (int, int, int)
        Points of ``resampled`` on the crown and the two trunk sides.
    outline : (L, 2) float64 ndarray
        The dilated outline of the interior of ``resampled`` that ``simplified`` samples and
        that :func:`cages` matches against (about one point per pixel).
    dilation : int
        The dilation ``outline`` and ``simplified`` were made with.
    """

    image: F32
    trunk: Mask
    contour: F64
    pins: tuple[int, int, int]
    resampled: F64
    simplified: F64
    split: tuple[int, int, int]
    outline: F64
    dilation: int = 8

    @property
    def vector(self) -> F64:
        """``u``: the mean-subtracted ``(x, y)`` of ``resampled``, flattened to length 2N (§3)."""
        centred: F64 = self.resampled - self.resampled.mean(axis=0)
        return centred.ravel()


def prepare(
    rgba: Any,
    *,
    trunk: Any = None,
    classifier: TrunkClassifier | None = None,
    size: int = 1024,
    alpha_threshold: float = 0.5,
    split: tuple[int, int, int] = (1600, 200, 200),
    m: int = 100,
    dilation: int = 8,
    normalized: bool = False,
) -> Tree:
    """Preprocess one exemplar: normalise, segment, contour, pins, resample, simplify (§4).

    Parameters
    ----------
    rgba : (M, N, 4) ndarray
        The exemplar.
    trunk : (S, S) bool ndarray, optional
        A trunk mask for the *normalised* image, e.g. drawn by hand; :func:`segment` otherwise.
    classifier : TrunkClassifier, optional
        Segment with this trained classifier instead of :func:`segment` (ignored with ``trunk``).
    size, alpha_threshold : optional
        See :func:`normalize`.
    split : optional
        See :func:`resample`.
    m, dilation : optional
        See :func:`simplify`.
    normalized : bool, optional
        ``rgba`` is already the output of :func:`normalize`; use it as it is.

    Returns
    -------
    Tree

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32)
    >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
    >>> tree = phloem.trees.prepare(img, size=128, split=(160, 20, 20), m=30)
    >>> tree.image.shape, tree.resampled.shape, tree.simplified.shape, tree.vector.shape
    ((128, 128, 4), (200, 2), (30, 2), (400,))
    """
    img = _rgba(rgba) if normalized else normalize(rgba, size=size, alpha_threshold=alpha_threshold)
    if trunk is None and classifier is not None:
        tm = classifier.predict(img)
    elif trunk is None:
        tm = segment(img, alpha_threshold=alpha_threshold)
    else:
        tm = as_mask(trunk, "trunk", img.shape[:2])
    c = contour(img[..., 3], alpha_threshold=alpha_threshold)
    pins = pin_points(c, tm)
    cr = resample(c, pins, split=split)
    # The dilated outline once: C_s samples it here, and cages() matches against it later.
    dilation = check_int(dilation, "dilation", 0)
    outline = _dilated_contour(fill_contour(cr, img.shape[:2]), dilation)
    cs = _simplify_outline(outline, check_int(m, "m", 3))
    counts = (int(split[0]), int(split[1]), int(split[2]))
    return Tree(
        image=img,
        trunk=tm,
        contour=c,
        pins=pins,
        resampled=cr,
        simplified=cs,
        split=counts,
        outline=outline,
        dilation=dilation,
    )


# -- synthesis (§5) --------------------------------------------------------------------------


def fill_contour(points: Any, shape: tuple[int, int]) -> Mask:
    """Preliminary alpha of a synthesised contour: draw it, then clear from outside (§5.1).

    The closed polyline is drawn onto an all-opaque canvas, and a flood fill from outside the
    image clears everything reachable without crossing it. Unlike a polygon fill this stays
    correct where a combined contour intersects itself: every pixel enclosed by some part of
    the curve is kept.

    Parameters
    ----------
    points : (K, 2) ndarray
        Closed contour, ``(x, y)``.
    shape : (int, int)
        ``(H, W)`` of the mask.

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
    p = _points(points, "points")
    h, w = (int(s) for s in shape)
    if h < 1 or w < 1:
        raise ValueError(f"shape: expected a positive (H, W), got {shape!r}")
    # The curve on an empty canvas with a one-pixel margin: the margin connects every outside
    # region to the seed, so whatever the fill reaches is outside; the rest (the curve and all
    # it encloses) is inside.
    # The canvas also covers the parts of the curve outside the image (up to one image size
    # beyond each edge; farther points are clamped there), so that no gap lets the fill in.
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
    cs = [_points(c, f"contours[{i}]") for i, c in enumerate(contours)]
    if len({c.shape for c in cs}) != 1:
        raise ValueError(f"contours: expected the same number of points in each, got {[len(c) for c in cs]}")
    w = check_convex_weights(weights, len(cs), "weights")
    return np.asarray(np.tensordot(w, np.stack(cs), axes=1), dtype=np.float64)


def _dilated_contour(mask: Mask, dilation: int) -> F64:
    """The longest exterior contour of ``mask`` dilated ``dilation`` times by a 3 x 3 square
    (one dilation by a square of side ``2 dilation + 1``)."""
    u8: NDArray[Any] = mask.astype(np.uint8)
    if dilation:
        u8 = cv2.copyMakeBorder(u8, dilation, dilation, dilation, dilation, cv2.BORDER_CONSTANT, value=0)
        u8 = cv2.dilate(u8, np.ones((2 * dilation + 1, 2 * dilation + 1), np.uint8))
    return contour(np.asarray(u8) > 0) - dilation


def _monotone_match(anchors: F64, loop: F64) -> F64:
    """Points of the closed polyline ``loop`` matched to ``anchors`` in order (a cage).

    The first anchor takes its nearest loop point; the others take loop points in strictly
    increasing (counter-clockwise) order from there, minimising the sum of squared distances
    (dynamic programming over the loop, O(len(anchors) * len(loop))). The result follows the
    loop without folding back, has no repeated point, and corresponds to the anchors.
    """
    m = len(anchors)
    # About ten loop points per anchor are plenty (the cost is O(m * len(loop))).
    loop = loop[:: max(1, len(loop) // (10 * m))]
    if len(loop) < 4 * m:  # densify a short loop so that every anchor finds its own point
        closed = np.vstack([loop, loop[:1]])
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
        loop = _at(closed, cum, np.arange(4 * m) * (cum[-1] / (4 * m)))
    start = int(np.argmin(((loop - anchors[0]) ** 2).sum(axis=1)))
    c = np.roll(loop, -start, axis=0)
    n = len(c)
    d = ((anchors[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)
    cost = np.full(n, np.inf)
    cost[0] = 0.0
    ar = np.arange(n)
    back = np.empty((m, n), np.int64)
    for i in range(1, m):
        best = np.minimum.accumulate(cost)
        arg = np.maximum.accumulate(np.where(cost <= best, ar, 0))
        prev = np.concatenate([[np.inf], best[:-1]])
        back[i] = np.concatenate([[0], arg[:-1]])
        cost = d[i] + prev
    idx = np.empty(m, np.int64)
    idx[-1] = int(np.argmin(cost))
    for i in range(m - 1, 0, -1):
        idx[i - 1] = back[i, idx[i]]
    return np.asarray(c[idx], dtype=np.float64)


def cages(
    target: Any,
    sources: Sequence[Tree],
    shape: tuple[int, int],
    *,
    m: int = 100,
    dilation: int = 8,
    mask: Any = None,
) -> tuple[F64, list[F64]]:
    """Matching simplified contours ``C_s'`` (target) and ``C_s`` (each source) for the warp (§4.6, §5.2).

    Each cage has ``m`` points on the contour of its tree's interior dilated ``dilation``
    times, as in §4.6. For the warp the cages must correspond point by point; the resampled
    contours ``C_r`` already do (same index, same part of the tree). So ``m`` indices into
    ``C_r`` are chosen at equal arc length along the target ``C_r'``, and every cage takes, in
    order, the points of its dilated outline nearest to its own ``C_r`` at those indices
    (a monotone matching, so a cage never folds back or repeats a point, even where the
    dilation has filled a concave notch or a tree has no visible trunk).

    Parameters
    ----------
    target : (N, 2) ndarray
        The synthesised resampled contour ``C_r'``, with the sources' number of points.
    sources : sequence of Tree
        The source exemplars.
    shape : (int, int)
        ``(H, W)`` of the images.
    m, dilation : int, optional
        Cage points (the paper's M = 100) and dilation iterations (8 in the paper).
    mask : (H, W) bool ndarray, optional
        The target's preliminary alpha (:func:`fill_contour` of ``target`` if omitted).

    Returns
    -------
    target_cage : (m, 2) float64 ndarray
    source_cages : list of (m, 2) float64 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32)
    >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
    >>> tree = phloem.trees.prepare(img, size=128, split=(160, 20, 20), m=30)
    >>> tc, (sc,) = phloem.trees.cages(tree.resampled, [tree], (128, 128), m=30)
    >>> tc.shape, bool(np.allclose(tc, sc))
    ((30, 2), True)
    """
    cr = _points(target, "target")
    if not sources:
        raise ValueError("sources: expected at least one Tree")
    n = len(sources[0].resampled)
    if len(cr) != n:
        raise ValueError(f"target: expected {n} points like the sources' resampled contours, got {len(cr)}")
    m = check_int(m, "m", 3)
    dilation = check_int(dilation, "dilation", 0)
    h, w = (int(s) for s in shape)
    tmask = fill_contour(cr, (h, w)) if mask is None else as_mask(mask, "mask", (h, w))
    closed = np.vstack([cr, cr[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    if cum[-1] <= 0:
        raise ValueError("target: the contour is degenerate (all points equal)")
    picks = np.searchsorted(cum, np.arange(m) * (cum[-1] / m), side="right") - 1
    picks = np.clip(picks, 0, n - 1)
    target_cage = _monotone_match(cr[picks], _dilated_contour(tmask, dilation))
    out = []
    for t in sources:
        if len(t.resampled) != n:
            raise ValueError(f"sources: every tree needs {n} resampled points, got {len(t.resampled)}")
        outline = t.outline if t.dilation == dilation else _dilated_contour(fill_contour(t.resampled, (h, w)), dilation)
        out.append(_monotone_match(t.resampled[picks], outline))
    return target_cage, out


def match_histograms(image: Any, reference: Any, *, alpha_threshold: float = 0.0) -> F32:
    """Histogram transfer of each colour channel, ignoring transparent pixels (paper §5.3).

    For each of the first three channels, the cumulative histograms of ``image`` and
    ``reference`` are computed over their pixels with alpha above ``alpha_threshold``; every
    distinct value of ``image`` is mapped to the value of ``reference`` at the same quantile,
    interpolating linearly between ``reference``'s distinct values (Gonzalez & Woods). Alpha
    and transparent pixels are left unchanged.

    Parameters
    ----------
    image, reference : (H, W, 4) ndarray
        RGBA images (sizes may differ).
    alpha_threshold : float, optional
        Pixels with alpha at or below it are ignored.

    Returns
    -------
    (H, W, 4) float32 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.ones((2, 2, 4), np.float32); img[..., 0] = [[0.1, 0.2], [0.3, 0.4]]
    >>> ref = np.ones((2, 2, 4), np.float32); ref[..., 0] = [[0.5, 0.6], [0.7, 0.9]]
    >>> phloem.trees.match_histograms(img, ref)[..., 0].astype(float).round(2).tolist()
    [[0.5, 0.6], [0.7, 0.9]]
    """
    img = _rgba(image, "image")
    ref = _rgba(reference, "reference")
    t = check_float(alpha_threshold, "alpha_threshold", 0.0)
    src_on = img[..., 3] > t
    ref_on = ref[..., 3] > t
    if not src_on.any():
        raise ValueError("image: every pixel is transparent; nothing to match")
    if not ref_on.any():
        raise ValueError("reference: every pixel is transparent; it has no colour histogram")
    out: F32 = img.copy()
    for ch in range(3):
        s = img[..., ch][src_on]
        _, s_idx, s_counts = np.unique(s, return_inverse=True, return_counts=True)
        r_values, r_counts = np.unique(ref[..., ch][ref_on], return_counts=True)
        s_q = np.cumsum(s_counts) / s.size
        r_q = np.cumsum(r_counts) / r_counts.sum()
        mapped = np.interp(s_q, r_q, r_values)
        out[..., ch][src_on] = mapped[s_idx].astype(np.float32)
    return out


def morph(
    trees: Sequence[Tree],
    weights: Any,
    *,
    color_weights: Any = None,
    m: int = 100,
    dilation: int = 8,
    threads: int | None = None,
) -> F32:
    """A new tree from several exemplars: combined contour, filled by MVC colour transfer (§5.1–5.2).

    1. ``C_r' = Σ w_i C_r,i`` (:func:`combine_contours`);
    2. the preliminary alpha: ``C_r'`` drawn and flood-filled from outside (:func:`fill_contour`);
    3. matching cages ``C_s'`` and ``C_s,i`` (:func:`cages`);
    4. every source with a non-zero colour weight warped onto the target cage by mean value
       coordinates and combined: alpha is the largest warped alpha, colour the
       ``color_weights`` combination of the sources that are not transparent there
       (:func:`phloem.warp.mvc_combine`); a source with colour weight 0 shapes the contour
       only (as in the paper's Fig. 14 and the "sampling one of the two images" of Fig. 16);
    5. pixels farther than ``dilation`` from the preliminary alpha are cleared, so the
       transferred alpha refines the contour's shape but cannot leave its cage.

    Parameters
    ----------
    trees : sequence of Tree
        The exemplars, all preprocessed at the same size and split.
    weights : (len(trees),) array_like
        Contour weights: non-negative, summing to 1.
    color_weights : (len(trees),) array_like, optional
        Colour weights (default: ``weights``); at least one must be positive.
    m, dilation : int, optional
        Cage points and dilation (see :func:`simplify`).
    threads : int, optional
        Worker threads for the warp.

    Returns
    -------
    (S, S, 4) float32 ndarray
        The new RGBA tree, transparent pixels black.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((120, 80, 4), np.float32); a[..., 1] = 0.6; a[..., 3] = 0
    >>> a[10:70, 10:70, 3] = 1.0; a[70:110, 35:45, 3] = 1.0
    >>> b = np.zeros((120, 120, 4), np.float32); b[..., 0] = 0.5
    >>> b[5:60, 5:115, 3] = 1.0; b[60:118, 52:68, 3] = 1.0
    >>> ta, tb = (phloem.trees.prepare(x, size=128, split=(160, 20, 20), m=30) for x in (a, b))
    >>> out = phloem.trees.morph([ta, tb], [0.5, 0.5], m=30)
    >>> out.shape, bool(out[..., 3].max() == 1.0), bool(out[0, 0, 3] == 0.0)
    ((128, 128, 4), True, True)
    """
    ts = list(trees)
    if not ts or not all(isinstance(t, Tree) for t in ts):
        raise TypeError("trees: expected a non-empty sequence of phloem.trees.Tree")
    shape = ts[0].image.shape[:2]
    if any(t.image.shape != ts[0].image.shape for t in ts):
        raise ValueError(f"trees: expected exemplars of one size, got {sorted({t.image.shape[:2] for t in ts})}")
    w = check_convex_weights(weights, len(ts), "weights")
    cw = w if color_weights is None else check_convex_weights(color_weights, len(ts), "color_weights")
    target = combine_contours([t.resampled for t in ts], w)
    mask = fill_contour(target, shape)
    keep = [i for i in range(len(ts)) if cw[i] > 0]
    tc, scs = cages(target, [ts[i] for i in keep], shape, m=m, dilation=dilation, mask=mask)
    # `dilation` 3 x 3 dilations are one square dilation of side 2 * dilation + 1.
    side = 2 * dilation + 1
    region = cv2.dilate(mask.astype(np.uint8), np.ones((side, side), np.uint8)) > 0
    ck = cw[keep] / cw[keep].sum()
    return warp.mvc_combine([ts[i].image for i in keep], scs, tc, ck, shape, region=region, threads=threads)


@dataclass
class Library:
    """A library of preprocessed tree exemplars (paper §3: the library ``L``).

    Build one with :meth:`from_images` or :meth:`load`; all trees share one size and
    one contour split, so their contours can be combined.

    Attributes
    ----------
    trees : list of Tree
    names : list of str
        One name per tree (file name, with ``[i]`` for the i-th tree of an atlas).
    """

    trees: list[Tree]
    names: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.trees = list(self.trees)
        if not self.trees:
            raise ValueError("trees: a library needs at least one tree")
        if not all(isinstance(t, Tree) for t in self.trees):
            raise TypeError("trees: expected phloem.trees.Tree objects (see phloem.trees.prepare)")
        self.names = list(self.names) or [f"tree{i}" for i in range(len(self.trees))]
        if len(self.names) != len(self.trees):
            raise ValueError(f"names: expected {len(self.trees)} names, got {len(self.names)}")
        first = self.trees[0]
        for name, t in zip(self.names, self.trees):
            if (
                t.image.shape != first.image.shape
                or t.split != first.split
                or len(t.simplified) != len(first.simplified)
            ):
                raise ValueError(f"trees: {name!r} was prepared with another size, split or m than {self.names[0]!r}")

    def __len__(self) -> int:
        return len(self.trees)

    def __getitem__(self, i: int) -> Tree:
        return self.trees[i]

    @property
    def size(self) -> int:
        """Side of the (square) normalised images."""
        return int(self.trees[0].image.shape[0])

    @classmethod
    def from_images(
        cls,
        images: Sequence[Any],
        *,
        names: Sequence[str] | None = None,
        size: int = 1024,
        alpha_threshold: float = 0.5,
        classifier: TrunkClassifier | None = None,
        progress: Any = None,
    ) -> Library:
        """Preprocess RGBA images (one tree each) into a library.

        Parameters
        ----------
        images : sequence of (M, N, 4) ndarray
        names : sequence of str, optional
        size, alpha_threshold : optional
            See :func:`normalize`.
        classifier : TrunkClassifier, optional
            Crown/trunk segmentation by this classifier instead of :func:`segment`.
        progress : callable, optional
            ``progress(done, total)`` after each tree.

        Examples
        --------
        >>> import numpy as np, phloem
        >>> img = np.zeros((120, 80, 4), np.float32)
        >>> img[10:70, 10:70] = 1.0; img[70:110, 35:45] = 1.0
        >>> lib = phloem.trees.Library.from_images([img, img[:, ::-1]], size=128)
        >>> len(lib), lib.size, lib.names
        (2, 128, ['tree0', 'tree1'])
        """
        imgs = list(images)
        out = []
        for i, img in enumerate(imgs):
            try:
                out.append(prepare(img, size=size, alpha_threshold=alpha_threshold, classifier=classifier))
            except ValueError as exc:
                label = names[i] if names is not None and i < len(names) else f"images[{i}]"
                raise ValueError(f"{label}: {exc}") from None
            if progress is not None:
                progress(i + 1, len(imgs))
        return cls(out, list(names) if names is not None else [])

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        *,
        atlas: bool | None = None,
        size: int = 1024,
        alpha_threshold: float = 0.5,
        skip_bad: bool = False,
        classifier: TrunkClassifier | None = None,
        max_pixels: int = io.DEFAULT_MAX_PIXELS,
        progress: Any = None,
    ) -> Library:
        """Read a folder of PNG/TIFF/WebP images (sorted by name), or one image, into a library.

        Parameters
        ----------
        path : path-like
            A folder, or one image (typically an atlas of several trees).
        atlas : bool, optional
            ``True``: every image is an atlas of several trees (:func:`split_atlas`);
            ``False``: one tree per image; ``None`` (default): split every image and keep
            all its pieces (an image of one tree gives one piece).
        size, alpha_threshold : optional
            See :func:`normalize`.
        skip_bad : bool, optional
            Skip images that cannot be used (no alpha, fully transparent, no usable contour)
            instead of raising.
        classifier : TrunkClassifier, optional
            Crown/trunk segmentation by this classifier instead of :func:`segment`.
        max_pixels : int, optional
            Refuse images with more pixels (see :func:`phloem.io.read_image`).
        progress : callable, optional
            ``progress(done, total)`` after each image.

        Raises
        ------
        ValueError
            If an image cannot be used (unless ``skip_bad``) or no tree is found.
        """
        folder = Path(path)
        if folder.is_dir():
            files = sorted(p for p in folder.iterdir() if p.suffix.lower() in {".png", ".tif", ".tiff", ".webp"})
            if not files:
                raise ValueError(f"path: {folder} has no PNG, TIFF or WebP images")
        elif folder.is_file():
            files = [folder]
        else:
            raise ValueError(f"path: {folder} does not exist")
        trees_: list[Tree] = []
        names: list[str] = []
        for k, f in enumerate(files):
            try:
                img = io.read_image(f, max_pixels=max_pixels)
                if img.ndim != 3 or img.shape[2] != 4:
                    raise ValueError("expected an RGBA image (trees need an alpha channel)")
                pieces = [img] if atlas is False else split_atlas(img, alpha_threshold=alpha_threshold)
                for i, piece in enumerate(pieces):
                    trees_.append(prepare(piece, size=size, alpha_threshold=alpha_threshold, classifier=classifier))
                    names.append(f.name if len(pieces) == 1 else f"{f.name}[{i}]")
            except ValueError as exc:
                if not skip_bad:
                    raise ValueError(f"{f}: {exc}") from None
            if progress is not None:
                progress(k + 1, len(files))
        if not trees_:
            raise ValueError(f"path: no usable tree in {folder}")
        return cls(trees_, names)


@dataclass
class Variation:
    """One synthesised tree and how it was made.

    Attributes
    ----------
    image : (S, S, 4) float32 ndarray
        The new RGBA tree.
    sources : list of int
        Library indices of the exemplars combined.
    weights : (k,) float64 ndarray
        Their contour weights.
    color_weights : (k,) float64 ndarray
        Their colour weights.
    reference : int or None
        Library index of the histogram reference, if any.
    """

    image: F32
    sources: list[int]
    weights: F64
    color_weights: F64
    reference: int | None = None

    def describe(self, library: Library) -> dict[str, Any]:
        """A JSON-ready record (names and weights) for a result sidecar."""
        return {
            "exemplars": [library.names[i] for i in self.sources],
            "weights": [round(float(v), 6) for v in self.weights],
            "color_weights": [round(float(v), 6) for v in self.color_weights],
            "histogram_reference": None if self.reference is None else library.names[self.reference],
        }


_COLORS = ("random", "contour", "single")


def _draw_weights(rng: np.random.Generator, k: int, spread: float) -> F64:
    # (1 - spread)/k + spread * Dirichlet(1): for two sources w_1 is uniform on
    # [(1 - spread)/2, (1 + spread)/2], i.e. [0.3, 0.7] for the default spread as in Fig. 16.
    return np.asarray((1.0 - spread) / k + spread * rng.dirichlet(np.ones(k)), dtype=np.float64)


def _color_weights(rng: np.random.Generator, w: F64, colors: str, spread: float) -> F64:
    if colors == "contour":
        return w
    if colors == "single":
        out = np.zeros_like(w)
        out[int(rng.choice(len(w), p=w))] = 1.0
        return out
    return _draw_weights(rng, len(w), spread)


def _check_variation_args(library: Any, sources: Any, spread: Any, colors: Any) -> tuple[int, float]:
    if not isinstance(library, Library):
        raise TypeError(f"library: expected a phloem.trees.Library, got {type(library).__name__}")
    k = check_int(sources, "sources", 1)
    spread = check_float(spread, "spread", 0.0)
    if spread > 1.0:
        raise ValueError(f"spread: expected a value in [0, 1], got {spread}")
    if colors not in _COLORS:
        raise ValueError(f"colors: expected one of {_COLORS}, got {colors!r}")
    return k, spread


def variation(
    library: Library,
    *,
    sources: int = 2,
    seed: int = 0,
    spread: float = 0.4,
    colors: str = "random",
    histogram: bool = False,
    threads: int | None = None,
) -> Variation:
    """A new tree from ``sources`` exemplars drawn at random from the library (paper §3, §5).

    The contour is a random convex combination of the exemplars' contours (§5.1) and is filled
    by RGBA colour transfer from all of them (§5.2); see :func:`morph`.

    Parameters
    ----------
    library : Library
    sources : int, optional
        How many distinct exemplars to combine (2 in the paper's Fig. 16).
    seed : int, optional
        Seed of the random choices; the same seed gives the same tree.
    spread : float, optional
        Contour weights are ``(1 - spread)/k + spread * Dirichlet(1, ..., 1)``; with two sources
        and the default 0.4, ``w_1`` is uniform on [0.3, 0.7] as in the paper's Fig. 16.
    colors : {"random", "contour", "single"}, optional
        Colour weights: a second random convex combination (§5.2, the default), the contour's
        weights, or one source picked with probability equal to its weight (both in Fig. 16).
    histogram : bool, optional
        Match the colour histogram to another random exemplar of the library (§5.3).
    threads : int, optional
        Worker threads for the warp.

    Returns
    -------
    Variation

    Raises
    ------
    ValueError
        If the library holds fewer than ``sources`` trees.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32); img[..., 1] = 0.5
    >>> img[..., 3] = 0; img[10:70, 10:70, 3] = 1.0; img[70:110, 35:45, 3] = 1.0
    >>> lib = phloem.trees.Library.from_images([img, img[:, ::-1], img[20:]], size=128)
    >>> v = phloem.trees.variation(lib, seed=3)
    >>> v.image.shape, len(v.sources), bool(abs(v.weights.sum() - 1) < 1e-9)
    ((128, 128, 4), 2, True)
    """
    k, spread = _check_variation_args(library, sources, spread, colors)
    if len(library) < k:
        raise ValueError(
            f"library: has {len(library)} tree(s) but sources={k}; a variation combines {k} distinct exemplars"
        )
    rng = np.random.default_rng(check_int(seed, "seed", 0))
    idx = [int(i) for i in rng.choice(len(library), size=k, replace=False)]
    w = _draw_weights(rng, k, spread)
    cw = _color_weights(rng, w, colors, spread)
    return _make(library, idx, w, cw, rng, histogram, threads)


def _make(
    library: Library,
    idx: list[int],
    w: F64,
    cw: F64,
    rng: np.random.Generator,
    histogram: bool,
    threads: int | None,
    extra: Tree | None = None,
) -> Variation:
    ts = ([extra] if extra is not None else []) + [library.trees[i] for i in idx]
    img = morph(ts, w, color_weights=cw, m=len(ts[0].simplified), threads=threads)
    ref = None
    if histogram:
        choices = [i for i in range(len(library)) if i not in idx] or list(range(len(library)))
        ref = int(rng.choice(choices))
        if img[..., 3].any():
            img = match_histograms(img, library.trees[ref].image)
    return Variation(img, idx, w, cw, ref)


def vary(
    tree: Any,
    library: Library,
    *,
    n: int,
    seed: int = 0,
    sources: int = 2,
    weight: tuple[float, float] = (0.6, 0.9),
    spread: float = 0.4,
    colors: str = "contour",
    histogram: bool = False,
    threads: int | None = None,
) -> list[Variation]:
    """``n`` variations of one tree ``T``, combined with library exemplars at a lower weight (§3).

    ``T`` is preprocessed like the exemplars (an RGBA image, or a :class:`Tree` made at the
    library's size), then each variation combines ``T`` with ``sources - 1`` random library
    exemplars. ``T``'s contour weight is drawn uniformly from ``weight``; the rest is shared
    among the others as in :func:`variation`. By default the colour weights equal the contour
    weights, so the variations keep ``T``'s look.

    Parameters
    ----------
    tree : (M, N, 4) ndarray or Tree
        The user's tree ``T``.
    library : Library
    n : int
        Number of variations.
    seed : int, optional
    sources : int, optional
        Trees per variation, ``T`` included (at least 2).
    weight : (float, float), optional
        Range of ``T``'s contour weight.
    spread, colors, histogram, threads : optional
        As in :func:`variation`.

    Returns
    -------
    list of Variation
        ``sources`` lists the library exemplars only; ``weights[0]`` is ``T``'s.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.zeros((120, 80, 4), np.float32); img[..., 1] = 0.5
    >>> img[..., 3] = 0; img[10:70, 10:70, 3] = 1.0; img[70:110, 35:45, 3] = 1.0
    >>> lib = phloem.trees.Library.from_images([img[:, ::-1], img[20:]], size=128)
    >>> vs = phloem.trees.vary(img, lib, n=2, seed=1)
    >>> len(vs), [bool(0.6 <= v.weights[0] <= 0.9) for v in vs]
    (2, [True, True])
    """
    k, spread = _check_variation_args(library, sources, spread, colors)
    n = check_int(n, "n", 1)
    if k < 2:
        raise ValueError(f"sources: a variation of a tree combines it with at least one exemplar, got {k}")
    if len(library) < k - 1:
        raise ValueError(f"library: has {len(library)} tree(s) but sources={k} needs {k - 1} besides the tree")
    lo, hi = (check_float(v, "weight", 0.0) for v in weight)
    if not lo <= hi <= 1.0:
        raise ValueError(f"weight: expected 0 <= low <= high <= 1, got {weight!r}")
    t = tree if isinstance(tree, Tree) else prepare(tree, size=library.size)
    first = library.trees[0]
    if t.image.shape != first.image.shape or t.split != first.split:
        raise ValueError("tree: prepared with another size or split than the library's trees")
    rng = np.random.default_rng(check_int(seed, "seed", 0))
    out = []
    for _ in range(n):
        idx = [int(i) for i in rng.choice(len(library), size=k - 1, replace=False)]
        wt = float(rng.uniform(lo, hi))
        w = np.concatenate([[wt], (1.0 - wt) * _draw_weights(rng, k - 1, spread)])
        cw = _color_weights(rng, w, colors, spread)
        out.append(_make(library, idx, w, cw, rng, histogram, threads, extra=t))
    return out


def morph_table(
    trees: Sequence[Tree],
    *,
    tile: int = 192,
    colors: bool = True,
    background: tuple[float, float, float] = (0.8, 0.8, 0.8),
    threads: int | None = None,
) -> F32:
    """The paper's combination tables (Fig. 13 and Fig. 14) for a few exemplars, as one image.

    Row ``i``, column ``j`` (``i != j``) shows the contour ``w_i C_i + w_j C_j`` with weights
    2/3 and 1/3 in the lower triangle and 1/3 and 2/3 in the upper one, filled with the colours
    of the row's tree only (Fig. 14) or, with ``colors=False``, as a silhouette (Fig. 13). The
    diagonal shows the exemplars, and the first row and column repeat them as headers.

    Parameters
    ----------
    trees : sequence of Tree
        Two or more exemplars (the paper shows seven).
    tile : int, optional
        Side of each cell in pixels.
    colors : bool, optional
        Colour transfer (Fig. 14) or silhouettes of the combined contours (Fig. 13).
    background : (float, float, float), optional
        RGB shown behind transparent pixels.
    threads : int, optional
        Worker threads for the warps.

    Returns
    -------
    ((k + 1) * tile, (k + 1) * tile, 3) float32 ndarray

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((120, 80, 4), np.float32); a[10:70, 10:70] = 1.0; a[70:110, 35:45] = 1.0
    >>> ts = [phloem.trees.prepare(x, size=96, split=(160, 20, 20), m=30) for x in (a, a[:, ::-1])]
    >>> phloem.trees.morph_table(ts, tile=32).shape
    (96, 96, 3)
    """
    ts = list(trees)
    if len(ts) < 2:
        raise ValueError(f"trees: a combination table needs at least two exemplars, got {len(ts)}")
    tile = check_int(tile, "tile", 8)
    k = len(ts)
    bg = np.asarray(background, np.float32)
    out = np.empty(((k + 1) * tile, (k + 1) * tile, 3), np.float32)
    out[:] = bg

    def put(r: int, c: int, rgba: F32) -> None:
        small = cv2.resize(rgba, (tile, tile), interpolation=cv2.INTER_AREA)
        a = small[..., 3:4]
        out[r * tile : (r + 1) * tile, c * tile : (c + 1) * tile] = small[..., :3] * a + bg * (1 - a)

    m = len(ts[0].simplified)
    for i, t in enumerate(ts):
        put(0, i + 1, t.image)
        put(i + 1, 0, t.image)
        for j, u in enumerate(ts):
            if i == j:
                cell = t.image
            else:
                w = [2 / 3, 1 / 3] if i > j else [1 / 3, 2 / 3]
                if colors:
                    cell = morph([t, u], w, color_weights=[1.0, 0.0], m=m, threads=threads)
                else:
                    sil = fill_contour(combine_contours([t.resampled, u.resampled], w), t.image.shape[:2])
                    cell = np.zeros((*sil.shape, 4), np.float32)
                    cell[sil] = (0.15, 0.35, 0.15, 1.0)
            put(i + 1, j + 1, cell)
    return out
