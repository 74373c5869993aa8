"""phloem.patch: PatchMatch against exact search, masks, determinism, k-NN, voting, errors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import phloem
from phloem.patch import candidates, knn, nnf, vote


def _crops(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two different crops of one texture: they share no coherent structure."""
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[0] >= 256:
        src, tgt = img[:128, :128], img[128:256, 100:228]
    else:
        src, tgt = img[:, :64], img[:, 64:]
    return np.ascontiguousarray(src), np.ascontiguousarray(tgt)


# Mean distance of a 5-iteration field over the exact one, measured (seed 1) and given ~2-3 %
# headroom. Plain PatchMatch shines where target and source share coherent structure (see
# test_crop_is_found_exactly); between two unrelated crops it relies on random search, which
# even 100 iterations leave 3-9 % above exact, and coarse-to-fine levels do not help.
# Enrichment (Generalized PatchMatch) closes most of the gap; kd-tree seeding (He & Sun
# 2012) closes it: the goal of 1.05 is met by method="kdtree" on every texture.
RATIO = {  # texture: (plain, enrich=8, kdtree); measured 1.310/1.085/1.027, 1.152/1.045/1.007, 1.248/1.062/1.013
    "bark": (1.34, 1.11, 1.04),
    "water": (1.18, 1.07, 1.02),
    "gravel": (1.28, 1.09, 1.03),
}
VARIANTS = {"plain": {}, "enrich8": {"enrich": 8}, "kdtree": {"method": "kdtree"}}


@pytest.fixture(scope="module")
def exact_fields(request):
    cache = {}

    def get(name):
        if name not in cache:
            src, tgt = _crops(request.getfixturevalue(name))
            cache[name] = (src, tgt, nnf(src, tgt, method="exact")[1])
        return cache[name]

    return get


@pytest.mark.parametrize("name", sorted(RATIO))
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_patchmatch_close_to_exact_on_real_textures(name, variant, exact_fields):
    src, tgt, d_ex = exact_fields(name)
    _, d_pm = nnf(src, tgt, patch_size=7, iterations=5, seed=1, **VARIANTS[variant])
    assert (d_pm >= d_ex - 1e-4 * np.maximum(d_ex, 1)).all(), "PatchMatch beat exact search: exact is wrong"
    ratio = float(d_pm.mean() / d_ex.mean())
    assert ratio <= RATIO[name][list(VARIANTS).index(variant)], ratio


def test_more_iterations_get_closer_to_exact(exact_fields):
    src, tgt, d_ex = exact_fields("water")
    ratios = [nnf(src, tgt, iterations=it, seed=1)[1].mean() / d_ex.mean() for it in (1, 3, 10, 30)]
    assert all(a > b for a, b in itertools.pairwise(ratios)), ratios


def test_exact_matches_numpy_brute_force(bark):
    src, tgt, p = bark[:20, :24], bark[100:112, 50:61], 5
    _field, dist = nnf(src, tgt, patch_size=p, method="exact")
    r = p // 2
    tpad = np.pad(tgt, ((r, r), (r, r), (0, 0)), constant_values=np.nan)
    for ty in range(tgt.shape[0]):
        for tx in range(tgt.shape[1]):
            tp = tpad[ty : ty + p, tx : tx + p]
            valid = ~np.isnan(tp)
            best = min(
                float(((np.where(valid, tp, 0) - src[sy - r : sy + r + 1, sx - r : sx + r + 1]) ** 2 * valid).sum())
                for sy in range(r, src.shape[0] - r)
                for sx in range(r, src.shape[1] - r)
            )
            assert dist[ty, tx] == pytest.approx(best, rel=1e-4, abs=1e-5)


def test_crop_is_found_exactly(bark):
    tgt = bark[40:100, 30:110]
    field, _dist = nnf(bark, tgt, seed=3)
    ys, xs = np.mgrid[40:100, 30:110]
    hits = (field[..., 0] == ys) & (field[..., 1] == xs)
    assert hits[3:-3, 3:-3].mean() > 0.99


