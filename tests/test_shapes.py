"""phloem.shapes: boundary-patch shape synthesis (Rosenberger et al. 2009, thesis §3.6)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import ndimage

import phloem
from phloem import shapes


def blobs(h: int, w: int, seed: int, k: int = 2, sigma: float = 3.0) -> np.ndarray:
    """Smooth random label map: blurred noise cut at quantiles into k labels."""
    rng = np.random.default_rng(seed)
    f = ndimage.gaussian_filter(rng.standard_normal((h, w)), sigma)
    cuts = np.quantile(f, np.linspace(0, 1, k + 1)[1:-1] + rng.uniform(-0.1, 0.1, k - 1))
    return np.digitize(f, np.sort(cuts)).astype(np.int32)


def brute_similarity(a: np.ndarray, b: np.ndarray, p: int, rotations: str) -> float:
    """Eq. 3.7-3.9 by brute force, independent of the Rust code."""

    def boundary(m: np.ndarray) -> np.ndarray:
        d = np.zeros(m.shape, bool)
        d[1:] |= m[1:] != m[:-1]
        d[:-1] |= m[:-1] != m[1:]
        d[:, 1:] |= m[:, 1:] != m[:, :-1]
        d[:, :-1] |= m[:, :-1] != m[:, 1:]
        return np.argwhere(d)

    def patches(m: np.ndarray) -> np.ndarray:
        r = p // 2
        pad = np.pad(m, r, mode="edge")
        return np.array([pad[y : y + p, x : x + p] for y, x in boundary(m)])

    pa, pb = patches(a), patches(b)

    def one_way(x: np.ndarray, y: np.ndarray) -> float:
        turns = [np.rot90(y, t, axes=(1, 2)) for t in range(4 if rotations == "all" else 1)]
        d = np.min([(x[:, None] != t[None]).sum(axis=(2, 3)) for t in turns], axis=0)
        return float(d.min(axis=1).sum())

    return (one_way(pa, pb) + one_way(pb, pa)) / (len(pa) + len(pb))


@pytest.mark.parametrize("rotations", ["all", "none"])
@pytest.mark.parametrize(("k", "p", "seed"), [(2, 7, 0), (2, 5, 1), (3, 7, 2), (4, 3, 3)])
def test_similarity_equals_brute_force(k, p, seed, rotations):
    a = blobs(18, 22, seed, k, sigma=1.5)
    b = blobs(20, 17, seed + 10, k, sigma=2.0)
    got = shapes.shape_similarity(a, b, patch_size=p, rotations=rotations)
    assert got == pytest.approx(brute_similarity(a, b, p, rotations), abs=1e-12)
    assert phloem.metrics.shape_similarity(a, b, patch_size=p, rotations=rotations) == got


def test_similarity_under_rotation_and_flips():
    yy, xx = np.mgrid[:40, :40]
    wedge = (yy > 2 * xx) | ((yy - 30) ** 2 + (xx - 28) ** 2 < 40)
    for t in (1, 2, 3):
        assert shapes.shape_similarity(wedge, np.rot90(wedge, t)) == 0.0
        assert shapes.shape_similarity(wedge, np.rot90(wedge, t), rotations="none") > 0.5
    # A mirror image is no rotation of this shape (Eq. 3.7 minimises over rotations only) ...
    assert shapes.shape_similarity(wedge, np.fliplr(wedge)) > 0.5
    # ... but a rectangle's mirror image is one.
    rect = np.zeros((30, 30), bool)
    rect[5:20, 3:12] = True
    assert shapes.shape_similarity(rect, np.fliplr(rect)) == 0.0
    assert shapes.shape_similarity(rect, rect) == 0.0
    assert shapes.shape_similarity(np.zeros((9, 9)), np.zeros((5, 5))) == 0.0
    assert shapes.shape_similarity(rect, np.zeros((5, 5))) == np.inf


@pytest.mark.parametrize("method", shapes.METHODS)
@pytest.mark.parametrize(("k", "size", "seed"), [(2, (70, 90), 0), (3, 96, 1), (4, (80, 64), 2)])
def test_label_areas_match_the_exemplar(method, k, size, seed):
    ex = blobs(80, 80, seed, k)
    out = shapes.synthesize_labels(ex, size, method=method, patch_size=7, seed=seed)
    assert out.shape == ((size, size) if isinstance(size, int) else size)
    fa = np.bincount(ex.ravel(), minlength=k) / ex.size
    fo = np.bincount(out.ravel(), minlength=k) / out.size
    assert np.abs(fa - fo).max() < 0.03, (fa, fo)


def test_binary_area_mask_and_dtype():
    ex = blobs(64, 64, 5) == 1
    out = shapes.synthesize(ex, (60, 75), patch_size=7, seed=3)
    assert out.dtype == bool and out.shape == (60, 75)
    assert abs(out.mean() - ex.mean()) < 0.01
    mask = np.zeros((60, 75), bool)
    mask[10:50, 5:60] = True
    out = shapes.synthesize(ex, (60, 75), patch_size=7, mask=mask, seed=3)
    assert not out[~mask].any()
    assert abs(out[mask].mean() - ex.mean()) < 0.02


def test_same_seed_same_output_for_any_thread_count():
    ex = blobs(72, 72, 7, 3)
    for method in shapes.METHODS:
        one = shapes.synthesize_labels(ex, 80, method=method, patch_size=7, seed=11, threads=1)
        two = shapes.synthesize_labels(ex, 80, method=method, patch_size=7, seed=11, threads=2)
        np.testing.assert_array_equal(one, two)
        other = shapes.synthesize_labels(ex, 80, method=method, patch_size=7, seed=12, threads=2)
        assert (other != one).mean() > 0.1
    b1 = shapes.synthesize(ex == 1, 64, patch_size=7, seed=1, threads=1)
    np.testing.assert_array_equal(b1, shapes.synthesize(ex == 1, 64, patch_size=7, seed=1, threads=2))


def test_output_is_shaped_like_the_exemplar():
    ex = blobs(96, 96, 8, 2, sigma=4.0)
    out = shapes.synthesize_labels(ex, 96, method="joint", patch_size=7, seed=2)
    rng = np.random.default_rng(0)
    frac = ex.mean()
    noise = (rng.random(ex.shape) < frac).astype(np.int32)
    smooth = ndimage.gaussian_filter(rng.standard_normal(ex.shape), 1.5)
    blurred = (smooth > np.quantile(smooth, 1 - frac)).astype(np.int32)
    s_out = shapes.shape_similarity(ex, out)
    assert s_out < 0.25 * shapes.shape_similarity(ex, noise)
    assert s_out < 0.6 * shapes.shape_similarity(ex, blurred)


def test_tileable_output_has_no_seam():
    ex = blobs(80, 80, 9, 2, sigma=3.0)
    out = shapes.synthesize_labels(ex, 64, method="joint", patch_size=7, tileable=True, seed=4)
    rolled = np.roll(out, (32, 32), axis=(0, 1))
    assert shapes.shape_similarity(ex, rolled) < 1.25 * shapes.shape_similarity(ex, out) + 0.1


def test_label_values_order_and_layer_order():
    ex = blobs(64, 64, 3, 3)
    values = np.array([7, -2, 30])[ex]
    order = shapes.layer_order(values)
    assert sorted(order) == [-2, 7, 30]
    # blobs() cuts one smooth field at two levels: the middle label (1, here -2) separates
    # the others, so it is the middle layer.
    assert order[1] == -2
    counts = {v: (values == v).sum() for v in (7, 30)}
    assert counts[order[0]] >= counts[order[2]]
    for method, kw in [("layered", {"order": [30, 7, -2]}), ("joint", {})]:
        out = shapes.synthesize_labels(values, 48, method=method, patch_size=5, seed=0, **kw)
        assert out.dtype == np.int32
        assert set(np.unique(out)) == {-2, 7, 30}


def test_progress_is_reported_and_can_stop_the_run():
    ex = blobs(48, 48, 1, 3)
    seen: list[tuple[int, int]] = []
    shapes.synthesize_labels(
        ex, 48, method="layered", patch_size=5, levels=2, iterations=2, progress=lambda d, t: seen.append((d, t))
    )
    assert seen[-1] == (2 * 2 * 2, 2 * 2 * 2)
    assert all(b >= a for (a, _), (b, _) in itertools.pairwise(seen))

    def stop(done: int, total: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        shapes.synthesize(ex == 1, 48, patch_size=5, progress=stop)


def test_errors_name_the_argument():
    ex = blobs(32, 32, 0, 3)
    with pytest.raises(ValueError, match="^shape"):
        shapes.synthesize(np.zeros((20, 20), bool), 32)
    with pytest.raises(ValueError, match="^shape"):
        shapes.synthesize(np.ones((20, 20)), 32)
    with pytest.raises(ValueError, match="^shape"):
        shapes.synthesize(np.zeros((4, 20, 20)), 32)
    with pytest.raises(ValueError, match="^shape"):
        shapes.synthesize(np.array([[0.0, np.nan], [1.0, 0.0]]), 32)
    with pytest.raises(TypeError, match="^shape"):
        shapes.synthesize(np.zeros((20, 20), complex), 32)
    with pytest.raises(ValueError, match="^shape"):
        shapes.synthesize(ex[:6, :6] == 1, 32, patch_size=7)
    with pytest.raises(ValueError, match="^patch_size"):
        shapes.synthesize(ex == 1, 32, patch_size=6)
    with pytest.raises(ValueError, match="^patch_size"):
        shapes.synthesize(ex == 1, 32, patch_size=13)
    with pytest.raises(ValueError, match="^patch_size"):
        shapes.shape_similarity(ex, ex, patch_size=4)
    with pytest.raises(ValueError, match="^size"):
        shapes.synthesize(ex == 1, (5, 40), patch_size=7)
    with pytest.raises(ValueError, match="^mask"):
        shapes.synthesize(ex == 1, 40, mask=np.ones((10, 10), bool))
    with pytest.raises(ValueError, match="^levels"):
        shapes.synthesize(ex == 1, 40, patch_size=7, levels=5)
    with pytest.raises(ValueError, match="^iterations"):
        shapes.synthesize(ex == 1, 40, iterations=0)
    with pytest.raises(ValueError, match="^method"):
        shapes.synthesize_labels(ex, 40, method="stacked")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^order"):
        shapes.synthesize_labels(ex, 40, order=[0, 1, 1])
    with pytest.raises(ValueError, match="^order"):
        shapes.synthesize_labels(ex, 40, order=[0, 1])
    with pytest.raises(ValueError, match="^order"):
        shapes.synthesize_labels(ex, 40, method="joint", order=[0, 1, 5])
    with pytest.raises(ValueError, match="^labels"):
        shapes.synthesize_labels(np.full((20, 20), 3), 40)
    with pytest.raises(ValueError, match="^labels"):
        shapes.synthesize_labels(np.arange(400).reshape(20, 20) % 65, 40)
    with pytest.raises(ValueError, match="^labels"):
        shapes.synthesize_labels(np.array([[0.0, np.nan], [1.0, 2.0]]), 40)
    with pytest.raises(ValueError, match="^threads"):
        shapes.synthesize(ex == 1, 40, threads=0)


THESIS_RUNS = ["bark1", "bark2", "eucalyptus", "eucap5"]


def thesis_map(run: str, name: str) -> np.ndarray:
    from phloem.testing import shared_file

    img = phloem.io.read_image(shared_file("bark", "thesis_runs", run, f"{name}.png"))
    flat = np.round(img.reshape(img.shape[0], img.shape[1], -1) * 255).astype(np.int32)
    _, inv = np.unique(flat.reshape(-1, flat.shape[2]), axis=0, return_inverse=True)
    return inv.reshape(flat.shape[:2]).astype(np.int32)


@pytest.mark.shared
@pytest.mark.parametrize("method", shapes.METHODS)
@pytest.mark.parametrize("run", THESIS_RUNS)
def test_thesis_runs_no_worse_than_the_thesis(run, method):
    # phloem's output from a at b's size is at least as close to a (Eq. 3.9) as the thesis'
    # own output b. Seed 0 is deterministic; seeds 1-3 also pass (tightest: layered on
    # eucalyptus, 2.33 against 2.36, and on eucap5, 5.87 against 5.94).
    a, b = thesis_map(run, "a"), thesis_map(run, "b")
    out = shapes.synthesize_labels(a, b.shape, method=method, seed=0)
    assert shapes.shape_similarity(a, out) <= shapes.shape_similarity(a, b)


def _scale_ratio(a: np.ndarray, b: np.ndarray) -> float:
    ca, cb = shapes.chord_length(a), shapes.chord_length(b)
    return max(ca, cb) / min(ca, cb)


def test_chord_length():
    assert shapes.chord_length(np.zeros((5, 7))) == pytest.approx((7 * 7 * 5 + 5 * 5 * 7) / 70)
    checker = np.indices((6, 6)).sum(axis=0) % 2
    assert shapes.chord_length(checker) == 1.0
    assert shapes.chord_length(checker) == shapes.chord_length(checker == 1)


@pytest.mark.parametrize("seed", [0, 1])
def test_output_keeps_the_exemplar_blob_scale(seed):
    # Large smooth blobs (chord length ~30 px) must not come out as small ones: the pyramid
    # starts where a patch covers a whole blob.
    ex = blobs(160, 160, seed, sigma=10.0)
    out = shapes.synthesize(ex, 160, seed=seed)
    assert _scale_ratio(ex, out) <= 1.5
    ex3 = blobs(160, 160, seed, k=3, sigma=10.0)
    out3 = shapes.synthesize_labels(ex3, 160, method="joint", seed=seed)
    assert _scale_ratio(ex3, out3) <= 1.5


def _vertical_share(m: np.ndarray) -> float:
    """Share of label changes between horizontal neighbours (edges that run vertically)."""
    across = float((m[:, 1:] != m[:, :-1]).sum())
    along = float((m[1:] != m[:-1]).sum())
    return across / (across + along)


def test_rotations_keep_a_vertical_input_vertical():
    yy, xx = np.mgrid[:128, :128]
    rng = np.random.default_rng(3)
    ex = np.zeros((128, 128), bool)
    for cy, cx in rng.uniform(0, 128, (14, 2)):  # tall thin ellipses, like bark furrows
        ex |= ((yy - cy) / 30.0) ** 2 + ((xx - cx) / 5.0) ** 2 < 1
    assert _vertical_share(ex) > 0.8
    for rot in ("none", "half"):
        out = shapes.synthesize(ex, 128, patch_size=9, rotations=rot, seed=0)
        assert _vertical_share(out) > 0.7, rot
        lab = shapes.synthesize_labels(
            ex.astype(int) + (yy > 64) * (xx > 100), 128, method="joint", patch_size=9, rotations=rot, seed=0
        )
        assert _vertical_share(lab) > 0.6, rot
    # With all four turns a furrow's patch also matches its quarter turn; only print it.
    out = shapes.synthesize(ex, 128, patch_size=9, rotations="all", seed=0)
    print("vertical share with rotations='all':", _vertical_share(out))


def test_rotations_half_is_between_none_and_all():
    yy, xx = np.mgrid[:32, :32]
    a = yy > 2 * xx
    assert shapes.shape_similarity(a, np.rot90(a, 2), rotations="half") == 0.0
    assert shapes.shape_similarity(a, np.rot90(a), rotations="half") > 0
    assert shapes.shape_similarity(a, np.rot90(a, 2), rotations="none") > 0
    for bad in ("full", 2, None):
        with pytest.raises(ValueError, match="^rotations"):
            shapes.synthesize(a, 32, rotations=bad)
        with pytest.raises(ValueError, match="^rotations"):
            shapes.synthesize_labels(a, 32, rotations=bad)
        with pytest.raises(ValueError, match="^rotations"):
            shapes.shape_similarity(a, a, rotations=bad)


@pytest.mark.shared
@pytest.mark.parametrize("run", THESIS_RUNS)
def test_thesis_runs_keep_the_blob_scale(run):
    # The joint method's output keeps the input's chord length within 1.5x (seed 0: bark1
    # 55.5 vs 68.4, bark2 74.6/77.3, eucalyptus 60.9/81.1, eucap5 40.9/44.3). The layered
    # method is still about half the input's scale (36/68, 39/77, 32/81, 16/44): a deeper
    # pyramid fixes its scale but loses it Eq. 3.9 on eucalyptus.
    a, b = thesis_map(run, "a"), thesis_map(run, "b")
    out = shapes.synthesize_labels(a, b.shape, method="joint", seed=0)
    assert _scale_ratio(a, out) <= 1.5
