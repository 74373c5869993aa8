"""branching.synthesize: fitted models passed back in give the same image as fitting again."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import branching
from phloem.branching.bending import TURN_HISTOGRAM
from phloem.branching.pipeline import GUIDED_TURN_HISTOGRAM, N_BEST


def _river() -> np.ndarray:
    img = np.full((96, 128), 0.8, np.float32)
    cv2.line(img, (5, 90), (70, 40), 0.1, 5)
    cv2.line(img, (70, 40), (125, 5), 0.1, 4)
    cv2.line(img, (70, 40), (90, 92), 0.1, 3)
    return img


def test_models_of_an_earlier_result_make_the_same_image_as_fitting_again():
    img, opts = _river(), {"kind": "dark", "sigmas": (1.5, 2.5)}
    first = branching.synthesize(img, trace_options=opts, seed=1)
    again = branching.synthesize(img, trace_options=opts, seed=2)
    reused = branching.synthesize(img, first.source, seed=2, models=(first.bending, first.furcation))
    assert np.array_equal(reused.image, again.image) and reused.target == again.target
    assert reused.bending is first.bending


@pytest.mark.parametrize("models", [("a", None), (None,), [1, 2]])
def test_models_of_the_wrong_kind_are_refused(models):
    with pytest.raises(TypeError, match="^models: expected"):
        branching.synthesize(_river(), trace_options={"kind": "dark", "sigmas": (1.5,)}, models=models)


def _meanders(n: int) -> branching.Skeleton:
    from phloem.testing import meander

    return branching.Skeleton(
        [meander((20, 40 + 30 * i), 0.0, 600, (3, 3), phase=float(i)) for i in range(n)], (60 + 30 * n, 700)
    )


@pytest.mark.parametrize("n", [1, 2, 4, 8])
def test_course_defaults_turn_on_where_the_input_s_drift_noise_is_at_most_0_125(n):
    from phloem.metrics import drift_noise

    sk = _meanders(n)
    on = drift_noise(sk) <= 0.125
    assert branching.course_defaults(sk) == ((2.0, True) if on else (0.0, False))


def test_course_defaults_of_inputs_with_much_and_with_little_long_branch():
    assert branching.course_defaults(_meanders(4)) == (2.0, True)  # 2400 px of branch: noise 0.10
    assert branching.course_defaults(_meanders(1)) == (0.0, False)  # 600 px: noise 0.20
    # no branch of 60 px: drift_noise has nothing to resample, so the paper's model
    short = branching.Skeleton([branching.Branch(np.array([[5.0, 5.0], [40.0, 9.0]]), np.full(2, 2.0))], (50, 50))
    assert branching.course_defaults(short) == (0.0, False)
    # a caller's values are kept, only those left at None are defaulted
    assert branching.course_defaults(_meanders(4), total_turn=0.5) == (0.5, True)
    assert branching.course_defaults(_meanders(1), repel_border=True) == (0.0, True)
    assert branching.course_defaults(short, total_turn=3.0, repel_border=False) == (3.0, False)
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.course_defaults("not a skeleton")  # type: ignore[arg-type]


def test_course_edges_default_switches_the_course_term_off_where_the_course_is_unknown():
    # the same criterion as course_defaults: the bending model's 8 m edges (None) where the
    # input's heading statistics are well determined, the paper's model (0) where not
    assert branching.course_edges_default(_meanders(4)) is None
    assert branching.course_edges_default(_meanders(1)) == 0
    short = branching.Skeleton([branching.Branch(np.array([[5.0, 5.0], [40.0, 9.0]]), np.full(2, 2.0))], (50, 50))
    assert branching.course_edges_default(short) == 0
    assert branching.course_edges_default(_meanders(1), course=12) == 12
    assert branching.course_edges_default(_meanders(4), course=0) == 0
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.course_edges_default("not a skeleton")  # type: ignore[arg-type]
    # synthesize fits with it: no course term on the short input, unless asked for
    sk = _meanders(1)
    img = np.full(sk.shape, 0.8, np.float32)
    for b in sk.branches:
        cv2.polylines(img, [np.round(b.points).astype(np.int32)], False, 0.1, 5)
    auto = branching.synthesize(img, sk, seed=3)
    asked = branching.synthesize(img, sk, seed=3, course=8 * auto.bending.m)
    assert auto.bending.course == 0 and asked.bending.course == 8 * auto.bending.m
    assert auto.target != asked.target


def test_synthesize_resolves_total_turn_and_repel_border_from_the_source():
    sk = _meanders(4)
    img = np.full(sk.shape, 0.8, np.float32)
    for b in sk.branches:
        cv2.polylines(img, [np.round(b.points).astype(np.int32)], False, 0.1, 5)
    size = (120, 260)
    auto = branching.synthesize(img, sk, size=size, seed=3)
    assert auto.bending.total_turn == 2.0 and auto.bending.course == 8 * auto.bending.m
    explicit = branching.synthesize(img, sk, size=size, seed=3, total_turn=2.0, repel_border=True)
    assert auto.target == explicit.target
    border_off = branching.synthesize(img, sk, size=size, seed=3, repel_border=False)
    assert border_off.bending.total_turn == 2.0 and border_off.target != auto.target
    paper = branching.synthesize(img, sk, size=size, seed=3, total_turn=0.0)
    assert paper.bending.total_turn == 0.0


def _hanging(n: int, jitter: float) -> branching.Skeleton:
    """``n`` branches zig-zagging down the image by ``jitter`` px either side."""
    rng = np.random.default_rng(1)
    brs = []
    for i in range(n):
        y = np.arange(10.0, 190.0, 6.0)
        x = 20.0 + 25 * i + rng.uniform(-jitter, jitter, len(y))
        brs.append(branching.Branch(np.c_[x, y], 2.0))
    return branching.Skeleton(brs, (200, 40 + 25 * n))


def test_orientation_default_turns_on_where_the_input_runs_one_way():
    from phloem.metrics import direction_concentration

    for jitter in (0.0, 2.0, 4.0, 6.0, 12.0):
        sk = _hanging(5, jitter)
        on = direction_concentration(sk) >= 0.4
        assert branching.orientation_default(sk) == (3.0 if on else 0.0)
    assert branching.orientation_default(_hanging(5, 1.0)) == 3.0  # nearly straight down
    assert branching.orientation_default(_hanging(5, 12.0)) == 0.0  # zig-zags every way
    # a caller's weight is kept; a structure of no length has no direction
    assert branching.orientation_default(_hanging(5, 1.0), orientation=0.5) == 0.5
    assert branching.orientation_default(_hanging(5, 1.0), guided=True) == 0.0  # a guide sets the way
    assert branching.orientation_default(_hanging(5, 1.0), orientation=0.5, guided=True) == 0.5
    dot = branching.Skeleton([branching.Branch(np.array([[5.0, 5.0], [5.0, 5.0]]), np.full(2, 1.0))], (10, 10))
    assert branching.orientation_default(dot) == 0.0
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.orientation_default("not a skeleton")  # type: ignore[arg-type]


def test_layout_default_turns_on_for_one_connected_structure():
    # a stem with four children is one structure across its picture; the same branches apart
    # are a forest of pieces, whose trees the layout term packed into a knot (the brain)
    pieces = _hanging(5, 4.0)
    stem = branching.Branch(np.c_[np.arange(10.0, 150.0, 4.0), np.full(35, 100.0)], 3.0)
    kids = [
        branching.Branch(b.points[:15] + [0.0, 0.0], 2.0, parent=(0, 5 + 6 * i))
        for i, b in enumerate(pieces.branches[1:])
    ]
    for kid in kids:  # each child leaves from its parent vertex
        kid.points = kid.points - kid.points[0] + stem.points[kid.parent[1]]
    tree = branching.Skeleton([stem, *kids], (200, 165))
    assert branching.layout_default(tree) == 1.0
    assert branching.layout_default(pieces) == 0.0
    assert branching.layout_default(tree, guided=True) == 0.0  # a guide sets the way
    assert branching.layout_default(pieces, layout=0.5) == 0.5
    assert branching.source_defaults(tree).layout == 1.0 and branching.source_defaults(pieces).layout == 0.0
    # a speck beside one structure does not make it a forest; a second structure does
    speck = branching.Branch(np.array([[150.0, 20.0], [152.0, 22.0], [154.0, 24.0]]), 1.0)
    assert branching.layout_default(branching.Skeleton([stem, *kids, speck], (200, 165))) == 1.0
    other = branching.Branch(np.c_[np.full(30, 155.0), np.arange(20.0, 140.0, 4.0)], 2.0)
    assert branching.layout_default(branching.Skeleton([stem, *kids, other], (200, 165))) == 0.0
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.layout_default("not a skeleton")  # type: ignore[arg-type]


def test_synthesize_fits_the_layout_of_a_connected_input():
    from phloem.testing import channel_scene

    img, sk = channel_scene()
    assert branching.layout_default(sk) == 1.0
    res = branching.synthesize(img, sk, seed=0)
    assert res.bending.layout == 1.0 and res.bending.direction_layout is not None
    off = branching.synthesize(img, sk, seed=0, layout=0.0)
    assert off.bending.layout == 0.0 and off.bending.direction_layout is None


def test_direction_histogram_default_follows_the_orientation_default():
    for jitter in (0.0, 4.0, 12.0):
        sk = _hanging(5, jitter)
        on = branching.orientation_default(sk) > 0
        assert branching.direction_histogram_default(sk) == (1.0 if on else 0.0)
    assert branching.direction_histogram_default(_hanging(5, 1.0)) == 1.0
    assert branching.direction_histogram_default(_hanging(5, 12.0)) == 0.0
    assert branching.direction_histogram_default(_hanging(5, 1.0), guided=True) == 0.0  # a guide sets the way
    assert branching.direction_histogram_default(_hanging(5, 12.0), direction_histogram=2.0) == 2.0
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.direction_histogram_default("not a skeleton")  # type: ignore[arg-type]


@pytest.mark.parametrize("guided", [False, True])
@pytest.mark.parametrize("source", ["meanders", "hanging", "zigzag"])
def test_source_defaults_are_the_four_resolvers_at_once(source, guided):
    sk = {"meanders": _meanders(4), "hanging": _hanging(5, 1.0), "zigzag": _hanging(5, 12.0)}[source]
    d = branching.source_defaults(sk, guided=guided)
    assert (d.total_turn, d.repel_border) == branching.course_defaults(sk)
    assert d.course == branching.course_edges_default(sk)
    assert d.orientation == branching.orientation_default(sk, guided=guided)
    assert d.direction_histogram == branching.direction_histogram_default(sk, guided=guided)
    # a guide's path sets the turns: the heading-change histogram steps back to its weaker weight
    assert (
        d.turn_histogram == (GUIDED_TURN_HISTOGRAM if guided else TURN_HISTOGRAM)
        and GUIDED_TURN_HISTOGRAM < TURN_HISTOGRAM
    )
    # a caller's values are kept, each on its own
    chosen = {"total_turn": 0.5, "repel_border": True, "course": 12, "orientation": 0.25, "direction_histogram": 2.0,
              "turn_histogram": 7.0}  # fmt: skip
    got = branching.source_defaults(sk, guided=guided, **chosen)
    assert {k: getattr(got, k) for k in chosen} == chosen
    kept = branching.source_defaults(sk, guided=guided, course=12)
    assert kept.course == 12 and kept.orientation == d.orientation and kept.total_turn == d.total_turn
    with pytest.raises(TypeError, match="^skeleton: expected"):
        branching.source_defaults("not a skeleton")  # type: ignore[arg-type]


def test_synthesize_resolves_orientation_from_the_source():
    for jitter, want in ((1.0, 3.0), (12.0, 0.0)):
        sk = _hanging(4, jitter)
        img = np.full(sk.shape, 0.8, np.float32)
        for b in sk.branches:
            cv2.polylines(img, [np.round(b.points).astype(np.int32)], False, 0.1, 3)
        auto = branching.synthesize(img, sk, seed=2)
        assert auto.bending.orientation == want
        assert auto.bending.direction_histogram == want / 3.0  # on with the heading
        explicit = branching.synthesize(img, sk, seed=2, orientation=want)
        assert explicit.target == auto.target
        other = branching.synthesize(img, sk, seed=2, orientation=3.0 - want)
        assert other.bending.orientation == 3.0 - want and other.target != auto.target
    # a guide sets the way the new structure runs (§4.5)
    guided = branching.synthesize(img, _hanging(4, 1.0), seed=2, guide=np.array([[10.0, 100.0], [110.0, 100.0]]))
    assert guided.bending.orientation == 0.0 and guided.bending.direction_histogram == 0.0
    # and its path sets the turns: the heading-change histogram steps back; both draw from N_BEST
    assert guided.bending.turn_histogram == GUIDED_TURN_HISTOGRAM and auto.bending.turn_histogram == TURN_HISTOGRAM
    assert guided.bending.c == auto.bending.c == N_BEST
    alone = branching.synthesize(img, _hanging(4, 1.0), seed=2, direction_histogram=0.0)
    assert alone.bending.orientation == 3.0 and alone.bending.direction_histogram == 0.0
    assert alone.target != branching.synthesize(img, _hanging(4, 1.0), seed=2).target


def test_the_output_keeps_the_input_s_frame_and_grows_inside_it():
    from phloem.testing import channel_scene

    scene, _ = channel_scene()
    img = np.zeros((168, 264), np.float32)  # the scene in a flat black frame 20 px wide
    img[20:-20, 20:-20] = scene
    ok = branching.valid_region(img)
    assert not ok.all()
    res = branching.synthesize(img, trace_options={"kind": "dark", "sigmas": (1.5, 2.5)}, seed=1)
    core = cv2.erode((~ok).astype(np.uint8), np.ones((11, 11), np.uint8), borderType=cv2.BORDER_REPLICATE) > 0
    assert np.array_equal(res.image[core], img[core])  # the frame as it was, beyond its fade
    assert float(res.image[ok].mean()) > 0.5  # the picture inside, completed from the scene
    at = np.round(np.vstack([b.points for b in res.target.branches])).astype(int)
    assert ok[at[:, 1], at[:, 0]].all()  # the structure grows inside it
    # a new size stretches the frame; valid=None fills the whole canvas
    big = branching.synthesize(img, trace_options={"kind": "dark", "sigmas": (1.5, 2.5)}, seed=1, size=(336, 264))
    assert np.all(big.image[:36] == 0.0) and float(big.image[60:-60, 60:-60].mean()) > 0.5
    free = branching.synthesize(img, trace_options={"kind": "dark", "sigmas": (1.5, 2.5)}, seed=1, valid=None)
    assert not np.array_equal(free.image[~ok], img[~ok])


def _growth_bench():
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benches" / "quality" / "branching_growth_drift.py"
    spec = importlib.util.spec_from_file_location("_branching_growth_drift", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench  # its dataclass looks its module up by name
    spec.loader.exec_module(bench)
    return bench


@pytest.mark.parametrize("framed", [False, True])
@pytest.mark.parametrize(
    "options", [{}, {"n_best": 4, "turn_histogram": 10.0}, {"total_turn": 2.0, "course": 0}, {"repel_border": True}]
)
def test_the_growth_bench_grows_what_synthesize_grows(options, framed):
    # benches/quality/branching_growth_drift.py skips the rendering; its skeletons must be
    # synthesize's targets, or its drift tables measure something no user gets
    img = _river()
    if framed:  # a flat frame round the picture: the trace's valid region and growth's domain
        img = np.pad(img, 12, constant_values=0.0)
    bench = _growth_bench()
    source, grown, _ = bench.grown(img, [1, 2], options)
    for seed, target in zip([1, 2], grown):
        res = branching.synthesize(img, seed=seed, **options)
        assert res.source == source and res.target == target
    row = bench.measure("river", img, [1, 2], options)
    assert len(row.drifts) == len(row.shares) == 2 and 0 <= row.histograms <= 2


def test_the_growth_bench_reads_its_overrides():
    bench = _growth_bench()
    got = bench.parse_set(["course=0", "turn_histogram=6.5", "colonize=false", "generations=none", "max_length=input"])
    assert got == {"course": 0, "turn_histogram": 6.5, "colonize": False, "generations": None, "max_length": "input"}
    for bad in ("foo=1", "course", "=3"):
        with pytest.raises(SystemExit, match="^--set: "):
            bench.parse_set([bad])
