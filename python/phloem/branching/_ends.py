"""Where each branch's end lies against the rest of its structure: on other structure (a loop
that the trace cut open, a channel that rejoins another, a crack that stops on a crack) or free.

Shared by the measure (:func:`phloem.branching.measures.joined_end_share`) and the growth
step that joins ends (:func:`phloem.branching.joins.join_ends`), so that the two agree on
what an end on structure is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree  # type: ignore[import-untyped]

from ._elements import F64, I64, _arc_lengths, _dense
from .skeleton import Skeleton

#: How far past the other structure's surface an end still counts as on it, px (at least;
#: half the end's own thickness where that is more): a traced centre line stops a pixel or two
#: short of the line it meets.
END_SLACK = 2.0


@dataclass(frozen=True)
class _Lines:
    """The skeleton's centre lines sampled at most a pixel apart, with a k-d tree over them,
    and each branch's children with the vertex they start at."""

    points: F64  # (N, 2) x, y
    radius: F64  # (N,) the branch's thickness there
    branch: I64  # (N,) which branch
    arc: F64  # (N,) arc length along that branch
    tree: cKDTree
    children: dict[int, list[tuple[int, int]]]  # branch -> [(child, vertex)]

    @classmethod
    def of(cls, skeleton: Skeleton) -> _Lines:
        dense = [_dense(b, 1.0) for b in skeleton.branches]
        p = np.vstack([d[0] for d in dense])
        children: dict[int, list[tuple[int, int]]] = {}
        for j, c in enumerate(skeleton.branches):
            if c.parent is not None:
                children.setdefault(c.parent[0], []).append((j, c.parent[1]))
        return cls(
            p,
            np.concatenate([d[1] for d in dense]),
            np.concatenate([np.full(len(d[0]), i, np.int64) for i, d in enumerate(dense)]),
            np.concatenate([d[2] for d in dense]),
            cKDTree(p),
            children,
        )

    @property
    def max_radius(self) -> float:
        return float(self.radius.max(initial=0.0))


def _end_slack(skeleton: Skeleton, i: int) -> float:
    return max(END_SLACK, 0.5 * float(skeleton.branches[i].thickness[-1]))


def _others(skeleton: Skeleton, lines: _Lines, i: int, ids: I64) -> NDArray[np.bool_]:
    """Which of the sampled points ``ids`` are other structure for branch ``i``'s end.

    Not the branch itself, nor its children that start at its end, nor its parent where the
    two still overlap at the branch's start (within twice their thicknesses there, plus twice
    :data:`END_SLACK`): a short stub ends beside its parent without closing a loop. Further
    along the parent an end on it closes one.
    """
    b = skeleton.branches[i]
    end, r = b.points[-1], float(b.thickness[-1])
    near_end = [j for j, v in lines.children.get(i, []) if np.hypot(*(b.points[v] - end)) <= 2 * r + END_SLACK]
    out = (lines.branch[ids] != i) & ~np.isin(lines.branch[ids], near_end)
    if b.parent is not None:
        pb, pv = b.parent
        parent = skeleton.branches[pb]
        at = float(_arc_lengths(parent)[pv])
        window = 2 * (float(b.thickness[0]) + float(parent.thickness[pv])) + 2 * END_SLACK
        out &= ~((lines.branch[ids] == pb) & (np.abs(lines.arc[ids] - at) < window))
    return np.asarray(out, dtype=np.bool_)


def _end_gap(skeleton: Skeleton, lines: _Lines, i: int, radius: float) -> float:
    """How far branch ``i``'s last vertex lies outside other structure's surface, px (the
    distance to a centre line less its thickness there; inf where none is within ``radius``)."""
    e = skeleton.branches[i].points[-1]
    ids = np.asarray(lines.tree.query_ball_point(e, radius + lines.max_radius), dtype=np.int64)
    if not ids.size:
        return float("inf")
    ids = ids[_others(skeleton, lines, i, ids)]
    if not ids.size:
        return float("inf")
    gap = np.linalg.norm(lines.points[ids] - e, axis=1) - lines.radius[ids]
    return float(gap.min())


def _on_structure(skeleton: Skeleton, lines: _Lines) -> NDArray[np.bool_]:
    """Whether each branch ends on other structure (within :data:`END_SLACK` of its surface)."""
    return np.array(
        [
            _end_gap(skeleton, lines, i, _end_slack(skeleton, i)) <= _end_slack(skeleton, i)
            for i in range(len(skeleton.branches))
        ],
        dtype=np.bool_,
    )
