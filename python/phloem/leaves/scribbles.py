"""The user's layers on the training leaf: scribbles in, full layers out (Assa & Cohen-Or §6,
by a lazy-snapping style graph cut after Li, Sun, Tang & Shum, *Lazy Snapping*, 2004).

A few strokes per layer (veins, spots, blade) are expanded to a label for every leaf pixel.
The leaf is over-segmented by a watershed of its CIELAB gradient and every pixel takes its
region's mean colour (the regions follow colour edges, so a vein a few pixels wide stays
apart from the blade, while scan noise is averaged away) and its region's mean thin-line
response (dark and bright ridges 2–6 px wide, beside colour: a vein and the pale relief band
beside it share a colour but not a shape). Each layer's scribbled colours are clustered by
k-means and each cluster takes the mean line response of its pixels; a pixel's data cost for
a layer is its distance to that layer's nearest cluster against the distance to the other
side's (Lazy Snapping's ``E1``), and neighbouring
pixels pay ``λ / (1 + ‖ΔC‖² / σ²)`` for taking different sides (``E2``: cheap across colour
edges, dear inside a region). Layers are cut one at a time in removal order, each against all
later ones together, by :func:`phloem.seams.grid_maxflow`; what a cut takes is no longer in
the later cuts, and what is left after the last cut is the background layer.
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from skimage.segmentation import watershed

from .._api import Seed
from .._ridges import ridge_response
from .._validate import as_image, check_seed, check_threads, derive_seed
from ..seams import grid_maxflow
from .color import _lab, palette

__all__ = ["layers_from_scribbles", "read_scribbles"]

I32 = NDArray[np.int32]

# More distinct opaque colours than this is not a set of layers but an anti-aliased or
# photographic image; the paper's leaves have 3–5 layers.
_MAX_COLOURS = 64
# Colour clusters per layer (Lazy Snapping uses 64; the palette engine takes up to 32, and a
# layer's scribbles on a leaf span a few shades only).
_CLUSTERS = 32
# Weight of E2 against E1 (E1 lies in [0, 1] per pixel, E2 in [0, λ] per 4-neighbour pair).
# 1 keeps 2–3 px veins (whose two long borders each pay λ/(1 + ‖ΔC‖²/σ²) per pixel, small
# across a colour edge) while ignoring speckle of a few pixels; see docs/pipelines/leaves/scribbles.md.
_SMOOTHNESS = 1.0
# Ridge-filter scales (px) of the thin-line feature: veins 2–6 px wide, not the broader relief
# bands beside them.
_LINE_SIGMAS = (1.0, 1.5, 2.0)
# Weight of the line response (scale-normalised curvature of CIELAB L*, in L* units) against
# colour in the data term; docs/pipelines/leaves/scribbles.md has the measured range.
_LINE_WEIGHT = 6.0


def _check_shape(shape: Any) -> tuple[int, int]:
    try:
        dims = tuple(shape)
    except TypeError:
        raise TypeError(f"shape: expected (H, W) or an image shape (H, W, C), got {shape!r}") from None
    if not 2 <= len(dims) <= 3 or not all(
        isinstance(d, numbers.Integral) and not isinstance(d, bool) and int(d) >= 1 for d in dims
    ):
        raise ValueError(f"shape: expected (H, W) or an image shape (H, W, C) of positive integers, got {shape!r}")
    return int(dims[0]), int(dims[1])


def _read_png(path: Path) -> NDArray[Any]:
    """The file's pixels as stored: integers for a gray PNG (labels), else RGBA or RGB."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            im.load()
            if im.mode in ("1", "L", "I", "I;16", "I;16B", "I;16L"):
                return np.asarray(im.convert("I") if im.mode == "1" else im).astype(np.int64)
            # With transparency the RGBA rule applies (opaque = marked), without it the RGB one.
            alpha = im.mode in ("RGBA", "LA", "PA") or "transparency" in im.info
            return np.asarray(im.convert("RGBA" if alpha else "RGB"))
    except FileNotFoundError:
        raise FileNotFoundError(f"scribbles: no such file {str(path)!r}") from None
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"scribbles: cannot read {str(path)!r} as an image ({err})") from None


