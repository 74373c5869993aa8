"""Graph-cut composition (Luo et al. §2, Eqs. 1–2): the fetched pieces joined into one image.

The pieces go onto the canvas one by one, along each stroke and stroke after stroke. Where a
new piece overlaps what is already there, every overlap pixel is given to the canvas or to the
piece by the minimum cut of :func:`phloem.seams.seam` with Luo's cost: ``min(d(x), d(y)) /
G(x, y)``, ``d`` the fourth power of the colour difference and ``G`` the summed gradient
magnitudes, with the data term of 10000 tying overlap pixels on the border of one side to that
side. Pieces of different strokes that meet are cut against each other the same way, with two
constraints the paper does not state (docs/pipelines/strokes/editing.md says why):

- at a junction (a stroke's end on another stroke's object), the branch takes its parent's rim
  where it leaves it (:data:`RIM`) and leaves the parent's core to it (:data:`CORE`): a branch
  grows out of its parent's silhouette instead of passing behind it;
- everywhere, a pixel deep inside one side's object (:data:`SOLID`) does not go to a side that
  is transparent there: a piece reaching past the object's end cuts no hole.

A pixel only ever takes a piece that covers it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage  # type: ignore[import-untyped]

from .. import seams
from .._distance import euclidean_distance
from .fetch import Piece

F32 = NDArray[np.float32]

#: The outer part of another stroke's object, as a fraction of that piece's half width, that a
#: piece leaving it must take: the parent's silhouette (its edge, its shading) stops where the
#: branch leaves it. The paper composes branches by the plain cut, which follows that edge,
#: since a strong edge makes a cheap seam (docs/pipelines/strokes/editing.md).
RIM = 0.35
#: Deeper than this fraction of its half width, another stroke's object keeps its pixels against
#: a piece leaving it: the seam between a branch and its parent falls just inside the parent.
CORE = 0.65
#: Deeper than this fraction of its piece's half width inside the object, a piece's opaque
#: pixel never gives way to another piece's transparent one.
SOLID = 0.35


@dataclass(frozen=True)
class Composite:
    """The composed pieces.

    Attributes
    ----------
    rgba : (H, W, 4) ndarray of float32
        The image: each pixel the colour and alpha of the piece it took.
    labels : (H, W) ndarray of int32
        The index of the piece each pixel took, -1 where none covers it.
    energy : float
        The summed energy of the cuts.
    """

    rgba: F32
    labels: NDArray[np.int32]
    energy: float


def compose(
    pieces: list[Piece],
    size: tuple[int, int],
    *,
    threads: int | None,
    owner: list[int] | None = None,
    ends: NDArray[np.float64] | None = None,
    check: Callable[[int], None] | None = None,
) -> Composite:
    """Compose ``pieces`` (in order) onto a transparent ``size`` = (H, W) canvas.

    ``owner[k]`` is piece ``k``'s stroke (default: all one stroke) and ``ends[s]`` the (2, 2)
    ``(x, y)`` end points of stroke ``s`` on the canvas (default: no junctions); ``check(k)``
    runs before piece ``k`` (progress, cancellation)."""
    owners = np.zeros(len(pieces), np.int64) if owner is None else np.asarray(owner, np.int64)
    half = np.array([0.5 * (p.widths[0] + p.widths[1]) for p in pieces])
    h, w = size
    rgba = np.zeros((h, w, 4), np.float32)
    labels = np.full((h, w), -1, np.int32)
    energy = 0.0
    depths: dict[int, F32] = {}  # a branching stroke's depth inside its own pieces' union
    for k, p in enumerate(pieces):
        if check is not None:
            check(k)
        x0, y0 = p.offset
        ph, pw = p.support.shape
        # The piece's box on the canvas plus a ring of one pixel, so overlap pixels on the box's
        # edge see the canvas that goes on beyond it.
        cy0, cy1 = max(0, y0 - 1), min(h, y0 + ph + 1)
        cx0, cx1 = max(0, x0 - 1), min(w, x0 + pw + 1)
        if cy1 <= cy0 or cx1 <= cx0:
            continue
        b = np.zeros((cy1 - cy0, cx1 - cx0, 4), np.float32)
        b_mask = np.zeros(b.shape[:2], bool)
        sy0, sx0 = max(0, cy0 - y0), max(0, cx0 - x0)
        sy1, sx1 = min(ph, cy1 - y0), min(pw, cx1 - x0)
        dy0, dx0 = y0 + sy0 - cy0, x0 + sx0 - cx0
        b[dy0 : dy0 + sy1 - sy0, dx0 : dx0 + sx1 - sx0] = p.rgba[sy0:sy1, sx0:sx1]
        b_mask[dy0 : dy0 + sy1 - sy0, dx0 : dx0 + sx1 - sx0] = p.support[sy0:sy1, sx0:sx1]
        if not b_mask.any():
            continue
        view = rgba[cy0:cy1, cx0:cx1]
        lab = labels[cy0:cy1, cx0:cx1]
        a_mask = lab >= 0
        region = a_mask & b_mask
        if region.any():
            seeds = None
            if ends is not None:
                at = _junctions(labels, owners, k, ends[owners[k]]) - (cx0, cy0)
                if len(at):
                    s = int(owners[k])
                    if s not in depths:
                        depths[s] = _footprint_depth([q for q, o in zip(pieces, owners, strict=True) if o == s], size)
                    own = depths[s][cy0:cy1, cx0:cx1]
                    seeds = _leaving(lab, b_mask, own, owners, half, k, at)
            seeds = _opaque_wins(view[..., 3], b[..., 3], region, half[np.maximum(lab, 0)], half[k], seeds)
            cut = seams.seam(
                view[..., :3],
                b[..., :3],
                region,
                cost="luo",
                a_mask=a_mask,
                b_mask=b_mask,
                seeds=seeds,
                threads=threads,
                full_output=True,
            )
            take = cut.take_b & b_mask
            energy += cut.energy
        else:
            take = b_mask
        view[take] = b[take]
        lab[take] = k
    return Composite(rgba, labels, energy)


def _depth(inside: NDArray[np.bool_]) -> F32:
    """Exact Euclidean distance (px) from every pixel to the nearest pixel not ``inside``;
    very large where the box holds none (the object goes on beyond it). OpenCV's transform
    (:func:`~phloem._distance.euclidean_distance`), 3× faster than SciPy's here, which also puts
    a phantom edge before the first corner of a box that is all inside."""
    return euclidean_distance(inside)


def _opaque_wins(
    a_alpha: F32,
    b_alpha: F32,
    region: NDArray[np.bool_],
    a_half: NDArray[np.float64],
    b_half: float,
    seeds: NDArray[np.uint8] | None,
) -> NDArray[np.uint8] | None:
    """``seeds`` with overlap pixels deep inside one side's object (alpha ≥ ½, more than
    :data:`SOLID` of its piece's half width from its edge) where the other side is not the
    object tied to that side: a piece that reaches past the object (beyond its end, or scaled
    down so that it reads past it) never cuts a hole into another piece's object. Near the
    edges the plain cut still decides which piece's outline shows."""
    a_in, b_in = a_alpha >= 0.5, b_alpha >= 0.5
    only_a, only_b = region & a_in & ~b_in, region & b_in & ~a_in
    if not only_a.any() and not only_b.any():
        return seeds
    if only_a.any():
        only_a &= _depth(a_in) > SOLID * a_half
    if only_b.any():
        only_b &= _depth(b_in) > SOLID * b_half
    if not only_a.any() and not only_b.any():
        return seeds
    out = np.zeros(region.shape, np.uint8) if seeds is None else seeds.copy()
    out[only_a & (out == 0)] = 1
    out[only_b & (out == 0)] = 2
    return out


