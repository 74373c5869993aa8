"""Tracing source skeletons from images (phloem.branching.trace) and maximum-gradient thickness (000 §3)."""

from __future__ import annotations

import itertools
import time

import cv2
import numpy as np
import pytest

import phloem
from phloem.branching import Branch, Skeleton, estimate_thickness, trace

# -- synthetic structures with a known centre line and radius ---------------------------------


def _seg_dist(px: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points ``px`` (..., 2) to segment ``a``-``b``."""
    d = b - a
    t = np.clip(((px - a) @ d) / float(d @ d), 0.0, 1.0)
    return np.linalg.norm(px - (a + t[..., None] * d), axis=-1)


class Tubes:
    """Straight segments ``(a, b, radius, name)`` rasterised exactly: a pixel is inside when its
    centre is within ``radius`` of a segment (round caps, round joints)."""

    def __init__(self, shape: tuple[int, int], segs: list[tuple[tuple[float, float], tuple[float, float], float, str]]):
        self.shape = shape
        self.segs = [(np.asarray(a, float), np.asarray(b, float), float(r), n) for a, b, r, n in segs]
        yy, xx = np.mgrid[: shape[0], : shape[1]]
        px = np.stack([xx, yy], axis=-1).astype(float)
        self.dist = np.min([_seg_dist(px, a, b) - r for a, b, r, _ in self.segs], axis=0)

    def mask(self) -> np.ndarray:
        return (self.dist <= 0).astype(np.uint8)

    def nearest(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance of each point to the nearest centre-line segment, and that segment's radius."""
        d = np.stack([_seg_dist(pts, a, b) for a, b, _, _ in self.segs])
        k = np.argmin(d, axis=0)
        return d[k, np.arange(len(pts))], np.array([self.segs[i][2] for i in k])


def _dist_to(pts: np.ndarray, seg: tuple) -> np.ndarray:
    return _seg_dist(pts, seg[0], seg[1])


def _near(pts: np.ndarray, where: list[tuple[float, float]], radius: float) -> np.ndarray:
    return np.min([np.linalg.norm(pts - np.asarray(w, float), axis=1) for w in where], axis=0) < radius


Y_SHAPE = Tubes(
    (110, 100),
    [((50, 100), (50, 60), 5, "stem"), ((50, 60), (20, 15), 3, "left"), ((50, 60), (82, 18), 3, "right")],
)

# Trunk r=5 splits at (100, 110) into A (straight on, r=4) and B (r=3); A has a short side branch
# A1 at (100, 70), B one (B1) at (130, 95). Every side branch is shorter than the rest of its
# parent, so the longest-path decomposition is trunk+A, then B and A1, then B1.
TREE = Tubes(
    (200, 200),
    [
        ((100, 190), (100, 110), 5, "trunk"),
        ((100, 110), (100, 30), 4, "A"),
        ((100, 110), (160, 80), 3, "B"),
        ((100, 70), (70, 55), 2.5, "A1"),
        ((130, 95), (135, 120), 2.5, "B1"),
    ],
)
TREE_TIPS = {"A": (100, 30), "B": (160, 80), "A1": (70, 55), "B1": (135, 120)}
JUNCTIONS = [(100, 110), (100, 70), (130, 95)]


def _tip_name(b: Branch) -> str:
    d = {n: np.linalg.norm(b.points[-1] - np.asarray(p, float)) for n, p in TREE_TIPS.items()}
    name = min(d, key=lambda n: d[n])
    assert d[name] < 8, f"branch ends at {b.points[-1]}, far from every tip"
    return name


def _assert_centreline(sk: Skeleton, tubes: Tubes, junctions: list[tuple[float, float]] = ()) -> None:
    """Every vertex within 1.5 px of the true centre line; 2.5 px within 8 px of a junction, where
    the medial axis of the union of tubes bends away from the centre lines."""
    pts = np.vstack([b.points for b in sk.branches])
    d, _ = tubes.nearest(pts)
    tol = np.where(_near(pts, list(junctions), 8.0), 2.5, 1.5) if junctions else np.full(len(pts), 1.5)
    bad = d - tol
    assert bad.max() <= 0, f"vertex {pts[np.argmax(bad)]} is {d[np.argmax(bad)]:.2f} px off the centre line"


def _assert_thickness(sk: Skeleton, tubes: Tubes, away: list[tuple[float, float]], tol: float = 0.8) -> None:
    """Thickness within ``tol`` of the true radius, away from junctions and tips (10 px)."""
    pts = np.vstack([b.points for b in sk.branches])
    thick = np.concatenate([b.thickness for b in sk.branches])
    keep = ~_near(pts, away, 10.0)
    assert keep.sum() > 0.5 * len(pts)
    _, r = tubes.nearest(pts[keep])
    err = np.abs(thick[keep] - r)
    assert err.max() <= tol, f"thickness off by {err.max():.2f} px at {pts[keep][np.argmax(err)]}"


# -- trace on masks ---------------------------------------------------------------------------


def test_y_shape_two_branches_on_the_centre_line_with_the_right_thickness():
    sk = trace(Y_SHAPE.mask(), kind="mask")
    assert sk.shape == (110, 100)
    assert len(sk.branches) == 2
    main, child = sk.branches
    # the thick stem is the root: the main branch starts at its bottom
    assert np.linalg.norm(main.points[0] - (50, 100)) < 3
    assert main.parent is None and child.parent is not None
    pb, pv = child.parent
    assert pb == 0
    assert np.linalg.norm(main.points[pv] - (50, 60)) < 4
    assert np.allclose(child.points[0], main.points[pv], atol=1.5)
    _assert_centreline(sk, Y_SHAPE, [(50, 60)])
    _assert_thickness(sk, Y_SHAPE, away=[(50, 60), (50, 100), (20, 15), (82, 18)])


# a thin side channel leaving at 45° and at 90°, and a T of two channels as wide
@pytest.mark.parametrize(("tip", "radius"), [((145, 55), 2.5), ((100, 35), 2.5), ((100, 35), 9.0)])
def test_a_channel_starts_at_its_own_width_and_does_not_widen_the_one_it_leaves(tip, radius):
    # Within a junction's disk the distance transform measures the junction: the thin side
    # channel started at 9 px, and at the T the river swelled to 11 px.
    tubes = Tubes((200, 200), [((10, 100), (190, 100), 9, "river"), ((100, 100), tip, radius, "side")])
    sk = trace(tubes.mask(), kind="mask")
    assert len(sk.branches) == 2
    river, side = sk.branches
    assert side.parent is not None and side.parent[0] == 0
    assert np.abs(side.thickness[:3] - radius).max() < 1.5, side.thickness[:6]
    assert np.abs(river.thickness[20:-20] - 9).max() < 1.5, river.thickness.max()


def test_a_photos_side_channel_starts_at_its_own_width():
    # estimate_thickness measures a child's first vertices across its parent's channel: a
    # 2.5-px channel leaving a 6-px one at 45° started at 3.5 px.
    tubes = Tubes((200, 200), [((10, 100), (190, 100), 6, "river"), ((100, 100), (145, 55), 2.5, "side")])
    photo = cv2.GaussianBlur(np.where(tubes.mask() > 0, 0.2, 0.8).astype(np.float32), (0, 0), 1.0)
    sk = trace(photo)
    assert len(sk.branches) == 2 and sk.branches[1].parent is not None
    assert np.abs(sk.branches[1].thickness[:3] - 2.5).max() < 0.5, sk.branches[1].thickness[:6]


def test_three_level_tree_parents_point_to_the_right_branch():
    sk = trace(TREE.mask(), kind="mask")
    assert len(sk.branches) == 4
    names = [_tip_name(b) for b in sk.branches]
    assert names[0] == "A" and np.linalg.norm(sk.branches[0].points[0] - (100, 190)) < 3
    assert sorted(names) == ["A", "A1", "B", "B1"]
    by = dict(zip(names, sk.branches))
    expect = {"B": ("A", (100, 110)), "A1": ("A", (100, 70)), "B1": ("B", (130, 95))}
    for child, (parent, at) in expect.items():
        pb, pv = by[child].parent
        assert names[pb] == parent, f"{child} hangs off {names[pb]}, not {parent}"
        assert np.linalg.norm(sk.branches[pb].points[pv] - at) < 5
    depth = []
    for b in sk.branches:
        depth.append(0 if b.parent is None else depth[b.parent[0]] + 1)
    assert sorted(depth) == [0, 1, 1, 2]
    _assert_centreline(sk, TREE, JUNCTIONS)
    _assert_thickness(sk, TREE, away=JUNCTIONS + list(TREE_TIPS.values()) + [(100, 190)])


def test_ring_and_braid_are_cut_into_trees():
    ring = Tubes(
        (100, 100),
        [
            ((50 + 30 * np.cos(a), 50 + 30 * np.sin(a)), (50 + 30 * np.cos(b), 50 + 30 * np.sin(b)), 3, "r")
            for a, b in zip(np.linspace(0, 2 * np.pi, 41)[:-1], np.linspace(0, 2 * np.pi, 41)[1:])
        ],
    )
    sk = trace(ring.mask(), kind="mask")
    assert len(sk.branches) >= 1 and sk.branches[0].parent is None
    _assert_centreline(sk, ring)
    # nearly the whole circumference, cut once
    assert 0.9 * 2 * np.pi * 30 < sk.total_length() < 2 * np.pi * 30 + 1
    # a braid: two channels that split and rejoin, with a stem on either side; the upper one is thinner
    braid = Tubes(
        (80, 160),
        [
            ((5, 40), (40, 40), 4, "in"),
            ((40, 40), (80, 15), 2, "u1"),
            ((80, 15), (120, 40), 2, "u2"),
            ((40, 40), (80, 65), 3, "d1"),
            ((80, 65), (120, 40), 3, "d2"),
            ((120, 40), (155, 40), 4, "out"),
        ],
    )
    sk = trace(braid.mask(), kind="mask")
    _assert_centreline(sk, braid, [(40, 40), (120, 40)])
    # the cycle is cut in the thin upper channel: the main branch runs along the lower one, and
    # branch ends lie inside the upper channel (away from its junctions)
    assert sk.branches[0].points[:, 1].max() > 60
    ends = np.array([p for b in sk.branches for p in (b.points[0], b.points[-1])])
    on_upper = np.min([_dist_to(ends, braid.segs[k]) for k in (1, 2)], axis=0) < 2.5
    assert (on_upper & ~_near(ends, [(40, 40), (120, 40)], 6.0)).any(), "the thick channel was cut"
    total = sum(np.hypot(*(b - a)) for a, b, _, _ in braid.segs)
    assert sk.total_length() < total


def test_several_components_give_several_roots_largest_first():
    m = np.zeros((60, 120), np.uint8)
    m[10:16, 5:40] = 1
    m[30:38, 50:115] = 1
    sk = trace(m, kind="mask")
    assert [b.parent for b in sk.branches] == [None, None]
    assert sk.branches[0].length() > sk.branches[1].length()


def test_options_root_h_and_determinism():
    mask = TREE.mask()
    a = trace(mask, kind="mask")
    assert trace(mask, kind="mask") == a
    sk = trace(mask, kind="mask", root=(160, 80))
    assert np.linalg.norm(sk.branches[0].points[0] - (160, 80)) < 6
    r = trace(mask, kind="mask", h=3.0)
    for b in r.branches:
        assert np.allclose(np.linalg.norm(np.diff(b.points, axis=0), axis=1), 3.0)
    assert len(trace(mask, kind="mask", min_length=60).branches) == 2  # only trunk+A and B are that long


# -- trace on photos --------------------------------------------------------------------------


@pytest.mark.parametrize("dark", [True, False])
def test_photo_of_a_tree_traced_by_ridge_filter(dark):
    rng = np.random.default_rng(1)
    soft = np.clip(0.5 - TREE.dist, 0.0, 1.0)  # anti-aliased tubes
    img = (0.75 - 0.5 * soft if dark else 0.25 + 0.5 * soft) + rng.normal(0, 0.03, TREE.shape)
    sk = trace(img.astype(np.float32), sigmas=(1.5, 3.0))
    assert 3 <= len(sk.branches) <= 8
    pts = np.vstack([b.points for b in sk.branches])
    d, _ = TREE.nearest(pts)
    assert np.percentile(d, 95) <= 2.0
    # most of the structure is found
    assert sk.total_length() > 0.8 * sum(np.hypot(*(b - a)) for a, b, _, _ in TREE.segs) - 40
    # thickness by maximum gradient: right within a pixel away from forks and tips
    thick = np.concatenate([b.thickness for b in sk.branches])
    keep = ~_near(pts, [*JUNCTIONS, *TREE_TIPS.values(), (100, 190)], 10.0)
    _, r = TREE.nearest(pts[keep])
    assert np.median(np.abs(thick[keep] - r)) < 0.5
    assert np.percentile(np.abs(thick[keep] - r), 90) < 1.0


def test_photo_roots_its_tree_at_the_thick_end():
    # Three arms from one fork, each end about as far from the others: only the thickness says
    # which is the trunk. Its ridge mask is no wider than the arms' (the filter's largest scale
    # is below its radius), so the root must come from the photo's own edges.
    img = np.full((300, 300), 0.8, np.float32)
    cv2.line(img, (150, 295), (150, 160), 0.2, thickness=13, lineType=cv2.LINE_AA)  # radius 6.5
    for end in [(33, 92), (267, 92)]:
        cv2.line(img, (150, 160), end, 0.2, thickness=5, lineType=cv2.LINE_AA)  # radius 2.5
    sk = trace(cv2.GaussianBlur(img, (0, 0), 1.0))
    main = sk.branches[0]
    assert np.linalg.norm(main.points[0] - (150, 297)) < 6, f"rooted at {main.points[0]}, not the trunk's end"
    assert np.median(main.thickness[:10]) > 5.0


def test_photo_rim_is_not_a_ridge_and_broken_vessels_are_bridged():
    # A retina-like photo: a lit disk on black with one dark vessel across it that has a 16 px gap.
    yy, xx = np.mgrid[:240, :240]
    img = np.where(np.hypot(xx - 120, yy - 120) < 110, 0.6, 0.02)
    vessel = Tubes((240, 240), [((30, 120), (112, 120), 3, "a"), ((128, 120), (210, 120), 3, "b")])
    img = (img - 0.3 * np.clip(0.5 - vessel.dist, 0, 1)).astype(np.float32)
    sk = trace(img, kind="dark", sigmas=(1.5, 3.0), gap=20)
    pts = np.vstack([b.points for b in sk.branches])
    rim = np.abs(np.hypot(pts[:, 0] - 120, pts[:, 1] - 120) - 110)
    assert rim.min() > 8, "the rim of the lit disk was traced"
    assert len(sk.branches) == 1, "the gap was not bridged"
    assert sk.branches[0].length() > 160
    assert len(trace(img, kind="dark", sigmas=(1.5, 3.0), gap=0).branches) == 2


def _bolt_in_a_glow(seed: int) -> tuple[np.ndarray, float]:
    """A bolt 1 px wide (a Gaussian profile of 0.4 px) wandering down through a bright glow on a
    dark sky, with noise; and its length."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:160, :240].astype(np.float32)
    t = np.linspace(0, 1, 600)
    bx, by = 120 + 40 * np.sin(3 * t) - 30 * t + 3 * np.sin(40 * t), 10 + 140 * t
    d2 = np.min([(xx - x0) ** 2 + (yy - y0) ** 2 for x0, y0 in zip(bx, by)], axis=0)
    img = 0.1 + 0.6 * np.exp(-((xx - 110) ** 2 + (yy - 70) ** 2) / (2 * 30.0**2))
    img = img + 0.2 * np.exp(-d2 / (2 * 0.4**2)) + rng.normal(0, 0.02, yy.shape)
    return img.astype(np.float32), float(np.hypot(np.diff(bx), np.diff(by)).sum())


@pytest.mark.parametrize("seed", [0, 1])
def test_subpixel_traces_a_thin_bolt_in_a_glow_whole(seed):
    # On the pixel grid the bolt keeps its ridge response only where its centre falls near a
    # pixel centre, so the default traces 24-37 px of it; on the finer grid it is one branch.
    img, length = _bolt_in_a_glow(seed)
    sk = trace(img, subpixel=True)
    assert len(sk.branches) == 1
    assert sk.total_length() > 0.9 * length


def _vessel_tree() -> np.ndarray:
    """A dark vessel tree on a light ground with noise: a trunk 17 px wide, far wider than the
    default ridge scales reach, forking at (150, 170) into two arms 5 px wide, with four twigs
    3 px wide off the trunk."""
    img = np.full((320, 300), 0.8, np.float32)
    cv2.line(img, (150, 315), (150, 170), 0.2, thickness=17, lineType=cv2.LINE_AA)
    for end in [(50, 40), (250, 40)]:
        cv2.line(img, (150, 170), end, 0.2, thickness=5, lineType=cv2.LINE_AA)
    for y, x in [(280, 70), (280, 230), (220, 80), (220, 220)]:
        cv2.line(img, (150, y), (x, y - 40), 0.2, thickness=3, lineType=cv2.LINE_AA)
    noise = np.random.default_rng(0).normal(0, 0.02, img.shape).astype(np.float32)
    return cv2.GaussianBlur(img, (0, 0), 1.0) + noise


def test_a_trunk_wider_than_the_ridge_scales_holds_its_tree_together():
    # The fine scales answer only beside the trunk's edges, so without the wide filter the
    # arms and twigs are six separate trees and the trunk none of them.
    img = _vessel_tree()
    assert len([b for b in trace(img, wide=False).branches if b.parent is None]) > 1
    sk = trace(img)
    assert [b.parent is None for b in sk.branches].count(True) == 1, "the tree fell apart"
    main = sk.branches[0]
    assert np.linalg.norm(main.points[0] - (150, 315)) < 8, f"rooted at {main.points[0]}, not the trunk's foot"
    assert np.median(main.thickness[: len(main) // 3]) > 6.0
    assert np.abs(main.points[: len(main) // 3, 0] - 150).max() < 6, "the main branch left the trunk's axis"


def _forked_bolt_in_a_glow(seed: int) -> np.ndarray:
    """A bright bolt 1 px wide with three forks in a glow of 6 px, on a dark sky with noise."""
    core = np.zeros((200, 260), np.float32)
    cv2.polylines(core, [np.array([(130, 5), (125, 60), (135, 100)], np.int32)], False, 1.0, 1, cv2.LINE_AA)
    for a, b in [((135, 100), (70, 190)), ((135, 100), (200, 190)), ((125, 60), (60, 90))]:
        cv2.line(core, a, b, 1.0, 1, cv2.LINE_AA)
    glow = cv2.GaussianBlur(core, (0, 0), 6.0)
    noise = np.random.default_rng(seed).normal(0, 0.02, core.shape)
    return (0.1 + 0.5 * core + 0.5 * glow / glow.max() + noise).astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1])
def test_wide_leaves_a_bolt_in_a_glow_as_the_fine_scales_trace_it(seed):
    # A glow is a wide ridge too, but its axis is the bolt's core, which the fine mask holds but
    # for a few px where the glow swells at a fork: painting those would knot the forks.
    img = _forked_bolt_in_a_glow(seed)
    a, b = trace(img), trace(img, wide=False)
    assert len(a.branches) == len(b.branches) == 3
    assert all(np.array_equal(x.points, y.points) for x, y in zip(a.branches, b.branches, strict=True))


def _crack_on(background: np.ndarray) -> tuple[np.ndarray, Skeleton]:
    """A dark wavy crack 2 px wide drawn across ``background`` (240x320), and its centre line."""
    x = np.arange(10, 310, dtype=np.float64)
    pts = np.c_[x, 120 + 30 * np.sin(x / 50)]
    img = background.astype(np.float32)
    cv2.polylines(img, [np.round(pts).astype(np.int32)], False, 0.40, 2)
    return np.clip(img, 0, 1), Skeleton([Branch(pts, 1.0)], (240, 320))


@pytest.mark.parametrize("seed", range(4))
def test_a_crack_on_grain_is_traced_without_the_grain(seed):
    # asphalt-like grain answers the ridge filter everywhere; Otsu's threshold takes it for
    # structure, the default climbs to where the grain is shed and the crack is left
    from phloem._ridges import ridge_response
    from phloem.branching.trace import DEFAULT_SIGMAS, _otsu, _ridge_mask, _stable_threshold
    from phloem.metrics import skeleton_agreement

    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 1.2)
    img, truth = _crack_on(0.55 + 0.05 * grain / grain.std())
    resp = ridge_response(img, DEFAULT_SIGMAS, "dark")
    otsu, (t, climb, mask) = _otsu(resp), _stable_threshold(resp, 30)
    assert climb > 1.0 and t > otsu
    assert np.array_equal(mask, _ridge_mask(resp, t))
    # the climb sheds most of the grain's mask and keeps the crack's
    assert mask.sum() < 0.5 * _ridge_mask(resp, otsu).sum()
    near = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    px = np.round(truth.branches[0].points).astype(int)
    assert near[px[:, 1], px[:, 0]].mean() >= 0.95
    new = skeleton_agreement(truth, trace(img, kind="dark"))
    old = skeleton_agreement(truth, trace(img, kind="dark", threshold=otsu))
    assert new.recall >= 0.95 and new.precision >= 0.8
    assert old.precision < 0.3  # the grain traced as cracks


def _broken_crack_on_grain(seed: int) -> tuple[np.ndarray, Skeleton]:
    """:func:`_crack_on`'s crack with two 10-px breaks, on grain, and its whole centre line."""
    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 1.2)
    img = 0.55 + 0.05 * grain / grain.std()
    x = np.arange(10, 310, dtype=np.float64)
    pts = np.c_[x, 120 + 30 * np.sin(x / 50)]
    for a, b in ((0, 85), (95, 190), (200, 300)):
        cv2.polylines(img, [np.round(pts[a:b]).astype(np.int32)], False, 0.40, 2)
    return np.clip(img, 0, 1).astype(np.float32), Skeleton([Branch(pts, 1.0)], (240, 320))


