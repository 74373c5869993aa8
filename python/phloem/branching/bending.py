"""The bending model of Sibbing, Pavić, Kobbelt 2010, §4.2: a Markov process over the turning
angles and thicknesses of uniformly resampled branches, with histogram matching.

A branch is extended by ``m`` elements at a time, copied from the input sub-sequence whose
``k + 1`` preceding elements best match the branch's history; one of the ``c`` best candidates
is chosen with probability proportional to its quality. The quality is adapted so that the
angle and thickness histograms of the synthesised structure follow the input's.

Beyond the paper's text: the synthesised histograms start with :attr:`BendingModel.warm_start`
pseudo-elements distributed like the input (default ``bins * m``), so that the first
extensions are not matched against the histograms of the ``k + 1`` copied stem elements alone
(which thins a thick stem to the input's commonest thickness at once); the paper's ``n_t / m``
weighting is kept. Angles are compared in radians, thicknesses in units of the resampling step
``h`` (so that the distance is scale-free, §2 "Contributions"). Each history also holds the
branch's deviation from its course over the last ``course`` edges (default ``8 m``), matched
like the angles: the paper's ``k + 1`` elements cannot hold a course at the scale of the
structure, and long branches drifted and curled (``docs/pipelines/branching.md``). A coarse
history beside it (:attr:`BendingModel.coarse_history`) matches the sums of ``m`` angles over
the ``k + 1`` extensions before each continuation, so that turns stay correlated as in the
input at the scale of several extensions (``docs/pipelines/branching/quality.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _core
from .._validate import check_float, check_int
from ._elements import (
    F64,
    I64,
    TAPER_VERTICES,
    _abs_turn,
    _axis_bins,
    _bin,
    _check_k,
    _check_skeleton,
    _denoised,
    _dist_columns,
    _edge_headings,
    _elements,
    _end_taper,
    _generations,
    _mod_2pi,
    _range,
)
from ._layout import DirectionLayout
from .skeleton import Skeleton

__all__ = [
    "ARC",
    "DENOISE",
    "STEM_THICKNESS",
    "TAPER_VERTICES",
    "TURN_BOUND",
    "TURN_HISTOGRAM",
    "BendingModel",
    "arc_window_turns",
    "block_sums",
    "course_deviation",
    "default_h",
]

#: Arc of the heading-change histogram, px: the arc over which issue 19 measures drift.
ARC = 60.0

#: Gaussian along each example branch, px, before its angles are taken: a traced centre line
#: keeps a pixel staircase that the Markov chain would copy as turning (measured in
#: ``docs/pipelines/branching/quality.md``, "The trace's pixel staircase taken for turning").
DENOISE = 3.0

#: Weight of a stem's thickness profile (measured in ``docs/pipelines/branching/quality.md``).
STEM_THICKNESS = 5.0

#: Weight of the bound on the total turn where the total turn is matched (measured in
#: ``docs/pipelines/branching/quality.md``).
TURN_BOUND = 5.0

#: Weight of the heading-change histogram's matching (measured in
#: ``docs/pipelines/branching/quality.md``, "The heading terms over many seeds").
TURN_HISTOGRAM = 10.0


def course_deviation(points: F64, tips: I64, edges: int) -> F64:
    """Heading at each tip vertex minus the direction of the chord over its last ``edges`` edges.

    ``tips`` index vertices of the polyline ``points``; the heading is that of the edge ending
    at the tip, the chord runs from ``edges`` vertices back (or the first vertex) to the tip.
    Radians, counter-clockwise on screen, in ``[-π, π)``; 0 where the chord is a single edge.
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tips, dtype=np.int64)
    chord = p[t] - p[np.maximum(t - max(edges, 1), 0)]
    course = np.arctan2(-chord[:, 1], chord[:, 0])
    return _angle(_edge_heading(p, t) - course)


def _edge_heading(points: F64, tips: I64) -> F64:
    """The heading on the image of the edge ending at each tip vertex (radians, counter-clockwise on screen)."""
    last = points[tips] - points[tips - 1]
    return np.asarray(np.arctan2(-last[:, 1], last[:, 0]), dtype=np.float64)


def _log_dist_angle(delta: F64) -> F64:
    """``log`` of the paper's ``dist`` on wrapped angle differences: ``log(1 / (|δ| + 1) + 1)``."""
    return np.asarray(np.log(1.0 / (np.abs(_angle(delta)) + 1.0) + 1.0), dtype=np.float64)


def _histogram_moves(target: F64, counts: F64, b: I64) -> F64:
    """§4.2's ``Δ`` for every candidate that adds one count to each of its bins ``b[i]`` (``(C, P)``):
    ``(‖Ĥ − H/n₀‖² − ‖Ĥ − (H + h_i)/(n₀ + P)‖²) / bins``, ``Ĥ`` the ``target``, ``H`` the ``counts``."""
    n0 = float(counts.sum())
    n = n0 + b.shape[1]
    now = float(((target - counts / n0) ** 2).sum())
    # ‖u − h_i/n‖² with u = Ĥ − H/n, h_i sparse (P ones): ‖u‖² − 2 Σ_p u[b_ip]/n + Σ_b h_ib²/n²,
    # one pass over the candidates in phloem_core::bending (‖u‖² and the rest stay NumPy's sums)
    u = target - counts / n
    return _core.histogram_moves(u, float(u @ u), now, n, np.ascontiguousarray(b, np.int64))


