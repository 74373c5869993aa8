"""Angle and thickness histograms of a branching structure: the statistics the paper compares
input and output by (Sibbing et al. 2010, §4.2 histogram matching and the Fig. 7 evaluation).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import check_int
from ._elements import F64, _bin, _check_skeleton, _range
from .skeleton import Skeleton

__all__ = ["angle_histogram", "histogram_distance", "thickness_histogram"]


def _all_angles(skeleton: Skeleton, h: float | None) -> F64:
    sk = skeleton.resample(h) if h is not None else skeleton
    parts = [b.angles() for b in sk.branches if len(b) >= 3]
    return np.concatenate(parts) if parts else np.zeros(0)


def _hist(values: F64, bins: int, range_: tuple[float, float] | None, name: str) -> tuple[F64, F64]:
    bins = check_int(bins, "bins", 1)
    if values.size == 0:
        raise ValueError(f"{name}: the skeleton has no values to histogram")
    lo, hi = _range(values) if range_ is None else (float(range_[0]), float(range_[1]))
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise ValueError(f"range: expected (low, high) with low < high, got {range_!r}")
    counts = np.bincount(_bin(values, lo, hi, bins), minlength=bins).astype(np.float64)
    return counts / counts.sum(), np.linspace(lo, hi, bins + 1)


def angle_histogram(
    skeleton: Skeleton, bins: int = 16, *, range: tuple[float, float] | None = None, h: float | None = None
) -> tuple[F64, F64]:
    """Normalised histogram of the turning angles of all branches (the paper's Fig. 7 evaluation).

    Parameters
    ----------
    skeleton : Skeleton
        The structure; resampled to step ``h`` first when ``h`` is given (angles only mean
        something for a fixed step).
    bins : int
        Number of bins (the paper uses 16).
    range : (float, float), optional
        Interval split into the bins; values outside go to the end bins. Defaults to the
        data's minimum and maximum; pass the input's range to compare two structures.
    h : float, optional
        Resampling step.

    Returns
    -------
    hist : ndarray of float64, shape (bins,)
        Fractions summing to 1.
    edges : ndarray of float64, shape (bins + 1,)

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[0, 0], [1, 0], [1, -1], [2, -1]], 1.0)])
    >>> hist, edges = angle_histogram(sk, bins=2)
    >>> hist.tolist(), edges.round(2).tolist()
    ([0.5, 0.5], [-1.57, 0.0, 1.57])
    """
    _check_skeleton(skeleton)
    return _hist(_all_angles(skeleton, h), bins, range, "skeleton")


def thickness_histogram(
    skeleton: Skeleton, bins: int = 16, *, range: tuple[float, float] | None = None, h: float | None = None
) -> tuple[F64, F64]:
    """Normalised histogram of the vertex thicknesses of all branches.

    Parameters and return values as in :func:`angle_histogram`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[0, 0], [1, 0], [2, 0]], [1.0, 2.0, 2.0])])
    >>> thickness_histogram(sk, bins=2)[0].tolist()
    [0.3333333333333333, 0.6666666666666666]
    """
    _check_skeleton(skeleton)
    sk = skeleton.resample(h) if h is not None else skeleton
    return _hist(np.concatenate([b.thickness for b in sk.branches]), bins, range, "skeleton")


def histogram_distance(a: Any, b: Any) -> float:
    """L1 distance of two histograms after normalising each to sum 1 (0 = equal, 2 = disjoint).

    Examples
    --------
    >>> histogram_distance([1, 1, 0], [0, 2, 2])
    1.0
    """
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError(f"a, b: expected two 1-D histograms of the same length, got {x.shape} and {y.shape}")
    if not (np.isfinite(x).all() and np.isfinite(y).all()) or (x < 0).any() or (y < 0).any():
        raise ValueError("a, b: histograms must be finite and non-negative")
    if x.sum() <= 0 or y.sum() <= 0:
        raise ValueError("a, b: histograms must not be all zero")
    return float(np.abs(x / x.sum() - y / y.sum()).sum())
