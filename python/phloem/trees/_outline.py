"""Outline geometry shared by the :mod:`phloem.trees` modules.

Equal-chord resampling of polylines (§4.5), the longest exterior contour of a mask (§4.2) and
the dilated outline that the simplified contours and the cages sample (§4.6).
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ._checks import F64, Mask


def screen_area(p: F64) -> float:
    """Signed shoelace area of a closed polygon, positive when it runs counter-clockwise on screen."""
    x, y = p[:, 0], p[:, 1]
    return float(-0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def longest_exterior(mask: Mask) -> F64:
    """The longest exterior contour of ``mask``, counter-clockwise on screen (see :func:`phloem.trees.contour`)."""
    if not mask.any():
        raise ValueError("alpha: expected some opaque pixels, the mask is empty")
    found, hierarchy = cv2.findContours(mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    exterior = [c for c, h in zip(found, hierarchy[0], strict=True) if h[3] < 0]
    best = max(exterior, key=lambda c: cv2.arcLength(c, True))
    pts = best[:, 0, :].astype(np.float64)
    if len(pts) > 2 and screen_area(pts) < 0:
        pts = np.ascontiguousarray(pts[::-1])
    return pts


def _chord_walk(seg: F64, cum: list[float], count: int, step: float) -> list[float]:
    """Arc-length positions of points at chord distance ``step`` from each other along the
    polyline ``seg`` (``cum`` its cumulative arc length), at most ``count`` of them."""
    xs, ys = seg[:, 0].tolist(), seg[:, 1].tolist()
    px, py = xs[0], ys[0]
    out = [0.0]
    i, m, s2 = 1, len(xs), step * step
    while len(out) < count and i < m:
        qx, qy = xs[i], ys[i]
        if (qx - px) ** 2 + (qy - py) ** 2 < s2:
            i += 1
            continue
        # The circle of radius `step` around p leaves the polyline on segment (i-1, i): take the
        # larger root of |a + t d - p| = step, the crossing ahead of p.
        ax, ay = xs[i - 1], ys[i - 1]
        dx, dy, fx, fy = qx - ax, qy - ay, ax - px, ay - py
        qa = dx * dx + dy * dy
        qb = 2 * (fx * dx + fy * dy)
        qc = fx * fx + fy * fy - s2
        tt = (-qb + math.sqrt(max(qb * qb - 4 * qa * qc, 0.0))) / (2 * qa) if qa > 0 else 1.0
        tt = min(max(tt, 0.0), 1.0)
        px, py = ax + tt * dx, ay + tt * dy
        out.append(cum[i - 1] + tt * (cum[i] - cum[i - 1]))
    return out


def points_at(seg: F64, cum: F64, u: Any) -> F64:
    return np.stack([np.interp(u, cum, seg[:, 0]), np.interp(u, cum, seg[:, 1])], axis=1)


def equal_chords(seg: F64, count: int) -> F64:
    """``count`` points from ``seg[0]`` on with equal chords; the end point ``seg[-1]`` excluded.

    Bisection finds the smallest chord length that fits only ``count`` steps into the polyline,
    so the last gap (to the end point, the next segment's first sample) is close to the others.
    Where a jagged polyline makes the count jump past ``count`` (a chord skipping a narrow
    spike), the missing points go to the arc-length middles of the longest gaps.
    """
    cum = np.concatenate([[0.0], np.cumsum(np.sqrt((np.diff(seg, axis=0) ** 2).sum(axis=1)))])
    total = float(cum[-1])
    if total == 0 or count == 1:
        return points_at(seg, cum, np.arange(count) * (total / count))
    cl = cum.tolist()
    lo, hi = 0.0, total / count * 1.0000001
    # hi must make the walk reach the end with at most `count` points: widen until it does.
    for _ in range(60):
        if len(_chord_walk(seg, cl, count + 1, hi)) <= count:
            break
        lo, hi = hi, hi * 1.5
    # Chords are barely shorter than arcs on a contour, so the answer is usually within 20 % of
    # hi: bracket it there first (half the bisection steps), else keep the whole interval.
    if lo == 0.0 and len(_chord_walk(seg, cl, count + 1, 0.8 * hi)) > count:
        lo = 0.8 * hi
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        if len(_chord_walk(seg, cl, count + 1, mid)) <= count:
            hi = mid
        else:
            lo = mid
    u = _chord_walk(seg, cl, count, hi)
    while len(u) < count:
        ends = [*u[1:], total]
        k = int(np.argmax(np.subtract(ends, u)))
        u.insert(k + 1, 0.5 * (u[k] + ends[k]))
    return points_at(seg, cum, np.asarray(u))


def simplify_outline(c: F64, m: int) -> F64:
    """``m`` points of equal chord along a closed outline, from its lowest point."""
    start = int(np.argmax(c[:, 1] + 1e-6 * np.abs(c[:, 0] - c[:, 0].mean()) * -1))
    loop = np.concatenate([c[start:], c[:start], c[start : start + 1]])
    return equal_chords(loop, m)


def dilated_outline(mask: Mask, dilation: int) -> F64:
    """The longest exterior contour of ``mask`` dilated ``dilation`` times by a 3 x 3 square
    (one dilation by a square of side ``2 dilation + 1``)."""
    u8: NDArray[Any] = mask.astype(np.uint8)
    if dilation:
        u8 = cv2.copyMakeBorder(u8, dilation, dilation, dilation, dilation, cv2.BORDER_CONSTANT, value=0)
        u8 = cv2.dilate(u8, np.ones((2 * dilation + 1, 2 * dilation + 1), np.uint8))
    return longest_exterior(np.asarray(u8) > 0) - dilation
