"""Measures of result quality that the papers use, so tests and users can score an output.

So far: per-label colour histogram distance (does each labelled region of a texture-by-numbers
output have the colours of the same label in the exemplar), label agreement (would the
exemplar's own colour model put each output pixel in the label it was asked for), patch coherence to an exemplar (how well every patch of an output is explained by some
patch of the exemplar — the quantity texture optimisation minimises, Kwatra et al. 2005, Eq. 1),
repetition (how strongly an output repeats itself at a distance, which coherence cannot see:
a tiled copy of the exemplar is perfectly coherent), the seam at the wrap of a tileable texture
(how much more neighbouring pixels differ across its borders, where copies meet, than inside),
and the shape similarity of binary shapes and
label maps (Rosenberger et al. 2009, thesis Eq. 3.9), and the angle and thickness histograms of
branching structures with their L1 distance (Sibbing et al. 2010, Fig. 7; defined in
:mod:`phloem.branching.histograms` and re-exported here), and the exact earth mover's distance
between two histograms (the colour measure of Assa & Cohen-Or, Eq. 1), and the layer measures of
Assa & Cohen-Or's induction (agreement of an induced layer with a reference, the Eq. 4 objective
as :func:`phloem.leaves.induce` implements it) with a leaf-set diversity measure, and the
stroke measures of Luo et al.'s edits (coverage of the target strokes, width agreement across
corresponding strokes; defined in :mod:`phloem.strokes.measures`), and the measures of whether a
synthesised branching structure looks like its input's kind (re-trace agreement, largest-tree
share, heading-change drift, two-level fraction, the share of the structure that runs along the frame,
how much children turn where they start, how far apart they leave their parent and where along
it the long ones leave, how the parent bends where a child leaves it, which ways it
runs on the image, how much it stands out from its surroundings, how much of the
background's grain its completed gaps keep, how far the picture's emptiest places lie from it,
how much it runs the way the input's branches run at the same places, what stands out
past its branches' ends, how many of them end on other structure, how they thin towards
those ends, and how many side branches grow wider than the branch they leave; defined in
:mod:`phloem.branching.measures`).
"""

from __future__ import annotations

import numbers
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from . import _core
from . import patch as _patch
from . import shapes as _shapes
from ._api import Seed
from ._color import check_denoise, denoised_lab, rgb8
from ._validate import as_image, as_mask, check_float, check_patch_size
from .branching.histograms import angle_histogram, histogram_distance, thickness_histogram
from .branching.measures import (
    Agreement,
    background_grain,
    border_share,
    direction_concentration,
    direction_histogram,
    drift,
    drift_noise,
    empty_space,
    end_taper,
    furcation_gaps,
    heading_change_histogram,
    heading_changes,
    joined_end_share,
    largest_tree_share,
    layout_agreement,
    median_heading_change,
    orientation_distance,
    parent_turns,
    past_end_share,
    retrace_agreement,
    sibling_order,
    skeleton_agreement,
    start_turns,
    structure_contrast,
    two_level_fraction,
    wider_children,
)
from .strokes.measures import stroke_coverage, width_agreement

__all__ = [
    "Agreement",
    "angle_histogram",
    "background_grain",
    "border_share",
    "chord_length",
    "coherence_map",
    "direction_concentration",
    "direction_histogram",
    "drift",
    "drift_noise",
    "emd",
    "empty_space",
    "end_taper",
    "furcation_gaps",
    "heading_change_histogram",
    "heading_changes",
    "histogram_distance",
    "joined_end_share",
    "label_agreement",
    "label_histogram_distance",
    "largest_tree_share",
    "layer_iou",
    "layer_objective",
    "layout_agreement",
    "leaf_diversity",
    "median_heading_change",
    "orientation_distance",
    "parent_turns",
    "past_end_share",
    "patch_coherence",
    "repetition",
    "retrace_agreement",
    "shape_similarity",
    "sibling_order",
    "skeleton_agreement",
    "start_turns",
    "stroke_coverage",
    "structure_contrast",
    "thickness_histogram",
    "two_level_fraction",
    "wider_children",
    "width_agreement",
    "wrap_seam",
]


