"""The bending model (Sibbing et al. 2010, §4.2): Markov quality, histogram matching, copying the source."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pytest

from phloem.branching import (
    BendingModel,
    Branch,
    Skeleton,
    SkeletonError,
    default_h,
    denoise_default,
    fit_models,
    grow,
    h_default,
    source_defaults,
    synthesize,
)
from phloem.branching.bending import DENOISE, STEM_THICKNESS, TURN_BOUND
from phloem.branching.pipeline import MIN_H
from phloem.metrics import drift

H = 2.0


def test_c1_large_k_reproduces_the_source_branch(walk_branch: Callable[..., Branch]):
    # Fig. 3d: with c = 1 and a large k the model copies the source branch exactly.
    src = walk_branch(np.random.default_rng(3), 120, 0.12)
    sk = Skeleton([src], (300, 400))
    model = BendingModel.fit(sk, h=H, k=20, m=15, c=1, omega_g=0.0)
    out = grow(
        model, size=(300, 400), start=(*src.points[0], src.heading()), branch_length=src.length(), colonize=False
    )
    got, want = out.branches[0].angles(), model.source.branches[0].angles()
    n = len(want) - model.m
    assert len(got) >= n
    np.testing.assert_allclose(got[:n], want[:n], atol=1e-9)
    np.testing.assert_allclose(out.branches[0].points[: n + 2], model.source.branches[0].points[: n + 2], atol=1e-6)
    # ... while allowing variability (Fig. 3b, c = 2) departs from it.
    varied = BendingModel.fit(sk, h=H, k=20, m=15, c=2, omega_g=0.0)
    loose = grow(
        varied,
        size=(300, 400),
        start=(*src.points[0], src.heading()),
        branch_length=src.length(),
        colonize=False,
        seed=1,
    )
    la = loose.branches[0].angles()
    assert not np.allclose(la[: min(n, len(la))], want[: min(n, len(la))], atol=1e-6)


def test_quality_is_the_papers_dist_product(walk_branch: Callable[..., Branch]):
    src = walk_branch(np.random.default_rng(0), 40, 0.2)
    model = BendingModel.fit(Skeleton([src]), h=H, k=3, m=2, omega_g=0.0)
    i = 5
    alpha, r = model.cand_hist_alpha[i], model.cand_hist_r[i] * H
    q = np.exp(model.log_quality(alpha, r, np.zeros(16), np.zeros(16)))
    assert q[i] == pytest.approx(4.0)  # dist = 2 for both at X = Y
    j = 9
    want = (1 / (np.linalg.norm(model.cand_hist_alpha[j] - alpha) + 1) + 1) * (
        1 / (np.linalg.norm(model.cand_hist_r[j] - r / H) + 1) + 1
    )
    assert q[j] == pytest.approx(want)
    assert (q > 1).all()


def test_histogram_matching_raises_quality_of_helpful_candidates(walk_branch: Callable[..., Branch]):
    src = walk_branch(np.random.default_rng(1), 80, 0.3)
    model = BendingModel.fit(Skeleton([src]), h=H)
    alpha, r = model.cand_hist_alpha[0], model.cand_hist_r[0] * H
    # A structure so far made only of angles from the input's most common bin: candidates that
    # add to that bin worsen the match, the others improve it (thickness counts match the input).
    top = int(np.argmax(model.hist_alpha))
    ca = np.zeros(16)
    ca[top] = 40.0
    cr = 40.0 * model.hist_r
    gain = model.log_quality(alpha, r, ca, cr) - model.log_quality(alpha, r, np.zeros(16), np.zeros(16))
    in_top = model.inc_alpha[:, top]
    assert (in_top == 0).any() and (in_top > 0).any()
    assert gain[in_top == 0].min() > gain[in_top > 0].max() - 1e-9
    assert gain[in_top == 0].mean() > gain[in_top == in_top.max()].mean()
    # the n_t / m factor: the same histograms with more nodes weigh more
    gain2 = model.log_quality(alpha, r, 2 * ca, 2 * cr) - model.log_quality(alpha, r, np.zeros(16), np.zeros(16))
    assert np.abs(gain2).max() > np.abs(gain).max()


@pytest.mark.parametrize(("coarse", "turn", "arcs"), [(0.0, 0.0, 0.0), (2.0, 0.0, 0.0), (2.0, 1.5, 3.0)])
def test_histogram_term_is_the_papers_with_the_angle_part_weighted_by_the_angle_terms(
    walk_branch: Callable[..., Branch], coarse: float, turn: float, arcs: float
) -> None:
    """Against §4.2's formula written out: ω_G (a Δ_α + Δ_r) n_t / m with
    Δ_x(i) = (‖Ĥ - H‖² - ‖Ĥ - H^i‖²) / B and a = 1 + coarse_history + total_turn + turn_histogram."""
    src = walk_branch(np.random.default_rng(2), 90, 0.3)
    model = BendingModel.fit(Skeleton([src]), h=H, coarse_history=coarse, total_turn=turn, turn_histogram=arcs)
    assert model.turn_histogram == arcs  # the 178-px branch spans the 60-px arc
    assert model.angle_weight == 1.0 + coarse + turn + arcs
    alpha, r = model.cand_hist_alpha[0], model.cand_hist_r[0] * H
    rng = np.random.default_rng(3)
    ca, cr = rng.integers(0, 9, 16).astype(float), rng.integers(0, 9, 16).astype(float)
    n_t = ca.sum()
    cr *= n_t / cr.sum()

    def delta(target: np.ndarray, counts: np.ndarray, inc: np.ndarray) -> np.ndarray:
        now = ((target - counts / n_t) ** 2).sum()
        after = ((target[None] - (counts[None] + inc) / (n_t + model.m)) ** 2).sum(axis=1)
        return (now - after) / model.bins

    want = (
        model.omega_g
        * (n_t / model.m)
        * (
            (1.0 + coarse + turn + arcs) * delta(model.hist_alpha, ca, model.inc_alpha)
            + delta(model.hist_r, cr, model.inc_r)
        )
    )
    got = model.log_quality(alpha, r, ca, cr) - model.log_quality(alpha, r, np.zeros(16), np.zeros(16))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)


def test_arc_window_turns_of_constant_turns_wrap_to_pi():
    from phloem.branching.bending import arc_window_turns

    # a circle's arc: the heading changes by the sum of the turns, wrapped to [0, π]
    np.testing.assert_allclose(arc_window_turns(np.full(40, 0.1), 30), np.full(11, 3.0), atol=1e-12)
    np.testing.assert_allclose(arc_window_turns(np.full(40, -0.15), 30), np.full(11, 2 * np.pi - 4.5), atol=1e-12)
    assert arc_window_turns(np.full(10, 0.1), 30).size == 0  # shorter than the arc: no value
    # on a resampled circle of radius R it is the heading change over the arc, edges h / R apart
    t = np.linspace(0, np.pi, 2000)
    circle = Skeleton([Branch(np.c_[200 + 80 * np.cos(t), 200 - 80 * np.sin(t)], 1.0)])
    a = circle.resample(2.0).branches[0].angles()
    np.testing.assert_allclose(arc_window_turns(a, 30), 60 / 80, rtol=0.01)


def test_fit_keeps_the_inputs_heading_change_histogram_over_the_arc(walk_branch: Callable[..., Branch]):
    from phloem.branching.bending import arc_window_turns

    src = Skeleton([walk_branch(np.random.default_rng(s), 90, 0.3) for s in range(3)])
    model = BendingModel.fit(src, h=H, m=4)
    assert model.arc_edges == 30  # 60 px at h = 2
    turns = np.concatenate([arc_window_turns(b.angles(), 30) for b in model.source.branches])
    want = np.histogram(turns, bins=16, range=(0, np.pi))[0] / turns.size
    np.testing.assert_allclose(model.hist_arc, want, atol=1e-12)
    assert BendingModel.fit(src, h=H, m=4, arc=4.0).arc_edges == 5  # at least one element beyond an extension
    # no branch spans the arc: nothing to match, the term is off
    assert BendingModel.fit(src, h=H, arc=400.0).turn_histogram == 0.0


def test_arc_delta_is_the_papers_delta_on_the_heading_change_histogram(walk_branch: Callable[..., Branch]):
    """Brute force: each candidate's continuation appended to the branch, its windows counted."""
    from phloem.branching.bending import arc_window_turns

    src = Skeleton([walk_branch(np.random.default_rng(s), 90, 0.4) for s in range(2)])
    model = BendingModel.fit(src, h=H, m=4, arc=20.0)  # windows of 10 elements
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 9, 16).astype(float)
    for tail in (rng.normal(0, 0.4, 20), rng.normal(0, 0.4, 7)):  # all windows, then the first one missing
        got = model.arc_delta(tail, counts)
        assert got is not None
        want = []
        n = counts.sum()
        now = ((model.hist_arc - counts / n) ** 2).sum()
        for nxt in model.next_alpha:
            full = np.concatenate([tail, nxt])
            new = arc_window_turns(full, 10)[-min(4, len(full) - 9) :]
            after = counts + np.bincount(np.minimum((new / np.pi * 16).astype(int), 15), minlength=16)
            want.append((now - ((model.hist_arc - after / (n + len(new))) ** 2).sum()) / 16)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert model.arc_delta(rng.normal(0, 0.4, 5), counts) is None  # no window ends in the continuation
    assert model.arc_delta(rng.normal(0, 0.4, 20), np.zeros(16)) is None  # nothing counted yet
    # in log Q: ω_G turn_histogram Δ n / m beside the other terms
    alpha, r = model.cand_hist_alpha[0], model.cand_hist_r[0] * H
    ca, cr = 10.0 * model.hist_alpha, 10.0 * model.hist_r
    tail = rng.normal(0, 0.4, 20)
    extra = model.log_quality(alpha, r, ca, cr, arc_tail=tail, counts_arc=counts) - model.log_quality(alpha, r, ca, cr)
    np.testing.assert_allclose(
        extra, model.omega_g * model.turn_histogram * model.arc_delta(tail, counts) * counts.sum() / 4, rtol=1e-9
    )


