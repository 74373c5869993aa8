"""Per-vertex elements of uniformly resampled branches (Sibbing et al. 2010, §4.1), shared by the
statistical models: the turning angles ``α_i`` and thicknesses ``r_i``, the paper's ``dist``,
histogram binning, headings, and the argument check of the model-fitting functions.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._validate import check_int
from .skeleton import MAX_VERTICES, Branch, Skeleton

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def _check_skeleton(skeleton: Any, name: str = "skeleton") -> Skeleton:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"{name}: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    if not skeleton.branches:
        raise ValueError(f"{name}: the skeleton has no branches")
    return skeleton


def _smooth_path(pts: F64, sigma: float) -> F64:
    """Gaussian smoothing along a polyline, point-reflected at the ends so the ends stay put.

    ``sigma`` is in vertices; one wider than the polyline is taken as wide as it (the kernel,
    4 ``sigma`` each side, would otherwise grow without bound for no different result).
    """
    from scipy import ndimage  # type: ignore[import-untyped]

    if sigma <= 0 or len(pts) < 3:
        return pts
    sigma = min(sigma, float(len(pts)))
    pad = min(len(pts) - 1, math.ceil(3 * sigma))
    head = 2 * pts[0] - pts[pad:0:-1]
    tail = 2 * pts[-1] - pts[-2 : -pad - 2 : -1]
    ext = np.vstack([head, pts, tail])
    sm = ndimage.gaussian_filter1d(ext, sigma, axis=0, mode="nearest")[pad : pad + len(pts)]
    sm[0] = pts[0]
    return np.asarray(sm, dtype=np.float64)


def _denoised(skeleton: Skeleton, sigma: float, h: float) -> Skeleton:
    """``skeleton`` resampled finely with each branch's points smoothed by a Gaussian of ``sigma``
    px along it, for resampling at ``h`` after; ``skeleton`` itself for ``sigma = 0``. A branch
    keeps its first point, so a child still starts where it did, within a pixel of its smoothed
    parent."""
    if sigma <= 0:
        return skeleton
    # 1 px (or h, if finer), unless that passes the vertex limit where h does not: the limit's
    # error then names the h the caller chose
    step = min(1.0, h)
    if skeleton.vertex_bound(step) > MAX_VERTICES:
        step = h
    fine = skeleton.resample(step)
    hi = None if fine.shape is None else [fine.shape[1] - 1, fine.shape[0] - 1]
    branches = []
    for b in fine.branches:
        pts = _smooth_path(b.points, sigma / step)
        if hi is not None:  # the end reflection can push a bent end a little outside the picture
            np.clip(pts, 0.0, hi, out=pts)
        branches.append(replace(b, points=pts))
    return replace(fine, branches=branches)


def _dist(x: F64, y: F64) -> F64:
    """The paper's ``dist(X, Y) = 1 / (||X - Y|| + 1) + 1`` along the last axis (> 1, no singularity)."""
    return np.asarray(1.0 / (np.linalg.norm(x - y, axis=-1) + 1.0) + 1.0, dtype=np.float64)


def _dist_columns(cols: F64, y: F64) -> F64:
    """:func:`_dist` of each column of ``cols`` ``(L, C)`` against ``y`` ``(L,)``, to the bit.

    The squares are summed row by row, in the order ``np.linalg.norm`` sums a row of length
    ``L < 8``, in one pass over the candidates (``phloem_core::bending``).
    """
    return _core.dist_columns(np.ascontiguousarray(cols, np.float64), np.ascontiguousarray(y, np.float64))


def _elements(branch: Branch) -> tuple[F64, F64]:
    """The per-vertex elements ``(α_i, r_i)`` at the interior vertices of a resampled branch."""
    if len(branch) < 3:
        return np.zeros(0), np.zeros(0)
    return branch.angles(), branch.thickness[1:-1].copy()


def _arc_lengths(branch: Branch) -> F64:
    """The arc length from ``branch``'s first vertex to each of its vertices, px."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(branch.points, axis=0), axis=1))])


def _dense(branch: Branch, spacing: float) -> tuple[F64, F64, F64]:
    """Points, thicknesses and arc positions along ``branch`` at most ``spacing`` px apart (ends included)."""
    cum = _arc_lengths(branch)
    n = max(2, math.ceil(cum[-1] / spacing) + 1)
    s = np.linspace(0.0, float(cum[-1]), n)
    pts = np.stack([np.interp(s, cum, branch.points[:, 0]), np.interp(s, cum, branch.points[:, 1])], axis=1)
    return pts, np.interp(s, cum, branch.thickness), s


def _free_ends(branch: Branch) -> list[int]:
    """The vertices where ``branch`` ends free: its last, and its first where it is a root
    (a child starts on its parent)."""
    n = len(branch.points) - 1
    return [n] if branch.parent is not None else [0, n]


def _tree_roots(skeleton: Skeleton) -> list[int]:
    """The index of each branch's root branch (parents come before their children)."""
    root: list[int] = []
    for i, b in enumerate(skeleton.branches):
        root.append(i if b.parent is None else root[b.parent[0]])
    return root


