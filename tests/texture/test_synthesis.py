"""phloem.texture.synthesize: texture optimisation produces exemplar patches, deterministically."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import phloem
from phloem.metrics import coherence_map, patch_coherence, repetition
from phloem.texture import synthesize


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


def test_repetition_of_the_detail_sees_a_repeated_grain_under_lighting():
    # a ramp of lighting resembles itself at every shift and hides whether the grain repeats;
    # the detail (less a Gaussian blur) tells a tiled grain from a fresh one under the same ramp
    rng = np.random.default_rng(0)
    ramp = np.linspace(0.0, 30.0, 144)[None, :] * np.ones((144, 1))
    tiled, fresh = np.tile(rng.random((24, 24)), (6, 6)) + ramp, rng.random((144, 144)) + ramp
    assert repetition(fresh) > 0.9  # the lighting alone
    assert repetition(tiled, detail=2.0) > 0.99
    assert repetition(fresh, detail=2.0) < 0.15
    for bad in (0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="detail"):
            repetition(fresh, detail=bad)


def _brute_repetition(g: np.ndarray, mask: np.ndarray, m: int) -> float:
    g = np.where(mask, g - g[mask].mean(), 0.0)
    h, w = g.shape
    best = -np.inf
    for dy in range(-h + 1, h):
        for dx in range(-w + 1, w):
            if max(abs(dy), abs(dx)) < m:
                continue
            a = (slice(max(0, -dy), h - max(0, dy)), slice(max(0, -dx), w - max(0, dx)))
            b = (slice(max(0, dy), h - max(0, -dy)), slice(max(0, dx), w - max(0, -dx)))
            both = mask[a] & mask[b]
            if both.sum() <= 0.25 * mask.sum():
                continue
            x, y = g[a][both], g[b][both]
            best = max(best, float((x * y).sum() / np.sqrt(max((x * x).sum() * (y * y).sum(), 1e-24))))
    return best


def test_repetition_in_a_mask_agrees_with_brute_force():
    rng = np.random.default_rng(3)
    g = rng.random((18, 22))
    mask = rng.random((18, 22)) < 0.7
    for m in (3, 6):
        assert repetition(g, mask=mask, min_shift=m) == pytest.approx(_brute_repetition(g, mask, m), abs=1e-6)
        assert repetition(g, min_shift=m) == pytest.approx(_brute_repetition(g, np.ones_like(mask), m), abs=1e-6)


def test_repetition_in_a_mask_sees_a_lattice_beside_bright_structure():
    # a completed gap that repeats one small patch, beside bright structure that does not
    # repeat: over the whole image the structure outweighs the lattice, in the gap it shows
    rng = np.random.default_rng(0)
    img = np.tile(0.02 * rng.random((16, 16)), (9, 9))
    structure = np.zeros(img.shape, bool)
    for _ in range(40):
        y, x = rng.integers(0, 144, 2)
        structure[max(0, y - 1) : y + 2, max(0, x - 20) : x + 20] = True
    img[structure] = 1.0 + rng.random(int(structure.sum()))
    # the gaps beyond the reach of the detail's blur round the structure
    gaps = cv2.dilate(structure.astype(np.uint8), np.ones((13, 13), np.uint8)) == 0
    assert repetition(img, detail=2.0) < 0.6
    assert repetition(img, detail=2.0, mask=gaps) > 0.9
    with pytest.raises(ValueError, match="mask: expected at least one pixel"):
        repetition(img, mask=np.zeros(img.shape, bool))
    with pytest.raises(ValueError, match="mask: expected shape"):
        repetition(img, mask=gaps[:, :10])


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
