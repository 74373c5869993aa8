"""The colour term of layer induction (Assa & Cohen-Or, §4, Eq. 1).

``S(x, c)`` is the normalised earth mover's distance between the colour histogram ``H(c)`` of
the pixels the user marked as one layer and the histogram of the ``8 × 8`` neighbourhood of each
pixel ``x`` of a leaf: 0 where the neighbourhood has the layer's colours, 1 where it is as far
from them as two histograms over the palette can be.

Colours are first quantised to a small palette (k-means in CIELAB over the leaf's pixels), so
each EMD is an exact ``n_bins × n_bins`` transportation problem under the Euclidean CIELAB
distance between palette colours; "normalised" divides it by the largest such distance. The
map is computed by phloem's Rust core (exact transportation simplex warm-started from window to
window, windows sliding along rows, an exact cache of window histograms, parallel over fixed
blocks of rows, GIL released, the same result for any number of threads).
"""

from __future__ import annotations

import numbers
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._api import Seed
from .._validate import as_image, as_mask, check_int, check_seed, check_threads

__all__ = ["color_distance", "palette"]

#: The largest palette the engine takes.
MAX_BINS = 32

# Enough pixels to place 16–32 centres well; k-means on all 2 Mpx would cost seconds for nothing.
_SAMPLE = 40_000
_ITERATIONS = 30


def _lab(image: NDArray[np.float32]) -> NDArray[np.float32]:
    rgb = image[..., :3] if image.shape[2] >= 3 else np.repeat(image[..., :1], 3, axis=2)
    rgb = np.ascontiguousarray(np.clip(rgb, 0.0, 1.0), dtype=np.float32)
    return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2Lab), dtype=np.float32)


def _lab_of(image: NDArray[np.float32], where: NDArray[np.bool_]) -> NDArray[np.float32]:
    """The CIELAB colours of the pixels ``where``, ``(N, 3)``.

    Only those pixels are converted (OpenCV converts each pixel on its own, so this equals
    converting the whole image and picking them), as one row.
    """
    px = image[where]
    rgb = px[:, :3] if px.shape[1] >= 3 else np.repeat(px[:, :1], 3, axis=1)
    rgb = np.ascontiguousarray(np.clip(rgb, 0.0, 1.0), dtype=np.float32).reshape(1, -1, 3)
    return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2Lab), dtype=np.float32).reshape(-1, 3)


def _nearest(points: NDArray[Any], centres: NDArray[np.float64], threads: int | None) -> NDArray[np.int32]:
    """The index of each point's nearest centre (the first on a tie), in float32.

    The smallest ``|c|² − 2 ⟨p, c⟩`` (``|p|²`` is the same for every centre), computed by the
    Rust core in the order of the NumPy expression ``cc[k] - 2.0 * (x * c[k, 0] + y * c[k, 1] +
    z * c[k, 2])``, so the labels equal that expression's bit for bit.
    """
    c = np.ascontiguousarray(centres, dtype=np.float32)
    cc = np.ascontiguousarray((c**2).sum(1), dtype=np.float32)
    p = np.ascontiguousarray(points, dtype=np.float32)
    return _core.nearest_colour(p, c, cc, threads=threads)


def palette(lab: Any, n_bins: int = 16, *, seed: Seed = 0, threads: int | None = None) -> NDArray[np.float64]:
    """Up to ``n_bins`` CIELAB colours that quantise the ``(N, 3)`` colours ``lab``.

    k-means (k-means++ start, then Lloyd iterations) on a seeded sample of at most 40 000
    colours; fewer distinct colours than ``n_bins`` give a palette of exactly those colours.
    Deterministic for a seed, the same for any number of ``threads`` (default: phloem's pool
    size).
    """
    n_bins = _check_bins(n_bins)
    threads = check_threads(threads)
    pts = np.asarray(lab).reshape(-1, 3)
    if len(pts) == 0:
        raise ValueError("lab: expected at least one colour")
    rng = np.random.default_rng(check_seed(seed))
    if len(pts) > _SAMPLE:
        pts = pts[np.sort(rng.choice(len(pts), _SAMPLE, replace=False))]
    pts = pts.astype(np.float64)  # after sampling: only the sample is converted
    unique = np.unique(pts, axis=0)
    if len(unique) <= n_bins:
        return unique
    centres = [pts[rng.integers(len(pts))]]
    d2 = ((pts - centres[0]) ** 2).sum(1)
    for _ in range(1, n_bins):
        centres.append(pts[rng.choice(len(pts), p=d2 / d2.sum())])
        d2 = np.minimum(d2, ((pts - centres[-1]) ** 2).sum(1))
    c = np.array(centres)
    pts32 = pts.astype(np.float32)  # what the assignment sees, converted once
    for _ in range(_ITERATIONS):
        lab_of = _nearest(pts32, c, threads)
        counts = np.bincount(lab_of, minlength=n_bins)
        sums = np.stack([np.bincount(lab_of, pts[:, d], minlength=n_bins) for d in range(3)], axis=1)
        moved = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], c)
        if np.allclose(moved, c, atol=1e-6):
            break
        c = moved
    return np.asarray(c[np.lexsort(c.T[::-1])])  # a canonical order, for stable label values