def test_direction_delta_is_the_papers_delta_on_the_direction_histogram(walk_branch: Callable[..., Branch]):
    """Brute force: each candidate's continuation laid from the heading, its edges' axes binned
    as phloem.metrics.direction_histogram bins them, and the input's histogram the same way."""
    from phloem.metrics import direction_histogram

    src = Skeleton([walk_branch(np.random.default_rng(s), 90, 0.4) for s in range(2)])
    model = BendingModel.fit(src, h=H, m=4, direction_histogram=1.0)
    np.testing.assert_allclose(model.hist_dir, direction_histogram(model.source, bins=16)[0], atol=1e-12)
    rng = np.random.default_rng(5)
    counts = rng.integers(0, 9, 16).astype(float)
    n = counts.sum()
    now = ((model.hist_dir - counts / n) ** 2).sum()
    for heading in (0.3, -2.0, 3.1):
        got = model.direction_delta(heading, counts)
        want = []
        for nxt in model.next_alpha:
            heads = heading + np.cumsum(nxt)  # the m new edges' headings
            pts = Branch.from_angles([0.0, 0.0], heads[0], np.diff(heads), 1.0, H).points
            # the m edges, each h long: the length-weighted shares times m are their counts
            after = counts + direction_histogram(Skeleton([Branch(pts, 1.0)]), bins=16)[0] * len(nxt)
            want.append((now - ((model.hist_dir - after / (n + len(nxt))) ** 2).sum()) / 16)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    # in log Q: ω_G direction_histogram Δ n / m beside the other terms, only with a heading
    alpha, r = model.cand_hist_alpha[0], model.cand_hist_r[0] * H
    ca, cr = 10.0 * model.hist_alpha, 10.0 * model.hist_r
    plain = model.log_quality(alpha, r, ca, cr)
    extra = model.log_quality(alpha, r, ca, cr, heading=0.3, counts_dir=counts) - plain
    np.testing.assert_allclose(extra, model.omega_g * model.direction_delta(0.3, counts) * n / 4, rtol=1e-9)
    np.testing.assert_array_equal(model.log_quality(alpha, r, ca, cr, counts_dir=counts), plain)
    off = BendingModel.fit(src, h=H, m=4)
    assert off.direction_histogram == 0.0
    np.testing.assert_array_equal(off.log_quality(alpha, r, ca, cr, heading=0.3, counts_dir=counts), plain)
    with pytest.raises(ValueError, match="^direction_histogram:"):
        BendingModel.fit(src, h=H, direction_histogram=-1.0)


