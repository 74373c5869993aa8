"""phloem.texture.complete: completion keeps known pixels and fills holes with known patches."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from phloem.metrics import coherence_map
from phloem.texture import complete
from phloem.texture.complete import _hole_pyramid


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
