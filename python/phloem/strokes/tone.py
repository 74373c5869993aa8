"""Tone matching at junctions: a branch's colours meet its parent's.

Pieces of one stroke come from neighbouring parts of the source and agree in tone; where a
stroke branches off another (its end point lies on the other's object) the two may come from
parts of the object lit or coloured differently, and the graph cut can only choose where the
step falls, not remove it. So the branch's part of the result near the junction takes a smooth
colour correction: at the seam, the difference of the two sides' local mean colours (a Gaussian
window, so the texture itself is not matched pixel by pixel); fading to zero :data:`REACH` half widths
into the branch; in between the smoothest field (:func:`phloem.blend.interpolate_field`,
free at the object's outline). The texture's gradients are kept, as in Poisson pasting with
the source's guidance field; only the low frequencies move. Strokes that merely cross keep
the cut's colours: two parts of an object that overlap need not share their light.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .. import blend

F32 = NDArray[np.float32]

#: How far into the branch the correction reaches, in its half widths.
REACH = 2.0


def match_seams(
    rgba: F32,
    stroke_of: NDArray[np.int64],
    half_widths: NDArray[np.float64],
    ends: NDArray[np.float64],
    *,
    threads: int | None,
) -> F32:
    """``rgba`` with each stroke's colours matched to its parent's near their junctions.

    ``stroke_of`` is the (H, W) stroke index of each pixel (-1 where none), ``half_widths[s]``
    stroke ``s``'s typical half width in px and ``ends[s]`` its (2, 2) ``(x, y)`` end points.
    An end point of stroke ``s`` on a pixel of an earlier stroke ``p`` is a junction; the seam
    between the two within two of ``p``'s half widths of it is matched. Alpha is unchanged;
    colours stay in [0, 1]."""
    out: F32 = np.array(rgba, np.float32)
    four = ndimage.generate_binary_structure(2, 1)
    h, w = stroke_of.shape
    for s in range(1, len(ends)):
        joins = []
        for x, y in ends[s]:
            xi, yi = round(x), round(y)
            if 0 <= yi < h and 0 <= xi < w and 0 <= stroke_of[yi, xi] < s:
                joins.append((x, y, 2.0 * float(half_widths[stroke_of[yi, xi]])))
        if not joins:
            continue
        reach = max(2.0, REACH * float(half_widths[s]))
        # Everything happens within the junctions' seams plus the reach and the mean's window.
        m = max(r for _, _, r in joins) + reach + 3 * _sigma(reach) + 2
        y0, y1 = max(0, int(min(y for _, y, _ in joins) - m)), min(h, int(max(y for _, y, _ in joins) + m) + 1)
        x0, x1 = max(0, int(min(x for x, _, _ in joins) - m)), min(w, int(max(x for x, _, _ in joins) + m) + 1)
        box = (slice(y0, y1), slice(x0, x1))
        of = stroke_of[box]
        mine, before = of == s, (of >= 0) & (of < s)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        near = np.zeros(of.shape, bool)
        for x, y, r in joins:
            near |= (xx - x) ** 2 + (yy - y) ** 2 <= r**2
        seam = mine & near & ndimage.binary_dilation(before, structure=four)
        if not seam.any():
            continue
        band = mine & (ndimage.distance_transform_edt(~seam) <= reach)
        parts, _ = ndimage.label(band, structure=four)
        touched = np.unique(parts[seam])
        band = np.isin(parts, touched[touched > 0])
        end = band & ~seam & ndimage.binary_dilation(mine & ~band, structure=four)
        view = out[box]
        diff = _mean(view[..., :3], before, reach) - _mean(view[..., :3], mine, reach)
        sy, sx = np.nonzero(seam)
        ey, ex = np.nonzero(end)
        points = np.concatenate([np.c_[sy, sx], np.c_[ey, ex]]).astype(np.int64)
        values = np.concatenate([diff[sy, sx], np.zeros((len(ey), 3), np.float32)])
        # A colour correction needs no more than 1e-4 of its size: far below one 8-bit level.
        field = blend.interpolate_field(band, points, values, tol=1e-4, threads=threads)
        view[..., :3][band] = np.clip(view[..., :3][band] + field[band], 0.0, 1.0)
    return out


def _sigma(reach: float) -> float:
    return max(1.5, reach / 6.0)


def _mean(rgb: F32, where: NDArray[np.bool_], reach: float) -> F32:
    """The Gaussian-weighted mean colour of ``rgb`` over ``where`` around every pixel."""
    sigma = _sigma(reach)
    wf = where.astype(np.float32)
    w = cv2.GaussianBlur(wf, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
    acc = cv2.GaussianBlur(np.ascontiguousarray(rgb * wf[..., None]), (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
    return (acc / np.maximum(w, 1e-6)[..., None]).astype(np.float32)
