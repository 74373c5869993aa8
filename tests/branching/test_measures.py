"""The measures of issue 19 (re-trace agreement, largest-tree share, drift, two-level fraction)
against analytic references and brute force."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

import phloem
from phloem.branching import Branch, Skeleton, trace
from phloem.branching.measures import (
    MIN_SIBLINGS,
    background_grain,
    border_share,
    direction_concentration,
    direction_histogram,
    drift,
    drift_noise,
    empty_space,
    end_taper,
    furcation_gaps,
    heading_change_histogram,
    heading_changes,
    largest_tree_share,
    layout_agreement,
    median_heading_change,
    orientation_distance,
    parent_turns,
    past_end_share,
    resolve_trace_options,
    retrace_agreement,
    sibling_order,
    skeleton_agreement,
    start_turns,
    structure_contrast,
    two_level_fraction,
    wider_children,
)


def arc_branch(radius: float, angle: float, centre=(150.0, 150.0), n: int = 2000, thickness: float = 1.0) -> Branch:
    t = np.linspace(0.0, angle, n)
    return Branch(np.c_[centre[0] + radius * np.cos(t), centre[1] - radius * np.sin(t)], thickness)


def test_metrics_reexports_the_measures() -> None:
    for name in (
        "retrace_agreement", "skeleton_agreement", "largest_tree_share", "border_share", "drift", "drift_noise",
        "two_level_fraction", "start_turns", "furcation_gaps", "direction_histogram", "direction_concentration",
        "orientation_distance", "structure_contrast", "background_grain", "sibling_order", "parent_turns",
        "empty_space", "layout_agreement", "joined_end_share", "end_taper",
    ):  # fmt: skip
        assert getattr(phloem.metrics, name) is getattr(phloem.branching.measures, name)
        assert name in phloem.metrics.__all__


# -- heading change and drift -----------------------------------------------------------------


def test_a_straight_branch_does_not_turn_whatever_its_direction_and_vertex_count() -> None:
    rng = np.random.default_rng(0)
    for angle in (0.0, 0.3, 2.0, -2.7):
        d = np.array([np.cos(angle), np.sin(angle)])
        s = np.sort(np.r_[0.0, rng.uniform(0, 200, 30), 200.0])  # irregular vertex spacing
        sk = Skeleton([Branch(np.array([10.0, 10.0]) + 250 + s[:, None] * d, 1.0)])
        values = heading_changes(sk, arc=60)
        assert values.size == 200 - 70 + 1  # one per px where both 10-px tangent chords fit
        assert np.abs(values).max() < 1e-9
        assert median_heading_change(sk) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(("radius", "arc"), [(50.0, 30.0), (80.0, 60.0), (120.0, 60.0), (40.0, 20.0)])
def test_a_circular_arc_turns_by_arc_over_radius(radius: float, arc: float) -> None:
    sk = Skeleton([arc_branch(radius, 3.0)])
    values = heading_changes(sk, arc=arc)
    assert values.size > 0
    np.testing.assert_allclose(values, arc / radius, atol=2e-3)


def test_heading_change_wraps_to_at_most_pi() -> None:
    # 100 px on a circle of radius 20 turns by 5 rad, which is 2π - 5 the other way round.
    sk = Skeleton([arc_branch(20.0, 1.9 * np.pi, n=3000)])
    np.testing.assert_allclose(heading_changes(sk, arc=100), 2 * np.pi - 5, atol=5e-3)


def test_heading_change_of_a_traced_circle_is_near_arc_over_radius() -> None:
    """Pixel staircase of a traced centre line must not swing the measure."""
    radius = 70.0
    mask = Skeleton([arc_branch(radius, 1.5 * np.pi, centre=(100.0, 100.0), thickness=3.0)], (200, 200)).mask()
    traced = trace(mask.astype(np.float32), kind="mask")
    assert median_heading_change(traced, arc=60) == pytest.approx(60 / radius, abs=0.05)
    # 10-px tangent chords: std 0.027 rad here; single-pixel tangents scatter by 0.075
    assert heading_changes(traced, arc=60).std() < 0.045


def test_short_branches_give_no_values() -> None:
    sk = Skeleton([Branch([[0, 0], [69, 0]], 1.0), Branch([[0, 5], [30, 5]], 1.0)])
    assert heading_changes(sk, arc=60).size == 0
    assert heading_changes(sk, arc=10).size > 0
    with pytest.raises(ValueError, match=r"^skeleton: no branch is at least 70 px long"):
        median_heading_change(sk, arc=60)
    with pytest.raises(ValueError, match=r"^candidate: no branch"):
        drift(Skeleton([Branch([[0, 0], [200, 0]], 1.0)]), sk)


def test_histogram_bins_the_heading_changes_over_0_to_pi() -> None:
    sk = Skeleton([arc_branch(30.0, 4.0), Branch([[0, 0], [100, 5], [180, 60], [200, 190]], 1.0)])
    values = heading_changes(sk, arc=45)
    hist, edges = heading_change_histogram(sk, arc=45, bins=8)
    expected = np.histogram(values, bins=8, range=(0.0, np.pi))[0]
    np.testing.assert_allclose(hist, expected / expected.sum())
    np.testing.assert_allclose(edges, np.linspace(0, np.pi, 9))


def test_drift_is_zero_for_the_same_bending_and_large_for_curls() -> None:
    line = Skeleton([Branch([[0, 0], [300, 0]], 1.0)])
    gentle = Skeleton([arc_branch(400.0, 0.7)])  # 0.15 rad over 60 px: the first bin of 16
    curl = Skeleton([arc_branch(40.0, 4.0)])  # 1.5 rad over 60 px
    assert drift(line, line) == 0.0
    assert drift(line, gentle) == 0.0
    assert drift(line, curl) == pytest.approx(2.0)
    assert drift(curl, line) == drift(line, curl)
    mixed = Skeleton([*line.branches, *curl.branches])
    d = drift(line, mixed)
    assert 0.0 < d < 2.0


def random_arcs(n: int, seed: int) -> Skeleton:
    """``n`` branches of one process: arcs of random radius (80-400 px) and length (90-250 px)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        r, length = rng.uniform(80, 400), rng.uniform(90, 250)
        out.append(arc_branch(r, length / r, n=int(length)))
    return Skeleton(out)