def coherence_map(
    image: Any,
    exemplar: Any,
    *,
    patch_size: int = 7,
    method: Literal["kdtree", "patchmatch", "exact"] = "kdtree",
    mask: Any = None,
    seed: Seed = 0,
    threads: int | None = None,
) -> NDArray[np.float32]:
    """Per-pixel distance of each ``image`` patch to its nearest ``exemplar`` patch.

    Distances are mean squared differences per value (the patch SSD divided by the number of
    values compared), so they do not depend on patch size or channel count. The default search
    (:func:`phloem.patch.nnf` with ``method="kdtree"``) comes within about 3% of the exact
    value; plain PatchMatch (8 iterations over a 3-level pyramid) overestimates it by a
    quarter or more, and by different amounts for different images (measured 1.26× exact on
    the thesis' blurry bark1 result and 1.38× on a sharp phloem output), so it is only fit for
    comparing outputs of one kind. ``method="exact"`` is brute force, minutes for a 256² image.

    Parameters
    ----------
    image, exemplar : (M, N[, C]) array_like
        The output and the example, with the same channel count.
    patch_size : int, optional
        Patch side, odd (default 7).
    method : {"kdtree", "patchmatch", "exact"}, optional
        Search used to find the nearest patches (default "kdtree").
    mask : (M, N) array_like of bool, optional
        Pixels of ``image`` to score (default all); NaN elsewhere.
    seed : int or numpy.random.Generator, optional
        Seed of the search (default 0).
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).

    Returns
    -------
    distance : (M, N) ndarray of float32
    """
    img = as_image(image, "image")
    ex = as_image(exemplar, "exemplar")
    p = check_patch_size(patch_size)
    m = None if mask is None else as_mask(mask, "mask", img.shape[:2])
    _, dist = _patch.nnf(
        ex, img, patch_size=p, iterations=8, levels=3, method=method, target_mask=m, seed=seed, threads=threads
    )
    h, w = img.shape[:2]
    # Number of values compared at each pixel (patches are clipped at the image border).
    r = p // 2
    ny = np.minimum(np.arange(h), r) + np.minimum(h - 1 - np.arange(h), r) + 1
    nx = np.minimum(np.arange(w), r) + np.minimum(w - 1 - np.arange(w), r) + 1
    out = dist / (ny[:, None] * nx[None, :] * img.shape[2]).astype(np.float32)
    if m is not None:
        out[~m] = np.nan
    return np.asarray(out, dtype=np.float32)


def patch_coherence(image: Any, exemplar: Any, **kwargs: Any) -> float:
    """Mean of :func:`coherence_map`: 0 when every patch of ``image`` occurs in ``exemplar``.

    Takes the same keyword arguments as :func:`coherence_map`. Lower is better.

    Examples
    --------
    >>> import phloem
    >>> bark = phloem.data.bark()[:64, :64, :3]
    >>> phloem.metrics.patch_coherence(bark[8:40, 8:40], bark, patch_size=5)
    0.0
    """
    return float(np.nanmean(coherence_map(image, exemplar, **kwargs)))


