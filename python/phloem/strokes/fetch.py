"""Fetching source texture (Luo et al. §2): which source pixels belong to which stroke, where the
samples lie along the strokes, and the rigid, turned pieces the engine copies around them.

A piece is the source object around a source sample ``p'``, turned so that the source stroke's
direction at ``p'`` lies along the target stroke's at the target sample ``p``, and placed at
``p``: a rectangle of half length ``h`` (the sample spacing, so neighbouring pieces overlap by
half) and as wide across as the object is at ``p'``. Only the object pixels nearest this source
stroke are taken, so a leg's piece does not bring the body along.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .. import _core
from .stroke_set import Stroke, StrokePair

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

#: Smallest and largest automatic sample spacing, px.
SPACING_RANGE: Final = (4.0, 64.0)
#: A piece reaches across the stroke at most this many times the object's largest half width
#: along its source stroke (the march across stops at the object's edge well before).
REACH_FACTOR: Final = 3.0
#: A pixel belongs to every source stroke it is at most this much farther from (px) than from
#: the nearest one.
SHARE_TOLERANCE: Final = 1.0
#: Step of the dense points that stand for a stroke when object pixels are given to strokes.
_DENSE_STEP = 0.5


@dataclass(frozen=True)
class StrokeSource:
    """The part of the source object that belongs to one source stroke.

    Attributes
    ----------
    rgba : (h, w, 4) ndarray of float32
        The source image over the part's box, alpha zero off the part.
    offset : (x0, y0)
        Where the box lies in the source image.
    half_width : float
        The object's largest half width (distance to its edge) along the stroke, px.
    """

    rgba: F32
    offset: tuple[int, int]
    half_width: float


def _dense(stroke: Stroke) -> F64:
    n = max(2, int(np.ceil(stroke.length() / _DENSE_STEP)) + 1)
    return stroke.at(np.linspace(0.0, 1.0, n))


def _stroke_distance(stroke: Stroke, shape: tuple[int, int]) -> F32:
    """Distance in px from every pixel to the stroke (to its nearest pixel, rasterised)."""
    h, w = shape
    d = _dense(stroke)
    on = np.ones(shape, bool)
    xi, yi = np.rint(d[:, 0]).astype(int), np.rint(d[:, 1]).astype(int)
    keep = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    on[yi[keep], xi[keep]] = False
    return np.asarray(ndimage.distance_transform_edt(on), dtype=np.float32)


def shares(alpha: F32, strokes: list[Stroke]) -> list[NDArray[np.bool_]]:
    """For each source stroke, the object pixels (``alpha > 0``) that belong to it: those no
    more than :data:`SHARE_TOLERANCE` px farther from it than from the nearest stroke. Strokes
    drawn over one another (one branch of a photo used for several target branches) share
    their pixels instead of splitting them at random."""
    shape = (alpha.shape[0], alpha.shape[1])
    nearest = np.full(shape, np.inf, np.float32)
    for s in strokes:
        np.minimum(nearest, _stroke_distance(s, shape), out=nearest)
    obj = alpha > 0
    return [obj & (_stroke_distance(s, shape) <= nearest + SHARE_TOLERANCE) for s in strokes]


def stroke_sources(rgba: F32, strokes: list[Stroke]) -> list[StrokeSource]:
    """One :class:`StrokeSource` per stroke of ``strokes`` over the RGBA source ``rgba``."""
    alpha = rgba[..., 3]
    inside = np.pad(alpha >= 0.5, 1)
    dist = ndimage.distance_transform_edt(inside)[1:-1, 1:-1]
    h, w = alpha.shape
    out = []
    for s, mine in zip(strokes, shares(alpha, strokes), strict=True):
        d = _dense(s)
        xi = np.clip(np.rint(d[:, 0]).astype(int), 0, w - 1)
        yi = np.clip(np.rint(d[:, 1]).astype(int), 0, h - 1)
        half = float(dist[yi, xi].max())
        ys, xs = np.nonzero(mine)
        if len(ys) == 0:
            out.append(StrokeSource(np.zeros((1, 1, 4), np.float32), (0, 0), 0.0))
            continue
        # Two pixels of ring keep the bilinear sampling at the part's edge inside the box.
        y0, y1 = max(0, ys.min() - 2), min(h, ys.max() + 3)
        x0, x1 = max(0, xs.min() - 2), min(w, xs.max() + 3)
        part = rgba[y0:y1, x0:x1].copy()
        part[..., 3] *= mine[y0:y1, x0:x1]
        out.append(StrokeSource(np.ascontiguousarray(part), (int(x0), int(y0)), half))
    return out


def specs(
    pair: StrokePair,
    target_arc: F64,
    source_arc: F64,
    part: StrokeSource,
    half_length: F64,
) -> F64:
    """The engine's piece rows (``_core.stroke_pieces``) for target samples at ``target_arc``
    taking their pieces at ``source_arc`` (px along each stroke), in ``part``'s frame; with
    the pair's wanted width, if it has one, as the pieces' target half width."""
    target, source = pair.target, pair.source
    tl, sl = target.length(), source.length()
    tp = target.at(np.asarray(target_arc) / tl)
    sp = source.at(np.asarray(source_arc) / sl) - np.asarray(part.offset, np.float64)
    # Directions over the piece's own length, so a piece follows the stroke at its scale.
    half = float(np.median(half_length))
    tt = target.directions(np.asarray(target_arc, np.float64) / tl, half=half)
    st = source.directions(np.asarray(source_arc, np.float64) / sl, half=half)
    reach = np.full(len(tp), REACH_FACTOR * part.half_width + 1.0)
    u = np.asarray(target_arc, np.float64) / tl
    width = pair.width_at(u)
    wanted, slope = np.zeros(len(tp)), np.zeros(len(tp))
    if width is not None and pair.width is not None:
        wanted = 0.5 * width
        # The half width's change per px of target arc: the profile's segment at each sample.
        knots = pair.width[:, 0]
        seg = np.clip(np.searchsorted(knots, u, side="right") - 1, 0, max(0, len(knots) - 2))
        if len(knots) > 1:
            inside = (u >= knots[0]) & (u < knots[-1])
            rate = np.diff(pair.width[:, 1]) / np.diff(knots)
            slope = np.where(inside, 0.5 * rate[seg] / tl, 0.0)
    rows = [tp, tt, sp, st, half_length, reach, wanted, slope]
    return np.ascontiguousarray(np.column_stack(rows), dtype=np.float64)


@dataclass(frozen=True)
class Piece:
    """A fetched piece in the target frame.

    Attributes
    ----------
    offset : (x0, y0)
        The box's top-left pixel in the target frame (may lie outside it).
    rgba : (h, w, 4) ndarray of float32
        Colours and alpha, zero off the support.
    support : (h, w) ndarray of bool
        The piece's pixels.
    widths : (float, float)
        The object's reach to either side of the source stroke at the sample, margin included.
    """

    offset: tuple[int, int]
    rgba: F32
    support: NDArray[np.bool_]
    widths: tuple[float, float]


def fetch(part: StrokeSource, rows: F64, *, threads: int | None) -> list[Piece]:
    """The pieces of ``rows`` (from :func:`specs`) cut from ``part``."""
    out = _core.stroke_pieces(part.rgba, rows, threads=threads)
    return [Piece((int(x0), int(y0)), rgba, sup, widths) for (y0, x0), rgba, sup, widths in out]


def pair_energies(part: StrokeSource, rows: F64, pairs: NDArray[np.int64], *, threads: int | None) -> F64:
    """The compositing energy (Eqs. 1–2) of each pair of the pieces ``rows``."""
    if len(pairs) == 0:
        return np.zeros(0)
    return np.asarray(
        _core.stroke_pair_energies(part.rgba, rows, np.ascontiguousarray(pairs, np.int64), threads=threads)
    )


def default_spacing(parts: list[StrokeSource], wanted: list[float | None] | None = None) -> float:
    """The sample spacing when none is given: the median over strokes of the object's half
    width along them (``wanted[i]``, the half width asked of stroke ``i``'s target, where not
    None), within :data:`SPACING_RANGE` (a piece is then about as long as the object is wide)."""
    asked = wanted if wanted is not None else [None] * len(parts)
    widths = [p.half_width if w is None else w for p, w in zip(parts, asked, strict=True) if p.half_width > 0]
    h = float(np.median(widths)) if widths else SPACING_RANGE[0]
    return float(np.clip(h, *SPACING_RANGE))