@pytest.mark.parametrize("seed", range(5))
def test_a_crack_broken_by_grain_is_joined_as_far_as_the_threshold_climbed(seed):
    # the crack's faint stretches fall below a raised threshold; the default gap grows with it
    img, _ = _broken_crack_on_grain(seed)

    def longest(sk: Skeleton) -> float:
        return max(b.length() for b in sk.branches)

    assert longest(trace(img, kind="dark")) > 200
    assert longest(trace(img, kind="dark", gap=9.0)) < 120  # the photos' gap before the climb: three pieces


def test_a_crack_on_a_smooth_surface_keeps_otsus_threshold():
    from phloem._ridges import ridge_response
    from phloem.branching.trace import DEFAULT_SIGMAS, _otsu, _ridge_mask, _stable_threshold

    rng = np.random.default_rng(0)
    img, _ = _crack_on(0.55 + 0.005 * rng.normal(0, 1, (240, 320)))
    resp = ridge_response(img, DEFAULT_SIGMAS, "dark")
    t, climb, mask = _stable_threshold(resp, 30)
    assert (t, climb) == (_otsu(resp), 1.0) and np.array_equal(mask, _ridge_mask(resp, t))
    assert trace(img, kind="dark") == trace(img, kind="dark", threshold=_otsu(resp))