def repetition(image: Any, *, min_shift: int = 16, detail: float | None = None, mask: Any = None) -> float:
    """Strongest self-similarity of ``image`` at shifts of at least ``min_shift`` pixels.

    The maximum, over all shifts ``(dy, dx)`` with ``max(|dy|, |dx|) >= min_shift``, of the
    normalised autocorrelation of the gray image (computed by FFT with zero padding, each
    shift normalised by its overlap). Near 1 for an image that repeats verbatim (an exemplar
    tiled periodically), low for a natural texture. Strongly regular textures (bricks) score
    high by nature: compare an output with its exemplar.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The image; colour is averaged to gray.
    min_shift : int, optional
        Shifts closer than this are ignored (default 16), since every image resembles itself
        shifted by a pixel.
    detail : float, optional
        Measure the image's fine grain only: the gray image less its Gaussian blur of this
        sigma (px). A photo's lighting and large shapes resemble themselves over long shifts
        and outweigh a grain that repeats; a fill that copies one small patch over and over
        shows here (default: the whole image).
    mask : (M, N) array_like of bool, optional
        Measure only these pixels (a synthesis' completed gaps, an input's background): each
        shift is compared over the pixels set on both sides, and counts where that overlap
        holds at least a quarter of the mask. Bright structure elsewhere outweighs a lattice
        in the gaps otherwise. The blur of ``detail`` is taken over the whole image first.

    Returns
    -------
    float
        In [-1, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> tile = np.random.default_rng(0).random((40, 40))
    >>> round(phloem.metrics.repetition(np.tile(tile, (3, 3))), 3)
    1.0
    """
    g = as_image(image, "image").mean(axis=2).astype(np.float64)
    if detail is not None:
        sigma = check_float(detail, "detail", 0.0, inclusive=False)
        g -= cv2.GaussianBlur(g, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    h, w = g.shape
    m = int(min_shift)
    if m < 1 or m >= max(h, w) // 2:
        raise ValueError(f"min_shift: expected 1 <= min_shift < {max(h, w) // 2} for a {h}×{w} image, got {min_shift}")
    inside = np.ones((h, w)) if mask is None else as_mask(mask, "mask", (h, w)).astype(np.float64)
    count = float(inside.sum())
    if count == 0:
        raise ValueError("mask: expected at least one pixel set, got an empty mask")
    g -= float((g * inside).sum()) / count
    g *= inside
    shape = (2 * h, 2 * w)
    f = np.fft.rfft2(g, shape)
    ac = np.fft.irfft2(f * np.conj(f), shape)
    fm = np.fft.rfft2(inside, shape)
    sq = np.fft.rfft2(g * g, shape)
    # Overlap count and the energy of each side of the overlap, per shift.
    n = np.fft.irfft2(fm * np.conj(fm), shape)
    e1 = np.fft.irfft2(sq * np.conj(fm), shape)
    e2 = np.fft.irfft2(fm * np.conj(sq), shape)
    dy = np.minimum(np.arange(2 * h), 2 * h - np.arange(2 * h))
    dx = np.minimum(np.arange(2 * w), 2 * w - np.arange(2 * w))
    far = np.maximum(dy[:, None], dx[None, :]) >= m
    # Keep shifts whose overlap is at least a quarter of the measured pixels, so tiny corners don't count.
    valid = far & (n > 0.25 * count)
    corr = ac[valid] / np.sqrt(np.maximum(e1[valid] * e2[valid], 1e-24))
    return float(corr.max()) if corr.size else 0.0


def wrap_seam(image: Any) -> float:
    """How visible the seam is where copies of ``image`` placed side by side meet.

    The mean absolute difference between the last and the first row (and column), i.e. across
    the lines where a 2×2 tiling of the image joins, divided by the mean difference between
    neighbouring rows (columns) inside the image; the mean of the two axes. About 1 for a
    texture that tiles (the wrap is an ordinary line of it), well above 1 for one that does
    not: a photo's opposite borders are unrelated.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The texture, at least 3×3 pixels.

    Returns
    -------
    float
        The ratio, ≥ 0 (``inf`` for a constant image with a step at the wrap).

    Examples
    --------
    >>> import numpy as np, phloem
    >>> noise = np.random.default_rng(0).random((64, 64))
    >>> round(phloem.metrics.wrap_seam(noise), 2)  # noise tiles: its wrap is like any line
    0.92
    >>> round(phloem.metrics.wrap_seam(noise + np.linspace(0, 1, 64)), 2)  # a ramp does not
    2.08
    """
    img = as_image(image, "image").astype(np.float64)
    if min(img.shape[:2]) < 3:
        raise ValueError(f"image: expected at least 3×3 pixels, got {img.shape[0]}×{img.shape[1]}")
    ratios = []
    for axis in (0, 1):
        # Line i vs line i + 1, the last entry across the wrap.
        d = np.abs(np.roll(img, -1, axis) - img).mean(axis=(1 - axis, 2))
        inside = float(d[:-1].mean())
        ratios.append(float(d[-1]) / inside if inside > 0 else (0.0 if d[-1] == 0 else np.inf))
    return float(np.mean(ratios))


def _label_maps(
    labels: Any, shape: tuple[int, ...], exemplar_labels: Any, exemplar_shape: tuple[int, ...]
) -> tuple[NDArray[Any], NDArray[Any]]:
    """An output's and an exemplar's label maps, checked against their images' shapes and for
    output labels the exemplar lacks."""
    lab, elab = np.asarray(labels), np.asarray(exemplar_labels)
    if lab.shape != shape:
        raise ValueError(f"labels: expected shape {shape} to match image, got {lab.shape}")
    if elab.shape != exemplar_shape:
        raise ValueError(f"exemplar_labels: expected shape {exemplar_shape} to match exemplar, got {elab.shape}")
    missing = np.setdiff1d(np.unique(lab), np.unique(elab))
    if missing.size:
        raise ValueError(f"labels: label {missing[0].item()} does not occur in exemplar_labels")
    return lab, elab


def label_histogram_distance(image: Any, labels: Any, exemplar: Any, exemplar_labels: Any, *, bins: int = 32) -> float:
    """How far each labelled region's colours are from the same label's colours in the exemplar.

    For every label of ``labels``, each channel's histogram (``bins`` bins over [0, 1]) of the
    ``image`` pixels with that label is compared with the histogram of the ``exemplar``
    pixels with that label by total variation (half the L1 distance of the normalised
    histograms, in [0, 1]); the result is the mean over channels and labels. 0 when every
    region has exactly its exemplar counterpart's colour distribution. Lower is better.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The output, e.g. of :func:`phloem.texture.by_numbers`.
    labels : (M, N) array_like of int
        Its label map.
    exemplar : (P, Q[, C]) array_like
        The example, with the same channel count.
    exemplar_labels : (P, Q) array_like of int
        The example's label map; must hold every label of ``labels``.
    bins : int, optional
        Histogram bins per channel (default 32).

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> ex = phloem.data.bark()[:64, :64, :3]
    >>> lab = (ex.mean(axis=2) > 0.3).astype(int)
    >>> phloem.metrics.label_histogram_distance(ex[::-1], lab[::-1], ex, lab)
    0.0
    """
    img = as_image(image, "image")
    ex = as_image(exemplar, "exemplar")
    if img.shape[2] != ex.shape[2]:
        raise ValueError(f"exemplar: expected {img.shape[2]} channels like image, got {ex.shape[2]}")
    lab, elab = _label_maps(labels, img.shape[:2], exemplar_labels, ex.shape[:2])
    if isinstance(bins, bool) or not isinstance(bins, int) or bins < 1:
        raise ValueError(f"bins: expected an integer >= 1, got {bins!r}")
    dists = []
    for value in np.unique(lab):
        a, b = img[lab == value], ex[elab == value]
        for c in range(img.shape[2]):
            ha = np.histogram(a[:, c], bins=bins, range=(0.0, 1.0))[0] / len(a)
            hb = np.histogram(b[:, c], bins=bins, range=(0.0, 1.0))[0] / len(b)
            dists.append(0.5 * float(np.abs(ha - hb).sum()))
    return float(np.mean(dists))


def label_agreement(image: Any, labels: Any, exemplar: Any, exemplar_labels: Any, *, denoise: float = 10.0) -> float:
    """Fraction of ``image`` pixels whose look matches the label ``labels`` asks for.

    The exemplar's labels define a colour model as the bark thesis builds its label maps
    (§3.5): non-local-means denoising (strength ``denoise``), CIELAB, and each label's mean
    colour. Every ``image`` pixel, denoised alike, is given the label of the nearest mean; the
    result is the fraction that agree with ``labels``. A texture-by-numbers output that copies
    every pixel from its own label can still score below 1 (noise, colours near the threshold
    between labels; the exemplar scores about 0.94–0.98 against its own map), and one that lets
    pieces run across label boundaries on stand-ins scores lower. Higher is better.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The output; its first 3 channels are read as RGB (gray is repeated).
    labels : (M, N) array_like of int
        Its label map.
    exemplar : (P, Q[, C]) array_like
        The example.
    exemplar_labels : (P, Q) array_like of int
        The example's label map; must hold every label of ``labels``.
    denoise : float, optional
        Non-local-means strength ``h`` on the 0–255 scale (default 10, as
        :func:`phloem.bark.input_labels`); 0 skips it.

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> ex = phloem.data.bark()[:96, :96, :3]
    >>> lab = (ex.mean(axis=2) > 0.3).astype(int)
    >>> round(phloem.metrics.label_agreement(ex, lab, ex, lab), 2)
    0.95
    """
    img = as_image(image, "image")
    ex = as_image(exemplar, "exemplar")
    lab, elab = _label_maps(labels, img.shape[:2], exemplar_labels, ex.shape[:2])
    check_denoise(denoise)
    values = np.unique(elab)
    ex_lab = denoised_lab(rgb8(ex), denoise)
    centres = np.stack([ex_lab[elab == v].mean(axis=0) for v in values])
    img_lab = denoised_lab(rgb8(img), denoise)
    d = ((img_lab[:, :, None, :] - centres[None, None]) ** 2).sum(axis=-1)
    return float(np.mean(values[d.argmin(axis=-1)] == lab))


def shape_similarity(
    a: Any, b: Any, *, patch_size: int = 7, rotations: _shapes.Rotations = "all", threads: int | None = None
) -> float:
    """Boundary-patch distance of two shapes or label maps (thesis Eq. 3.9); lower is better.

    The same function as :func:`phloem.shapes.shape_similarity`, listed here with the other
    measures.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((32, 32), int); a[8:20, 4:12] = 1
    >>> phloem.metrics.shape_similarity(a, np.rot90(a))
    0.0
    """
    return _shapes.shape_similarity(a, b, patch_size=patch_size, rotations=rotations, threads=threads)


def chord_length(labels: Any) -> float:
    """The scale of a shape or label map: its pixel-weighted mean chord length, in pixels.

    The same function as :func:`phloem.shapes.chord_length`, listed here with the other
    measures; compare an output's with its exemplar's to check that blob size was kept.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> phloem.metrics.chord_length(np.zeros((8, 8), int))
    8.0
    """
    return _shapes.chord_length(labels)


def emd(hist_a: Any, hist_b: Any, ground: Any, *, normalized: bool = False) -> float:
    """The exact earth mover's distance between two histograms under a ground distance.

    Both histograms are scaled to unit mass first, so the value is the least mean ground
    distance over which mass must move to turn ``hist_a`` into ``hist_b`` (an exact
    transportation simplex in phloem's Rust core). With ``normalized=True`` it is divided by
    the largest ground distance, so 0 is a match and 1 the farthest two histograms can be: the
    measure of Assa & Cohen-Or, Eq. 1 (see :func:`phloem.leaves.color_distance`).

    Parameters
    ----------
    hist_a, hist_b : array_like
        ``(n,)`` non-negative, finite, not all zero; ``n`` at most 32.
    ground : array_like
        ``(n, n)`` finite, non-negative distances between the bins.
    normalized : bool
        Divide by ``ground.max()`` (0 when every distance is 0).
    """
    a = np.ascontiguousarray(hist_a, dtype=np.float64)
    b = np.ascontiguousarray(hist_b, dtype=np.float64)
    g = np.ascontiguousarray(ground, dtype=np.float64)
    for name, h in (("hist_a", a), ("hist_b", b)):
        if h.ndim != 1:
            raise ValueError(f"{name}: expected a 1-D histogram, got shape {h.shape}")
    if g.shape != (len(a), len(a)) or len(b) != len(a):
        raise ValueError(
            f"ground: expected shape ({len(a)}, {len(a)}) for histograms of {len(a)} and {len(b)} bins, got {g.shape}"
        )
    d = float(_core.emd(a, b, g))
    if normalized:
        top = float(g.max()) if g.size else 0.0
        return d / top if top > 0 else 0.0
    return d


def _layer_pair(a: Any, b: Any, names: tuple[str, str]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    arr = np.asarray(a)
    if arr.ndim != 2:
        raise ValueError(f"{names[0]}: expected a 2-D mask, got shape {arr.shape}")
    first = as_mask(arr, names[0], (arr.shape[0], arr.shape[1]))
    return first, as_mask(b, names[1], (arr.shape[0], arr.shape[1]))


def layer_iou(induced: Any, reference: Any) -> float:
    """Agreement of an induced layer with a reference mask: intersection over union.

    1 when the two masks are equal (two empty masks included), 0 when they share no pixel.
    Higher is better.

    Parameters
    ----------
    induced, reference : (H, W) array_like of bool
        The layer found (e.g. :attr:`phloem.leaves.Induction.masks`) and the true one.

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((4, 4), bool); a[:2] = True
    >>> b = np.zeros((4, 4), bool); b[1:3] = True
    >>> round(phloem.metrics.layer_iou(a, b), 3)
    0.333
    """
    a, b = _layer_pair(induced, reference, ("induced", "reference"))
    union = int((a | b).sum())
    return float((a & b).sum()) / union if union else 1.0


def layer_objective(dissimilarity: Any, layer: Any, delta: float) -> float:
    """The Eq. 4 objective of Assa & Cohen-Or as :func:`phloem.leaves.induce` implements it.

    The layer a threshold ``delta`` induces, ``L = {x : D(x) < delta}`` (pixels where ``D`` is
    NaN, off the leaf, are never in it), scored against the user's layer ``C`` by
    ``|L ∩ C| / (|L ∩ C| + |C − L| + |L − C|)``, the intersection over union. The printed Eq. 4,
    ``|L ∩ C| / (|C − L| · |L − C|)``, grows with the pixels found and shrinks with the pixels
    missed and added, but is unbounded (infinite for a perfect cut), while the paper reports
    maxima of 0.7–0.8: the normalised form with the same three counts is this one
    (``docs/pipelines/leaves/induction.md``). Higher is better.

    Parameters
    ----------
    dissimilarity : (H, W) array_like of float
        ``D`` on the training leaf (NaN off it).
    layer : (H, W) array_like of bool
        The user's layer ``C``.
    delta : float
        The threshold.

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> d = np.array([[0.1, 0.2], [0.6, np.nan]], np.float32)
    >>> c = np.array([[True, True], [False, False]])
    >>> phloem.metrics.layer_objective(d, c, 0.5), phloem.metrics.layer_objective(d, c, 0.15)
    (1.0, 0.5)
    """
    d = np.asarray(dissimilarity)
    if d.ndim != 2 or d.dtype == np.bool_ or not np.issubdtype(d.dtype, np.floating):
        raise ValueError(f"dissimilarity: expected a 2-D float map, got shape {d.shape} of {d.dtype}")
    c = as_mask(layer, "layer", (d.shape[0], d.shape[1]))
    if isinstance(delta, bool) or not isinstance(delta, numbers.Real):
        raise TypeError(f"delta: expected a number, got {delta!r}")
    if np.isnan(delta):
        raise ValueError("delta: expected a number, got NaN")
    with np.errstate(invalid="ignore"):
        induced = d < delta  # NaN compares False: off the leaf is never in the layer
    return layer_iou(induced, c)


def _centred_alpha(leaf: Any, name: str) -> NDArray[np.bool_]:
    arr = np.asarray(leaf)
    if arr.ndim == 3:
        if arr.shape[2] not in (2, 4):
            raise ValueError(
                f"{name}: expected RGBA (H, W, 4), gray+alpha (H, W, 2) or an (H, W) alpha, got {arr.shape}"
            )
        alpha = as_image(arr, name)[..., -1]
    elif arr.ndim == 2:
        alpha = as_image(arr, name)[..., 0] if arr.dtype != np.bool_ else arr.astype(np.float32)
    else:
        raise ValueError(f"{name}: expected RGBA (H, W, 4), gray+alpha (H, W, 2) or an (H, W) alpha, got {arr.shape}")
    m = alpha > 0.5
    ys, xs = np.nonzero(m)
    if len(ys) == 0:
        raise ValueError(f"{name}: the leaf has no pixels (alpha > 0.5)")
    return np.asarray(m[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1])


def leaf_diversity(leaves: Any) -> float:
    """How different the shapes of a set of leaves are: mean pairwise ``1 − IoU`` of their
    alpha masks after centring.

    Each leaf's mask (alpha > 0.5) is translated so that its centroid falls on a common point
    (rounded to the pixel grid), and every pair is scored by one minus the intersection over
    union of the two masks; the result is the mean over pairs. 0 when every leaf has the same
    outline (up to translation), near 1 for outlines that hardly overlap. Only translation is
    removed: the pipeline's leaves all share the training leaf's orientation and scale, so a
    rotated or resized copy counts as a different shape. For the texture side (is a new leaf's
    texture explained by the exemplars) use :func:`patch_coherence`. Higher means more varied.

    Parameters
    ----------
    leaves : list of array_like
        At least two leaves: RGBA ``(H, W, 4)`` (alpha is the last channel), gray + alpha
        ``(H, W, 2)`` or ``(H, W)`` alpha / bool masks; sizes may differ.

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np, phloem
    >>> a = np.zeros((10, 10), bool); a[2:6, 2:6] = True
    >>> b = np.zeros((12, 9), bool); b[5:9, 1:5] = True   # the same square elsewhere
    >>> c = np.zeros((10, 10), bool); c[2:6, 2:4] = True   # half of it
    >>> phloem.metrics.leaf_diversity([a, b]), phloem.metrics.leaf_diversity([a, c])
    (0.0, 0.5)
    """
    if isinstance(leaves, np.ndarray) or not isinstance(leaves, (list, tuple)):
        raise TypeError(f"leaves: expected a list of leaves, got {type(leaves).__name__}")
    if len(leaves) < 2:
        raise ValueError(f"leaves: expected at least 2 leaves, got {len(leaves)}")
    masks = [_centred_alpha(leaf, f"leaves[{i}]") for i, leaf in enumerate(leaves)]
    cy = max(m.shape[0] for m in masks)
    cx = max(m.shape[1] for m in masks)
    placed = []
    for m in masks:
        ys, xs = np.nonzero(m)
        # Centroid onto (cy, cx) of a (2cy+1, 2cx+1) canvas: every cropped mask fits.
        oy, ox = cy - round(float(ys.mean())), cx - round(float(xs.mean()))
        canvas = np.zeros((2 * cy + 1, 2 * cx + 1), bool)
        canvas[oy : oy + m.shape[0], ox : ox + m.shape[1]] = m
        placed.append(canvas)
    scores = [
        1.0 - float((placed[i] & placed[j]).sum()) / float((placed[i] | placed[j]).sum())
        for i in range(len(placed))
        for j in range(i + 1, len(placed))
    ]
    return float(np.mean(scores))
