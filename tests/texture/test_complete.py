"""phloem.texture.complete: completion keeps known pixels and fills holes with known patches."""

from __future__ import annotations

import importlib
import itertools

import cv2
import numpy as np
import pytest

from phloem import _core
from phloem.metrics import coherence_map
from phloem.texture import complete
from phloem.texture._pyramid import upsample_at, upsample_field
from phloem.texture.complete import _copy_centres, _hole_pyramid, _refresh_gradients, _with_gradients

complete_module = importlib.import_module("phloem.texture.complete")


@pytest.fixture(scope="module")
def hole_case(bark):
    img = np.ascontiguousarray(bark[:160, :160])
    hole = np.zeros(img.shape[:2], bool)
    hole[60:100, 50:90] = True
    return img, hole, complete(img, hole, seed=0)


def test_completion_keeps_known_pixels(hole_case):
    img, hole, out = hole_case
    assert np.array_equal(out[~hole], img[~hole])
    assert np.isfinite(out).all()


def _local_std(img, mask):
    g = img.mean(axis=2)
    ys, xs = np.nonzero(mask)
    return float(np.mean([g[y - 3 : y + 4, x - 3 : x + 4].std() for y, x in zip(ys[::7], xs[::7])]))


def test_completion_fills_with_known_patches(hole_case):
    img, hole, out = hole_case
    src = img[100:]  # known rows below the hole
    # The fill is as well explained by known patches as the real (hidden) content is ...
    assert np.nanmean(coherence_map(out, src, mask=hole)) <= np.nanmean(coherence_map(img, src, mask=hole))
    # ... and keeps bark's local contrast: a mean-colour or blurred fill fails here (nearest-patch
    # coherence alone prefers flat patches, so it cannot catch a wash-out).
    inner = np.zeros_like(hole)
    inner[64:96, 54:86] = True
    flat = img.copy()
    flat[hole] = img[~hole].mean(0)
    assert _local_std(flat, inner) < 0.05 * _local_std(img, inner)
    assert _local_std(out, inner) > 0.6 * _local_std(img, inner)


def test_completion_deterministic_across_threads(hole_case):
    img, hole, out = hole_case
    assert np.array_equal(complete(img, hole, seed=0, threads=1), out)


@pytest.mark.parametrize(
    ("mask", "match"),
    [
        (np.zeros((64, 64), bool), "mask"),
        (np.ones((64, 64), bool), "mask"),
        (np.zeros((32, 64), bool), "mask"),
        (np.zeros((64, 64, 3), bool), "mask"),
    ],
)
def test_completion_bad_masks(bark, mask, match):
    with pytest.raises(ValueError, match=match):
        complete(bark[:64, :64], mask)


def test_completion_pyramid_shrinks_the_hole(bark):
    # A coarse pixel is known when any fine pixel under its kernel is, so the hole shrinks by
    # more than the 4x of halving at every level, down to a sliver (the old pyramid, which
    # marked partly known coarse pixels as hole, made it grow).
    img = np.ascontiguousarray(bark[:256, :256])
    hole = np.zeros((256, 256), bool)
    hole[80:176, 80:176] = True
    levels = _hole_pyramid(img, hole, 7, None)
    areas = [int(h.sum()) for _, h, _, _ in levels]
    assert len(levels) >= 3
    assert all(b < a / 4 for a, b in itertools.pairwise(areas)), areas  # measured 9216, 2116, 400, 64, 4
    assert areas[-1] <= 64, areas


def _stripes(side):
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:160, :160]
    img = (0.5 + 0.35 * np.sin(2 * np.pi * (xx + yy) / 14.0))[..., None] * np.ones(3)
    img = np.clip(img + rng.normal(0, 0.02, img.shape), 0, 1).astype(np.float32)
    hole = np.zeros((160, 160), bool)
    a = 80 - side // 2
    hole[a : a + side, a : a + side] = True
    return img, hole


@pytest.mark.parametrize("side", [32, 40, 56])
def test_completion_continues_structure_across_a_large_hole(side):
    # Diagonal stripes with a little noise: the fill must continue them in phase. The
    # interpolating pyramid alone loses the phase at its aliased coarse levels (0.40 / 0.88 /
    # 1.14 of a flat fill's error); "auto" keeps the strict pyramid's fill here (0.10).
    img, hole = _stripes(side)
    out = complete(img, hole, seed=0)
    err = float(np.abs(out - img)[hole].mean())
    flat = float(np.abs(img[~hole].mean(0) - img)[hole].mean())
    assert err < 0.15 * flat, (err, flat)
    strict = complete(img, hole, seed=0, pyramid="strict")
    assert float(np.abs(strict - img)[hole].mean()) < 0.15 * flat


