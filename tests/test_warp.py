"""phloem.warp: mean value coordinates against an independent numpy implementation of Hormann &
Floater (2006) (atan2 angles), their exact values on the polygon, and the image warps they define
(identity, integer translation, scaling, the float64 map, the §5.2 combination); errors."""

from __future__ import annotations

import numpy as np
import pytest

from phloem.warp import mvc, mvc_combine, mvc_weights


def star(n: int = 5, cx: float = 20.0, cy: float = 15.0, r1: float = 10.0, r2: float = 4.0) -> np.ndarray:
    a = np.pi * np.arange(2 * n) / n
    r = np.where(np.arange(2 * n) % 2 == 0, r1, r2)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


L_SHAPE = np.array([(2, 2), (12, 2), (12, 6), (6, 6), (6, 14), (2, 14)], float)
HEXAGON = np.array([(10 + 7 * np.cos(t), 9 + 5 * np.sin(t)) for t in np.linspace(0, 2 * np.pi, 6, endpoint=False)])
POLYGONS = {
    "star": star(),
    "star_clockwise": star(7)[::-1].copy(),
    "l_shape": L_SHAPE,
    "hexagon": HEXAGON,
}


def hf_numpy(polygon: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Hormann & Floater 2006, Eq. 6, with the angles from atan2 (off the polygon only)."""
    s = polygon[None, :, :] - p[:, None, :]  # (P, N, 2)
    r = np.hypot(s[..., 0], s[..., 1])
    sn = np.roll(s, -1, axis=1)
    alpha = np.arctan2(s[..., 0] * sn[..., 1] - s[..., 1] * sn[..., 0], (s * sn).sum(-1))
    t = np.tan(alpha / 2)
    w = (np.roll(t, 1, axis=1) + t) / r
    return w / w.sum(axis=1, keepdims=True)


def random_points(polygon: np.ndarray, n: int, seed: int) -> np.ndarray:
    lo, hi = polygon.min(0) - 8, polygon.max(0) + 8
    return np.random.default_rng(seed).uniform(lo, hi, size=(n, 2))


@pytest.mark.parametrize("name", list(POLYGONS))
def test_weights_match_an_independent_implementation(name):
    poly = POLYGONS[name]
    pts = random_points(poly, 2000, 1)
    w = mvc_weights(poly, pts)
    ref = hf_numpy(poly, pts)
    assert w.shape == (2000, len(poly)) and w.dtype == np.float64
    np.testing.assert_allclose(w, ref, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", list(POLYGONS))
def test_weights_sum_to_one_and_reproduce_linear_functions(name):
    poly = POLYGONS[name]
    pts = random_points(poly, 3000, 2)
    w = mvc_weights(poly, pts)
    np.testing.assert_allclose(w.sum(1), 1.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(w @ poly, pts, rtol=0, atol=1e-9)
    # Any affine function of the vertices, not just the coordinates.
    f = 0.3 * poly[:, 0] - 1.7 * poly[:, 1] + 4.0
    np.testing.assert_allclose(w @ f, 0.3 * pts[:, 0] - 1.7 * pts[:, 1] + 4.0, rtol=0, atol=1e-9)


def test_weights_outside_and_inside_a_concave_polygon_have_expected_signs():
    inside_convex = mvc_weights(HEXAGON, [(10.0, 9.0), (12.5, 8.0)])
    assert (inside_convex > 0).all()
    outside = mvc_weights(L_SHAPE, [(30.0, 30.0)])
    assert (outside < 0).any()  # far outside some coordinates are negative


def test_points_on_vertices_and_edges_interpolate_exactly():
    w = mvc_weights(L_SHAPE, L_SHAPE)
    assert np.array_equal(w, np.eye(6))
    on_edges = np.array([(6.0, 8.0), (2.0, 5.0), (9.0, 2.0), (12.0, 3.0)])
    w = mvc_weights(L_SHAPE, on_edges)
    expected = np.zeros((4, 6))
    expected[0, 3], expected[0, 4] = 0.75, 0.25  # on edge 3-4
    expected[1, 5], expected[1, 0] = 0.25, 0.75  # on the closing edge 5-0
    expected[2, 0], expected[2, 1] = 0.3, 0.7
    expected[3, 1], expected[3, 2] = 0.75, 0.25
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(w @ L_SHAPE, on_edges, rtol=0, atol=1e-14)


def test_weights_are_continuous_towards_an_edge():
    near = mvc_weights(L_SHAPE, [(6.0 + 1e-7, 8.0), (6.0 - 1e-7, 8.0)])
    on = mvc_weights(L_SHAPE, [(6.0, 8.0)])
    np.testing.assert_allclose(near, np.repeat(on, 2, 0), atol=1e-5)


# --- warps ----------------------------------------------------------------------------------

CROWN = np.array(
    [
        (32 + r * np.cos(t), 30 + 0.9 * r * np.sin(t))
        for t, r in zip(
            np.linspace(0, 2 * np.pi, 40, endpoint=False),
            20 + 5 * np.sin(5 * np.linspace(0, 2 * np.pi, 40, endpoint=False)),
        )
    ]
)


@pytest.fixture
def rgba() -> np.ndarray:
    rng = np.random.default_rng(3)
    img = rng.random((60, 64, 4), dtype=np.float32)
    img[..., 3] = 1.0
    return img


def test_identical_contours_return_the_source(rgba):
    out = mvc(rgba, CROWN, CROWN)
    assert out.shape == rgba.shape and out.dtype == np.float32
    assert np.array_equal(out, rgba)


def test_grayscale_images_stay_2d(rgba):
    gray = rgba[..., 0]
    out = mvc(gray, CROWN, CROWN, (30, 40))
    assert out.shape == (30, 40) and np.array_equal(out, gray[:30, :40])


def test_integer_translation_translates_the_image(rgba):
    dy, dx = 3, -5
    out = mvc(rgba, CROWN, CROWN + (dx, dy))
    # out[y, x] = rgba[y - dy, x - dx] wherever that is inside the source, transparent elsewhere.
    np.testing.assert_allclose(out[dy:, : dx or None], rgba[:-dy, -dx:], rtol=0, atol=1e-4)
    assert (out[:dy] == 0).all() and (out[:, dx:] == 0).all()


def test_scaled_contour_scales_the_image(rgba):
    # Target = source / 2: pixel (y, x) of the result shows source pixel (2y, 2x).
    out = mvc(rgba, CROWN, CROWN / 2, (30, 32))
    np.testing.assert_allclose(out, rgba[::2, ::2], rtol=0, atol=1e-4)


def test_the_warp_follows_the_float64_map():
    # A source whose values are its own pixel coordinates: bilinear sampling is exact on it, so
    # the result shows where each pixel was sampled.
    h, w = 120, 130
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    coords = np.stack([xx, yy, np.ones_like(xx)], axis=-1)
    target = star(6, 45, 40, 30, 12)
    rng = np.random.default_rng(4)
    source = target * 1.25 + (8, 5) + rng.uniform(-3, 3, target.shape)
    out = mvc(coords, source, target, (90, 95))
    py, px = np.mgrid[:90, :95]
    pts = np.stack([px.ravel(), py.ravel()], axis=1).astype(float)
    q = mvc_weights(target, pts) @ source
    ok = (q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
    assert ok.mean() > 0.9
    got = out.reshape(-1, 3)[:, :2]
    err = np.abs(got[ok] - q[ok]).max()
    assert err < 2e-3, err
    assert (out.reshape(-1, 3)[~ok & ((q < -0.5).any(1) | (q[:, 0] >= w - 0.5) | (q[:, 1] >= h - 0.5))] == 0).all()


def test_same_result_for_any_thread_count(rgba):
    target = CROWN * 1.1 + (-2, 1)
    one = mvc(rgba, CROWN, target, (70, 70), threads=1)
    two = mvc(rgba, CROWN, target, (70, 70), threads=2)
    assert np.array_equal(one, two)
    c1 = mvc_combine([rgba, rgba[::-1].copy()], [CROWN, CROWN], target, [0.3, 0.7], 70, threads=1)
    c2 = mvc_combine([rgba, rgba[::-1].copy()], [CROWN, CROWN], target, [0.3, 0.7], 70, threads=2)
    assert np.array_equal(c1, c2)


def _constant(shape, colour, alpha):
    img = np.empty((*shape, 4), np.float32)
    img[..., :3] = colour
    img[..., 3] = alpha
    return img


def test_combine_takes_max_alpha_and_a_convex_colour_mix():
    a = _constant((40, 40), (1.0, 0.0, 0.0), 0.4)
    b = _constant((40, 40), (0.0, 0.0, 1.0), 0.9)
    b[:, :20, 3] = 0.0  # b transparent on its left half
    c = np.array([(5, 5), (34, 5), (34, 34), (5, 34)], float)
    out = mvc_combine([a, b], [c, c], c, [0.25, 0.75], (40, 40))
    # Right half: both opaque, colour 0.25 a + 0.75 b, alpha max.
    np.testing.assert_allclose(out[:, 21:], np.broadcast_to([0.25, 0.0, 0.75, 0.9], (40, 19, 4)), atol=1e-6)
    # Left half: only a counts, whatever its weight.
    np.testing.assert_allclose(out[:, :19], np.broadcast_to([1.0, 0.0, 0.0, 0.4], (40, 19, 4)), atol=1e-6)
    # A zero weight on the only opaque source: its own colour (the plain mean of the opaque ones).
    out = mvc_combine([a, b], [c, c], c, [0.0, 1.0], (40, 40))
    np.testing.assert_allclose(out[:, :19], np.broadcast_to([1.0, 0.0, 0.0, 0.4], (40, 19, 4)), atol=1e-6)


def test_combine_matches_the_separate_warps(rgba):
    b = np.random.default_rng(5).random((50, 55, 4), dtype=np.float32)
    b[..., 3] = (b[..., 3] > 0.3) * b[..., 3]
    cb = CROWN * 0.8 + (2, 3)
    target = CROWN * 1.05
    wa, wb = mvc(rgba, CROWN, target, (64, 70)), mvc(b, cb, target, (64, 70))
    out = mvc_combine([rgba, b], [CROWN, cb], target, [0.6, 0.4], (64, 70))
    on_a, on_b = wa[..., 3] > 0, wb[..., 3] > 0
    wsum = 0.6 * on_a + 0.4 * on_b
    colour = (0.6 * on_a[..., None] * wa[..., :3] + 0.4 * on_b[..., None] * wb[..., :3]) / np.maximum(wsum, 1e-12)[
        ..., None
    ]
    expect = np.concatenate([colour, np.maximum(wa[..., 3:], wb[..., 3:])], axis=-1)
    expect[~(on_a | on_b)] = 0
    np.testing.assert_allclose(out, expect, atol=1e-5)
    assert (~(on_a | on_b)).any() and (on_a & ~on_b).any()


# --- errors ---------------------------------------------------------------------------------

SQ = [(0, 0), (4, 0), (4, 4), (0, 4)]


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"polygon": [(0, 0), (1, 0)]}, ValueError, "^polygon: expected at least 3 points"),
        ({"polygon": [(0, 0, 0), (1, 0, 0), (0, 1, 0)]}, ValueError, r"^polygon: expected shape \(N, 2\)"),
        ({"polygon": [(0, 0), (np.nan, 0), (0, 1)]}, ValueError, "^polygon: expected finite"),
        ({"polygon": [(0, 0), (1, 0), (1, 0), (0, 1)]}, ValueError, "^polygon: points 1 and 2 are equal"),
        ({"polygon": [(0, 0), (1, 0), (1, 1), (0, 0)]}, ValueError, "^polygon: points 3 and 0 are equal"),
        ({"polygon": [(0, 0), (1, 1), (2, 2), (3, 3)]}, ValueError, "^polygon: expected a polygon with non-zero area"),
        ({"polygon": ["a", "b", "c"]}, TypeError, "^polygon: expected real"),
        ({"points": [(0, np.inf)]}, ValueError, "^points: expected finite"),
        ({"points": [1.0, 2.0]}, ValueError, r"^points: expected shape \(N, 2\)"),
        ({"threads": 0}, ValueError, "^threads"),
    ],
)
def test_weights_errors_name_the_argument(kwargs, exc, match):
    args = {"polygon": SQ, "points": [(1.0, 1.0)]} | kwargs
    with pytest.raises(exc, match=match):
        mvc_weights(args.pop("polygon"), args.pop("points"), **args)


IMG = np.zeros((8, 8, 4), np.float32)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((IMG, SQ[:2], SQ), "^source_contour: expected at least 3 points"),
        ((IMG, SQ, SQ[:3]), "^source_contour: expected 3 points like target_contour, got 4"),
        ((IMG, SQ, [(0, 0), (1, 1), (2, 2), (3, 3)]), "^target_contour: expected a polygon with non-zero area"),
        ((IMG, [(0, 0), (1, 1), (2, 2), (3, 3)], SQ), "^source_contour: expected a polygon with non-zero area"),
        ((IMG, [(0, 0), (1, 1), (1, 1), (3, 0)], SQ), "^source_contour: points 1 and 2 are equal"),
        ((IMG, SQ, [(0, 0), (1, np.nan), (1, 1), (3, 0)]), "^target_contour: expected finite"),
        ((np.zeros((2, 2, 2, 2)), SQ, SQ), r"^image: expected shape"),
        ((IMG[:, :, :0], SQ, SQ), r"^image: expected a non-empty"),
        ((np.full((8, 8), np.nan), SQ, SQ), r"^image: expected finite"),
    ],
)
def test_mvc_errors_name_the_argument(args, match):
    with pytest.raises(ValueError, match=match):
        mvc(*args)


def test_size_errors():
    with pytest.raises(ValueError, match=r"^size\[0\]"):
        mvc(IMG, SQ, SQ, (0, 4))
    with pytest.raises(TypeError, match="^size"):
        mvc(IMG, SQ, SQ, "big")


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"weights": [0.5, 0.6]}, ValueError, "^weights: expected weights summing to 1"),
        ({"weights": [1.5, -0.5]}, ValueError, "^weights: expected finite non-negative"),
        ({"weights": [1.0]}, ValueError, "^weights: expected 2 weights"),
        ({"weights": [np.nan, 1.0]}, ValueError, "^weights: expected finite"),
        ({"images": []}, TypeError, "^images"),
        ({"images": [IMG, IMG[..., :3]]}, ValueError, r"^images\[1\]: expected 4 channels"),
        ({"images": [IMG[..., 0], IMG[..., 0]]}, ValueError, r"^images: expected colour channels and a last alpha"),
        ({"source_contours": [SQ]}, ValueError, r"^source_contours: expected one contour per image \(2\), got 1"),
        (
            {"source_contours": [SQ, SQ[:3]]},
            ValueError,
            r"^source_contours\[1\]: expected 4 points like target_contour",
        ),
        ({"target_contour": SQ[:2]}, ValueError, "^target_contour: expected at least 3"),
    ],
)
def test_combine_errors_name_the_argument(kwargs, exc, match):
    args = {
        "images": [IMG, IMG],
        "source_contours": [SQ, SQ],
        "target_contour": SQ,
        "weights": [0.5, 0.5],
        "size": 8,
    } | kwargs
    with pytest.raises(exc, match=match):
        mvc_combine(**args)


def test_core_checks_hold_without_the_python_layer():
    from phloem import _core

    sq = np.array(SQ, float)
    with pytest.raises(ValueError, match="^target_contour: expected at least 3"):
        _core.mvc_warp([IMG], [sq], sq[:2].copy(), (8, 8), region=None, threads=None)
    with pytest.raises(ValueError, match="^source_contours: expected 4 points"):
        _core.mvc_warp([IMG], [sq[:3].copy()], sq, (8, 8), region=None, threads=None)
    with pytest.raises(ValueError, match="^weights: expected weights summing to 1"):
        _core.mvc_combine([IMG, IMG], [sq, sq], sq, np.array([0.2, 0.2]), (8, 8), region=None, threads=None)
    with pytest.raises(ValueError, match="^sources: expected at least one"):
        _core.mvc_warp([], [], sq, (8, 8), region=None, threads=None)


def test_region_computes_only_its_pixels():
    rng = np.random.default_rng(7)
    img = rng.random((40, 50, 4)).astype(np.float32)
    src = [(5, 5), (44, 6), (40, 35), (25, 20), (6, 33)]
    dst = [(7, 4), (45, 8), (38, 36), (24, 23), (4, 30)]
    region = rng.random((40, 50)) < 0.4
    full = mvc(img, src, dst)
    part = mvc(img, src, dst, region=region)
    assert np.array_equal(part[region], full[region]) and not part[~region].any()
    both = mvc_combine([img, img[::-1].copy()], [src, src], dst, [0.5, 0.5], (40, 50))
    both_part = mvc_combine([img, img[::-1].copy()], [src, src], dst, [0.5, 0.5], (40, 50), region=region)
    assert np.array_equal(both_part[region], both[region]) and not both_part[~region].any()
    with pytest.raises(ValueError, match=r"^region: expected shape \(40, 50\)"):
        mvc(img, src, dst, region=np.ones((4, 5), bool))
