"""The photo's label map (thesis §3.5): k-means of the denoised CIELAB colours, majority-filter
erosion of specks, and the optional edge region of §3.5.5."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._api import Seed, renamed
from .._color import check_denoise, denoised_lab, rgb8
from .._progress import Progress
from .._validate import as_image, as_labels, check_int, check_seed

__all__ = ["add_edge_label", "input_labels"]


def _kmeans(
    x: NDArray[np.float32], k: int, rng: np.random.Generator, restarts: int = 3, max_iter: int = 100
) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
    """Lloyd's k-means with k-means++ seeding; the best of ``restarts`` runs by inertia.

    Works on the distinct rows of ``x`` weighted by their counts, which gives the same
    clustering as the full set at a fraction of the cost (8-bit photos repeat colours a lot).
    """
    pts, inverse, counts = np.unique(x.astype(np.float64), axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    wts = counts.astype(np.float64)
    n = len(pts)
    sq = (pts**2).sum(1)
    best: tuple[float, NDArray[np.int64], NDArray[np.float64]] | None = None
    for _ in range(restarts):
        centres = np.empty((k, pts.shape[1]), np.float64)
        centres[0] = pts[rng.choice(n, p=wts / wts.sum())]
        d2 = ((pts - centres[0]) ** 2).sum(1)
        for j in range(1, k):
            p = d2 * wts
            centres[j] = pts[rng.choice(n, p=p / p.sum())] if p.sum() > 0 else pts[rng.integers(n)]
            d2 = np.minimum(d2, ((pts - centres[j]) ** 2).sum(1))
        assign = np.full(n, -1, np.int64)
        for _ in range(max_iter):
            dist = sq[:, None] - 2 * pts @ centres.T + (centres**2).sum(1)[None, :]
            new = dist.argmin(1)
            if np.array_equal(new, assign):
                break
            assign = new
            mass = np.bincount(assign, weights=wts, minlength=k)
            for j in range(k):
                if mass[j] > 0:
                    sel = assign == j
                    centres[j] = (pts[sel] * wts[sel, None]).sum(0) / mass[j]
                else:  # an empty cluster restarts at the point farthest from its centre
                    far = int(dist[np.arange(n), assign].argmax())
                    centres[j] = pts[far]
        inertia = float((wts * ((pts - centres[assign]) ** 2).sum(1)).sum())
        if best is None or inertia < best[0]:
            best = (inertia, assign, centres)
    assert best is not None
    return best[1][inverse].astype(np.int32), best[2].astype(np.float32)


def _majority(labels: NDArray[np.int32], k: int) -> NDArray[np.int32]:
    """One pass of §3.5.4: every pixel becomes its most common 8-neighbour (ties keep the pixel's
    own label when it is among the most common, else the lowest label)."""
    kernel = np.ones((3, 3), np.float32)
    kernel[1, 1] = 0
    counts = np.stack(
        [cv2.filter2D((labels == j).astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT) for j in range(k)]
    )
    top = counts.max(0)
    own = np.take_along_axis(counts, labels[None].astype(np.int64), 0)[0]
    return np.where(own >= top, labels, counts.argmax(0)).astype(np.int32)


@renamed(k="n_labels")
def input_labels(
    image: Any,
    n_labels: int = 2,
    *,
    denoise: float = 10.0,
    erosion: int = 1,
    seed: Seed = 0,
    progress: Progress = None,
) -> NDArray[np.int32]:
    """Segment a bark photo into ``n_labels`` regions: the input label map of the bark thesis (§3.5).

    Steps: non-local-means denoising (Buades et al., OpenCV's ``fastNlMeansDenoisingColored``,
    which itself works in CIELAB), conversion to CIELAB, k-means of the pixel colours into
    ``n_labels`` clusters (Lloyd's algorithm with k-means++ seeding, best of 3; the thesis used scikit-learn's
    mini-batch approximation of the same objective), then ``erosion`` passes of the majority
    filter that removes tiny regions (§3.5.4: every pixel becomes its most common neighbour).
    The thesis keeps only a grey level per region (§3.5.5); phloem numbers the regions
    ``0 … n_labels - 1`` from dark to light by the L* of their cluster centre.

    Parameters
    ----------
    image : array_like, shape (H, W, 3) or (H, W, 4) or (H, W)
        The bark photo; uint8/uint16 are scaled to [0, 1], floats are taken as [0, 1]. Alpha
        is ignored.
    n_labels : int, optional
        Number of regions (default 2; the thesis uses 2–5, §3.5). ``k`` before (deprecated).
    denoise : float, optional
        Filter strength ``h`` of the non-local-means denoising on the 0–255 scale, for both
        lightness and colour (default 10, OpenCV's documented example value); 0 skips it.
    erosion : int, optional
        Passes of the majority filter (default 1, as in the thesis).
    seed : int or numpy.random.Generator, optional
        Seed of the k-means seeding.
    progress : callable, optional
        ``progress(done, total)`` when the work starts and after each step (denoising,
        k-means, every majority pass).

    Returns
    -------
    numpy.ndarray of int32, shape (H, W)
        Labels ``0 … n_labels - 1``, darkest region first.

    Raises
    ------
    ValueError
        If ``n_labels`` is below 2 or larger than the number of distinct colours in ``image``.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = phloem.bark.input_labels(phloem.data.bark(), 3)
    >>> lab.shape, lab.dtype, sorted(np.unique(lab).tolist())
    ((256, 256), dtype('int32'), [0, 1, 2])
    """
    img = as_image(image, "image")
    k = check_int(n_labels, "n_labels", 2)
    erosion = check_int(erosion, "erosion", 0)
    check_denoise(denoise)
    u8 = rgb8(img)
    distinct = len(np.unique(u8.reshape(-1, 3), axis=0))
    if k > distinct:
        raise ValueError(f"n_labels: asked for {k} regions, but the image has only {distinct} distinct colours")
    steps = 2 + erosion
    if progress is not None:
        progress(0, steps)
    lab = denoised_lab(u8, denoise)
    if progress is not None:
        progress(1, steps)
    rng = np.random.default_rng(check_seed(seed))
    assign, centres = _kmeans(lab.reshape(-1, 3), k, rng)
    if progress is not None:
        progress(2, steps)
    order = np.argsort(centres[:, 0], kind="stable")
    rank = np.empty(k, np.int32)
    rank[order] = np.arange(k, dtype=np.int32)
    labels = rank[assign].reshape(img.shape[:2])
    for i in range(erosion):
        labels = _majority(labels, k)
        if progress is not None:
            progress(3 + i, steps)
    return labels


def add_edge_label(labels: Any, *, width: int = 1, label: int | None = None) -> NDArray[np.int32]:
    """Mark the borders between regions with a label of their own (thesis §3.5.5).

    A pixel is on an edge when a pixel within ``width`` steps (8-connected) has another label.
    The thesis found that this extra region often helps texture-by-numbers, and applies it to
    the input and the output label map after both exist (so the shape synthesis never sees it).

    Parameters
    ----------
    labels : array_like of int, shape (H, W)
        A label map.
    width : int, optional
        Half-width of the edge band in pixels (default 1: a 2-pixel band on each border).
    label : int, optional
        Value of the edge label (default: one more than the largest label).

    Returns
    -------
    numpy.ndarray of int32, shape (H, W)

    Examples
    --------
    >>> import numpy as np, phloem
    >>> lab = np.zeros((6, 6), np.int32); lab[:, 3:] = 1
    >>> phloem.bark.add_edge_label(lab)[0].tolist()
    [0, 0, 2, 2, 1, 1]
    """
    lab = as_labels(labels, "labels")
    width = check_int(width, "width", 1)
    edge_value = int(lab.max()) + 1 if label is None else int(label)
    if label is not None and np.any(lab == edge_value):
        raise ValueError(f"label: {edge_value} is already used in labels")
    size = 2 * width + 1
    kernel = np.ones((size, size), np.uint8)
    f = lab.astype(np.float32)
    # min and max filters: a pixel is on an edge when its window holds more than one label
    lo = cv2.erode(f, kernel, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(f, kernel, borderType=cv2.BORDER_REPLICATE)
    return np.where(lo != hi, edge_value, lab).astype(np.int32)
