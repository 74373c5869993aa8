"""Texture correction (Assa & Cohen-Or §3, after Fang & Hart 2007): stretched texture comes back at
the source's scale, and nothing outside the distorted region moves."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import _core
from phloem.leaves import correct_texture, distortion
from phloem.leaves.correction import _ROUNDS, checked

PERIOD = 8


def _profile(n: int, a: int, b: int, factor: float, ramp: int = 6) -> np.ndarray:
    """Displacement along one axis whose map ``x ↦ x + d(x)`` has slope ``factor`` on [a, b], 1 away."""
    x = np.arange(n, dtype=np.float64)
    t = np.clip((x - a) / ramp, 0, 1) * np.clip((b - x) / ramp, 0, 1)
    slope = 1 - (1 - factor) * t
    phi = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]))])
    return phi + (n / 2 - phi[n // 2]) - x


def _stripes(h: int, w: int) -> np.ndarray:
    """Opaque RGBA vertical stripes, 4 px green and 4 px yellow."""
    on = (np.sin(2 * np.pi * (np.arange(w) + 0.5) / PERIOD) > 0).astype(np.float32)
    img = np.zeros((h, w, 4), np.float32)
    img[..., 0] = 0.2 + 0.6 * on[None]
    img[..., 1] = 0.5 + 0.3 * on[None]
    img[..., 2] = 0.1
    img[..., 3] = 1.0
    return img


def _period(img: np.ndarray, cols: slice) -> float:
    """Dominant horizontal period of the red channel over ``cols`` (zero-padded FFT, 256 bins)."""
    g = img[:, cols, 0] - img[:, cols, 0].mean(axis=1, keepdims=True)
    spectrum = np.abs(np.fft.rfft(g, n=256, axis=1)).mean(axis=0)
    return 256 / (int(np.argmax(spectrum[1:])) + 1)


def _dot_leaf(n: int = 128) -> np.ndarray:
    """A disc-shaped RGBA leaf with yellow dots of radius 2 every 9 px (jittered) on green."""
    rng = np.random.default_rng(3)
    img = np.zeros((n, n, 4), np.float32)
    img[..., :3] = (0.25, 0.55, 0.15)
    for y in range(4, n, 9):
        for x in range(4, n, 9):
            centre = (x + int(rng.integers(-1, 2)), y + int(rng.integers(-1, 2)))
            cv2.circle(img, centre, 2, (0.8, 0.7, 0.2, 1.0), -1)
    yy, xx = np.mgrid[:n, :n]
    img[..., 3] = (((yy - n / 2) / (n / 2 - 2)) ** 2 + ((xx - n / 2) / (n / 2 - 2)) ** 2 <= 1).astype(np.float32)
    return img


def _dot_areas(img: np.ndarray, box: tuple[slice, slice]) -> list[int]:
    """Pixel areas of the yellow dots wholly inside ``box``."""
    g = (img[box][..., 0] > 0.5).astype(np.uint8)
    _, _, stats, _ = cv2.connectedComponentsWithStats(g, connectivity=8)
    hh, ww = g.shape
    return [int(s[4]) for s in stats[1:] if s[0] > 0 and s[1] > 0 and s[0] + s[2] < ww and s[1] + s[3] < hh]


@pytest.fixture(scope="module")
def dots() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Dot leaf magnified ×2 in both axes over its centre: source, field, warped, corrected."""
    src = _dot_leaf()
    n = src.shape[0]
    field = np.zeros((n, n, 2), np.float32)
    field[..., 0] = _profile(n, 40, 88, 0.5)[None]
    field[..., 1] = _profile(n, 40, 88, 0.5)[:, None]
    warped = _core.tps_sample(src, field, threads=1)
    return src, field, warped, correct_texture(warped, src, field, seed=0, threads=2)


