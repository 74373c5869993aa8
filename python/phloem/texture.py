"""Texture synthesis and image completion on the patch-matching engine.

:func:`synthesize` is texture optimisation (Kwatra, Essa, Bobick, Kwatra 2005), the base of the
texture-by-numbers solver of Laitoch (2018, §3.3): alternate a search step (every output patch
finds its nearest exemplar patch — here by PatchMatch, warm-started from the previous field)
and a voting step (every output pixel becomes the robustly weighted mean of the exemplar pixels
the overlapping matched patches put there), coarse to fine over an image pyramid.

:func:`complete` is the same machinery restricted to a hole (Wexler, Shechtman, Irani 2007):
hole pixels are voted from patches of the known region, with Wexler's similarity weights and
confidence falling off towards the hole's centre.
"""

from __future__ import annotations

import math
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from . import _core, seams
from ._progress import Progress
from ._validate import (
    as_image,
    as_mask,
    check_float,
    check_int,
    check_patch_size,
    check_seed,
    check_size,
    check_threads,
    restore_ndim,
)

__all__ = ["by_numbers", "complete", "feature_distance_map", "quilt", "synthesize"]

#: Kwatra et al. 2005 robust exponent r: weights are |z_p − x_p|^(r − 2).
ROBUST_EXPONENT = 0.8
#: Wexler et al. 2007 confidence base: a pixel at distance d inside the hole has weight γ^−d.
WEXLER_GAMMA = 1.3
#: Wexler et al. 2007 take σ from the distribution of patch distances; their 75th percentile
#: makes the weights nearly uniform and the fill soft. The 25th keeps edges (local contrast
#: in a 96² hole: coffee 0.64 → 0.67, bark 0.78 → 0.84); lower starts to break structures.
WEXLER_SIGMA_PERCENTILE = 25.0
#: Floor of the natural log of a completion vote weight. Deep in a large hole γ^−d times a poor
#: match's similarity underflows float32 (a 60×120 hole in a birch photo: 1753 of its 7200
#: pixels got no vote at all and kept their upsampled value); e^−80 ≈ 2e−35 stays a normal float32, so floored votes
#: still average exactly, and only ties among hopeless patches.
_LOG_WEIGHT_FLOOR = -80.0
#: Completion matches patches on their values and their central-difference gradients
#: (y and x, per channel, this weight each), the distance PyPatchMatch uses. Gradients make a
#: flat patch a poor match for a textured one, so the fill keeps its local contrast
#: (20 held-out fills, 3 seeds: contrast against PyPatchMatch's 0.897 → 0.955 at a mean
#: error still 3 % below PyPatchMatch's; weights 0.5 and 1.5 gave 0.917 and 0.962 at errors
#: 5 % and 0.5 % below).
COMPLETION_GRADIENT_WEIGHT = 1.0
#: Mean-shift steps of the very last vote of completion (Wexler et al. 2007, §3.2; see
#: :func:`phloem.patch.vote`): the final colours move from the mean of the overlapping
#: patches' votes to their dominant mode, so that disagreeing votes do not blur the fill.
COMPLETION_MEAN_SHIFT = 3


def _downsample(img: NDArray[np.float32], shape: tuple[int, int]) -> NDArray[np.float32]:
    h, w = shape
    out = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(out.reshape(h, w, img.shape[2]), dtype=np.float32)