def _colour_labels(arr: NDArray[Any]) -> I32:
    """Number the opaque colours of an RGB(A) array 1, 2, … in order of first appearance."""
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"scribbles: expected a real-valued colour image, got dtype {arr.dtype}")
    if np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all():
            raise ValueError("scribbles: expected finite colour values")
        top = 1.0
    else:
        top = float(np.iinfo(arr.dtype).max) if arr.dtype in (np.uint8, np.uint16) else 255.0
    h, w, c = arr.shape
    flat = arr.reshape(-1, c)
    # RGBA: only opaque pixels (anti-aliased stroke edges are unmarked); RGB: black is unmarked.
    marked = np.asarray(flat[:, 3] >= top if c == 4 else flat.any(axis=1), bool)
    labels = np.zeros(h * w, np.int32)
    if marked.any():
        colours, first, inverse = np.unique(flat[marked, :3], axis=0, return_index=True, return_inverse=True)
        if len(colours) > _MAX_COLOURS:
            raise ValueError(
                f"scribbles: {len(colours)} distinct opaque colours, at most {_MAX_COLOURS} layers "
                "(draw with a hard, non-anti-aliased brush)"
            )
        rank = np.empty(len(colours), np.int32)
        rank[np.argsort(first, kind="stable")] = np.arange(1, len(colours) + 1, dtype=np.int32)
        labels[marked] = rank[inverse.ravel()]
    return labels.reshape(h, w)


def _integer_labels(arr: NDArray[Any]) -> I32:
    if arr.dtype == np.bool_:
        return arr.astype(np.int32)
    if np.issubdtype(arr.dtype, np.floating):
        if not np.isfinite(arr).all() or (arr != np.round(arr)).any():
            raise ValueError("scribbles: a 2-D label image must hold whole numbers 0..n")
    elif not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"scribbles: expected an integer label image or an RGB(A) image, got dtype {arr.dtype}")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0 or hi > np.iinfo(np.int32).max:
        bad = lo if lo < 0 else hi
        raise ValueError(f"scribbles: labels must lie in 0..n (0 unmarked), found {bad:g}")
    return np.ascontiguousarray(arr, dtype=np.int32)


def read_scribbles(scribbles: Any, shape: Any) -> tuple[I32, int]:
    """The user's scribbles as a label image and the number of layers.

    Parameters
    ----------
    scribbles : array_like or path
        Either an integer image ``(H, W)``: 0 unmarked, ``1..n`` the layers (a gray PNG file
        is read this way too); or a colour image ``(H, W, 4)`` RGBA / ``(H, W, 3)`` RGB
        (array, or a colour PNG file: read as RGBA when it has transparency, else as RGB)
        with one colour per layer. In RGBA only
        opaque pixels are marks (alpha at its maximum: anti-aliased stroke edges and the
        transparent rest are unmarked); in RGB black is unmarked. The colours are numbered
        ``1, 2, …`` in order of first appearance in raster order (row by row, top to bottom,
        each left to right), so the layer drawn highest on the leaf is layer 1.
    shape : tuple of int
        ``(H, W)`` of the training leaf (or its full ``(H, W, C)`` shape).

    Returns
    -------
    labels : (H, W) ndarray of int32
        0 unmarked, ``1..n`` the layers.
    n_layers : int
        ``n``, at least 2: the last layer is the background (residual) layer.

    Raises
    ------
    ValueError
        If the size differs from ``shape``, nothing is marked, only one layer is marked, a
        label lies outside ``0..n`` or a label below the largest has no pixel.
    """
    size = _check_shape(shape)
    if isinstance(scribbles, (str, os.PathLike)):
        arr = _read_png(Path(scribbles))
    else:
        try:
            arr = np.asarray(scribbles)
        except (ValueError, TypeError):
            raise TypeError(
                f"scribbles: expected an image array or a path, got a ragged {type(scribbles).__name__}"
            ) from None
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (3, 4))):
        raise ValueError(f"scribbles: expected an (H, W) label image or an (H, W, 3|4) colour image, got {arr.shape}")
    if arr.shape[:2] != size:
        raise ValueError(f"scribbles: expected the training leaf's size {size}, got {arr.shape[:2]}")
    labels = _integer_labels(arr) if arr.ndim == 2 else _colour_labels(arr)
    n = int(labels.max())
    if n == 0:
        raise ValueError("scribbles: no layer marked (every pixel is 0 / unmarked)")
    present = np.bincount(labels.ravel(), minlength=n + 1)[1:] > 0
    if not present.all():
        missing = int(np.flatnonzero(~present)[0]) + 1
        raise ValueError(f"scribbles: labels must be 1..{n} with none missing; layer {missing} has no pixel")
    if n < 2:
        raise ValueError("scribbles: only one layer marked; need at least two (the last is the background)")
    return labels, n