@pytest.mark.parametrize("factor", [0.5, 2.0], ids=["stretched", "squeezed"])
def test_stripes_come_back_with_the_source_period(factor: float) -> None:
    h, w = 40, 200
    src = _stripes(h, w)
    field = np.zeros((h, w, 2), np.float32)
    field[..., 0] = _profile(w, 70, 130, factor)[None]
    warped = _core.tps_sample(src, field, threads=1)
    out = correct_texture(warped, src, field, seed=0, threads=2)
    band = slice(80, 120)  # inside the distorted columns (73–127)
    assert _period(warped, band) == pytest.approx(PERIOD / factor, rel=0.1)  # the warp did distort
    assert _period(out, band) == pytest.approx(PERIOD, rel=0.1)
    # Two-tone stripes stay two-tone: the colours are the source's, not a blur of them.
    assert np.mean(np.abs(out[:, band, 0] - 0.5) > 0.25) > 0.9


def test_dots_come_back_at_the_source_size(dots) -> None:  # type: ignore[no-untyped-def]
    src, _field, warped, out = dots
    box = (slice(44, 84), slice(44, 84))  # the centre, magnified ×2 both ways
    size = np.median(_dot_areas(src, box))  # 13 px: a disc of radius 2
    assert np.median(_dot_areas(warped, box)) >= 3 * size  # the warp blew them up
    areas = _dot_areas(out, box)
    assert len(areas) >= 8, areas  # dots, not a smear or a flat fill (measured 13)
    assert np.median(areas) == pytest.approx(size, rel=0.25), areas


def test_only_distorted_leaf_pixels_change_and_alpha_is_kept(dots) -> None:  # type: ignore[no-untyped-def]
    _src, field, warped, out = dots
    moved = distortion(field) & (warped[..., 3] > 0.5)
    assert moved.mean() > 0.2  # the test has a real region to correct
    assert np.array_equal(out[~moved].view(np.uint32), warped[~moved].view(np.uint32))  # bit for bit
    assert np.array_equal(out[..., 3].view(np.uint32), warped[..., 3].view(np.uint32))
    assert np.mean(np.any(out[moved] != warped[moved], axis=-1)) > 0.2
    assert out.dtype == np.float32 and out.min() >= 0 and out.max() <= 1


def test_alpha_is_the_warped_one_even_where_the_source_differs(dots) -> None:  # type: ignore[no-untyped-def]
    src, field, warped, _out = dots
    soft = warped.copy()
    soft[..., 3] *= np.float32(0.8)  # the source is opaque where this is not
    out = correct_texture(soft, src, field, seed=0)
    assert np.array_equal(out[..., 3], soft[..., 3])
    assert not np.array_equal(out[..., :3], soft[..., :3])


def test_search_and_vote_mend_the_quilting_seams(dots) -> None:  # type: ignore[no-untyped-def]
    _src, field, _warped, out = dots
    # Dot fragments (under half a dot) in the distorted region: the source has a few there (cut
    # by the region's edge), the quilted start alone far more; counts in docs/pipelines/leaves/correction.md.
    g = ((out[..., 0] > 0.5) & distortion(field)).astype(np.uint8)
    _, _, stats, _ = cv2.connectedComponentsWithStats(g, connectivity=8)
    areas = stats[1:, 4]
    assert np.mean(areas < 7) <= 0.18, (int((areas < 7).sum()), len(areas))


def test_same_output_for_one_and_two_threads(dots) -> None:  # type: ignore[no-untyped-def]
    src, field, warped, out = dots
    assert np.array_equal(correct_texture(warped, src, field, seed=0, threads=1), out)


