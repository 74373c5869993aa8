"""Image completion (Wexler, Shechtman, Irani 2007) on the patch-matching engine.

Texture optimisation restricted to a hole: hole pixels are voted from patches of the known
region, with Wexler's similarity weights and confidence falling off towards the hole's centre,
coarse to fine over a mask-aware pyramid.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from .. import _core, _memory
from .._progress import Progress
from .._validate import (
    as_image,
    as_mask,
    check_float,
    check_int,
    check_patch_size,
    check_seed,
    check_threads,
    derive_seed,
    restore_ndim,
)
from ._occurrence import occurrence_cost
from ._pyramid import DENSE_SHARE, upsample_at

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


def _patch_masks(hole: NDArray[np.bool_], p: int, wrap: bool = False) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """For completion with ``p × p`` patches: the target pixels whose patch touches the hole
    (they need a match) and the source centres whose patch is wholly known and inside (with
    ``wrap``, on the torus: patches continue across the border, every pixel may be a centre)."""
    r = p // 2
    kernel = np.ones((p, p), np.uint8)
    if wrap:
        grown = cv2.dilate(np.pad(hole.astype(np.uint8), r, mode="wrap"), kernel, borderType=cv2.BORDER_CONSTANT)
        need = grown[r : r + hole.shape[0], r : r + hole.shape[1]].astype(bool)
        return need, ~need
    need = cv2.dilate(hole.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    source = ~need.astype(bool)
    if r:
        source[:r, :] = source[-r:, :] = False
        source[:, :r] = source[:, -r:] = False
    return need.astype(bool), source


def _wrap_pad(img: NDArray[Any], r: int) -> NDArray[Any]:
    """``img`` grown by ``r`` pixels of the opposite side on every border: the torus as a
    plain image whose ``r``-inner centres are each torus pixel once (at ``+ r``)."""
    pad = ((r, r), (r, r)) + ((0, 0),) * (img.ndim - 2)
    return np.ascontiguousarray(np.pad(img, pad, mode="wrap"))


def _with_gradients(img: NDArray[np.float32], weight: float, wrap: bool = False) -> NDArray[np.float32]:
    """``img`` with ``weight`` times its central-difference y and x gradients appended as
    channels (C → 3C; zero on the image border, or across it with ``wrap``), the features
    completion matches on."""
    if wrap:
        gy = (0.5 * weight) * (np.roll(img, -1, 0) - np.roll(img, 1, 0))
        gx = (0.5 * weight) * (np.roll(img, -1, 1) - np.roll(img, 1, 1))
        return np.ascontiguousarray(np.concatenate([img, gy, gx], axis=2), dtype=np.float32)
    gy = np.zeros_like(img)
    gx = np.zeros_like(img)
    gy[1:-1] = (0.5 * weight) * (img[2:] - img[:-2])
    gx[:, 1:-1] = (0.5 * weight) * (img[:, 2:] - img[:, :-2])
    return np.ascontiguousarray(np.concatenate([img, gy, gx], axis=2), dtype=np.float32)


def _refresh_gradients(
    feat: NDArray[np.float32],
    img: NDArray[np.float32],
    at: tuple[NDArray[np.intp], ...],
    weight: float,
    wrap: bool = False,
) -> None:
    """Recomputes ``feat = _with_gradients(img, weight, wrap)`` in place at the pixels ``at``
    (rows, columns) only, with the same arithmetic, so the values are those of a full
    recomputation."""
    ys, xs = at
    h, w, c = img.shape
    feat[ys, xs, :c] = img[ys, xs]
    if wrap:
        feat[ys, xs, c : 2 * c] = (0.5 * weight) * (img[(ys + 1) % h, xs] - img[(ys - 1) % h, xs])
        feat[ys, xs, 2 * c :] = (0.5 * weight) * (img[ys, (xs + 1) % w] - img[ys, (xs - 1) % w])
        return
    iy = (ys >= 1) & (ys <= h - 2)
    y, x = ys[iy], xs[iy]
    feat[y, x, c : 2 * c] = (0.5 * weight) * (img[y + 1, x] - img[y - 1, x])
    ix = (xs >= 1) & (xs <= w - 2)
    y, x = ys[ix], xs[ix]
    feat[y, x, 2 * c :] = (0.5 * weight) * (img[y, x + 1] - img[y, x - 1])


def _box3(x: NDArray[np.float32], wrap: bool) -> NDArray[np.float32]:
    """3×3 sums of a 2-D array, zero outside it or (``wrap``) around the torus."""
    if wrap:  # OpenCV's filters do not wrap
        rows = x + np.roll(x, 1, 0) + np.roll(x, -1, 0)
        return np.asarray(rows + np.roll(rows, 1, 1) + np.roll(rows, -1, 1), np.float32)
    return np.asarray(cv2.filter2D(x, -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT), np.float32)


def _fill_inward(img: NDArray[np.float32], hole: NDArray[np.bool_], wrap: bool = False) -> NDArray[np.float32]:
    """Onion-peel start for the coarsest level: each ring of the hole takes the mean of its
    already known 8-neighbours (around the torus with ``wrap``)."""
    img = img.copy()
    ys, xs = np.nonzero(hole)
    if ys.size == 0:
        return img
    # Only the hole's box and a one-pixel ring take part, so rings cost their box, not the
    # image; on a torus the hole may cross the border, and the whole (coarsest) image does.
    box = (
        (slice(None), slice(None))
        if wrap
        else (slice(max(0, ys.min() - 1), ys.max() + 2), slice(max(0, xs.min() - 1), xs.max() + 2))
    )
    sub, remaining = img[box], hole[box].copy()
    known = (~remaining).astype(np.float32)
    sub[remaining] = 0.0
    while remaining.any():
        cnt = _box3(known, wrap)
        ring = remaining & (cnt > 0)
        if not ring.any():
            break
        acc = np.stack([_box3(np.ascontiguousarray(sub[..., c]) * known, wrap) for c in range(sub.shape[2])], axis=-1)
        sub[ring] = acc[ring] / cnt[ring][:, None]
        known[ring] = 1.0
        remaining &= ~ring
    return img


#: Mask-aware downsampling kernel of the completion pyramid (binomial, 6 taps: a coarse pixel
#: sees fine pixels 2y − 2 … 2y + 3), as in Philippeau's completion that PyPatchMatch implements.
_HOLE_KERNEL = np.array([1, 5, 10, 10, 5, 1], np.float32) / 32.0
#: A coarse pixel counts as known when this much of its kernel weight falls on known pixels
#: (below the smallest single-pixel weight 1/1024, so one known fine pixel is enough).
_KNOWN_WEIGHT = 1e-4
#: The strict pyramid's threshold: a coarse pixel is known only when its whole kernel is (the
#: classic pyramid, whose hole grows). Rim pixels are then synthesised, not interpolated from the
#: few known pixels they see, which are biased towards the rim (aliased stripes, a bright bank's
#: halo).
_STRICT_KNOWN_WEIGHT = 0.999
#: ``pyramid="auto"``'s strict alternative differs from the interpolating pyramid from this level
#: on (0: the finest), so the two share the finer levels and are compared one level below.
_STRICT_FROM = 2
#: ``complete(start="blocks")`` builds no level whose hole has more pixels than this many per
#: usable source centre: there the fill would repeat a few source patches.
BLOCKS_MAX_REUSE = 8.0
#: ``pyramid="auto"`` keeps the interpolating pyramid's fill unless the strict one's patch
#: energy is below this fraction of it: a structure broken at the coarse levels (stripes out of
#: phase) raises it several-fold, while on natural photos the two stay within about 20 %.
_AUTO_ENERGY_RATIO = 0.5
#: With a ``source_mask``, completion runs on the box of the hole and the sources (widened by
#: :data:`_CROP_MARGIN` patches) when that box is at most this fraction of the image: nothing
#: outside it can be copied or needs a match, and every level's work then shrinks with the box
#: (a leaf on its canvas: about half). The fill differs only through the random draws, with the
#: same held-out error (docs/engines/completion.md).
_CROP_MAX_FRACTION = 0.75
#: Margin of that box in patch sides: it keeps every pixel a hole patch's match is compared on.
_CROP_MARGIN = 2

Pyramid = Literal["auto", "interpolate", "strict"]
_Level = tuple[NDArray[np.float32], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]


def _copy_centres(level: _Level, field: NDArray[np.int32], cur: NDArray[np.float32]) -> NDArray[np.bool_]:
    """Set every hole pixel of ``cur`` (in place) to the known pixel its patch centre is matched
    to in ``field`` (``complete(finest="copy")``); returns the pixels set, those without a
    usable match keep their value."""
    orig, hole, _, smask = level
    if hole.mean() >= DENSE_SHARE and cur.flags.c_contiguous:
        # flat indices on the whole level: one gather each instead of 2-d ones at nonzero pixels
        src, ok = _usable_centres(field, smask, hole)
        idx = np.flatnonzero(ok)
        cur.reshape(-1, cur.shape[2])[idx] = orig.reshape(-1, orig.shape[2])[src.ravel()[idx]]
        return ok
    ys, xs = np.nonzero(hole)
    at = field[ys, xs]
    ok = (at[:, 0] >= 0) & (at[:, 1] >= 0)
    ok[ok] = smask[at[ok, 0], at[ok, 1]]
    cur[ys[ok], xs[ok]] = orig[at[ok, 0], at[ok, 1]]
    done = np.zeros_like(hole)
    done[ys[ok], xs[ok]] = True
    return done


def _usable_centres(
    field: NDArray[np.int32], smask: NDArray[np.bool_], where: NDArray[np.bool_]
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The flat index of every pixel's matched centre (0 where there is none) and whether it is
    a usable source centre, for the pixels of ``where``."""
    fy, fx = field[..., 0], field[..., 1]
    ok = where & (fy >= 0) & (fx >= 0)
    src = fy.astype(np.intp) * smask.shape[1] + fx
    src[~ok] = 0
    ok &= smask.ravel()[src]
    return src, ok


