"""Branch ends that run on into other structure, as often as the input's (beyond the paper).

The paper's growth (§4) makes trees: a branch stops where the density or a crossing stops it,
a few pixels short of the structure ahead. In a braided river, a delta or a crack network many
branches end *on* other structure instead: the channels part and rejoin round islands, and the
trace cuts each such loop open at one end. :func:`join_ends` carries grown ends that stopped
short of structure ahead on to it, shortest way first, until as large a share of the branches
end on structure as in the input (:func:`~phloem.branching.measures.joined_end_share`).
Measured in ``docs/pipelines/branching/quality.md`` ("Fiftieth session").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validate import as_mask, check_float
from ._elements import F64, _arc_lengths, _check_skeleton
from ._ends import _end_slack, _Lines, _on_structure, _others
from .skeleton import Branch, Skeleton

__all__ = ["JOIN_CONE", "join_ends"]

#: Half-angle of the cone ahead of an end in which it may join structure, radians: a branch
#: carries on roughly the way it was heading, as the input's rejoining channels do.
JOIN_CONE = math.radians(60.0)


def join_ends(
    skeleton: Skeleton,
    share: float,
    *,
    reach: float,
    step: float,
    domain: Any = None,
) -> Skeleton:
    """Carry branch ends on to structure ahead until ``share`` of the branches end on it.

    An end that is not yet on other structure (as :func:`~phloem.branching.measures.joined_end_share`
    counts it) may join the nearest surface of other structure within ``reach`` px and within
    :data:`JOIN_CONE` of its heading, along a cubic Hermite curve that leaves in the branch's
    heading and meets the other branch's centre line. A way that crosses other structure on
    the way, or leaves the image or ``domain``, is not taken, nor one that would run within
    the two thicknesses of a way already taken. The shortest ways are taken first, one per
    end missing from the share (a way can bring another end onto structure too, so the share
    reached can be a little over). The extension keeps the end's thickness and is resampled
    to ``step`` (its last edge, onto the centre line, may be shorter). The branches' order and
    attachments stay as they were: a joined branch is still a tree's branch, whose last vertex
    lies on another.

    Parameters
    ----------
    skeleton : Skeleton
        The grown structure; it is not modified.
    share : float
        The share of branches that should end on other structure, in ``[0, 1]`` (the input's
        :func:`~phloem.branching.measures.joined_end_share`). Nothing changes where the
        skeleton already has that share.
    reach : float
        How far an end may be carried, px (:func:`~phloem.branching.grow` uses the density's
        look-ahead, ``3 m h``).
    step : float
        Edge length of the extensions, px (the bending model's ``h``).
    domain : (H, W) array_like of bool, optional
        Where the structure may lie (default: the whole image of ``skeleton.shape``).

    Returns
    -------
    Skeleton

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> from phloem.metrics import joined_end_share
    >>> stem = Branch([[10, 50], [60, 50], [190, 50]], 3.0)
    >>> side = Branch([[60, 50], [75, 30], [100, 30], [112, 40]], 2.0, parent=(0, 1))
    >>> sk = Skeleton([stem, side], (100, 200))
    >>> joined = join_ends(sk, 0.5, reach=40.0, step=2.0)
    >>> joined_end_share(sk), joined_end_share(joined)
    (0.0, 0.5)
    >>> bool(abs(joined.branches[1].points[-1, 1] - 50) < 3)
    True
    """
    _check_skeleton(skeleton)
    share = check_float(share, "share", 0.0)
    if share > 1:
        raise ValueError(f"share: expected a share in [0, 1], got {share}")
    reach = check_float(reach, "reach", 0.0, inclusive=False)
    step = check_float(step, "step", 0.0, inclusive=False)
    if skeleton.shape is None:
        raise ValueError("skeleton: has no shape; join_ends keeps the structure inside its image")
    inside = None if domain is None else as_mask(domain, "domain", skeleton.shape)
    n = len(skeleton.branches)
    lines = _Lines.of(skeleton)
    on = _on_structure(skeleton, lines)
    need = round(share * n) - int(on.sum())
    if need <= 0:
        return skeleton
    ways = []
    for free in np.flatnonzero(~on).tolist():
        way = _way_on(skeleton, lines, free, reach, inside)
        if way is not None:
            ways.append((float(np.linalg.norm(np.diff(way, axis=0), axis=1).sum()), free, way))
    ways.sort(key=lambda w: (w[0], w[1]))
    branches = list(skeleton.branches)
    taken: list[tuple[F64, float]] = []  # the ways joined so far, with their thickness
    for _, i, way in ways:
        if need <= 0:
            break
        r = float(branches[i].thickness[-1])
        if any(_too_close(way[:-1], w, r + rw) for w, rw in taken):
            continue  # two ways that would cross or run together
        b = branches[i]
        ext = Branch(way, np.full(len(way), r)).resample(step).points[1:]
        if not len(ext) or np.hypot(*(ext[-1] - way[-1])) > 0.25 * step:
            ext = np.vstack([ext, way[-1:]])  # on to the centre line: one shorter last edge
        pts = np.vstack([b.points, ext])
        branches[i] = Branch(pts, np.concatenate([b.thickness, np.full(len(ext), r)]), b.parent)
        taken.append((way, r))
        need -= 1
    return Skeleton(branches, skeleton.shape)


def _heading(branch: Branch, back: float) -> F64:
    """Unit direction from the point ``back`` px before the end (along the branch) to the end."""
    s = _arc_lengths(branch)
    at = max(0.0, float(s[-1]) - back)
    p = np.array([np.interp(at, s, branch.points[:, 0]), np.interp(at, s, branch.points[:, 1])])
    d = branch.points[-1] - p
    norm = float(np.hypot(*d))
    return d / norm if norm > 0 else np.zeros(2)


def _way_on(skeleton: Skeleton, lines: _Lines, i: int, reach: float, inside: Any) -> F64 | None:
    """The way from branch ``i``'s end to the nearest surface of other structure ahead, sampled
    every half pixel, or None."""
    b = skeleton.branches[i]
    e, r = b.points[-1], float(b.thickness[-1])
    hd = _heading(b, 2.0 * max(r, 1.0))
    if not hd.any():
        return None
    ids = np.asarray(lines.tree.query_ball_point(e, reach), dtype=np.int64)
    if not ids.size:
        return None
    ids = ids[_others(skeleton, lines, i, ids)]
    v = lines.points[ids] - e
    dist = np.linalg.norm(v, axis=1)
    ahead = (dist > 0) & (v @ hd >= np.cos(JOIN_CONE) * dist)
    if not ahead.any():
        return None
    ids, dist = ids[ahead], dist[ahead]
    j = ids[np.argmin(dist - lines.radius[ids])]
    q = lines.points[j]
    chord = float(np.hypot(*(q - e)))
    t = np.linspace(0.0, 1.0, max(2, math.ceil(2 * chord) + 1))[:, None]
    way = (
        (2 * t**3 - 3 * t**2 + 1) * e
        + (t**3 - 2 * t**2 + t) * (hd * chord)
        + (-2 * t**3 + 3 * t**2) * q
        + (t**3 - t**2) * (q - e)
    )
    H, W = skeleton.shape  # type: ignore[misc]
    x, y = way[:, 0], way[:, 1]
    if (x < 0).any() or (y < 0).any() or (x > W - 1).any() or (y > H - 1).any():
        return None
    if inside is not None and not inside[np.round(y).astype(int), np.round(x).astype(int)].all():
        return None
    # The way must not touch other structure before it reaches the surface it was aimed at.
    arrive = np.linalg.norm(way - q, axis=1) <= lines.radius[j] + r + _end_slack(skeleton, i)
    path = way[~arrive][::2]  # every pixel
    hits = lines.tree.query_ball_point(path, lines.max_radius + r)
    rows = np.repeat(np.arange(len(path)), [len(h) for h in hits])
    near = np.concatenate([np.asarray(h, dtype=np.int64) for h in hits] + [np.zeros(0, np.int64)])
    keep = _others(skeleton, lines, i, near)
    rows, near = rows[keep], near[keep]
    if (np.linalg.norm(lines.points[near] - path[rows], axis=1) < lines.radius[near] + 0.5 * r).any():
        return None
    return np.asarray(way, dtype=np.float64)


def _too_close(a: F64, b: F64, gap: float) -> bool:
    """Whether any point of polyline samples ``a`` lies within ``gap`` of any of ``b``'s."""
    d = np.linalg.norm(a[:, None, :] - b[None, ::4, :], axis=2)
    return bool((d < gap).any())