def _upsample_field(
    field: NDArray[np.int32], shape: tuple[int, int], src_shape: tuple[int, int], r: int
) -> NDArray[np.int32]:
    """Coherent upsampling of a field: pixel (y, x) inherits its parent's match, shifted by
    its position inside the parent, clamped to valid centres; ``-1`` stays ``-1``."""
    h, w = shape
    ys, xs = np.arange(h), np.arange(w)
    py = np.minimum(ys // 2, field.shape[0] - 1)
    px = np.minimum(xs // 2, field.shape[1] - 1)
    parent = field[py[:, None], px[None, :]]
    up = np.empty((h, w, 2), dtype=np.int32)
    up[..., 0] = np.clip(2 * parent[..., 0] + (ys - 2 * py)[:, None], r, src_shape[0] - 1 - r)
    up[..., 1] = np.clip(2 * parent[..., 1] + (xs - 2 * px)[None, :], r, src_shape[1] - 1 - r)
    up[parent[..., 0] < 0] = -1
    return up


def _block_field(
    shape: tuple[int, int], src_shape: tuple[int, int], p: int, rng: np.random.Generator
) -> NDArray[np.int32]:
    """Starting field of random coherent blocks: voting it gives a patchwork of exemplar
    pieces, not the grey average a per-pixel random field gives."""
    r = p // 2
    h, w = shape
    bh, bw = (max(1, min(2 * p, src_shape[0] - 2 * r)), max(1, min(2 * p, src_shape[1] - 2 * r)))
    field = np.empty((h, w, 2), np.int32)
    for y0 in range(0, h, bh):
        for x0 in range(0, w, bw):
            sy = rng.integers(r, src_shape[0] - r - bh + 1)
            sx = rng.integers(r, src_shape[1] - r - bw + 1)
            hh, ww = min(bh, h - y0), min(bw, w - x0)
            field[y0 : y0 + hh, x0 : x0 + ww, 0] = sy + np.arange(hh)[:, None]
            field[y0 : y0 + hh, x0 : x0 + ww, 1] = sx + np.arange(ww)[None, :]
    return field


def _occurrence_cost(
    field: NDArray[np.int32], src_shape: tuple[int, int], p: int, lam: float, scale: float
) -> NDArray[np.float32]:
    """Occurrence penalty of Kaspar et al. 2015: how much more than uniformly each source
    patch is covered by the current field, times ``lam`` and the median patch distance."""
    sh, sw = src_shape
    centres = np.bincount((field[..., 0] * sw + field[..., 1]).ravel(), minlength=sh * sw).reshape(sh, sw)
    # Pixels covered: each used centre covers its p×p patch; a candidate's occurrence is the
    # mean coverage over its own patch (two box filters).
    cover = cv2.boxFilter(centres.astype(np.float32), -1, (p, p), normalize=False, borderType=cv2.BORDER_CONSTANT)
    mean_cover = cv2.boxFilter(cover, -1, (p, p), normalize=True, borderType=cv2.BORDER_CONSTANT)
    r = p // 2
    usable = (sh - 2 * r) * (sw - 2 * r)
    expected = field.shape[0] * field.shape[1] * p * p / max(usable, 1)
    over = np.maximum(mean_cover / expected - 1.0, 0.0)
    return np.ascontiguousarray(lam * max(scale, 1e-8) * over, dtype=np.float32)


def _robust_weights(dist: NDArray[np.float32]) -> NDArray[np.float32]:
    """Kwatra's robust vote weights |z − x|^(r − 2) = SSD^((r − 2) / 2), with the SSD floored
    at a tenth of its median so one exact copy cannot outvote every neighbour (hard seams)."""
    floor = max(0.1 * float(np.median(dist)), 1e-8)
    return np.power(np.maximum(dist, floor), (ROBUST_EXPONENT - 2.0) / 2.0, dtype=np.float32)


def _auto_levels(min_side: int, patch_size: int) -> int:
    # The coarsest exemplar keeps at least ~4 patches across. Going coarser (2.5 patches)
    # gets brick courses right but leaves so little exemplar that the output tiles it
    # periodically, which is worse (see metrics.repetition and the note on issue 2).
    return max(1, min(6, math.floor(math.log2(max(min_side / (4 * patch_size), 1.0))) + 1))


def synthesize(
    exemplar: Any,
    size: int | tuple[int, int],
    *,
    patch_size: int = 7,
    levels: int | None = None,
    iterations: int = 4,
    search_iterations: int = 2,
    diversity: float = 1.0,
    weights: Any = None,
    max_pixels: int = 2**28,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    progress: Progress = None,
) -> NDArray[np.float32]:
    """Synthesise a texture of any size from an exemplar by texture optimisation.

    Parameters
    ----------
    exemplar : (M, N[, C]) array_like
        The example texture; any number of channels (a height map can ride along as an extra
        channel and is synthesised consistently with the colours).
    size : int or (int, int)
        Output (height, width); an int makes a square.
    patch_size : int, optional
        Neighbourhood side, odd (default 7).
    levels : int, optional
        Pyramid levels (default: as many as keep the coarsest exemplar at least four patches
        wide, at most 6). One more level helps strongly regular textures (brick courses)
        but risks periodic tiling of small exemplars; check with
        :func:`phloem.metrics.repetition`.
    iterations : int, optional
        Search-and-vote iterations per level (default 4).
    search_iterations : int, optional
        PatchMatch iterations inside each search step, warm-started from the previous field
        (default 2).
    diversity : float, optional
        Weight λ of the occurrence penalty (Kaspar et al. 2015): a source patch used more
        often than uniform use would give costs ``λ × median distance × overuse``, which
        keeps the optimisation from settling on a few (usually the smoothest) exemplar
        patches. 0 gives plain texture optimisation (default 1).
    weights : (C,) array_like, optional
        Per-channel weights of the patch distance.
    max_pixels : int, optional
        Refuse outputs larger than this many pixels (default 2**28, about 16k × 16k), so a
        typo in ``size`` fails at once instead of exhausting memory.
    seed : int or numpy.random.Generator, optional
        Seed (default 0). The output is identical for any number of threads.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    progress : callable, optional
        Called as ``progress(done, total)`` after every iteration.

    Returns
    -------
    texture : (H, W[, C]) ndarray of float32
        The synthesised texture, 2-D if the exemplar was.

    References
    ----------
    .. [1] V. Kwatra, I. Essa, A. Bobick, N. Kwatra, "Texture optimization for example-based
       synthesis", ACM TOG 24(3), 2005.
    .. [2] M. Laitoch, "Procedural modeling of tree bark", 2018, §3.3.
    .. [3] A. Kaspar, B. Neubert, D. Lischinski, M. Pauly, J. Kopf, "Self tuning texture
       optimization", Computer Graphics Forum 34(2), 2015.

    Examples
    --------
    >>> import phloem
    >>> out = phloem.texture.synthesize(phloem.data.bark()[:96, :96, :3], (64, 80), seed=3)
    >>> out.shape, out.dtype.name
    ((64, 80, 3), 'float32')
    """
    ex = as_image(exemplar, "exemplar")
    h, w = check_size(size)
    if h * w > check_int(max_pixels, "max_pixels", 1):
        raise ValueError(f"size: {w}×{h} = {h * w} pixels exceeds max_pixels = {max_pixels}")
    p = check_patch_size(patch_size)
    if p > min(ex.shape[:2]):
        raise ValueError(f"patch_size: {p} does not fit in the {ex.shape[0]}×{ex.shape[1]} exemplar")
    n_levels = _auto_levels(min(ex.shape[:2]), p) if levels is None else check_int(levels, "levels", 1)
    iters = check_int(iterations, "iterations", 1)
    s_iters = check_int(search_iterations, "search_iterations", 1)
    s = check_seed(seed)
    t = check_threads(threads)
    wts = None if weights is None else np.ascontiguousarray(np.asarray(weights, dtype=np.float32).reshape(-1))
    if wts is not None and wts.shape != (ex.shape[2],):
        raise ValueError(f"weights: expected {ex.shape[2]} per-channel weights, got shape {np.shape(weights)}")
    r = p // 2

    # Pyramid, coarsest last; stop where the exemplar no longer holds a patch.
    pyramid: list[tuple[NDArray[np.float32], tuple[int, int]]] = []
    for lv in range(n_levels):
        f = 2**lv
        es = (max(1, round(ex.shape[0] / f)), max(1, round(ex.shape[1] / f)))
        if lv and min(es) < p:
            break
        pyramid.append((ex if lv == 0 else _downsample(ex, es), (max(1, math.ceil(h / f)), max(1, math.ceil(w / f)))))
    lam = float(diversity)
    if not math.isfinite(lam) or lam < 0:
        raise ValueError(f"diversity: expected a finite value >= 0, got {diversity}")
    total = len(pyramid) * iters
    done = 0
    field: NDArray[np.int32] | None = None
    out: NDArray[np.float32] | None = None
    for lv in range(len(pyramid) - 1, -1, -1):
        ex_l, shape = pyramid[lv]
        if field is None:
            field = _block_field(shape, ex_l.shape[:2], p, np.random.default_rng(s))
        else:
            field = _upsample_field(field, shape, ex_l.shape[:2], r)
        out, _ = _core.vote(ex_l, field, patch_size=p, weights=None, threads=t, mean_shift=0)
        last = 0.0
        for it in range(iters):
            cost = _occurrence_cost(field, ex_l.shape[:2], p, lam, last) if lam > 0 and it else None
            field, dist, _ = _core.nnf(
                ex_l, out, patch_size=p, iterations=s_iters, levels=1, exact=False,
                seed=s + 7919 * (lv * 64 + it + 1), weights=wts, source_mask=None, target_mask=None, init=field,
                source_knn=None, source_cost=cost, threads=t, kdtree=False,
            )  # fmt: skip
            last = float(np.median(dist))
            out, _ = _core.vote(ex_l, field, patch_size=p, weights=_robust_weights(dist), threads=t, mean_shift=0)
            done += 1
            if progress is not None:
                progress(done, total)
    assert out is not None
    return restore_ndim(out, exemplar)


def _patch_masks(hole: NDArray[np.bool_], p: int) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """For completion with ``p × p`` patches: the target pixels whose patch touches the hole
    (they need a match) and the source centres whose patch is wholly known and inside."""
    need = cv2.dilate(hole.astype(np.uint8), np.ones((p, p), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    source = ~need.astype(bool)
    r = p // 2
    if r:
        source[:r, :] = source[-r:, :] = False
        source[:, :r] = source[:, -r:] = False
    return need.astype(bool), source


def _with_gradients(img: NDArray[np.float32], weight: float) -> NDArray[np.float32]:
    """``img`` with ``weight`` times its central-difference y and x gradients appended as
    channels (C → 3C; zero on the image border), the features completion matches on."""
    gy = np.zeros_like(img)
    gx = np.zeros_like(img)
    gy[1:-1] = (0.5 * weight) * (img[2:] - img[:-2])
    gx[:, 1:-1] = (0.5 * weight) * (img[:, 2:] - img[:, :-2])
    return np.ascontiguousarray(np.concatenate([img, gy, gx], axis=2), dtype=np.float32)


def _fill_inward(img: NDArray[np.float32], hole: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Onion-peel start for the coarsest level: each ring of the hole takes the mean of its
    already known 8-neighbours."""
    img = img.copy()
    known = (~hole).astype(np.float32)
    img[hole] = 0.0
    kernel = np.ones((3, 3), np.float32)
    remaining = hole.copy()
    while remaining.any():
        cnt = cv2.filter2D(known, -1, kernel, borderType=cv2.BORDER_CONSTANT)
        ring = remaining & (cnt > 0)
        if not ring.any():
            break
        acc = np.stack(
            [
                cv2.filter2D(img[..., c] * known, -1, kernel, borderType=cv2.BORDER_CONSTANT)
                for c in range(img.shape[2])
            ],
            axis=-1,
        )
        img[ring] = acc[ring] / cnt[ring][:, None]
        known[ring] = 1.0
        remaining &= ~ring
    return img


#: Mask-aware downsampling kernel of the completion pyramid (binomial, 6 taps: a coarse pixel
#: sees fine pixels 2y − 2 … 2y + 3), as in Philippeau's completion that PyPatchMatch implements.
_HOLE_KERNEL = np.array([1, 5, 10, 10, 5, 1], np.float32) / 32.0
#: A coarse pixel counts as known when this much of its kernel weight falls on known pixels
#: (below the smallest single-pixel weight 1/1024, so one known fine pixel is enough).
_KNOWN_WEIGHT = 1e-4


def _hole_pyramid(
    img: NDArray[np.float32], hole: NDArray[np.bool_], p: int, max_levels: int | None
) -> list[tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]]:
    """Coarse-to-fine levels for :func:`complete`, finest first: (image, hole, pixels needing a
    match, usable source centres).

    Each level is a normalised convolution of the one below (known pixels only, weighted by
    :data:`_HOLE_KERNEL`, then every second pixel), so a coarse pixel is known as soon as any
    fine pixel under its kernel is: the hole *shrinks* by about two pixels per side at every
    level instead of growing, and the coarsest levels see only a sliver of it, filled by
    interpolation from its rim. Levels are added until the hole vanishes, the image gets
    narrower than a patch, or no whole known patch is left (or ``max_levels`` is reached).
    """
    need, source = _patch_masks(hole, p)
    levels = [(img, hole, need, source)]
    k = (~hole).astype(np.float32)
    v = img * k[..., None]
    a = (2, 2)  # the anchor: output x sums input x − 2 … x + 3

    def down(x: NDArray[np.float32]) -> NDArray[np.float32]:
        y = cv2.sepFilter2D(x, -1, _HOLE_KERNEL, _HOLE_KERNEL, anchor=a, borderType=cv2.BORDER_CONSTANT)
        return np.ascontiguousarray(y.reshape(x.shape[0], x.shape[1], -1)[::2, ::2])

    while max_levels is None or len(levels) < max_levels:
        k, v = down(k)[..., 0], down(v)
        hole_l = k < _KNOWN_WEIGHT
        if not hole_l.any() or min(k.shape) < p:
            break
        need_l, source_l = _patch_masks(hole_l, p)
        if not source_l.any():
            break
        values = np.ascontiguousarray(v / np.maximum(k, _KNOWN_WEIGHT)[..., None], dtype=np.float32)
        values[hole_l] = 0.0
        levels.append((values, hole_l, need_l, source_l))
    return levels


def complete(
    image: Any,
    mask: Any,
    *,
    patch_size: int = 7,
    levels: int | None = None,
    iterations: int | None = None,
    search_iterations: int | None = None,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    progress: Progress = None,
) -> NDArray[np.float32]:
    """Fill the masked pixels of an image from its known pixels (Wexler-style completion).

    The image is completed coarse to fine (Wexler, Shechtman, Irani 2007): at every pyramid
    level, each patch touching the hole finds its nearest wholly known patch by PatchMatch
    (warm-started from the coarser level's field; compared on values and gradients), and
    each hole pixel becomes the mean of the pixels the overlapping matches put there,
    weighted by Wexler's similarity
    ``exp(−d / 2σ²)`` (σ² at the 25th percentile of the distances) times the confidence
    ``1.3^−depth``. The next level starts from the field upsampled and voted with the finer
    level's own pixels, so no blurred upsampled image is ever carried down. The very last
    vote moves each pixel from the mean of its votes to their dominant mode by mean-shift,
    as Wexler et al. propose (:data:`COMPLETION_MEAN_SHIFT`).

    Three choices follow Philippeau's completion as implemented in PyPatchMatch. The first
    two make fills of structured photos accurate: the pyramid is mask-aware and the hole
    *shrinks* on the way up (a coarse pixel is known if any fine pixel under its 6-tap
    binomial kernel is), down to the level where the hole disappears, so large structures
    are settled by interpolation across a sliver of hole and only refined below; and the
    iteration schedule spends many cheap iterations on coarse levels and one at the finest.
    The third keeps fills sharp: patch distances include the gradients
    (:data:`COMPLETION_GRADIENT_WEIGHT`).

    Parameters
    ----------
    image : (M, N[, C]) array_like
        The image; values under the mask are ignored.
    mask : (M, N) array_like of bool
        True where pixels are to be filled.
    patch_size : int, optional
        Patch side, odd (default 7).
    levels : int, optional
        Most pyramid levels (default: until the hole vanishes at the coarsest level).
    iterations : int, optional
        Search-and-vote iterations per level (default ``1 + 2·level``, level 0 the finest:
        one at full resolution, more on the cheap coarse levels).
    search_iterations : int, optional
        PatchMatch iterations per search step (default ``min(7, 1 + level)``).
    seed : int or numpy.random.Generator, optional
        Seed (default 0); identical output for any thread count.
    threads : int, optional
        Worker threads.
    progress : callable, optional
        Called as ``progress(done, total)`` after every iteration.

    Returns
    -------
    completed : (M, N[, C]) ndarray of float32
        The image with the hole filled; pixels outside the mask are returned unchanged.

    References
    ----------
    .. [1] Y. Wexler, E. Shechtman, M. Irani, "Space-time completion of video", IEEE TPAMI
       29(3), 2007.
    .. [2] X. Philippeau, "Inpainting by PatchMatch" (2010); its C++ port in PyPatchMatch
       (J. Mao, https://github.com/vacancy/PyPatchMatch) is the peer in ``benches/peers.py``.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> img = phloem.data.bark()[:96, :96, :3]
    >>> hole = np.zeros((96, 96), bool); hole[40:56, 40:56] = True
    >>> out = phloem.texture.complete(img, hole, seed=0)
    >>> bool(np.array_equal(out[~hole], img[~hole]))
    True
    """
    img = as_image(image, "image")
    hole = as_mask(mask, "mask", img.shape[:2])
    p = check_patch_size(patch_size)
    r = p // 2
    if not hole.any():
        raise ValueError("mask: no pixel is selected for filling (the mask is empty)")
    iters = None if iterations is None else check_int(iterations, "iterations", 1)
    s_iters = None if search_iterations is None else check_int(search_iterations, "search_iterations", 1)
    s = check_seed(seed)
    t = check_threads(threads)
    max_levels = None if levels is None else check_int(levels, "levels", 1)

    pyramid = _hole_pyramid(img, hole, p, max_levels)
    if not pyramid[0][3].any():  # the full-resolution level's usable source centres
        raise ValueError(f"mask: the known region holds no complete {p}×{p} patch to copy from")
    schedule = [(iters or 1 + 2 * lv, s_iters or min(7, 1 + lv)) for lv in range(len(pyramid))]
    total = sum(n for n, _ in schedule)
    done = 0
    field: NDArray[np.int32] | None = None
    cur: NDArray[np.float32] | None = None
    for lv in range(len(pyramid) - 1, -1, -1):
        orig, hole_l, need, smask = pyramid[lv]
        # Distance of hole pixels to the known region, for Wexler's confidence γ^−d (as a log:
        # the vote weights are formed in the log domain and floored).
        depth = cv2.distanceTransform(hole_l.astype(np.uint8), cv2.DIST_L2, 3)
        log_conf = -math.log(WEXLER_GAMMA) * depth[need]
        if cur is None:
            cur = _fill_inward(orig, hole_l)
            init = None
        else:
            cur = orig.copy()
            up = _upsample_field(field, hole_l.shape, orig.shape[:2], r) if field is not None else None
            if up is not None:
                up[~need] = -1
                bad = ~smask[np.maximum(up[..., 0], 0), np.maximum(up[..., 1], 0)] & need
                up[bad] = -1
                voted, wsum = _core.vote(orig, up, patch_size=p, weights=None, threads=t, mean_shift=0)
                fill = hole_l & (wsum > 0)
                cur[fill] = voted[fill]
                rest = hole_l & ~fill
                if rest.any():
                    cur = _fill_inward(cur, rest)
            init = up
        n_iters, n_search = schedule[lv]
        for it in range(n_iters):
            feat = _with_gradients(cur, COMPLETION_GRADIENT_WEIGHT)
            field, dist, _ = _core.nnf(
                feat, feat, patch_size=p, iterations=n_search, levels=1, exact=False,
                seed=s + 7919 * (lv * 64 + it + 1), weights=None, source_mask=smask, target_mask=need,
                init=init, source_knn=None, source_cost=None, threads=t, kdtree=False,
            )  # fmt: skip
            d = dist[need]
            sigma2 = max(float(np.percentile(d, WEXLER_SIGMA_PERCENTILE)), 1e-8)
            wvote = np.zeros(dist.shape, np.float32)
            wvote[need] = np.exp(np.maximum(log_conf - d / (2.0 * sigma2), _LOG_WEIGHT_FLOOR))
            shift = COMPLETION_MEAN_SHIFT if lv == 0 and it == n_iters - 1 else 0
            voted, wsum = _core.vote(cur, field, patch_size=p, weights=wvote, threads=t, mean_shift=shift)
            fill = hole_l & (wsum > 0)
            cur[fill] = voted[fill]  # cur is this level's own copy, never the pyramid's image
            init = field
            done += 1
            if progress is not None:
                progress(done, total)
    assert cur is not None
    out = img.copy()
    out[hole] = cur[hole]
    return restore_ndim(out, image)


def _masked_ssd(ex: NDArray[np.float32], tmpl: NDArray[np.float32], mask: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Sum of squared differences between ``tmpl`` and every same-sized window of ``ex``,
    over the pixels where ``mask`` is set (all channels), by OpenCV's FFT correlation."""
    m = mask.astype(np.float32)
    out: NDArray[np.float32] | None = None
    for c0 in range(0, ex.shape[2], 4):  # matchTemplate takes up to four channels at a time
        e = np.ascontiguousarray(ex[..., c0 : c0 + 4])
        t = np.ascontiguousarray(tmpl[..., c0 : c0 + 4])
        r = np.asarray(cv2.matchTemplate(e, t, cv2.TM_SQDIFF, mask=m), np.float32)
        out = r if out is None else out + r
    assert out is not None
    return np.maximum(out, 0)


@overload
def quilt(
    exemplar: Any,
    size: int | tuple[int, int],
    *,
    block: int | None = ...,
    overlap: int | None = ...,
    randomness: float = ...,
    cost: Literal["kwatra", "gradient", "luo"] = ...,
    max_pixels: int = ...,
    seed: int | np.random.Generator = ...,
    threads: int | None = ...,
    return_sources: Literal[False] = ...,
    progress: Progress = ...,
) -> NDArray[np.float32]: ...
@overload
def quilt(
    exemplar: Any,
    size: int | tuple[int, int],
    *,
    block: int | None = ...,
    overlap: int | None = ...,
    randomness: float = ...,
    cost: Literal["kwatra", "gradient", "luo"] = ...,
    max_pixels: int = ...,
    seed: int | np.random.Generator = ...,
    threads: int | None = ...,
    return_sources: Literal[True],
    progress: Progress = ...,
) -> tuple[NDArray[np.float32], NDArray[np.int32]]: ...
def quilt(
    exemplar: Any,
    size: int | tuple[int, int],
    *,
    block: int | None = None,
    overlap: int | None = None,
    randomness: float = 0.01,
    cost: Literal["kwatra", "gradient", "luo"] = "kwatra",
    max_pixels: int = 2**28,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    return_sources: bool = False,
    progress: Progress = None,
) -> NDArray[np.float32] | tuple[NDArray[np.float32], NDArray[np.int32]]:
    """Synthesise a texture by placing exemplar blocks and joining them along graph-cut seams.

    The output is covered in scanline order by ``block × block`` pieces of the exemplar that
    overlap their predecessors by ``overlap`` pixels. Each piece is chosen by entire-patch
    matching (Kwatra et al. 2003, §3.1): the cost ``C(t)`` of exemplar offset ``t`` is the
    mean squared colour difference with the output over the whole overlap (an L-shaped region
    after the first row), and the offset is drawn with probability ``∝ exp(−C(t) / (k σ²))``,
    σ² the variance of the exemplar's values. The piece is then cut into the output along the
    minimum-cost seam through the overlap (:func:`phloem.seams.seam`), so every output pixel
    is a copy of an exemplar pixel.

    Parameters
    ----------
    exemplar : (M, N[, C]) array_like
        The example texture, any number of channels.
    size : int or (int, int)
        Output (height, width); an int makes a square.
    block : int, optional
        Side of the pieces (default: 64, or half the exemplar's shorter side if smaller).
    overlap : int, optional
        Overlap of neighbouring pieces in pixels, ``1 ≤ overlap < block`` (default
        ``block // 4``).
    randomness : float, optional
        Kwatra's ``k``: 0 always takes the best-matching offset; larger values pick worse
        matches more often (the paper used 0.001 to 1; default 0.01).
    cost : {"kwatra", "gradient", "luo"}, optional
        Seam cost (see :func:`phloem.seams.seam`; default the colour difference).
    max_pixels : int, optional
        Refuse outputs larger than this many pixels (default 2**28).
    seed : int or numpy.random.Generator, optional
        Seed of the placement choices (default 0).
    threads : int, optional
        Worker threads of the seam computation.
    return_sources : bool, optional
        Also return, for every output pixel, the exemplar (row, col) it was copied from.
    progress : callable, optional
        Called as ``progress(done, total)`` after every placed block.

    Returns
    -------
    texture : (H, W[, C]) ndarray of float32
        The quilted texture, 2-D if the exemplar was.
    sources : (H, W, 2) ndarray of int32
        Only with ``return_sources=True``.

    References
    ----------
    .. [1] V. Kwatra, A. Schödl, I. Essa, G. Turk, A. Bobick, "Graphcut textures: image and
       video synthesis using graph cuts", ACM TOG 22(3), 2003.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> ex = phloem.data.bark()[:128, :128, :3]
    >>> out, src = phloem.texture.quilt(ex, (100, 150), block=48, seed=1, return_sources=True)
    >>> out.shape, bool((out == ex[src[..., 0], src[..., 1]]).all())
    ((100, 150, 3), True)
    """
    ex = as_image(exemplar, "exemplar")
    h, w = check_size(size)
    if h * w > check_int(max_pixels, "max_pixels", 1):
        raise ValueError(f"size: {w}×{h} = {h * w} pixels exceeds max_pixels = {max_pixels}")
    eh, ew, nc = ex.shape
    if min(eh, ew) < 2:
        raise ValueError(f"exemplar: expected at least 2×2 pixels, got {eh}×{ew}")
    b = max(2, min(64, min(eh, ew) // 2)) if block is None else check_int(block, "block", 2)
    if b > min(eh, ew):
        raise ValueError(f"block: {b} does not fit in the {eh}×{ew} exemplar")
    ov = max(1, b // 4) if overlap is None else check_int(overlap, "overlap", 1)
    if ov >= b:
        raise ValueError(f"overlap: expected less than block = {b}, got {ov}")
    k = float(randomness)
    if not (math.isfinite(k) and k >= 0):
        raise ValueError(f"randomness: expected a finite value >= 0, got {randomness}")
    if cost not in seams.COSTS:
        raise ValueError(f"cost: expected one of {seams.COSTS}, got {cost!r}")
    rng = np.random.default_rng(check_seed(seed))
    t = check_threads(threads)

    step = b - ov
    ny, nx = max(1, math.ceil((h - ov) / step)), max(1, math.ceil((w - ov) / step))
    hc, wc = ny * step + ov, nx * step + ov
    canvas = np.zeros((hc, wc, nc), np.float32)
    filled = np.zeros((hc, wc), bool)
    src = np.full((hc, wc, 2), -1, np.int32)
    var = max(float(ex.var()), 1e-12)
    rows, cols = np.mgrid[0:b, 0:b].astype(np.int32)
    for n, (i, j) in enumerate((i, j) for i in range(ny) for j in range(nx)):
        y, x = i * step, j * step
        old = filled[y : y + b, x : x + b]
        first = not old.any()
        if first:
            ty, tx = int(rng.integers(eh - b + 1)), int(rng.integers(ew - b + 1))
        else:
            c = _masked_ssd(ex, canvas[y : y + b, x : x + b], old) / float(old.sum())
            if k == 0:
                flat = int(np.argmin(c))
            else:
                p = np.exp(-(c - c.min()) / (k * var)).ravel().astype(np.float64)
                flat = int(rng.choice(p.size, p=p / p.sum()))
            ty, tx = divmod(flat, c.shape[1])
        piece = ex[ty : ty + b, tx : tx + b]
        take = np.ones((b, b), bool)
        if not first:
            # The seam is cut in a window one pixel wider than the block, so the region pixels
            # that border old-only or new-only pixels are tied to that side.
            y0, x0, y1, x1 = max(y - 1, 0), max(x - 1, 0), min(y + b + 1, hc), min(x + b + 1, wc)
            foot = np.zeros((y1 - y0, x1 - x0), bool)
            foot[y - y0 : y - y0 + b, x - x0 : x - x0 + b] = True
            new = np.zeros((y1 - y0, x1 - x0, nc), np.float32)
            new[foot] = piece.reshape(-1, nc)
            have = filled[y0:y1, x0:x1]
            take_b = seams.seam(canvas[y0:y1, x0:x1], new, have & foot, cost=cost, a_mask=have, b_mask=foot, threads=t)
            take = take_b[y - y0 : y - y0 + b, x - x0 : x - x0 + b]
        canvas[y : y + b, x : x + b][take] = piece[take]
        src[y : y + b, x : x + b][take] = np.stack([rows + ty, cols + tx], axis=-1)[take]
        filled[y : y + b, x : x + b] = True
        if progress is not None:
            progress(n + 1, ny * nx)
    out = restore_ndim(np.ascontiguousarray(canvas[:h, :w]), exemplar)
    if return_sources:
        return out, np.ascontiguousarray(src[:h, :w])
    return out


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
    k: int = ...,
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
    seed: int | np.random.Generator = ...,
    threads: int | None = ...,
    return_sources: Literal[False] = ...,
    progress: Progress = ...,
) -> NDArray[np.float32]: ...
@overload
def by_numbers(
    exemplar: Any,
    labels_in: Any,
    labels_out: Any,
    *,
    patch_size: int = ...,
    k: int = ...,
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
    seed: int | np.random.Generator = ...,
    threads: int | None = ...,
    return_sources: Literal[True],
    progress: Progress = ...,
) -> tuple[NDArray[np.float32], NDArray[np.int32]]: ...
def by_numbers(
    exemplar: Any,
    labels_in: Any,
    labels_out: Any,
    *,
    patch_size: int = 7,
    k: int = 1,
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
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    return_sources: bool = False,
    progress: Progress = None,
) -> NDArray[np.float32] | tuple[NDArray[np.float32], NDArray[np.int32]]:
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
    k : int, optional
        k of k-coherence search: every coherence candidate brings its ``k − 1`` nearest
        exemplar patches (default 1: coherence candidates only). ``patch_size=7, k=1``
        measured more coherent than ``5, 2`` on the thesis' bark runs and about as close in
        per-label histograms, at the same time; larger patches or ``k`` raise coherence and
        lower histogram fidelity, at up to twice the time.
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
    return_sources : bool, optional
        Also return the exemplar (row, col) each output pixel was copied from.
    progress : callable, optional
        Called as ``progress(done, total)`` after every solver iteration.

    Returns
    -------
    image : (H, W[, C]) ndarray of float32
        ``B'``, 2-D if the exemplar was.
    sources : (H, W, 2) ndarray of int32
        Only with ``return_sources=True``: ``image == exemplar[sources[..., 0], sources[..., 1]]``.

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
    >>> out, src = phloem.texture.by_numbers(ex, a, b, seed=1, return_sources=True)
    >>> out.shape, bool((a[src[..., 0], src[..., 1]] == b).all())
    ((80, 100, 3), True)
    """
    ex = as_image(exemplar, "exemplar")
    eh, ew, nc = ex.shape
    la, lb = _compact_labels(labels_in, labels_out, (eh, ew))
    p = check_patch_size(patch_size)
    kk = check_int(k, "k", 1)
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
    if return_sources:
        return out, src
    return out