def _random_blocks(need: NDArray[np.bool_], smask: NDArray[np.bool_], p: int, seed: int) -> NDArray[np.int32]:
    """A field that tiles ``need`` with ``p``-sized blocks, each copied whole from a random usable
    source centre (``complete(start="blocks")``); a pixel whose shifted centre is not usable
    takes its block's centre."""
    H, W = need.shape
    sy, sx = np.nonzero(smask)
    ys, xs = np.nonzero(need)
    by, bx = ys // p, xs // p
    block = by * (W // p + 1) + bx
    pick = np.random.default_rng(seed).integers(0, sy.size, (H // p + 1) * (W // p + 1))[block]
    cy, cx = sy[pick] + ys - by * p - p // 2, sx[pick] + xs - bx * p - p // 2
    ok = (cy >= 0) & (cy < H) & (cx >= 0) & (cx < W)
    ok[ok] = smask[cy[ok], cx[ok]]
    field = np.full((H, W, 2), -1, np.int32)
    field[ys, xs, 0] = np.where(ok, cy, sy[pick])
    field[ys, xs, 1] = np.where(ok, cx, sx[pick])
    return field


def _hole_pyramid(
    img: NDArray[np.float32],
    hole: NDArray[np.bool_],
    p: int,
    max_levels: int | None,
    *,
    allowed: NDArray[np.bool_] | None = None,
    strict_from: int | None = None,
    wrap: bool = False,
    max_reuse: float | None = None,
) -> list[_Level]:
    """Coarse-to-fine levels for :func:`complete`, finest first: (image, hole, pixels needing a
    match, usable source centres).

    Each level is a normalised convolution of the one below (known pixels only, weighted by
    :data:`_HOLE_KERNEL`, then every second pixel), so a coarse pixel is known as soon as any
    fine pixel under its kernel is: the hole *shrinks* by about two pixels per side at every
    level instead of growing, and the coarsest levels see only a sliver of it, filled by
    interpolation from its rim. From level ``strict_from`` on, a coarse pixel is known only when
    its whole kernel is (:data:`_STRICT_KNOWN_WEIGHT`). Source centres need a wholly known
    patch of ``allowed`` pixels (a coarse pixel is allowed when every fine pixel under its
    kernel is). Levels are added until the hole vanishes, the image gets narrower than a patch,
    or no usable source patch is left (or ``max_levels`` is reached), or, with ``max_reuse``,
    until a level's hole has more than ``max_reuse`` pixels per usable source centre. With
    ``wrap`` the image is a torus: the kernel and the patches continue across its borders.
    """
    forbid = None if allowed is None else ~allowed
    need, source = _patch_masks(hole if forbid is None else hole | forbid, p, wrap)
    if forbid is not None:
        need = _patch_masks(hole, p, wrap)[0]
    levels = [(img, hole, need, source)]
    k = (~hole).astype(np.float32)
    v = img * k[..., None]
    f = None if forbid is None else forbid.astype(np.float32)
    a = (2, 2)  # the anchor: output x sums input x − 2 … x + 3

    def down(x: NDArray[np.float32]) -> NDArray[np.float32]:
        if wrap:  # the kernel reads x − 2 … x + 3: three pixels of the opposite side suffice
            y = cv2.sepFilter2D(_wrap_pad(x, 3), -1, _HOLE_KERNEL, _HOLE_KERNEL, anchor=a)
            y = y[3 : 3 + x.shape[0], 3 : 3 + x.shape[1]]
        else:
            y = cv2.sepFilter2D(x, -1, _HOLE_KERNEL, _HOLE_KERNEL, anchor=a, borderType=cv2.BORDER_CONSTANT)
        return np.ascontiguousarray(y.reshape(x.shape[0], x.shape[1], -1)[::2, ::2])

    while max_levels is None or len(levels) < max_levels:
        k, v = down(k)[..., 0], down(v)
        strict = strict_from is not None and len(levels) >= strict_from
        hole_l = k < (_STRICT_KNOWN_WEIGHT if strict else _KNOWN_WEIGHT)
        if not hole_l.any() or min(k.shape) < p:
            break
        need_l, source_l = _patch_masks(hole_l, p, wrap)
        if f is not None:
            f = (down(f)[..., 0] >= _KNOWN_WEIGHT).astype(np.float32)
            source_l = _patch_masks(hole_l | (f > 0), p, wrap)[1]
        if not source_l.any():
            break
        if max_reuse is not None and hole_l.sum() > max_reuse * source_l.sum():
            break
        values = np.ascontiguousarray(v / np.maximum(k, _KNOWN_WEIGHT)[..., None], dtype=np.float32)
        values[hole_l] = 0.0
        levels.append((values, hole_l, need_l, source_l))
    return levels


def _schedule(value: Any, name: str, n_levels: int, default: Callable[[int], int], minimum: int) -> list[int]:
    """Per-level counts, finest first, from None (``default(level)``), an int (every level) or a
    sequence (the finest levels, each at least ``minimum``; the coarser ones repeat its last)."""
    if value is None:
        return [default(lv) for lv in range(n_levels)]
    if isinstance(value, Sequence) and not isinstance(value, str):
        counts = [check_int(c, name, minimum) for c in value]
        if not counts:
            raise ValueError(f"{name}: expected at least one count, got an empty sequence")
        return [counts[min(lv, len(counts) - 1)] for lv in range(n_levels)]
    return [check_int(value, name, 1)] * n_levels


class _Filler:
    """The search-and-vote loop of :func:`complete` over one pyramid's levels."""

    def __init__(
        self,
        p: int,
        seed: int,
        threads: int | None,
        gradient_weight: float,
        progress: Progress,
        base: NDArray[np.float32] | None,
        wrap: bool = False,
        diversity: float = 0.0,
        copy_finest: bool = False,
        blocks: bool = False,
    ) -> None:
        self.p, self.seed, self.threads, self.gw = p, seed, threads, gradient_weight
        self.progress, self.done, self.total = progress, 0, 0
        self.base, self.wrap, self.diversity = base, wrap, diversity
        self.copy_finest = copy_finest  # the full-resolution level copies its field instead of voting it
        self.blocks = blocks  # the coarsest level starts from random source blocks

    def features(self, img: NDArray[np.float32]) -> NDArray[np.float32]:
        return _with_gradients(img, self.gw, self.wrap) if self.gw > 0 else img

    def nnf(
        self,
        feat: NDArray[np.float32],
        smask: NDArray[np.bool_],
        need: NDArray[np.bool_],
        init: NDArray[np.int32] | None,
        seed: int,
        iterations: int,
        cost: NDArray[np.float32] | None = None,
    ) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
        """The hole's patches matched to the source centres. On a torus the target wraps in the
        engine and the source is the image grown by its opposite sides, so source patches
        cross the border too; fields stay in image coordinates either way."""
        src, sm, ini, r = feat, smask, init, (self.p // 2 if self.wrap else 0)
        if self.wrap:
            src, sm = _wrap_pad(feat, r), _wrap_pad(smask, r)
            cost = None if cost is None else _wrap_pad(cost, r)
            ini = None if init is None else np.where(init >= 0, init + r, init).astype(np.int32)
        field, dist, _ = _core.nnf(
            src, feat, patch_size=self.p, iterations=iterations, levels=1, exact=False, seed=seed, weights=None,
            source_mask=sm, target_mask=need, init=ini, source_knn=None, source_cost=cost, threads=self.threads,
            kdtree=False, tileable=self.wrap,
        )  # fmt: skip
        if self.wrap:
            field = np.where(field >= 0, field - r, field).astype(np.int32)
        return field, dist

    def vote(
        self,
        cur: NDArray[np.float32],
        field: NDArray[np.int32],
        weights: NDArray[np.float32] | None,
        mean_shift: int,
        pixels: NDArray[np.bool_],
    ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """:func:`phloem.patch.vote` of ``field`` at ``pixels``, around the torus with ``wrap``."""
        src, f = cur, field
        if self.wrap:
            r = self.p // 2
            src, f = _wrap_pad(cur, r), np.where(field >= 0, field + r, field).astype(np.int32)
        return _core.vote(
            src, f, patch_size=self.p, weights=weights, threads=self.threads, mean_shift=mean_shift, pixels=pixels,
            tileable=self.wrap,
        )  # fmt: skip

    def copies_start(self, lv: int, n_iters: int) -> bool:
        """Whether level ``lv`` with ``n_iters`` iterations starts by copying (not voting) its field."""
        return self.copy_finest and lv == 0 and n_iters == 0

    def start(
        self, level: _Level, field: NDArray[np.int32] | None, copy: bool = False
    ) -> tuple[NDArray[np.float32], NDArray[np.int32] | None]:
        """A level's first image: the coarser field upsampled and voted with this level's own
        pixels (no blurred upsampled image is carried down), or copied (``copy``: a finest
        level without iterations under ``copy_finest``); at the coarsest, the onion peel or
        the ``base`` colour, or random source blocks (``blocks``) whose field the first search
        starts from."""
        orig, hole_l, need, smask = level
        if field is None and self.blocks:
            # a stream of its own: the searches draw lv * 64 + it + 1, the energy lv * 64 + 63
            field = _random_blocks(need, smask, self.p, derive_seed(self.seed, 4093))
            cur = orig.copy()
            rest = hole_l & ~_copy_centres(level, field, cur)
            return (_fill_inward(cur, rest, self.wrap) if rest.any() else cur), field
        if field is None:
            if self.base is None:
                return _fill_inward(orig, hole_l, self.wrap), None
            cur = orig.copy()
            cur[hole_l] = self.base
            return cur, None
        cur = orig.copy()
        up = upsample_at(field, need, orig.shape[:2], self.p // 2, wrap=self.wrap)
        if need.mean() >= DENSE_SHARE:
            up[need & ~_usable_centres(up, smask, need)[1]] = -1
        else:
            ys, xs = np.nonzero(need)
            at = up[ys, xs]
            bad = ~smask[np.maximum(at[:, 0], 0), np.maximum(at[:, 1], 0)]
            up[ys[bad], xs[bad]] = -1
        if copy:
            fill = _copy_centres(level, up, cur)
        else:
            voted, wsum = self.vote(orig, up, None, 0, hole_l)
            fill = hole_l & (wsum > 0)
            cur[fill] = voted[fill]
        rest = hole_l & ~fill
        if rest.any():
            cur = _fill_inward(cur, rest, self.wrap)
        return cur, up

    def iterate(
        self,
        level: _Level,
        lv: int,
        cur: NDArray[np.float32],
        init: NDArray[np.int32] | None,
        n_iters: int,
        n_search: int,
        mean_shift: int,
    ) -> tuple[NDArray[np.float32], NDArray[np.int32] | None]:
        """Search-and-vote iterations at one level; ``cur`` is this level's own copy."""
        _, hole_l, need, smask = level
        # Wexler's confidence γ^−d as a log: the vote weights are formed in the log domain and
        # floored, so deep inside a large hole they cannot underflow float32.
        if self.wrap:  # distances around the torus: half of it on every side covers them all
            mh, mw = hole_l.shape[0] // 2 + 1, hole_l.shape[1] // 2 + 1
            grown = np.pad(hole_l.astype(np.uint8), ((mh, mh), (mw, mw)), mode="wrap")
            depth = cv2.distanceTransform(grown, cv2.DIST_L2, 3)[mh:-mh, mw:-mw]
        else:
            depth = cv2.distanceTransform(hole_l.astype(np.uint8), cv2.DIST_L2, 3)
        log_conf = -math.log(WEXLER_GAMMA) * depth[need]
        field = init
        usable, last = int(smask.sum()), 0.0
        # A vote changes only hole pixels, and a gradient sees one pixel either side: after the
        # first iteration the features are refreshed on the hole's one-pixel dilation alone.
        feat: NDArray[np.float32] | None = None
        band: tuple[NDArray[np.intp], ...] | None = None
        for it in range(n_iters):
            if feat is None:
                feat = self.features(cur)
            elif self.gw > 0:
                if band is None:
                    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
                    h8 = hole_l.astype(np.uint8)
                    band = np.nonzero(
                        cv2.dilate(_wrap_pad(h8, 1), cross)[1:-1, 1:-1] if self.wrap else cv2.dilate(h8, cross)
                    )
                _refresh_gradients(feat, cur, band, self.gw, self.wrap)
            # Kaspar's occurrence penalty from the second iteration on, as texture synthesis runs it.
            cost = None
            if self.diversity > 0 and it and field is not None:
                cost = occurrence_cost(field[need], cur.shape[:2], self.p, self.diversity, last, usable)
            field, dist = self.nnf(feat, smask, need, field, derive_seed(self.seed, lv * 64 + it + 1), n_search, cost)
            d = dist[need]
            last = float(np.median(d))
            if self.copy_finest and lv == 0 and it == n_iters - 1:
                _copy_centres(level, field, cur)
            else:
                sigma2 = max(float(np.percentile(d, WEXLER_SIGMA_PERCENTILE)), 1e-8)
                wvote = np.zeros(dist.shape, np.float32)
                wvote[need] = np.exp(np.maximum(log_conf - d / (2.0 * sigma2), _LOG_WEIGHT_FLOOR))
                shift = mean_shift if it == n_iters - 1 else 0
                voted, wsum = self.vote(cur, field, wvote, shift, hole_l)
                fill = hole_l & (wsum > 0)
                cur[fill] = voted[fill]
            self.done += 1
            if self.progress is not None:
                self.progress(self.done, self.total)
        return cur, field

    def run(
        self, pyramid: list[_Level], stop: int, iters: list[int], search: list[int]
    ) -> tuple[NDArray[np.float32], NDArray[np.int32] | None]:
        """Levels from the coarsest down to ``stop``; returns the image and field there."""
        field: NDArray[np.int32] | None = None
        cur = pyramid[-1][0]
        for lv in range(len(pyramid) - 1, stop - 1, -1):
            cur, init = self.start(pyramid[lv], field, self.copies_start(lv, iters[lv]))
            shift = COMPLETION_MEAN_SHIFT if lv == 0 else 0
            cur, new = self.iterate(pyramid[lv], lv, cur, init, iters[lv], search[lv], shift)
            field = new if new is not None else init
        return cur, field

    def energy(self, level: _Level, cur: NDArray[np.float32], init: NDArray[np.int32] | None, lv: int) -> float:
        """Mean patch distance of the hole's patches to their nearest sources (Wexler's
        objective), searched from ``init``."""
        _, _, need, smask = level
        feat = self.features(cur)
        _, dist = self.nnf(feat, smask, need, init, derive_seed(self.seed, lv * 64 + 63), 3)
        return float(dist[need].mean())


def complete(
    image: Any,
    mask: Any,
    *,
    source_mask: Any = None,
    patch_size: int = 7,
    levels: int | None = None,
    iterations: int | Sequence[int] | None = None,
    search_iterations: int | Sequence[int] | None = None,
    pyramid: Pyramid = "auto",
    gradient_weight: float = COMPLETION_GRADIENT_WEIGHT,
    diversity: float = 0.0,
    finest: Literal["vote", "copy"] = "vote",
    start: Literal["auto", "blocks"] = "auto",
    tileable: bool = False,
    seed: int | np.random.Generator = 0,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
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
    source_mask : (M, N) array_like of bool, optional
        Pixels patches may be copied from (default: every known pixel), as in
        :func:`phloem.patch.nnf`. A patch is a source only if all its pixels are known and in
        ``source_mask``; known pixels outside it still guide the matching as the hole's
        surroundings, but the coarsest level starts from the sources' median colour rather
        than from the rim. To fill a hole from another image, place both in one frame and pass
        the other image's region. When the box of the hole and the sources is at most 3/4 of
        the image, only that box (two patches wider) is worked on: the same fill quality from
        other random draws, in time that follows the box.
    patch_size : int, optional
        Patch side, odd (default 7).
    levels : int, optional
        Most pyramid levels (default: until the hole vanishes at the coarsest level).
    iterations : int or sequence of int, optional
        Search-and-vote iterations per level (default ``1 + 2·level``, level 0 the finest:
        one at full resolution, more on the cheap coarse levels). A sequence gives them per
        level, finest first, the coarser levels repeating its last entry; 0 at a level only
        votes the coarser level's field upsampled (a cheap schedule for large fills).
    search_iterations : int or sequence of int, optional
        PatchMatch iterations per search step (default ``min(7, 1 + level)``), per level like
        ``iterations``.
    pyramid : {"auto", "interpolate", "strict"}, optional
        How coarse levels treat pixels on the hole's rim. ``"interpolate"``: a coarse pixel is
        known as soon as one fine pixel under its kernel is (the shrinking hole above).
        ``"strict"``: only when all of them are (the hole grows); rim pixels are synthesised
        instead of interpolated from the few fine pixels they see, which keeps fine periodic
        structure in phase and a bright rim from bleeding into the fill. ``"auto"`` (default)
        runs both (strict from the third level on) and keeps the interpolating fill unless the
        strict one is far more coherent.
    gradient_weight : float, optional
        Weight of the gradients in the patch distance (default
        :data:`COMPLETION_GRADIENT_WEIGHT`; 0: values only, faster).
    diversity : float, optional
        Weight λ of Kaspar et al.'s occurrence penalty, as in :func:`synthesize` (default 0:
        Wexler's completion). A fill from few sources into a large hole settles on the
        smoothest source patches; a λ of 1 spreads it over more of them, at some coherence.
    finest : {"vote", "copy"}, optional
        How the full-resolution level's last step sets the hole: ``"vote"`` (default), the
        weighted mean of the overlapping matches (with mean-shift), Wexler's; ``"copy"``, each
        pixel the source pixel its own patch centre is matched to. Where the matches disagree
        (a stochastic texture: asphalt, leaf, terrain grain) the vote averages them into a
        smooth fill, the copy keeps the grain; where they agree both give the same pixels.
    start : {"auto", "blocks"}, optional
        What the coarsest level starts from. ``"auto"`` (default): the hole's rim peeled inward,
        or with ``source_mask`` the sources' median colour. ``"blocks"``: random ``patch_size``
        blocks copied from the sources, as texture synthesis starts, and the pyramid stops
        before a level whose hole has more than :data:`BLOCKS_MAX_REUSE` pixels per usable
        source patch. A flat start, or a coarse level with few sources, settles a large hole on
        a few source patches, which ``finest="copy"`` then repeats as a regular pattern; the
        blocks and the cap keep such a fill on many sources and a stochastic texture's grain.
    tileable : bool, optional
        Treat the image as a tile (default False): it is a torus whose opposite borders
        touch, so the hole may cross a border and continues on the other side, its context
        there is the opposite side, and source patches may straddle the borders too. The fill
        then tiles with the rest. (Fill a cross over the middle of a texture rolled by half
        its size to make it tileable.)
    seed : int or numpy.random.Generator, optional
        Seed (default 0); identical output for any thread count.
    threads : int, optional
        Worker threads.
    progress : callable, optional
        Called as ``progress(done, total)`` after every iteration.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

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
    p = check_patch_size(patch_size)
    pad = p // 2 if tileable else 0
    _memory.check_size(_memory.complete(img.shape, pad), max_memory, img.shape[:2], "image")
    hole = as_mask(mask, "mask", img.shape[:2])
    allowed = None if source_mask is None else as_mask(source_mask, "source_mask", img.shape[:2])
    if not hole.any():
        raise ValueError("mask: no pixel is selected for filling (the mask is empty)")
    if pyramid not in ("auto", "interpolate", "strict"):
        raise ValueError(f"pyramid: expected 'auto', 'interpolate' or 'strict', got {pyramid!r}")
    gw = check_float(gradient_weight, "gradient_weight", 0.0)
    lam = check_float(diversity, "diversity", 0.0)
    if finest not in ("vote", "copy"):
        raise ValueError(f"finest: expected 'vote' or 'copy', got {finest!r}")
    if start not in ("auto", "blocks"):
        raise ValueError(f"start: expected 'auto' or 'blocks', got {start!r}")
    reuse = BLOCKS_MAX_REUSE if start == "blocks" else None
    s = check_seed(seed)
    t = check_threads(threads)
    max_levels = None if levels is None else check_int(levels, "levels", 1)

    wrap = bool(tileable)
    if allowed is not None and not wrap:  # a box would cut the torus open
        ys, xs = np.nonzero(hole | allowed)
        m = _CROP_MARGIN * p
        y0, y1 = max(0, int(ys.min()) - m), min(img.shape[0], int(ys.max()) + 1 + m)
        x0, x1 = max(0, int(xs.min()) - m), min(img.shape[1], int(xs.max()) + 1 + m)
        if (y1 - y0) * (x1 - x0) <= _CROP_MAX_FRACTION * hole.size:
            box = (slice(y0, y1), slice(x0, x1))
            out = img.copy()
            out[box] = complete(
                img[box], hole[box], source_mask=allowed[box], patch_size=p, levels=levels, iterations=iterations,
                search_iterations=search_iterations, pyramid=pyramid, gradient_weight=gw, diversity=lam, finest=finest,
                start=start, seed=s, threads=t,
                progress=progress, max_memory=max_memory,
            )  # fmt: skip
            return restore_ndim(out, image)
    main = _hole_pyramid(
        img, hole, p, max_levels, allowed=allowed, strict_from=1 if pyramid == "strict" else None, wrap=wrap,
        max_reuse=reuse,
    )  # fmt: skip
    if not main[0][3].any():  # the full-resolution level's usable source centres
        where = "the known region" if allowed is None else "the known pixels in source_mask"
        raise ValueError(f"mask: {where} holds no complete {p}×{p} patch to copy from")
    alt = None
    if pyramid == "auto" and len(main) > _STRICT_FROM:
        # No deeper than the interpolating pyramid: the strict hole never vanishes, and its
        # extra levels would cost most of the time.
        alt = _hole_pyramid(
            img, hole, p, len(main), allowed=allowed, strict_from=_STRICT_FROM, wrap=wrap, max_reuse=reuse
        )
        if len(alt) <= _STRICT_FROM:
            alt = None
    n = max(len(main), len(alt) if alt is not None else 0)
    iters = _schedule(iterations, "iterations", n, lambda lv: 1 + 2 * lv, 0)
    search = _schedule(search_iterations, "search_iterations", n, lambda lv: min(7, 1 + lv), 1)
    # With restricted sources the hole's rim need not look like what fills it (a branch beside a
    # gap), so the coarsest level starts from the sources' median colour instead of the rim's.
    base = None if allowed is None else np.median(img[allowed & ~hole], axis=0).astype(np.float32)
    if start == "blocks":  # a coarsest level that starts from random blocks searches at least once
        iters[len(main) - 1] = max(1, iters[len(main) - 1])
    filler = _Filler(p, s, t, gw, progress, base, wrap, lam, finest == "copy", start == "blocks")
    # The alternative only has to show whether its fill is far better: one iteration less a level.
    alt_iters = [max(1, n - 1) for n in iters]
    filler.total = sum(iters[: len(main)]) + (sum(alt_iters[_STRICT_FROM : len(alt)]) if alt is not None else 0)
    if alt is None:
        cur, _ = filler.run(main, 0, iters, search)
    else:
        # Both pyramids down to the first level they share; there, the fill whose patches are
        # better explained by known ones continues.
        starts = []
        for pyr in (main, alt):
            _, field = filler.run(pyr, _STRICT_FROM, iters if pyr is main else alt_iters, search)
            cur1, up = filler.start(pyr[_STRICT_FROM - 1], field)
            starts.append((filler.energy(pyr[_STRICT_FROM - 1], cur1, up, _STRICT_FROM - 1), cur1, up))
        pick = 1 if starts[1][0] < _AUTO_ENERGY_RATIO * starts[0][0] else 0
        _, cur, field = starts[pick]
        lv = _STRICT_FROM - 1
        cur, new = filler.iterate(
            main[lv], lv, cur, field, iters[lv], search[lv], COMPLETION_MEAN_SHIFT if lv == 0 else 0
        )
        field = new if new is not None else field
        for lv in range(_STRICT_FROM - 2, -1, -1):
            cur, init = filler.start(main[lv], field, filler.copies_start(lv, iters[lv]))
            shift = COMPLETION_MEAN_SHIFT if lv == 0 else 0
            cur, new = filler.iterate(main[lv], lv, cur, init, iters[lv], search[lv], shift)
            field = new if new is not None else init
    out = img.copy()
    out[hole] = cur[hole]
    return restore_ndim(out, image)
