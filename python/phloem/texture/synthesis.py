"""Texture synthesis by texture optimisation (Kwatra, Essa, Bobick, Kwatra 2005), the base of the
texture-by-numbers solver of Laitoch (2018, §3.3).

Alternate a search step (every output patch finds its nearest exemplar patch — here by
PatchMatch, warm-started from the previous field) and a voting step (every output pixel becomes
the robustly weighted mean of the exemplar pixels the overlapping matched patches put there),
coarse to fine over an image pyramid.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core, _memory
from .._progress import Progress
from .._validate import (
    as_image,
    check_int,
    check_patch_size,
    check_seed,
    check_size,
    check_threads,
    derive_seed,
    restore_ndim,
)
from ._occurrence import occurrence_cost
from ._pyramid import downsample, upsample_field

__all__ = ["synthesize"]

#: Kwatra et al. 2005 robust exponent r: weights are |z_p − x_p|^(r − 2).
ROBUST_EXPONENT = 0.8


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


def _robust_weights(dist: NDArray[np.float32]) -> NDArray[np.float32]:
    """Kwatra's robust vote weights |z − x|^(r − 2) = SSD^((r − 2) / 2), with the SSD floored
    at a tenth of its median so one exact copy cannot outvote every neighbour (hard seams)."""
    floor = max(0.1 * float(np.median(dist)), 1e-8)
    return np.power(np.maximum(dist, floor), (ROBUST_EXPONENT - 2.0) / 2.0, dtype=np.float32)


def _auto_levels(min_side: int, patch_size: int) -> int:
    # The coarsest exemplar keeps at least ~4 patches across: coarser, a small exemplar gets
    # tiled periodically (docs/pipelines/texture.md).
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
    tileable: bool = False,
    max_pixels: int = 2**28,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
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
    tileable : bool, optional
        Make the output tile (default False): it is synthesised on a torus, where the
        patches of the search and the votes that cross an edge continue on the opposite
        side, so copies of it placed side by side show no seam. The exemplar itself need
        not tile.
    max_pixels : int, optional
        Refuse outputs larger than this many pixels (default 2**28, about 16k × 16k), so a
        typo in ``size`` fails at once instead of exhausting memory.
    seed : int or numpy.random.Generator, optional
        Seed (default 0). The output is identical for any number of threads.
    threads : int, optional
        Worker threads (default: ``PHLOEM_NUM_THREADS`` or all cores).
    progress : callable, optional
        Called as ``progress(done, total)`` after every iteration.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

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
    _memory.check_size(_memory.texture_synthesize((h, w), ex.shape), max_memory, (h, w))
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
    wrap = bool(tileable)

    # Pyramid, coarsest last; stop where the exemplar no longer holds a patch.
    pyramid: list[tuple[NDArray[np.float32], tuple[int, int]]] = []
    for lv in range(n_levels):
        f = 2**lv
        es = (max(1, round(ex.shape[0] / f)), max(1, round(ex.shape[1] / f)))
        if lv and min(es) < p:
            break
        pyramid.append((ex if lv == 0 else downsample(ex, es), (max(1, math.ceil(h / f)), max(1, math.ceil(w / f)))))
    lam = float(diversity)
    if not math.isfinite(lam) or lam < 0:
        raise ValueError(f"diversity: expected a finite value >= 0, got {diversity}")
    total = len(pyramid) * iters
    done = 0
    field: NDArray[np.int32] | None = None
    out: NDArray[np.float32] | None = None
    for lv in range(len(pyramid) - 1, -1, -1):
        ex_l, shape = pyramid[lv]
        usable = (ex_l.shape[0] - 2 * r) * (ex_l.shape[1] - 2 * r)
        if field is None:
            field = _block_field(shape, ex_l.shape[:2], p, np.random.default_rng(s))
        else:
            field = upsample_field(field, shape, ex_l.shape[:2], r)
        out, _ = _core.vote(
            ex_l, field, patch_size=p, weights=None, threads=t, mean_shift=0, pixels=None, tileable=wrap
        )
        last = 0.0
        for it in range(iters):
            cost = (
                occurrence_cost(field.reshape(-1, 2), ex_l.shape[:2], p, lam, last, usable) if lam > 0 and it else None
            )
            field, dist, _ = _core.nnf(
                ex_l, out, patch_size=p, iterations=s_iters, levels=1, exact=False,
                seed=derive_seed(s, lv * 64 + it + 1), weights=wts, source_mask=None, target_mask=None, init=field,
                source_knn=None, source_cost=cost, threads=t, kdtree=False, tileable=wrap,
            )  # fmt: skip
            last = float(np.median(dist))
            out, _ = _core.vote(
                ex_l, field, patch_size=p, weights=_robust_weights(dist), threads=t, mean_shift=0, pixels=None,
                tileable=wrap,
            )  # fmt: skip
            done += 1
            if progress is not None:
                progress(done, total)
    assert out is not None
    return restore_ndim(out, exemplar)
