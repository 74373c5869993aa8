"""phloem.blend: Poisson blending checked against an independently assembled sparse system and
closed-form solutions; smooth field interpolation against a sparse direct solve; errors."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import phloem
from phloem.blend import interpolate_field, seamless

NEIGHBOURS = ((-1, 0), (0, -1), (0, 1), (1, 0))


def _disk(n: int, r: float, cy: float | None = None, cx: float | None = None) -> np.ndarray:
    yy, xx = np.mgrid[:n, :n]
    cy = (n - 1) / 2 if cy is None else cy
    cx = (n - 1) / 2 if cx is None else cx
    return (yy - cy) ** 2 + (xx - cx) ** 2 < r * r


def poisson_system(src, dst, mask, offset, mode="normal", fixed=None, labels=None):
    """Pérez Eq. 7 as the docstring of seamless states it, built pixel by pixel with scipy
    (with ``labels``: no source gradient between pixels of different labels).

    Returns A, b (n × C), and the (row, col) destination pixels of the unknowns.
    """
    src = np.asarray(src, np.float64).reshape(src.shape[0], src.shape[1], -1)
    dst = np.asarray(dst, np.float64).reshape(dst.shape[0], dst.shape[1], -1)
    H, W, _ = dst.shape
    h, w = mask.shape
    oy, ox = offset
    kind = np.zeros((H, W), np.int8)  # 0 Dirichlet dst, 1 fixed (Dirichlet src), 2 unknown
    sy, sx = np.nonzero(mask)
    y, x = sy + oy, sx + ox
    inside = (y >= 0) & (y < H) & (x >= 0) & (x < W)
    kind[y[inside], x[inside]] = 2
    if fixed is not None:
        fy, fx = np.nonzero(fixed)
        fy, fx = fy + oy, fx + ox
        ok = (fy >= 0) & (fy < H) & (fx >= 0) & (fx < W)
        kind[fy[ok], fx[ok]] = 1

    def g(yy, xx):  # source with its edge replicated, in destination coordinates
        return src[np.clip(yy - oy, 0, h - 1), np.clip(xx - ox, 0, w - 1)]

    def lab(yy, xx):  # the labels, read like the source
        return 0 if labels is None else labels[np.clip(yy - oy, 0, h - 1), np.clip(xx - ox, 0, w - 1)]

    uy, ux = np.nonzero(kind == 2)
    n = len(uy)
    index = -np.ones((H, W), int)
    index[uy, ux] = np.arange(n)
    rows, cols = [], []
    diag = np.zeros(n)
    b = np.zeros((n, src.shape[2]))
    for dy, dx in NEIGHBOURS:
        qy, qx = uy + dy, ux + dx
        ok = (qy >= 0) & (qy < H) & (qx >= 0) & (qx < W)
        p = np.nonzero(ok)[0]
        qy, qx = qy[ok], qx[ok]
        diag[p] += 1
        gs = g(uy[p], ux[p]) - g(qy, qx)
        gs = np.where(np.asarray(lab(uy[p], ux[p]) == lab(qy, qx))[..., None], gs, 0.0)
        if mode == "mixed":
            ds = dst[uy[p], ux[p]] - dst[qy, qx]
            v = np.where(np.abs(ds) > np.abs(gs), ds, gs)
        else:
            v = gs
        b[p] += v
        unk = kind[qy, qx] == 2
        rows.append(p[unk])
        cols.append(index[qy[unk], qx[unk]])
        dval = np.where((kind[qy, qx] == 1)[:, None], g(qy, qx), dst[qy, qx])
        b[p[~unk]] += dval[~unk]
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    A = sp.csr_matrix((-np.ones(len(r)), (r, c)), shape=(n, n)) + sp.diags(diag)
    return A.tocsr(), b, (uy, ux)


def relative_residual(out, src, dst, mask, offset, **kw):
    A, b, (uy, ux) = poisson_system(src, dst, mask, offset, **kw)
    f = np.asarray(out, np.float64).reshape(out.shape[0], out.shape[1], -1)[uy, ux]
    return float(max(np.linalg.norm(b[:, c] - A @ f[:, c]) / np.linalg.norm(b[:, c]) for c in range(b.shape[1])))


@pytest.fixture(scope="module")
def scene(bark, water):
    return np.ascontiguousarray(bark[:90, :90]), np.ascontiguousarray(water[:160, :170])


def _ring(n: int) -> np.ndarray:
    return _disk(n, 0.45 * n) & ~_disk(n, 0.2 * n)


@pytest.mark.parametrize("mode", ["normal", "mixed"])
@pytest.mark.parametrize(
    "shape,offset",
    [("disk", (30, 40)), ("ring", (35, 20)), ("touches_border", (-20, 100)), ("two_parts", (10, 10))],
)
def test_residual_of_the_returned_image_is_small(scene, mode, shape, offset):
    src, dst = scene
    n = src.shape[0]
    mask = {
        "disk": _disk(n, 40),
        "ring": _ring(n),
        # Crosses the top and right borders of dst: clipped, Neumann there.
        "touches_border": _disk(n, 44),
        "two_parts": _disk(n, 15, 20, 20) | _disk(n, 20, 60, 62),
    }[shape]
    info = seamless(src, dst, mask, offset, mode=mode, full_output=True)
    out = info.image
    assert info.residual < 1e-6 and 1 <= info.iterations <= 20, info
    assert relative_residual(out, src, dst, mask, offset, mode=mode) < 1e-4
    # Outside the region dst is untouched.
    _A, _b, (uy, ux) = poisson_system(src, dst, mask, offset)
    outside = np.ones(dst.shape[:2], bool)
    outside[uy, ux] = False
    assert np.array_equal(out[outside], dst[outside])


def test_residual_check_catches_a_wrong_solution(scene):
    """The independent residual is sensitive: perturbing the output by 1e-3 fails it."""
    src, dst = scene
    mask = _disk(90, 40)
    out = seamless(src, dst, mask, (30, 40))
    out[70, 80] += 1e-3
    assert relative_residual(out, src, dst, mask, (30, 40)) > 1e-4


def _quadratic_scene(n=64, dn=100, off=(18, 20)):
    yy, xx = np.mgrid[:dn, :dn].astype(np.float64)
    s_of = lambda y, x: 0.3 + 1e-4 * (y**2 + 2 * x**2) + 0.05 * np.sin(0.3 * x)  # noqa: E731
    harmonic = 0.1 + 2e-4 * (yy - 40) * (xx - 50) - 1e-4 * ((xx - 50) ** 2 - (yy - 40) ** 2)
    syy, sxx = np.mgrid[:n, :n].astype(np.float64)
    src = s_of(syy, sxx)
    # dst = src + harmonic around the region, noise inside it (never read in normal mode).
    dst = s_of(yy - off[0], xx - off[1]) + harmonic
    return src, dst, harmonic


def test_analytic_solution_dirichlet():
    """src quadratic, dst = src + H on the boundary with H discrete-harmonic: f = src + H."""
    n, off = 64, (18, 20)
    src, dst, _harmonic = _quadratic_scene(n, 100, off)
    mask = _ring(n)  # a hole: dst values inside it are Dirichlet too
    inner = np.zeros(dst.shape, bool)
    inner[off[0] : off[0] + n, off[1] : off[1] + n] = mask
    noisy = dst.copy()
    noisy[inner] = np.random.default_rng(0).random(inner.sum())
    out = seamless(src.astype(np.float32), noisy.astype(np.float32), mask, off, tol=1e-9)
    np.testing.assert_allclose(out[inner], dst[inner], atol=2e-5)


def test_analytic_solution_neumann_at_the_destination_border():
    """A region across dst's top edge: with H linear in the column only, H has zero normal
    derivative there, so f = src + H still."""
    n, dn, off = 40, 60, (-10, 8)
    yy, xx = np.mgrid[:dn, :dn].astype(np.float64)
    syy, sxx = np.mgrid[:n, :n].astype(np.float64)
    src = 0.2 + 1e-3 * (syy - 5) ** 2 + 5e-4 * sxx**2
    dst = 0.2 + 1e-3 * (yy - off[0] - 5) ** 2 + 5e-4 * (xx - off[1]) ** 2 + (0.1 + 3e-3 * xx)
    mask = _disk(n, 18)
    inner = np.zeros(dst.shape, bool)
    sy, sx = np.nonzero(mask)
    ok = sy + off[0] >= 0
    inner[sy[ok] + off[0], sx[ok] + off[1]] = True
    assert inner[0].any(), "the region must reach the top border"
    noisy = dst.copy()
    noisy[inner] = 0.0
    out = seamless(src.astype(np.float32), noisy.astype(np.float32), mask, off, tol=1e-9)
    np.testing.assert_allclose(out[inner], dst[inner], atol=2e-5)


def test_self_blend_changes_nothing(water):
    dst = np.ascontiguousarray(water[:120, :130])
    src = dst[20:100, 30:110].copy()
    mask = _ring(80)
    for mode in ("normal", "mixed"):
        info = seamless(src, dst, mask, (20, 30), mode=mode, full_output=True)
        out = info.image
        assert np.array_equal(out, dst)
        assert info.iterations == 0


def test_fixed_pixels_keep_the_source_exactly(scene):
    src, dst = scene
    mask = _disk(90, 40)
    fixed = mask & (np.add.outer(np.arange(90), np.arange(90)) % 7 == 0)
    fixed[:, :45] &= False
    off = (30, 40)
    out = seamless(src, dst, mask, off, fixed=fixed)
    fy, fx = np.nonzero(fixed)
    assert np.array_equal(out[fy + off[0], fx + off[1]], src[fy, fx])
    assert relative_residual(out, src, dst, mask, off, fixed=fixed) < 1e-4
    # Without the constraint the colours drift towards dst there.
    free = seamless(src, dst, mask, off)
    assert np.abs(free[fy + off[0], fx + off[1]] - src[fy, fx]).max() > 1e-2


@pytest.mark.parametrize("mode", ["normal", "mixed"])
def test_labels_cut_the_guidance_between_labels(scene, mode):
    # Three labels in stripes, a fourth around the region: the system with the source gradient
    # zeroed across labels, assembled independently, is what the engine solves.
    src, dst = scene
    mask = _disk(90, 40)
    labels = np.where(mask, np.arange(90)[None, :] // 30, -1).astype(np.int32)
    out = seamless(src, dst, mask, (30, 40), mode=mode, labels=labels, tol=1e-8)
    assert relative_residual(out, src, dst, mask, (30, 40), mode=mode, labels=labels) < 1e-6
    # and it is not the plain paste
    assert np.abs(out - seamless(src, dst, mask, (30, 40), mode=mode, tol=1e-8)).max() > 1e-2
    # one label everywhere is the plain paste, bit for bit
    one = seamless(src, dst, mask, (30, 40), mode=mode, labels=np.zeros((90, 90), np.int32))
    assert np.array_equal(one, seamless(src, dst, mask, (30, 40), mode=mode))


def test_labels_spread_the_level_steps_between_pieces():
    # Two flat pieces at different levels, labelled apart and apart from the rest: the guidance
    # is zero everywhere, so the paste takes the destination's level (a harmonic, here flat).
    src = np.zeros((40, 40), np.float32)
    src[:, 20:] = 0.8
    labels = (np.arange(40)[None, :] >= 20).astype(np.int32) * np.ones((40, 1), np.int32) + 1
    mask = np.zeros((40, 40), bool)
    mask[5:35, 5:35] = True
    labels[~mask] = 0
    out = seamless(src, np.full((40, 40), 0.3, np.float32), mask, (0, 0), labels=labels, tol=1e-8)
    assert np.abs(out - 0.3).max() < 1e-5


def test_mixed_mode_takes_the_stronger_gradient(water):
    dst = np.ascontiguousarray(water[:100, :100])
    flat = np.full((60, 60, 3), 0.5, np.float32)
    mask = _disk(60, 27)
    # A flat source has no gradient: mixed guidance is all dst's, and the solution is dst.
    mixed = seamless(flat, dst, mask, (20, 20), mode="mixed", tol=1e-9)
    np.testing.assert_allclose(mixed, dst, atol=1e-4)
    # Normal guidance is zero: a membrane (discrete-harmonic inside the region), unlike dst.
    normal = seamless(flat, dst, mask, (20, 20), tol=1e-9)
    inner = np.zeros((100, 100), bool)
    inner[20:80, 20:80] = mask

    def laplacian(f):
        return 4 * f[1:-1, 1:-1] - f[:-2, 1:-1] - f[2:, 1:-1] - f[1:-1, :-2] - f[1:-1, 2:]

    inside = inner[1:-1, 1:-1]
    assert np.abs(laplacian(normal.astype(np.float64)))[inside].max() < 1e-4
    assert np.abs(laplacian(dst.astype(np.float64)))[inside].max() > 0.1


def test_whole_destination_keeps_the_source_mean(bark):
    """No Dirichlet pixel at all: the solution keeps the mean of the source (documented)."""
    src = np.ascontiguousarray(bark[:50, :60])
    dst = np.zeros_like(src)
    info = seamless(src, dst, np.ones((50, 60), bool), (0, 0), full_output=True)
    out = info.image
    np.testing.assert_allclose(out, src, atol=1e-4)
    assert info.residual < 1e-6


def test_gray_and_many_channels(scene):
    src, dst = scene
    mask = _disk(90, 40)
    gray = seamless(src[..., 0], dst[..., 0], mask, (30, 40))
    assert gray.shape == dst.shape[:2]
    assert relative_residual(gray[..., None], src[..., :1], dst[..., :1], mask, (30, 40)) < 1e-4
    five = np.concatenate([src, src[..., :2] * 0.5], axis=2)
    dfive = np.concatenate([dst, dst[..., :2]], axis=2)
    out = seamless(five, dfive, mask, (30, 40))
    # Channels are independent (a group may iterate once more for a slower channel).
    np.testing.assert_allclose(out[..., :3], seamless(src, dst, mask, (30, 40)), atol=1e-5)
    assert relative_residual(out, five, dfive, mask, (30, 40)) < 1e-4


def test_integer_images_are_scaled(scene):
    src, dst = scene
    s8 = (src * 255).round().astype(np.uint8)
    d8 = (dst * 255).round().astype(np.uint8)
    out = seamless(s8, d8, _disk(90, 40), (30, 40))
    assert out.dtype == np.float32 and out.max() <= 1.5


def test_same_result_for_any_thread_count(bark, water):
    src = np.ascontiguousarray(bark[:200, :200])
    dst = np.ascontiguousarray(np.concatenate([water[:260, :260]] * 1, axis=0))
    mask = _disk(200, 95)
    one = seamless(src, dst, mask, (30, 30), threads=1)
    two = seamless(src, dst, mask, (30, 30), threads=2)
    assert np.array_equal(one, two)
    f1 = interpolate_field(_disk(100, 48), [(50, 50), (20, 40)], [(1.0, 2.0), (0.0, -1.0)], threads=1)
    f2 = interpolate_field(_disk(100, 48), [(50, 50), (20, 40)], [(1.0, 2.0), (0.0, -1.0)], threads=2)
    assert np.array_equal(f1, f2, equal_nan=True)


# ---------------------------------------------------------------------------------------------
# interpolate_field


def field_reference(region, points, values):
    """argmin Σ‖L d‖² with d fixed at points, by a sparse direct solve (L: graph Laplacian)."""
    H, W = region.shape
    ry, rx = np.nonzero(region)
    n = len(ry)
    index = -np.ones((H, W), int)
    index[ry, rx] = np.arange(n)
    rows, cols = [], []
    for dy, dx in NEIGHBOURS:
        qy, qx = ry + dy, rx + dx
        ok = (qy >= 0) & (qy < H) & (qx >= 0) & (qx < W)
        ok[ok] &= region[qy[ok], qx[ok]]
        rows.append(np.nonzero(ok)[0])
        cols.append(index[qy[ok], qx[ok]])
    r, c = np.concatenate(rows), np.concatenate(cols)
    adj = sp.csr_matrix((np.ones(len(r)), (r, c)), shape=(n, n))
    L = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    B = (L.T @ L).tocsr()
    con = index[points[:, 0], points[:, 1]]
    free = np.setdiff1d(np.arange(n), con)
    d = np.zeros((n, values.shape[1]))
    d[con] = values
    if len(free):
        rhs = -B[free][:, con] @ values
        d[free] = spla.spsolve(B[free][:, free].tocsc(), rhs).reshape(len(free), -1)
    out = np.full((H, W, values.shape[1]), np.nan)
    out[ry, rx] = d
    return out, L


def _random_region(rng, h, w):
    import cv2

    noise = cv2.GaussianBlur(rng.random((h, w)), (0, 0), 2.0)
    return noise > np.quantile(noise, 0.45)


def _components(region):
    import cv2

    n, labels = cv2.connectedComponents(region.astype(np.uint8), connectivity=4)
    return n, labels


@pytest.mark.parametrize("seed", range(6))
def test_field_matches_a_sparse_direct_solve(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(12, 40, size=2)
    region = _random_region(rng, h, w)
    if seed == 0:  # a one-pixel-wide strip with a bend, and a separate blob
        region = np.zeros((30, 40), bool)
        region[5, 3:35] = True
        region[5:25, 34] = True
        region[15:25, 5:15] = True
    n, labels = _components(region)
    points = []
    for k in range(1, n):  # every 4-connected part gets one to three points
        ys, xs = np.nonzero(labels == k)
        for i in rng.choice(len(ys), size=min(len(ys), int(rng.integers(1, 4))), replace=False):
            points.append((ys[i], xs[i]))
    points = np.array(points)
    values = rng.normal(size=(len(points), 2))
    info = interpolate_field(region, points, values, full_output=True)
    ours = info.field
    ref, _L = field_reference(region, points, values)
    assert np.array_equal(np.isnan(ours), np.isnan(ref))
    assert np.array_equal(ours[points[:, 0], points[:, 1]], values.astype(np.float32))
    np.testing.assert_allclose(ours[region], ref[region], atol=1e-4 * (1 + np.abs(values).max()))
    assert info.residual <= 1e-10


def test_field_is_smooth():
    region = _disk(60, 28)
    # One constraint: a constant field (zero energy).
    d = interpolate_field(region, [(30, 30)], [(0.5, -2.0)])
    np.testing.assert_allclose(d[region], np.broadcast_to([0.5, -2.0], d[region].shape), atol=1e-6)
    # Equal values at two points: constant too.
    d = interpolate_field(region, [(10, 30), (50, 30)], [3.0, 3.0])
    assert d.shape == (60, 60)
    np.testing.assert_allclose(d[region], 3.0, atol=1e-6)
    # Two different values: no overshoot beyond them far from the points, and a smooth field.
    d = interpolate_field(region, [(30, 10), (30, 50)], [0.0, 1.0])
    assert np.nanmin(d) > -0.3 and np.nanmax(d) < 1.3
    lap = d[1:-1, 1:-1] * 4 - d[:-2, 1:-1] - d[2:, 1:-1] - d[1:-1, :-2] - d[1:-1, 2:]
    assert np.nanmax(np.abs(lap)) < 0.05


def test_field_on_a_large_region():
    region = _disk(256, 125)
    pts = np.array([(128, 128), (40, 128), (200, 60), (128, 230)])
    vals = np.array([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.5), (0.2, -0.3)])
    info = interpolate_field(region, pts, vals, tol=1e-8, full_output=True)
    d = info.field
    assert info.residual <= 1e-8
    assert np.array_equal(d[pts[:, 0], pts[:, 1]], vals.astype(np.float32))


# ---------------------------------------------------------------------------------------------
# errors


def test_seamless_errors_name_the_argument(scene):
    src, dst = scene
    mask = _disk(90, 40)
    with pytest.raises(ValueError, match="^mask"):
        seamless(src, dst, mask[:-1], (0, 0))
    with pytest.raises(ValueError, match="^dst"):
        seamless(src, dst[..., :2], mask, (0, 0))
    with pytest.raises(ValueError, match="^mask"):
        seamless(src, dst, np.zeros_like(mask), (0, 0))
    with pytest.raises(ValueError, match="^mask: no pixel"):
        seamless(src, dst, mask, (1000, 0))
    with pytest.raises(ValueError, match="^mask: no pixel"):
        seamless(src, dst, mask, (0, -90))
    with pytest.raises(ValueError, match="^fixed"):
        seamless(src, dst, mask, (0, 0), fixed=~mask)
    with pytest.raises(ValueError, match="^fixed"):
        seamless(src, dst, mask, (0, 0), fixed=mask[:10])
    bad = src.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="^src: expected finite"):
        seamless(bad, dst, mask, (0, 0))
    bad = dst.copy()
    bad[150, 7, 0] = np.inf
    with pytest.raises(ValueError, match=r"^dst: expected finite values, found inf at pixel \(row 150, col 7\)"):
        seamless(src, bad, mask, (0, 0))
    with pytest.raises(TypeError, match="^src"):
        seamless(src.astype(np.complex64), dst, mask, (0, 0))
    with pytest.raises(ValueError, match="^src"):
        seamless(src[None], dst, mask, (0, 0))
    with pytest.raises(ValueError, match="^mode"):
        seamless(src, dst, mask, (0, 0), mode="average")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="^offset"):
        seamless(src, dst, mask, (0.5, 0))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^tol"):
        seamless(src, dst, mask, (0, 0), tol=0.0)
    with pytest.raises(ValueError, match="^threads"):
        seamless(src, dst, mask, (0, 0), threads=0)
    with pytest.raises(ValueError, match="^labels"):
        seamless(src, dst, mask, (0, 0), labels=np.zeros((89, 90), np.int32))
    with pytest.raises(TypeError, match="^labels"):
        seamless(src, dst, mask, (0, 0), labels=np.zeros((90, 90), np.float32))


def test_seamless_warns_when_it_stops_early(scene):
    src, dst = scene
    with pytest.warns(RuntimeWarning, match="max_iterations"):
        seamless(src, dst, _disk(90, 40), (30, 40), tol=1e-12, max_iterations=1)


def test_field_errors_name_the_argument():
    region = _disk(20, 9)
    with pytest.raises(ValueError, match="^points: point 0 = \\(0, 0\\) is not inside the region"):
        interpolate_field(region, [(0, 0)], [1.0])
    with pytest.raises(ValueError, match="^points: point 1 .* outside"):
        interpolate_field(region, [(10, 10), (25, 3)], [1.0, 2.0])
    with pytest.raises(ValueError, match="^points: point 0 .* outside"):
        interpolate_field(region, [(-1, 3)], [1.0])
    two = region | _disk(20, 2, 1, 1)
    with pytest.raises(ValueError, match="^points: the connected part"):
        interpolate_field(two, [(10, 10)], [1.0])
    with pytest.raises(ValueError, match="^values: expected finite"):
        interpolate_field(region, [(10, 10)], [np.nan])
    with pytest.raises(ValueError, match="^values"):
        interpolate_field(region, [(10, 10), (9, 9)], [1.0])
    with pytest.raises(ValueError, match="^values: points 0 and 1"):
        interpolate_field(region, [(10, 10), (10, 10)], [1.0, 2.0])
    interpolate_field(region, [(10, 10), (10, 10)], [1.0, 1.0])  # a repeat with one value is fine
    with pytest.raises(ValueError, match="^region"):
        interpolate_field(np.zeros((5, 5), bool), [(1, 1)], [1.0])
    with pytest.raises(ValueError, match="^region"):
        interpolate_field(region[None], [(1, 1)], [1.0])
    with pytest.raises(ValueError, match="^points"):
        interpolate_field(region, [(1, 1, 1)], [1.0])
    with pytest.raises(TypeError, match="^points"):
        interpolate_field(region, [(10.0, 10.0)], [1.0])
    with pytest.raises(TypeError, match="^values"):
        interpolate_field(region, [(10, 10)], ["a"])


def test_package_exports_blend():
    assert "blend" in phloem.__all__ and phloem.blend.seamless is seamless