def _junctions(
    labels: NDArray[np.int32], owners: NDArray[np.int64], k: int, ends: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The end points of piece ``k``'s stroke that lie on another stroke's object on the
    canvas so far: where that stroke branches off (or runs into) another one."""
    h, w = labels.shape
    out = []
    for x, y in ends:
        xi, yi = round(x), round(y)
        if 0 <= yi < h and 0 <= xi < w and labels[yi, xi] >= 0 and owners[labels[yi, xi]] != owners[k]:
            out.append((x, y))
    return np.array(out, np.float64).reshape(-1, 2)


def _footprint_depth(pieces: list[Piece], size: tuple[int, int]) -> F32:
    """The distance (px) from every pixel to the edge of the union of ``pieces`` on the canvas:
    how deep inside its own object a stroke's pixel lies, whatever piece ends are there."""
    h, w = size
    union = np.zeros((h, w), bool)
    for p in pieces:
        x0, y0 = p.offset
        ph, pw = p.support.shape
        ya, yb, xa, xb = max(0, y0), min(h, y0 + ph), max(0, x0), min(w, x0 + pw)
        if ya < yb and xa < xb:
            union[ya:yb, xa:xb] |= p.support[ya - y0 : yb - y0, xa - x0 : xb - x0]
    depth = np.zeros((h, w), np.float32)
    rows, cols = np.nonzero(union)
    if len(rows):
        # The union's box with a ring of one pixel: the canvas's edge stays inside, as on the canvas.
        box = (slice(max(0, rows.min() - 1), rows.max() + 2), slice(max(0, cols.min() - 1), cols.max() + 2))
        depth[box] = _depth(union[box])
    return depth


def _leaving(
    lab: NDArray[np.int32],
    b_mask: NDArray[np.bool_],
    own: F32,
    owners: NDArray[np.int64],
    half: NDArray[np.float64],
    k: int,
    at: NDArray[np.float64],
) -> NDArray[np.uint8] | None:
    """Seeds for :func:`seams.seam` where piece ``k`` leaves another stroke's object (the
    parent) near a junction ``at`` ((n, 2) ``(x, y)`` in the box).

    2 (take the piece) on the parent's rim: within :data:`RIM` of the parent's half width of
    its edge, as deep inside the piece's own stroke's object (``own``), and connected to where
    the piece alone lies; 1 (keep the parent) deeper than :data:`CORE`. Only within two parent
    half widths of a junction: strokes that merely cross are cut as the paper cuts them. None
    where nothing is seeded."""
    if len(at) == 0:
        return None
    a_mask = lab >= 0
    parent = a_mask & (owners[np.maximum(lab, 0)] != owners[k])
    other = parent & b_mask
    if not other.any():
        return None
    reach = half[np.maximum(lab, 0)]
    yy, xx = np.mgrid[: lab.shape[0], : lab.shape[1]]
    near = np.zeros(lab.shape, bool)
    for x, y in at:
        near |= (xx - x) ** 2 + (yy - y) ** 2 <= (2 * reach) ** 2
    other &= near
    depth = _depth(parent)
    rim = other & (depth <= RIM * reach) & (own > RIM * half[k])
    alone = b_mask & ~a_mask
    parts, _ = ndimage.label(rim | alone, structure=np.ones((3, 3), bool))
    found = np.unique(parts[alone])
    take = rim & np.isin(parts, found[found > 0])
    if not take.any():
        return None
    keep = other & (depth > CORE * reach)
    return np.where(take, 2, np.where(keep, 1, 0)).astype(np.uint8)


def keep_on_strokes(comp: Composite, points: NDArray[np.float64]) -> Composite:
    """``comp`` without the pieces of it that touch no target stroke: the connected parts
    (8-connected, alpha above zero) that hold none of ``points`` ((N, 2) ``(x, y)`` along the
    target strokes). A piece at a stroke's end or junction can bring a sliver of the source
    from beyond it, apart from the object."""
    h, w = comp.labels.shape
    parts, n = ndimage.label(comp.rgba[..., 3] > 0, structure=np.ones((3, 3), bool))
    if n <= 1:
        return comp
    xi, yi = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
    ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    keep = np.zeros(n + 1, bool)
    keep[parts[yi[ok], xi[ok]]] = True
    keep[0] = False
    drop = ~keep[parts] & (parts > 0)
    if not drop.any():
        return comp
    rgba, labels = comp.rgba.copy(), comp.labels.copy()
    rgba[drop] = 0.0
    labels[drop] = -1
    return Composite(rgba, labels, comp.energy)


def seam_map(labels: NDArray[np.int32]) -> NDArray[np.bool_]:
    """Pixels where two different pieces meet (4-neighbours with different labels, both
    covered)."""
    out = np.zeros(labels.shape, bool)
    for a, b, oa, ob in (
        (labels[:, 1:], labels[:, :-1], (slice(None), slice(1, None)), (slice(None), slice(None, -1))),
        (labels[1:], labels[:-1], (slice(1, None), slice(None)), (slice(None, -1), slice(None))),
    ):
        edge = (a != b) & (a >= 0) & (b >= 0)
        out[oa] |= edge
        out[ob] |= edge
    return out