def test_drift_noise_is_the_quantile_of_drift_to_block_bootstrap_resamples() -> None:
    """Against a brute force: blocks of 60 heading changes per branch, resampled, histogrammed by numpy."""
    sk = Skeleton([*random_arcs(9, 1).branches, Branch([[0, 0], [30, 0]], 1.0)])  # one branch too short
    blocks = []
    for b in sk.branches:
        v = heading_changes(Skeleton([b]), arc=60)
        blocks += [v[i : i + 60] for i in range(0, len(v), 60)]
    assert len(blocks) > 9
    whole = np.histogram(np.concatenate(blocks), bins=16, range=(0, np.pi))[0]
    rng = np.random.default_rng(5)
    picks = rng.integers(0, len(blocks), size=(50, len(blocks)))
    brute = []
    for p in picks:
        h = np.histogram(np.concatenate([blocks[i] for i in p]), bins=16, range=(0, np.pi))[0]
        brute.append(np.abs(h / h.sum() - whole / whole.sum()).sum())
    for q in (0.0, 0.5, 0.9, 1.0):
        assert drift_noise(sk, quantile=q, resamples=50, seed=5) == pytest.approx(np.quantile(brute, q), abs=1e-12)


def test_drift_noise_falls_as_the_structure_grows() -> None:
    """Zero for an arc of one radius, above zero for one wavy branch, and for one process smaller
    with 64 branches than with 6."""
    assert drift_noise(Skeleton([arc_branch(50.0, 3.0)])) == 0.0
    x = np.arange(0.0, 600.0)
    assert drift_noise(Skeleton([Branch(np.c_[x, 100 + 30 * np.sin(x / 40)], 1.0)])) > 0.1
    few = [drift_noise(random_arcs(6, s)) for s in range(4)]
    many = [drift_noise(random_arcs(64, s)) for s in range(4)]
    assert max(many) < min(few), (few, many)
    # Two draws of the process differ by more than the bootstrap's median: it is a lower bound.
    gaps = [drift(random_arcs(6, s), random_arcs(6, s + 10)) for s in range(8)]
    assert np.median(gaps) > np.median([drift_noise(random_arcs(6, s), quantile=0.5) for s in range(8)])


def test_drift_noise_names_a_bad_argument() -> None:
    sk = random_arcs(5, 0)
    with pytest.raises(ValueError, match=r"^quantile: expected a number in \[0, 1\]"):
        drift_noise(sk, quantile=1.5)
    with pytest.raises(ValueError, match=r"^resamples"):
        drift_noise(sk, resamples=0)
    with pytest.raises(ValueError, match=r"^skeleton: no branch is at least 70 px long"):
        drift_noise(Skeleton([Branch([[0, 0], [50, 0]], 1.0)]))
    with pytest.raises(ValueError, match=r"^skeleton: its long branches hold a single stretch of 60 px"):
        drift_noise(Skeleton([Branch([[0, 0], [120, 0]], 1.0)]))  # 50 values: one block
    with pytest.raises(TypeError, match=r"^skeleton"):
        drift_noise(np.zeros((4, 2)))  # type: ignore[arg-type]


# -- largest-tree share -----------------------------------------------------------------------


def test_largest_tree_share_of_known_trees() -> None:
    a = Branch([[0, 0], [30, 0]], 1.0)
    b = Branch([[10, 0], [10, 20]], 1.0, parent=(0, 0))
    c = Branch([[10, 20], [20, 20]], 1.0, parent=(1, 1))  # a grandchild: still tree 0
    d = Branch([[0, 50], [40, 50]], 1.0)
    assert largest_tree_share(Skeleton([a, b, c])) == 1.0
    assert largest_tree_share(Skeleton([a, b, c, d])) == pytest.approx(60 / 100)
    assert largest_tree_share(Skeleton([a, d, Branch([[0, 60], [40, 60]], 1.0, parent=(1, 0))])) == pytest.approx(
        80 / 110
    )
    pieces = Skeleton([Branch([[0, 5 * i], [10, 5 * i]], 1.0) for i in range(4)])
    assert largest_tree_share(pieces) == pytest.approx(0.25)


# -- border share -----------------------------------------------------------------------------


def test_border_share_is_the_length_within_the_band_of_any_side() -> None:
    shape = (100, 200)  # H, W: the right side is x = 199, the bottom y = 99
    middle = Branch([[50, 50], [150, 50]], 1.0)
    assert border_share(Skeleton([middle], shape=shape), band=5) == 0.0
    top = Branch([[20, 1], [120, 1]], 1.0)
    assert border_share(Skeleton([top], shape=shape), band=5) == 1.0
    # a stem down the right side, then into the middle: 40 px along the side, 3 more leaving the band
    bend = Branch([[197, 10], [197, 50], [97, 50]], 1.0)
    assert border_share(Skeleton([bend], shape=shape), band=5) == pytest.approx(43 / 140)
    # a branch crossing the frame spends only the band's width in it, on either side
    across = Branch([[100, 0], [100, 99]], 1.0)
    assert border_share(Skeleton([across], shape=shape), band=5) == pytest.approx(10 / 99)
    both = Skeleton([middle, top], shape=shape)
    assert border_share(both, band=5) == pytest.approx(0.5)


def test_border_share_band_defaults_to_four_median_thicknesses() -> None:
    sk = Skeleton([Branch([[50, 2], [50, 52]], 3.0)], shape=(100, 100))  # 12 px band: y < 12 counts
    assert border_share(sk) == pytest.approx(border_share(sk, band=12.0)) == pytest.approx(10 / 50)
    thin = Skeleton([Branch([[50, 0], [50, 50]], 0.0)], shape=(100, 100))  # at least 2 px
    assert border_share(thin) == pytest.approx(2 / 50)


