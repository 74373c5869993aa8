"""Texture-by-numbers (Laitoch 2018, §3.3–3.4, after Fan et al. 2012) and the feature distance
map it matches on (Lefebvre and Hoppe 2006, §4.3)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core, _memory
from .._api import Seed, old_flag, renamed
from .._progress import Progress
from .._validate import as_image, check_float, check_int, check_patch_size, check_seed, check_threads, restore_ndim

__all__ = ["ByNumbersResult", "by_numbers", "feature_distance_map"]


@dataclass(frozen=True)
class ByNumbersResult:
    """What :func:`by_numbers` returns with ``full_output=True``.

    Attributes
    ----------
    image : (H, W[, C]) ndarray of float32
        ``B'`` (the default return value).
    sources : (H, W, 2) ndarray of int32
        The exemplar (row, col) each output pixel was copied from:
        ``image == exemplar[sources[..., 0], sources[..., 1]]``.
    """

    image: NDArray[np.float32]
    sources: NDArray[np.int32]


def feature_distance_map(image: Any, *, sigma: float = 3.0, radius: float = 12.0) -> NDArray[np.float32]:
    """Signed feature distance map of an image, the extra channel of Laitoch's Eq. 3.3.

    Laitoch (2018, §3.3.4) takes the feature distance map of Lefebvre and Hoppe (2006, §4.3):
    features are the structural lines of the image — here the dark valleys (bark furrows,
    cracks), found as the pixels of the image smoothed at ``sigma`` that are darker than its
    local mean at ``4 sigma`` — and every pixel stores its signed distance to the feature
    boundary (positive inside a feature), clamped to ``±radius`` and mapped to [0, 1] with
    0.5 on the boundary. Patches compared with this channel see *where* a pixel lies relative
    to the nearest ridge or furrow, which plain colour cannot tell apart in flat regions.

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The exemplar; colour is averaged to gray.
    sigma : float, optional
        Gaussian smoothing in pixels before features are found (default 3).
    radius : float, optional
        Distances are clamped to this many pixels (default 12).

    Returns
    -------
    fdm : (M, N) ndarray of float32
        In [0, 1]: 1 deep inside a feature, 0 far outside, 0.5 on its border.

    References
    ----------
    .. [1] S. Lefebvre, H. Hoppe, "Appearance-space texture synthesis", ACM TOG 25(3), 2006.
    .. [2] M. Laitoch, "Procedural modeling of tree bark", 2018, §3.3.4.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = np.ones((40, 40)); img[:, 18:22] = 0.0  # one dark furrow
    >>> fdm = phloem.texture.feature_distance_map(img, sigma=1.0, radius=8.0)
    >>> bool(fdm[20, 20] > 0.5 > fdm[20, 5]), round(float(fdm[20, 0]), 2)
    (True, 0.0)
    """
    img = as_image(image, "image")
    sg = check_float(sigma, "sigma", 0.0)
    rad = check_float(radius, "radius", 0.0, inclusive=False)
    gray = img.mean(axis=2)
    smooth = cv2.GaussianBlur(gray, (0, 0), sg) if sg > 0 else gray
    local = cv2.GaussianBlur(gray, (0, 0), max(4.0 * sg, 1.0))
    feature = (smooth < local).astype(np.uint8)
    inside = cv2.distanceTransform(feature, cv2.DIST_L2, 5) if feature.any() else np.zeros_like(gray)
    outside = cv2.distanceTransform(1 - feature, cv2.DIST_L2, 5) if not feature.all() else np.zeros_like(gray)
    signed = np.where(feature > 0, inside - 0.5, 0.5 - outside)
    return np.ascontiguousarray((np.clip(signed / rad, -1.0, 1.0) + 1.0) / 2.0, dtype=np.float32)


def _compact_labels(
    labels_in: Any, labels_out: Any, shape_in: tuple[int, int]
) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
    """Label maps as int32 ``0..n-1`` (``np.unique`` order of ``labels_in``), with checks."""
    li, lo = np.asarray(labels_in), np.asarray(labels_out)
    for name, a in (("labels_in", li), ("labels_out", lo)):
        if not (np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_):
            raise TypeError(f"{name}: expected an integer label map, got dtype {a.dtype}")
        if a.ndim != 2:
            raise ValueError(f"{name}: expected a 2-D label map, got shape {a.shape}")
    if li.shape != shape_in:
        raise ValueError(f"labels_in: expected shape {shape_in} to match the exemplar, got {li.shape}")
    values = np.unique(li)
    idx = np.searchsorted(values, lo)
    idx_c = np.minimum(idx, values.size - 1)
    absent = values[idx_c] != lo
    if absent.any():
        y, x = np.argwhere(absent)[0]
        missing = sorted(set(np.unique(lo[absent]).tolist()))
        raise ValueError(f"labels_out: label(s) {missing} (first at row {y}, col {x}) do not occur in labels_in")
    return (
        np.ascontiguousarray(np.searchsorted(values, li), dtype=np.int32),
        np.ascontiguousarray(idx_c, dtype=np.int32),
    )


@overload
def by_numbers(
    exemplar: Any,
    labels_in: Any,
    labels_out: Any,
    *,
    patch_size: int = ...,
    coherence_k: int = ...,
    label_weight: float = ...,
    feature_weight: float = ...,
    features: Any = ...,
    levels: int | None = ...,
    iterations: int = ...,
    init: Literal["smart", "random"] = ...,
    selection: Literal["medoid", "hybrid", "average"] = ...,
    composite: int = ...,
    stand_in_weight: float | None = ...,
    wrap: bool = ...,
    tileable: bool = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.float32]: ...
@overload
def by_numbers(
    exemplar: Any,
    labels_in: Any,
    labels_out: Any,
    *,
    patch_size: int = ...,
    coherence_k: int = ...,
    label_weight: float = ...,
    feature_weight: float = ...,
    features: Any = ...,
    levels: int | None = ...,
    iterations: int = ...,
    init: Literal["smart", "random"] = ...,
    selection: Literal["medoid", "hybrid", "average"] = ...,
    composite: int = ...,
    stand_in_weight: float | None = ...,
    wrap: bool = ...,
    tileable: bool = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    max_memory: int | None = ...,
    full_output: Literal[True],
) -> ByNumbersResult: ...


@renamed(k="coherence_k", return_sources=old_flag(lambda r: (r.image, r.sources)))
def by_numbers(
    exemplar: Any,
    labels_in: Any,
    labels_out: Any,
    *,
    patch_size: int = 7,
    coherence_k: int = 1,
    label_weight: float = 3.0,
    feature_weight: float = 8.0,
    features: Any = "auto",
    levels: int | None = None,
    iterations: int = 3,
    init: Literal["smart", "random"] = "smart",
    selection: Literal["medoid", "hybrid", "average"] = "average",
    composite: int = 1,
    stand_in_weight: float | None = 5.0,
    wrap: bool = True,
    tileable: bool = False,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
    full_output: bool = False,
) -> NDArray[np.float32] | ByNumbersResult:
    """Texture-by-numbers: paint an output label map with the exemplar's matching material.

    Given an exemplar ``A'``, its label map ``A`` and an output label map ``B``, synthesise
    ``B'`` that relates to ``B`` as ``A'`` relates to ``A`` (Laitoch 2018, §3.3–3.4, after Fan
    et al. 2012). The output is an image of references: every pixel is a copy of one exemplar
    pixel, and — a hard constraint phloem adds — always of an exemplar pixel with its own
    label. Coarse to fine over a pyramid of reference images (§3.3.2), from a "smart"
    region-growing (§3.4.2) or a random (§3.4.1) start, each level runs ``iterations`` steps
    (two more at the coarser levels) of the k-coherence discrete solver (§3.3.5): an M-step matches the neighbourhoods of a sparse
    grid of output pixels among k-coherence candidates (plus a PatchMatch-style random search
    among same-label pixels), and an E-step gives every pixel one of the forward-shifted
    matches covering it (its votes), chosen as set by ``selection``. The distance (Eq. 3.3) adds ``w`` per
    label mismatch and ``z`` times the squared feature distance map difference to the squared
    colour difference.

    Parameters
    ----------
    exemplar : (M, N[, C]) array_like
        ``A'``; any number of channels. Extra channels (a height map) ride along: they take
        part in the distance and come out from the same sources.
    labels_in : (M, N) array_like of int
        ``A``; any integer values (they are matched by value, ``np.unique`` order).
    labels_out : (H, W) array_like of int
        ``B``; defines the output size. Every value must occur in ``labels_in``.
    patch_size : int, optional
        Neighbourhood side, odd (default 7).
    coherence_k : int, optional
        The ``k`` of k-coherence search (Tong et al. 2002): every coherence candidate brings
        its ``k − 1`` nearest exemplar patches (default 1: coherence candidates only; ``k``
        before, deprecated). ``patch_size=7, coherence_k=1`` measured more coherent than
        ``5, 2`` on the thesis' bark runs and about as close in per-label histograms, at the
        same time; larger patches or ``coherence_k`` raise coherence and lower histogram
        fidelity, at up to twice the time.
    label_weight : float, optional
        ``w`` of Eq. 3.3 (default 3, the thesis' bark value; Fan et al. used 1).
    feature_weight : float, optional
        ``z`` of Eq. 3.3 (default 8, the thesis' bark value; Fan et al. used 3).
    features : "auto", None or (M, N[, F]) array_like, optional
        Feature distance map of the exemplar: ``"auto"`` computes
        :func:`feature_distance_map`, scaled to the standard deviation of the exemplar's gray
        values (so that ``z`` weighs it like a colour channel, as with the thesis' maps);
        ``None`` leaves the term out; an array supplies it as is.
    levels : int, optional
        Pyramid levels (default: as many as keep the coarsest images 40 pixels wide, at most 5).
    iterations : int, optional
        Solver iterations at the finest level, the thesis' ``maxIterTime`` (default 3); the
        coarser levels run two more (cheap, and the coarse layout decides the coherence).
    init : {"smart", "random"}, optional
        Initialisation of the coarsest level (default "smart").
    selection : {"medoid", "hybrid", "average"}, optional
        How the E-step chooses among a pixel's votes (default "average", followed by one
        round of compositing: see ``composite``).

        - ``"medoid"``: the weighted medoid of the same-label votes (the vote with the least
          weighted sum of distances to the others). Keeps the exemplar's contrast and fine
          cracks (on the bark pipeline's output, Laplacian variance 1.05× the photo's) and the
          closest per-label histograms (0.28–0.43 × the thesis' results), but is the least
          patch-coherent (1.15–1.67 × the thesis').
        - ``"average"``: the vote or coherence candidate nearest to the votes' weighted
          average (Eq. 3.5, as in the thesis). The most patch-coherent (0.95–1.18 × the
          thesis'), but where votes disagree it picks mid-tones: soft, watercolour-like plates
          (Laplacian variance half the photo's).
        - ``"hybrid"``: medoid at every iteration except the finest level's last, which
          averages: in between (coherence 1.00–1.35 × the thesis', Laplacian variance 0.66×
          the photo's).
    composite : int, optional
        Rounds of graph-cut compositing after the finest level (default 1; 0: none). Each round
        walks 32×32 windows (stride 16) and lets each window's 4 most frequent source offsets
        take over pixels by α-expansion under Kwatra et al.'s (2003) seam cost on the colour
        channels, so whole exemplar pieces grow and meet where their copies agree; pixels only
        take copies of their own label (see ``stand_in_weight``). With
        ``selection="average"`` and no stand-ins, one round brings back the photo's sharpness
        (Laplacian variance 0.52× → 1.00× the photo's on the embedded bark) and closer
        per-label histograms (0.31–0.42 × the thesis' results) at the average's coherence
        (0.95–1.23 × the thesis'); with the medoid it cuts incoherence (1.00–1.41 × the
        thesis', from 1.14–1.67). About 0.1–0.2 s per round on bark1.
    stand_in_weight : float or None, optional
        Lets the compositing run a piece across an output label boundary that the exemplar's
        boundaries do not match (default 5; None: never). Where the piece's copy has another
        label than the output pixel, the pixel shows the copy's *stand-in* instead: the
        exemplar pixel of its own label nearest in colour, both its own and its mean over a
        patch around it. Every output pixel still comes from its own label, but the piece
        stays coherent across the boundary. Each stand-in costs this weight times that
        distance, against the seams' unit weight, so only copies that look like the other
        label's pixels around them too are replaced. Lower values give more coherent, less
        label-faithful outputs. On the thesis' four bark runs (seeds 0–2) the default takes
        patch coherence from 0.92–1.28 to 0.65–0.99 × the thesis' results, at a label
        agreement (:func:`phloem.metrics.label_agreement`) above theirs or within 0.6 points.
        Costs about 0.1 s on bark1.
    wrap : bool, optional
        Forward shifts that leave the exemplar wrap around (default True) instead of being
        dropped.
    tileable : bool, optional
        Neighbourhoods wrap around the output's borders so that it tiles (default False).
    seed : int or numpy.random.Generator, optional
        Seed (default 0). The output is identical for any number of threads.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    progress : callable, optional
        Called as ``progress(done, total)`` after every solver iteration.
    full_output : bool, optional
        Return a :class:`ByNumbersResult` with the exemplar (row, col) each output pixel was
        copied from (``return_sources`` before; it still works, deprecated).
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    image : (H, W[, C]) ndarray of float32
        ``B'``, 2-D if the exemplar was; a :class:`ByNumbersResult` with ``full_output=True``.

    References
    ----------
    .. [1] M. Laitoch, "Procedural modeling of tree bark", 2018, §3.3–3.4.
    .. [2] C. Fan, Y. Qi, S. Wang, F. Wen, "Parallel texture-by-numbers", 2012.
    .. [3] S. Lefebvre, H. Hoppe, "Appearance-space texture synthesis", ACM TOG 25(3), 2006.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> ex = phloem.data.bark()[:96, :96, :3]
    >>> a = (ex.mean(axis=2) > 0.3).astype(np.int32)      # dark furrows 0, plates 1
    >>> b = np.zeros((80, 100), np.int32); b[:, 30:70] = 1  # one wide plate
    >>> res = phloem.texture.by_numbers(ex, a, b, seed=1, full_output=True)
    >>> src = res.sources
    >>> res.image.shape, bool((a[src[..., 0], src[..., 1]] == b).all())
    ((80, 100, 3), True)
    """
    ex = as_image(exemplar, "exemplar")
    eh, ew, nc = ex.shape
    la, lb = _compact_labels(labels_in, labels_out, (eh, ew))
    p = check_patch_size(patch_size)
    kk = check_int(coherence_k, "coherence_k", 1)
    w = check_float(label_weight, "label_weight", 0.0)
    z = check_float(feature_weight, "feature_weight", 0.0)
    n_levels = None if levels is None else check_int(levels, "levels", 1)
    iters = check_int(iterations, "iterations", 1)
    rounds = check_int(composite, "composite", 0)
    stand_in = math.inf if stand_in_weight is None else check_float(stand_in_weight, "stand_in_weight", 0.0)
    if init not in ("smart", "random"):
        raise ValueError(f"init: expected 'smart' or 'random', got {init!r}")
    if selection not in ("medoid", "hybrid", "average"):
        raise ValueError(f"selection: expected 'medoid', 'hybrid' or 'average', got {selection!r}")
    if min(eh, ew) < p:
        raise ValueError(f"patch_size: {p} does not fit in the {eh}×{ew} exemplar")
    if min(lb.shape) < p:
        raise ValueError(f"patch_size: {p} does not fit in the {lb.shape[0]}×{lb.shape[1]} output")
    s = check_seed(seed)
    t = check_threads(threads)
    # the exemplar's channels and (by default) its feature-distance channel
    _memory.check_size(_memory.by_numbers(lb.shape, ex.shape, nc + 1), max_memory, lb.shape, "labels_out")
    if isinstance(features, str):
        if features != "auto":
            raise ValueError(f"features: expected 'auto', None or an array, got {features!r}")
        fdm: NDArray[np.float32] | None = None
        if z > 0:
            # The thesis' z = 8 was tuned with a feature channel on the photo's own scale; the
            # [0, 1] map is rescaled to the exemplar's gray standard deviation to match.
            fdm = feature_distance_map(ex)
            fdm *= np.float32(float(ex.mean(axis=2).std()) / max(float(fdm.std()), 1e-6))
    elif features is None:
        fdm = None
    else:
        fdm = as_image(features, "features")
        if fdm.shape[:2] != (eh, ew):
            raise ValueError(f"features: expected shape ({eh}, {ew}[, F]) to match the exemplar, got {fdm.shape}")
    channels = ex
    weights = np.ones(nc, np.float32)
    if fdm is not None and z > 0:
        f3 = fdm.reshape(eh, ew, -1)
        channels = np.ascontiguousarray(np.concatenate([ex, f3], axis=2))
        weights = np.concatenate([weights, np.full(f3.shape[2], z, np.float32)])
    src = _core.by_numbers(
        channels, la, lb, patch_size=p, k=kk, label_weight=w, levels=n_levels, iterations=iters, init=init,
        wrap=bool(wrap), tileable=bool(tileable), seed=s, selection=selection, composite=rounds,
        stand_in_weight=stand_in, seam_channels=nc,
        weights=weights, threads=t,
        progress=progress,
    )  # fmt: skip
    out = restore_ndim(np.ascontiguousarray(ex[src[..., 0], src[..., 1]]), exemplar)
    return ByNumbersResult(out, src) if full_output else out