def block_sums(alpha: F64, k: int, m: int) -> F64 | None:
    """The sums of ``m`` turning angles over the ``k + 1`` blocks that end with ``alpha``.

    The coarse history of a branch whose angles so far are ``alpha``: oldest block first, each
    block the turn of one extension's worth of elements. None when ``alpha`` holds fewer than
    ``(k + 1) m`` angles.

    Examples
    --------
    >>> block_sums(np.arange(10.0), k=1, m=3)
    array([15., 24.])
    """
    a = np.asarray(alpha, dtype=np.float64)
    n = (k + 1) * m
    if len(a) < n:
        return None
    return np.asarray(a[len(a) - n :].reshape(k + 1, m).sum(axis=1), dtype=np.float64)


def arc_window_turns(alpha: F64, edges: int) -> F64:
    """The absolute heading change over every window of ``edges`` consecutive angles.

    ``|Σ α|`` over each window, wrapped to ``[0, π]``: on a branch resampled to step ``h`` it
    is :func:`phloem.metrics.heading_changes` over an arc of ``edges h`` px, measured with
    the edges' own headings instead of chords (empty when the branch has fewer angles).

    Examples
    --------
    >>> arc_window_turns(np.array([0.1, 0.2, -0.3, 0.4]), 2).round(2).tolist()
    [0.3, 0.1, 0.1]
    """
    if len(alpha) < edges:
        return np.zeros(0)
    c = np.concatenate([[0.0], np.cumsum(alpha)])
    t = c[edges:] - c[:-edges]
    return _abs_turn(t)


def _angle(a: F64) -> F64:
    return np.asarray(_mod_2pi(np.asarray(a, np.float64) + np.pi) - np.pi, dtype=np.float64)


def default_h(skeleton: Skeleton) -> float:
    """The default resampling step ``h`` for a skeleton: its median thickness.

    A step of about one branch radius keeps the turning angles at the scale of the branch's
    own width (finer steps would sample the hand-drawn polyline's noise). For skeletons
    without thickness (all zero) it falls back to 1/100 of the total length. :func:`synthesize`
    takes at least 2 px (:func:`~phloem.branching.h_default`), for traced centre lines.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> sk = Skeleton([Branch([[0, 0], [100, 0]], 3.0)])
    >>> default_h(sk)
    3.0
    """
    _check_skeleton(skeleton)
    r = np.concatenate([b.thickness for b in skeleton.branches])
    h = float(np.median(r))
    if not h > 0:
        h = skeleton.total_length() / 100.0
    if not h > 0:
        raise ValueError("skeleton: has zero total length, cannot choose a step h")
    return h