@pytest.mark.parametrize("seed", range(3))
def test_threshold_scale_multiplies_the_default_threshold(seed):
    # the default threshold (climbed on grain) times the factor, in no unit the user must know
    from phloem._ridges import ridge_response
    from phloem.branching.trace import DEFAULT_SIGMAS, _stable_threshold

    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 1.2)
    img, _ = _crack_on(0.55 + 0.05 * grain / grain.std())
    t, _, _ = _stable_threshold(ridge_response(img, DEFAULT_SIGMAS, "dark"), 30)
    default = trace(img, kind="dark")
    assert trace(img, kind="dark", threshold_scale=1.0) == default
    for f in (0.6, 1.5):
        # the same gap as the default's: the climb still sets it
        assert trace(img, kind="dark", threshold_scale=f) == trace(img, kind="dark", threshold=f * t, gap=_gap(img))
    # lower keeps more (grain included), higher less
    assert trace(img, kind="dark", threshold_scale=0.6).total_length() > default.total_length()
    assert trace(img, kind="dark", threshold_scale=1.5).total_length() < default.total_length()


def _gap(img: np.ndarray) -> float:
    """The default trace's bridging gap on ``img`` (dark, default scales), climb included."""
    from phloem.branching import threshold_climb
    from phloem.branching.trace import DEFAULT_SIGMAS, _default_gap

    return _default_gap(DEFAULT_SIGMAS, "dark") * threshold_climb(img, kind="dark")