def test_bad_input_errors() -> None:
    tiny = Skeleton([Branch([[0, 0], [2, 0], [4, 0], [6, 0]], 1.0)])
    with pytest.raises(ValueError, match="skeleton: the skeleton has no branches"):
        BendingModel.fit(Skeleton([]))
    with pytest.raises(ValueError, match=r"skeleton: no branch is long enough for k \+ m"):
        BendingModel.fit(tiny, h=H)
    with pytest.raises(SkeletonError, match="NaN"):
        Branch([[0, 0], [np.nan, 1]], 1.0)
    with pytest.raises(ValueError, match="^h:"):
        BendingModel.fit(tiny, h=float("nan"))
    with pytest.raises(ValueError, match="^k:"):
        BendingModel.fit(tiny, h=H, k=0)
    with pytest.raises(TypeError, match="^skeleton:"):
        BendingModel.fit([[0, 0], [1, 1]])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^turn_histogram:"):
        BendingModel.fit(tiny, h=1.0, k=1, m=1, turn_histogram=-1.0)
    with pytest.raises(ValueError, match="^arc:"):
        BendingModel.fit(tiny, h=1.0, k=1, m=1, arc=0.0)
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="^denoise:"):
            BendingModel.fit(tiny, h=1.0, k=1, m=1, denoise=bad)


