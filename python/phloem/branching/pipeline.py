"""The whole branching pipeline in one call: image (and skeleton) in, new image out (§3–§5)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _memory
from .._api import Seed, Size, renamed
from .._progress import Progress
from .._validate import as_image, as_mask, check_size
from ._forest import connected, input_trees
from .bending import DENOISE, STEM_THICKNESS, TURN_HISTOGRAM, BendingModel, default_h
from .frame import _kept_inside, valid_region
from .furcation import FurcationModel
from .gaps import gap_diversity_default
from .growth import grow
from .measures import direction_concentration, drift_noise, joined_end_share, median_heading_change
from .render import RenderResult, render
from .skeleton import Skeleton
from .trace import trace

__all__ = [
    "SourceDefaults",
    "SynthesisResult",
    "course_defaults",
    "course_edges_default",
    "denoise_default",
    "direction_histogram_default",
    "fit_models",
    "h_default",
    "orientation_default",
    "source_defaults",
    "synthesize",
]

#: The largest ``drift_noise`` at which an input's heading statistics count as well determined:
#: half of issue 19's drift mark (0.25), so that the mark measures the synthesis, not the input.
COURSE_NOISE = 0.125
#: The total-turn weight :func:`course_defaults` turns on (the weight measured).
COURSE_TOTAL_TURN = 2.0
#: The :func:`~phloem.metrics.direction_concentration` from which an input counts as running one
#: way: for axes drawn from a von Mises law, its most common direction is then about six times
#: as frequent as its least common.
ORIENTATION_CONCENTRATION = 0.4
#: Candidates the pipeline draws each extension and furcation from (the paper's ``c`` is 2):
#: with the heading-change histogram matched, two leave it little to choose between
#: (measured in ``docs/pipelines/branching/quality.md``, "The heading terms over many seeds").
N_BEST = 4
#: The heading-change histogram's weight under a guide: the path sets how branches turn, and at
#: :data:`~phloem.branching.bending.TURN_HISTOGRAM` the histogram pulls them off it
#: (``docs/pipelines/branching/quality.md``).
GUIDED_TURN_HISTOGRAM = 3.0
#: The heading weight :func:`orientation_default` turns on there (the weight measured).
ORIENTATION_WEIGHT = 3.0
#: The direction histogram's weight :func:`direction_histogram_default` turns on there (the
#: weight measured).
DIRECTION_HISTOGRAM_WEIGHT = 1.0
#: The layout weight :func:`layout_default` turns on for a connected input (the weight measured).
LAYOUT_WEIGHT = 1.0
#: The largest median heading change over 60 px (radians, about 23°) at which an input's
#: branches count as keeping a course, so that :func:`denoise_default` smooths them: their
#: turning at the resampling step is then mostly the trace's pixel staircase (measured in
#: ``docs/pipelines/branching/quality.md``, "The trace's pixel staircase taken for turning").
DENOISE_COURSE = 0.4
#: The shortest resampling step :func:`h_default` gives, in pixels: a traced centre line keeps
#: the pixel grid's staircase, and a step under two pixels samples it rather than the
#: branch's course (measured in ``docs/pipelines/branching/quality.md``, "A step of at least
#: two pixels").
MIN_H = 2.0


@dataclass
class SynthesisResult:
    """What :func:`synthesize` made, stage by stage.

    Attributes
    ----------
    image : (H, W[, C]) float32 ndarray
        The new image (2-D for a 2-D input).
    source : Skeleton
        The input's skeleton (given or traced).
    target : Skeleton
        The synthesised skeleton the new image shows.
    bending : BendingModel
    furcation : FurcationModel or None
        ``None`` when the input has no furcation to learn from.
    render : RenderResult
        Fragments, their placement map and the image before gap completion.
    """

    image: NDArray[np.float32]
    source: Skeleton
    target: Skeleton
    bending: BendingModel
    furcation: FurcationModel | None
    render: RenderResult


@renamed(k="order", c="n_best")
def fit_models(
    skeleton: Skeleton,
    *,
    h: float | None = None,
    order: int = 3,
    m: int | None = None,
    n_best: int = N_BEST,
    course: int | None = None,
    coarse_history: float = 2.0,
    total_turn: float = 0.0,
    turn_bound: float | None = None,
    orientation: float = 0.0,
    turn_histogram: float = TURN_HISTOGRAM,
    stem_thickness: float = STEM_THICKNESS,
    direction_histogram: float = 0.0,
    layout: float = 0.0,
    denoise: float = 0.0,
) -> tuple[BendingModel, FurcationModel | None]:
    """The bending model (§4.2) and, if the skeleton branches at all, the furcation model (§4.3).

    Both use the bending model's resampling step ``h``.

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    h : float, optional
        Resampling step in pixels (default: the input's median thickness).
    order : int, optional
        Order of the Markov bending model, the paper's ``k`` (default 3); also the half-width
        of the furcation model's neighbourhood. ``k`` before (deprecated).
    m : int, optional
        Elements appended per step (see :meth:`BendingModel.fit`).
    n_best : int, optional
        Candidates to draw from, the paper's ``c`` (default :data:`N_BEST`, 4; the paper's 2
        leaves the heading-change histogram little to choose between; 1 follows the input
        exactly). ``c`` before (deprecated).
    course : int, optional
        Edges over which the bending model matches a branch's course (default ``8 m``; 0: the
        paper's model; see :meth:`BendingModel.fit`).
    coarse_history : float, optional
        Weight of the bending model's coarse history, the sums of ``m`` angles over the last
        ``k + 1`` extensions (default 2; 0: the paper's model; see :meth:`BendingModel.fit`).
    total_turn : float, optional
        Weight of the bending model's total turn, each branch's turn since its start
        (default 0: the paper's model; see :meth:`BendingModel.fit`).
    turn_bound : float, optional
        Weight of the bound on a stem's total turn (default 5 where ``total_turn > 0``, else 0;
        see :meth:`BendingModel.fit`).
    orientation : float, optional
        Weight of the bending model's absolute heading, so that branches run the ways the
        input's run (default 0: the paper's orientation-independent model; see
        :meth:`BendingModel.fit`).
    turn_histogram : float, optional
        Weight of the matching of the histogram of heading changes over 60 px, so that
        branches turn over that arc as the input's do (default 10; 0: the paper's model; see
        :meth:`BendingModel.fit`).
    stem_thickness : float, optional
        Weight of the match of each root tree's main branch against its template stem's
        thickness, so that a trunk stays as thick as the input's (default 5; 0: the paper's
        model; see :meth:`BendingModel.fit`).
    direction_histogram : float, optional
        Weight of the matching of the histogram of the directions the branches run on the
        image, so that the structure runs each way as much as the input's (default 0: the
        paper's orientation-independent model; see :meth:`BendingModel.fit`).
    layout : float, optional
        Weight of the input's layout of directions, so that branches run the way the input's
        run at the same place of the picture (default 0: the paper's model, the same
        everywhere; see :meth:`BendingModel.fit`). :func:`synthesize` turns it on where the
        input is one connected structure (:func:`layout_default`).
    denoise : float, optional
        Standard deviation in px of the Gaussian that smooths the skeleton's branches along
        their length before the bending model takes their angles, so that a traced centre
        line's pixel staircase is not grown as turning (default 0: the skeleton as given, the
        paper's model; :func:`synthesize` defaults it by :func:`denoise_default`; see
        :meth:`BendingModel.fit`). The furcation model uses the skeleton as given.

    Examples
    --------
    >>> from phloem.branching import synthetic_skeleton
    >>> bend, fur = fit_models(synthetic_skeleton(0), h=2.0)
    >>> bend.h, fur is not None
    (2.0, True)
    """
    bending = BendingModel.fit(
        skeleton, h=h, k=order, m=m, c=n_best, course=course, coarse_history=coarse_history, total_turn=total_turn,
        turn_bound=turn_bound, orientation=orientation, turn_histogram=turn_histogram, stem_thickness=stem_thickness,
        direction_histogram=direction_histogram, layout=layout, denoise=denoise,
    )  # fmt: skip
    has_children = any(b.parent is not None for b in skeleton.branches)
    furcation = FurcationModel.fit(skeleton, h=bending.h, k=order, c=n_best) if has_children else None
    return bending, furcation


def course_defaults(
    skeleton: Skeleton, *, total_turn: float | None = None, repel_border: bool | None = None
) -> tuple[float, bool]:
    """:func:`synthesize`'s defaults of ``total_turn`` and ``repel_border`` for this source skeleton.

    ``(2.0, True)`` where the input's heading statistics are well determined, that is where
    :func:`phloem.metrics.drift_noise` of ``skeleton`` is at most 0.125, half the drift mark
    of ``docs/pipelines/branching/quality.md``: long stems then keep the input's course across
    the image (the turn since a branch's start matched as the input's) and leave the frame
    alone. Otherwise ``(0.0, False)``, the paper's model: an input with little long branch does
    not say what course a stem keeps, and matching its few branches' total turn makes the
    output's branches drift further from it (measured on that page).

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    total_turn, repel_border : optional
        Values chosen by the caller, returned as they are; only those left at None are
        defaulted.

    Returns
    -------
    (float, bool)
        ``total_turn`` for :func:`fit_models` and ``repel_border`` for :func:`grow`.

    Examples
    --------
    >>> from phloem.branching import synthetic_skeleton
    >>> course_defaults(synthetic_skeleton(0))
    (0.0, False)
    """
    _check_source(skeleton)
    if total_turn is not None and repel_border is not None:
        return total_turn, repel_border
    turn, border = (COURSE_TOTAL_TURN, True) if _course_known(skeleton) else (0.0, False)
    return (turn if total_turn is None else total_turn), (border if repel_border is None else repel_border)


def course_edges_default(skeleton: Skeleton, *, course: int | None = None) -> int | None:
    """:func:`synthesize`'s default of ``course`` for this source skeleton.

    ``None`` (the bending model's ``8 m`` edges) where the input's heading statistics are well
    determined, as :func:`course_defaults` decides; ``0`` otherwise, the paper's Markov model
    without the course term. An input with little long branch does not say what course a
    branch keeps over ``8 m`` edges, and matching its few branches' courses holds the grown
    ones straighter than the input's (``docs/pipelines/branching/quality.md``, "The course
    term where the course is unknown").

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    course : int, optional
        A value chosen by the caller, returned as it is.

    Returns
    -------
    int or None
        ``course`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import synthetic_skeleton
    >>> course_edges_default(synthetic_skeleton(0)), course_edges_default(synthetic_skeleton(0), course=16)
    (0, 16)
    """
    _check_source(skeleton)
    if course is not None:
        return course
    return None if _course_known(skeleton) else 0


def denoise_default(skeleton: Skeleton, *, denoise: float | None = None) -> float:
    """:func:`synthesize`'s default of ``denoise`` for this source skeleton.

    :data:`~phloem.branching.bending.DENOISE` (3 px) where the input's branches keep a course,
    that is where their :func:`phloem.metrics.median_heading_change` over 60 px is at most
    :data:`DENOISE_COURSE` (0.4 rad): the turning angles of such branches at the resampling
    step are mostly the pixel staircase of their traced centre lines, which the Markov chain
    would grow as wander (veins, cracks, roots, vessels). Otherwise ``0.0``, the skeleton as
    given: branches that bend sharply within 60 px (valleys of an elevation model, zigzag
    bolts, braided channels) turn for real at the step, and smoothing rounds their bends. Also
    ``0.0`` where no branch is long enough to measure (the paper's model).

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    denoise : float, optional
        A value chosen by the caller, returned as it is.

    Returns
    -------
    float
        ``denoise`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> denoise_default(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]))
    3.0
    >>> denoise_default(Skeleton([Branch([[0, 0], [50, 0], [50, 50], [100, 50], [100, 100]], 1.0)]))
    0.0
    """
    _check_source(skeleton)
    if denoise is not None:
        return denoise
    try:
        keeps_course = median_heading_change(skeleton) <= DENOISE_COURSE
    except ValueError:  # no branch as long as the arc: nothing to tell a course from
        return 0.0
    return DENOISE if keeps_course else 0.0


def h_default(skeleton: Skeleton, *, h: float | None = None) -> float:
    """:func:`synthesize`'s default of the resampling step ``h`` for this source skeleton.

    The paper's :func:`~phloem.branching.default_h` (the median thickness, about one branch
    radius), but at least :data:`MIN_H` (2 px): below that, the steps of a traced centre line
    sample the pixel grid's staircase, and the Markov chain, which remembers ``order`` steps,
    holds a course over only a few pixels (cracks, thin bolts and vessels a pixel or two wide).

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    h : float, optional
        A value chosen by the caller, returned as it is.

    Returns
    -------
    float
        ``h`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> h_default(Skeleton([Branch([[0, 0], [100, 0]], 0.8)])), h_default(Skeleton([Branch([[0, 0], [100, 0]], 3.5)]))
    (2.0, 3.5)
    """
    _check_source(skeleton)
    if h is not None:
        return h
    return max(default_h(skeleton), MIN_H)


def _check_source(skeleton: Any) -> None:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"skeleton: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")


def _course_known(skeleton: Skeleton) -> bool:
    """Whether the input's heading statistics are well determined (its drift noise at most :data:`COURSE_NOISE`)."""
    try:
        return drift_noise(skeleton) <= COURSE_NOISE
    except ValueError:  # no branch long enough, or a single stretch: nothing to learn a course from
        return False


def orientation_default(skeleton: Skeleton, *, orientation: float | None = None, guided: bool = False) -> float:
    """:func:`synthesize`'s default of ``orientation`` for this source skeleton.

    ``3.0`` where the input runs one way on the image, that is where
    :func:`phloem.metrics.direction_concentration` of ``skeleton`` is at least 0.4 (bolts that
    hang down, cracks and roots that run along one axis): branches then keep the ways the
    input's run, which the paper's turn-only model forgets after a few steps. Otherwise
    ``0.0``, the paper's orientation-independent model: a structure that runs every way has
    no direction to keep, and matching its headings only narrows the candidates. Also ``0.0``
    where the growth is ``guided``: a guide says which way the new structure runs (§4.5).

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    orientation : float, optional
        A weight chosen by the caller, returned as it is.
    guided : bool, optional
        Whether :func:`grow` is given a ``guide`` (default False).

    Returns
    -------
    float
        ``orientation`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> orientation_default(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]))
    3.0
    >>> orientation_default(Skeleton([Branch([[0, 0], [50, 0], [50, 50]], 1.0)]))
    0.0
    """
    _check_source(skeleton)
    if orientation is not None:
        return orientation
    if guided:
        return 0.0
    try:
        directed = direction_concentration(skeleton) >= ORIENTATION_CONCENTRATION
    except ValueError:  # no branch with any length: no direction to keep
        directed = False
    return ORIENTATION_WEIGHT if directed else 0.0


def direction_histogram_default(
    skeleton: Skeleton, *, direction_histogram: float | None = None, guided: bool = False
) -> float:
    """:func:`synthesize`'s default of ``direction_histogram`` for this source skeleton.

    ``1.0`` where :func:`orientation_default` turns the heading on (the input runs one way on
    the image and no ``guide`` is given): the heading keeps a branch running the way it runs,
    and the histogram steers back a branch that has wandered off the input's ways (a bolt
    that turned sideways, a root that turned back). Otherwise ``0.0``, the paper's model.

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    direction_histogram : float, optional
        A weight chosen by the caller, returned as it is.
    guided : bool, optional
        Whether :func:`grow` is given a ``guide`` (default False).

    Returns
    -------
    float
        ``direction_histogram`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> direction_histogram_default(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]))
    1.0
    >>> direction_histogram_default(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]), guided=True)
    0.0
    """
    _check_source(skeleton)
    if direction_histogram is not None:
        return direction_histogram
    return DIRECTION_HISTOGRAM_WEIGHT if orientation_default(skeleton, guided=guided) > 0 else 0.0


def layout_default(skeleton: Skeleton, *, layout: float | None = None, guided: bool = False) -> float:
    """:func:`synthesize`'s default of ``layout`` for this source skeleton.

    ``1.0`` where the input is connected (its largest tree holds
    :data:`~phloem.branching._forest.CONNECTED_SHARE` of its length) and no ``guide`` is given:
    such an input is one structure across its picture (a river's belt, a delta's fan, a crack),
    and the one tree grown from it runs the way the input runs at the same places instead of
    wandering to an edge of the picture. Otherwise ``0.0``, the paper's model, the same
    everywhere: a forest of pieces (vessel photos, a terrain's valleys) packed its trees into a
    knot under the term (``docs/pipelines/branching/quality.md``, forty-second, forty-third
    and fifty-fourth sessions). Where the input's branches agree on no way (a crack) the term
    changes little either way.

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    layout : float, optional
        A weight chosen by the caller, returned as it is.
    guided : bool, optional
        Whether :func:`grow` is given a ``guide`` (default False): the guide sets the way.

    Returns
    -------
    float
        ``layout`` for :func:`fit_models`.

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> tree = Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0), Branch([[12, 50], [40, 60]], 1.0, parent=(0, 1))])
    >>> layout_default(tree), layout_default(tree, guided=True)
    (1.0, 0.0)
    >>> pieces = Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0), Branch([[50, 0], [52, 50], [49, 100]], 1.0)])
    >>> layout_default(pieces)
    0.0
    """
    _check_source(skeleton)
    if layout is not None:
        return layout
    return LAYOUT_WEIGHT if not guided and connected(input_trees(skeleton)) else 0.0


@dataclass(frozen=True)
class SourceDefaults:
    """The options :func:`synthesize` resolves from its source skeleton (:func:`source_defaults`).

    Attributes
    ----------
    total_turn : float
        For :func:`fit_models` (:func:`course_defaults`).
    repel_border : bool
        For :func:`grow` (:func:`course_defaults`).
    course : int or None
        For :func:`fit_models` (:func:`course_edges_default`).
    orientation : float
        For :func:`fit_models` (:func:`orientation_default`).
    direction_histogram : float
        For :func:`fit_models` (:func:`direction_histogram_default`).
    turn_histogram : float
        For :func:`fit_models`: :data:`~phloem.branching.bending.TURN_HISTOGRAM`, or
        :data:`GUIDED_TURN_HISTOGRAM` with a guide.
    denoise : float
        For :func:`fit_models` (:func:`denoise_default`).
    h : float
        For :func:`fit_models` (:func:`h_default`).
    joined_ends : float
        For :func:`grow`: the share of the source's branches that end on other structure
        (:func:`~phloem.metrics.joined_end_share`).
    layout : float
        For :func:`fit_models` (:func:`layout_default`).
    """

    total_turn: float
    repel_border: bool
    course: int | None
    orientation: float
    direction_histogram: float
    turn_histogram: float
    denoise: float
    h: float
    joined_ends: float = 0.0
    layout: float = 0.0


def source_defaults(
    skeleton: Skeleton,
    *,
    total_turn: float | None = None,
    repel_border: bool | None = None,
    course: int | None = None,
    orientation: float | None = None,
    direction_histogram: float | None = None,
    turn_histogram: float | None = None,
    denoise: float | None = None,
    h: float | None = None,
    joined_ends: float | None = None,
    layout: float | None = None,
    guided: bool = False,
) -> SourceDefaults:
    """Every option that :func:`synthesize` defaults from its source skeleton, resolved at once.

    :func:`synthesize`, ``phloem branching grow`` and the studio's growth all call this, so a
    skeleton grows the same way from each of them. A value chosen by the caller is kept; those
    left at None get :func:`course_defaults`' (``total_turn``, ``repel_border``),
    :func:`course_edges_default`'s, :func:`orientation_default`'s,
    :func:`direction_histogram_default`'s, :func:`denoise_default`'s, :func:`h_default`'s and
    :func:`layout_default`'s, ``joined_ends`` the source's :func:`~phloem.metrics.joined_end_share`;
    ``turn_histogram`` gets :data:`~phloem.branching.bending.TURN_HISTOGRAM`, or
    :data:`GUIDED_TURN_HISTOGRAM` with a guide.

    Parameters
    ----------
    skeleton : Skeleton
        The example structure.
    total_turn, repel_border, course, orientation, direction_histogram, turn_histogram, denoise, h, joined_ends, layout : optional
        Values chosen by the caller.
    guided : bool, optional
        Whether :func:`grow` is given a ``guide`` (default False): a guide sets the way the new
        structure runs, so the heading terms stay off and the heading-change histogram is
        matched more weakly.

    Returns
    -------
    SourceDefaults

    Examples
    --------
    >>> from phloem.branching import Branch, Skeleton
    >>> d = source_defaults(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]))
    >>> d.total_turn, d.repel_border, d.course, d.orientation, d.direction_histogram
    (0.0, False, 0, 3.0, 1.0)
    >>> source_defaults(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]), guided=True, course=8).course
    8
    >>> d.turn_histogram, source_defaults(Skeleton([Branch([[10, 0], [12, 50], [9, 100]], 1.0)]), guided=True).turn_histogram
    (10.0, 3.0)
    """
    turn, border = course_defaults(skeleton, total_turn=total_turn, repel_border=repel_border)
    if turn_histogram is None:
        turn_histogram = GUIDED_TURN_HISTOGRAM if guided else TURN_HISTOGRAM
    return SourceDefaults(
        total_turn=turn,
        repel_border=border,
        course=course_edges_default(skeleton, course=course),
        orientation=orientation_default(skeleton, orientation=orientation, guided=guided),
        direction_histogram=direction_histogram_default(
            skeleton, direction_histogram=direction_histogram, guided=guided
        ),
        turn_histogram=turn_histogram,
        denoise=denoise_default(skeleton, denoise=denoise),
        h=h_default(skeleton, h=h),
        joined_ends=joined_end_share(skeleton) if joined_ends is None else float(joined_ends),
        layout=layout_default(skeleton, layout=layout, guided=guided),
    )


@renamed(k="order", c="n_best")
def synthesize(
    image: Any,
    skeleton: Skeleton | None = None,
    *,
    size: Size | None = None,
    seed: Seed = 0,
    trace_options: dict[str, Any] | None = None,
    h: float | None = None,
    order: int = 3,
    m: int | None = None,
    n_best: int = N_BEST,
    course: int | None = None,
    coarse_history: float = 2.0,
    total_turn: float | None = None,
    turn_bound: float | None = None,
    orientation: float | None = None,
    turn_histogram: float | None = None,
    stem_thickness: float = STEM_THICKNESS,
    direction_histogram: float | None = None,
    layout: float | None = None,
    denoise: float | None = None,
    generations: int | None = None,
    max_length: float | str | None = "input",
    colonize: bool = True,
    repel_border: bool | None = None,
    joined_ends: float | None = None,
    guide: Any = None,
    valid: Any = "auto",
    render_options: dict[str, Any] | None = None,
    threads: int | None = None,
    progress: Progress = None,
    max_memory: int | None = None,
    models: tuple[BendingModel, FurcationModel | None] | None = None,
) -> SynthesisResult:
    """A new image of a branching structure like the one in ``image`` (Sibbing et al. 2010).

    1. the source skeleton: ``skeleton``, or :func:`trace` of ``image`` (with
       ``trace_options``);
    2. the bending model (§4.2) and, if the source branches, the furcation model (§4.3);
    3. a new skeleton by :func:`grow` (§4.4–4.5) on a canvas of ``size``, by default about as
       much structure as the input holds (``max_length="input"``);
    4. the new image by :func:`render` (§5: fragments, deformation, photometric correction,
       seams, gap completion), with ``render_options``.

    Parameters
    ----------
    image : (H, W[, C]) array_like
        The example image.
    skeleton : Skeleton, optional
        Its skeleton; traced when omitted.
    size : int or (int, int), optional
        ``(H, W)`` of the new image (default: the input's).
    seed : int or numpy.random.Generator, optional
        Seed of the growth and of the fragment choices.
    trace_options : dict, optional
        Keyword arguments for :func:`trace` (e.g. ``{"kind": "dark", "sigmas": (1.5, 3, 5)}``).
    h, order, m, n_best, course, coarse_history, total_turn, turn_bound, orientation, turn_histogram, stem_thickness, direction_histogram, layout, denoise : optional
        Model parameters, as in :func:`fit_models` (``k`` and ``c`` before, deprecated).
        ``total_turn`` defaults to :func:`course_defaults`'s for the source skeleton,
        ``course`` to :func:`course_edges_default`'s (0 where the total turn is off),
        ``turn_bound`` to 5 where the total turn is matched, ``orientation`` to
        :func:`orientation_default`'s (3 where the source runs one way on the image and no
        ``guide`` is given, else 0) and ``direction_histogram`` to
        :func:`direction_histogram_default`'s (1 where the orientation is on, else 0),
        ``turn_histogram`` to :data:`~phloem.branching.bending.TURN_HISTOGRAM` (10; 3 with a
        ``guide``, :data:`GUIDED_TURN_HISTOGRAM`), ``layout`` to :func:`layout_default`'s (1
        where the source is one connected structure and no ``guide`` is given, else 0; 1 grows
        the branches along the input's ways at the same places of the picture). ``denoise`` defaults to :func:`denoise_default`'s
        (3 px where the source's branches keep a course, else 0): the source's branches are
        smoothed before their angles are taken, so that a traced centre line's pixel
        staircase is not grown as wander. ``h`` defaults to :func:`h_default`'s (the median
        thickness, at least 2 px).
    generations, max_length, colonize, guide : optional
        See :func:`grow`.
    repel_border : bool, optional
        See :func:`grow`; default :func:`course_defaults`'s for the source skeleton (on with
        ``total_turn``).
    joined_ends : float, optional
        See :func:`grow`; default the source's :func:`~phloem.metrics.joined_end_share`, so
        that as many of the new branches end on other structure as the input's do (channels
        that rejoin round islands; a tree's ends stay free). 0: the paper's trees.
    valid : (H, W) array_like of bool, "auto" or None, optional
        Where ``image`` shows content: structure is traced there only (when ``skeleton`` is
        not given), fragments are taken from inside it and the gaps completed from it.
        ``"auto"`` (default): :func:`valid_region`, everything but a flat frame touching the
        border (a fundus photo's black disc frame, constant padding); None: everywhere. The
        new image keeps the input's frame around it, stretched to ``size``, where that frame
        runs along at least a sixth of the border (:func:`render`'s ``keep_frame``), and the
        new structure then grows inside it (:func:`grow`'s ``domain``).
    render_options : dict, optional
        Keyword arguments for :func:`render`. Its ``gap_diversity`` defaults to
        :func:`gap_diversity_default`'s for ``image`` with ``trace_options`` (1 on a grainy
        surface such as asphalt, else 0).
    threads : int, optional
        Worker threads for the pixel work.
    progress : callable, optional
        ``progress(done, total)`` over the four stages' work.
    max_memory : int, optional
        Refuse the job with :class:`phloem.MemoryLimitError` if its estimated peak memory is
        over this many bytes (default None: 75% of the machine's memory; see ``docs/hardening/memory.md``).
    models : (BendingModel, FurcationModel or None), optional
        Models fitted to ``skeleton`` before (an earlier result's ``bending`` and ``furcation``),
        used instead of fitting them again: many seeds of one input fit once. ``h``, ``order``,
        ``m``, ``n_best``, ``course``, ``coarse_history``, ``total_turn``, ``turn_bound``,
        ``orientation``, ``turn_histogram``, ``stem_thickness``, ``direction_histogram``,
        ``layout`` and ``denoise`` are then not used.

    Returns
    -------
    SynthesisResult

    Examples
    --------
    >>> import numpy as np, cv2
    >>> img = np.full((96, 128), 0.8, np.float32)
    >>> _ = cv2.line(img, (5, 90), (70, 40), 0.1, 5); _ = cv2.line(img, (70, 40), (125, 5), 0.1, 4)
    >>> _ = cv2.line(img, (70, 40), (90, 92), 0.1, 3)
    >>> res = synthesize(img, trace_options={"kind": "dark", "sigmas": (1.5, 2.5)}, seed=1)
    >>> res.image.shape, res.target.shape
    ((96, 128), (96, 128))
    """
    img = as_image(image, "image")
    shape = img.shape[:2] if size is None else check_size(size, "size")
    _memory.check_size(_memory.branching(shape, img.shape), max_memory, shape)
    steps = 4

    def tick(i: int) -> None:
        if progress is not None:
            progress(i, steps)

    if isinstance(valid, str):
        if valid != "auto":
            raise ValueError(f"valid: expected a boolean (H, W) mask, 'auto' or None, got {valid!r}")
        ok: NDArray[np.bool_] | None = valid_region(img)
        ok = None if ok is not None and ok.all() else ok
    else:
        ok = None if valid is None else as_mask(valid, "valid", img.shape[:2])
    if skeleton is None:
        source = trace(img, **({"valid": ok} | (trace_options or {})))
    elif isinstance(skeleton, Skeleton):
        source = skeleton
        if source.shape is not None and source.shape != img.shape[:2]:
            raise ValueError(f"skeleton: made for a {source.shape} image, but image is {img.shape[:2]}")
        # Before fitting: a skeleton without a shape is only known to fit the image here, and
        # the models' resampling would otherwise walk far-away coordinates vertex by vertex.
        source.check_inside(img.shape[:2], "skeleton")
    else:
        raise TypeError(f"skeleton: expected a phloem.branching.Skeleton, got {type(skeleton).__name__}")
    tick(1)
    d = source_defaults(
        source, total_turn=total_turn, repel_border=repel_border, course=course, orientation=orientation,
        direction_histogram=direction_histogram, turn_histogram=turn_histogram, denoise=denoise, h=h,
        joined_ends=joined_ends, layout=layout, guided=guide is not None,
    )  # fmt: skip
    if models is None:
        bending, furcation = fit_models(
            source, h=d.h, order=order, m=m, n_best=n_best, course=d.course, coarse_history=coarse_history,
            total_turn=d.total_turn, turn_bound=turn_bound, orientation=d.orientation, turn_histogram=d.turn_histogram,
            stem_thickness=stem_thickness, direction_histogram=d.direction_histogram, layout=d.layout, denoise=d.denoise,
        )  # fmt: skip
    elif (
        isinstance(models, tuple)
        and len(models) == 2
        and isinstance(models[0], BendingModel)
        and (models[1] is None or isinstance(models[1], FurcationModel))
    ):
        bending, furcation = models
    else:
        raise TypeError("models: expected (BendingModel, FurcationModel or None), as a result's bending and furcation")
    tick(2)
    target = grow(
        bending, furcation, size=shape, seed=seed, generations=generations, max_length=max_length,
        colonize=colonize, repel_border=d.repel_border, guide=guide,
        domain=None if ok is None else _kept_inside(ok, shape), joined_ends=d.joined_ends,
    )  # fmt: skip
    tick(3)
    ropts = {"valid": ok} | (render_options or {})
    if ropts.get("complete", True):
        # resolved with the trace's options, which render does not know
        ropts["gap_diversity"] = gap_diversity_default(
            img, valid=ropts["valid"], trace_options=trace_options, gap_diversity=ropts.get("gap_diversity")
        )
    # A 2-D input goes to render as 2-D, so that the new image is 2-D as well.
    res = render(
        img[..., 0] if np.ndim(image) == 2 else img,
        source,
        target,
        seed=seed,
        threads=threads,
        full_output=True,
        max_memory=max_memory,
        **ropts,
    )
    tick(4)
    return SynthesisResult(res.image, source, target, bending, furcation, res)