def test_border_share_refuses_what_it_cannot_measure() -> None:
    sk = Skeleton([Branch([[0, 0], [30, 0]], 1.0)], shape=(10, 40))
    with pytest.raises(ValueError, match="^skeleton: has no shape"):
        border_share(Skeleton([Branch([[0, 0], [30, 0]], 1.0)]))
    for band in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="^band:"):
            border_share(sk, band=band)
    with pytest.raises(ValueError, match="^skeleton: the branches have no length"):
        border_share(Skeleton([Branch([[1, 1], [1, 1]], 1.0)], shape=(10, 10)))


# -- empty space ------------------------------------------------------------------------------


def test_empty_space_is_the_quantile_of_the_brute_force_distance_to_the_centre_lines() -> None:
    rng = np.random.default_rng(3)
    shape = (70, 90)
    branches = [Branch(rng.uniform([0, 0], [89, 69], size=(4, 2)), 1.0) for _ in range(3)]
    branches.append(Branch([[-0.5, 10.0], [89.5, 10.0]], 1.0))  # from edge to edge of the pixels
    sk = Skeleton(branches, shape=shape)
    # the half-pixel samples of every branch, rounded to the nearest pixel inside the image
    pts = []
    for b in branches:
        seg = np.linalg.norm(np.diff(b.points, axis=0), axis=1)
        cum = np.r_[0.0, np.cumsum(seg)]
        s = np.linspace(0.0, cum[-1], max(2, int(np.ceil(2 * cum[-1])) + 1))
        pts.append(np.c_[np.interp(s, cum, b.points[:, 0]), np.interp(s, cum, b.points[:, 1])])
    ij = np.rint(np.concatenate(pts)).astype(int)
    ij = ij[(ij[:, 0] >= 0) & (ij[:, 0] < 90) & (ij[:, 1] >= 0) & (ij[:, 1] < 70)]
    yy, xx = np.mgrid[:70, :90]
    d = np.sqrt((xx[..., None] - ij[:, 0]) ** 2 + (yy[..., None] - ij[:, 1]) ** 2).min(axis=-1)
    valid = xx < 60
    for q in (0.0, 0.5, 0.9, 1.0):
        assert empty_space(sk, quantile=q) == pytest.approx(np.quantile(d, q), abs=1e-3)
        assert empty_space(sk, quantile=q, valid=valid) == pytest.approx(np.quantile(d[valid], q), abs=1e-3)


def test_a_knot_leaves_more_empty_space_than_the_same_length_spread_out() -> None:
    shape = (200, 200)
    spread = Skeleton([Branch([[x, 0], [x, 199]], 1.0) for x in (25, 75, 125, 175)], shape=shape)
    knot = Skeleton([Branch([[x, 0], [x, 199]], 1.0) for x in (10, 20, 30, 40)], shape=shape)
    assert empty_space(spread) == pytest.approx(22.0, abs=1.0)  # no place 25 px from a line
    assert empty_space(knot) > 5 * empty_space(spread)  # the right three quarters are empty


def test_empty_space_refuses_what_it_cannot_measure() -> None:
    sk = Skeleton([Branch([[0, 5], [30, 5]], 1.0)], shape=(10, 40))
    with pytest.raises(ValueError, match="^skeleton: has no shape"):
        empty_space(Skeleton([Branch([[0, 0], [30, 0]], 1.0)]))
    for q in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="^quantile:"):
            empty_space(sk, quantile=q)
    with pytest.raises(ValueError, match="^valid: expected at least one pixel"):
        empty_space(sk, valid=np.zeros((10, 40), bool))
    with pytest.raises(ValueError, match="^valid:"):
        empty_space(sk, valid=np.ones((11, 40), bool))


# -- agreement --------------------------------------------------------------------------------


def brute_agreement(ref: Skeleton, cand: Skeleton, tol: float) -> tuple[float, float]:
    def dense(sk: Skeleton) -> np.ndarray:
        out = []
        for b in sk.branches:
            for p, q in zip(b.points[:-1], b.points[1:]):
                n = int(np.ceil(np.linalg.norm(q - p) / 0.25)) + 1
                out.append(p + np.linspace(0, 1, n)[:, None] * (q - p))
        return np.concatenate(out)

    r, c = dense(ref), dense(cand)
    d = np.linalg.norm(r[:, None] - c[None], axis=2)
    return float(np.mean(d.min(axis=0) <= tol)), float(np.mean(d.min(axis=1) <= tol))


def test_skeleton_agreement_matches_brute_force() -> None:
    rng = np.random.default_rng(3)
    for _ in range(4):
        ref = Skeleton([Branch(np.cumsum(rng.uniform(-8, 12, (6, 2)), axis=0) + 50, 2.0)])
        cand = Skeleton([Branch(ref.branches[0].points[:4] + rng.normal(0, 2, (4, 2)), 2.0)])
        got = skeleton_agreement(ref, cand)
        p, r = brute_agreement(ref, cand, 3.0)
        # 1-px sampling against 0.25-px sampling: a few points near the tolerance edge differ
        assert got.precision == pytest.approx(p, abs=0.05) and got.recall == pytest.approx(r, abs=0.05)
        assert got.f1 == pytest.approx(2 * got.precision * got.recall / (got.precision + got.recall))


def test_agreement_tolerance_follows_the_reference_radius() -> None:
    ref = Skeleton([Branch([[0, 50], [200, 50]], [6.0, 6.0])])
    assert skeleton_agreement(ref, ref).tolerance == 9.0
    near = Skeleton([Branch([[0, 58], [200, 58]], 1.0)])
    assert skeleton_agreement(ref, near).f1 == 1.0
    assert skeleton_agreement(near, ref).f1 == 0.0  # the other way round the tolerance is 3 px
    assert skeleton_agreement(near, ref, tolerance=8.0).f1 == 1.0