def test_course_deviation_of_a_line_and_a_regular_polygon():
    from phloem.branching.bending import course_deviation

    line = np.stack([np.arange(20.0), np.full(20, 5.0)], axis=1)
    assert np.allclose(course_deviation(line, np.arange(1, 20), 8), 0.0)
    # a regular polygon turning by beta at every vertex (counter-clockwise on screen): the last
    # edge's heading is (N - 1) / 2 turns ahead of the chord over the last N edges
    beta, n = 0.05, 10
    heads = beta * np.arange(40)
    pts = np.vstack([[0.0, 0.0], np.cumsum(np.stack([np.cos(heads), -np.sin(heads)], axis=1), axis=0)])
    got = course_deviation(pts, np.arange(n, 41), n)
    assert np.allclose(got, (n - 1) / 2 * beta, atol=1e-9)
    # fewer edges than N behind the tip: the chord starts at the first vertex
    assert np.isclose(course_deviation(pts, np.array([3]), n)[0], beta)


def test_course_off_is_the_paper_model():
    rng = np.random.default_rng(0)
    b = Branch.from_angles([10, 100], 0.0, rng.normal(0, 0.3, 60), np.full(62, 2.0), 2.0)
    on = BendingModel.fit(Skeleton([b]), h=2.0)
    off = BendingModel.fit(Skeleton([b]), h=2.0, course=0)
    assert on.course == 8 * on.m and off.course == 0
    a, r = on.cand_hist_alpha[5], on.cand_hist_r[5] * 2.0
    z = np.zeros(on.bins)
    assert np.array_equal(off.log_quality(a, r, z, z, 0.3), off.log_quality(a, r, z, z))
    assert not np.array_equal(on.log_quality(a, r, z, z, 0.3), on.log_quality(a, r, z, z))
    with pytest.raises(ValueError, match="^course:"):
        BendingModel.fit(Skeleton([b]), h=2.0, course=-1)


def test_block_sums_of_a_short_and_a_long_history():
    from phloem.branching.bending import block_sums

    a = np.arange(12.0)
    assert block_sums(a[:7], 1, 4) is None  # fewer than (k + 1) m angles
    np.testing.assert_array_equal(block_sums(a, 1, 4), [4 + 5 + 6 + 7, 8 + 9 + 10 + 11])
    np.testing.assert_array_equal(block_sums(a, 2, 4), [6, 22, 38])


def test_candidates_coarse_histories_are_the_block_sums_before_them():
    from phloem.branching._elements import _elements
    from phloem.branching.bending import block_sums

    rng = np.random.default_rng(1)
    brs = [Branch.from_angles([10, 40 + 30 * j], 0.0, rng.normal(0, 0.3, 50 + 9 * j), np.full(52 + 9 * j, 2.0), 2.0)
           for j in range(3)]  # fmt: skip
    model = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3)
    assert model.cand_coarse.shape == (len(model.next_alpha), model.k + 1) and model.coarse_history == 2.0
    for row, (b, i) in enumerate(model.cand_where):
        a = _elements(model.source.branches[b])[0]
        # brute force: the history's angles and all before them, with zeros before the branch's start
        before = np.concatenate([np.zeros((model.k + 1) * model.m), a[: i + model.k + 1]])
        np.testing.assert_allclose(model.cand_coarse[row], block_sums(before, model.k, model.m), atol=1e-12)


def test_coarse_history_off_is_the_model_without_it():
    rng = np.random.default_rng(0)
    b = Branch.from_angles([10, 100], 0.0, rng.normal(0, 0.3, 60), np.full(62, 2.0), 2.0)
    on = BendingModel.fit(Skeleton([b]), h=2.0)
    off = BendingModel.fit(Skeleton([b]), h=2.0, coarse_history=0)
    a, r = on.cand_hist_alpha[20], on.cand_hist_r[20] * 2.0
    z, coarse = np.zeros(on.bins), on.cand_coarse[20]
    assert np.array_equal(off.log_quality(a, r, z, z, coarse=coarse), off.log_quality(a, r, z, z))
    with_coarse = on.log_quality(a, r, z, z, coarse=coarse)
    assert not np.array_equal(with_coarse, on.log_quality(a, r, z, z))
    # the weight is the exponent of the paper's dist on the block sums
    d = np.linalg.norm(on.cand_coarse - coarse, axis=1)
    np.testing.assert_allclose(with_coarse - on.log_quality(a, r, z, z), 2.0 * np.log(1 / (d + 1) + 1))
    with pytest.raises(ValueError, match="^coarse_history:"):
        BendingModel.fit(Skeleton([b]), h=2.0, coarse_history=-1.0)
    with pytest.raises(ValueError, match="^coarse:"):
        on.log_quality(a, r, z, z, coarse=coarse[:2])