def _check_order(order: Any, n: int) -> list[int]:
    if order is None:
        return list(range(1, n + 1))
    if isinstance(order, (str, bytes)) or not isinstance(order, Sequence | np.ndarray):
        raise TypeError(f"order: expected a sequence of the labels 1..{n}, got {order!r}")
    items = list(order)
    if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in items):
        raise TypeError(f"order: expected integer labels, got {order!r}")
    out = [int(v) for v in items]
    if sorted(out) != list(range(1, n + 1)):
        raise ValueError(f"order: expected a permutation of the labels 1..{n}, got {out}")
    return out


def _regions(lab: NDArray[np.float32], leaf: NDArray[np.bool_]) -> I32:
    """Watershed over-segmentation of the leaf (Lazy Snapping's pre-segmentation), 0 off it."""
    grad = np.zeros(leaf.shape, np.float32)
    for c in range(3):
        gx = cv2.Sobel(lab[..., c], cv2.CV_32F, 1, 0)
        gy = cv2.Sobel(lab[..., c], cv2.CV_32F, 0, 1)
        grad += gx * gx + gy * gy
    # Local minima of the gradient seed the basins; plateaus (flat colour) are one basin each.
    return np.asarray(watershed(np.sqrt(grad), mask=leaf, connectivity=1), np.int32)  # type: ignore[no-untyped-call]