def test_retrace_of_an_exact_drawing_agrees_and_of_a_shifted_or_blank_one_does_not() -> None:
    main = Branch([[20, 100], [120, 90], [220, 110], [280, 100]], 5.0)
    child = Branch([[120, 90], [160, 40], [200, 20]], 3.0, parent=(0, 1))
    target = Skeleton([main, child], (160, 300))
    drawn = target.mask().astype(np.float32)
    assert retrace_agreement(drawn, target, trace_options={"kind": "mask"}) > 0.95
    shifted = np.zeros_like(drawn)
    shifted[40:] = drawn[:-40]
    assert retrace_agreement(shifted, target, trace_options={"kind": "mask"}) < 0.15
    assert retrace_agreement(np.zeros_like(drawn), target, trace_options={"kind": "mask"}) == 0.0
    # a dark structure on a light photo-like background, traced with the ridge filter
    photo = 0.8 - 0.6 * drawn
    assert retrace_agreement(photo, target, trace_options={"kind": "dark", "sigmas": (2.0, 3.0)}) > 0.8


def test_retrace_resolves_auto_on_the_input_like_trace_does() -> None:
    main = Branch([[20, 100], [120, 90], [220, 110], [280, 100]], 3.0)
    target = Skeleton([main, Branch([[120, 90], [160, 40], [200, 20]], 2.0, parent=(0, 1))], (160, 300))
    mask = target.mask().astype(np.float32)
    assert resolve_trace_options(mask) == {"kind": "mask"}
    photo = cv2.GaussianBlur(mask, (0, 0), 1.5)  # no longer two-valued
    assert resolve_trace_options(0.8 - 0.6 * photo)["kind"] == "dark"
    assert resolve_trace_options(0.2 + 0.6 * photo)["kind"] == "bright"
    assert resolve_trace_options(mask, {"kind": "bright", "min_area": 5}) == {"kind": "bright", "min_area": 5}
    # a mask output with a few grey pixels is traced as the mask input was
    out = mask.copy()
    out[np.nonzero(mask)[0][::50], np.nonzero(mask)[1][::50]] = 0.9
    out[5:8, 5:8] = 0.1
    assert retrace_agreement(out, target, like=mask) > 0.95
    assert resolve_trace_options(out)["kind"] != "mask"


# -- two-level fraction -----------------------------------------------------------------------


def test_two_level_fraction_of_a_constructed_image() -> None:
    ref = np.zeros((20, 20), np.float32)
    ref[:, 10:] = 1.0
    out = ref.copy()
    out[0, :4] = 0.04  # still the lower level
    out[1, :4] = 0.06  # off it
    out[2, 10:14] = 0.96  # still the upper level
    out[3, :5] = 0.5  # grey ramp
    assert two_level_fraction(out, ref) == pytest.approx(1 - 9 / 400)
    assert two_level_fraction(out, ref, tolerance=0.0) == pytest.approx(1 - 17 / 400)
    # levels in the reference's own range: a 0.2 / 0.6 mask scales distances by 1 / 0.4
    ref2 = 0.2 + 0.4 * ref
    out2 = 0.2 + 0.4 * out
    assert two_level_fraction(out2, ref2) == pytest.approx(two_level_fraction(out, ref), abs=1e-9)
    # uint8 and bool references, output of another size
    assert two_level_fraction(out[:5], (ref * 255).astype(np.uint8)) == pytest.approx(1 - 9 / 100)
    assert two_level_fraction(ref, ref > 0.5) == 1.0


def test_two_level_fraction_of_colour_masks_needs_every_channel_at_one_level() -> None:
    ref = np.zeros((4, 4, 3), np.float32)
    ref[2:] = [1.0, 0.5, 0.0]
    out = ref.copy()
    out[0, 0] = [0.0, 0.0, 0.3]  # one channel off
    out[3, 3] = [1.0, 0.52, 0.0]  # within 0.05 of 0.5 / 0.5 span
    assert two_level_fraction(out, ref) == pytest.approx(15 / 16)


# -- bad input --------------------------------------------------------------------------------


def test_bad_input_errors() -> None:
    sk = Skeleton([Branch([[0, 0], [200, 0]], 1.0)])
    empty = Skeleton([])
    img = sk.mask((10, 210)).astype(np.float32)
    with pytest.raises(TypeError, match="^reference: expected a phloem.branching.Skeleton"):
        skeleton_agreement(np.zeros((3, 2)), sk)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^candidate: the skeleton has no branches"):
        skeleton_agreement(sk, empty)
    with pytest.raises(ValueError, match="^tolerance:"):
        skeleton_agreement(sk, sk, tolerance=-1.0)
    with pytest.raises(TypeError, match="^target:"):
        retrace_agreement(img, "skeleton")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="^trace_options:"):
        retrace_agreement(img, sk, trace_options=["mask"])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^kind:"):
        retrace_agreement(img, sk, trace_options={"kind": "nope"})
    with pytest.raises(TypeError, match="^trace_options:"):
        resolve_trace_options(img, "mask")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^skeleton: the skeleton has no branches"):
        largest_tree_share(empty)
    with pytest.raises(ValueError, match="^skeleton: the branches have no length"):
        largest_tree_share(Skeleton([Branch([[1, 1], [1, 1]], 1.0)]))
    with pytest.raises(TypeError, match="^skeleton:"):
        heading_changes([[0, 0], [1, 1]])  # type: ignore[arg-type]
    for arc in (0.0, -5.0, float("nan")):
        with pytest.raises(ValueError, match="^arc:"):
            heading_changes(sk, arc=arc)
    with pytest.raises(TypeError, match="^arc:"):
        drift(sk, sk, arc="60")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^bins:"):
        heading_change_histogram(sk, bins=0)
    with pytest.raises(ValueError, match="^reference: the skeleton has no branches"):
        drift(empty, sk)
    ref = np.zeros((4, 4), np.float32)
    with pytest.raises(ValueError, match="^reference: expected a two-level image .* got 1 distinct"):
        two_level_fraction(ref, ref)
    with pytest.raises(ValueError, match="^reference: expected a two-level image .* got 3 distinct"):
        two_level_fraction(ref, np.array([[0, 0.5, 1.0]], np.float32))
    with pytest.raises(ValueError, match="^image: expected 1 channels"):
        two_level_fraction(np.zeros((4, 4, 3)), np.eye(4))
    with pytest.raises(ValueError, match="^tolerance:"):
        two_level_fraction(np.eye(4), np.eye(4), tolerance=-0.1)
    with pytest.raises(TypeError, match="^image:"):
        two_level_fraction(np.eye(4, dtype=np.int64), np.eye(4))