def test_orientation_matches_each_candidates_heading_on_the_image():
    rng = np.random.default_rng(3)
    brs = [Branch.from_angles([10, 40 + 30 * j], 0.4 * j, rng.normal(0, 0.3, 50), np.full(52, 2.0), 2.0)
           for j in range(3)]  # fmt: skip
    on = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3, orientation=3.0)
    off = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3)
    assert on.orientation == 3.0 and off.orientation == 0.0
    # brute force: the direction of the edge into the tip after each history, y pointing down
    for row, (b, i) in enumerate(on.cand_where):
        p = on.source.branches[b].points
        d = p[i + on.k + 2] - p[i + on.k + 1]
        np.testing.assert_allclose(on.cand_heading[row], np.arctan2(-d[1], d[0]), atol=1e-12)
    a, r = on.cand_hist_alpha[20], on.cand_hist_r[20] * 2.0
    z = np.zeros(on.bins)
    # the weight is the exponent of the paper's dist on the wrapped heading difference
    delta = np.abs((on.cand_heading - 3.0 + np.pi) % (2 * np.pi) - np.pi)
    np.testing.assert_allclose(
        on.log_quality(a, r, z, z, heading=3.0) - on.log_quality(a, r, z, z), 3.0 * np.log(1 / (delta + 1) + 1)
    )
    # off, a heading changes nothing: the paper's orientation-independent model
    assert np.array_equal(off.log_quality(a, r, z, z, heading=3.0), off.log_quality(a, r, z, z))
    assert fit_models(Skeleton(brs), h=2.0, orientation=1.5)[0].orientation == 1.5
    with pytest.raises(ValueError, match="^orientation:"):
        BendingModel.fit(Skeleton(brs), h=2.0, orientation=-1.0)


def test_stem_thickness_matches_each_candidates_following_thickness_against_the_profile():
    rng = np.random.default_rng(4)
    brs = [Branch.from_angles([10, 40 + 30 * j], 0.0, rng.normal(0, 0.2, 50), np.linspace(6.0 - j, 1.0, 52), 2.0)
           for j in range(3)]  # fmt: skip
    on = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3)
    off = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3, stem_thickness=0.0)
    assert on.stem_thickness == STEM_THICKNESS > 0 and off.stem_thickness == 0.0
    a, r = on.cand_hist_alpha[20], on.cand_hist_r[20] * 2.0
    z = np.zeros(on.bins)
    want = np.array([5.0, 4.8, 4.6])
    # the paper's dist between the m following thicknesses and the profile, in units of h
    d = np.linalg.norm(on.next_r / 2.0 - want / 2.0, axis=1)
    np.testing.assert_allclose(
        on.log_quality(a, r, z, z, profile=want) - on.log_quality(a, r, z, z),
        STEM_THICKNESS * np.log(1 / (d + 1) + 1),
    )
    # the best candidate continues where the branches are 4.6-5 px thick
    best = on.log_quality(a, r, z, z, profile=want).argmax()
    assert np.all(np.abs(on.next_r[best] - want) < 0.5)
    # a child is not matched, nor is any branch with the term off
    assert np.array_equal(on.log_quality(a, r, z, z, profile=want, stem=False), on.log_quality(a, r, z, z))
    assert np.array_equal(off.log_quality(a, r, z, z, profile=want), off.log_quality(a, r, z, z))
    with pytest.raises(ValueError, match="^profile:"):
        on.log_quality(a, r, z, z, profile=want[:2])
    with pytest.raises(ValueError, match="^stem_thickness:"):
        BendingModel.fit(Skeleton(brs), h=2.0, stem_thickness=-1.0)
    assert fit_models(Skeleton(brs), h=2.0, stem_thickness=1.5)[0].stem_thickness == 1.5


def test_stem_profile_is_the_running_median_over_four_extensions():
    t = np.linspace(8.0, 2.0, 60)
    t[30] = 40.0  # a knot one vertex long: not the branch's level
    b = Branch(np.stack([np.arange(60) * 2.0 + 5, np.full(60, 20.0)], axis=1), t)
    model = BendingModel.fit(Skeleton([b]), h=2.0, k=3, m=3)
    got = model.stem_profile(0)
    src = model.source.branches[0].thickness
    half = 2 * model.m
    for i in range(len(src)):
        window = [src[min(max(j, 0), len(src) - 1)] for j in range(i - half, i + half + 1)]
        assert got[i] == np.median(window)
    assert got.max() < 9.0


