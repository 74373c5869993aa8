"""Growing a new branching structure (Sibbing, Pavić, Kobbelt 2010, §4, §4.4, §4.5).

:func:`grow` starts a main branch with copied input elements, extends it with the bending model
(:mod:`.bending`), forks it with the furcation model (:mod:`.furcation`) and grows the children
the same way, breadth first. Space colonisation (§4.4): a density map
``D(p) = exp(-d(p, B)² / ρ²)`` of the structure grown so far divides candidate qualities by
``D_i + ε``; guided synthesis (§4.5) divides them by ``G_i + ε`` for a guidance map ``G``;
extensions that would cross an existing branch get quality zero. :func:`extend` grows one
branch of an existing skeleton (§6, interactive use).

Beyond the paper's text:

* **Trees from templates.** Traced inputs are forests; each output tree copies the topology
  statistics of one input tree (branch lengths and numbers of children per generation), so
  that a connected input gives a connected output and a forest a forest of the same tree
  sizes; ``max_length="input"`` grows about as much structure as the input.
* **Siblings in order.** The children picked on one branch are dealt their template
  branches so that length and place along the parent correlate as in the input
  (:func:`~phloem.branching.measures.sibling_order`): long children near the parent's start.
* **Course.** The bending model also matches each branch's heading against its course over
  ``8 m`` edges (:class:`.BendingModel`, ``course``), so branches keep a course at the scale
  of the structure.
* **Stem thickness.** Each root tree's main branch is matched against its template stem's
  thickness at the same arc length (:class:`.BendingModel`, ``stem_thickness``), so that a
  trunk stays as thick as the input's and tapers as it does.
* **Orientation** (an option, off by default). The bending model can also match each
  branch's heading on the image (:class:`.BendingModel`, ``orientation``), so that branches
  run the ways the input's run; the paper's model knows only turns.
* **Density map.** ``d(p, B)`` is the distance from a pixel to the branch's surface (per
  segment, the distance to its nearest point minus the thickness there), written where it is
  at most ``3ρ`` (``phloem_core::colonisation``); candidates whose average directions agree to
  within a quarter pixel at the end of the ``3 m h`` look-up ray share one ray. A step tests
  only its best candidates for the frame and for crossings, exactly, against the segments
  within their reach (``phloem_core::growth``).

All randomness comes from ``numpy.random.default_rng(seed)``, so a seed fixes the output.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core, _memory
from .._api import Seed, Size, renamed
from .._progress import Progress
from .._validate import as_mask, check_float, check_int, check_seed
from ._elements import F64, _check_skeleton, _direction, _edge_headings, _elements, _tangent, _wrap
from ._forest import InputTree, connected, input_trees
from ._world import _guide_map, _World
from .bending import BendingModel, block_sums, course_deviation
from .furcation import FurcationModel
from .joins import join_ends
from .measures import sibling_order
from .skeleton import Branch, Skeleton

__all__ = ["extend", "grow"]

#: ``1/ε`` of §4.4: the largest factor by which an empty region can raise a candidate's quality.
INV_EPS = 1e3
_EPS = 1.0 / INV_EPS
#: Further vertices of the parent tried for a child that cannot start where it was picked.
_CHILD_RETRIES = 3
#: Extra furcations tried on a tree that its template's topology left short of the template's length.
_TOP_UPS = 256
#: Density along its first ``3 m h`` over which a connected input's further tree does not start.
_CROWDED = 0.5
#: A child whose first ``3 m h`` reads a density above this (it would come within ``ρ``, the
#: paper's "how close the different branches are allowed to approach", of other structure)
#: does not start there: squeezed between branches it could only run alongside them.
_CROWDED_START = math.exp(-1.0)


@dataclass
class _Growing:
    """A branch while it grows: points, thickness, and its elements (interior-vertex α, r)."""

    points: list[F64]
    thickness: list[float]
    alpha: list[float]
    r: list[float]
    heading: float
    parent: tuple[int, int] | None
    generation: int
    index: int
    inserted: int = 0  # segments already written into the density map
    # the parent's vertices within ``near`` of the attachment and their thickness (children only)
    parent_near: tuple[F64, F64] | None = None
    # a stem's template thickness per vertex (:meth:`BendingModel.stem_profile`), or None
    profile: F64 | None = None
    # the thickness of the last vertices before the end tapered them (see ``_Grower.taper``)
    level: F64 | None = None

    def length(self) -> float:
        return float(len(self.points) - 1)


def _check_start(start: Any) -> tuple[float, float, float | None] | None:
    if start is None:
        return None
    vals = np.asarray(start, dtype=np.float64).ravel()
    if vals.size not in (2, 3) or not np.isfinite(vals).all():
        raise ValueError(f"start: expected (x, y) or (x, y, heading in radians) with finite values, got {start!r}")
    return float(vals[0]), float(vals[1]), (float(vals[2]) if vals.size == 3 else None)


class _Grower:
    """Runs the Markov growth of single branches inside a :class:`_World`."""

    def __init__(self, world: _World, model: BendingModel) -> None:
        self.world = world
        self.model = model
        self.cum_alpha = np.cumsum(model.next_alpha, axis=1)
        # vertices around a child's attachment on its parent that its density lookups ignore
        self.near = math.ceil(3.0 * world.rho / model.h) + 1
        # Candidate paths relative to a tip at the origin heading along +x: a step only has to
        # rotate them (no trigonometry per candidate and step).
        unit = _direction(self.cum_alpha)  # (C, m, 2)
        self.rel_ext = model.h * np.cumsum(unit, axis=1)
        mean_dir = unit.sum(axis=1)
        norm = np.linalg.norm(mean_dir, axis=1)
        psi = np.where(norm > 1e-12, np.arctan2(-mean_dir[:, 1], mean_dir[:, 0]), self.cum_alpha[:, -1])
        # The density (guide) maximum is looked up along each candidate's average direction,
        # 3 m h long. Candidates whose directions agree to within a quarter pixel at the ray's
        # end share one ray (a few hundred rays instead of one per candidate).
        self.ray_length = 3.0 * model.m * model.h
        self.ray_samples = max(3 * model.m, 4)
        key = np.rint(psi / (0.25 / self.ray_length)).astype(np.int64)
        _, first, self.ray_of = np.unique(key, return_index=True, return_inverse=True)
        self.ray_psi = psi[first]
        self.ray_of = np.ascontiguousarray(self.ray_of, np.int64)

    def step(self, br: _Growing) -> bool:
        """Append one extension of ``m`` elements to ``br``; False when no candidate is valid."""
        m, w = self.model, self.world
        L = min(len(br.alpha), m.k + 1)
        if L == 0:
            # no history yet (should not happen: branches start with copied elements)
            return False
        dev = None
        if m.course > 0:
            tail = np.asarray(br.points[-(m.course + 1) :])  # the chord needs no more than the last course edges
            dev = float(course_deviation(tail, np.array([len(tail) - 1]), m.course)[0])
        coarse = block_sums(np.asarray(br.alpha[-(m.k + 1) * m.m :]), m.k, m.m) if m.coarse_history > 0 else None
        turn = float(np.sum(br.alpha)) if m.total_turn > 0 or m.turn_bound > 0 else None
        alpha, r = np.asarray(br.alpha[-L:]), np.asarray(br.r[-L:])
        head = br.heading if m.orientation > 0 or m.direction_histogram > 0 else None
        recent = np.asarray(br.alpha[-(m.arc_edges - 1) :]) if m.turn_histogram > 0 else None
        want = None
        if br.profile is not None and m.stem_thickness > 0:
            # the extension writes the thickness of the tip vertex and the m - 1 after it
            n = len(br.points) - 1
            want = br.profile[np.minimum(np.arange(n, n + m.m), len(br.profile) - 1)]
        q = m.log_quality(
            alpha, r, w.counts_alpha, w.counts_r, dev, coarse, turn, stem=br.parent is None, heading=head,
            arc_tail=recent, counts_arc=w.counts_arc, profile=want, counts_dir=w.counts_dir,
        )  # fmt: skip
        tip = br.points[-1]
        H, W = w.shape
        if m.direction_layout is not None:  # fitted only where layout > 0
            # the log-density of each candidate's mean direction under the input's layout at the tip
            kappa, phi = m.direction_layout.at(float(tip[0]), float(tip[1]), w.shape)
            if kappa > 0:
                q = q + (m.layout * kappa) * np.cos(2.0 * (br.heading + self.ray_psi - phi))[self.ray_of]
        cos, sin = math.cos(br.heading), math.sin(br.heading)
        density = None
        if w.colonize and w.dens is not None and w.owner_branch is not None and w.owner_vertex is not None:
            density = (w.dens, w.owner_branch, w.owner_vertex)
        skip = self.parent_skip(br) if density is not None else None  # no density, nothing to skip
        # the density and guidance terms, the frame and the crossings, for the best candidates
        valid, lq = _core.growth_choose(
            q,
            self.rel_ext,
            self.ray_of,
            (float(tip[0]), float(tip[1])),
            cos,
            sin,
            H,
            W,
            _direction(br.heading + self.ray_psi),
            self.ray_length,
            self.ray_samples,
            density,
            skip,
            w.rho if w.repel_border else None,
            w.guide,
            w.segment_rows,
            self.model.c,
            _EPS,
        )
        if w.domain is not None and len(valid):
            # a branch ends where it would leave the domain (a photo's frame), as at the image's border
            keep = w.inside(_placed(tip, cos, sin, self.rel_ext[valid]))
            valid, lq = valid[keep], lq[keep]
        if not len(valid):
            return False
        # among the c best valid candidates, one drawn in proportion to its quality
        p = np.exp(lq - lq.max())
        choice = int(w.rng.choice(valid, p=p / p.sum()))
        self._append(br, choice, _placed(tip, cos, sin, self.rel_ext[choice]))
        return True

    def parent_skip(self, br: _Growing) -> tuple[int, int, int, float] | None:
        """``(parent branch, attachment vertex, near, floor)`` of the parent density ``br``'s
        candidates discount, or None.

        A child starts on its parent, where every direction would read ``D = 1``, so the parent's
        vertices within ``near`` (``3ρ``) of the attachment count only with their density above
        ``floor``, the parent's density at the child's tip: moving away or alongside reads as
        empty, turning back towards the parent does not. This holds only until the child is
        ``3ρ`` long: beyond that it sees the whole parent.
        """
        if br.parent is None or len(br.points) - 1 > self.near:
            return None
        floor = 1.0
        if br.parent_near is not None:
            floor = self.world.surface_density(br.points[-1], *br.parent_near)
        return br.parent[0], br.parent[1], self.near, floor

    def crowded_start(self, start: F64, heading: float, parent: tuple[int, int]) -> bool:
        """Whether a child leaving ``parent = (branch, vertex)`` at ``start`` along ``heading``
        would come within ``ρ`` of other structure (density over :data:`_CROWDED_START`) over
        its first ``3 m h``; the parent near the attachment does not count."""
        w = self.world
        if w.dens is None:
            return False
        d = w.ray_density(
            np.asarray(start)[None, :], np.array([heading]), self.ray_length, self.ray_samples, parent, self.near,
            include_start=False,
        )  # fmt: skip
        return bool(d[0] > _CROWDED_START)

    def near_parent(self, parent: Branch, vertex: int) -> tuple[F64, F64]:
        """The parent's vertices within ``near`` of the attachment ``vertex`` and their thickness."""
        lo, hi = max(vertex - self.near, 0), vertex + self.near + 1
        return parent.points[lo:hi], parent.thickness[lo:hi]

    def _append(self, br: _Growing, i: int, new_pts: F64) -> None:
        self.append_elements(br, self.model.next_alpha[i], self.model.next_r[i], new_pts)

    def append_elements(self, br: _Growing, alpha: F64, r: F64, new_pts: F64) -> None:
        """Turn at the tip by each ``alpha`` and give the tip thickness ``r`` (the tip becomes interior)."""
        w = self.world
        start = len(br.points) - 1
        for j in range(len(alpha)):
            br.thickness[-1] = float(r[j])
            br.points.append(new_pts[j])
            br.thickness.append(float(r[j]))
        br.alpha.extend(float(a) for a in alpha)
        br.r.extend(float(v) for v in r)
        headings = br.heading + np.cumsum(np.asarray(alpha, dtype=np.float64))
        br.heading = _wrap(br.heading + float(np.sum(alpha)))
        # the windows of the heading-change histogram that end at the new elements
        windows = None
        if self.model.turn_histogram > 0:
            windows = np.asarray(br.alpha[-(len(alpha) + self.model.arc_edges - 1) :], dtype=np.float64)
        w.add_elements(np.asarray(alpha, dtype=np.float64), np.asarray(r, dtype=np.float64), windows, headings)
        pts = np.asarray(br.points[start:])
        w.add_segments(pts)
        self.flush(br, final=False)

    def taper(self, br: _Growing) -> None:
        """End ``br`` as the input's branches end: its last vertices' thickness times
        :attr:`BendingModel.end_taper` (all but the first vertex on a shorter branch).

        The elements' thicknesses and the structure's thickness histogram follow, so that
        the histogram matching sees the tapered ends; ``br.level`` keeps what was there.
        """
        prof = self.model.end_taper
        n = min(len(prof), len(br.thickness) - 1)
        if n <= 0:
            return
        first = len(br.thickness) - n
        old = np.asarray(br.thickness[first:], np.float64)
        new = old * prof[len(prof) - n :]
        br.level = old
        br.thickness[first:] = new.tolist()
        # elements are the interior vertices: vertex v holds element v - 1 (the tip holds none)
        lo, hi = max(first - 1, 0), min(len(br.thickness) - 2, len(br.r))
        if lo < hi:
            before = np.array(br.r[lo:hi])
            br.r[lo:hi] = br.thickness[lo + 1 : hi + 1]
            self.world.recount_r(before, np.array(br.r[lo:hi]))

    def flush(self, br: _Growing, *, final: bool) -> None:
        """Write the branch's segments into the density map, holding back the last ``3ρ`` of arc
        length while it grows so that a tip does not repel itself."""
        w = self.world
        if w.dens is None:
            return
        hold = 0 if final else math.ceil(3.0 * w.rho / self.model.h) + 1
        upto = len(br.points) - 1 - hold  # segments [inserted, upto) are final
        if upto > br.inserted:
            pts = np.asarray(br.points[br.inserted : upto + 1])
            th = np.asarray(br.thickness[br.inserted : upto + 1])
            w.stamp(pts, th, br.index, br.inserted)
            br.inserted = upto