def _arc_branch(radius: float, turn: float, start: tuple[float, float], parent: tuple[int, int] | None) -> Branch:
    """A circular arc of ``radius`` through ``turn`` radians, leaving ``start`` along +x."""
    t = np.linspace(0.0, turn, max(8, int(radius * turn * 4)))
    pts = np.c_[start[0] + radius * np.sin(t), start[1] - radius * (1 - np.cos(t))]
    return Branch(pts, 1.0, parent=parent)


def test_start_turns_is_the_turn_over_the_first_arc_of_every_child() -> None:
    stem = Branch(np.c_[np.linspace(0, 300, 151), np.full(151, 150.0)], 1.0)
    straight = Branch(np.c_[np.linspace(100, 160, 31), np.linspace(150, 100, 31)], 1.0, parent=(0, 50))
    gentle = _arc_branch(60.0, 1.0, (200.0, 150.0), (0, 100))
    # a loop: 20 px on a circle of radius 3 turn 5.6 rad, which wraps to 0.7 without unwrapping
    loop = _arc_branch(3.0, 3 * np.pi, (40.0, 150.0), (0, 20))
    short = Branch([[250.0, 150.0], [252.0, 149.0]], 1.0, parent=(0, 125))
    sk = Skeleton([stem, straight, gentle, loop, short])
    got = start_turns(sk, arc=20.0)
    w = 20.0 / 6
    # the root and the too-short child give nothing; chords from w/2 to 20 - w/2: (20 - w) / R
    assert got.shape == (3,)
    assert got[0] == pytest.approx(0.0, abs=1e-9)
    assert got[1] == pytest.approx((20.0 - w) / 60.0, rel=0.02)
    assert got[2] == pytest.approx((20.0 - w) / 3.0, rel=0.02)
    assert got[2] > np.pi
    # a child shorter than the arc is measured over its length
    assert start_turns(Skeleton([stem, gentle]), arc=200.0)[0] == pytest.approx((60.0 - 200.0 / 6) / 60.0, rel=0.02)
    with pytest.raises(ValueError, match="^arc:"):
        start_turns(sk, arc=0.0)
    with pytest.raises(TypeError, match="^skeleton:"):
        start_turns([stem], arc=20.0)  # type: ignore[arg-type]


def test_furcation_gaps_are_arc_lengths_between_neighbouring_children() -> None:
    # a bent stem (arc length differs from the x distance) with children at vertices 40, 10, 25, 25
    t = np.linspace(0.0, np.pi / 2, 61)
    stem = Branch(np.c_[100 + 80 * np.sin(t), 100 - 80 * (1 - np.cos(t))], 1.0)
    s = 80 * t
    kids = [Branch([stem.points[v], stem.points[v] + [0.0, 15.0]], 1.0, parent=(0, v)) for v in (40, 10, 25, 25)]
    # a grandchild alone on its parent gives no gap
    only = Branch([kids[0].points[1], kids[0].points[1] + [10.0, 0.0]], 1.0, parent=(1, 1))
    got = furcation_gaps(Skeleton([stem, *kids, only]))
    assert got == pytest.approx([s[25] - s[10], 0.0, s[40] - s[25]], rel=1e-4, abs=1e-9)
    assert furcation_gaps(Skeleton([stem])).shape == (0,)
    with pytest.raises(TypeError, match="^skeleton:"):
        furcation_gaps([stem])  # type: ignore[arg-type]


def _kinked_fork(kink: float, side: float, rotation: float, mirror: bool, child_length: float = 60.0) -> Skeleton:
    """A parent that turns by ``kink`` at (100, 0) and a child leaving there on ``side`` (+1 / -1)."""
    stem = np.array([[0.0, 0.0], [100.0, 0.0], [100.0 + 100.0 * np.cos(kink), 100.0 * np.sin(kink)]])
    child = np.array([[100.0, 0.0], [100.0 + child_length * np.cos(side), child_length * np.sin(side)]])
    c, s = np.cos(rotation), np.sin(rotation)
    rot = np.array([[c, -s], [s, c]])
    flip = np.array([1.0, -1.0 if mirror else 1.0])
    place = lambda p: (p * flip) @ rot.T + 300.0  # noqa: E731
    return Skeleton([Branch(place(stem), 1.0), Branch(place(child), 1.0, parent=(0, 1))])


def test_parent_turns_is_the_parent_s_turn_signed_away_from_the_child() -> None:
    rng = np.random.default_rng(0)
    for _ in range(8):
        rotation, mirror = float(rng.uniform(-np.pi, np.pi)), bool(rng.integers(2))
        # both chords lie on the straight legs, so the measured turn is the kink to rounding
        away = _kinked_fork(0.3, -1.0, rotation, mirror)  # the parent turns one way, the child leaves the other
        toward = _kinked_fork(0.3, 1.0, rotation, mirror)
        straight = _kinked_fork(0.0, 1.0, rotation, mirror)
        assert parent_turns(away, arc=40.0) == pytest.approx([0.3], abs=1e-9)
        assert parent_turns(toward, arc=40.0) == pytest.approx([-0.3], abs=1e-9)
        assert parent_turns(straight, arc=40.0) == pytest.approx([0.0], abs=1e-9)
    # an attachment closer than (arc + w) / 2 to the parent's end, or a child shorter than arc / 2,
    # gives no value; the root gives none either
    assert parent_turns(_kinked_fork(0.3, -1.0, 0.0, False), arc=200.0).shape == (0,)
    assert parent_turns(_kinked_fork(0.3, -1.0, 0.0, False, child_length=15.0), arc=40.0).shape == (0,)
    with pytest.raises(ValueError, match="^arc:"):
        parent_turns(_kinked_fork(0.3, -1.0, 0.0, False), arc=0.0)
    with pytest.raises(TypeError, match="^skeleton:"):
        parent_turns([Branch([[0.0, 0.0], [1.0, 0.0]], 1.0)], arc=20.0)  # type: ignore[arg-type]