@given(
    sh=st.integers(7, 30), sw=st.integers(7, 30), th=st.integers(1, 25), tw=st.integers(1, 25),
    p=st.sampled_from([1, 3, 5, 7]), seed=st.integers(0, 2**32), levels=st.integers(1, 3),
    method=st.sampled_from(["patchmatch", "kdtree"]),
)  # fmt: skip
def test_offsets_in_bounds_and_inside_source_mask(sh, sw, th, tw, p, seed, levels, method):
    rng = np.random.default_rng(seed)
    src = rng.random((sh, sw, 2), dtype=np.float32)
    tgt = rng.random((th, tw, 2), dtype=np.float32)
    smask = rng.random((sh, sw)) < 0.5
    r = p // 2
    smask[sh // 2, sw // 2] = sh > 2 * r and sw > 2 * r  # at least one usable centre when possible
    if not smask[r : sh - r, r : sw - r].any():
        with pytest.raises(ValueError, match="source_mask"):
            nnf(src, tgt, patch_size=p, source_mask=smask)
        return
    field, dist = nnf(src, tgt, patch_size=p, source_mask=smask, seed=seed, levels=levels, method=method)
    assert field.shape == (th, tw, 2) and field.dtype == np.int32
    ys, xs = field[..., 0], field[..., 1]
    assert ((ys >= r) & (ys < sh - r) & (xs >= r) & (xs < sw - r)).all()
    assert smask[ys, xs].all()
    assert np.isfinite(dist).all() and (dist >= 0).all()


def test_target_mask_leaves_other_pixels_unmatched(bark):
    tmask = np.zeros((50, 60), bool)
    tmask[10:20, 5:50] = True
    field, dist = nnf(bark[:64, :64], bark[100:150, 100:160], target_mask=tmask)
    assert (field[~tmask] == -1).all() and np.isinf(dist[~tmask]).all()
    assert (field[tmask] >= 3).all() and np.isfinite(dist[tmask]).all()


@pytest.mark.parametrize("method", ["patchmatch", "kdtree", "exact"])
def test_same_seed_bit_identical_with_1_and_2_threads(water, method):
    src, tgt = water[:96, :96], water[150:250, 120:230]
    kw = dict(patch_size=7, seed=11, levels=2, method=method)
    if method == "exact":
        src, tgt = src[:40, :40], tgt[:30, :30]
    f1, d1 = nnf(src, tgt, threads=1, **kw)
    f2, d2 = nnf(src, tgt, threads=2, **kw)
    assert np.array_equal(f1, f2)
    assert np.array_equal(d1.view(np.uint32), d2.view(np.uint32))


def test_different_seeds_differ_but_both_converge(water):
    src, tgt = water[:96, :96], water[150:250, 120:230]
    f1, d1 = nnf(src, tgt, seed=1)
    f2, d2 = nnf(src, tgt, seed=2)
    assert not np.array_equal(f1, f2)
    assert abs(d1.mean() - d2.mean()) < 0.05 * d1.mean()


def test_given_init_is_kept_when_optimal(bark):
    src, tgt = bark[:40, :40], bark[60:80, 60:90]
    exact, d_ex = nnf(src, tgt, patch_size=5, method="exact")
    _field, dist = nnf(src, tgt, patch_size=5, init=exact, iterations=3, seed=9)
    np.testing.assert_allclose(dist, d_ex, rtol=1e-5)


def test_weights_zero_out_a_channel(bark):
    src = bark[:48, :48].copy()
    tgt = bark[:48, :48].copy()
    tgt[..., 2] = 1.0 - tgt[..., 2]  # channel 2 differs everywhere
    _, d = nnf(src, tgt, weights=[1, 1, 0], method="exact", patch_size=5)
    assert d[2:-2, 2:-2].max() == 0.0
    _, d = nnf(src, tgt, weights=[1, 1, 1], method="exact", patch_size=5)
    assert d[2:-2, 2:-2].min() > 0.0


def test_knn_exact_agrees_with_numpy(gravel):
    ex, p, k = gravel[:18, :20], 3, 3
    idx, dist = knn(ex, k, patch_size=p, exact=True, exclude=1)
    pad = np.pad(ex, 1, mode="reflect")
    patches = np.lib.stride_tricks.sliding_window_view(pad, (p, p)).reshape(ex.size, -1)
    d_all = ((patches[:, None, :] - patches[None, :, :]) ** 2).sum(-1)
    ys, xs = np.divmod(np.arange(ex.size), ex.shape[1])
    near = (np.abs(ys[:, None] - ys[None]) <= 1) & (np.abs(xs[:, None] - xs[None]) <= 1)
    d_all[near] = np.inf
    ref = np.sort(d_all, axis=1)[:, :k].reshape(*ex.shape, k)
    np.testing.assert_allclose(dist, ref, rtol=1e-4, atol=1e-6)
    assert (
        np.maximum(
            np.abs(idx[..., 0] - ys.reshape(ex.shape)[..., None]), np.abs(idx[..., 1] - xs.reshape(ex.shape)[..., None])
        )
        > 1
    ).all()


def test_knn_approximate_close_to_exact(water):
    ex = water[:48, :48]
    _, d_ex = knn(ex, 4, patch_size=5, exact=True)
    _, d_ap = knn(ex, 4, patch_size=5, iterations=8, seed=2)
    assert d_ap.mean() <= 1.10 * d_ex.mean()
    assert (np.diff(d_ap, axis=-1) >= 0).all()


def test_knn_thread_independent(water):
    ex = water[:40, :50]
    a = knn(ex, 3, patch_size=5, threads=1, seed=4)
    b = knn(ex, 3, patch_size=5, threads=2, seed=4)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_candidates_contain_forward_shifts_and_neighbours():
    eh, ew = 20, 20
    refs = np.stack(np.mgrid[5:10, 7:12], axis=-1).astype(np.int32)  # a copied 5x5 block
    cands = candidates(refs, (eh, ew), patch_size=3)
    # A coherent block: every pixel's only candidate is its own reference.
    assert (cands[:, :, 0] == refs).all() and (cands[:, :, 1:] == -1).all()
    nb = np.full((eh, ew, 1, 2), 0, np.int32)
    nb[..., 0, 0], nb[..., 0, 1] = 1, 2  # every pixel's neighbour is (1, 2)
    cands = candidates(refs, (eh, ew), patch_size=3, neighbours=nb)
    assert (cands[:, :, 1] == [1, 2]).all() and (cands[:, :, 2:] == -1).all()


def test_candidates_wrap():
    # A coherent pair: pixel (0, 0)'s own reference comes first in its set.
    refs = np.array([[[0, 0], [0, 1]]], np.int32)
    assert (candidates(refs, (4, 4), patch_size=3)[0, 0, 0] == [0, 0]).all()
    # A reference at column 0 shifted left leaves the exemplar: dropped without wrap, wrapped to 3 with.
    refs2 = np.array([[[2, 2], [2, 0]]], np.int32)
    assert not (candidates(refs2, (4, 4), patch_size=3)[0, 0] == [2, 3]).all(-1).any()
    assert (candidates(refs2, (4, 4), patch_size=3, wrap=True)[0, 0] == [2, 3]).all(-1).any()


def test_vote_identity_reproduces_source(bark):
    src = bark[:32, :40]
    ys, xs = np.mgrid[0:32, 0:40]
    field = np.stack([np.clip(ys, 3, 28), np.clip(xs, 3, 36)], -1).astype(np.int32)
    inner = (ys >= 3) & (ys <= 28) & (xs >= 3) & (xs <= 36)
    field[~inner] = -1
    out, w = vote(src, field, patch_size=7)
    np.testing.assert_allclose(out, src, atol=1e-6)
    assert (w > 0).all()
    # Votes that agree stay put under mean-shift.
    np.testing.assert_allclose(vote(src, field, patch_size=7, mean_shift=3)[0], src, atol=1e-6)


def test_vote_mean_shift_takes_the_majority_side():
    src = np.zeros((3, 9, 1), np.float32)
    src[:, 5:] = 1.0  # columns 0..4 hold 0, columns 5..8 hold 1
    field = np.array([[[1, 1], [1, 7]]], np.int32)  # pixel 0 matched to zeros, pixel 1 to ones
    weights = np.array([[3.0, 1.0]], np.float32)
    mean, _ = vote(src, field, patch_size=3, weights=weights)
    assert mean[0, 0, 0] == pytest.approx(0.25)
    shifted, _ = vote(src, field, patch_size=3, weights=weights, mean_shift=3)
    assert shifted[0, 0, 0] < 0.05
    assert np.array_equal(vote(src, field, patch_size=3, weights=weights, mean_shift=0)[0], mean)
    with pytest.raises(ValueError, match="mean_shift"):
        vote(src, field, patch_size=3, mean_shift=-1)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(patch_size=4), "patch_size"),
        (dict(patch_size=0), "patch_size"),
        (dict(patch_size=99), "patch_size"),
        (dict(method="fast"), "method"),
        (dict(iterations=-1), "iterations"),
        (dict(weights=[1, 2]), "weights"),
        (dict(weights=[1, -2, 1]), "weights"),
        (dict(source_mask=np.zeros((32, 32), bool)), "source_mask"),
        (dict(source_mask=np.ones((5, 5), bool)), "source_mask"),
        (dict(target_mask=np.zeros((20, 20), bool)), "target_mask"),
        (dict(init=np.zeros((20, 20, 2), np.int32)), "init"),
        (dict(seed=-1), "seed"),
        (dict(threads=0), "threads"),
    ],
)
def test_bad_arguments_name_the_argument(bark, kwargs, name):
    with pytest.raises((ValueError, TypeError), match=name):
        nnf(bark[:32, :32], bark[:20, :20], **kwargs)