def _points_for(br: _Growing, alpha: F64, h: float) -> F64:
    heads = br.heading + np.cumsum(alpha)
    return np.asarray(br.points[-1] + np.cumsum(h * _direction(heads), axis=0))


def _valid_prefix(world: _World, tip: F64, pts: F64) -> int:
    """How many of the points ``pts`` (a path from ``tip``) stay inside and cross nothing."""
    n = 0
    prev = tip
    for p in pts:
        if not world.inside(p[None, :])[()] or world.crossings(prev, p[None, None, :])[0]:
            break
        prev = p
        n += 1
    return n


def _new_branch(
    world: _World,
    grower: _Grower,
    start: F64,
    heading: float,
    r0: float,
    alpha: F64,
    r: F64,
    parent: tuple[int, int] | None,
    generation: int,
    index: int,
    *,
    partial: bool,
) -> _Growing | None:
    """Start a branch: first edge along ``heading``, then the copied initial elements.

    Returns None when the first edge is invalid (outside or crossing), or when ``partial`` is
    False and any copied element is invalid.
    """
    h = grower.model.h
    p1 = start + h * _direction(heading)
    if not world.inside(np.vstack([start, p1])[None]).all() or world.crossings(start, p1[None, None, :])[0]:
        return None
    br = _Growing([start.copy(), p1], [r0, r0], [], [], heading, parent, generation, index)
    pts = _points_for(br, alpha, h)
    ok = _valid_prefix(world, p1, pts)
    if ok < len(alpha) and not partial:
        return None
    world.add_segments(np.vstack([start, p1]))
    if ok:
        grower.append_elements(br, alpha[:ok], r[:ok], pts[:ok])
    return br