def _line_features(lightness: NDArray[np.float32], leaf: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Dark- and bright-line strength of every pixel, ``(h, w, 2)``, 0 off the leaf.

    The ridge filter the branching trace uses (``phloem._ridges``: curvature across the line less twice the
    gradient, so the flanks of a broad band or a step do not respond) on CIELAB L*, max over
    ``_LINE_SIGMAS``, weighted by ``_LINE_WEIGHT``.
    """
    strength = np.stack([ridge_response(lightness, _LINE_SIGMAS, p) for p in ("dark", "bright")], axis=-1)
    # The filter answers on a line's centre pixels only; spread that over the line's width (3 px)
    # so that the regions of a 3–5 px vein all carry it.
    spread = cv2.dilate(np.maximum(strength, 0.0), np.ones((3, 3), np.uint8))
    return np.where(leaf[..., None], spread * np.float32(_LINE_WEIGHT), 0.0).astype(np.float32)


def _nearest_distance(colours: NDArray[np.float64], centres: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of each colour to its nearest centre (|a - b|² = |a|² - 2a·b + |b|², one product)."""
    d2 = (centres**2).sum(1)[None, :] - 2.0 * (colours @ centres.T)
    return np.asarray(np.sqrt(np.maximum(d2.min(axis=1) + (colours**2).sum(1), 0.0)))


def layers_from_scribbles(
    training: Any, scribbles: Any, *, order: Any = None, seed: Seed = 0, threads: int | None = None
) -> I32:
    """Expand the user's scribbles on the training leaf to full layers.

    Parameters
    ----------
    training : array_like
        The training leaf, ``(H, W, 4)`` RGBA (straight alpha; the leaf is alpha > 0.5) or
        ``(H, W, 3)`` RGB (every pixel is leaf), uint8/uint16 or float in [0, 1].
    scribbles : array_like or path
        The strokes, in any form :func:`read_scribbles` takes, of the same ``(H, W)``.
        Marks off the leaf are ignored; every layer needs some on it.
    order : sequence of int, optional
        The labels in removal order (default ``1..n``); the last is the background layer,
        which takes every leaf pixel no earlier layer took.
    seed : int or numpy.random.Generator
        Seeds the k-means colour clusters.
    threads : int, optional
        Worker threads of the cuts (default: phloem's pool size); the result is the same for
        any number.

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` int32: the layer ``1..n`` of every leaf pixel, 0 off the leaf. Scribbled
        leaf pixels keep their label.

    Notes
    -----
    Layer ``order[k]`` is cut against ``order[k+1:]`` together on the pixels no earlier cut
    took (a binary graph cut each, :func:`phloem.seams.grid_maxflow`); the method and its
    constants are in ``docs/pipelines/leaves/scribbles.md``.
    """
    img = as_image(training, "training")
    if img.shape[2] not in (3, 4):
        raise ValueError(f"training: expected an RGB or RGBA leaf, got {img.shape[2]} channels")
    labels, n = read_scribbles(scribbles, img.shape)
    removal = _check_order(order, n)
    rng_seed = check_seed(seed)
    threads = check_threads(threads)
    leaf = img[..., 3] > 0.5 if img.shape[2] == 4 else np.ones(img.shape[:2], bool)
    if not leaf.any():
        raise ValueError("training: no leaf pixel (alpha > 0.5)")
    marks = np.where(leaf, labels, 0)
    on_leaf = np.bincount(marks.ravel(), minlength=n + 1)[1:]
    if (on_leaf == 0).any():
        k = int(np.flatnonzero(on_leaf == 0)[0]) + 1
        raise ValueError(f"scribbles: layer {k} has no mark on the leaf (alpha > 0.5)")

    # Work in the leaf's bounding box: the cuts' cost grows with the grid.
    rows, cols = np.flatnonzero(leaf.any(1)), np.flatnonzero(leaf.any(0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    sub_leaf, sub_marks = leaf[box], marks[box]
    lab = _lab(np.ascontiguousarray(img[box]))
    regions = _regions(lab, sub_leaf)
    count = np.bincount(regions.ravel())
    per_pixel = np.concatenate([lab, _line_features(np.ascontiguousarray(lab[..., 0]), sub_leaf)], axis=-1)
    # Per region: mean L*, a*, b* and mean dark- and bright-line strength.
    features = (
        np.stack(
            [np.bincount(regions.ravel(), weights=per_pixel[..., c].ravel(), minlength=len(count)) for c in range(5)],
            axis=1,
        )
        / np.maximum(count, 1)[:, None]
    )
    colour = features[:, :3].astype(np.float32)[regions]  # (h, w, 3): each pixel its region's mean colour

    # Distance of every region's features to each layer's nearest cluster: k-means on the
    # scribbled colours, each cluster then given the mean line response of its pixels.
    # Seeded by place in the removal order, so relabelling the strokes changes nothing.
    dist = np.empty((n, len(count)))
    for place, k in enumerate(removal):
        marked = features[regions[sub_marks == k]]
        centres = palette(marked[:, :3], _CLUSTERS, seed=derive_seed(rng_seed, place))
        near = np.argmin((centres**2).sum(1)[None, :] - 2.0 * (marked[:, :3] @ centres.T), axis=1)
        size = np.maximum(np.bincount(near, minlength=len(centres)), 1)
        line_centres = np.stack([np.bincount(near, marked[:, 3 + c], len(centres)) / size for c in range(2)], axis=1)
        dist[k - 1] = _nearest_distance(features, np.concatenate([centres, line_centres], axis=1))

    # E2 weights of the east and south neighbour pairs; σ² is the mean squared colour step
    # across region borders, so the weights do not depend on the image's contrast.
    d_e = ((colour[:, 1:] - colour[:, :-1]) ** 2).sum(-1)
    d_s = ((colour[1:] - colour[:-1]) ** 2).sum(-1)
    in_e, in_s = sub_leaf[:, 1:] & sub_leaf[:, :-1], sub_leaf[1:] & sub_leaf[:-1]
    steps = np.concatenate([d_e[in_e & (d_e > 0)], d_s[in_s & (d_s > 0)]])
    sigma2 = float(steps.mean()) if steps.size else 1.0
    w_e = np.where(in_e, _SMOOTHNESS / (1.0 + d_e / sigma2), 0.0)
    w_s = np.where(in_s, _SMOOTHNESS / (1.0 + d_s / sigma2), 0.0)

    out = np.zeros(sub_leaf.shape, np.int32)
    free = sub_leaf.copy()
    for step, k in enumerate(removal[:-1]):
        later = removal[step + 1 :]
        d_f, d_b = dist[k - 1], dist[[j - 1 for j in later]].min(axis=0)
        total = d_f + d_b
        e_f = np.where(total > 0, d_f / np.where(total > 0, total, 1.0), 0.5)[regions]  # cost of joining layer k
        source = np.where(free, 1.0 - e_f, 0.0)
        sink = np.where(free, e_f, 0.0)
        source[free & (sub_marks == k)] = np.inf
        sink[free & np.isin(sub_marks, later)] = np.inf
        edges = np.zeros((*sub_leaf.shape, 2))
        edges[:, :-1, 0] = np.where(free[:, 1:] & free[:, :-1], w_e, 0.0)
        edges[:-1, :, 1] = np.where(free[1:] & free[:-1], w_s, 0.0)
        _, sink_side = grid_maxflow(source, sink, edges, threads=threads)
        taken = free & ~sink_side
        out[taken] = k
        free &= ~taken
    out[free] = removal[-1]
    full = np.zeros(leaf.shape, np.int32)
    full[box] = out
    return full
