"""tileable=True for synthesize, quilt and complete: outputs whose wrap is an ordinary line.

The measure is :func:`phloem.metrics.wrap_seam`: the neighbour difference across the lines
where a 2×2 tiling of the output joins, over the mean across the output's interior lines.
Bark (embedded, strongly oriented furrows) scores about 2–2.5 without the option, about 1
with it (docs/results.md).
"""

from __future__ import annotations

import numpy as np
import pytest

from phloem import patch
from phloem.metrics import wrap_seam
from phloem.texture import complete, quilt, synthesize

#: The brief's bound: the wrap at most ~1.5× an interior line.
WRAP_BOUND = 1.5
#: Without the option the wrap must be clearly worse than that.
PLAIN_FLOOR = 1.8


@pytest.fixture(scope="module")
def exemplar(bark):
    return np.ascontiguousarray(bark[:128, :128])


@pytest.mark.parametrize("seed", [0, 3])
def test_synthesize_tileable_has_no_seam_at_the_wrap(exemplar, seed):
    tiled = synthesize(exemplar, (96, 112), tileable=True, seed=seed)
    plain = synthesize(exemplar, (96, 112), seed=seed)
    assert tiled.shape == plain.shape == (96, 112, 3)
    assert wrap_seam(tiled) <= WRAP_BOUND, wrap_seam(tiled)
    assert wrap_seam(plain) >= PLAIN_FLOOR, wrap_seam(plain)
    # The 2×2 tiling joins like any interior line: the wrap rows differ no more than the
    # 95th percentile of the interior's neighbouring rows.
    t = np.tile(tiled, (2, 2, 1))
    rows = np.abs(np.diff(t, axis=0)).mean(axis=(1, 2))
    assert rows[95] <= np.percentile(rows[np.arange(rows.size) % 96 != 95], 95)


@pytest.mark.parametrize("seed", [0, 3])
def test_quilt_tileable_has_no_seam_at_the_wrap(exemplar, seed):
    res = quilt(exemplar, (96, 104), block=32, tileable=True, seed=seed, full_output=True)
    plain = quilt(exemplar, (96, 104), block=32, seed=seed)
    assert res.texture.shape == plain.shape == (96, 104, 3)
    assert wrap_seam(res.texture) <= WRAP_BOUND, wrap_seam(res.texture)
    assert wrap_seam(plain) >= PLAIN_FLOOR, wrap_seam(plain)
    # Still a pure copy: every output pixel is the exemplar pixel its source names.
    src = res.sources
    assert (src >= 0).all()
    np.testing.assert_array_equal(res.texture, exemplar[src[..., 0], src[..., 1]])


def test_quilt_cuts_the_last_block_into_the_first_across_the_wrap(exemplar):
    # Across the wrap the output must continue one exemplar piece (the seam between the last
    # and the first block lies inside their overlap, elsewhere): the pixels left and right of
    # the wrap line come from neighbouring exemplar pixels almost everywhere. Without the
    # option they never do.
    def continued(res):
        s = res.sources
        across_x = ((s[:, 0] - s[:, -1]) == [0, 1]).all(-1).mean()
        across_y = ((s[0] - s[-1]) == [1, 0]).all(-1).mean()
        return min(float(across_x), float(across_y))

    for seed in (0, 1):
        kw = {"block": 32, "overlap": 8, "seed": seed, "full_output": True}
        assert continued(quilt(exemplar, (64, 100), tileable=True, **kw)) > 0.9
        assert continued(quilt(exemplar, (64, 100), **kw)) < 0.1


def test_tileable_outputs_are_identical_for_any_thread_count(exemplar):
    a = synthesize(exemplar, 72, tileable=True, seed=2, threads=1)
    b = synthesize(exemplar, 72, tileable=True, seed=2, threads=2)
    np.testing.assert_array_equal(a, b)
    q1 = quilt(exemplar, 72, block=24, tileable=True, seed=2, threads=1)
    q2 = quilt(exemplar, 72, block=24, tileable=True, seed=2, threads=2)
    np.testing.assert_array_equal(q1, q2)


@pytest.fixture(scope="module")
def tile(exemplar):
    """A 96² bark tile that really tiles (the completion tests' torus)."""
    out = synthesize(exemplar, 96, tileable=True, seed=7)
    assert wrap_seam(out) <= WRAP_BOUND
    return out


def _band(shape, rows, cols):
    m = np.zeros(shape, bool)
    m[np.ix_(rows, cols)] = True
    return m