def _generations(skeleton: Skeleton) -> list[int]:
    gen: list[int] = []
    for b in skeleton.branches:
        gen.append(0 if b.parent is None else gen[b.parent[0]] + 1)
    return gen


def _bin(values: F64, lo: float, hi: float, bins: int) -> I64:
    t = (values - lo) / (hi - lo) * bins
    # fmax / fmin ignore NaN: a NaN goes to bin 0, infinities to the end bins
    return np.fmin(np.fmax(np.floor(t), 0), bins - 1).astype(np.int64)


def _edge_headings(points: F64) -> F64:
    """The heading on the image of every edge of a polyline (radians, counter-clockwise on screen)."""
    d = np.diff(np.asarray(points, np.float64), axis=0)
    return np.asarray(np.arctan2(-d[:, 1], d[:, 0]), dtype=np.float64)


def _axis_bins(theta: F64, bins: int) -> I64:
    """Bins of headings as axes (a heading and its reverse in one bin) on ``[0, π)``, centred on
    ``0, π / bins, …``: a run along one of the image's axes that jitters stays in one bin."""
    half = math.pi / (2 * bins)
    return _bin(np.mod(np.asarray(theta, np.float64) + half, math.pi), 0.0, math.pi, bins)


def _range(values: F64) -> tuple[float, float]:
    lo, hi = float(values.min()), float(values.max())
    if hi - lo < 1e-12:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def _direction(theta: float | F64) -> F64:
    """Unit step for a heading counter-clockwise on screen (``y`` grows downwards)."""
    t = np.asarray(theta, dtype=np.float64)
    return np.stack([np.cos(t), -np.sin(t)], axis=-1)


def _wrap(a: float) -> float:
    return float(math.pi - (math.pi - a) % (2 * math.pi))


def _mod_2pi(x: F64) -> F64:
    """``x % 2π`` to the bit, in half the time of NumPy's float ``%`` (``fmod`` moved into ``[0, 2π)``)."""
    r = np.fmod(np.asarray(x, np.float64), 2 * math.pi)
    return np.asarray(r + np.where(r < 0, 2 * math.pi, 0.0), dtype=np.float64)


def _abs_turn(turn: F64) -> F64:
    """Absolute heading changes, wrapped to ``[0, π]``."""
    return np.asarray(np.abs(math.pi - _mod_2pi(math.pi - np.asarray(turn, np.float64))), dtype=np.float64)


def _check_k(k: Any) -> int:
    return check_int(k, "k", 1)


def _tangent(branch: Branch, v: int) -> float:
    """Heading of the branch at vertex ``v`` (mean of the adjacent edge directions)."""
    p = branch.points
    i0, i1 = max(v - 1, 0), min(v + 1, len(p) - 1)
    d = p[i1] - p[i0]
    return float(math.atan2(-d[1], d[0]))


#: Vertices at a branch's end over which ``BendingModel.end_taper`` is measured; the
#: ``_TAPER_LEVEL`` vertices before them give the thickness the end tapers from.
TAPER_VERTICES = 10
_TAPER_LEVEL = 6
#: An end vertex at least this share of the level (median over the input's branches) does
#: not taper: a traced photo's thickness estimate stays level to the tip.
_TAPER_MIN = 0.95


def _end_taper(source: Skeleton) -> F64:
    """The thickness at a skeleton's branch ends over the level before them (``end_taper``).

    Per vertex from ``TAPER_VERTICES`` before the end to the end, the median over the
    branches long enough to have a level (``TAPER_VERTICES + _TAPER_LEVEL`` vertices, at
    least three of them) of its thickness over the median of the ``_TAPER_LEVEL`` before;
    capped at 1 and cut to the vertices after the last one at ``_TAPER_MIN`` or more.
    Empty where the ends do not taper.
    """
    need = TAPER_VERTICES + _TAPER_LEVEL
    rows = []
    for b in source.branches:
        if len(b) >= need:
            t = np.asarray(b.thickness, np.float64)
            level = float(np.median(t[-need:-TAPER_VERTICES]))
            if level > 0:
                rows.append(t[-TAPER_VERTICES:] / level)
    if len(rows) < 3:
        return np.zeros(0)
    ratio = np.minimum(np.median(np.vstack(rows), axis=0), 1.0)
    # the tapered run is the one that ends at the tip
    kept = np.flatnonzero(ratio >= _TAPER_MIN)
    first = 0 if not len(kept) else int(kept[-1]) + 1
    return np.asarray(ratio[first:], np.float64)