@pytest.mark.parametrize("seed", range(3))
def test_threshold_climb_is_how_far_the_default_trace_climbed(seed):
    # the public measure is the trace's own: on grain its threshold and gap climbed this far
    from phloem._ridges import ridge_response
    from phloem.branching import threshold_climb
    from phloem.branching.trace import DEFAULT_SIGMAS, GRAIN_STEP, GRAIN_STEPS, _default_gap, _otsu

    rng = np.random.default_rng(seed)
    grain = cv2.GaussianBlur(rng.normal(0, 1, (240, 320)).astype(np.float32), (0, 0), 1.2)
    grainy, _ = _crack_on(0.55 + 0.05 * grain / grain.std())
    smooth, _ = _crack_on(0.55 + 0.005 * rng.normal(0, 1, (240, 320)))
    c = threshold_climb(grainy, kind="dark")
    assert c in {GRAIN_STEP**k for k in range(1, GRAIN_STEPS + 1)}
    otsu = _otsu(ridge_response(grainy, DEFAULT_SIGMAS, "dark"))
    gap = _default_gap(DEFAULT_SIGMAS, "dark") * c
    assert trace(grainy, kind="dark") == trace(grainy, kind="dark", threshold=otsu * c, gap=gap)
    assert threshold_climb(smooth) == threshold_climb(smooth, kind="dark") == 1.0
    # a mask has no grain, whatever its kind says or auto finds
    assert threshold_climb(grainy, kind="mask") == 1.0
    assert threshold_climb((smooth < 0.5).astype(np.float32)) == 1.0