@pytest.mark.parametrize(
    ("source", "target", "name"),
    [
        (np.zeros((8, 8, 3, 1), np.float32), np.zeros((8, 8, 3), np.float32), "source"),
        (np.zeros((8,), np.float32), np.zeros((8, 8, 3), np.float32), "source"),
        (np.zeros((8, 8, 3), np.float32), np.zeros((0, 8, 3), np.float32), "target"),
        (np.zeros((8, 8, 3), np.float32), np.zeros((8, 8, 4), np.float32), "target"),
        (np.zeros((8, 8, 3), np.complex64), np.zeros((8, 8, 3), np.float32), "source"),
        (np.zeros((8, 8, 3), bool), np.zeros((8, 8, 3), np.float32), "source"),
        (np.full((8, 8, 3), np.nan, np.float32), np.zeros((8, 8, 3), np.float32), "source"),
        (np.zeros((8, 8, 3), np.float32), np.full((8, 8, 3), np.inf), "target"),
    ],
)
def test_bad_images_name_the_argument(source, target, name):
    with pytest.raises((ValueError, TypeError), match=name):
        nnf(source, target, patch_size=3)


def test_enrich_table_outside_the_source_is_named(bark):
    table, _ = knn(bark[:32, :32], 2, patch_size=5)
    table[3, 4, 1] = (5, 32)  # one column past the source
    with pytest.raises(ValueError, match="source_knn"):
        nnf(bark[:32, :32], bark[:20, :20], patch_size=5, enrich=table)