def _finish(grower: _Grower, br: _Growing) -> Branch:
    grower.taper(br)
    grower.flush(br, final=True)
    return Branch(np.asarray(br.points), np.asarray(br.thickness), br.parent)


def _ordered(
    planned: list[tuple[float, int]], vertices: list[int], order: float, rng: np.random.Generator
) -> list[tuple[float, int]]:
    """Siblings' planned (length, children) given to their furcation vertices so that length and
    place along the parent correlate as in the input (:func:`~.measures.sibling_order`, Spearman's
    ``ρ_s``): a Gaussian copula of Pearson ``ρ = 2 sin(π ρ_s / 6)`` between the vertices' normal
    scores and the keys by which the lengths are dealt, shortest to the lowest key."""
    n = len(planned)
    if n < 2 or order == 0.0:
        return planned
    rho = 2.0 * math.sin(math.pi * order / 6.0)
    rank = np.argsort(np.argsort(np.asarray(vertices), kind="stable"), kind="stable")
    score = np.array([NormalDist().inv_cdf((float(k) + 0.5) / n) for k in rank])
    key = rho * score + math.sqrt(max(0.0, 1.0 - rho * rho)) * rng.standard_normal(n)
    by_size = sorted(planned)
    out: list[tuple[float, int]] = [planned[0]] * n
    for size, i in zip(by_size, np.argsort(key, kind="stable").tolist(), strict=True):
        out[i] = size
    return out


def _check_models(bending: Any, furcation: Any) -> None:
    if not isinstance(bending, BendingModel):
        raise TypeError(f"bending: expected a BendingModel, got {type(bending).__name__}")
    if furcation is not None:
        if not isinstance(furcation, FurcationModel):
            raise TypeError(f"furcation: expected a FurcationModel or None, got {type(furcation).__name__}")
        if abs(furcation.h - bending.h) > 1e-9 * bending.h:
            raise ValueError(
                f"furcation: was fitted with h = {furcation.h:g} but bending with h = {bending.h:g}; fit both with the same h"
            )