@pytest.mark.parametrize("seed", [0, 3])
def test_complete_tileable_fills_a_hole_across_the_border_seamlessly(tile, seed):
    # A band of 24 columns centred on the left/right wrap, over rows 24…71. Measured (seeds
    # 0–3): 0.88–1.03 with the wrap, 1.57–2.24 without (docs/engines/completion.md).
    rows, cols = np.arange(24, 72), np.r_[84:96, 0:12]
    hole = _band(tile.shape[:2], rows, cols)
    wrapped = complete(tile, hole, tileable=True, seed=seed)
    plain = complete(tile, hole, seed=seed)
    np.testing.assert_array_equal(wrapped[~hole], tile[~hole])

    def seam(img):  # column wrap over the hole's rows vs the median interior column there
        d = np.abs(np.roll(img[rows], -1, 1) - img[rows]).mean(axis=(0, 2))
        return d[-1] / np.median(d[:-1])

    assert seam(wrapped) <= WRAP_BOUND, seam(wrapped)
    assert seam(plain) >= WRAP_BOUND, seam(plain)


def test_complete_tileable_takes_context_from_the_opposite_side(tile):
    # Left half normal bark, right half darkened: on the torus, the right half's dark
    # bark touches column 0 across the wrap. A hole on columns 0…9 must continue the dark
    # bark at its left (wrapped) side; without wrap it only sees normal bark.
    img = tile.copy()
    img[:, 48:] *= 0.35
    hole = _band(img.shape[:2], np.arange(96), np.arange(10))
    wrapped = complete(img, hole, tileable=True, seed=1)
    plain = complete(img, hole, seed=1)
    dark, light = float(img[:, 60:90].mean()), float(img[:, 14:40].mean())
    edge = np.s_[:, 0:3]
    assert abs(float(wrapped[edge].mean()) - dark) < abs(float(wrapped[edge].mean()) - light)
    assert abs(float(plain[edge].mean()) - light) < abs(float(plain[edge].mean()) - dark)


def test_complete_tileable_fills_the_four_corners_as_one_hole(tile):
    # A 20×20 hole around the corner of the torus: four pieces of one hole on the image.
    hole = np.zeros(tile.shape[:2], bool)
    hole[np.ix_(np.r_[86:96, 0:10], np.r_[86:96, 0:10])] = True
    a = complete(tile, hole, tileable=True, seed=3, threads=1)
    b = complete(tile, hole, tileable=True, seed=3, threads=2)
    np.testing.assert_array_equal(a, b)
    assert wrap_seam(a) <= WRAP_BOUND
    plain = complete(tile, hole, seed=3)
    span = np.r_[86:96, 0:10]

    def seam(img):  # inside the hole: across the wrap vs across its other lines
        v = img[span][:, span]
        d = (np.abs(np.diff(v, axis=0)).mean(axis=(1, 2)) + np.abs(np.diff(v, axis=1)).mean(axis=(0, 2))) / 2
        return d[9] / np.delete(d, 9).mean()

    assert seam(a) <= WRAP_BOUND, seam(a)
    assert seam(plain) > seam(a) + 0.5, (seam(plain), seam(a))


def test_patch_engine_wraps_the_target(exemplar):
    # nnf on a torus target compares whole patches at the border, and a tileable vote of a
    # field commutes with rolling the field.
    tgt = np.ascontiguousarray(np.roll(exemplar[:40, :48], (9, 13), axis=(0, 1)))
    src = np.ascontiguousarray(np.tile(exemplar[:40, :48], (2, 2, 1)))
    field, dist = patch.nnf(src, tgt, patch_size=5, method="exact", tileable=True)
    assert float(dist.max()) == pytest.approx(0.0, abs=1e-9)
    voted, _ = patch.vote(src, field, patch_size=5, tileable=True)
    np.testing.assert_allclose(voted, tgt, atol=1e-6)
    rolled, _ = patch.vote(src, np.roll(field, (3, 5), axis=(0, 1)), patch_size=5, tileable=True)
    np.testing.assert_array_equal(rolled, np.roll(voted, (3, 5), axis=(0, 1)))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda ex: quilt(ex, (40, 100), block=48, tileable=True), "size: a tileable quilt needs"),
        (lambda ex: synthesize(ex, 0, tileable=True), "size"),
        (lambda ex: complete(ex, np.zeros(ex.shape[:2], bool), tileable=True), "mask: no pixel"),
    ],
)
def test_tileable_bad_input_errors(exemplar, call, match):
    with pytest.raises(ValueError, match=match):
        call(exemplar)


def test_a_tileable_completion_counts_its_grown_source_against_max_memory():
    import phloem

    img = np.random.default_rng(0).random((256, 256, 3), dtype=np.float32)
    hole = np.zeros((256, 256), bool)
    hole[100:120, 100:120] = True
    plain = phloem._memory.complete(img.shape)
    grown = phloem._memory.complete(img.shape, 3)  # patch 7: 3 pixels wrapped round every side
    assert grown - plain == (12 * 3 + 1) * 262 * 262
    budget = plain + 1_000_000
    complete(img, hole, patch_size=7, iterations=1, max_memory=budget)
    with pytest.raises(phloem.MemoryLimitError, match="image"):
        complete(img, hole, patch_size=7, iterations=1, tileable=True, max_memory=budget)
