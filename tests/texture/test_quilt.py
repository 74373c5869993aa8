"""phloem.texture.quilt: graph-cut quilting copies exemplar pixels along minimum seams."""

from __future__ import annotations

from dataclasses import astuple

import numpy as np
import pytest

import phloem
from phloem.metrics import repetition
from phloem.seams import seam
from phloem.texture import quilt


@pytest.fixture(scope="module")
def quilted(bark):
    return astuple(quilt(bark, (200, 260), block=48, overlap=12, seed=3, full_output=True))


def test_every_output_pixel_is_copied_from_the_exemplar(bark, quilted):
    out, src = quilted
    assert out.shape == (200, 260, 3)
    assert (src >= 0).all() and (src[..., 0] < bark.shape[0]).all() and (src[..., 1] < bark.shape[1]).all()
    assert np.array_equal(out, bark[src[..., 0], src[..., 1]])


def test_output_is_made_of_a_few_translated_pieces(quilted):
    """Each block is one exemplar offset: the offset field takes at most one value per block."""
    out, src = quilted
    yy, xx = np.mgrid[0 : out.shape[0], 0 : out.shape[1]]
    offsets = np.unique(np.stack([src[..., 0] - yy, src[..., 1] - xx], -1).reshape(-1, 2), axis=0)
    step = 48 - 12
    blocks = int(np.ceil((200 - 12) / step) * np.ceil((260 - 12) / step))
    assert 2 <= len(offsets) <= blocks


def test_seams_are_the_minimum_cuts_of_the_overlaps(bark):
    """The second block of the first row overlaps the first in columns 36..47. Cutting that
    overlap independently with seams.seam gives the labels quilting used (rows 0..35, which
    later blocks do not touch)."""
    out, src = astuple(quilt(bark, (84, 84), block=48, overlap=12, randomness=1.0, seed=0, full_output=True))
    (ay, ax), (by, bx) = src[0, 0], src[0, 83] - [0, 83 - 36]
    a = np.zeros((48, 84, 3), np.float32)
    b = np.zeros((48, 84, 3), np.float32)
    a[:, :48] = bark[ay : ay + 48, ax : ax + 48]
    b[:, 36:] = bark[by : by + 48, bx : bx + 48]
    cols = np.arange(84)
    a_mask, b_mask = np.broadcast_to(cols < 48, (48, 84)), np.broadcast_to(cols >= 36, (48, 84))
    take_b = seam(a, b, a_mask & b_mask, a_mask=a_mask, b_mask=b_mask)
    assert np.array_equal(out[:36], np.where(take_b[..., None], b, a)[:36])
    assert not take_b[:, 36].any() and take_b[:, 47].all(), "border ties hold"
    # With k = 1 the second block does not simply continue the first, so the cut has work to do.
    assert (ay, ax - 0) != (by, bx - 36) and 0 < take_b[:36, 37:47].sum() < 36 * 10


def test_quilting_beats_random_placement_at_the_seams(bark):
    """Entire-patch matching plus seams: the colour jump between neighbouring pixels that come
    from different pieces is far smaller than for randomly placed pieces with straight cuts."""
    out, src = astuple(quilt(bark, (192, 192), block=48, overlap=12, seed=2, full_output=True))
    yy, xx = np.mgrid[0:192, 0:192]
    off = (src[..., 0] - yy) * 10000 + (src[..., 1] - xx)

    def seam_jump(img, labels):
        dx = labels[:, 1:] != labels[:, :-1]
        jump = np.abs(img[:, 1:] - img[:, :-1]).sum(-1)
        return float(jump[dx].mean())

    rng = np.random.default_rng(0)
    tiles = np.zeros_like(out)
    lab = np.zeros((192, 192), int)
    for i in range(0, 192, 48):
        for j in range(0, 192, 48):
            ty, tx = rng.integers(0, 256 - 48, 2)
            tiles[i : i + 48, j : j + 48] = bark[ty : ty + 48, tx : tx + 48]
            lab[i : i + 48, j : j + 48] = i * 1000 + j
    inside = np.abs(bark[:, 1:] - bark[:, :-1]).sum(-1).mean()
    assert seam_jump(out, off) < 0.75 * seam_jump(tiles, lab)
    assert seam_jump(out, off) < 1.5 * inside


def test_quilt_is_not_a_tiling(bark):
    """Entire-patch matching often continues the exemplar verbatim (that is how it hides
    seams), so quilts repeat more than optimisation-based synthesis, but far less than a
    periodic tiling of the exemplar."""
    out = quilt(bark, (384, 384), seed=4)
    tiled = np.tile(bark, (2, 2, 1))[:384, :384]
    assert repetition(out) < 0.5 * repetition(tiled)


def test_quilt_deterministic_and_seed_dependent(bark):
    a = quilt(bark, (120, 120), block=40, seed=9, threads=1)
    b = quilt(bark, (120, 120), block=40, seed=9, threads=2)
    c = quilt(bark, (120, 120), block=40, seed=10)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_greedy_quilt_and_other_costs(bark, gravel):
    for cost in ("gradient", "luo"):
        out, src = astuple(quilt(bark, (100, 100), block=40, randomness=0.0, cost=cost, full_output=True))
        assert np.array_equal(out, bark[src[..., 0], src[..., 1]])
    g = quilt(gravel, (150, 90), block=32)
    assert g.shape == (150, 90) and g.dtype == np.float32


def test_extra_channels_ride_along(bark):
    """A height map and a label channel (5 channels: more than OpenCV matches at once) are
    copied from the same exemplar pixels as the colours."""
    yy, xx = np.mgrid[0:256, 0:256]
    ex = np.dstack([bark, (yy / 255.0)[..., None], ((xx // 32) / 8.0)[..., None]]).astype(np.float32)
    out, src = astuple(quilt(ex, (90, 90), block=40, seed=1, full_output=True))
    assert out.shape == (90, 90, 5)
    assert np.array_equal(out, ex[src[..., 0], src[..., 1]])


def test_progress_is_reported(bark):
    calls = []
    quilt(bark, (100, 100), block=40, overlap=10, progress=lambda d, t: calls.append((d, t)))
    assert calls[-1][0] == calls[-1][1] == len(calls) == 9


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"block": 300}, "block"),
        ({"block": 1}, "block"),
        ({"block": 32, "overlap": 32}, "overlap"),
        ({"overlap": 0}, "overlap"),
        ({"randomness": -1.0}, "randomness"),
        ({"randomness": float("nan")}, "randomness"),
        ({"cost": "sobel"}, "cost"),
        ({"size": (0, 10)}, "size"),
        ({"size": (100000, 100000)}, "size"),
    ],
)
def test_quilt_bad_arguments(bark, kwargs, name):
    args = {"size": (64, 64), **kwargs}
    size = args.pop("size")
    with pytest.raises((ValueError, TypeError), match=f"^{name}"):
        quilt(bark, size, **args)


def test_quilt_rejects_nan(bark):
    ex = bark.copy()
    ex[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="^exemplar"):
        quilt(ex, 64)


def test_seam_module_is_exported():
    assert phloem.seams.seam is seam