def test_candidates_total_turns_are_the_sums_of_all_angles_before_them():
    from phloem.branching._elements import _elements

    rng = np.random.default_rng(2)
    brs = [Branch.from_angles([10, 40 + 30 * j], 0.0, rng.normal(0.05, 0.3, 50 + 9 * j), np.full(52 + 9 * j, 2.0), 2.0)
           for j in range(3)]  # fmt: skip
    model = BendingModel.fit(Skeleton(brs), h=2.0, k=3, m=3)
    assert model.cand_turn.shape == (len(model.next_alpha),) and model.total_turn == 0.0  # off by default
    for row, (b, i) in enumerate(model.cand_where):
        a = _elements(model.source.branches[b])[0]
        # the heading at the history's end minus the branch's first edge's, not wrapped
        assert model.cand_turn[row] == pytest.approx(float(np.sum(a[: i + model.k + 1])), abs=1e-9)


def test_total_turn_off_is_the_model_without_it():
    rng = np.random.default_rng(0)
    b = Branch.from_angles([10, 100], 0.0, rng.normal(0.05, 0.3, 60), np.full(62, 2.0), 2.0)
    on = BendingModel.fit(Skeleton([b]), h=2.0, total_turn=2.0, turn_bound=0.0)
    off = BendingModel.fit(Skeleton([b]), h=2.0)
    a, r = on.cand_hist_alpha[20], on.cand_hist_r[20] * 2.0
    z = np.zeros(on.bins)
    assert np.array_equal(off.log_quality(a, r, z, z, turn=1.5), off.log_quality(a, r, z, z))
    with_turn = on.log_quality(a, r, z, z, turn=1.5)
    # the weight is the exponent of the paper's dist on the total turns
    d = np.abs(on.cand_turn - 1.5)
    np.testing.assert_allclose(with_turn - on.log_quality(a, r, z, z), 2.0 * np.log(1 / (d + 1) + 1))
    with pytest.raises(ValueError, match="^total_turn:"):
        BendingModel.fit(Skeleton([b]), h=2.0, total_turn=-1.0)


def test_turn_bound_costs_the_excess_of_the_total_turn_over_the_inputs():
    rng = np.random.default_rng(0)
    b = Branch.from_angles([10, 100], 0.0, rng.normal(0.05, 0.3, 60), np.full(62, 2.0), 2.0)
    free = BendingModel.fit(Skeleton([b]), h=2.0, total_turn=2.0, turn_bound=0.0)
    bound = BendingModel.fit(Skeleton([b]), h=2.0, total_turn=2.0)
    assert bound.turn_bound == TURN_BOUND > 0  # on where the total turn is matched
    assert BendingModel.fit(Skeleton([b]), h=2.0).turn_bound == 0.0  # and off with it
    assert bound.turn_limit == pytest.approx(float(np.percentile(np.abs(bound.cand_turn), 90)))
    a, r = bound.cand_hist_alpha[20], bound.cand_hist_r[20] * 2.0
    z = np.zeros(bound.bins)
    for turn in (0.0, bound.turn_limit + 1.0, -bound.turn_limit - 3.0):
        after = np.abs(turn + bound.next_alpha.sum(axis=1))
        want = -TURN_BOUND * np.maximum(after - bound.turn_limit, 0.0)
        got = bound.log_quality(a, r, z, z, turn=turn) - free.log_quality(a, r, z, z, turn=turn)
        np.testing.assert_allclose(got, want, atol=1e-12)
    # furcations are not bounded
    far = bound.turn_limit + 1.0
    assert np.array_equal(bound.log_quality(a, r, z, z, turn=far, stem=False), free.log_quality(a, r, z, z, turn=far))
    # inside the input's range nothing changes; beyond it, continuations that turn back win
    assert np.array_equal(bound.log_quality(a, r, z, z, turn=0.0), free.log_quality(a, r, z, z, turn=0.0))
    far = bound.log_quality(a, r, z, z, turn=bound.turn_limit + 1.0)
    back, on = bound.next_alpha.sum(axis=1) < -0.2, bound.next_alpha.sum(axis=1) > 0.2
    assert np.median(far[back]) > np.median(far[on]) + 1.0
    with pytest.raises(ValueError, match="^turn_bound:"):
        BendingModel.fit(Skeleton([b]), h=2.0, turn_bound=-1.0)


def test_turn_limit_is_the_stems():
    # a nearly straight stem and a child that curls: the limit is the stem's, not the curl's
    rng = np.random.default_rng(1)
    stem = Branch.from_angles([10, 100], 0.0, rng.normal(0.0, 0.05, 80), np.full(82, 2.0), 2.0)
    curl = Branch.from_angles(stem.points[40], 1.0, np.full(60, 0.15), np.full(62, 2.0), 2.0, parent=(0, 40))
    model = BendingModel.fit(Skeleton([stem, curl]), h=2.0, total_turn=2.0)
    mine = model.cand_where[:, 0] == 0
    assert 0 < mine.sum() < len(mine)
    assert model.turn_limit == pytest.approx(float(np.percentile(np.abs(model.cand_turn[mine]), 90)))
    assert model.turn_limit < 0.5 < float(np.abs(model.cand_turn).max())


