"""Graph-cut quilting (Kwatra, Schödl, Essa, Turk, Bobick 2003): exemplar blocks placed by
entire-patch matching and joined along minimum-cost seams."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _memory, seams
from .._api import Seed, Size, old_flag, renamed
from .._progress import Progress
from .._validate import as_image, check_int, check_seed, check_size, check_threads, restore_ndim

__all__ = ["QuiltResult", "quilt"]


@dataclass(frozen=True)
class QuiltResult:
    """What :func:`quilt` returns with ``full_output=True``.

    Attributes
    ----------
    texture : (H, W[, C]) ndarray of float32
        The quilted texture (the default return value).
    sources : (H, W, 2) ndarray of int32
        The exemplar (row, col) each output pixel was copied from.
    """

    texture: NDArray[np.float32]
    sources: NDArray[np.int32]


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


def _default_block(eh: int, ew: int) -> int:
    """The block side when none is given: half the exemplar's shorter side, 2 to 64 pixels."""
    return max(2, min(64, min(eh, ew) // 2))


def _default_overlap(block: int) -> int:
    """The overlap when none is given: a quarter of the block, at least 1 pixel."""
    return max(1, block // 4)


@overload
def quilt(
    exemplar: Any,
    size: Size,
    *,
    block: int | None = ...,
    overlap: int | None = ...,
    randomness: float = ...,
    cost: Literal["kwatra", "gradient", "luo"] = ...,
    tileable: bool = ...,
    max_pixels: int = ...,
    max_memory: int | None = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[False] = ...,
) -> NDArray[np.float32]: ...
@overload
def quilt(
    exemplar: Any,
    size: Size,
    *,
    block: int | None = ...,
    overlap: int | None = ...,
    randomness: float = ...,
    cost: Literal["kwatra", "gradient", "luo"] = ...,
    tileable: bool = ...,
    max_pixels: int = ...,
    max_memory: int | None = ...,
    seed: Seed = ...,
    threads: int | None = ...,
    progress: Progress = ...,
    full_output: Literal[True],
) -> QuiltResult: ...


@renamed(return_sources=old_flag(lambda r: (r.texture, r.sources)))
def quilt(
    exemplar: Any,
    size: Size,
    *,
    block: int | None = None,
    overlap: int | None = None,
    randomness: float = 0.01,
    cost: Literal["kwatra", "gradient", "luo"] = "kwatra",
    tileable: bool = False,
    max_pixels: int = 2**28,
    max_memory: int | None = None,
    seed: Seed = 0,
    threads: int | None = None,
    progress: Progress = None,
    full_output: bool = False,
) -> NDArray[np.float32] | QuiltResult:
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
    tileable : bool, optional
        Make the output tile (default False): blocks are placed on a torus, so the last block
        of every row and column overlaps the first ones across the wrap, is matched against
        them and cut into them along a seam like any other overlap. Needs sides of at least
        ``block + 2`` pixels.
    max_pixels : int, optional
        Refuse outputs larger than this many pixels (default 2**28).
    seed : int or numpy.random.Generator, optional
        Seed of the placement choices (default 0).
    threads : int, optional
        Worker threads of the seam computation.
    progress : callable, optional
        Called as ``progress(done, total)`` after every placed block.
    full_output : bool, optional
        Return a :class:`QuiltResult` with, for every output pixel, the exemplar (row, col) it
        was copied from (``return_sources`` before; it still works, deprecated).
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    texture : (H, W[, C]) ndarray of float32
        The quilted texture, 2-D if the exemplar was; a :class:`QuiltResult` with
        ``full_output=True``.

    References
    ----------
    .. [1] V. Kwatra, A. Schödl, I. Essa, G. Turk, A. Bobick, "Graphcut textures: image and
       video synthesis using graph cuts", ACM TOG 22(3), 2003.

    Examples
    --------
    >>> import numpy as np, phloem
    >>> ex = phloem.data.bark()[:128, :128, :3]
    >>> res = phloem.texture.quilt(ex, (100, 150), block=48, seed=1, full_output=True)
    >>> src = res.sources
    >>> res.texture.shape, bool((res.texture == ex[src[..., 0], src[..., 1]]).all())
    ((100, 150, 3), True)
    """
    ex = as_image(exemplar, "exemplar")
    h, w = check_size(size)
    if h * w > check_int(max_pixels, "max_pixels", 1):
        raise ValueError(f"size: {w}×{h} = {h * w} pixels exceeds max_pixels = {max_pixels}")
    _memory.check_size(_memory.quilt((h, w), ex.shape), max_memory, (h, w))
    eh, ew, nc = ex.shape
    if min(eh, ew) < 2:
        raise ValueError(f"exemplar: expected at least 2×2 pixels, got {eh}×{ew}")
    b = _default_block(eh, ew) if block is None else check_int(block, "block", 2)
    if b > min(eh, ew):
        raise ValueError(f"block: {b} does not fit in the {eh}×{ew} exemplar")
    ov = _default_overlap(b) if overlap is None else check_int(overlap, "overlap", 1)
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
    wrap = bool(tileable)
    if wrap:
        if min(h, w) < b + 2:
            raise ValueError(f"size: a tileable quilt needs at least block + 2 = {b + 2} pixels a side, got {w}×{h}")
        # On the torus the canvas is the output; the last block of a row or column overlaps
        # the first by at least `ov` (less than a block) across the wrap.
        ny, nx = math.ceil(h / step), math.ceil(w / step)
        hc, wc = h, w
    else:
        ny, nx = max(1, math.ceil((h - ov) / step)), max(1, math.ceil((w - ov) / step))
        hc, wc = ny * step + ov, nx * step + ov
    canvas = np.zeros((hc, wc, nc), np.float32)
    filled = np.zeros((hc, wc), bool)
    src = np.full((hc, wc, 2), -1, np.int32)
    var = max(float(ex.var()), 1e-12)
    rows, cols = np.mgrid[0:b, 0:b].astype(np.int32)
    for n, (i, j) in enumerate((i, j) for i in range(ny) for j in range(nx)):
        y, x = i * step, j * step
        # The block with a one-pixel ring around it, as row and column indices: clipped to the
        # canvas, or wrapped around the torus.
        if wrap:
            ys, xs = np.arange(y - 1, y + b + 1) % hc, np.arange(x - 1, x + b + 1) % wc
        else:
            ys, xs = np.arange(max(y - 1, 0), min(y + b + 1, hc)), np.arange(max(x - 1, 0), min(x + b + 1, wc))
        win = np.ix_(ys, xs)
        oy, ox = int(wrap or y > 0), int(wrap or x > 0)
        blk = (slice(oy, oy + b), slice(ox, ox + b))
        c_win, f_win, s_win = canvas[win], filled[win], src[win]
        old = f_win[blk]
        first = not old.any()
        if first:
            ty, tx = int(rng.integers(eh - b + 1)), int(rng.integers(ew - b + 1))
        else:
            c = _masked_ssd(ex, np.ascontiguousarray(c_win[blk]), old) / float(old.sum())
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
            foot = np.zeros(f_win.shape, bool)
            foot[blk] = True
            new = np.zeros(c_win.shape, np.float32)
            new[foot] = piece.reshape(-1, nc)
            take_b = seams.seam(c_win, new, f_win & foot, cost=cost, a_mask=f_win, b_mask=foot, threads=t)
            take = take_b[blk]
        c_win[blk][take] = piece[take]
        s_win[blk][take] = np.stack([rows + ty, cols + tx], axis=-1)[take]
        f_win[blk] = True
        canvas[win], src[win], filled[win] = c_win, s_win, f_win
        if progress is not None:
            progress(n + 1, ny * nx)
    out = restore_ndim(np.ascontiguousarray(canvas[:h, :w]), exemplar)
    return QuiltResult(out, np.ascontiguousarray(src[:h, :w])) if full_output else out
