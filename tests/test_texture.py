"""phloem.texture: synthesis and completion produce exemplar patches, deterministically."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import phloem
from phloem.metrics import coherence_map, patch_coherence, repetition
from phloem.texture import complete, synthesize


@pytest.fixture(scope="module")
def exemplar(bark):
    return np.ascontiguousarray(bark[:128, :128])


@pytest.fixture(scope="module")
def synthesized(exemplar):
    return synthesize(exemplar, (160, 200), seed=5)


def test_synthesis_patches_come_from_the_exemplar(synthesized, exemplar, bark):
    assert synthesized.shape == (160, 200, 3) and synthesized.dtype == np.float32
    # Every output patch is close to some exemplar patch: far closer than patches of another
    # real crop of the same bark are (which are new arrangements of the same material).
    ours = patch_coherence(synthesized, exemplar)
    other_crop = patch_coherence(bark[128:256, 128:256], exemplar)
    assert ours < 0.35 * other_crop, (ours, other_crop)
    assert np.nanpercentile(coherence_map(synthesized, exemplar), 95) < other_crop


def test_synthesis_keeps_the_exemplar_contrast(synthesized, exemplar):
    # Texture optimisation's failure mode is a wash-out towards flat, averaged patches: the
    # output's local contrast and colour spread must stay near the exemplar's.
    def local_std(img):
        g = img.mean(axis=2)
        return float(
            np.mean(
                [
                    g[y : y + 8, x : x + 8].std()
                    for y in range(0, g.shape[0] - 8, 8)
                    for x in range(0, g.shape[1] - 8, 8)
                ]
            )
        )

    assert local_std(synthesized) > 0.8 * local_std(exemplar)
    np.testing.assert_allclose(synthesized.reshape(-1, 3).std(0), exemplar.reshape(-1, 3).std(0), rtol=0.2)


def test_synthesis_is_not_a_copy(synthesized, exemplar):
    # A new arrangement, not the exemplar tiled: the output's 32x32 blocks are not all found
    # verbatim in one place of the exemplar.
    field, _ = phloem.patch.nnf(exemplar, synthesized, patch_size=7, iterations=6, seed=0)
    offsets = field - np.stack(np.mgrid[0:160, 0:200], -1)
    _, counts = np.unique(offsets.reshape(-1, 2), axis=0, return_counts=True)
    assert counts.max() < 0.25 * 160 * 200


@pytest.mark.parametrize("name", ["bark", "water"])
def test_synthesis_does_not_tile_the_exemplar(name, request):
    # A tiled copy is perfectly coherent, so coherence cannot catch it; repetition can. The
    # output may repeat itself no more than the exemplar does (a tiled output scores ~0.9).
    ex = np.ascontiguousarray(request.getfixturevalue(name)[:150, :150])
    out = synthesize(ex, (256, 256), seed=0)
    assert repetition(out) < repetition(ex) + 0.05


def test_repetition_metric():
    rng = np.random.default_rng(0)
    tile = rng.random((40, 40))
    assert repetition(np.tile(tile, (3, 3))) > 0.99
    assert repetition(rng.random((120, 120))) < 0.15
    with pytest.raises(ValueError, match="min_shift"):
        repetition(tile, min_shift=30)


def test_synthesis_deterministic_across_threads(exemplar):
    a = synthesize(exemplar[:64, :64], (70, 90), seed=2, threads=1)
    b = synthesize(exemplar[:64, :64], (70, 90), seed=2, threads=2)
    assert np.array_equal(a, b)
    c = synthesize(exemplar[:64, :64], (70, 90), seed=3, threads=2)
    assert not np.array_equal(a, c)


def test_extra_channel_rides_along(exemplar):
    # A "height map" that is a fixed function of the colour stays that function of the
    # synthesised colour: channels are synthesised jointly.
    height = exemplar @ np.array([0.2, 0.5, 0.3], np.float32)
    ex4 = np.concatenate([exemplar, height[..., None]], axis=2)
    out = synthesize(ex4, (96, 96), seed=1)
    assert out.shape == (96, 96, 4)
    np.testing.assert_allclose(out[..., 3], out[..., :3] @ np.array([0.2, 0.5, 0.3], np.float32), atol=1e-4)


def test_gray_in_gray_out(gravel):
    out = synthesize(gravel[:64, :64], 80, seed=0)
    assert out.shape == (80, 80)


def test_progress_is_reported(exemplar):
    calls = []
    synthesize(exemplar[:48, :48], (40, 40), levels=2, iterations=3, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(i, 6) for i in range(1, 7)]


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


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(size=(0, 10)), "size"),
        (dict(size="big"), "size"),
        (dict(size=32, patch_size=8), "patch_size"),
        (dict(size=32, patch_size=41), "patch_size"),
        (dict(size=32, diversity=-1.0), "diversity"),
        (dict(size=32, weights=[1.0]), "weights"),
        (dict(size=32, iterations=0), "iterations"),
    ],
)
def test_synthesis_bad_arguments(bark, kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        synthesize(bark[:40, :40], **kwargs)


def test_synthesis_rejects_nan_exemplar(bark):
    ex = bark[:40, :40].copy()
    ex[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="exemplar"):
        synthesize(ex, 32)


def test_absurd_output_size_fails_at_once(bark):
    with pytest.raises(ValueError, match="max_pixels"):
        synthesize(bark[:32, :32], (100_000, 100_000))


def test_completion_pyramid_shrinks_the_hole(bark):
    # A coarse pixel is known when any fine pixel under its kernel is, so the hole shrinks by
    # more than the 4x of halving at every level, down to a sliver (the old pyramid, which
    # marked partly known coarse pixels as hole, made it grow).
    from phloem.texture import _hole_pyramid

    img = np.ascontiguousarray(bark[:256, :256])
    hole = np.zeros((256, 256), bool)
    hole[80:176, 80:176] = True
    levels = _hole_pyramid(img, hole, 7, None)
    areas = [int(h.sum()) for _, h, _, _ in levels]
    assert len(levels) >= 3
    assert all(b < a / 4 for a, b in itertools.pairwise(areas)), areas  # measured 9216, 2116, 400, 64, 4
    assert areas[-1] <= 64, areas


@pytest.mark.xfail(
    strict=True,
    reason="known regression since the mask-aware pyramid: fill error 0.35-1.14x a flat fill on "
    "pure stripes, where the previous pyramid and PyPatchMatch reach 0.10-0.16x",
)
def test_completion_continues_structure_across_a_large_hole():
    # Diagonal stripes with a little noise and a 56×56 hole: the fill must continue them.
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[:160, :160]
    img = (0.5 + 0.35 * np.sin(2 * np.pi * (xx + yy) / 14.0))[..., None] * np.ones(3)
    img = np.clip(img + rng.normal(0, 0.02, img.shape), 0, 1).astype(np.float32)
    hole = np.zeros((160, 160), bool)
    hole[52:108, 52:108] = True
    out = complete(img, hole, seed=0)
    err = float(np.abs(out - img)[hole].mean())
    flat = float(np.abs(img[~hole].mean(0) - img)[hole].mean())
    assert err < 0.15 * flat, (err, flat)