# -- directions on the image -------------------------------------------------------------------


def _segments(angles_deg: list[float], lengths: list[float]) -> Skeleton:
    """One two-vertex branch per (angle, length), counter-clockwise on screen, spread apart."""
    brs = []
    for i, (a, n) in enumerate(zip(angles_deg, lengths)):
        start = np.array([50.0 + 30 * i, 200.0])
        t = np.deg2rad(a)
        brs.append(Branch([start, start + n * np.array([np.cos(t), -np.sin(t)])], 1.0))
    return Skeleton(brs)


def test_direction_histogram_weights_axes_by_length_in_bins_centred_on_the_image_axes() -> None:
    # 12 bins of 15 degrees centred on 0, 15, ...: 7 and -7 degrees fall in the horizontal bin,
    # an edge and its reverse in one bin, 95 degrees beside the vertical's
    sk = _segments([7.0, -7.0, 180.0, 90.0, 270.0, 95.0, 50.0], [10.0, 10.0, 20.0, 30.0, 10.0, 15.0, 5.0])
    hist, edges = direction_histogram(sk)
    want = np.zeros(12)
    want[0] = 40.0
    want[6] = 40.0
    want[round(95 / 15)] += 15.0  # 95 degrees: bin 6 is [82.5, 97.5)
    want[round(50 / 15)] += 5.0  # bin 3 is [37.5, 52.5)
    assert hist == pytest.approx(want / want.sum())
    assert edges[0] == pytest.approx(-np.pi / 24) and edges[-1] == pytest.approx(np.pi - np.pi / 24)
    # a polyline's edges each count with their own direction
    bent = Skeleton([Branch([[0.0, 0.0], [30.0, 0.0], [30.0, 10.0]], 1.0)])
    assert direction_histogram(bent, bins=2)[0] == pytest.approx([0.75, 0.25])


def test_direction_concentration_is_the_mean_resultant_length_of_doubled_axes() -> None:
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 360, 40)
    n = rng.uniform(5, 30, 40)
    t = np.deg2rad(a)
    brute = abs(np.sum(n * np.exp(2j * t))) / n.sum()
    assert direction_concentration(_segments(list(a), list(n))) == pytest.approx(brute)
    assert direction_concentration(_segments([90.0, 270.0, 90.0], [10.0, 20.0, 5.0])) == pytest.approx(1.0)
    # two perpendicular axes equally: no one way
    assert direction_concentration(_segments([0.0, 90.0], [10.0, 10.0])) == pytest.approx(0.0, abs=1e-12)
    # turning the structure does not change it
    assert direction_concentration(_segments(list(a + 33.0), list(n))) == pytest.approx(brute)


def test_orientation_distance_sees_a_turned_structure_that_the_turn_measures_do_not() -> None:
    a = [80.0, 95.0, 100.0, 85.0, 90.0]
    n = [40.0, 60.0, 30.0, 50.0, 70.0]
    hanging = _segments(a, n)
    assert orientation_distance(hanging, hanging) == 0.0
    # turned by 90 degrees: every bin moves, so the histograms share nothing
    turned = _segments([x - 90.0 for x in a], n)
    assert orientation_distance(hanging, turned) == pytest.approx(2.0)
    # half of the length turned: half the mass moves
    half = _segments([90.0, 0.0], [50.0, 50.0])
    assert orientation_distance(_segments([90.0], [100.0]), half) == pytest.approx(1.0)
    with pytest.raises(TypeError, match="^candidate:"):
        orientation_distance(hanging, [1, 2])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^skeleton: the skeleton has no length"):
        direction_histogram(Skeleton([Branch([[3.0, 3.0], [3.0, 3.0]], 1.0)]))


def test_structure_contrast_is_the_centre_lines_over_their_surroundings() -> None:
    # brute force: every pixel against the exact distance to a straight bolt of thickness 2
    rng = np.random.default_rng(0)
    img = (0.2 + 0.02 * rng.standard_normal((60, 120))).astype(np.float32)
    yy, xx = np.mgrid[:60, :120]
    on = (np.abs(yy - 30) <= 2) & (xx >= 10) & (xx <= 109)
    img[on] = 0.9
    sk = Skeleton([Branch([[10, 30], [109, 30]], 2.0)], img.shape)
    d = np.hypot(np.maximum(np.maximum(10 - xx, xx - 109), 0), yy - 30)
    ring = (d >= 6) & (d < 8)
    want = float(np.median(img[(yy == 30) & (xx >= 10) & (xx <= 109)]) - np.median(img[ring]))
    assert structure_contrast(img, sk) == pytest.approx(want, abs=1e-6)
    assert structure_contrast(img, sk) == pytest.approx(0.7, abs=0.01)
    # a dark line is negative, and a glow round the bolt lowers its contrast
    assert structure_contrast(1.0 - img, sk) == pytest.approx(-0.7, abs=0.01)
    glow = img + np.where(on, 0.0, 0.3 * np.exp(-np.abs(yy - 30) / 6.0)).astype(np.float32)
    assert structure_contrast(np.clip(glow, 0, 1), sk) < 0.7 - 0.08
    # colour: the mean over channels
    rgb = np.stack([img, img, np.full_like(img, 0.5)], axis=2)
    assert structure_contrast(rgb, sk) == pytest.approx(2 / 3 * want, abs=1e-6)