def test_course_is_an_option_of_the_pipeline():
    from phloem.branching import synthetic_skeleton

    src = synthetic_skeleton(0)
    assert fit_models(src, h=2.0)[0].course == 8 * 4
    assert fit_models(src, h=2.0, course=0)[0].course == 0
    img = np.where(src.mask(), 0.1, 0.8).astype(np.float32)
    assert fit_models(src, h=2.0, coarse_history=0.5)[0].coarse_history == 0.5
    assert fit_models(src, h=2.0, total_turn=0.5)[0].total_turn == 0.5
    res = synthesize(img, src, course=12, coarse_history=0, total_turn=0, seed=0, render_options={"complete": False})
    assert res.bending.course == 12 and res.bending.coarse_history == 0 and res.bending.total_turn == 0


def test_the_column_dist_is_the_papers_dist_to_the_bit():
    # log_quality reads the history tables by columns (contiguous, fast); the growth must not
    # change by a bit for it
    from phloem.branching._elements import _dist, _dist_columns

    rng = np.random.default_rng(3)
    for L in range(1, 6):
        table = rng.normal(0.0, 1.0, (4000, L)) * rng.choice([1e-3, 1.0, 30.0], (4000, 1))
        y = rng.normal(0.0, 1.0, L)
        assert np.array_equal(_dist_columns(np.ascontiguousarray(table.T), y), _dist(table, y[None, :]))


