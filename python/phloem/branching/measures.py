"""Measures that say whether a synthesised branching structure looks like its input's kind of
structure, beyond the angle and thickness histograms that it matches by construction (issue 19):
does the rendered image show the skeleton it was asked to show (re-trace agreement), does the
structure hold together (largest-tree share), do branches keep a course at the scale of the
structure (heading change over a fixed arc and its histogram distance, "drift"), does a
mask stay a mask (two-level fraction), does the structure stand out from its surroundings
as much as the input's (structure contrast), does it spread over its picture as the input's
does (empty space), do its branches end where the skeleton's do (what stands out past
their ends), do as many of them end on other structure (joined ends), do their ends
thin as the input's do (end taper), and do side branches stay no wider than the branch they
leave (wider children). Re-exported by :mod:`phloem.metrics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .._validate import as_image, as_mask, check_float, check_int
from ._elements import (
    F64,
    _abs_turn,
    _arc_lengths,
    _axis_bins,
    _bin,
    _check_skeleton,
    _dense,
    _edge_headings,
    _end_taper,
    _free_ends,
    _tree_roots,
)
from ._ends import _Lines, _on_structure
from ._layout import DirectionLayout
from .bending import ARC  # the arc the bending model matches, so that the two stay one
from .histograms import _hist, histogram_distance
from .skeleton import Skeleton
from .trace import DEFAULT_SIGMAS, _gray, _resolve_kind, _sigmas, trace

__all__ = [
    "Agreement",
    "background_grain",
    "border_share",
    "direction_concentration",
    "direction_histogram",
    "drift",
    "drift_noise",
    "empty_space",
    "end_taper",
    "furcation_gaps",
    "heading_change_histogram",
    "heading_changes",
    "joined_end_share",
    "largest_tree_share",
    "layout_agreement",
    "median_heading_change",
    "orientation_distance",
    "parent_turns",
    "past_end_share",
    "resolve_trace_options",
    "retrace_agreement",
    "sibling_order",
    "skeleton_agreement",
    "start_turns",
    "structure_contrast",
    "two_level_fraction",
    "wider_children",
]


@dataclass(frozen=True)
class Agreement:
    """How well two skeletons cover each other (see :func:`skeleton_agreement`).

    Attributes
    ----------
    precision : float
        Fraction of the candidate's points within ``tolerance`` of the reference.
    recall : float
        Fraction of the reference's points within ``tolerance`` of the candidate.
    f1 : float
        Their harmonic mean (0 when both are 0).
    tolerance : float
        The matching distance used, px.
    """

    precision: float
    recall: float
    f1: float
    tolerance: float


def _sample(skeleton: Skeleton) -> tuple[F64, F64]:
    parts = [_dense(b, 1.0) for b in skeleton.branches]
    return np.concatenate([p for p, _, _ in parts]), np.concatenate([t for _, t, _ in parts])


def skeleton_agreement(reference: Skeleton, candidate: Skeleton, *, tolerance: float | None = None) -> Agreement:
    """Precision, recall and F1 of ``candidate``'s centre lines against ``reference``'s.

    Both skeletons are sampled along every branch at 1 px spacing; a point matches if a point of
    the other skeleton lies within ``tolerance``. Recall is the fraction of reference points
    matched, precision that of candidate points.

    Parameters
    ----------
    reference, candidate : Skeleton
        E.g. the target skeleton of a synthesis and the skeleton traced from its image.
    tolerance : float, optional
        Matching distance in px (default ``max(3, 1.5 × median radius)`` of the reference, the
        median over its arc length): a traced centre line of a thick branch may sit anywhere
        across its middle.

    Returns
    -------
    Agreement

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> ref = Skeleton([Branch([[0, 10], [100, 10]], 2.0)])
    >>> half = Skeleton([Branch([[0, 11], [50, 11]], 2.0)])
    >>> a = skeleton_agreement(ref, half)
    >>> a.precision, round(a.recall, 2), a.tolerance
    (1.0, 0.52, 3.0)
    """
    _check_skeleton(reference, "reference")
    _check_skeleton(candidate, "candidate")
    ref, thick = _sample(reference)
    cand, _ = _sample(candidate)
    tol = max(3.0, 1.5 * float(np.median(thick))) if tolerance is None else check_float(tolerance, "tolerance", 0.0)
    from scipy.spatial import cKDTree  # type: ignore[import-untyped]

    # The bound is exclusive; "within" includes the tolerance itself.
    bound = tol * (1 + 1e-9) + 1e-12
    precision = float(np.mean(cKDTree(ref).query(cand, distance_upper_bound=bound)[0] <= tol))
    recall = float(np.mean(cKDTree(cand).query(ref, distance_upper_bound=bound)[0] <= tol))
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return Agreement(precision, recall, f1, tol)


def resolve_trace_options(image: Any, trace_options: dict[str, Any] | None = None) -> dict[str, Any]:
    """``trace_options`` with ``kind="auto"`` (or no kind) replaced by the kind :func:`trace` picks on ``image``.

    ``"mask"`` for an image of at most two values, else the stronger ridge polarity. Trace an
    output with the input's resolved options to trace it as the input was traced: an output
    with a few grey pixels is no longer two-valued, and ``"auto"`` would trace it as a photo.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((20, 20), np.float32); img[8:12] = 1
    >>> resolve_trace_options(img), resolve_trace_options(img, {"kind": "dark", "sigmas": 2.0})
    ({'kind': 'mask'}, {'kind': 'dark', 'sigmas': 2.0})
    >>> resolve_trace_options(img + np.linspace(0, 0.1, 20, dtype=np.float32))
    {'kind': 'bright'}
    """
    if trace_options is not None and not isinstance(trace_options, dict):
        raise TypeError(f"trace_options: expected a dict of trace() arguments, got {type(trace_options).__name__}")
    opts = dict(trace_options or {})
    if opts.get("kind", "auto") == "auto":
        gray = _gray(image, opts.get("channel"))
        opts["kind"] = _resolve_kind(gray, _sigmas(opts.get("sigmas", DEFAULT_SIGMAS)))
    return opts


def retrace_agreement(
    image: Any,
    target: Skeleton,
    *,
    trace_options: dict[str, Any] | None = None,
    like: Any = None,
    tolerance: float | None = None,
) -> float:
    """Does ``image`` show ``target``? F1 of ``target`` against the skeleton traced from ``image``.

    The image is traced by :func:`phloem.branching.trace` with ``trace_options`` (pass the ones
    the input was traced with, and the input as ``like`` so that ``kind="auto"`` is resolved on
    the input, :func:`resolve_trace_options`) and compared by :func:`skeleton_agreement` (which
    gives precision and recall too). An image where nothing is traced scores 0. 1 when the
    structure the image shows is the one it was asked to show, near 0 when it shows something
    else. Higher is better.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        A rendered image, e.g. :attr:`SynthesisResult.image`.
    target : Skeleton
        The skeleton it should show, e.g. :attr:`SynthesisResult.target`.
    trace_options : dict, optional
        Keyword arguments of :func:`phloem.branching.trace`.
    like : (P, Q[, C]) array_like, optional
        The input image: trace ``image`` with the kind ``trace`` picks on it.
    tolerance : float, optional
        See :func:`skeleton_agreement`.

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[10, 30], [110, 30]], 4.0)], (60, 120))
    >>> round(retrace_agreement(sk.mask().astype(np.float32), sk, trace_options={"kind": "mask"}), 2)
    1.0
    """
    target = _check_skeleton(target, "target")
    opts = resolve_trace_options(like, trace_options) if like is not None else trace_options
    if opts is not None and not isinstance(opts, dict):
        raise TypeError(f"trace_options: expected a dict of trace() arguments, got {type(opts).__name__}")
    try:
        traced = trace(image, **(opts or {}))
    except ValueError as e:
        if not str(e).startswith("image: nothing to trace"):
            raise
        return 0.0
    return skeleton_agreement(target, traced, tolerance=tolerance).f1


def largest_tree_share(skeleton: Skeleton) -> float:
    """Share of the total branch length that lies in the largest connected tree.

    Trees are given by the branches' ``parent`` links (a branch whose parent is ``None`` starts
    a new tree), not by where branches happen to cross in the image. 1 for a single tree;
    ``1 / n`` for ``n`` equally long separate pieces.

    Parameters
    ----------
    skeleton : Skeleton

    Returns
    -------
    float
        In (0, 1].

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[0, 0], [30, 0]], 1.0), Branch([[15, 0], [15, 10]], 1.0, parent=(0, 1)),
    ...                Branch([[0, 20], [10, 20]], 1.0)])
    >>> largest_tree_share(sk)
    0.8
    """
    _check_skeleton(skeleton)
    lengths = np.bincount(_tree_roots(skeleton), weights=[b.length() for b in skeleton.branches])
    total = float(lengths.sum())
    if total <= 0:
        raise ValueError("skeleton: the branches have no length")
    return float(lengths.max()) / total


def joined_end_share(skeleton: Skeleton) -> float:
    """Share of the branches whose end lies on other structure.

    A branch's end is its last vertex. It lies on other structure where it is within
    :data:`~phloem.branching._ends.END_SLACK` px (2, or half the end's thickness where that
    is more) of another branch's surface (its centre line, widened by its thickness there). Not
    counted as other structure: the branch itself, its children that start at its end, and its
    parent where the two still overlap at the branch's start (within twice their thicknesses
    plus 4 px of it along the parent): a short stub ends beside its parent without closing a
    loop, while an end further along the parent closes one.

    In a braided river, a delta or a crack network many ends lie on other structure: the
    channels rejoin round islands and the trace cuts each loop open at one end. A tree grown
    by the paper's growth stops short of structure ahead, so its ends are free
    (:func:`~phloem.branching.joins.join_ends` joins them).

    Parameters
    ----------
    skeleton : Skeleton

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> stem = Branch([[0, 50], [20, 50], [100, 50]], 3.0)
    >>> loop = Branch([[20, 50], [40, 30], [70, 30], [80, 46]], 2.0, parent=(0, 1))
    >>> joined_end_share(Skeleton([stem, loop]))
    0.5
    >>> short = Branch([[20, 50], [40, 30], [70, 30], [80, 38]], 2.0, parent=(0, 1))
    >>> joined_end_share(Skeleton([stem, short]))
    0.0
    """
    _check_skeleton(skeleton)
    return float(_on_structure(skeleton, _Lines.of(skeleton)).mean())


def end_taper(skeleton: Skeleton) -> F64:
    """How the branches thin towards their ends: thickness over the level before, per vertex.

    For each of a branch's last :data:`~phloem.branching.bending.TAPER_VERTICES` (10)
    vertices, the median over the branches with 6 more vertices before those of its
    thickness over the median of those 6 (the level the end tapers from). Capped at 1 and cut
    to the run below 0.95 that ends at the tip; empty where the ends keep their thickness
    (as a traced photo's do) or fewer than three branches are long enough.

    A traced mask's channels and cracks thin to their ends, and
    :attr:`~phloem.branching.BendingModel.end_taper` is this measure of the input, which a
    grown branch ends with. The measure counts vertices, so compare skeletons resampled to
    the same step (:meth:`~phloem.branching.Skeleton.resample`).

    Parameters
    ----------
    skeleton : Skeleton

    Returns
    -------
    ndarray of float64, shape (T,)
        ``T <= 10`` ratios in ``(0, 0.95)``, the last at the tip.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> ends = [0.9, 0.6, 0.3]
    >>> sk = Skeleton([Branch([[0, 10 * i], [4, 10 * i]], 2.0).resample(0.25) for i in range(3)])
    >>> sk = Skeleton([Branch(b.points, [2.0] * (len(b) - 3) + [2 * e for e in ends]) for b in sk.branches])
    >>> end_taper(sk).round(2).tolist()
    [0.9, 0.6, 0.3]
    >>> end_taper(Skeleton([Branch(b.points, 2.0) for b in sk.branches])).size
    0
    """
    _check_skeleton(skeleton)
    return _end_taper(skeleton)


def wider_children(skeleton: Skeleton, *, factor: float = 1.5) -> float:
    """Share of the child branches that grow wider than ``factor`` times their parent.

    A child's largest thickness against its parent's thickness at the attachment vertex. A
    traced river's or crack's side branches are narrower than the channel they leave, so
    its value is near 0, and a grown child that swells into a wide finger or a round blob
    counts (issue 19; values per input in ``docs/pipelines/branching/quality.md``). A traced
    photo's thickness is noisier, so compare an output with its own input's value.

    Parameters
    ----------
    skeleton : Skeleton
    factor : float
        How much wider than the parent a child must grow to count (at least 1).

    Returns
    -------
    float
        In ``[0, 1]``; NaN where no branch has a parent.

    Raises
    ------
    ValueError
        If ``factor`` is under 1 or not finite.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> stem = Branch([[0, 0], [100, 0]], 4.0).resample(10)
    >>> thin = Branch([[50, 0], [50, 40]], 2.0, (0, 5))
    >>> blob = Branch([[80, 0], [80, 40]], [2.0, 8.0], (0, 8))
    >>> wider_children(Skeleton([stem, thin, blob]))
    0.5
    """
    _check_skeleton(skeleton)
    f = check_float(factor, "factor", 1.0)
    br = skeleton.branches
    wider = [
        float(np.max(b.thickness)) > f * float(br[b.parent[0]].thickness[b.parent[1]])
        for b in br
        if b.parent is not None
    ]
    return float(np.mean(wider)) if wider else math.nan


def border_share(skeleton: Skeleton, *, band: float | None = None) -> float:
    """Share of the total branch length that runs within ``band`` px of the image's border.

    A grown stem that the frame stops runs along it; an input's branches mostly cross the
    frame or stay away from it. Compare an output's share with its input's at the same
    ``band``. Branches are sampled at 1 px; a piece counts if its middle is nearer than
    ``band`` to the first or last row or column.

    Parameters
    ----------
    skeleton : Skeleton
        With its ``shape`` (the image the branches lie in).
    band : float, optional
        Width of the border band in px. Default: 4 × the median thickness over the arc
        length (one bending feature at the default ``h`` and ``m``), at least 2 px.

    Returns
    -------
    float
        In [0, 1]. Lower is further from the frame.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[50, 2], [50, 50]], 1.0)], shape=(100, 100))
    >>> border_share(sk, band=5) == 3 / 48
    True
    """
    _check_skeleton(skeleton)
    if skeleton.shape is None:
        raise ValueError("skeleton: has no shape; border_share needs the image the branches lie in")
    H, W = skeleton.shape
    pts, thick = [], []
    for b in skeleton.branches:
        p, t, _ = _dense(b, 1.0)
        pts.append(p)
        thick.append(t)
    if band is None:
        # thickness weighted by arc length: the 1-px samples are that already
        band = max(2.0, 4.0 * float(np.median(np.concatenate(thick))))
    else:
        band = check_float(band, "band", 0.0, inclusive=False)
    lengths, near = [], []
    for p in pts:
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        mid = 0.5 * (p[1:] + p[:-1])
        d = np.minimum(np.minimum(mid[:, 0], W - 1 - mid[:, 0]), np.minimum(mid[:, 1], H - 1 - mid[:, 1]))
        lengths.append(seg)
        near.append(seg[d < band])
    total = float(np.concatenate(lengths).sum())
    if total <= 0:
        raise ValueError("skeleton: the branches have no length")
    return float(np.concatenate(near).sum()) / total


def layout_agreement(source: Skeleton, skeleton: Skeleton) -> float:
    """How much ``skeleton`` runs the way ``source``'s branches run at the same places of the picture.

    The length-weighted mean, over ``skeleton``'s edges, of ``κ cos 2(θ − φ)``: ``θ`` the
    edge's axis, ``κ`` and ``φ`` the von Mises distribution of axes that ``source``'s
    different branches near there follow (``DirectionLayout``, the ``layout`` growth term's),
    laid over ``skeleton``'s picture. The log-density of the edges under the input's layout,
    less that of directions drawn at random. 0 where the source has no layout (its branches
    agree on no way: cracks, bark) or where the structure runs every way; negative where it
    runs across the input's ways. Compare an output's value with the input's own
    (``layout_agreement(source, source)``): a fundus's vessels grown without the layout give
    about a quarter of it.

    Parameters
    ----------
    source : Skeleton
        The input's structure (its ``shape`` gives its picture; else its bounds).
    skeleton : Skeleton
        The structure measured; its ``shape`` gives its picture (else ``source``'s).

    Returns
    -------
    float

    Examples
    --------
    Ten parallel lines: a line along them agrees, one across them disagrees.

    >>> from phloem.branching import Branch, Skeleton
    >>> src = Skeleton([Branch([[20, y], [280, y]], 1.0) for y in range(60, 241, 20)], shape=(300, 300))
    >>> along = Skeleton([Branch([[50, 150], [250, 150]], 1.0)], shape=(300, 300))
    >>> across = Skeleton([Branch([[150, 50], [150, 250]], 1.0)], shape=(300, 300))
    >>> layout_agreement(src, along) > 2, layout_agreement(src, across) < -2
    (True, True)
    """
    _check_skeleton(source, "source")
    _check_skeleton(skeleton)
    lay = DirectionLayout.fit(source)
    shape = skeleton.shape if skeleton.shape is not None else lay.shape
    num = den = 0.0
    for b in skeleton.branches:
        p = np.asarray(b.points, np.float64)
        if len(p) < 2:
            continue
        length = np.hypot(*np.diff(p, axis=0).T)
        kappa, phi = lay.sample(0.5 * (p[1:] + p[:-1]), shape)
        num += float(np.sum(length * kappa * np.cos(2.0 * (_edge_headings(p) - phi))))
        den += float(length.sum())
    if den <= 0:
        raise ValueError("skeleton: has no length to measure")
    return num / den


def empty_space(skeleton: Skeleton, *, valid: Any = None, quantile: float = 0.9) -> float:
    """How far the picture's emptiest places lie from the structure: the ``quantile`` of the
    distance from every pixel (of ``valid``) to the nearest centre line, in px.

    The empty-space function of spatial statistics at one level. A structure that spreads over
    its picture as the input's does leaves no place far from it; one grown into a knot leaves
    half the picture empty, whatever its histograms, drift and re-trace agreement say. Compare
    an output's value with its input's at the same picture size. Branches are sampled every half pixel.

    Parameters
    ----------
    skeleton : Skeleton
        With its ``shape`` (the image the branches lie in).
    valid : (H, W) array_like of bool, optional
        The pixels that count (default all): a fundus photo's disc, not its black surround.
    quantile : float
        In [0, 1]; 0.9 by default (the emptiest tenth of the picture), 0.5 for the median.

    Returns
    -------
    float
        In px, at least 0.

    Examples
    --------
    A vertical line down the middle of a 100-px square leaves the tenth of the picture
    farthest from it within 5 px of the sides.

    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[50, 0], [50, 99]], 1.0)], shape=(100, 100))
    >>> round(empty_space(sk), 1)
    45.0
    """
    _check_skeleton(skeleton)
    if skeleton.shape is None:
        raise ValueError("skeleton: has no shape; empty_space needs the image the branches lie in")
    shape = (int(skeleton.shape[0]), int(skeleton.shape[1]))
    q = check_float(quantile, "quantile", 0.0)
    if q > 1.0:
        raise ValueError(f"quantile: expected a value in [0, 1], got {quantile}")
    ok = None if valid is None else as_mask(valid, "valid", shape)
    if ok is not None and not ok.any():
        raise ValueError("valid: expected at least one pixel set, got an empty mask")
    _, dist, _ = _thickness_distance(skeleton, shape)
    return float(np.quantile(dist if ok is None else dist[ok], q))


def _check_arc(arc: Any) -> float:
    return check_float(arc, "arc", 0.0, inclusive=False)


def _chord_headings(pts: F64, s: F64, at: F64, w: float) -> F64:
    """Directions (radians) of the chords from arc positions ``at - w/2`` to ``at + w/2`` along
    a polyline ``pts`` with arc positions ``s``: a tangent that pixel noise does not swing."""
    x0, y0 = np.interp(at - w / 2, s, pts[:, 0]), np.interp(at - w / 2, s, pts[:, 1])
    x1, y1 = np.interp(at + w / 2, s, pts[:, 0]), np.interp(at + w / 2, s, pts[:, 1])
    return np.asarray(np.arctan2(y1 - y0, x1 - x0), dtype=np.float64)


def heading_changes(skeleton: Skeleton, *, arc: float = ARC) -> F64:
    """Absolute change of heading over ``arc`` px of branch, at every px along every branch.

    At arc position ``s`` the heading is the direction of the chord from ``s - w/2`` to
    ``s + w/2`` with ``w = arc / 6`` (a tangent that pixel-level noise of a traced centre line
    does not swing; on a circle the chord is parallel to the tangent at its middle, so the
    measure is exact there); the value is ``|θ(s + arc) - θ(s)|``, wrapped to ``[0, π]``, for
    every ``s`` (1 px apart) where both chords lie on the branch. Branches shorter than
    ``7 arc / 6`` give no values. A straight branch gives 0, a circular arc of radius ``R``
    gives ``arc / R`` (up to π).

    Parameters
    ----------
    skeleton : Skeleton
    arc : float, optional
        Arc length in px (default 60, the scale issue 19 reports; compare an output with its
        input at the same image scale, or pass a multiple of the median thickness to compare
        structures of different scales).

    Returns
    -------
    ndarray of float64
        Radians; empty when no branch is long enough.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> t = np.linspace(0, np.pi, 400)
    >>> circle = Skeleton([Branch(np.c_[100 + 50 * np.cos(t), 100 - 50 * np.sin(t)], 1.0)])
    >>> bool(np.allclose(heading_changes(circle, arc=30), 30 / 50, atol=1e-3))
    True
    """
    _check_skeleton(skeleton)
    out = _branch_changes(skeleton, _check_arc(arc))
    return np.concatenate(out) if out else np.zeros(0)


def _branch_changes(skeleton: Skeleton, a: float) -> list[F64]:
    """:func:`heading_changes` branch by branch, for the branches long enough to give any."""
    half = a / 12
    out = []
    for b in skeleton.branches:
        pts, _, s = _dense(b, 1.0)
        total = float(s[-1])
        if total < a + 2 * half:
            continue
        start = np.arange(half, total - a - half + 1e-9, 1.0)
        turn = _chord_headings(pts, s, start + a, 2 * half) - _chord_headings(pts, s, start, 2 * half)
        out.append(_abs_turn(turn))
    return out


def _parts_or_raise(skeleton: Skeleton, arc: float, name: str) -> list[F64]:
    """:func:`_branch_changes` of a checked skeleton, raising when no branch is long enough."""
    a = _check_arc(arc)
    parts = _branch_changes(_check_skeleton(skeleton, name), a)
    if not parts:
        raise ValueError(f"{name}: no branch is at least {7 * a / 6:g} px long (arc={arc:g} and its tangents)")
    return parts


def _changes_or_raise(skeleton: Skeleton, arc: float, name: str) -> F64:
    return np.concatenate(_parts_or_raise(skeleton, arc, name))


def start_turns(skeleton: Skeleton, *, arc: float = 20.0) -> F64:
    """How much every child branch turns over its first ``arc`` px: hooks where children start.

    The heading at arc position ``s`` is the chord from ``s - w/2`` to ``s + w/2`` (``w = arc /
    6``, as in :func:`heading_changes`), taken at most 1 px apart from ``w/2`` to ``min(arc, L) - w/2``
    (``L`` the branch's length) and unwrapped, so a loop reads more than π. The value is the
    absolute difference between the last heading and the first. A child that leaves its parent
    and runs on gives a small value; one that hooks back gives more than π/2. Branches without
    a parent, and children shorter than ``w`` + 1 px, give no value.

    Parameters
    ----------
    skeleton : Skeleton
    arc : float, optional
        Arc length in px from the child's start (default 20).

    Returns
    -------
    ndarray of float64
        Radians, one per child long enough, in branch order.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> t = np.linspace(0, np.pi, 200)
    >>> hook = Branch(np.c_[100 + 5 * np.sin(t), 50 - 5 * np.cos(t)], 1.0, parent=(0, 50))
    >>> stem = Branch(np.c_[np.linspace(0, 200, 101), np.full(101, 50.0)], 1.0)
    >>> turns = start_turns(Skeleton([stem, hook]), arc=12)
    >>> bool(abs(turns[0] - 12 / 5 * (1 - 1 / 6)) < 0.05)
    True
    """
    _check_skeleton(skeleton)
    a = _check_arc(arc)
    w = a / 6
    out = []
    for b in skeleton.branches:
        if b.parent is None:
            continue
        pts, _, s = _dense(b, 1.0)
        end = min(a, float(s[-1]))
        if end < w + 1.0:
            continue
        at = np.linspace(w / 2, end - w / 2, math.ceil(end - w) + 1)
        theta = np.unwrap(_chord_headings(pts, s, at, w))
        out.append(abs(float(theta[-1] - theta[0])))
    return np.asarray(out, dtype=np.float64)


def furcation_gaps(skeleton: Skeleton) -> F64:
    """Arc length between neighbouring children's attachments on each parent: combs of children.

    For every branch with two or more children, the distances along it between consecutive
    attachment vertices (children attached at one vertex give 0). A structure whose children
    are packed along their parents, or spaced more evenly than its input's, shows it in the
    low quantiles.

    Parameters
    ----------
    skeleton : Skeleton

    Returns
    -------
    ndarray of float64
        Pixels, parents in branch order, each parent's gaps from its start to its end.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> stem = Branch(np.c_[np.linspace(0, 100, 51), np.full(51, 50.0)], 1.0)
    >>> kids = [Branch([[x, 50.0], [x, 20.0]], 1.0, parent=(0, x // 2)) for x in (60, 20, 30)]
    >>> furcation_gaps(Skeleton([stem, *kids])).tolist()
    [10.0, 30.0]
    """
    _check_skeleton(skeleton)
    at: dict[int, list[int]] = {}
    for b in skeleton.branches:
        if b.parent is not None:
            at.setdefault(b.parent[0], []).append(b.parent[1])
    out: list[F64] = []
    for i in sorted(at):
        if len(at[i]) < 2:
            continue
        s = _arc_lengths(skeleton.branches[i])
        out.append(np.diff(s[np.sort(np.asarray(at[i]))]))
    return np.concatenate(out) if out else np.zeros(0, np.float64)


def parent_turns(skeleton: Skeleton, *, arc: float = 20.0) -> F64:
    """How the parent turns where each child leaves it, positive when it turns away from the child.

    At a child's attachment, at arc position ``s`` on its parent, the parent's heading at
    ``s - arc/2`` and at ``s + arc/2`` (chords of ``w = arc / 6``, as in :func:`heading_changes`)
    differ by the turn ``τ``, wrapped to ``(-π, π]``. The child's side is the side of the
    parent's tangent at ``s`` on which the child's point ``arc / 2`` along it lies. The value is
    ``τ`` signed so that it is positive when the parent turns away from that side. Real
    junctions open as a ``Y``: the parent bends away from the child it gives off (a river at a
    confluence, a vessel or a root at a fork), so an input's values lie mostly above 0 and
    their median above its branches' typical turn over ``arc``; a structure whose children
    leave straight parents at random places gives values spread round 0.

    Children whose attachment lies less than ``(arc + w) / 2`` from either end of the parent,
    and children shorter than ``arc / 2``, give no value.

    Parameters
    ----------
    skeleton : Skeleton
    arc : float, optional
        Arc length in px across the attachment (default 20).

    Returns
    -------
    ndarray of float64
        Radians, one per child measured, in branch order.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> stem = Branch([[0.0, 100.0], [100.0, 100.0], [200.0, 80.0]], 1.0)  # bends up at x = 100
    >>> below = Branch([[100.0, 100.0], [140.0, 140.0]], 1.0, parent=(0, 1))
    >>> above = Branch([[100.0, 100.0], [140.0, 60.0]], 1.0, parent=(0, 1))
    >>> t = parent_turns(Skeleton([stem, below, above]), arc=40)
    >>> bool(t[0] > 0.1 and t[1] == -t[0])
    True
    """
    _check_skeleton(skeleton)
    a = _check_arc(arc)
    w = a / 6
    dense: dict[int, tuple[F64, F64, F64]] = {}
    out = []
    for b in skeleton.branches:
        if b.parent is None:
            continue
        pi, v = b.parent
        if pi not in dense:
            pts, _, s = _dense(skeleton.branches[pi], 1.0)
            dense[pi] = (pts, s, _arc_lengths(skeleton.branches[pi]))
        pts, s, cum = dense[pi]
        at = float(cum[v])
        cs = _arc_lengths(b)
        if at - (a + w) / 2 < 0 or at + (a + w) / 2 > s[-1] or cs[-1] < a / 2:
            continue
        before, here, after = _chord_headings(pts, s, np.array([at - a / 2, at, at + a / 2]), w)
        turn = (after - before + math.pi) % (2 * math.pi) - math.pi
        # the child's side of the parent's tangent: the sign of their cross product
        cx = float(np.interp(a / 2, cs, b.points[:, 0]) - b.points[0, 0])
        cy = float(np.interp(a / 2, cs, b.points[:, 1]) - b.points[0, 1])
        side = math.copysign(1.0, math.cos(here) * cy - math.sin(here) * cx)
        out.append(-side * turn)
    return np.asarray(out, dtype=np.float64)


#: Fewest children (of parents with at least three) for :func:`sibling_order` to be measured.
MIN_SIBLINGS = 10


def sibling_order(skeleton: Skeleton) -> float:
    """Where along their parent the long children leave: Spearman's rank correlation of place and length.

    Pooled over the parents with at least three children: each child's attachment, as a share
    of its parent's arc length, against the child's own length. Negative where the long
    children leave near their parent's start and the short ones near its end, as in a tree's
    crown or a river network (the traced real inputs measure -0.06 to -0.42); near 0 where
    they are dealt along the parent at random.

    Parameters
    ----------
    skeleton : Skeleton
        A traced input or a grown output; its ``parent`` links say which branch is whose child.

    Returns
    -------
    float
        In [-1, 1]; 0 with fewer than :data:`MIN_SIBLINGS` such children, or where the places
        or the lengths are all equal.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> stem = Branch(np.c_[np.linspace(0, 240, 121), np.full(121, 100.0)], 1.0)
    >>> kids = [Branch([[20 * k, 100.0], [20 * k, 100.0 - 90 + 6 * k]], 1.0, parent=(0, 10 * k))
    ...         for k in range(1, 12)]
    >>> round(sibling_order(Skeleton([stem, *kids])), 6)
    -1.0
    """
    _check_skeleton(skeleton)
    kids: dict[int, list[int]] = {}
    for i, b in enumerate(skeleton.branches):
        if b.parent is not None:
            kids.setdefault(b.parent[0], []).append(i)
    where: list[float] = []
    length: list[float] = []
    for p, ks in kids.items():
        if len(ks) < 3:
            continue
        arc = _arc_lengths(skeleton.branches[p])
        for k in ks:
            at = skeleton.branches[k].parent
            assert at is not None
            where.append(float(arc[min(at[1], len(arc) - 1)] / max(float(arc[-1]), 1e-9)))
            length.append(skeleton.branches[k].length())
    if len(where) < MIN_SIBLINGS:
        return 0.0
    from scipy.stats import rankdata  # type: ignore[import-untyped]  # (as trace imports scipy: lazily)

    rw, rl = rankdata(where), rankdata(length)  # ties share their mean rank, as Spearman's takes them
    if rw.std() == 0 or rl.std() == 0:
        return 0.0
    return float(np.corrcoef(rw, rl)[0, 1])


def _edge_axes(skeleton: Skeleton, name: str) -> tuple[F64, F64]:
    """Every edge's axis on the image (radians in ``[0, π)``, counter-clockwise on screen) and its length."""
    _check_skeleton(skeleton, name)
    d = np.concatenate([np.diff(np.asarray(b.points, np.float64), axis=0) for b in skeleton.branches])
    length = np.hypot(d[:, 0], d[:, 1])
    if not length.sum() > 0:
        raise ValueError(f"{name}: the skeleton has no length")
    return np.mod(np.arctan2(-d[:, 1], d[:, 0]), math.pi), length


def direction_histogram(skeleton: Skeleton, *, bins: int = 12) -> tuple[F64, F64]:
    """Length-weighted histogram of the directions the skeleton's edges run on the image.

    Directions are axes (an edge and its reverse fall in one bin), counted counter-clockwise
    on screen from the image's x axis, in bins centred on ``0, π / bins, …`` (the first holds
    the axes within half a bin of horizontal, either side): a trace does not say which end of
    a branch is its start. Lightning that hangs down has its mass around ``π / 2``; a structure
    that runs every way is flat.

    Parameters
    ----------
    skeleton : Skeleton
    bins : int, optional
        Number of bins (default 12, 15° each).

    Returns
    -------
    hist : ndarray of float64, shape (bins,)
        Shares of the total length, summing to 1.
    edges : ndarray of float64, shape (bins + 1,)
        From ``-π / (2 bins)`` to ``π - π / (2 bins)``.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> hist, _ = direction_histogram(Skeleton([Branch([[5, 0], [5, 90], [35, 90]], 1.0)]), bins=2)
    >>> hist.tolist()
    [0.25, 0.75]
    """
    bins = check_int(bins, "bins", 1)
    axis, length = _edge_axes(skeleton, "skeleton")
    counts = np.bincount(_axis_bins(axis, bins), weights=length, minlength=bins)
    half = math.pi / (2 * bins)
    return counts / counts.sum(), np.linspace(-half, math.pi - half, bins + 1)


def direction_concentration(skeleton: Skeleton) -> float:
    """How much the skeleton runs along one axis on the image: the length-weighted mean
    resultant length of its edges' doubled directions (axial data), in ``[0, 1]``.

    1 when every edge lies along one line, about 0 for a structure that runs every way (or
    along two perpendicular axes equally).

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> direction_concentration(Skeleton([Branch([[0, 0], [0, 50], [0, 100]], 1.0)]))
    1.0
    >>> round(direction_concentration(Skeleton([Branch([[0, 0], [50, 0], [50, 50]], 1.0)])), 6)
    0.0
    """
    axis, length = _edge_axes(skeleton, "skeleton")
    return float(abs(np.sum(length * np.exp(2j * axis))) / length.sum())


def orientation_distance(reference: Skeleton, candidate: Skeleton, *, bins: int = 12) -> float:
    """L1 distance of the two skeletons' :func:`direction_histogram`: does the candidate run the
    ways its reference runs on the image (bolts that hang down, roots that spread sideways)?

    The paper's measures compare angles between successive edges, which do not change when a
    structure is turned; this one does. 0 when the directions are shared in the same
    proportions, 2 when no bin is shared. Lower is better.

    Parameters
    ----------
    reference, candidate : Skeleton
        E.g. the input's skeleton and the synthesised one.
    bins : int, optional
        See :func:`direction_histogram`.

    Returns
    -------
    float
        In [0, 2].

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> down = Skeleton([Branch([[10, 0], [10, 100]], 1.0)])
    >>> across = Skeleton([Branch([[0, 10], [100, 10]], 1.0)])
    >>> orientation_distance(down, down), orientation_distance(down, across)
    (0.0, 2.0)
    """
    a = direction_histogram(_check_skeleton(reference, "reference"), bins=bins)[0]
    b = direction_histogram(_check_skeleton(candidate, "candidate"), bins=bins)[0]
    return histogram_distance(a, b)


def median_heading_change(skeleton: Skeleton, *, arc: float = ARC) -> float:
    """The median of :func:`heading_changes`, in radians: how much branches turn over ``arc`` px.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> median_heading_change(Skeleton([Branch([[0, 0], [200, 0]], 1.0)]))
    0.0
    """
    return float(np.median(_changes_or_raise(skeleton, arc, "skeleton")))


def heading_change_histogram(skeleton: Skeleton, *, arc: float = ARC, bins: int = 16) -> tuple[F64, F64]:
    """Normalised histogram of :func:`heading_changes` over ``[0, π]``.

    Parameters
    ----------
    skeleton : Skeleton
    arc : float, optional
        See :func:`heading_changes`.
    bins : int, optional
        Number of bins (default 16, as the angle histograms).

    Returns
    -------
    hist : ndarray of float64, shape (bins,)
        Fractions summing to 1.
    edges : ndarray of float64, shape (bins + 1,)

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> hist, edges = heading_change_histogram(Skeleton([Branch([[0, 0], [200, 0]], 1.0)]), bins=4)
    >>> hist.tolist(), round(float(edges[1]), 4)
    ([1.0, 0.0, 0.0, 0.0], 0.7854)
    """
    return _histogram(skeleton, arc, bins, "skeleton")


def _histogram(skeleton: Skeleton, arc: float, bins: int, name: str) -> tuple[F64, F64]:
    return _hist(_changes_or_raise(skeleton, arc, name), bins, (0.0, math.pi), name)


def drift(reference: Skeleton, candidate: Skeleton, *, arc: float = ARC, bins: int = 16) -> float:
    """L1 distance of the heading-change histograms (:func:`heading_change_histogram`) of two skeletons.

    0 when the candidate's branches turn over ``arc`` px exactly as the reference's do, 2 when
    the two histograms share no bin. A candidate whose branches wander and curl where the
    reference's keep a course has its mass in higher bins. Lower is better.

    Parameters
    ----------
    reference, candidate : Skeleton
        E.g. the input's skeleton and the synthesised one.
    arc, bins : optional
        See :func:`heading_change_histogram`.

    Returns
    -------
    float
        In [0, 2].

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> line = Skeleton([Branch([[0, 0], [200, 0]], 1.0)])
    >>> t = np.linspace(0, np.pi, 400)
    >>> circle = Skeleton([Branch(np.c_[100 + 50 * np.cos(t), 100 - 50 * np.sin(t)], 1.0)])
    >>> drift(line, line), drift(line, circle)
    (0.0, 2.0)
    """
    a = _histogram(reference, arc, bins, "reference")[0]
    b = _histogram(candidate, arc, bins, "candidate")[0]
    return histogram_distance(a, b)


def drift_noise(
    skeleton: Skeleton,
    *,
    arc: float = ARC,
    bins: int = 16,
    quantile: float = 0.9,
    resamples: int = 400,
    seed: int = 0,
) -> float:
    """The drift that a skeleton's own sampling noise reaches: a scale for :func:`drift`.

    A structure with little long branch has a noisy heading-change histogram, so another
    structure drawn from the same process differs from it by a drift well above 0. The
    heading changes (:func:`heading_changes`, one per px of branch) are cut into stretches of
    ``arc`` px along each branch, the blocks of a block bootstrap (neighbouring values share
    most of their arc, so single values are not independent). This draws ``resamples``
    bootstrap samples of the blocks (as many as there are, with replacement) and returns the
    ``quantile`` of their drift to the whole skeleton. A bootstrap sample differs from the
    skeleton about as much as the skeleton differs from its process, which is less than two
    independent samples of the process differ, so the value is a lower bound on the drift a
    faithful synthesis can be expected to show against its input.

    Parameters
    ----------
    skeleton : Skeleton
        E.g. the input's skeleton.
    arc, bins : optional
        See :func:`drift`.
    quantile : float, optional
        In [0, 1] (default 0.9).
    resamples : int, optional
        Bootstrap samples (default 400).
    seed : int, optional
        Seed of the resampling (default 0).

    Returns
    -------
    float
        In [0, 2]; 0 when every block has the same histogram (e.g. arcs of one radius).

    Raises
    ------
    ValueError
        When no branch is long enough for ``arc``, or all together hold a single block.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> t = np.linspace(0, np.pi, 400)
    >>> arcs = [Branch(np.c_[100 + r * np.cos(t), 100 - r * np.sin(t)], 1.0) for r in (60, 90, 30, 40)]
    >>> drift_noise(Skeleton(arcs[:1])), drift_noise(Skeleton(arcs)) > 0.5
    (0.0, True)
    """
    nb = check_int(bins, "bins", 1)
    q = check_float(quantile, "quantile", 0.0)
    if q > 1.0:
        raise ValueError(f"quantile: expected a number in [0, 1], got {quantile!r}")
    n_res = check_int(resamples, "resamples", 1)
    parts = _parts_or_raise(skeleton, arc, "skeleton")
    block = max(1, math.ceil(_check_arc(arc)))
    blocks = [v[i : i + block] for v in parts for i in range(0, len(v), block)]
    if len(blocks) < 2:
        raise ValueError(f"skeleton: its long branches hold a single stretch of {arc:g} px; the noise needs two")
    counts = np.stack([np.bincount(_bin(v, 0.0, math.pi, nb), minlength=nb) for v in blocks]).astype(np.float64)
    whole = counts.sum(axis=0) / counts.sum()
    rng = np.random.default_rng(check_int(seed, "seed", 0))
    picks = rng.integers(0, len(blocks), size=(n_res, len(blocks)))
    times = np.stack([np.bincount(p, minlength=len(blocks)) for p in picks]).astype(np.float64)
    boot = times @ counts
    boot /= boot.sum(axis=1, keepdims=True)
    return float(np.quantile(np.abs(boot - whole).sum(axis=1), q))


def two_level_fraction(image: Any, reference: Any, *, tolerance: float = 0.05) -> float:
    """Fraction of ``image``'s pixels at one of the two values of a two-level ``reference`` (a mask).

    Values are measured in the reference's range scaled to [0, 1] (its lower value 0, its upper
    1); a pixel counts if every channel is within ``tolerance`` of the same level. 1 when the
    output is a mask of the same two values; grey ramps and blurred edges lower it. Higher is
    better.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The output, with the reference's channel count (any size).
    reference : (P, Q[, C]) array_like
        The input; at most two distinct values.
    tolerance : float, optional
        Distance to a level that still counts, in the normalised range (default 0.05).

    Returns
    -------
    float
        In [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.zeros((10, 10), np.float32); mask[:, :5] = 1
    >>> out = mask.copy(); out[:, 4:6] = 0.5
    >>> two_level_fraction(out, mask)
    0.8
    """
    img = as_image(image, "image")
    ref = as_image(
        np.asarray(reference, dtype=np.float32) if np.asarray(reference).dtype == np.bool_ else reference, "reference"
    )
    if img.shape[2] != ref.shape[2]:
        raise ValueError(f"image: expected {ref.shape[2]} channels like reference, got {img.shape[2]}")
    tol = check_float(tolerance, "tolerance", 0.0)
    levels = np.unique(ref.reshape(-1, ref.shape[2]), axis=0)
    if len(levels) != 2:
        raise ValueError(f"reference: expected a two-level image (a mask), got {len(levels)} distinct values")
    lo, hi = levels[0].astype(np.float64), levels[1].astype(np.float64)
    span = np.where(hi != lo, np.abs(hi - lo), 1.0)
    d_lo = (np.abs(img - lo) / span).max(axis=2)
    d_hi = (np.abs(img - hi) / span).max(axis=2)
    return float(np.mean(np.minimum(d_lo, d_hi) <= tol))


def structure_contrast(image: Any, skeleton: Skeleton, *, ring: tuple[float, float] = (3.0, 4.0)) -> float:
    """How much the structure stands out on ``image``: the median brightness on ``skeleton``'s
    centre lines minus the median over its surroundings.

    Brightness is the mean over channels. The surroundings are the pixels between ``ring[0]``
    and ``ring[1]`` times the thickness of the nearest centre-line point away from it (just
    beyond a fragment's disk, whose radius is three thicknesses); whatever lies there, a glow,
    a shadow or untraced structure, counts. Positive for bright structure (lightning, roots),
    negative for dark (vessels, cracks). An output's contrast over its input's says how much
    of it the output kept: below 1 the structure is fainter than the input's.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The image the skeleton lies in.
    skeleton : Skeleton
        Its structure, with ``image``'s shape (or none).
    ring : (float, float), optional
        Inner and outer radius of the surroundings in thicknesses (default 3 and 4).

    Returns
    -------
    float
        In [-1, 1] for images in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> img = np.full((40, 80), 0.2, np.float32); img[18:23, 10:70] = 0.9
    >>> sk = Skeleton([Branch([[10, 20], [69, 20]], 2.0)], (40, 80))
    >>> round(structure_contrast(img, sk), 3)
    0.7
    """
    img, (H, W) = _image_of(image, skeleton)
    vals = np.asarray(ring, np.float64).ravel() if np.size(ring) == 2 else np.zeros(0)
    if vals.size != 2 or not (np.isfinite(vals).all() and 0 < vals[0] < vals[1]):
        raise ValueError(f"ring: expected (inner, outer) with 0 < inner < outer, got {ring!r}")
    inner, outer = float(vals[0]), float(vals[1])
    drawn, dist, r = _thickness_distance(skeleton, (H, W))
    around = (dist >= inner * r) & (dist < outer * r) & (dist >= 1.0)
    if not around.any():
        raise ValueError("skeleton: the surroundings of the structure lie outside the image")
    light = img.mean(axis=2)
    return float(np.median(light[drawn]) - np.median(light[around]))


#: A branch's tube past its free ends: this many times its thickness plus ``END_TUBE_ADD`` px.
#: :func:`past_end_share` counts beyond it, and :func:`~phloem.branching.render` paints an end
#: fragment only inside it, so that the measure and the rule agree.
END_TUBE, END_TUBE_ADD = 1.5, 2.0


def past_end_share(image: Any, skeleton: Skeleton) -> float:
    """The share of the pixels just past ``skeleton``'s free ends that stand out on ``image`` as
    its structure does: pieces of structure that the skeleton does not hold, where its branches
    end (issue 19: "branch ends never paste pieces of other structure").

    A free end is every branch's last point and a root branch's first. Past an end of
    thickness ``t`` are the pixels within ``3 t`` of it (a fragment's disk, at least 2 px) that
    lie off the structure: farther from every centre line than 1.5 times that point's
    thickness plus 2 px (the tube a branch's end paints in :func:`~phloem.branching.render`).
    Such a pixel stands out if it differs from the median of the end's surroundings (off the
    structure, ``3 t`` to ``3 t + max(t, 2)`` px from the end) by more than half of
    :func:`structure_contrast`, towards the structure's side. Brightness is the mean over
    channels. On an input, past its traced ends lies whatever stopped the trace (a crossing, a
    tangle of finer structure, a fading tip), so its share is not 0; on an output of
    :func:`~phloem.branching.render` with its target skeleton it is near 0 wherever the
    structure stands out from the background's grain (on a faint crack in asphalt, whose
    contrast is about the grain's, a share of the grain counts too).

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The image the skeleton lies in.
    skeleton : Skeleton
        Its structure, with ``image``'s shape (or none).

    Returns
    -------
    float
        In [0, 1].

    Raises
    ------
    ValueError
        If the structure does not stand out from its surroundings, or no pixel past an end
        lies in the image.

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> img = np.full((40, 80), 0.8, np.float32); img[18:23, 10:50] = 0.1
    >>> sk = Skeleton([Branch([[10, 20], [49, 20]], 2.0)], (40, 80))
    >>> past_end_share(img, sk)
    0.0
    >>> img[18:23, 50:56] = 0.1  # the dark line goes on past the skeleton's end
    >>> round(past_end_share(img, sk), 2)
    0.15
    """
    img, (H, W) = _image_of(image, skeleton)
    contrast = structure_contrast(img, skeleton)
    if contrast == 0.0:
        raise ValueError("image: the structure does not stand out from its surroundings")
    light = img.mean(axis=2) * np.float32(math.copysign(1.0, contrast))  # the structure's side up
    _, dist, r = _thickness_distance(skeleton, (H, W))
    off = dist > END_TUBE * r + END_TUBE_ADD
    hit = total = 0
    for b in skeleton.branches:
        for v in _free_ends(b):
            (x, y), t = b.points[v], float(b.thickness[v])
            near = max(3.0 * t, 2.0)
            outer = near + max(t, 2.0)
            x0, x1 = max(0, math.floor(x - outer)), min(W, math.ceil(x + outer) + 1)
            y0, y1 = max(0, math.floor(y - outer)), min(H, math.ceil(y + outer) + 1)
            if x0 >= x1 or y0 >= y1:
                continue
            yy, xx = np.mgrid[y0:y1, x0:x1]
            d = np.hypot(xx - x, yy - y)
            here, ring = off[y0:y1, x0:x1] & (d <= near), off[y0:y1, x0:x1] & (d > near) & (d <= outer)
            if not (here.any() and ring.any()):
                continue
            level = float(np.median(light[y0:y1, x0:x1][ring]))
            hit += int((light[y0:y1, x0:x1][here] - level > 0.5 * abs(contrast)).sum())
            total += int(here.sum())
    if total == 0:
        raise ValueError(
            "skeleton: no pixel within 3 thicknesses of its ends lies in the image and off its tube "
            "(1.5 thicknesses + 2 px; ends under 1.4 px thick have none)"
        )
    return hit / total


def _image_of(image: Any, skeleton: Skeleton) -> tuple[NDArray[np.float32], tuple[int, int]]:
    """``image`` as (H, W, C) float32 and its size, checked against ``skeleton``'s."""
    img = as_image(image, "image")
    _check_skeleton(skeleton)
    H, W = img.shape[:2]
    if skeleton.shape is not None and skeleton.shape != (H, W):
        raise ValueError(f"skeleton: made for a {skeleton.shape} image, but image is {(H, W)}")
    return img, (H, W)


def _thickness_distance(skeleton: Skeleton, shape: tuple[int, int]) -> tuple[NDArray[np.bool_], F64, F64]:
    """``skeleton``'s centre-line pixels on a ``shape`` image, every pixel's distance to the
    nearest of them, and that one's thickness."""
    from scipy import ndimage  # type: ignore[import-untyped]

    H, W = shape
    radius = np.zeros((H, W), np.float64)
    drawn = np.zeros((H, W), bool)
    for b in skeleton.branches:
        p, t, _ = _dense(b, 0.5)
        x, y = np.rint(p[:, 0]).astype(np.int64), np.rint(p[:, 1]).astype(np.int64)
        ok = (x >= 0) & (x < W) & (y >= 0) & (y < H)
        np.maximum.at(radius, (y[ok], x[ok]), t[ok])
        drawn[y[ok], x[ok]] = True
    if not drawn.any():
        raise ValueError("skeleton: no centre-line point lies in the image")
    dist, (rows, cols) = ndimage.distance_transform_edt(~drawn, return_indices=True)
    return drawn, np.asarray(dist, np.float64), radius[rows, cols]


def background_grain(
    image: Any, skeleton: Skeleton, *, reach: float = 4.0, sigma: float = 1.0, valid: Any = None
) -> float:
    """The fine grain of ``image`` away from its structure: the median absolute difference
    between the brightness and its Gaussian blur of ``sigma`` px, over the pixels farther than
    ``reach`` thicknesses from ``skeleton``'s centre lines (beyond its fragments' disks and
    their surroundings).

    Brightness is the mean over channels. A median, so that sparse edges (untraced structure,
    the frame) do not count. An output's grain over its input's says how much of the
    background's texture its completed gaps kept: a completion that settled on a few smooth
    background patches (an elevation model's relief filled as a flat plateau) is well below 1.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The image the skeleton lies in.
    skeleton : Skeleton
        Its structure, with ``image``'s shape (or none).
    reach : float, optional
        How far from the centre lines the background starts, in thicknesses (default 4).
    sigma : float, optional
        Scale of the grain in px (default 1).
    valid : (H, W) array_like of bool, optional
        The pixels that belong to the picture (default: all); a frame's flat pixels would
        otherwise count as background without grain.

    Returns
    -------
    float
        In [0, 1] for images in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from phloem.branching import Branch, Skeleton
    >>> grain = np.random.default_rng(0).normal(0.5, 0.05, (60, 80)).astype(np.float32)
    >>> sk = Skeleton([Branch([[10, 30], [69, 30]], 1.5)], (60, 80))
    >>> background_grain(grain, sk) > 5 * background_grain(np.full((60, 80), 0.5), sk)
    True
    """
    img, (H, W) = _image_of(image, skeleton)
    reach = check_float(reach, "reach", 0.0)
    sigma = check_float(sigma, "sigma", 0.0, inclusive=False)
    _, dist, r = _thickness_distance(skeleton, (H, W))
    away = dist > reach * r
    k = 2 * math.ceil(3 * sigma) + 1  # the blur's kernel
    if valid is not None:
        # a pixel whose blur reaches beyond the picture would measure the frame's edge
        ok = as_mask(valid, "valid", (H, W))
        away &= cv2.erode(ok.astype(np.uint8), np.ones((k, k), np.uint8), borderType=cv2.BORDER_REPLICATE) > 0
    if not away.any():
        raise ValueError(f"skeleton: no background pixel lies farther than reach={reach} thicknesses from it")
    light = img.mean(axis=2).astype(np.float32)
    detail = light - cv2.GaussianBlur(light, (k, k), sigma, borderType=cv2.BORDER_REFLECT)
    return float(np.median(np.abs(detail[away])))