def test_auto_keeps_the_interpolating_fill_on_a_photo(hole_case):
    img, hole, out = hole_case
    assert np.array_equal(out, complete(img, hole, seed=0, pyramid="interpolate"))


def test_completion_copies_only_from_sources(bark):
    # A frame of a target (top, a hole in it) and a source (bottom): with source_mask=, the fill is
    # made of the bottom's pixels only, even though the top's known pixels match as well.
    top = np.full((64, 96, 3), 0.9, np.float32)  # a bright canvas that must not be copied
    bottom = np.ascontiguousarray(bark[:64, :96])
    frame = np.concatenate([top, bottom])
    hole = np.zeros(frame.shape[:2], bool)
    hole[12:52, 20:76] = True
    src = np.zeros_like(hole)
    src[64:] = True
    out = complete(frame, hole, source_mask=src, seed=0)
    fill = out[hole]
    assert float(np.isclose(fill, 0.9, atol=1e-3).all(axis=1).mean()) < 0.01
    without = complete(frame, hole, seed=0)
    assert float(np.isclose(without[hole], 0.9, atol=1e-3).all(axis=1).mean()) > 0.5
    with pytest.raises(ValueError, match="^mask: the known pixels in source_mask holds no"):
        complete(frame, hole, source_mask=np.zeros_like(hole))
    with pytest.raises(ValueError, match="^source_mask:"):
        complete(frame, hole, source_mask=np.zeros((3, 3), bool))


def test_completion_schedules(hole_case):
    img, hole, out = hole_case
    calls = []
    cheap = complete(
        img, hole, seed=0, iterations=[0, 2], search_iterations=[1, 3], progress=lambda d, t: calls.append((d, t))
    )
    assert np.array_equal(cheap[~hole], img[~hole]) and np.isfinite(cheap).all()
    assert calls and calls[-1][0] == calls[-1][1] and [d for d, _ in calls] == list(range(1, len(calls) + 1))
    values_only = complete(img, hole, seed=0, gradient_weight=0.0, pyramid="interpolate")
    assert not np.array_equal(values_only, out)
    for kwargs, match in [
        (dict(iterations=[]), "iterations"),
        (dict(iterations=[1, -1]), "iterations"),
        (dict(iterations=0), "iterations"),
        (dict(search_iterations=[0]), "search_iterations"),
        (dict(pyramid="box"), "pyramid"),
        (dict(gradient_weight=-1.0), "gradient_weight"),
    ]:
        with pytest.raises(ValueError, match=match):
            complete(img, hole, **kwargs)


def test_strict_pyramid_does_not_grow_spurs_off_a_bright_rim():
    # Branching's gap filling: a painted white channel (known, not a source) in a black gap, the
    # background sources holding thin untraced tributaries. The interpolating pyramid's coarse
    # levels take the channel's white into rim pixels and the fill matches them with tributary
    # pieces (18 white pixels here); the strict pyramid synthesises the rim and adds none.
    rng = np.random.default_rng(0)
    canvas = np.zeros((160, 160, 1), np.float32)
    canvas[20:140, 74:86] = 1.0
    hole = np.ones((160, 160), bool)
    hole[19:141, 73:87] = False
    src = np.zeros((200, 160, 1), np.float32)
    for _ in range(8):
        y, x = rng.integers(10, 190), rng.integers(10, 130)
        src[y : y + 2, x : x + 25] = 1.0
    frame = np.concatenate([canvas, np.zeros((56, 160, 1), np.float32), src])
    fill = np.zeros(frame.shape[:2], bool)
    fill[:160] = hole
    sources = np.zeros_like(fill)
    sources[216:] = True
    kw = dict(source_mask=sources, levels=4, iterations=[0, 2, 4], search_iterations=[1, 1, 3], gradient_weight=0.0)
    white = {
        pyr: int((complete(frame, fill, pyramid=pyr, **kw)[:160][hole] > 0.5).sum())
        for pyr in ("strict", "interpolate")
    }
    assert white["strict"] == 0 and white["interpolate"] > 0, white


def _scattered_hole(shape, seed):
    rng = np.random.default_rng(seed)
    hole = np.zeros(shape, bool)
    for _ in range(6):
        y, x = rng.integers(0, shape[0] - 4), rng.integers(0, shape[1] - 4)
        hole[y : y + rng.integers(1, 9), x : x + rng.integers(1, 9)] = True
    hole[0, 3] = hole[-1, -1] = True  # the border, where gradients are zero
    return hole