@dataclass
class BendingModel:
    """The Markov bending model of §4.2 with histogram matching.

    Build it with :meth:`fit`. The candidate tables hold every input sub-sequence
    ``C_i = (α̂_{i,k+1}, r̂_{i,k+1})`` that is followed by at least ``m`` more elements.

    Attributes
    ----------
    h : float
        Resampling step (edge length) in pixels.
    k, m, c, bins : int
        Markov order (history of ``k + 1`` elements), extension length, number of candidates
        to choose among, histogram bins ``B``.
    omega_g : float
        Weight ``ω_G`` of the histogram matching (of the angle histogram times
        :attr:`angle_weight`).
    source : Skeleton
        The input, smoothed by :attr:`denoise` and resampled to ``h``.
    hist_alpha, hist_r : ndarray, shape (bins,)
        The input's normalised angle and thickness histograms ``Ĥ_α``, ``Ĥ_r``.
    range_alpha, range_r : (float, float)
        Intervals split into the bins (the input's minimum and maximum).
    lengths : dict of int to list of float
        Branch lengths of the input per generation (0 = roots), used to pick target lengths.
    warm_start : float
        Pseudo-elements, distributed like the input's histograms, that the synthesised
        structure's histograms ``H_α, H_r`` start with (they count in ``n_t``).
    course : int
        Edges over which a branch's course is matched (0: off).
    coarse_history : float
        Weight of the coarse history's ``log dist`` beside the fine history's (0: off).
    total_turn : float
        Weight of the ``log dist`` of the turn since the branch's start (0: off).
    turn_bound : float
        Weight of the bound on a stem's total turn (0: off), see :meth:`fit`.
    turn_limit : float
        The bound: the 90th percentile of the absolute total turns of the input's stems
        (radians).
    hist_arc : ndarray, shape (bins,)
        The input's normalised histogram of :func:`arc_window_turns` over ``arc_edges``
        elements, on ``[0, π]``.
    arc_edges : int
        Elements in a heading-change window.
    turn_histogram : float
        Weight of the heading-change histogram's matching (0: off), see :meth:`fit`.
    stem_thickness : float
        Weight of a stem's thickness profile (0: off), see :meth:`fit`.
    hist_dir : ndarray, shape (bins,)
        The input's normalised histogram of its edges' directions on the image, as axes in
        bins centred on the image's axes (:func:`phloem.metrics.direction_histogram`'s).
    direction_histogram : float
        Weight of the direction histogram's matching (0: off), see :meth:`fit`.
    denoise : float
        Standard deviation (px) of the Gaussian the input's branches were smoothed by along
        their length before fitting (0: none), see :meth:`fit`.
    end_taper : ndarray, shape (T,)
        How the input's branches taper at their ends: the thickness of a branch's last ``T``
        vertices (``T`` at most :data:`TAPER_VERTICES`) over its level before them, the
        median over the input's branches. Grown branches end with it
        (:func:`~phloem.branching.grow`). Empty where the input's ends keep their thickness,
        as a traced photo's do.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> rng = np.random.default_rng(0)
    >>> b = Branch.from_angles([10, 100], 0.0, rng.normal(0, 0.3, 60), np.full(62, 2.0), 2.0)
    >>> model = BendingModel.fit(Skeleton([b]), h=2.0)
    >>> model.k, model.m, model.c, model.bins
    (3, 4, 2, 16)
    >>> len(model.cand_hist_alpha) > 0
    True
    """

    h: float
    k: int
    m: int
    c: int
    bins: int
    omega_g: float
    source: Skeleton
    hist_alpha: F64
    hist_r: F64
    range_alpha: tuple[float, float]
    range_r: tuple[float, float]
    lengths: dict[int, list[float]]
    # candidate tables, one row per candidate sub-sequence
    cand_hist_alpha: F64 = field(repr=False)  # (C, k+1) history angles
    cand_hist_r: F64 = field(repr=False)  # (C, k+1) history thickness / h
    next_alpha: F64 = field(repr=False)  # (C, m) following angles
    next_r: F64 = field(repr=False)  # (C, m) following thickness (pixels)
    inc_alpha: F64 = field(repr=False)  # (C, bins) histogram counts the extension adds
    inc_r: F64 = field(repr=False)
    cand_where: I64 = field(repr=False)  # (C, 2) source branch, first history element
    warm_start: float = 0.0
    # (C,) heading minus the course over the last ``course`` edges at the end of each history
    cand_course: F64 = field(default_factory=lambda: np.zeros(0), repr=False)
    course: int = 0
    # (C, k+1) sums of m angles over the k + 1 blocks ending with each history (see block_sums)
    cand_coarse: F64 = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    coarse_history: float = 0.0
    # (C,) the turn from the source branch's first edge to the end of each history (radians, unwrapped)
    cand_turn: F64 = field(default_factory=lambda: np.zeros(0), repr=False)
    total_turn: float = 0.0
    turn_bound: float = 0.0
    turn_limit: float = math.inf
    # (C,) the heading on the image of each history's last edge (radians, counter-clockwise on screen)
    cand_heading: F64 = field(default_factory=lambda: np.zeros(0), repr=False)
    orientation: float = 0.0
    # (bins,) the input's histogram of arc_window_turns over arc_edges elements, on [0, pi]
    hist_arc: F64 = field(default_factory=lambda: np.zeros(0), repr=False)
    arc_edges: int = 0
    turn_histogram: float = 0.0
    stem_thickness: float = 0.0
    # (bins,) the input's histogram of edge directions on the image, as axes (see _axis_bins)
    hist_dir: F64 = field(default_factory=lambda: np.zeros(0), repr=False)
    direction_histogram: float = 0.0
    # where the input's branches run which way (None where layout is 0)
    direction_layout: DirectionLayout | None = field(default=None, repr=False)
    layout: float = 0.0

    denoise: float = 0.0
    # (T,) the input's thickness over the last T vertices of a branch, over its level before
    # them (empty: the input's ends do not taper)
    end_taper: F64 = field(default_factory=lambda: np.zeros(0), repr=False)

    @classmethod
    def fit(
        cls,
        skeleton: Skeleton,
        *,
        h: float | None = None,
        k: int = 3,
        m: int | None = None,
        c: int = 2,
        bins: int = 16,
        omega_g: float = 50.0,
        feature_size: float | None = None,
        warm_start: float | None = None,
        course: int | None = None,
        coarse_history: float = 2.0,
        total_turn: float = 0.0,
        turn_bound: float | None = None,
        orientation: float = 0.0,
        turn_histogram: float = TURN_HISTOGRAM,
        arc: float = ARC,
        stem_thickness: float = STEM_THICKNESS,
        direction_histogram: float = 0.0,
        layout: float = 0.0,
        denoise: float = 0.0,
    ) -> BendingModel:
        """Learn the bending model from an example skeleton.

        Parameters
        ----------
        skeleton : Skeleton
            The example structure (any sampling; it is resampled to ``h``).
        h : float, optional
            Resampling step in pixels; default :func:`default_h` (median thickness).
        k : int
            Order of the Markov process: the history is ``k + 1`` elements (paper: 3).
        m : int, optional
            Elements added per step. Default ``round(feature_size / h)`` (the paper's
            ``m = s/h``), or 4 when no ``feature_size`` is given.
        c : int
            Number of best candidates to choose among (paper: 2; ``c = 1`` is deterministic).
        bins : int
            Histogram bins ``B`` (paper: 16).
        omega_g : float
            Histogram-matching weight ``ω_G`` (paper: 50; 0 switches the matching off). The
            angle histogram's term is weighted by ``ω_G`` times :attr:`angle_weight`
            (``1 + coarse_history + total_turn + turn_histogram``), which keeps the paper's
            balance beside the extra angle terms below.
        feature_size : float, optional
            Typical bending feature size ``s`` in pixels, sets ``m`` when ``m`` is not given.
        warm_start : float, optional
            Pseudo-elements distributed like the input that the synthesised histograms start
            with; default ``bins * m`` (one extension's worth per bin). With 0, as in the
            paper's formula taken literally, the first extensions are matched against the
            histograms of the ``k + 1`` copied stem elements alone, and a thick stem drops to
            the input's most common thickness at once. The pseudo-elements keep the histograms
            near the input's until the structure has a distribution of its own; from then on
            the paper's ``n_t / m`` weighting applies unchanged.
        course : int, optional
            Edges over which a branch's course is measured (default ``8 m``; 0 switches it
            off). Beyond the paper: each history also holds the branch's heading minus the
            direction of the chord over its last ``course`` edges, matched like the angles, so
            that a branch keeps the input's course at the scale of the structure and not only
            over the ``k + 1`` elements of the Markov history (which let long branches drift
            and curl).
        coarse_history : float
            Weight of the coarse history (default 2; 0 switches it off). Beyond the paper:
            a branch of at least ``(k + 1) m`` elements is also matched on the sums of ``m``
            angles over its last ``k + 1`` blocks (:func:`block_sums`), against the same sums
            before each candidate, with the paper's ``dist`` raised to this power. With the
            fine history alone turns correlate over ``k + 1`` elements only, and branches
            turned about twice as much as the input's over 60 px.
        total_turn : float
            Weight of the total turn (default 0: off; 2 is the weight measured). Beyond the paper: each
            history also holds the branch's heading minus the heading of its first edge
            (the sum of all its angles, not wrapped), matched against the same sum at the end
            of each candidate's history with the paper's ``dist`` raised to this power. A
            branch then turns over its whole length as the input's branches do after as
            much turning, so that a stem keeps a course across the image instead of
            curling. Off by default: with :func:`grow`'s ``repel_border`` it takes the river
            deltas' stems across the image, but on inputs with few long branches it makes the
            output drift further from them (``docs/pipelines/branching/quality.md``);
            :func:`synthesize` turns both on where the input's course is known
            (:func:`course_defaults`).
        turn_bound : float, optional
            Weight of the bound on a stem's total turn (default :data:`TURN_BOUND` where
            ``total_turn > 0``, else 0: off). Beyond the paper: a candidate whose continuation
            takes a stem's (a root tree's main branch's) absolute total turn beyond
            :attr:`turn_limit` (the 90th percentile of the input's stems') loses
            ``turn_bound`` times the excess (radians) in ``log Q``: matching the total turn
            alone holds no branch back once it has turned further than any input branch
            (measurements in ``docs/pipelines/branching/quality.md``).
        orientation : float
            Weight of the absolute heading (default 0: off; 3 is the weight measured). Beyond
            the paper, whose model is orientation independent and leaves the coarsest scale,
            the global path, to the user's guidance: each history also holds the direction of
            its last edge on the image, matched against the branch's heading like the course.
            Continuations then come from input branches running the same way, so lightning
            keeps falling and a leaf's side veins keep their slant. Off by default: on
            inputs that run every way the marks fall (``docs/pipelines/branching/quality.md``);
            :func:`synthesize` turns it on where the input runs one way
            (:func:`orientation_default`).
        turn_histogram : float
            Weight of the heading-change histogram (default :data:`TURN_HISTOGRAM`; 0 switches
            it off). Beyond the paper: §4.2's histogram matching applied to a third histogram,
            of the absolute heading change over ``arc`` px (:func:`arc_window_turns` over
            ``round(arc / h)`` elements, at least ``m + 1``). Every candidate gains
            ``ω_G turn_histogram Δ n_t / m`` in ``log Q``, ``Δ`` the histogram's move towards
            the input's if the candidate's continuation were taken (:meth:`arc_delta`). The
            Markov chain's ``k + 1`` elements and the coarse history correlate turns over a few
            extensions only, and grown branches turned more than smooth inputs and less than
            jagged ones over 60 px; the histogram pulls both ways.
        arc : float
            Arc of the heading-change histogram in px (default 60, the arc of
            :func:`phloem.metrics.drift`).
        stem_thickness : float
            Weight of a stem's thickness profile (default :data:`STEM_THICKNESS`; 0 switches
            it off). Beyond the paper: :func:`~phloem.branching.grow` gives each root tree's
            main branch the thickness its template stem has at the same arc length (the
            template's thickness under a running median of ``4 m + 1`` elements), and each
            candidate's ``m`` following thicknesses are matched against it with the paper's
            ``dist`` (in units of ``h``) raised to this power. The ``k + 1`` elements of the
            history hold a thickness for a few extensions only, and the thickness histogram
            pulls every extension towards the input's commonest thickness, so a thick trunk
            thinned to its children's thickness within its first extensions.
        direction_histogram : float
            Weight of the direction histogram (default 0: off). Beyond the paper: §4.2's
            histogram matching applied to the directions the edges run on the image, as axes
            (an edge and its reverse in one bin, ``bins`` bins centred on the image's axes).
            Every candidate gains ``ω_G direction_histogram Δ n_t / m`` in ``log Q``, ``Δ`` the
            histogram's move towards the input's if the candidate's ``m`` edges, turned from
            the branch's heading, were added (:meth:`direction_delta`). ``orientation`` matches
            each candidate's heading where it was taken from; it keeps a branch running the way
            it runs, but a branch that has wandered off the input's ways finds few candidates
            and none that steer it back. The histogram does, and it holds the whole
            structure's share of each direction to the input's. :func:`synthesize` turns it
            on where the input runs one way (:func:`direction_histogram_default`).
        layout : float
            Weight of the input's layout of directions (default 0: off, the paper's model,
            the same everywhere in the picture). Beyond the paper: a von Mises distribution of
            the edges' axes fitted at each place of the input to its different branches near
            there (:class:`~phloem.branching._layout.DirectionLayout`), laid over the new
            picture. A candidate gains ``layout · κ cos 2(θ − φ)`` in ``log Q``, ``θ`` its
            mean direction and ``κ``, ``φ`` the distribution at the branch's tip: its
            log-density there. Where the input's branches do not agree on a way (a crack
            network, bark) ``κ`` is 0 and nothing changes; a fundus's vessels, a delta's
            channels or roots sweeping one way are grown along the input's ways
            (``docs/pipelines/branching.md``, ``layout``). :func:`synthesize` turns it on
            where the input is one connected structure (:func:`layout_default`).
        denoise : float
            Standard deviation in px of a Gaussian along each branch of ``skeleton`` before
            it is resampled and its angles taken (default 0: the skeleton as given, the
            paper's model; :func:`~phloem.branching.synthesize` uses :data:`DENOISE`, 3,
            where the input's branches keep a course,
            :func:`~phloem.branching.denoise_default`). Beyond the paper: a traced centre
            line keeps the pixel grid's staircase, which at a step of a few pixels is most of
            a straight vein's turning angle and reverts over tens of elements. The Markov
            chain copies the turns but not their return to the line, so grown branches
            wandered off their course. Only the angles and the points of :attr:`source`
            change; the thicknesses are the skeleton's.

        Returns
        -------
        BendingModel

        Raises
        ------
        ValueError
            If no branch is long enough for a history of ``k + 1`` plus ``m`` elements.

        Examples
        --------
        >>> from phloem.branching import Branch, Skeleton
        >>> b = Branch.from_angles([10, 100], 0.0, 0.1 * np.sin(np.arange(50)), np.full(52, 2.0), 2.0)
        >>> model = BendingModel.fit(Skeleton([b]), h=2.0, k=2, m=3, c=1)
        >>> model.next_alpha.shape[1]
        3
        """
        _check_skeleton(skeleton)
        h = default_h(skeleton) if h is None else check_float(h, "h", 0.0, inclusive=False)
        k = _check_k(k)
        if m is None:
            if feature_size is None:
                m = 4
            else:
                m = max(1, round(check_float(feature_size, "feature_size", 0.0, inclusive=False) / h))
        m = check_int(m, "m", 1)
        c = check_int(c, "c", 1)
        bins = check_int(bins, "bins", 1)
        omega_g = check_float(omega_g, "omega_g", 0.0)
        warm = float(bins * m) if warm_start is None else check_float(warm_start, "warm_start", 0.0)
        n_course = 8 * m if course is None else check_int(course, "course", 0)
        coarse_history = check_float(coarse_history, "coarse_history", 0.0)
        total_turn = check_float(total_turn, "total_turn", 0.0)
        if turn_bound is None:
            turn_bound = TURN_BOUND if total_turn > 0 else 0.0
        turn_bound = check_float(turn_bound, "turn_bound", 0.0)
        orientation = check_float(orientation, "orientation", 0.0)
        turn_histogram = check_float(turn_histogram, "turn_histogram", 0.0)
        stem_thickness = check_float(stem_thickness, "stem_thickness", 0.0)
        direction_histogram = check_float(direction_histogram, "direction_histogram", 0.0)
        layout = check_float(layout, "layout", 0.0)
        arc = check_float(arc, "arc", 0.0, inclusive=False)
        denoise = check_float(denoise, "denoise", 0.0)
        src = _denoised(skeleton, denoise, h).resample(h)
        elems = [_elements(b) for b in src.branches]
        all_a = np.concatenate([a for a, _ in elems])
        all_r = np.concatenate([r for _, r in elems])
        need = k + 1 + m
        if max(len(a) for a, _ in elems) < need:
            longest = max(len(b) for b in src.branches)
            raise ValueError(
                f"skeleton: no branch is long enough for k + m = {k} + {m}: after resampling to h = {h:g} the "
                f"longest branch has {longest} vertices, but k + m + 3 = {need + 2} are needed (lower k, m or h)"
            )
        ra, rr = _range(all_a), _range(all_r)
        hist_a = np.bincount(_bin(all_a, *ra, bins), minlength=bins) / all_a.size
        hist_r = np.bincount(_bin(all_r, *rr, bins), minlength=bins) / all_r.size
        ha, hr, na, nr, where, dev, coarse, turn, head = [], [], [], [], [], [], [], [], []
        for bi, (a, r) in enumerate(elems):
            n = len(a) - need + 1
            if n <= 0:
                continue
            # the tip after history i is vertex i + k + 2, reached along edge i + k + 1
            tips = np.arange(n) + k + 2
            dev.append(course_deviation(src.branches[bi].points, tips, n_course))
            head.append(_edge_heading(src.branches[bi].points, tips))
            idx = np.arange(n)[:, None]
            # Blocks reaching before the branch's first element sum only what it has: a
            # candidate near a branch start is matched as if it had been straight before.
            csum = np.concatenate([[0.0], np.cumsum(a)])
            ends = np.maximum(idx + k + 1 - m * np.arange(k + 1)[::-1], 0)
            coarse.append(csum[ends] - csum[np.maximum(ends - m, 0)])
            turn.append(csum[np.arange(n) + k + 1])
            ha.append(a[idx + np.arange(k + 1)])
            hr.append(r[idx + np.arange(k + 1)] / h)
            na.append(a[idx + k + 1 + np.arange(m)])
            nr.append(r[idx + k + 1 + np.arange(m)])
            where.append(np.stack([np.full(n, bi), np.arange(n)], axis=1))
        next_a, next_r = np.vstack(na), np.vstack(nr)
        rows = np.arange(len(next_a))[:, None]
        inc_a = np.zeros((len(next_a), bins))
        np.add.at(inc_a, (np.broadcast_to(rows, next_a.shape), _bin(next_a, *ra, bins)), 1.0)
        inc_r = np.zeros((len(next_a), bins))
        np.add.at(inc_r, (np.broadcast_to(rows, next_r.shape), _bin(next_r, *rr, bins)), 1.0)
        cand_turn = np.concatenate(turn)
        gens = np.asarray(_generations(src))
        stems = gens[np.concatenate([w[:, 0] for w in where])] == 0
        limit = float(np.percentile(np.abs(cand_turn[stems] if stems.any() else cand_turn), 90))
        # a window longer than one extension, so that every continuation has a history in it
        arc_edges = max(m + 1, round(arc / h))
        arc_all = np.concatenate([arc_window_turns(a, arc_edges) for a, _ in elems])
        hist_arc = np.bincount(_bin(arc_all, 0.0, math.pi, bins), minlength=bins) / max(arc_all.size, 1)
        if not arc_all.size:
            turn_histogram = 0.0  # no input branch spans the arc: nothing to match
        # every resampled edge is h long: counting edges weights the directions by length
        axes = np.concatenate([_edge_headings(b.points) for b in src.branches])
        hist_dir = np.bincount(_axis_bins(axes, bins), minlength=bins) / max(axes.size, 1)
        lengths: dict[int, list[float]] = {}
        for g, b in zip(gens.tolist(), src.branches):
            lengths.setdefault(g, []).append(b.length())
        return cls(
            h=h,
            k=k,
            m=m,
            c=c,
            bins=bins,
            omega_g=omega_g,
            source=src,
            hist_alpha=hist_a.astype(np.float64),
            hist_r=hist_r.astype(np.float64),
            range_alpha=ra,
            range_r=rr,
            lengths=lengths,
            cand_hist_alpha=np.vstack(ha),
            cand_hist_r=np.vstack(hr),
            next_alpha=next_a,
            next_r=next_r,
            inc_alpha=inc_a,
            inc_r=inc_r,
            cand_where=np.vstack(where).astype(np.int64),
            warm_start=warm,
            cand_course=np.concatenate(dev),
            course=n_course,
            cand_coarse=np.vstack(coarse),
            coarse_history=coarse_history,
            cand_turn=cand_turn,
            total_turn=total_turn,
            turn_bound=turn_bound,
            turn_limit=limit,
            cand_heading=np.concatenate(head),
            orientation=orientation,
            hist_arc=hist_arc.astype(np.float64),
            arc_edges=arc_edges,
            turn_histogram=turn_histogram,
            stem_thickness=stem_thickness,
            hist_dir=hist_dir.astype(np.float64),
            direction_histogram=direction_histogram,
            direction_layout=DirectionLayout.fit(skeleton) if layout > 0 else None,
            layout=layout,
            denoise=denoise,
            end_taper=_end_taper(src),
        )

    def log_quality(
        self,
        alpha: F64,
        r: F64,
        counts_alpha: F64,
        counts_r: F64,
        deviation: float | None = None,
        coarse: F64 | None = None,
        turn: float | None = None,
        stem: bool = True,
        heading: float | None = None,
        arc_tail: F64 | None = None,
        counts_arc: F64 | None = None,
        profile: F64 | None = None,
        counts_dir: F64 | None = None,
    ) -> F64:
        """``log Q*_i`` of every candidate for a branch history (vectorised over candidates).

        Parameters
        ----------
        alpha, r : ndarray, shape (L,)
            The branch's last ``L <= k + 1`` angles and thicknesses (pixels); shorter
            histories are matched against the last ``L`` elements of each candidate.
        counts_alpha, counts_r : ndarray, shape (bins,)
            Histogram counts of the whole structure synthesised so far (``n_t`` elements).
        deviation : float, optional
            The branch's heading minus its course (see ``course`` in :meth:`fit`); matched
            against the candidates' when given and the model has a course.
        coarse : ndarray, shape (k + 1,), optional
            The branch's coarse history, :func:`block_sums` of all its angles; matched
            against the candidates' when given and ``coarse_history > 0``.
        turn : float, optional
            The branch's total turn, the sum of all its angles; matched against the
            candidates' when given and ``total_turn > 0``, and bounded by :attr:`turn_limit`
            when ``turn_bound > 0`` and the branch is a ``stem``.
        stem : bool
            Whether the branch is a root tree's main branch (the total turn's bound applies).
        heading : float, optional
            The branch's heading on the image (radians, counter-clockwise on screen); matched
            against the candidates' when given and ``orientation > 0``, and the direction of
            their continuations' edges when ``counts_dir`` is given too.
        arc_tail, counts_arc : ndarray, optional
            The branch's last angles and the structure's heading-change histogram counts;
            the histogram is matched (:meth:`arc_delta`) when both are given and
            ``turn_histogram > 0``.
        profile : ndarray, shape (m,), optional
            The thickness (pixels) the branch's template has at the ``m`` vertices an
            extension writes (see :meth:`stem_profile`); matched against each candidate's
            following thicknesses when given, ``stem`` is true and ``stem_thickness > 0``.
        counts_dir : ndarray, shape (bins,), optional
            The structure's direction histogram counts; the histogram is matched
            (:meth:`direction_delta`) when ``heading`` is given too and
            ``direction_histogram > 0``.

        Returns
        -------
        ndarray of float64, shape (C,)
            ``log Q_i + ω_G (a Δ_α(i) + Δ_r(i)) n_t / m``, ``a`` the :attr:`angle_weight`,
            plus the heading-change and direction histograms' terms.
        """
        L = len(alpha)
        if not 1 <= L <= self.k + 1 or len(r) != L:
            raise ValueError(f"alpha, r: expected 1 .. {self.k + 1} history elements each, got {len(alpha)}, {len(r)}")
        cols = self._columns()
        q = np.log(_dist_columns(cols[0][-L:], np.asarray(alpha, np.float64)))
        q += np.log(_dist_columns(cols[1][-L:], np.asarray(r, np.float64) / self.h))
        if coarse is not None and self.coarse_history > 0 and len(self.cand_coarse):
            if np.shape(coarse) != (self.k + 1,):
                raise ValueError(f"coarse: expected {self.k + 1} block sums, got shape {np.shape(coarse)}")
            q += self.coarse_history * np.log(_dist_columns(cols[2], np.asarray(coarse, np.float64)))
        if turn is not None and self.total_turn > 0 and len(self.cand_turn):
            q += self.total_turn * np.log(_dist_columns(self.cand_turn[None, :], np.array([float(turn)])))
        if turn is not None and stem and self.turn_bound > 0:
            after = np.abs(float(turn) + self._next_turn())
            q -= self.turn_bound * np.maximum(after - self.turn_limit, 0.0)
        if profile is not None and stem and self.stem_thickness > 0:
            if np.shape(profile) != (self.m,):
                raise ValueError(f"profile: expected {self.m} thicknesses, got shape {np.shape(profile)}")
            q += self.stem_thickness * np.log(
                _dist_columns(self._next_r_rows(), np.asarray(profile, np.float64) / self.h)
            )
        if deviation is not None and self.course > 0:
            q += _log_dist_angle(self.cand_course - deviation)
        if heading is not None and self.orientation > 0 and len(self.cand_heading):
            q += self.orientation * _log_dist_angle(self.cand_heading - heading)
        n_t = float(counts_alpha.sum())
        if self.omega_g > 0 and n_t > 0:
            delta = self.angle_weight * self._delta(self.hist_alpha, counts_alpha, self.inc_alpha, n_t)
            delta += self._delta(self.hist_r, counts_r, self.inc_r, n_t)
            q += self.omega_g * delta * (n_t / self.m)
        if arc_tail is not None and counts_arc is not None and self.turn_histogram > 0 and self.omega_g > 0:
            got = self.arc_delta(arc_tail, counts_arc)
            if got is not None:
                q += self.omega_g * self.turn_histogram * got * (float(counts_arc.sum()) / self.m)
        if heading is not None and counts_dir is not None and self.direction_histogram > 0 and self.omega_g > 0:
            n_d = float(counts_dir.sum())
            if n_d > 0:
                delta_dir = self.direction_delta(float(heading), counts_dir)
                q += self.omega_g * self.direction_histogram * delta_dir * (n_d / self.m)
        return q

    def arc_delta(self, tail: F64, counts: F64) -> F64 | None:
        """``Δ`` of the heading-change histogram for every candidate (see ``turn_histogram``).

        Parameters
        ----------
        tail : ndarray, shape (L,)
            The branch's last angles (at most ``arc_edges - 1`` are used).
        counts : ndarray, shape (bins,)
            The heading-change histogram's counts of the structure so far (with the warm start).

        Returns
        -------
        ndarray of float64, shape (C,), or None
            ``(‖Ĥ − H/n‖² − ‖Ĥ − (H + h_i)/(n + P)‖²) / bins``, ``h_i`` the counts of the ``P``
            windows that end at candidate ``i``'s new elements, the §4.2 ``Δ`` of the angle
            histogram applied to this one; None when the branch is too short for any window
            to end in the continuation, or nothing has been counted yet (``n = 0``).
        """
        W, m = self.arc_edges, self.m
        n0 = float(counts.sum())
        need = W - np.arange(1, m + 1)  # the branch's elements in the window ending at new element p
        ok = need <= len(tail)
        if not ok.any() or n0 <= 0:
            return None
        back = np.concatenate([[0.0], np.cumsum(np.asarray(tail, np.float64)[::-1])])
        t = back[need[ok]][None, :] + self._next_cumsum()[:, ok]
        return _histogram_moves(self.hist_arc, counts, _core.turn_bins(np.ascontiguousarray(t), self.bins))

    def direction_delta(self, heading: float, counts: F64) -> F64:
        """``Δ`` of the direction histogram for every candidate (see ``direction_histogram``).

        Parameters
        ----------
        heading : float
            The branch's heading on the image (radians, counter-clockwise on screen).
        counts : ndarray, shape (bins,)
            The direction histogram's counts of the structure so far (with the warm start),
            not all zero.

        Returns
        -------
        ndarray of float64, shape (C,)
            ``(‖Ĥ − H/n‖² − ‖Ĥ − (H + h_i)/(n + m)‖²) / bins``, ``h_i`` the counts of candidate
            ``i``'s ``m`` edges, run from ``heading`` turned by its angles.
        """
        # _axis_bins of heading + the running turns, with the turns' scaling done once per model
        got = self.__dict__.get("_next_cumsum_bins_of")
        if got is None or got[0] is not self.next_alpha:
            got = (self.next_alpha, self._next_cumsum() * (self.bins / math.pi))
            self.__dict__["_next_cumsum_bins_of"] = got
        shift = (float(heading) + math.pi / (2 * self.bins)) * (self.bins / math.pi)
        b = np.floor(got[1] + shift).astype(np.int64) % self.bins
        return _histogram_moves(self.hist_dir, counts, b)

    def _next_cumsum(self) -> F64:
        """``(C, m)`` the running turn along every candidate's continuation (cached)."""
        got = self.__dict__.get("_next_cumsum_of")
        if got is None or got[0] is not self.next_alpha:
            got = (self.next_alpha, np.cumsum(self.next_alpha, axis=1))
            self.__dict__["_next_cumsum_of"] = got
        out: F64 = got[1]
        return out

    @property
    def angle_weight(self) -> float:
        """The factor on ``ω_G`` for the angle histogram: ``1 + coarse_history + total_turn + turn_histogram``.

        The coarse history and the total turn are angle terms beyond the paper, each entering
        ``log Q`` as the paper's ``dist`` raised to its weight. They widen the range of the
        angle similarity by those weights, so the angle histogram's term is scaled with them to
        keep the paper's balance between the two (without them, 1: the paper's model). The
        thickness histogram keeps ``ω_G``, as the thickness similarity is unchanged.
        """
        return 1.0 + self.coarse_history + self.total_turn + self.turn_histogram

    def _next_r_rows(self) -> F64:
        """``(m, C)`` every candidate's following thicknesses over ``h``, transposed (cached)."""
        got = self.__dict__.get("_next_r_rows_of")
        if got is None or got[0] is not self.next_r:
            got = (self.next_r, np.ascontiguousarray(self.next_r.T / self.h))
            self.__dict__["_next_r_rows_of"] = got
        out: F64 = got[1]
        return out

    def _next_turn(self) -> F64:
        """``(C,)`` the turn of every candidate's continuation, the sum of its ``m`` angles (cached)."""
        got = self.__dict__.get("_next_turn_of")
        if got is None or got[0] is not self.next_alpha:
            got = (self.next_alpha, self.next_alpha.sum(axis=1))
            self.__dict__["_next_turn_of"] = got
        out: F64 = got[1]
        return out

    def _columns(self) -> tuple[F64, F64, F64]:
        """The history tables transposed, ``(k + 1, C)`` each (cached; rebuilt if a table is replaced)."""
        got = self.__dict__.get("_cols")
        tables = (self.cand_hist_alpha, self.cand_hist_r, self.cand_coarse)
        if got is None or any(a is not b for a, b in zip(got[0], tables)):
            cols: tuple[F64, F64, F64] = (
                np.ascontiguousarray(tables[0].T),
                np.ascontiguousarray(tables[1].T),
                np.ascontiguousarray(tables[2].T),
            )
            got = (tables, cols)
            self.__dict__["_cols"] = got
        out: tuple[F64, F64, F64] = got[1]
        return out

    def _delta(self, target: F64, counts: F64, inc: F64, n_t: float) -> F64:
        now = float(((target - counts / n_t) ** 2).sum()) / self.bins
        # ||u - v_i||² = ||u||² - 2 u·v_i + ||v_i||² with u = target - counts / (n_t + m) and
        # v_i = inc_i / (n_t + m): one matrix-vector product instead of a (C, bins) temporary
        n = n_t + self.m
        u = target - counts / n
        sq = self.__dict__.get("_inc_sq")
        if sq is None or sq[0] is not self.inc_alpha or sq[1] is not self.inc_r:
            sq = (self.inc_alpha, self.inc_r, (self.inc_alpha**2).sum(axis=1), (self.inc_r**2).sum(axis=1))
            self.__dict__["_inc_sq"] = sq
        inc_sq = sq[2] if inc is self.inc_alpha else sq[3] if inc is self.inc_r else (inc**2).sum(axis=1)
        after = (float(u @ u) - 2.0 * (inc @ u) / n + inc_sq / (n * n)) / self.bins
        return np.asarray(now - after, dtype=np.float64)

    def start_elements(self, branch: int = 0) -> tuple[float, F64, F64, float]:
        """Heading, first ``k + 1`` elements and first thickness of an input branch (a stem to copy)."""
        b = self.source.branches[branch]
        a, r = _elements(b)
        return b.heading(), a[: self.k + 1], r[: self.k + 1], float(b.thickness[0])

    def stem_profile(self, branch: int = 0) -> F64:
        """The thickness of an input branch at each of its vertices under a running median of
        ``4 m + 1`` elements: its level along the branch, without the local texture that the
        candidates bring (see ``stem_thickness`` in :meth:`fit`)."""
        t = np.asarray(self.source.branches[branch].thickness, np.float64)
        half = 2 * self.m
        padded = np.concatenate([np.full(half, t[0]), t, np.full(half, t[-1])])
        out: F64 = np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1), axis=1)
        return out
