"""Filling a synthesised contour with colour: matching cages, MVC colour transfer, histogram transfer.

Argudo et al. 2017 §5.2 (the cages of §4.6 made to correspond, then :func:`phloem.warp.mvc_combine`)
and §5.3 (per-channel histogram matching that ignores transparent pixels).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from .. import warp
from .._api import Size, renamed
from .._validate import as_mask, check_convex_weights, check_float, check_int, check_size
from ._checks import F32, F64, as_points, as_rgba
from ._outline import dilated_outline, points_at
from .contour_space import combine_contours, fill_contour
from .preprocessing import Tree

__all__ = ["cages", "match_histograms", "morph"]


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
        loop = points_at(closed, cum, np.arange(4 * m) * (cum[-1] / (4 * m)))
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


@renamed(shape="size")
def cages(
    target: Any,
    sources: Sequence[Tree],
    size: Size,
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
    size : int or (int, int)
        ``(H, W)`` of the images (``shape`` before, deprecated).
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
    cr = as_points(target, "target")
    if not sources:
        raise ValueError("sources: expected at least one Tree")
    n = len(sources[0].resampled)
    if len(cr) != n:
        raise ValueError(f"target: expected {n} points like the sources' resampled contours, got {len(cr)}")
    m = check_int(m, "m", 3)
    dilation = check_int(dilation, "dilation", 0)
    h, w = check_size(size)
    tmask = fill_contour(cr, (h, w)) if mask is None else as_mask(mask, "mask", (h, w))
    closed = np.vstack([cr, cr[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    if cum[-1] <= 0:
        raise ValueError("target: the contour is degenerate (all points equal)")
    picks = np.searchsorted(cum, np.arange(m) * (cum[-1] / m), side="right") - 1
    picks = np.clip(picks, 0, n - 1)
    target_cage = _monotone_match(cr[picks], dilated_outline(tmask, dilation))
    out = []
    for t in sources:
        if len(t.resampled) != n:
            raise ValueError(f"sources: every tree needs {n} resampled points, got {len(t.resampled)}")
        outline = t.outline if t.dilation == dilation else dilated_outline(fill_contour(t.resampled, (h, w)), dilation)
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
    img = as_rgba(image, "image")
    ref = as_rgba(reference, "reference")
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