def _default_start(bending: BendingModel, shape: tuple[int, int], root: int) -> tuple[float, float]:
    x, y = bending.source.branches[root].points[0]
    H, W = shape
    if bending.source.shape is not None:
        sh, sw = bending.source.shape
        return float(x / max(sw - 1, 1) * (W - 1)), float(y / max(sh - 1, 1) * (H - 1))
    x0, y0, x1, y1 = bending.source.bounds()
    fx = (x - x0) / (x1 - x0) if x1 > x0 else 0.5
    fy = (y - y0) / (y1 - y0) if y1 > y0 else 0.5
    return float((0.05 + 0.9 * fx) * (W - 1)), float((0.05 + 0.9 * fy) * (H - 1))


def _placed(tip: F64, cos: float, sin: float, ext: F64) -> F64:
    """Extensions ``(..., m, 2)`` relative to a tip heading ``(cos, sin)``, placed on the image."""
    rx, ry = ext[..., 0], ext[..., 1]
    return np.stack([tip[0] + cos * rx + sin * ry, tip[1] - sin * rx + cos * ry], axis=-1)


def _nearest_inside(inside: NDArray[np.bool_], x: float, y: float) -> tuple[float, float]:
    """``(x, y)``, or the centre of the pixel of ``inside`` nearest to it when it lies outside."""
    if inside[round(y), round(x)]:
        return x, y
    ys, xs = np.nonzero(inside)
    i = int(np.argmin((xs - x) ** 2 + (ys - y) ** 2))
    return float(xs[i]), float(ys[i])


def _top_up(
    out: list[Branch],
    first: int,
    tree: InputTree,
    furcation: FurcationModel,
    tried: dict[int, list[int]],
    started: dict[int, list[int]],
    rng: np.random.Generator,
    generations: int | None,
    min_spacing: int | None,
) -> tuple[int, int, int] | None:
    """A further furcation ``(branch, vertex, child generation)`` on the tree ``out[first:]``.

    The parent is drawn in proportion to its length among the tree's branches whose children's
    generation the template has (the next draw when it has no free vertex); the vertex is the
    furcation model's best free one.
    """
    gens: list[int] = []
    for b in out[first:]:
        gens.append(0 if b.parent is None or b.parent[0] < first else gens[b.parent[0] - first] + 1)
    ok = [
        i
        for i, g in enumerate(gens)
        if tree.branches.get(g + 1) and (generations is None or g + 1 < generations) and len(out[first + i]) >= 3
    ]
    if not ok:
        return None
    w = np.array([out[first + i].length() for i in ok])
    # parents in a random order weighted by length: one without a free vertex left (every vertex
    # tried or too near a child) must not end the tree while others have room
    for j in rng.choice(len(ok), size=len(ok), replace=False, p=w / w.sum()):
        i = ok[int(j)]
        pi = first + i
        kids = started.get(pi, [])
        failed = [v for v in tried.get(pi, []) if v not in kids]
        picked = furcation.pick(out[pi], 1, existing=kids, tried=failed, min_spacing=min_spacing, rng=rng)
        if picked:
            return pi, picked[0], gens[i] + 1
    return None


def _deal_next(
    queue: list[tuple[int, int, int, float, int]], qpos: int, block_end: int, rng: np.random.Generator
) -> int:
    """Swap into ``queue[qpos]`` a child drawn uniformly from those still queued of its generation.

    The queue holds one generation after the other, in the order their parents finished. A tree
    that reaches its template's length leaves the rest of the queue out, so taken in that order
    the children left out would all be on the branches grown last: a braided river's stem kept
    its side channels near its root and bare stubs towards its end. Returns the end of the
    generation's block (``block_end`` while ``qpos`` is inside it: children appended meanwhile
    are of the next generation).
    """
    if qpos >= block_end:
        gen = queue[qpos][2]
        block_end = qpos + 1
        while block_end < len(queue) and queue[block_end][2] == gen:
            block_end += 1
    k = qpos + int(rng.integers(block_end - qpos))
    queue[qpos], queue[k] = queue[k], queue[qpos]
    return block_end


def _input_length(bending: BendingModel, shape: tuple[int, int]) -> float:
    """The input's total length scaled by the ratio of the image areas (same structure density)."""
    src = bending.source
    if src.shape is not None:
        area = float(src.shape[0] * src.shape[1])
    else:
        x0, y0, x1, y1 = src.bounds()
        area = max((x1 - x0) * (y1 - y0), 1.0)
    return float(src.total_length() * shape[0] * shape[1] / area)


def _place_root(
    world: _World,
    grower: _Grower,
    bending: BendingModel,
    root: int,
    shape: tuple[int, int],
    rng: np.random.Generator,
    index: int,
    tries: int = 24,
    *,
    anywhere: bool = True,
) -> _Growing | None:
    """Start a further root tree, copying the input root branch ``root``, where the structure is sparse.

    Each try copies the root's first elements and heading (so the output's roots follow the
    input's); the first half of the tries start near the root's own (scaled) position,
    jittered by ``2ρ`` (roots at the image border stay there), the other half anywhere in the
    image. The start with the least density along its first ``3 m h`` wins, preferring a start
    near the input root when one is practically empty.

    Without ``anywhere`` (a connected input's minor trees) every try starts near the root's
    own position, and none where that density is over ``_CROWDED``: such a tree is a piece of
    the input's structure in its place (Colville's coastal lagoon), which anywhere else in the
    image reads as a foreign body. Returns None when no try can start.
    """
    H, W = shape
    rho = world.rho
    xs = np.zeros(tries)
    ys = np.zeros(tries)
    js = np.zeros(tries, np.int64)
    heads = np.zeros(tries)
    for t in range(tries):
        j = root
        x, y = _default_start(bending, shape, j)
        if t < tries // 2 or not anywhere:
            x = float(np.clip(x + rng.normal(0.0, 2.0 * rho), 0.0, W - 1))
            y = float(np.clip(y + rng.normal(0.0, 2.0 * rho), 0.0, H - 1))
        else:
            x, y = float(rng.uniform(0.0, W - 1)), float(rng.uniform(0.0, H - 1))
        xs[t], ys[t], js[t], heads[t] = x, y, j, bending.source.branches[j].heading()
    score = np.zeros(tries)
    if world.dens is not None:
        score = world.ray_density(np.stack([xs, ys], axis=1), heads, grower.ray_length, grower.ray_samples)
    near = np.arange(tries) < tries // 2
    order = np.argsort(score + np.where(near & (score < 0.05), -1.0, 0.0), kind="stable")
    if not anywhere:
        order = order[score[order] <= _CROWDED]
    if world.domain is not None:  # never in a photo's frame
        order = order[world.inside(np.stack([xs[order], ys[order]], axis=1)[:, None, :])]
    for t in order:
        j = int(js[t])
        heading, a0, r0, t0 = bending.start_elements(j)
        br = _new_branch(world, grower, np.array([xs[t], ys[t]]), heading, t0, a0, r0, None, 0, index, partial=True)
        if br is not None:
            return br
    return None


