"""Image completion (Wexler, Shechtman, Irani 2007) on the patch-matching engine.

Texture optimisation restricted to a hole: hole pixels are voted from patches of the known
region, with Wexler's similarity weights and confidence falling off towards the hole's centre,
coarse to fine over a mask-aware pyramid.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._progress import Progress
from .._validate import as_image, as_mask, check_int, check_patch_size, check_seed, check_threads, restore_ndim
from ._pyramid import upsample_field

__all__ = ["complete"]

#: Wexler et al. 2007 confidence base: a pixel at distance d inside the hole has weight γ^−d.
WEXLER_GAMMA = 1.3
#: Wexler et al. 2007 take σ from the distribution of patch distances; their 75th percentile
#: makes the weights nearly uniform and the fill soft, the 25th keeps edges
#: (docs/engines/completion.md).
WEXLER_SIGMA_PERCENTILE = 25.0
#: Floor of the natural log of a completion vote weight: deep in a large hole γ^−d times a poor
#: match's similarity underflows float32 and pixels got no vote; e^−80 ≈ 2e−35 stays a normal
#: float32, so floored votes still average exactly.
_LOG_WEIGHT_FLOOR = -80.0
#: Completion matches patches on their values and their central-difference gradients
#: (y and x, per channel, this weight each), the distance PyPatchMatch uses: gradients make a
#: flat patch a poor match for a textured one, so the fill keeps its local contrast.
COMPLETION_GRADIENT_WEIGHT = 1.0
#: Mean-shift steps of the very last vote of completion (Wexler et al. 2007, §3.2; see
#: :func:`phloem.patch.vote`): the final colours move from the mean of the overlapping
#: patches' votes to their dominant mode, so that disagreeing votes do not blur the fill.
COMPLETION_MEAN_SHIFT = 3


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
            up = upsample_field(field, hole_l.shape, orig.shape[:2], r) if field is not None else None
            if up is not None:
                up[~need] = -1
                bad = ~smask[np.maximum(up[..., 0], 0), np.maximum(up[..., 1], 0)] & need
                up[bad] = -1
                voted, wsum = _core.vote(orig, up, patch_size=p, threads=t)
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
                seed=s + 7919 * (lv * 64 + it + 1), source_mask=smask, target_mask=need,
                init=init, threads=t,
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