def test_upsample_at_equals_full_upsample_on_its_pixels():
    rng = np.random.default_rng(1)
    coarse = np.stack([rng.integers(3, 20, (12, 17)), rng.integers(3, 30, (12, 17))], -1).astype(np.int32)
    coarse[rng.random((12, 17)) < 0.2] = -1
    at = _scattered_hole((25, 35), 2)  # odd sides: the last row and column clamp to the parent
    full = upsample_field(coarse, at.shape, (24, 34), 3)
    part = upsample_at(coarse, at, (24, 34), 3)
    np.testing.assert_array_equal(part[at], full[at])
    assert (part[~at] == -1).all()


def _upsample_reference(coarse, at, src_shape, r, wrap):
    """The coherent upsampling of one pixel at a time, as its docstring states it."""
    up = np.full((*at.shape, 2), -1, np.int32)
    for y, x in zip(*np.nonzero(at), strict=True):
        py, px = min(y // 2, coarse.shape[0] - 1), min(x // 2, coarse.shape[1] - 1)
        if coarse[py, px, 0] < 0:
            continue
        cy, cx = 2 * coarse[py, px, 0] + y - 2 * py, 2 * coarse[py, px, 1] + x - 2 * px
        if wrap:
            up[y, x] = cy % src_shape[0], cx % src_shape[1]
        else:
            up[y, x] = min(max(cy, r), src_shape[0] - 1 - r), min(max(cx, r), src_shape[1] - 1 - r)
    return up


@pytest.mark.parametrize("share", [0.03, 0.6])  # below and above DENSE_SHARE: both paths
@pytest.mark.parametrize("wrap", [False, True])
def test_upsample_at_agrees_with_a_pixel_by_pixel_reference(share, wrap):
    rng = np.random.default_rng(7)
    coarse = np.stack([rng.integers(0, 24, (12, 17)), rng.integers(0, 34, (12, 17))], -1).astype(np.int32)
    coarse[rng.random((12, 17)) < 0.2] = -1
    at = rng.random((25, 35)) < share  # odd sides: the last row and column repeat their parent
    got = upsample_at(coarse, at, (24, 34), 3, wrap=wrap)
    np.testing.assert_array_equal(got, _upsample_reference(coarse, at, (24, 34), 3, wrap))


@pytest.mark.parametrize("share", [0.03, 0.6])
def test_copy_centres_copies_usable_matches_only(share):
    rng = np.random.default_rng(11)
    orig = rng.random((30, 41, 3), dtype=np.float32)
    hole = rng.random((30, 41)) < share
    smask = ~hole & (rng.random((30, 41)) < 0.8)
    field = np.stack([rng.integers(0, 30, (30, 41)), rng.integers(0, 41, (30, 41))], -1).astype(np.int32)
    field[rng.random((30, 41)) < 0.1] = -1
    cur = orig.copy()
    cur[hole] = -1.0
    done = _copy_centres((orig, hole, hole, smask), field, cur)
    want = cur.copy()
    want_done = np.zeros_like(hole)
    for y, x in zip(*np.nonzero(hole), strict=True):
        fy, fx = field[y, x]
        if fy >= 0 and smask[fy, fx]:
            want[y, x], want_done[y, x] = orig[fy, fx], True
    np.testing.assert_array_equal(done, want_done)
    np.testing.assert_array_equal(cur, want)


def test_gradient_refresh_equals_full_features_on_the_band():
    rng = np.random.default_rng(3)
    img = rng.random((30, 41, 3), dtype=np.float32)
    feat = _with_gradients(img, 0.7)
    hole = _scattered_hole(img.shape[:2], 4)
    img[hole] = rng.random((int(hole.sum()), 3), dtype=np.float32)
    band = np.nonzero(cv2.dilate(hole.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))))
    _refresh_gradients(feat, img, band, 0.7)
    np.testing.assert_array_equal(feat, _with_gradients(img, 0.7))


def test_masked_vote_equals_full_vote_on_its_pixels(bark):
    img = bark[:40, :50, :3].copy()
    rng = np.random.default_rng(5)
    field = np.stack([rng.integers(3, 37, (40, 50)), rng.integers(3, 47, (40, 50))], -1).astype(np.int32)
    field[rng.random((40, 50)) < 0.3] = -1
    weights = rng.random((40, 50), dtype=np.float32)
    at = _scattered_hole((40, 50), 6)
    kw = dict(patch_size=7, weights=weights, threads=2, mean_shift=3)
    full, wfull = _core.vote(img, field, pixels=None, **kw)
    part, wpart = _core.vote(img, field, pixels=at, **kw)
    np.testing.assert_array_equal(part[at], full[at])
    np.testing.assert_array_equal(wpart[at], wfull[at])
    assert not part[~at].any() and not wpart[~at].any()
    with pytest.raises(ValueError, match="pixels"):
        _core.vote(img, field, pixels=at[1:], **kw)