def _joined_untapered(joined: Skeleton, grown: list[Branch], levels: dict[int, F64]) -> Skeleton:
    """``joined`` with each joined end's taper taken back: a channel that runs on into another
    keeps its thickness to the junction, as the input's joined ends do."""
    branches = list(joined.branches)
    for i, level in levels.items():
        n0 = len(grown[i])
        if len(branches[i]) > n0:
            t = branches[i].thickness.copy()
            t[n0 - len(level) : n0] = level
            t[n0:] = level[-1]
            branches[i] = Branch(branches[i].points, t, branches[i].parent)
    return Skeleton(branches, joined.shape)


@renamed(shape="size")
def grow(
    bending: BendingModel,
    furcation: FurcationModel | None = None,
    *,
    size: Size,
    start: Any = None,
    seed: Seed = 0,
    generations: int | None = None,
    max_length: float | str | None = None,
    roots: int | None = None,
    max_density: float | None = None,
    branch_length: float | None = None,
    children: int | None = None,
    colonize: bool = True,
    repel_border: bool = False,
    rho: float | None = None,
    guide: Any = None,
    guide_width: float | None = None,
    min_spacing: int | None = None,
    domain: Any = None,
    joined_ends: float = 0.0,
    progress: Progress = None,
    max_memory: int | None = None,
) -> Skeleton:
    """Synthesise a new branching structure (§4): a main branch, then furcations, recursively.

    Every output tree copies one input tree as its template (largest first, see
    ``_forest``): the main branch starts with the first ``k + 1`` elements of the template's
    root branch and is extended by the bending model ``m`` elements at a time up to that
    root's length; each finished branch gets as many furcations from the furcation model as a
    branch of the template of the same generation has, drawn together with that branch's
    length, whose children are grown the same way, breadth first (within a generation in an
    order drawn from the seed). A child that cannot start
    at its vertex (crossing, border, or within ``ρ`` of other structure over its first ``3 m h``)
    tries the parent's next-best vertices; a tree left short
    of its template's length gets further furcations on its own branches, and a tree that
    reaches it starts no further children (in further rounds of the deal a prolific template
    branch can come twice, and the numbers of children compound).

    With ``roots`` above 1, or with ``max_length="input"`` (about as much structure as the
    input), further root trees follow once a tree is finished: one per input tree (an input
    whose largest tree holds 90 % of its length gets its trees once per input area, so it stays
    connected), each copying its template's root stem,
    placed where the density along its first ``3 m h`` is lowest among 24 tries, half near
    the root's own (scaled) position (jittered by ``2ρ``; preferred when practically empty,
    so border roots stay at the border) and half anywhere in the image, until ``roots`` trees
    exist, the length or density limit is reached, or eight starts in a row fail. The minor
    trees of a connected input try near their own position only, and not where that density
    is over 0.5: they are pieces of the input's structure in their place, and one without
    room there is left out.

    Parameters
    ----------
    bending : BendingModel
        The bending model.
    furcation : FurcationModel, optional
        The furcation model; without it only the main branch grows.
    size : int or (int, int)
        ``(H, W)`` of the output image (an int: square); every vertex stays inside.
        ``shape`` before (deprecated).
    start : (x, y) or (x, y, heading), optional
        Start of the main branch (heading in radians, counter-clockwise on screen from ``+x``).
        Default: the first point of a polyline ``guide``, else the input root's start scaled
        to ``size``; the heading defaults to the guide's or the input root's.
    seed : int or numpy.random.Generator
        Seed; the same seed gives the same structure.
    generations : int, optional
        Stop criterion: maximum branch generations (1 = main branch only). Default: as deep
        as each tree's template.
    max_length : float or "input", optional
        Stop criterion: maximum total branch length in pixels. ``"input"``: the input's total
        length scaled by the ratio of the image areas (the input's ``shape``, else its bounding
        box), i.e. the input's structure density; then ``roots`` defaults to as many trees as
        needed.
    roots : int, optional
        Maximum number of root trees. Default: 1, or unlimited with ``max_length="input"``.
        ``start`` and a polyline ``guide`` only place the first tree.
    max_density : float, optional
        Stop criterion: maximum mean of the density map ``D`` over the image (in ``(0, 1]``).
    branch_length : float, optional
        Target length of every branch in pixels. Default: drawn from the input's branch
        lengths of the same generation.
    children : int, optional
        Furcations per branch ``d``; default drawn from the input's distribution.
    colonize : bool
        Space colonisation (§4.4): density map with ``Q** = Q* / (D + ε)``, ``1/ε = 10³``.
        Crossing extensions are always rejected, also without colonisation.
    repel_border : bool
        With ``colonize``: the image's border counts as structure in the density a
        candidate sees (``exp(-d²/ρ²)`` at distance ``d`` from the first pixel outside, 1
        beyond it). Beyond the paper, which grows without a frame: without it a tip that
        meets the border can only turn along it, and stems run down the image's edges.
        Off by default: alone it keeps stems off the border but lets them curl in a
        corner; with the bending model's ``total_turn`` they cross the image
        (``docs/pipelines/branching/quality.md``), and :func:`synthesize` turns both on
        where the input's course is known (:func:`course_defaults`).
    rho : float, optional
        Density width ``ρ`` in pixels; default ``m h`` (one bending feature).
    guide : (H, W) array or (n, 2) array, optional
        Guidance (§4.5): an ``(x, y)`` polyline or a boolean ``(H, W)`` path mask, turned into
        ``G = 1 - exp(-d² / w²)`` (a valley of width ``w = guide_width`` along the path), or a
        real ``(H, W)`` map used as ``G`` directly (values in ``[0, 1]``, low = attractive).
        Candidate qualities are divided by ``G_i + ε`` with ``G_i`` the maximum of ``G`` along
        the candidate's direction, as for the density.
    guide_width : float, optional
        Valley width; default ``3 m h``.
    min_spacing : int, optional
        Minimum index distance between furcations on a branch (default: the model's).
    domain : (H, W) array_like of bool, optional
        Where the structure may grow (default everywhere), e.g. the inside of a photo's frame
        (:func:`valid_region` of the input, stretched to ``size``). No vertex leaves it: a
        branch ends where its next extension would, as at the image's border. With
        ``colonize`` the rest counts as structure in the density (``exp(-d²/ρ²)`` at distance
        ``d`` from it, 1 in it), so branches turn away before they meet it and children do not
        start towards it. Further roots start inside only, and the first root, when its
        default start lies outside, at the nearest pixel inside.
    joined_ends : float, optional
        Share of the branches that should end on other structure, in ``[0, 1]`` (default 0:
        the paper's trees, whose branches stop short of structure ahead). Beyond the paper:
        once the structure is grown, ends are carried on to structure within the density's
        look-ahead ``3 m h`` ahead of them by :func:`~phloem.branching.joins.join_ends`, the
        shortest ways first, until that share of the branches end on it, so that channels
        rejoin round islands as a braided river's do. :func:`synthesize` takes the input's
        :func:`~phloem.metrics.joined_end_share`.
    progress : callable, optional
        ``progress(done, total)`` in finished branches.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).

    Returns
    -------
    Skeleton
        The new structure with ``shape``; branch edges have length ``h``.

    Examples
    --------
    >>> from phloem.branching import BendingModel, FurcationModel, synthetic_skeleton
    >>> src = synthetic_skeleton(0)
    >>> bend = BendingModel.fit(src, h=2.0)
    >>> fur = FurcationModel.fit(src, h=2.0)
    >>> out = grow(bend, fur, size=(200, 300), seed=1, generations=2)
    >>> out.shape, len(out.branches) >= 1
    ((200, 300), True)
    >>> out == grow(bend, fur, size=(200, 300), seed=1, generations=2)
    True

    About as much structure per pixel as the input, in as many trees as it takes:

    >>> forest = grow(bend, fur, size=(200, 300), seed=1, max_length="input")
    >>> scale = 200 * 300 / (src.shape[0] * src.shape[1])
    >>> bool(forest.total_length() > 0.8 * scale * src.total_length()), len(forest.branches) > len(out.branches)
    (True, True)
    """
    from .._validate import check_size

    _check_models(bending, furcation)
    shape = check_size(size, "size")
    _memory.check_size(_memory.grow(shape, colonize=bool(colonize), guide=guide is not None), max_memory, shape)
    st = _check_start(start)
    rng = np.random.default_rng(check_seed(seed))
    generations = None if generations is None else check_int(generations, "generations", 1)
    input_sized = isinstance(max_length, str)
    if input_sized and max_length != "input":
        raise ValueError(f"max_length: expected a length in pixels, 'input' or None, got {max_length!r}")
    if input_sized:
        limit = _input_length(bending, shape)
    else:
        limit = math.inf if max_length is None else check_float(max_length, "max_length", 0.0, inclusive=False)
    n_roots = None if roots is None else check_int(roots, "roots", 1)
    dens_limit = None if max_density is None else check_float(max_density, "max_density", 0.0, inclusive=False)
    if dens_limit is not None and dens_limit > 1:
        raise ValueError(f"max_density: expected a value in (0, 1], got {max_density}")
    blen = None if branch_length is None else check_float(branch_length, "branch_length", 0.0, inclusive=False)
    d_fixed = None if children is None else check_int(children, "children", 0)
    h, m = bending.h, bending.m
    rho = m * h if rho is None else check_float(rho, "rho", 0.0, inclusive=False)
    gw = 3.0 * m * h if guide_width is None else check_float(guide_width, "guide_width", 0.0, inclusive=False)
    gmap, gline = (None, None) if guide is None else _guide_map(guide, shape, gw)
    if not isinstance(repel_border, (bool, np.bool_)):
        raise TypeError(f"repel_border: expected True or False, got {repel_border!r}")
    inside = None if domain is None else as_mask(domain, "domain", shape)
    joined_ends = check_float(joined_ends, "joined_ends", 0.0)
    if joined_ends > 1:
        raise ValueError(f"joined_ends: expected a share in [0, 1], got {joined_ends}")
    if inside is not None and not inside.any():
        raise ValueError("domain: expected some pixels where the structure may grow, got none")
    world = _World(
        bending, shape, colonize=bool(colonize), rho=rho, guide=gmap, rng=rng, repel_border=bool(repel_border),
        domain=inside,
    )  # fmt: skip
    grower = _Grower(world, bending)

    H, W = shape
    forest = input_trees(bending.source)
    order = sibling_order(bending.source)
    # a connected input: one structure, stray specks beside it (``_forest.CONNECTED_SHARE``)
    dominant = connected(forest)
    if n_roots is None:
        # A connected input stays connected: its trees once per input area, a tree cut short by
        # the room it finds topped up (see ``_top_up``). A forest takes as many trees as the
        # length needs.
        area_ratio = limit / max(bending.source.total_length(), 1e-9)
        n_roots = (
            1 if not input_sized else (max(1, math.ceil(len(forest) * area_ratio - 1e-9)) if dominant else 1_000_000)
        )
    out: list[Branch] = []
    # (parent branch, vertex, generation, planned length, planned children), one generation
    # after the other (breadth first); within a generation taken in a random order, see _deal_next
    queue: list[tuple[int, int, int, float, int]] = []
    qpos = 0
    block_end = 0  # end of the queued block of the generation being grown
    stop = False
    trees = 0
    turn = 0  # trees attempted: the template of the next one
    tried: dict[int, list[int]] = {}  # furcation vertices used or tried on each branch
    levels: dict[int, F64] = {}  # each branch's end thickness before it tapered
    started: dict[int, list[int]] = {}  # the vertices of each branch's children, in creation order
    failures = 0

    def plan(length: float, kids: int) -> tuple[float, int]:
        """The target length and number of children of a branch: the options, else the template's."""
        return (length if blen is None else blen), (kids if d_fixed is None else d_fixed)

    def template_branch(tree: InputTree | None, gen: int) -> tuple[float, int]:
        drawn = None if tree is None else tree.draw(gen, rng)
        if drawn is None:
            # a template without this generation (only with ``children`` or ``branch_length`` set)
            g = max((x for x in bending.lengths if x <= gen), default=0)
            counts = furcation.counts if furcation is not None else {}
            pool = counts.get(gen) or [c for v in counts.values() for c in v] or [0]
            drawn = float(rng.choice(bending.lengths[g])), int(rng.choice(pool))
        return plan(*drawn)

    while not stop and trees < n_roots and world.total_length < limit:
        # each tree copies one input tree, largest first, then again from the largest
        tree = forest[turn % len(forest)] if forest else None
        if turn == 0 and forest and (st is not None or gline is not None):
            # at a given start any input tree can serve (uniform draw), as a user placing a
            # structure expects variety across seeds, not the same stem
            tree = forest[int(rng.integers(len(forest)))]
        turn += 1
        root = 0 if tree is None else tree.root
        if trees == 0:
            heading, a0, r0, t0 = bending.start_elements(root)
            if st is not None:
                x, y = st[0], st[1]
                if st[2] is not None:
                    heading = st[2]
            elif gline is not None:
                x, y = float(gline[0, 0]), float(gline[0, 1])
            else:
                x, y = _default_start(bending, shape, root)
                if inside is not None:
                    x, y = _nearest_inside(inside, x, y)
            if (st is None or st[2] is None) and gline is not None:
                d = gline[min(1, len(gline) - 1)] - gline[0]
                heading = math.atan2(-d[1], d[0])
            if not (0 <= x <= W - 1 and 0 <= y <= H - 1):
                raise ValueError(f"start: ({x:g}, {y:g}) is outside the {W}x{H} image")
            current = _new_branch(world, grower, np.array([x, y]), heading, t0, a0, r0, None, 0, len(out), partial=True)
            if current is None:
                raise ValueError(
                    f"start: the first edge from ({x:g}, {y:g}) with heading {heading:.2f} leaves the image"
                )
        else:
            # a connected input's minor trees belong where they were; copies of its main tree
            # (a canvas larger than the input) go wherever there is room
            anywhere = not dominant or tree is None or tree is forest[0]
            current = _place_root(world, grower, bending, root, shape, rng, len(out), anywhere=anywhere)
            if current is None and not anywhere:
                # no room in its place: the tree is left out, not replaced by a copy of the main tree
                trees += 1
                continue
            if current is None:
                failures += 1
                if failures >= 8:
                    break
                continue
        goal, d = plan(float(bending.source.branches[root].length()), 0 if tree is None else tree.branches[0][0][1])
        current.profile = bending.stem_profile(root) if bending.stem_thickness > 0 else None
        trees += 1
        first_branch, start_length, top_ups = len(out), world.total_length, 0
        # Children drawn with their template branches' numbers of children compound: uncapped,
        # one tree can outgrow its template and use up the input's length (a forest as one tree).
        full = tree.length if tree is not None and blen is None and d_fixed is None else None
        stalled: bool | None = None  # did the tree's main branch stop short without a single step?
        while current is not None:
            while not stop and current.length() * h < goal:
                if world.total_length >= limit or not grower.step(current):
                    break
                if dens_limit is not None and world.density_mean() >= dens_limit:
                    stop = True
            if stalled is None:
                stalled = current.length() * h < goal - 1e-9 and len(current.alpha) <= len(
                    bending.start_elements(root)[1]
                )
            branch = _finish(grower, current)
            if current.level is not None:
                levels[len(out)] = current.level
            out.append(branch)
            if branch.parent is not None:
                started.setdefault(branch.parent[0], []).append(branch.parent[1])
            stop = stop or world.total_length >= limit
            gen = current.generation + 1
            if (
                not stop
                and furcation is not None
                and d > 0
                and (generations is None or gen < generations)
                and len(branch) >= 3
            ):
                picked = furcation.pick(branch, d, min_spacing=min_spacing, rng=rng)
                planned = _ordered([template_branch(tree, gen) for _ in picked], picked, order, rng)
                for v, (goal_c, d_c) in zip(picked, planned, strict=True):
                    queue.append((len(out) - 1, v, gen, goal_c, d_c))
            if progress is not None:
                progress(len(out), len(out) + len(queue) - qpos)
            current = None
            retries = 0
            while True:
                added = False
                can_top_up = tree is not None and furcation is not None and top_ups < _TOP_UPS
                qpos_was_end = qpos == len(queue)
                if qpos_was_end and can_top_up:
                    assert tree is not None and furcation is not None
                    # Blocked children leave the tree short of its template: more furcations on the
                    # tree's own branches, rather than a new tree, keep the input's connectivity.
                    short = tree.length - (world.total_length - start_length)
                    if not stop and short > 0.05 * tree.length:
                        top_ups += 1
                        extra = _top_up(
                            out, first_branch, tree, furcation, tried, started, rng, generations, min_spacing
                        )
                        if extra is not None:
                            pi, v, gen = extra
                            queue.append((pi, v, gen, *template_branch(tree, gen)))
                            added = True
                while not stop and current is None and qpos < len(queue):
                    if full is not None and world.total_length - start_length >= full:
                        qpos = len(queue)  # the tree is as long as its template: its queued children are left out
                        break
                    if retries == 0:
                        block_end = _deal_next(queue, qpos, block_end, rng)
                    pi, v, gen, goal, d = queue[qpos]
                    assert furcation is not None
                    pb = out[pi]
                    tried.setdefault(pi, []).append(v)
                    for j in furcation.child_start(pb, v, rng)[: max(furcation.c, 4)]:
                        hd = _tangent(pb, v) + float(furcation.offsets[j])
                        if grower.crowded_start(pb.points[v], hd, (pi, v)):
                            continue  # blocked as a crossing start is: the next example, vertex or top-up
                        current = _new_branch(
                            world,
                            grower,
                            pb.points[v],
                            hd,
                            float(furcation.child_r0[j]),
                            furcation.child_alpha[j],
                            furcation.child_r[j],
                            (pi, v),
                            gen,
                            len(out),
                            partial=False,
                        )
                        if current is not None:
                            current.parent_near = grower.near_parent(pb, v)
                            break
                    if current is None and retries < _CHILD_RETRIES:
                        # blocked here (crossing, border, crowding): the same child from the parent's
                        # next-best vertex, kept apart from its siblings still queued as from those tried
                        queued = [e[1] for e in queue[qpos + 1 :] if e[0] == pi]
                        kids = started.get(pi, [])
                        failed = [u for u in tried[pi] if u not in kids]
                        alt = furcation.pick(
                            pb, 1, existing=kids + queued, tried=failed, min_spacing=min_spacing, rng=rng
                        )
                        if alt:
                            queue[qpos] = (pi, alt[0], gen, goal, d)
                            retries += 1
                            continue
                    qpos += 1
                    retries = 0
                # children that could not start (queued or topped up) must not end a tree that is
                # still short: top up again until one starts, the tree is long enough or no
                # branch has room
                if current is not None or stop or not can_top_up or (qpos_was_end and not added):
                    break
        # a tree whose stem could not grow beyond its copied start counts as a failed placement
        failures = failures + 1 if stalled else 0
        if failures >= 8:
            break
    grown = Skeleton(out, shape)
    if joined_ends > 0 and out:
        grown = _joined_untapered(join_ends(grown, joined_ends, reach=3.0 * m * h, step=h, domain=inside), out, levels)
    return grown