def test_background_grain_of_white_noise_is_the_analytic_median() -> None:
    # noise of deviation s less its blur has variance s^2 * sum((delta - w)^2) over the 2-D
    # kernel w; the median of |N(0, v)| is 0.6745 sqrt(v)
    s = 0.05
    img = (0.5 + s * np.random.default_rng(1).standard_normal((300, 300))).astype(np.float32)
    sk = Skeleton([Branch([[20, 150], [279, 150]], 2.0)], img.shape)
    k1 = cv2.getGaussianKernel(7, 1.0)[:, 0]  # the 7-tap kernel of sigma 1 (3 sigma a side)
    w = np.outer(k1, k1)
    delta = np.zeros_like(w)
    delta[3, 3] = 1.0
    want = 0.6745 * s * float(np.sqrt(((delta - w) ** 2).sum()))
    assert background_grain(img, sk) == pytest.approx(want, rel=0.03)
    # a flat fill has none (to float32 rounding), a smoothed one little
    assert background_grain(np.full_like(img, 0.5), sk) < 1e-6
    assert background_grain(cv2.GaussianBlur(img, (0, 0), 3.0), sk) < 0.2 * want


def test_background_grain_counts_only_the_background_inside_the_picture() -> None:
    rng = np.random.default_rng(2)
    img = (0.5 + 0.05 * rng.standard_normal((120, 160))).astype(np.float32)
    sk = Skeleton([Branch([[20, 60], [139, 60]], 3.0)], img.shape)
    base = background_grain(img, sk)
    # anything within reach (4 thicknesses = 12 px) of the centre line, less the blur's
    # reach of 3 px, does not count
    striped = img.copy()
    striped[51:70, 20:140] = np.where(np.arange(120) % 2 == 0, 1.0, 0.0)[None, :]
    assert background_grain(striped, sk) == base
    assert background_grain(striped, sk, reach=0.5) > base
    # a flat frame outside valid counts without it, and not with it
    framed = img.copy()
    framed[:, 120:] = 0.0
    ok = np.zeros(img.shape, bool)
    ok[:, :120] = True
    assert background_grain(framed, sk) < 0.8 * base
    assert background_grain(framed, sk, valid=ok) == background_grain(img, sk, valid=ok)


def test_background_grain_refuses_what_it_cannot_measure() -> None:
    img = np.zeros((40, 80), np.float32)
    sk = Skeleton([Branch([[10, 20], [69, 20]], 2.0)], (40, 80))
    with pytest.raises(ValueError, match="^skeleton: made for a"):
        background_grain(np.zeros((40, 81), np.float32), sk)
    with pytest.raises(ValueError, match="^skeleton: no background pixel"):
        background_grain(img, sk, reach=50.0)
    with pytest.raises(ValueError, match="^reach:"):
        background_grain(img, sk, reach=-1.0)
    with pytest.raises(ValueError, match="^sigma:"):
        background_grain(img, sk, sigma=0.0)
    with pytest.raises(ValueError, match="^valid:"):
        background_grain(img, sk, valid=np.ones((40, 81), bool))
    with pytest.raises(ValueError, match="^image:"):
        background_grain(np.full((40, 80), np.nan), sk)


def test_structure_contrast_refuses_what_it_cannot_measure() -> None:
    img = np.zeros((40, 80), np.float32)
    sk = Skeleton([Branch([[10, 20], [69, 20]], 2.0)], (40, 80))
    with pytest.raises(ValueError, match="^skeleton: made for a"):
        structure_contrast(np.zeros((40, 81), np.float32), sk)
    for bad in ((4.0, 3.0), (0.0, 2.0), (3.0,), (1.0, float("nan"))):
        with pytest.raises(ValueError, match="^ring:"):
            structure_contrast(img, sk, ring=bad)
    with pytest.raises(ValueError, match="^image:"):
        structure_contrast(np.full((40, 80), np.nan), sk)


def _line_with_ends(dark_at: tuple[tuple[float, float], ...]) -> tuple[np.ndarray, Skeleton]:
    """A dark line of thickness 3 from x = 20 to 99 across a light 60 x 120 field, with the
    disk of a fragment (9 px) around each point of ``dark_at`` dark as well."""
    img = np.full((60, 120), 0.8, np.float32)
    yy, xx = np.mgrid[:60, :120]
    img[(np.abs(yy - 30) <= 3) & (xx >= 20) & (xx <= 99)] = 0.1
    for x, y in dark_at:
        img[np.hypot(xx - x, yy - y) <= 9.0] = 0.1
    return img, Skeleton([Branch([[20, 30], [99, 30]], 3.0)], img.shape)


def test_past_end_share_counts_what_stands_out_past_the_free_ends() -> None:
    img, sk = _line_with_ends(())
    assert past_end_share(img, sk) == 0.0
    # everything past the tip stands out, nothing past the start: the two ends are mirror
    # images, so half of the pixels counted
    img, sk = _line_with_ends(((99, 30),))
    assert past_end_share(img, sk) == pytest.approx(0.5, abs=1e-9)
    img, sk = _line_with_ends(((99, 30), (20, 30)))
    assert past_end_share(img, sk) == 1.0
    # bright structure on a dark field alike
    assert past_end_share(1.0 - img, sk) == 1.0
    # structure beside the branch away from its ends is not past an end
    img, sk = _line_with_ends(((60, 45),))
    assert past_end_share(img, sk) == 0.0
    # a child's start lies on its parent: only its tip counts
    child = Branch([[60, 30], [60, 55]], 3.0, parent=(0, 1))
    img, _ = _line_with_ends(((60, 30 + 25),))
    fam = Skeleton([sk.branches[0], child], img.shape)
    assert 0.2 < past_end_share(img, fam) < 0.45


def test_past_end_share_refuses_what_it_cannot_measure() -> None:
    img, sk = _line_with_ends(())
    with pytest.raises(ValueError, match="^skeleton: made for a"):
        past_end_share(img[:, :-1], sk)
    with pytest.raises(ValueError, match="^image: the structure does not stand out"):
        past_end_share(np.full_like(img, 0.5), sk)
    with pytest.raises(ValueError, match="^image:"):
        past_end_share(np.full(img.shape, np.nan), sk)


def _stem_with_children(lengths: list[float]) -> Skeleton:
    """A straight stem with a child every 20 px, of the given lengths from the stem's start on."""
    stem = Branch(
        np.c_[
            np.linspace(0, 20.0 * (len(lengths) + 1), 10 * (len(lengths) + 1) + 1),
            np.full(10 * (len(lengths) + 1) + 1, 200.0),
        ],
        1.0,
    )
    kids = [
        Branch([[20.0 * (k + 1), 200.0], [20.0 * (k + 1), 200.0 - ln]], 1.0, parent=(0, 10 * (k + 1)))
        for k, ln in enumerate(lengths)
    ]
    return Skeleton([stem, *kids])