@pytest.mark.parametrize(
    ("kwargs", "err", "match"),
    [
        ({"image": np.full((10, 10), 0.3)}, ValueError, "^image: nothing to trace"),
        ({"image": np.zeros((2, 10))}, ValueError, "^image: nothing to trace"),
        ({"kind": "ridges"}, ValueError, "^kind: "),
        ({"sigmas": -1.0}, ValueError, "^sigmas: "),
        ({"min_area": -1}, ValueError, "^min_area: "),
        ({"channel": 2}, ValueError, "^channel: "),
        ({"subpixel": "yes"}, TypeError, "^subpixel: "),
        ({"valid": np.ones((3, 3), bool)}, ValueError, "^valid: "),
        ({"image": np.full((10, 10), np.nan), "kind": "mask"}, ValueError, "^image: "),
    ],
)
def test_threshold_climb_names_a_bad_argument(kwargs, err, match):
    from phloem.branching import threshold_climb

    image = kwargs.pop("image", Y_SHAPE.mask().astype(np.float32) * 0.5 + 0.25)
    with pytest.raises(err, match=match):
        threshold_climb(image, **kwargs)


def _dish(edge: bool) -> np.ndarray:
    """A vessel tree, two vessel pieces and a thick dark band above them: the rim of a dish
    with its bright outside above it (``edge``), or a thick vessel with tissue on both sides."""
    rng = np.random.default_rng(0)
    img = np.full((220, 280), 0.6, np.float32)
    if edge:
        img[:40, :] = 0.95
    cv2.line(img, (80, 46), (200, 46), 0.25, 9)
    cv2.line(img, (140, 215), (140, 140), 0.3, 4)
    cv2.line(img, (140, 140), (60, 75), 0.3, 3)
    cv2.line(img, (140, 140), (225, 80), 0.3, 3)
    for x in (30, 250):
        cv2.line(img, (x, 120), (x + 10, 200), 0.3, 3)
    return np.clip(img + rng.normal(0, 0.01, img.shape).astype(np.float32), 0, 1)