@renamed(shape="size")
def extend(
    skeleton: Skeleton,
    branch_index: int,
    bending: BendingModel,
    *,
    steps: int = 1,
    seed: Seed = 0,
    colonize: bool = True,
    rho: float | None = None,
    size: Size | None = None,
) -> Skeleton:
    """Extend one branch's tip by ``steps`` Markov steps of ``m`` elements (§6, interactive use).

    The other branches are obstacles (no crossings) and, with ``colonize``, fill the density
    map. Existing vertices are kept; new vertices are ``h`` apart.

    Parameters
    ----------
    skeleton : Skeleton
        The structure to edit; it is not modified.
    branch_index : int
        Branch whose last vertex is the tip to extend.
    bending : BendingModel
        The bending model.
    steps : int
        Number of extensions (each adds up to ``m`` vertices).
    seed : int or numpy.random.Generator
        Seed.
    colonize : bool
        Use the density map (§4.4).
    rho : float, optional
        Density width; default ``m h``.
    size : int or (int, int), optional
        Image ``(H, W)``; default the skeleton's ``shape`` (required when it has none).
        ``shape`` before (deprecated).

    Returns
    -------
    Skeleton
        A copy with the branch extended (fewer vertices if the tip runs out of valid moves).

    Examples
    --------
    >>> from phloem.branching import BendingModel, synthetic_skeleton
    >>> src = synthetic_skeleton(0)
    >>> bend = BendingModel.fit(src, h=2.0)
    >>> grown = grow(bend, size=(200, 300), seed=0, branch_length=60)
    >>> longer = extend(grown, 0, bend, steps=3, seed=0)
    >>> len(longer.branches[0]) > len(grown.branches[0])
    True
    """
    from .._validate import check_size

    _check_models(bending, None)
    _check_skeleton(skeleton)
    if isinstance(branch_index, bool) or not isinstance(branch_index, numbers.Integral):
        raise TypeError(f"branch_index: expected an integer, got {branch_index!r}")
    if not 0 <= int(branch_index) < len(skeleton.branches):
        raise ValueError(f"branch_index: expected 0 .. {len(skeleton.branches) - 1}, got {branch_index}")
    bi = int(branch_index)
    steps = check_int(steps, "steps", 0)
    if size is None:
        if skeleton.shape is None:
            raise ValueError("size: the skeleton has no shape; pass size=(H, W)")
        size = skeleton.shape
    shape = check_size(size, "size")
    rng = np.random.default_rng(check_seed(seed))
    h, m = bending.h, bending.m
    rho = m * h if rho is None else check_float(rho, "rho", 0.0, inclusive=False)
    world = _World(bending, shape, colonize=bool(colonize), rho=rho, guide=None, rng=rng)
    grower = _Grower(world, bending)
    for b in skeleton.branches:
        world.add_segments(b.points)
        rb = b.resample(h)
        a, r = _elements(rb)
        if len(a):
            world.add_elements(a, r, a, _edge_headings(rb.points))
    target = skeleton.branches[bi]
    # resample from the tip backwards so that the tip stays exactly where it is
    tail = Branch(target.points[::-1].copy(), target.thickness[::-1].copy()).resample(h)
    tail = Branch(tail.points[::-1].copy(), tail.thickness[::-1].copy())
    a, r = _elements(tail)
    d = tail.points[-1] - tail.points[-2]
    br = _Growing(
        [p for p in target.points],
        list(target.thickness),
        list(a[-(bending.k + 1) :]),
        list(r[-(bending.k + 1) :]),
        math.atan2(-d[1], d[0]),
        target.parent,
        0,
        bi,
    )
    if target.parent is not None:
        br.parent_near = grower.near_parent(skeleton.branches[target.parent[0]], target.parent[1])
    hold = math.ceil(3.0 * rho / h) + 1
    for j, b in enumerate(skeleton.branches):
        if j != bi:
            world.stamp(b.points, b.thickness, j, 0)
        elif len(b) - 1 - hold > 0:
            world.stamp(b.points[: len(b) - hold], b.thickness[: len(b) - hold], j, 0)
    br.inserted = max(len(target) - 1 - hold, 0)
    n0 = len(target)
    keep = float(target.thickness[-1])
    for _ in range(steps):
        if not br.alpha or not grower.step(br):
            break
    br.thickness[n0 - 1] = keep
    branches = list(skeleton.branches)
    branches[bi] = Branch(np.asarray(br.points), np.asarray(br.thickness), target.parent)
    return Skeleton(branches, skeleton.shape if skeleton.shape is not None else None)