def _small_scene(bark):
    # A textured patch in the top-left corner of a flat canvas: the hole and the sources fill
    # a third of the image, so completion runs on their box.
    canvas = np.full((150, 150, 3), 0.5, np.float32)
    canvas[:80, :70] = bark[:80, :70, :3]
    hole = np.zeros((150, 150), bool)
    hole[30:44, 25:40] = True
    sources = np.zeros_like(hole)
    sources[:80, :70] = True
    return canvas, hole, sources & ~hole


def test_completion_on_the_sources_box_is_the_completion_of_the_box(bark):
    canvas, hole, sources = _small_scene(bark)
    out = complete(canvas, hole, source_mask=sources, seed=2)
    box = np.s_[: 80 + 14, : 70 + 14]  # the box of hole and sources, two patches wider
    alone = complete(canvas[box], hole[box], source_mask=sources[box], seed=2)
    np.testing.assert_array_equal(out[box], alone)
    np.testing.assert_array_equal(out[~hole], canvas[~hole])


def test_cropped_completion_keeps_the_held_out_error(bark, monkeypatch):
    # Hidden known patches are filled as well with the crop as without it (within the spread
    # between seeds), which is the crop's only effect: other random draws.
    canvas, hole, sources = _small_scene(bark)
    hide = np.zeros_like(hole)
    hide[8:20, 45:57] = hide[55:67, 10:22] = True
    errors = {}
    for frac in (0.75, 0.0):
        monkeypatch.setattr(complete_module, "_CROP_MAX_FRACTION", frac)
        errs = []
        for seed in range(3):
            out = complete(canvas, hole | hide, source_mask=sources & ~hide, seed=seed)
            errs.append(float(np.abs(out[hide] - canvas[hide]).mean()))
        errors[frac] = float(np.mean(errs))
    assert errors[0.75] <= 1.25 * errors[0.0], errors


def test_occurrence_cost_charges_overuse_only():
    # 100 matches spread evenly over the 10×10 usable centres of a 16×16 source (p = 7) cost
    # nothing; all on one centre cost λ × scale × overuse around it and nothing away from it.
    from phloem.texture._occurrence import occurrence_cost

    ys, xs = np.mgrid[3:13, 3:13]
    even = np.stack([ys.ravel(), xs.ravel()], axis=1).astype(np.int32)
    cost = occurrence_cost(even, (16, 16), 7, 2.0, 0.5, 100)
    assert float(cost[5:11, 5:11].max()) == 0.0
    one = np.full((100, 2), 8, np.int32)
    cost = occurrence_cost(one, (16, 16), 7, 2.0, 0.5, 100)
    # at the centre, the mean coverage over its own patch is 100, uniform is 100 × 49 / 100
    assert cost[8, 8] == pytest.approx(2.0 * 0.5 * (100 / 49.0 - 1.0))
    assert cost[0, 15] == 0.0  # a patch that does not overlap the overused one
    assert float(occurrence_cost(np.full((4, 2), -1, np.int32), (16, 16), 7, 1.0, 1.0, 100).max()) == 0.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_diversity_keeps_the_fine_scale_of_a_collapsing_fill(seed):
    # A source whose texture grows from nothing (left) to strong (right) and a hole three times
    # its height, filled as the branching gaps are: plain completion settles on the smoothest
    # patches, the occurrence penalty draws on more of the source and keeps more fine scale.
    rng = np.random.default_rng(0)
    H, W = 64, 192
    grain = cv2.GaussianBlur(rng.normal(size=(H, W)).astype(np.float32), (0, 0), 0.8)
    frame = np.full((112 + H, W), 0.5, np.float32)
    frame[112:] += grain * np.linspace(0.0, 0.15, W, dtype=np.float32)[None, :]
    hole = np.zeros(frame.shape, bool)
    hole[8:88, 8:184] = True
    sources = np.zeros_like(hole)
    sources[112:] = True

    def fine(diversity: float) -> float:
        out = complete(
            frame, hole, source_mask=sources, patch_size=7, levels=3, iterations=[0, 2, 4],
            search_iterations=[1, 1, 3], pyramid="strict", gradient_weight=0.0, diversity=diversity, seed=seed,
            threads=1,
        )  # fmt: skip
        return float((out - cv2.GaussianBlur(out, (0, 0), 2.0))[hole].std())

    assert fine(1.0) > 1.1 * fine(0.0)