def test_a_thick_edge_between_two_regions_is_not_traced_as_a_tree():
    def bands(sk: Skeleton) -> list[Branch]:
        return [b for b in sk.branches if b.parent is None and abs(np.median(b.points[:, 1]) - 46) < 3]

    vessel = trace(_dish(False), kind="dark")
    assert len(bands(vessel)) == 1 and np.median(bands(vessel)[0].thickness) > 4  # a thick vessel stays
    rim = trace(_dish(True), kind="dark")
    assert bands(rim) == []  # the rim between the bright outside and the tissue is an edge
    assert len(rim.branches) == len(vessel.branches) - 1  # and nothing else went with it
    # the caller's root says what the structure is: its tree stays; edges=False keeps every tree
    assert len(bands(trace(_dish(True), kind="dark", root=(140, 46)))) == 1
    assert len(bands(trace(_dish(True), kind="dark", edges=False))) == 1


def test_the_truth_bench_rescores_the_default_trace_at_one_times_its_threshold():
    # benches/quality/branching_trace_truth.py passes the default threshold and gap explicitly
    # for its --fractions; at 1x they must give the default trace, or its rows compare unlike
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benches" / "quality" / "branching_trace_truth.py"
    spec = importlib.util.spec_from_file_location("_branching_trace_truth", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)

    img, truth = _broken_crack_on_grain(0)  # a climb, so the gap grows and joins the breaks
    drawn = truth.mask()
    rows = bench.score(img, drawn, fractions=(1.0, 0.5), kinds=("dark", "bright"))
    names = bench.variants((1.0, 0.5), ("dark", "bright"))
    assert len(rows) == len(names) == 6
    default, otsu, one, half, dark, bright = rows
    assert one == default and dark == default  # auto resolves this crack to dark
    assert default[0] >= 0.8 and otsu[0] < 0.3  # precision: the grain rule's climb against Otsu's
    assert half[0] < default[0] and bright[2] < 0.3
    assert bench.score(img, np.zeros_like(drawn)) is None  # nothing drawn


def test_a_trunks_foot_is_a_root_candidate_though_its_arms_span_the_tree():
    # A short thick trunk under two long thin arms: the foot is 0.7 of the diameter from the
    # farthest end, the arms' ends 1.0; the thickest of the far ends is the foot.
    tubes = Tubes((200, 440), [((220, 190), (220, 110), 6, "trunk"), ((220, 110), (20, 60), 2, "left"),
                               ((220, 110), (420, 60), 2, "right")])  # fmt: skip
    main = trace(tubes.mask(), kind="mask").branches[0]
    assert np.linalg.norm(main.points[0] - (220, 190)) < 8, f"rooted at {main.points[0]}, not the trunk's foot"


@pytest.mark.parametrize("foot", [199, 180])
def test_a_trunk_entering_at_the_frame_is_the_root(foot):
    # A trunk an eighth thicker than its two long arms, 0.7 of the diameter from the farthest end:
    # where it leaves the picture it is where the structure enters, and its foot is the root;
    # ending inside the picture it is a nearer, only somewhat thicker end, and an arm's end is.
    tubes = Tubes((200, 440), [((220, foot), (220, 110), 4.5, "trunk"), ((220, 110), (20, 60), 4, "left"),
                               ((220, 110), (420, 60), 4, "right")])  # fmt: skip
    start = trace(tubes.mask(), kind="mask").branches[0].points[0]
    at_foot = np.linalg.norm(start - (220, foot)) < 10
    assert at_foot == (foot == 199), f"rooted at {start}"


