"""Small helpers the image-side modules (fragments, render, gaps, rectify) share: the skeleton
check, row-wise masked copies, per-channel clipping, rotations, sub-pixel line coordinates and
the modified z-score that finds outliers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .skeleton import Skeleton

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]


def _check_skeleton(skeleton: Any, name: str, shape: tuple[int, int] | None) -> Skeleton:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"{name}: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    if not skeleton.branches:
        raise ValueError(f"{name}: the skeleton has no branches")
    for i, b in enumerate(skeleton.branches):
        if not (np.isfinite(b.points).all() and np.isfinite(b.thickness).all()):
            raise ValueError(f"{name}: branches[{i}] has NaN or infinite points or thickness")
    if shape is not None:
        skeleton.check_inside(shape, name)
    return skeleton


def _by_channels(fn: Callable[[Any], Any], img: NDArray[Any]) -> NDArray[Any]:
    """``fn(img)`` for an (H, W, C) image with any ``C``, keeping the channel axis.

    Some OpenCV functions (``resize`` with ``INTER_AREA``; ``remap`` and ``warpPerspective`` in
    some versions) take at most 4 channels, so wider images go through in chunks of 4.
    """
    c = img.shape[2]
    parts = [img] if c <= 4 else [np.ascontiguousarray(img[..., i : i + 4]) for i in range(0, c, 4)]
    outs = []
    for part in parts:
        out = np.asarray(fn(part))
        outs.append(out.reshape(*out.shape[:2], part.shape[2]))  # OpenCV drops a single channel
    return outs[0] if len(outs) == 1 else np.concatenate(outs, axis=2)


def _clip_channels(x: F32, lo: F32, hi: F32) -> F32:
    """Clip each channel of ``x`` (H, W, C) to ``[lo[c], hi[c]]`` in place, one channel at a time
    (one ``np.clip`` with ``(C,)`` bounds runs its inner loop over the channels: much slower)."""
    for c in range(x.shape[2]):
        np.clip(x[..., c], lo[c], hi[c], out=x[..., c])
    return x


def _paste(dst: F32, src: F32, mask: NDArray[np.bool_]) -> None:
    """``dst[mask] = src[mask]`` for (H, W, C) images, in place (``dst`` may be a view).

    OpenCV's masked copy takes one mask for all channels and releases the GIL: several times
    faster than NumPy's ``copyto`` through a mask repeated over the channels.
    """
    m = np.asarray(mask, dtype=bool)
    out = cv2.copyTo(np.asarray(src, dtype=dst.dtype), m.view(np.uint8), dst)
    if out is not dst:  # OpenCV could not write through this view: copy its result back
        np.copyto(dst, out.reshape(dst.shape))


def _rot(theta: float) -> F64:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _pt(p: F64) -> tuple[int, int]:
    return round(p[0] * 16), round(p[1] * 16)


def _robust_z(v: NDArray[Any], floor: Any = 0.0) -> NDArray[Any]:
    """The modified z-score ``(v − median) / (1.4826 MAD)`` along the first axis, the MAD at
    least ``floor`` (Iglewicz and Hoaglin: robust to the outliers it is meant to find)."""
    mid = np.median(v, axis=0)
    spread = np.maximum(1.4826 * np.median(np.abs(v - mid), axis=0), floor)
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero spread: any excess is an outlier
        z: NDArray[Any] = (v - mid) / spread
    return z


#: A soft mask (a mask anti-aliased, scaled or saved as a JPEG): at least this share of its
#: pixels within :data:`SOFT_TOLERANCE` of the channel range from a level in every channel...
SOFT_NEAR = 0.5
SOFT_TOLERANCE = 0.1
#: ... and at least this share of the others on a transition between the levels: within 2 px
#: of pixels near each level (an edge), or, in a piece of at least :data:`SOFT_LINE` such
#: pixels, beside a pixel near a level with a step of :data:`SOFT_STEP` of the range to a
#: neighbour (a channel thinner than a pixel once scaled down, grey where it covers part of
#: one). Not shading: a photo of thin bright structure on a black sky has its glow away from
#: both levels and smooth; and not specks of noise.
SOFT_EDGES = 0.8
SOFT_STEP = 0.25
SOFT_LINE = 6


def two_level(img: F32, lo: F32, hi: F32) -> bool:
    """Whether ``img`` is a mask: at least 95 % of its pixels at their channels' minimum or
    maximum, or a soft mask (:data:`SOFT_NEAR`, :data:`SOFT_EDGES`)."""
    H, W = img.shape[:2]
    need = 0.95 * H * W
    at: NDArray[np.bool_] | None = None
    # Channel by channel: a photo fails on its first channel, without a pass over the others.
    for c in range(img.shape[2]):
        ch = img[..., c]
        here = (ch == lo[c]) | (ch == hi[c])
        at = here if at is None else np.logical_and(at, here, out=at)
        if np.count_nonzero(at) < need:
            return _soft_two_level(img, lo, hi)
    return True


def _soft_two_level(img: F32, lo: F32, hi: F32) -> bool:
    """Whether ``img`` is a soft mask: :data:`SOFT_NEAR` of its pixels near one of the two levels
    in every channel, and :data:`SOFT_EDGES` of the rest on a transition between the two."""
    H, W = img.shape[:2]
    tol = SOFT_TOLERANCE * np.maximum(hi - lo, 1e-12)
    near_lo = np.ones((H, W), bool)
    near_hi = np.ones((H, W), bool)
    for c in range(img.shape[2]):
        ch = img[..., c]
        near_lo &= ch <= lo[c] + tol[c]
        near_hi &= ch >= hi[c] - tol[c]
        if np.count_nonzero(near_lo | near_hi) < SOFT_NEAR * H * W:
            return False
    rest = ~(near_lo | near_hi)
    if not rest.any():
        return bool(near_lo.any() and near_hi.any())
    need = SOFT_EDGES * np.count_nonzero(rest)
    k = np.ones((5, 5), np.uint8)
    edge = (cv2.dilate(near_lo.view(np.uint8), k) > 0) & (cv2.dilate(near_hi.view(np.uint8), k) > 0)
    if np.count_nonzero(rest & edge) >= need:
        return True
    k3 = np.ones((3, 3), np.uint8)
    beside = cv2.dilate((near_lo | near_hi).view(np.uint8), k3) > 0
    if np.count_nonzero(rest & (edge | beside)) < need:  # a photo's shading: the costlier tests cannot help
        return False
    step = np.zeros((H, W), bool)
    for c in range(img.shape[2]):
        ch = np.ascontiguousarray(img[..., c])
        s = SOFT_STEP * max(float(hi[c] - lo[c]), 1e-12)
        step |= (cv2.dilate(ch, k3) - ch >= s) | (ch - cv2.erode(ch, k3) >= s)
    # a line, not a speck: noise on a mask leaves isolated in-between pixels
    _, labels, stats, _ = cv2.connectedComponentsWithStats(rest.view(np.uint8), connectivity=8)
    line = (stats[:, cv2.CC_STAT_AREA] >= SOFT_LINE)[labels]
    return bool(np.count_nonzero(rest & (edge | (step & beside & line))) >= need)