def _check_bins(n_bins: Any) -> int:
    if isinstance(n_bins, bool) or not isinstance(n_bins, numbers.Integral):
        raise TypeError(f"n_bins: expected an integer, got {n_bins!r}")
    if not 2 <= int(n_bins) <= MAX_BINS:
        raise ValueError(f"n_bins: expected 2 to {MAX_BINS} palette colours, got {n_bins}")
    return int(n_bins)


def _leaf(image: NDArray[np.float32], mask: Any, name: str) -> NDArray[np.bool_]:
    shape = (image.shape[0], image.shape[1])
    if mask is not None:
        return as_mask(mask, name, shape)
    if image.shape[2] in (2, 4):  # an alpha channel: the leaf is where it is opaque
        return np.ascontiguousarray(image[..., -1] > 0.5)
    return np.ones(shape, bool)


def color_distance(
    image: Any,
    layer_mask: Any,
    *,
    reference: Any = None,
    mask: Any = None,
    window: int = 8,
    n_bins: int = 16,
    seed: Seed = 0,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """The colour similarity ``S`` of Eq. 1: per pixel of ``image``, the normalised EMD between
    the colour histogram of its ``window × window`` neighbourhood and that of the layer.

    Parameters
    ----------
    image : array_like
        The leaf, ``(H, W, C)`` RGB or RGBA (gray is repeated), uint8/uint16 or float in [0, 1].
    layer_mask : array_like
        ``(H', W')`` bool, the pixels ``c`` of the layer on ``reference`` (the user's layer).
    reference : array_like, optional
        The training leaf that ``layer_mask`` marks; default ``image`` itself.
    mask : array_like, optional
        ``(H, W)`` bool, the leaf pixels of ``image``; default its alpha > 0.5 if it has alpha,
        else every pixel. Pixels outside count in no window and get NaN.
    window : int
        The neighbourhood side (the paper: 8); pixel ``(y, x)`` sees rows
        ``y - window // 2`` to ``y - window // 2 + window - 1`` (and so for columns), clipped.
    n_bins : int
        Palette size, 2 to 32. 16 separates a leaf's blade, vein and spot colours (a leaf is a
        few hues) while keeping each EMD a 16 × 16 problem.
    seed : int or numpy.random.Generator
        Seeds the k-means palette.
    threads : int, optional
        Worker threads (default: phloem's pool size); the result is the same for any number.

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` float32 in [0, 1], NaN outside ``mask``.
    """
    img = as_image(image, "image")
    ref = img if reference is None else as_image(reference, "reference")
    window = check_int(window, "window", 1)
    n_bins = _check_bins(n_bins)
    threads = check_threads(threads)
    leaf = _leaf(img, mask, "mask")
    layer = as_mask(layer_mask, "layer_mask", (ref.shape[0], ref.shape[1]))
    if not layer.any():
        raise ValueError("layer_mask: the layer has no pixels")
    if not leaf.any():
        raise ValueError("mask: the leaf has no pixels")
    leaf_lab = _lab_of(img, leaf)
    layer_lab = _lab_of(ref, layer)
    # The palette covers the leaf and the layer, so the layer's colours have bins of their own
    # even when the leaf shows them rarely.
    pal = palette(np.concatenate([leaf_lab, layer_lab]), n_bins, seed=seed, threads=threads)
    ground = np.sqrt(((pal[:, None, :] - pal[None, :, :]) ** 2).sum(-1))
    labels = np.full(leaf.size, -1, np.int32)
    labels[leaf.ravel()] = _nearest(leaf_lab, pal, threads)
    target = np.bincount(_nearest(layer_lab, pal, threads), minlength=len(pal)).astype(np.float64)
    return _core.emd_map(
        labels.reshape(leaf.shape),
        np.ascontiguousarray(ground),
        target,
        window=window,
        threads=threads,
    )