def test_sibling_order_is_the_rank_correlation_of_place_and_length():
    falling = [150.0 - 10 * i for i in range(12)]
    assert sibling_order(_stem_with_children(falling)) == pytest.approx(-1.0)
    assert sibling_order(_stem_with_children(falling[::-1])) == pytest.approx(1.0)
    mixed = [150.0, 40.0, 130.0, 60.0, 110.0, 20.0, 90.0, 80.0, 70.0, 100.0, 50.0, 120.0]
    place, length = np.arange(12), np.asarray(mixed)
    ranks = np.argsort(np.argsort(length))
    assert sibling_order(_stem_with_children(mixed)) == pytest.approx(float(np.corrcoef(place, ranks)[0, 1]))


def test_sibling_order_needs_enough_children():
    assert sibling_order(_stem_with_children([150.0 - 10 * i for i in range(MIN_SIBLINGS - 1)])) == 0.0
    assert sibling_order(_stem_with_children([50.0] * 12)) == 0.0  # no order among equal lengths


def test_layout_agreement_is_the_mean_log_density_under_the_inputs_layout() -> None:
    from phloem.branching._layout import DirectionLayout

    src = Skeleton([Branch([[20, y], [280, y + 8]], 1.0) for y in range(60, 241, 20)], shape=(300, 300))
    lay = DirectionLayout.fit(src)
    kappa, phi = lay.at(150, 150, (300, 300))
    # one short edge at the middle: exactly kappa cos 2(theta - phi) there
    for theta in (0.0, 0.7, math.pi / 2):
        d = 2.0 * np.array([math.cos(theta), -math.sin(theta)])
        edge = Skeleton([Branch([[150, 150] - d / 2, [150, 150] + d / 2], 1.0)], shape=(300, 300))
        assert layout_agreement(src, edge) == pytest.approx(kappa * math.cos(2 * (theta - phi)), abs=1e-9)
    # the same picture twice the size: the layout is laid over it
    big = Skeleton([Branch([[100, 300], [500, 300]], 1.0)], shape=(600, 600))
    assert layout_agreement(src, big) > 2.0
    # an input whose branches run every way has no layout: nothing agrees or disagrees
    mesh = [Branch([[20, y], [280, y]], 1.0) for y in (100, 200)] + [
        Branch([[x, 20], [x, 280]], 1.0) for x in (100, 200)
    ]
    assert layout_agreement(Skeleton(mesh, shape=(300, 300)), src) == pytest.approx(0.0, abs=0.05)
    with pytest.raises(ValueError, match="^source:"):
        layout_agreement(Skeleton([], shape=(300, 300)), src)
    with pytest.raises(TypeError, match="^skeleton:"):
        layout_agreement(src, None)  # type: ignore[arg-type]


# -- end taper ----------------------------------------------------------------------------------


def test_end_taper_is_the_median_end_over_the_level_before() -> None:
    rng = np.random.default_rng(0)
    branches = []
    for i in range(5):
        n = 20 + 3 * i
        level = 2.0 + i
        # the level with some noise, then an end that thins to a third over four vertices
        t = level * (1 + 0.02 * rng.standard_normal(n))
        t[-4:] = level * np.array([0.8, 0.6, 0.45, 0.33])
        branches.append(Branch(np.c_[np.arange(n, dtype=float), np.full(n, 10.0 * i)], t))
    taper = end_taper(Skeleton(branches))
    assert taper.shape == (4,)
    assert np.allclose(taper, [0.8, 0.6, 0.45, 0.33], atol=0.02)
    # level ends, too few long branches, or only short ones: no taper
    level = Skeleton([Branch(b.points, float(np.median(b.thickness))) for b in branches])
    assert end_taper(level).size == 0
    assert end_taper(Skeleton(branches[:2])).size == 0
    assert end_taper(Skeleton([Branch(b.points[:15], b.thickness[:15]) for b in branches])).size == 0
    # an end that thickens (a blob) is capped at the level, not a taper
    blob = Skeleton([Branch(b.points, np.r_[b.thickness[:-3], 3 * b.thickness[-3:]]) for b in level.branches])
    assert end_taper(blob).size == 0
    with pytest.raises(TypeError, match="skeleton"):
        end_taper([[0, 0], [1, 1]])  # type: ignore[arg-type]


def test_wider_children_counts_children_past_their_parent_at_the_attachment() -> None:
    stem = Branch([[0.0, 50.0], [200.0, 50.0]], np.linspace(8.0, 2.0, 2)).resample(10.0)
    at = [4, 10, 16]  # 6.8, 5.0 and 3.2 px thick there
    kids = [
        Branch([[10.0 * v, 50.0], [10.0 * v, 90.0]], [3.0, 3.0], (0, v)) for v in at
    ]  # narrower than every attachment
    assert wider_children(Skeleton([stem, *kids])) == 0.0
    # the same width on a thinner stretch of the parent: wider than 1.5 x only at 3.2 px
    swell = [Branch(k.points, [3.0, 5.0], k.parent) for k in kids]
    assert wider_children(Skeleton([stem, *swell])) == pytest.approx(1 / 3)
    # a child that swells anywhere along it counts, not only at its start
    bulb = Branch([[100.0, 50.0], [100.0, 70.0], [100.0, 90.0]], [1.0, 12.0, 1.0], (0, 10))
    assert wider_children(Skeleton([stem, *kids, bulb])) == 0.25
    assert wider_children(Skeleton([stem, *kids, bulb]), factor=3.0) == 0.0
    assert math.isnan(wider_children(Skeleton([stem])))
    for bad in (0.5, math.nan, "wide"):
        with pytest.raises((ValueError, TypeError), match="^factor"):
            wider_children(Skeleton([stem, *kids]), factor=bad)  # type: ignore[arg-type]