# -- thickness by maximum gradient ----------------------------------------------------------


@pytest.mark.parametrize("radius", [2.0, 4.0, 7.0])
def test_estimate_thickness_on_blurred_tubes(radius):
    import cv2

    t = np.linspace(0.2, 2.6, 40)
    centre = np.stack([80 + 50 * np.cos(t), 80 + 50 * np.sin(t)], axis=1)
    tubes = Tubes((160, 160), [(tuple(a), tuple(b), radius, "arc") for a, b in itertools.pairwise(centre)])
    img = cv2.GaussianBlur(np.clip(0.5 - tubes.dist, 0, 1).astype(np.float32), (0, 0), 1.0)
    img = 0.8 - 0.5 * img  # dark tube on a bright background
    sk = Skeleton([Branch(centre, 0.0)], (160, 160))
    est = estimate_thickness(img, sk).branches[0].thickness
    assert np.abs(est - radius).max() < 1.0, est
    # a centre line 1 px off still gives the radius: half the distance between the edges
    off = Skeleton([Branch(centre * 1.0 + 1.0, 0.0)])
    est = estimate_thickness(img, off).branches[0].thickness
    assert np.abs(est - radius).max() < 1.0, est


def test_estimate_thickness_keeps_structure():
    sk = trace(TREE.mask(), kind="mask")
    est = estimate_thickness(TREE.mask().astype(np.float32), sk)
    assert [b.parent for b in est.branches] == [b.parent for b in sk.branches] and est.shape == sk.shape
    assert all(np.array_equal(a.points, b.points) for a, b in zip(est.branches, sk.branches))


# -- errors -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("image", "kwargs", "err", "match"),
    [
        (np.zeros((0, 10)), {}, ValueError, "image"),
        (np.zeros((4, 4, 4, 4)), {}, ValueError, "image"),
        (np.zeros((10, 10), bool), {}, TypeError, "image"),
        (np.full((10, 10), np.nan), {}, ValueError, "image"),
        (np.full((10, 10), 0.3), {}, ValueError, "image: nothing to trace"),
        (Y_SHAPE.mask(), {"kind": "ridges"}, ValueError, "kind"),
        (Y_SHAPE.mask(), {"sigmas": -1.0}, ValueError, "sigmas"),
        (Y_SHAPE.mask(), {"sigmas": ()}, ValueError, "sigmas"),
        (Y_SHAPE.mask(), {"min_length": -1.0}, ValueError, "min_length"),
        (Y_SHAPE.mask(), {"min_length": 1000.0}, ValueError, "image: nothing to trace"),
        (Y_SHAPE.mask(), {"root": (500, 5)}, ValueError, "root"),
        (Y_SHAPE.mask(), {"channel": 2}, ValueError, "channel"),
        (Y_SHAPE.mask(), {"h": 0.0}, ValueError, "h"),
        (Y_SHAPE.mask(), {"thickness": "dt"}, ValueError, "thickness"),
        (Y_SHAPE.mask(), {"gap": -1.0}, ValueError, "gap"),
        (Y_SHAPE.mask(), {"subpixel": "yes"}, TypeError, "subpixel"),
        (Y_SHAPE.mask(), {"wide": "yes"}, TypeError, "wide"),
        (Y_SHAPE.mask(), {"edges": "yes"}, TypeError, "edges"),
        (Y_SHAPE.mask(), {"threshold_scale": 0.0}, ValueError, "threshold_scale"),
        (Y_SHAPE.mask(), {"threshold_scale": float("nan")}, ValueError, "threshold_scale"),
        (Y_SHAPE.mask(), {"kind": "mask", "threshold_scale": 0.5}, ValueError, "threshold_scale: a mask"),
        (Y_SHAPE.mask(), {"threshold": 0.5, "threshold_scale": 0.5}, ValueError, "threshold_scale: scales"),
        (Y_SHAPE.mask(), {"kind": "mask", "threshold": 2.0}, ValueError, "image: nothing to trace"),
        (Y_SHAPE.mask(), {"kind": "mask", "threshold": -1.0}, ValueError, "foreground fills the whole image"),
        (np.random.default_rng(0).random((3, 3)), {}, ValueError, "foreground fills the whole image"),
    ],
)
def test_bad_input_names_the_argument(image, kwargs, err, match):
    with pytest.raises(err, match=match):
        trace(image, **kwargs)


def test_estimate_thickness_bad_input():
    sk = Skeleton([Branch([[1, 1], [5, 5]], 1.0)])
    with pytest.raises(TypeError, match="skeleton"):
        estimate_thickness(np.zeros((10, 10)), "not a skeleton")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="max_radius"):
        estimate_thickness(np.zeros((10, 10)), sk, max_radius=0)
    with pytest.raises(ValueError, match="image"):
        estimate_thickness(np.full((10, 10), np.nan), sk)


# -- real images ------------------------------------------------------------------------------


