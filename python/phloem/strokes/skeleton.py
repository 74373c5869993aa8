"""Source strokes from a skeleton traced on the object (:func:`phloem.branching.trace`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..branching import Skeleton
from .stroke_set import Stroke, StrokeError

__all__ = ["strokes_from_skeleton"]


def strokes_from_skeleton(skeleton: Any, *, min_length: float = 0.0) -> list[Stroke]:
    """One stroke per branch of ``skeleton``, in its order, each child starting at the parent
    vertex it grows out of (so strokes meet at the junctions, as branching targets do).

    Parameters
    ----------
    skeleton : Skeleton
        E.g. ``phloem.branching.trace(mask, kind="mask")`` of the object's mask.
    min_length : float, optional
        Branches shorter than this (px) are left out (spurs of the trace); default keep all.

    Returns
    -------
    list of Stroke

    Raises
    ------
    StrokeError
        No branch as long as ``min_length``.
    """
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    if isinstance(min_length, bool) or not isinstance(min_length, (int, float)) or not min_length >= 0:
        raise ValueError(f"min_length: expected a length >= 0 in px, got {min_length!r}")
    out = []
    for b in skeleton.branches:
        pts = b.points
        if b.parent is not None:
            joint = skeleton.branches[b.parent[0]].points[b.parent[1]]
            if not np.array_equal(joint, pts[0]):
                pts = np.concatenate([joint[None, :], pts])
        stroke = Stroke(pts)
        if stroke.length() >= min_length:
            out.append(stroke)
    if not out:
        raise StrokeError(f"skeleton: no branch is at least {min_length:g} px long")
    return out