def test_exact_search_refuses_hours_of_work():
    big = np.zeros((600, 600), np.float32)
    with pytest.raises(ValueError, match="patchmatch"):
        nnf(big, big, method="exact")


def test_any_real_dtype_and_layout_is_accepted(bark):
    u8 = (bark[:40, :40] * 255).round().astype(np.uint8)
    f_u8, _ = nnf(u8, u8[5:25, 5:25], method="exact", patch_size=5)
    fortran = np.asfortranarray(u8.astype(np.float64) / 255)
    f_f, _ = nnf(fortran, fortran[5:25, 5:25], method="exact", patch_size=5)
    assert np.array_equal(f_u8, f_f)


def test_version_matches_the_package_metadata():
    from importlib.metadata import version

    assert phloem.__version__ == version("phloem")


@pytest.mark.shared
def test_patchmatch_close_to_exact_on_shared_grass():
    from phloem.testing import shared_file

    grass = phloem.io.read_image(shared_file("textures", "skimage_grass.png"))[..., None]
    src, tgt = np.ascontiguousarray(grass[:128, :128]), np.ascontiguousarray(grass[200:328, 300:428])
    _, d_ex = nnf(src, tgt, method="exact")
    # Measured 1.254 (plain), 1.140 (enrich=8) and 1.029 (kdtree); see RATIO above.
    for kw, limit in (({}, 1.28), ({"enrich": 8}, 1.17), ({"method": "kdtree"}, 1.05)):
        ratio = nnf(src, tgt, iterations=5, seed=1, **kw)[1].mean() / d_ex.mean()
        assert ratio <= limit, (kw, ratio)


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs os.fork")
@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded:DeprecationWarning")
def test_forked_child_can_use_the_thread_pools(bark):
    # The parent builds and caches a 2-thread pool; a forked child inherits the cache but not
    # the threads. Without phloem's at-fork hook the child's call hangs (killed by the timeout).
    import multiprocessing as mp

    src = np.ascontiguousarray(bark[:64, :64])
    expected, _ = nnf(src, src[8:40, 8:40], threads=2, seed=3)
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        got = pool.apply_async(_nnf_in_child, (src,)).get(timeout=60)
    assert np.array_equal(got, expected)