def test_diversity_is_checked(hole_case):
    img, hole, _ = hole_case
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="^diversity:"):
            complete(img, hole, diversity=bad)


def test_finest_copy_fills_with_source_pixels_and_keeps_the_grain():
    # A stochastic texture (blurred noise, no two patches alike) with a large hole, completed as
    # the branching gaps are (the finest level only takes the half-resolution field): the vote
    # averages the disagreeing matches into a smooth fill, the copy puts source pixels there,
    # every one of them a known pixel, and keeps the texture's fine scale.
    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(rng.normal(size=(128, 128)).astype(np.float32), (0, 0), 1.0)
    img = (0.5 + 0.2 * img / img.std()).astype(np.float32)
    hole = np.zeros(img.shape, bool)
    hole[30:98, 30:98] = True
    kw = dict(patch_size=7, levels=3, iterations=[0, 2, 4], search_iterations=[1, 1, 3], pyramid="strict",
              gradient_weight=0.0, seed=0, threads=1)  # fmt: skip
    voted, copied = complete(img, hole, **kw), complete(img, hole, finest="copy", **kw)
    assert np.array_equal(voted[~hole], img[~hole]) and np.array_equal(copied[~hole], img[~hole])
    known = np.unique(img[~hole])
    assert np.isin(copied[hole], known).all()
    assert np.isin(voted[hole], known).mean() < 0.5

    def fine(out: np.ndarray) -> float:
        return float((out - cv2.GaussianBlur(out, (0, 0), 2.0))[hole].std())

    src = float((img - cv2.GaussianBlur(img, (0, 0), 2.0))[~hole].std())
    assert fine(copied) > 0.8 * src and fine(copied) > 1.8 * fine(voted)
    with pytest.raises(ValueError, match="^finest: expected 'vote' or 'copy'"):
        complete(img, hole, finest="mode")  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_start_blocks_copies_many_sources_where_a_flat_start_repeats_a_few(seed):
    # Blurred noise (every pixel value unique) and a hole filled as the branching gaps are, from
    # the rows below it only: a flat start settles every half-resolution patch on the few
    # smoothest sources, and the copied finest level repeats their 2×2 blocks, so the fill holds
    # a twentieth as many distinct pixels as it has and their rows alternate in brightness.
    # Random source blocks at the start keep the fill's pixels distinct and its rows level.
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.random((300, 300)).astype(np.float32), (0, 0), 0.8)
    img = (img - img.min()) / (img.max() - img.min())
    hole = np.zeros(img.shape, bool)
    hole[20:150, 20:280] = True
    rows = np.nonzero(hole)[0]

    def fill(start: str) -> tuple[float, float]:
        out = complete(
            img, hole, source_mask=~hole, patch_size=7, levels=2, iterations=[0, 4], search_iterations=[1, 3],
            pyramid="strict", gradient_weight=0.0, finest="copy", start=start, seed=seed, threads=1,  # type: ignore[arg-type]
        )  # fmt: skip
        f = out[hole]
        assert np.isin(f, img[~hole]).all() and np.array_equal(out[~hole], img[~hole])
        return np.unique(f).size / f.size, abs(float(f[rows % 2 == 0].mean() - f[rows % 2 == 1].mean()))

    (flat_distinct, flat_rows), (block_distinct, block_rows) = fill("auto"), fill("blocks")
    assert flat_distinct < 0.1 and block_distinct > 0.4
    assert flat_rows > 0.01 and block_rows < 0.004
    with pytest.raises(ValueError, match="^start: expected 'auto' or 'blocks'"):
        complete(img, hole, start="noise")  # type: ignore[arg-type]


def test_start_blocks_builds_no_level_with_too_few_sources():
    # Sources in a band 24 px high: at half resolution a 7×7 patch barely fits in it, so that
    # level would fill its hole from a few centres; with the cap it is not built (the full
    # resolution always is).
    from phloem.texture.complete import BLOCKS_MAX_REUSE, _hole_pyramid

    img = np.random.default_rng(1).random((200, 200)).astype(np.float32)[..., None]
    hole = np.zeros((200, 200), bool)
    hole[:150] = True
    allowed = np.zeros_like(hole)
    allowed[170:194] = True
    free = _hole_pyramid(img, hole, 7, None, allowed=allowed, strict_from=1)
    capped = _hole_pyramid(img, hole, 7, None, allowed=allowed, strict_from=1, max_reuse=BLOCKS_MAX_REUSE)
    ratios = [lv[1].sum() / lv[3].sum() for lv in free]
    assert len(free) > 1 and ratios[1] > BLOCKS_MAX_REUSE
    assert len(capped) == 1 and np.array_equal(capped[0][3], free[0][3])