def _reference_quilt(target, source, hole, field, *, rgba, patch_size, radius_sides, bias):  # type: ignore[no-untyped-def]
    """The guided quilting of ``rust/core/src/correction.rs`` with ``cv2.matchTemplate`` (the
    first implementation, a Python loop): the oracle of the Rust loop."""
    h, w, nc = target.shape
    b, o, radius = patch_size, patch_size // 2, radius_sides * patch_size
    pad = radius + b + o
    padded = np.pad(source, ((pad, pad), (pad, pad), (0, 0)))
    cur, pos = target.copy(), np.full((h, w, 2), -1, np.int32)
    known = np.repeat((~hole)[..., None], nc, axis=2).astype(np.float32)
    if rgba:
        known[..., 3] = 1.0
    span = np.arange(-radius, radius + 1, dtype=np.float32) ** 2
    ys, xs = np.nonzero(hole)
    for by in range(int(ys.min()), int(ys.max()) + 1, b):
        for bx in range(int(xs.min()), int(xs.max()) + 1, b):
            block = hole[by : by + b, bx : bx + b]
            if not block.any():
                continue
            ty0, tx0, ty1, tx1 = max(by - o, 0), max(bx - o, 0), min(by + b + o, h), min(bx + b + o, w)
            cy, cx = min(by + b // 2, h - 1), min(bx + b // 2, w - 1)
            hi_y, hi_x = padded.shape[0] - (ty1 - ty0) - 2 * radius, padded.shape[1] - (tx1 - tx0) - 2 * radius
            wy = int(np.clip(np.rint(ty0 + field[cy, cx, 1]) + pad - radius, 0, hi_y))
            wx = int(np.clip(np.rint(tx0 + field[cy, cx, 0]) + pad - radius, 0, hi_x))
            window = padded[wy : wy + ty1 - ty0 + 2 * radius, wx : wx + tx1 - tx0 + 2 * radius]
            cost = cv2.matchTemplate(window, cur[ty0:ty1, tx0:tx1], cv2.TM_SQDIFF, mask=known[ty0:ty1, tx0:tx1])
            cost += np.float32(bias) * (span[:, None] + span[None, :])
            ky, kx = np.unravel_index(int(np.argmin(cost)), cost.shape)
            sy, sx = wy + int(ky) - pad - ty0, wx + int(kx) - pad - tx0
            yy, xx = np.nonzero(block)
            yy, xx = yy + by, xx + bx
            cur[yy, xx] = padded[yy + sy + pad, xx + sx + pad]
            pos[yy, xx, 0], pos[yy, xx, 1] = yy + sy, xx + sx
            known[yy, xx] = 1.0
    return pos


def test_rust_quilting_places_the_blocks_the_opencv_reference_does(dots) -> None:  # type: ignore[no-untyped-def]
    from phloem.leaves import correction

    src, field, warped, _out = dots
    hole = distortion(field) & (warped[..., 3] > 0.5)
    feat_t, feat_s = correction._features(warped), correction._features(src)
    got = correction._quilt(feat_t, feat_s, hole, field, rgba=True, patch_size=7)
    ref = _reference_quilt(feat_t, feat_s, hole, field, rgba=True, patch_size=7, radius_sides=1, bias=correction._BIAS)
    assert np.array_equal(got[~hole], ref[~hole]) and (got[~hole] == -1).all()
    # Float sums in another order may break a near-tie differently, and later blocks follow.
    same = np.all(got[hole] == ref[hole], axis=-1)
    assert same.mean() >= 0.98, same.mean()  # measured 1.0


def test_distortion_reads_singular_values_not_displacement() -> None:
    n = 32
    yy, xx = np.mgrid[:n, :n].astype(np.float64)
    # A rotation by 30° and a translation: large displacements, no stretch at all.
    a = np.deg2rad(30)
    rot = np.stack([np.cos(a) * xx - np.sin(a) * yy - xx + 5, np.sin(a) * xx + np.cos(a) * yy - yy - 7], axis=-1)
    assert not distortion(rot.astype(np.float32)).any()
    for scale, flagged in [(1.2, False), (1.3, True), (1 / 1.2, False), (1 / 1.3, True)]:
        f = np.zeros((n, n, 2), np.float32)
        f[..., 1] = (scale - 1) * yy  # scaled along y only: one singular value is 1
        assert bool(distortion(f).all()) is flagged, scale
        assert not distortion(f, tolerance=0.35).any()


def test_an_undistorted_warp_returns_the_warped_image() -> None:
    src = _stripes(24, 40)
    field = np.full((24, 40, 2), 1.5, np.float32)  # a pure shift
    warped = _core.tps_sample(src, field, threads=1)
    out = correct_texture(warped, src, field)
    assert np.array_equal(out, warped) and out is not warped


def test_grey_images_keep_their_shape() -> None:
    h, w = 32, 96
    src = np.ascontiguousarray(_stripes(h, w)[..., 0])
    field = np.zeros((h, w, 2), np.float32)
    field[..., 0] = _profile(w, 30, 66, 0.5)[None]
    warped = _core.tps_sample(src[..., None], field, threads=1)[..., 0]
    out = correct_texture(warped, src, field, seed=1)
    assert out.shape == (h, w) and _period(out[..., None], slice(36, 60)) == pytest.approx(PERIOD, rel=0.15)


def test_off_leaf_pixels_are_never_touched(dots) -> None:  # type: ignore[no-untyped-def]
    src, field, warped, _out = dots
    off = warped.copy()
    off[..., 3] = 0.0
    assert np.array_equal(correct_texture(off, src, field), off)


def test_bad_input_one_line_errors() -> None:
    src = _stripes(24, 40)
    field = np.zeros((24, 40, 2), np.float32)
    cases: list[tuple[dict[str, object], type[Exception], str]] = [
        ({"source": src[..., :3]}, ValueError, r"^source: expected 4 channels like warped, got 3"),
        ({"field": field[..., :1]}, ValueError, r"^field: expected shape \(24, 40, 2\)"),
        ({"field": np.full_like(field, np.nan)}, ValueError, r"^field: expected finite displacements"),
        ({"field": field.astype(bool)}, TypeError, r"^field: expected a real-valued"),
        ({"tolerance": 0.0}, ValueError, r"^tolerance: expected a finite value > 0"),
        ({"patch_size": 6}, ValueError, r"^patch_size: expected an odd size"),
        ({"patch_size": 1}, ValueError, r"^patch_size: expected an odd size >= 3"),
        ({"patch_size": 41}, ValueError, r"^patch_size: 41 does not fit"),
        ({"seed": -1}, ValueError, r"^seed: expected an integer >= 0"),
        ({"threads": 0}, ValueError, r"^threads: expected an integer >= 1"),
        ({"warped": np.zeros((24, 40, 5)), "source": np.zeros((24, 40, 5))}, ValueError, r"^warped: expected 1 to 4"),
        ({"warped": np.zeros(5)}, ValueError, r"^warped: expected shape \(H, W\) or \(H, W, C\)"),
    ]
    for change, kind, message in cases:
        args: dict[str, object] = {"warped": src, "source": src, "field": field, **change}
        with pytest.raises(kind, match=message):
            correct_texture(args.pop("warped"), args.pop("source"), args.pop("field"), **args)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^source: no patch centre lies on the leaf"):
        stretched = field.copy()
        stretched[..., 0] = -0.5 * np.arange(40)
        correct_texture(src, np.zeros_like(src), stretched)
    with pytest.raises(ValueError, match=r"^field: expected a non-empty \(H, W, 2\)"):
        distortion(np.zeros((4, 4)))


def test_the_check_runs_between_engine_calls_and_changes_nothing(dots) -> None:  # type: ignore[no-untyped-def]
    # leaves.analyze stops a correction on a worker thread through this check
    src, field, warped, out = dots
    calls: list[int] = []
    with checked(lambda: calls.append(1)):
        assert np.array_equal(correct_texture(warped, src, field, seed=0, threads=2), out)
    assert len(calls) == 1 + 2 * _ROUNDS  # after the quilting, then after each search and each vote
    correct_texture(warped, src, field, seed=0, threads=2)
    assert len(calls) == 1 + 2 * _ROUNDS  # only within the block

    def stop() -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), checked(stop):
        correct_texture(warped, src, field, seed=0, threads=2)