def _nnf_in_child(src):
    return nnf(src, src[8:40, 8:40], threads=2, seed=3)[0]


def test_concurrent_calls_get_workers_of_their_own(bark):
    # A call checks a pool out for its duration. Here a one-thread shape synthesis waits,
    # inside its progress callback (so while holding its pool), for a one-thread nnf call made
    # from another Python thread. Had the two calls shared one cached one-thread pool, nnf
    # would queue behind the synthesis and the wait would time out.
    import threading

    from phloem import shapes

    src = np.ascontiguousarray(bark[:64, :64])
    expected, _ = nnf(src, src[8:40, 8:40], threads=1, seed=3)
    got: list[np.ndarray] = []
    done = threading.Event()

    def other() -> None:
        got.append(nnf(src, src[8:40, 8:40], threads=1, seed=3)[0])
        done.set()

    waited: list[bool] = []
    worker = threading.Thread(target=other)

    def progress(i: int, n: int) -> None:
        if not waited:
            worker.start()
            waited.append(done.wait(timeout=20))
            if not waited[0]:  # cancel the synthesis, freeing its pool for nnf
                raise TimeoutError("nnf queued behind the running call")

    ex = np.zeros((48, 48), bool)
    ex[10:30, 12:20] = True
    try:
        shapes.synthesize(ex, (48, 48), patch_size=7, seed=0, threads=1, progress=progress)
    finally:
        worker.join()
    assert waited == [True]
    assert np.array_equal(got[0], expected)


@pytest.mark.parametrize("shape", [(0, 5, 2), (5, 0, 2), (0, 0, 2)])
def test_vote_refuses_an_empty_field(shape):
    src = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match=r"^field: expected a non-empty field"):
        vote(src, np.zeros(shape, np.int32), patch_size=3)