def _reference_histogram_moves(target: np.ndarray, counts: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The NumPy ``_histogram_moves`` had before ``phloem_core::bending``."""
    n0 = float(counts.sum())
    n = n0 + b.shape[1]
    now = float(((target - counts / n0) ** 2).sum())
    u = target - counts / n
    same = np.full(len(b), float(b.shape[1]))
    for p in range(b.shape[1]):
        for q in range(p + 1, b.shape[1]):
            same += 2.0 * (b[:, p] == b[:, q])
    after = float(u @ u) - 2.0 * u[b].sum(axis=1) / n + same / (n * n)
    return np.asarray((now - after) / len(target), dtype=np.float64)


def test_the_growth_step_kernels_give_the_bits_of_their_numpy_reference():
    # phloem_core::bending replaces NumPy passes in every growth step; the growth must not
    # change by a bit for it
    import math

    from phloem import _core
    from phloem.branching._elements import _abs_turn, _bin
    from phloem.branching.bending import _angle, _histogram_moves

    rng = np.random.default_rng(5)
    turns = rng.normal(0.0, 4.0, (5000, 3)) * rng.choice([1e-9, 1.0, 100.0], (5000, 1))
    turns[:4] = [
        [np.nan, np.inf, -np.inf],
        [math.pi, -math.pi, 3 * math.pi],
        [0.0, -0.0, 2 * math.pi],
        [1e300, -1e300, 7.0],
    ]
    with np.errstate(invalid="ignore"):
        want_abs = np.abs(math.pi - (math.pi - turns) % (2 * math.pi))
        want_angle = (turns + np.pi) % (2 * np.pi) - np.pi
        want_bins = np.clip(np.floor(np.nan_to_num(want_abs / math.pi * 16)), 0, 15).astype(np.int64)
        assert np.array_equal(_abs_turn(turns), want_abs, equal_nan=True)
        assert np.array_equal(_angle(turns), want_angle, equal_nan=True)
        assert np.array_equal(_bin(want_abs, 0.0, math.pi, 16), want_bins)
        assert np.array_equal(_core.turn_bins(turns, 16), want_bins)
    for P in (1, 2, 4):
        target = rng.dirichlet(np.ones(16))
        counts = rng.integers(0, 50, 16).astype(np.float64)
        b = rng.integers(0, 16, (3000, P))
        assert np.array_equal(_histogram_moves(target, counts, b), _reference_histogram_moves(target, counts, b))


def _digitised(points: np.ndarray) -> Branch:
    """A centre line as a trace leaves it: every point on its pixel, repeats dropped."""
    p = np.rint(points)
    keep = np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]
    return Branch(p[keep], np.full(int(keep.sum()), 1.5))


def _staircase_lines() -> Skeleton:
    t = np.arange(0.0, 330.0)
    lines = []
    for i in range(6):
        heading = 0.9 + 0.15 * i
        lines.append(_digitised(np.stack([20 + 40 * i + t * np.cos(heading), 380 - t * np.sin(heading)], axis=1)))
    return Skeleton(lines, (400, 400))


def test_denoise_takes_the_pixel_staircase_out_and_keeps_the_bends():
    # Straight lines on the pixel grid turn by 0.19 rad a step at h = 3 (their staircase); a
    # circle of radius 60 turns by h / R = 0.05 a step under as much noise.
    lines = _staircase_lines()
    t = np.arange(0.0, 5.0, 1 / 60)
    circle = Skeleton([_digitised(np.stack([200 + 60 * np.cos(t), 200 - 60 * np.sin(t)], axis=1))], (400, 400))

    def angles(sk: Skeleton, denoise: float) -> np.ndarray:
        model = BendingModel.fit(sk, h=3.0, k=2, m=2, denoise=denoise)
        assert model.denoise == denoise
        for b, given in zip(model.source.branches, sk.branches, strict=True):
            np.testing.assert_array_equal(b.points[0], given.points[0])  # children would stay put
            np.testing.assert_allclose(b.thickness, 1.5)
        return np.concatenate([b.angles()[5:-5] for b in model.source.branches])

    assert np.std(angles(lines, 0.0)) > 0.15
    assert np.std(angles(lines, DENOISE)) < 0.05
    # a Gaussian far wider than any branch is cut to the branch: it straightens it, quickly
    # (at its full width the kernel alone would need gigabytes)
    assert np.std(angles(lines, 1e12)) < 0.01
    assert np.std(angles(circle, 0.0)) > 0.15
    bent = angles(circle, DENOISE)
    assert abs(np.mean(bent) - 3.0 / 60) < 0.002 and np.std(bent) < 0.03


def test_denoise_keeps_branches_grown_from_staircase_lines_straight():
    # The Markov chain copies the staircase's turns but not their return to the line: grown
    # branches wander off it unless the staircase is taken out first (the pipeline's default).
    lines = _staircase_lines()

    def mean_drift(denoise: float) -> float:
        bend, fur = fit_models(lines, h=3.0, denoise=denoise)
        assert bend.denoise == denoise
        return float(
            np.mean([drift(lines, grow(bend, fur, size=(400, 400), seed=s, max_length="input")) for s in range(3)])
        )

    assert source_defaults(lines).denoise == DENOISE  # lines keep a course
    assert mean_drift(0.0) > 0.06
    assert mean_drift(DENOISE) < 0.03


def test_the_default_step_is_at_least_two_pixels():
    # At a step under 2 px a traced centre line's turns are its pixel staircase: grown from
    # them unsmoothed, thin lines wander off at once; synthesize's default step keeps them.
    lines = _staircase_lines()
    thin = Skeleton([Branch(b.points, 0.7) for b in lines.branches], lines.shape)
    thick = Skeleton([Branch(b.points, 3.5) for b in lines.branches], lines.shape)
    assert default_h(thin) == 0.7 and h_default(thin) == MIN_H == 2.0
    assert h_default(thick) == 3.5 and h_default(thin, h=0.5) == 0.5
    assert source_defaults(thin).h == 2.0 and source_defaults(thin, h=1.0).h == 1.0

    def mean_drift(h: float) -> float:
        bend, fur = fit_models(thin, h=h, denoise=0.0)
        return float(
            np.mean([drift(thin, grow(bend, fur, size=(400, 400), seed=s, max_length="input")) for s in range(3)])
        )

    assert mean_drift(0.7) > 0.6
    assert mean_drift(h_default(thin)) < 0.45
    img = np.where(thin.mask(), 0.1, 0.8).astype(np.float32)
    assert synthesize(img, thin, seed=0, render_options={"complete": False}).bending.h == 2.0
    assert synthesize(img, thin, seed=0, h=1.0, render_options={"complete": False}).bending.h == 1.0


def test_denoise_is_defaulted_where_the_input_keeps_a_course():
    # Branches that keep a course get the staircase taken out; a zigzag of right angles every
    # 50 px turns by a right angle over 60 px, for real, and is taken as given.
    lines = _staircase_lines()
    assert denoise_default(lines) == DENOISE and denoise_default(lines, denoise=1.5) == 1.5
    steps = np.array([[0, 0], [50, 0], [50, 50], [100, 50], [100, 100], [150, 100], [150, 150]], float)
    zigzag = Skeleton([_digitised(np.concatenate([np.linspace(a, b, 60)[:-1] for a, b in itertools.pairwise(steps)]))])
    assert denoise_default(zigzag) == 0.0
    short = Skeleton([_digitised(np.stack([np.arange(40.0), np.zeros(40)], axis=1))])
    assert denoise_default(short) == 0.0  # nothing as long as the arc: the paper's model
    img = np.where(lines.mask(), 0.1, 0.8).astype(np.float32)
    res = synthesize(img, lines, seed=0, render_options={"complete": False})
    assert res.bending.denoise == DENOISE
    assert synthesize(img, lines, seed=0, denoise=0.0, render_options={"complete": False}).bending.denoise == 0.0