@pytest.mark.shared
def test_retina_trace_is_plausible():
    from phloem.testing import shared_file

    img = phloem.io.read_image(shared_file("branching", "skimage_retina.jpg"))
    t0 = time.perf_counter()
    sk = trace(img, kind="dark", channel=1, sigmas=(1.5, 3.0))
    assert time.perf_counter() - t0 < 30  # loose: it takes well under a second
    assert 50 <= len(sk.branches) <= 800
    assert 8_000 < sk.total_length() < 60_000
    # vessels are dark: traced vertices are darker than the image around them
    import cv2

    g = img[..., 1]
    local = cv2.blur(g, (31, 31))
    pts = np.vstack([b.points for b in sk.branches]).round().astype(int)
    darker = g[pts[:, 1], pts[:, 0]] < local[pts[:, 1], pts[:, 0]]
    assert darker.mean() > 0.8


@pytest.mark.shared
def test_colville_delta_trace_is_plausible():
    from phloem.testing import shared_file

    img = phloem.io.read_image(shared_file("branching", "rivgraph_colville_delta_mask.png"))
    t0 = time.perf_counter()
    sk = trace(img)
    assert time.perf_counter() - t0 < 30  # loose: it takes about half a second
    assert sk.shape == img.shape[:2]
    assert 30 <= len(sk.branches) <= 1000
    assert 8_000 < sk.total_length() < 50_000
    pts = np.vstack([b.points for b in sk.branches]).round().astype(int)
    assert (img[pts[:, 1], pts[:, 0]] > 0.5).mean() > 0.99
    assert max(b.thickness.max() for b in sk.branches) > 10  # the main channel is wide


def test_a_bool_mask_traces_like_its_float_copy():
    mask = Y_SHAPE.mask() > 0.5
    assert mask.dtype == np.bool_
    a, b = trace(mask, kind="mask"), trace(mask.astype(np.float32), kind="mask")
    assert [br.points.tolist() for br in a.branches] == [br.points.tolist() for br in b.branches]


@pytest.mark.parametrize("size", [(1, 50), (50, 1), (2, 40)])
def test_images_thinner_than_three_pixels_are_refused_in_one_line(size):
    # Before: numpy's "Shape of array too small to calculate a numerical gradient".
    img = np.random.default_rng(0).random(size).astype(np.float32)
    with pytest.raises(ValueError, match=r"^image: nothing to trace in a \d+x\d+ image; it needs at least 3x3 pixels$"):
        trace(img, kind="dark")


def test_a_lake_is_not_traced_as_a_branch() -> None:
    import cv2

    mask = np.zeros((200, 300), np.uint8)
    cv2.line(mask, (10, 100), (180, 100), 1, thickness=7)  # a channel ...
    cv2.line(mask, (90, 100), (90, 190), 1, thickness=5)  # ... with a tributary
    cv2.circle(mask, (230, 100), 60, 1, -1)  # ... flowing into a lake
    lake = np.zeros_like(mask)
    cv2.circle(lake, (230, 100), 20, 1, -1)  # its middle, where the radius is 40-60 px
    for blob, inside in ((None, True), (8.0, False)):
        sk = trace(mask, kind="mask", blob=blob)
        pts = np.concatenate([b.points for b in sk.branches])
        hit = lake[np.rint(pts[:, 1]).astype(int), np.rint(pts[:, 0]).astype(int)].any()
        assert bool(hit) is inside
        assert sk.total_length() > 150  # the channels stay
    with pytest.raises(ValueError, match="^blob:"):
        trace(mask, kind="mask", blob=0.5)


def test_a_blob_is_not_a_branch_but_a_short_thin_branch_is() -> None:
    import cv2

    mask = np.zeros((200, 300), np.uint8)
    cv2.line(mask, (10, 150), (290, 150), 1, thickness=5)  # a long channel
    cv2.line(mask, (200, 150), (200, 120), 1, thickness=3)  # a short, thin tributary: kept
    cv2.ellipse(mask, (150, 60), (50, 30), 0, 0, 360, 1, -1)  # a pond: axis ~64 px, radius 30
    sk = trace(mask, kind="mask")
    pts = np.concatenate([b.points for b in sk.branches])
    assert pts[:, 1].min() > 100  # nothing in the pond
    assert len(sk.branches) == 2 and sk.branches[1].parent is not None
    # a larger spur factor drops the tributary too; 0 keeps the pond
    assert len(trace(mask, kind="mask", spur=12.0).branches) == 1
    kept = trace(mask, kind="mask", spur=0.0)
    assert np.concatenate([b.points for b in kept.branches])[:, 1].min() < 100


def test_a_smoothing_wider_than_any_branch_is_cut_to_the_branch():
    # Before: smooth=1e9 asked SciPy for a kernel of 8e9 taps (a MemoryError traceback).
    img = np.full((96, 128), 0.8, np.float32)
    cv2.line(img, (5, 90), (70, 40), 0.1, 5)
    cv2.line(img, (70, 40), (125, 5), 0.1, 4)
    sk = trace(img, kind="dark", sigmas=(1.5, 2.5), smooth=1e9)
    assert sk.branches and all(np.isfinite(b.points).all() and np.isfinite(b.thickness).all() for b in sk.branches)
    # the widest Gaussian leaves each branch about as thick as its mean along it
    for b in sk.branches:
        assert np.ptp(b.thickness) < 0.25 * np.mean(b.thickness)
