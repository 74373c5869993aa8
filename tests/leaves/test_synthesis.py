"""Synthesis (§5): random warps, Eq. 7's blend, and new leaves from small synthetic models."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage

from phloem.leaves import LeafModel, blend_fields, random_warp, synthesize
from phloem.leaves import synthesis as synth
from phloem.leaves._fields import sample
from phloem.leaves._rgba import straight

H = W = 96
SCALES = (1.0, 0.8, 1.2)
BACKGROUNDS = ((0.2, 0.6, 0.2), (0.85, 0.8, 0.1), (0.6, 0.2, 0.2))
VEIN = (0.05, 0.3, 0.05)
SPOT = (0.1, 0.1, 0.95)  # only exemplar 2 has blue spots


def _leaf_alpha(scale: float) -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = np.hypot((x - 48) / (30 * scale), (y - 48) / (18 * scale))
    return np.clip((1.0 - r) * 30 * scale, 0.0, 1.0).astype(np.float32)


def _rgba(colour: tuple[float, float, float], alpha: np.ndarray) -> np.ndarray:
    out = np.empty((H, W, 4), np.float32)
    out[..., :3] = colour
    out[..., 3] = alpha
    return out


def _model(n: int = 3, lam: tuple[float, ...] = (1.5, 0.0)) -> LeafModel:
    """Exemplars are the training ellipse scaled about the centre, so the registration
    fields are known exactly; layer 0 a vein along the midrib, layer 1 spots."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    rel = np.stack([xx - 48, yy - 48], axis=2)
    leaves, forward, inverse, background, layers, diss = [], [], [], [], [], []
    train_alpha = _leaf_alpha(1.0)
    for i in range(n):
        s = SCALES[i]
        leaves.append(_rgba(BACKGROUNDS[i], _leaf_alpha(s)))
        forward.append(((s - 1.0) * rel).astype(np.float32))
        inverse.append(((1.0 / s - 1.0) * rel).astype(np.float32))
        background.append(_rgba(BACKGROUNDS[i], train_alpha))
        vein = (np.abs(yy - 48 + (i - 1)) < 2) & (np.abs(xx - 48) < 24)
        rng = np.random.default_rng(i)
        spots = np.zeros((H, W), bool)
        for cy, cx in zip(rng.integers(38, 58, 4), rng.integers(28, 68, 4), strict=True):
            spots |= np.hypot(yy - cy, xx - cx) < 3
        spot_colour = SPOT if i == 2 else (0.45, 0.35, 0.1)
        per_layer, per_d = [], []
        for mask, colour in ((vein, VEIN), (spots, spot_colour)):
            per_layer.append(_rgba(colour, mask.astype(np.float32)))
            per_d.append((ndimage.distance_transform_edt(~mask) / 10.0).astype(np.float32))
        layers.append(per_layer)
        diss.append(per_d)
    return LeafModel(
        training=0,
        order=[1, 2, 3],
        leaves=leaves,
        forward=forward,
        inverse=inverse,
        residual=[0.0, 2.0, 3.0][:n],
        aligned=[_rgba(BACKGROUNDS[i], train_alpha) for i in range(n)],
        masks=[[layer[..., 3] > 0.5 for layer in per] for per in layers],
        dissimilarity=diss,
        layers=layers,
        background=background,
        lam=list(lam),
        delta=[0.5, 0.5],
        objective=[0.8, 0.8],
    )


def _centred(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    out = np.zeros(shape + (4,), np.float32)
    ys, xs = np.nonzero(img[..., 3] > 0.5)
    cy, cx = (ys.min() + ys.max()) // 2, (xs.min() + xs.max()) // 2
    oy, ox = shape[0] // 2 - cy, shape[1] // 2 - cx
    y0, x0 = max(oy, 0), max(ox, 0)
    y1, x1 = min(oy + img.shape[0], shape[0]), min(ox + img.shape[1], shape[1])
    out[y0:y1, x0:x1] = img[y0 - oy : y1 - oy, x0 - ox : x1 - ox]
    return out


def test_sample_reads_the_displaced_pixel() -> None:
    img = np.zeros((5, 6), np.float32)
    img[2, 3] = 1.0
    field = np.zeros((5, 6, 2), np.float32)
    field[..., 0], field[..., 1] = 1.0, -1.0  # (row, col) reads (row - 1, col + 1)
    out = sample(img, field)
    assert out.shape == (5, 6) and out[3, 2] == 1.0 and out.sum() == 1.0
    with pytest.raises(ValueError, match="field"):
        sample(img, np.zeros((5, 5, 2), np.float32))


@pytest.mark.parametrize(("magnitude", "smoothness"), [(6.0, 20.0), (40.0, 5.0), (0.0, 10.0)])
def test_random_warp_is_bounded_and_fold_free(magnitude: float, smoothness: float) -> None:
    f = random_warp((80, 120), magnitude, smoothness=smoothness, seed=4)
    assert f.shape == (80, 120, 2) and f.dtype == np.float32
    norm = np.hypot(f[..., 0], f[..., 1])
    assert norm.max() <= magnitude + 1e-4
    g = np.gradient(f.astype(np.float64), axis=(0, 1))  # d/drow, d/dcol of (dx, dy)
    det = (1 + g[1][..., 0]) * (1 + g[0][..., 1]) - g[0][..., 0] * g[1][..., 1]
    assert det.min() > 0.2
    if magnitude == 6.0:  # a smooth warp reaches its bound; a rough one is capped by the Jacobian
        assert norm.max() >= 0.98 * magnitude
    if magnitude == 40.0:
        # capped by the Jacobian: the slope bound along rows and columns sits exactly at the cap
        gx = np.sqrt((np.diff(f.astype(np.float64), axis=1) ** 2).sum(axis=2)).max()
        gy = np.sqrt((np.diff(f.astype(np.float64), axis=0) ** 2).sum(axis=2)).max()
        assert np.hypot(gx, gy) == pytest.approx(synth.MAX_GRADIENT, rel=1e-4)
        assert norm.max() < 0.5 * magnitude
    assert np.array_equal(f, random_warp((80, 120), magnitude, smoothness=smoothness, seed=4))
    if magnitude > 0:
        assert not np.array_equal(f, random_warp((80, 120), magnitude, smoothness=smoothness, seed=5))


def test_eq7_blend_is_a_pointwise_convex_combination() -> None:
    fields = [random_warp((64, 80), 10.0, smoothness=15.0, seed=i) for i in range(3)]
    out = blend_fields(fields, seed=2, smoothness=20.0)
    stack = np.stack(fields)
    assert (out >= stack.min(axis=0) - 1e-4).all() and (out <= stack.max(axis=0) + 1e-4).all()
    a = synth._coefficients(3, (64, 80), smoothness=20.0, seed=2)
    assert (a >= 0).all() and np.allclose(a.sum(axis=2), 1.0, atol=1e-5)
    assert np.allclose(out, np.einsum("hwi,ihwc->hwc", a, stack), atol=1e-4)
    assert (a.max(axis=(0, 1)) - a.min(axis=(0, 1)) > 0.2).all()  # a map, not one global weight
    assert not np.array_equal(out, blend_fields(fields, seed=3, smoothness=20.0))
    with pytest.raises(ValueError, match="fields\\[1\\]"):
        blend_fields([fields[0], fields[1][:10]], smoothness=5.0)
    with pytest.raises(ValueError, match="fields"):
        blend_fields([], smoothness=5.0)


def test_synthesis_is_deterministic_for_any_thread_count() -> None:
    model = _model()
    one = synthesize(model, count=3, seed=7, threads=1)
    two = synthesize(model, count=3, seed=7, threads=2)
    assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))
    first = synthesize(model, count=1, seed=7, threads=2)
    assert np.array_equal(first[0], one[0])  # leaf n depends on the seed and n only
    other = synthesize(model, count=1, seed=8)
    assert not np.array_equal(other[0], one[0])


def test_new_leaves_are_single_leaves_in_the_exemplars_range_and_not_copies() -> None:
    model = _model()
    areas = [int((leaf[..., 3] > 0.5).sum()) for leaf in model.leaves]
    calls: list[tuple[int, int]] = []
    leaves = synthesize(model, count=8, seed=1, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(i + 1, 8) for i in range(8)]
    for leaf in leaves:
        assert leaf.dtype == np.float32 and leaf.ndim == 3 and leaf.shape[2] == 4
        assert leaf.min() >= 0.0 and leaf.max() <= 1.0
        solid = leaf[..., 3] > 0.5
        assert ndimage.label(solid)[1] == 1
        assert min(areas) <= solid.sum() <= max(areas)
        # cropped with the margin: the border rows and columns are transparent
        assert leaf[:8].max() == 0 and leaf[-8:].max() == 0 and leaf[:, :8].max() == 0 and leaf[:, -8:].max() == 0
        for ex in model.leaves:
            shape = (max(leaf.shape[0], H), max(leaf.shape[1], W))
            a, b = _centred(leaf, shape), _centred(ex, shape)
            sa, sb = a[..., 3] > 0.5, b[..., 3] > 0.5
            assert (sa & sb).sum() / (sa | sb).sum() < 0.995
            both = sa & sb
            assert np.abs(a[both, :3] - b[both, :3]).mean() > 0.01


def test_shapes_come_from_eq7() -> None:
    """Without random warps (no registration error) the shape is the Eq. 7 blend alone: it
    varies from leaf to leaf, between the exemplars' shapes."""
    model = _model()
    model = LeafModel(**{**model.__dict__, "residual": [0.0, 0.0, 0.0]})
    areas = [int((leaf[..., 3] > 0.5).sum()) for leaf in model.leaves]
    new = [int((leaf[..., 3] > 0.5).sum()) for leaf in synthesize(model, count=8, seed=1)]
    assert min(areas) < min(new) and max(new) < max(areas)
    assert np.ptp(new) > 0.1 * np.ptp(areas)


def test_layers_of_other_exemplars_show_up() -> None:
    model = _model()
    found = False
    for leaf in synthesize(model, count=12, seed=0):
        solid = leaf[..., 3] > 0.5
        rgb = leaf[solid, :3]
        yellow = (np.abs(rgb - BACKGROUNDS[1]).max(axis=1) < 0.05).mean() > 0.5
        blue = (np.abs(rgb - SPOT).max(axis=1) < 0.1).sum() >= 10
        found |= bool(yellow and blue)
    assert found


@pytest.mark.parametrize(("n_exemplars", "n_layers"), [(2, 1), (4, 2), (3, 3)])
def test_a_set_of_leaves_uses_every_mix_before_repeating_one(n_exemplars: int, n_layers: int) -> None:
    total = n_exemplars * (n_exemplars - 1) ** n_layers
    mixes = synth._mixes(n_exemplars, n_layers, 5, 2 * total + 3)
    assert all(0 <= bg < n_exemplars and bg not in layers for bg, layers in mixes)  # mixing is the point
    keys = [(bg, tuple(layers)) for bg, layers in mixes]
    assert len(set(keys[:total])) == total and len(set(keys[total : 2 * total])) == total
    # the first leaves spread over the backgrounds, and each layer over its exemplars
    assert sorted(bg for bg, _ in mixes[:n_exemplars]) == list(range(n_exemplars))
    for k in range(n_layers):
        counts = np.bincount([layers[k] for _, layers in mixes[:total]], minlength=n_exemplars)
        assert counts.max() - counts.min() <= n_exemplars - 1
    assert synth._mixes(n_exemplars, n_layers, 5, 4) == mixes[:4]  # leaf n depends on the seed and n only
    if total > 2:  # another seed deals in another order
        assert keys != [(bg, tuple(layers)) for bg, layers in synth._mixes(n_exemplars, n_layers, 6, 2 * total + 3)]


def test_mixes_beyond_the_dealt_limit_are_drawn_and_still_valid(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(synth, "MAX_DEALT", 10)
    mixes = synth._mixes(4, 2, 0, 300)
    assert all(bg not in layers for bg, layers in mixes)
    assert len({(bg, tuple(layers)) for bg, layers in mixes}) == 36  # every mix still reachable
    assert synth._mixes(4, 2, 0, 8) == mixes[:8]


def test_structural_layers_stay_and_stochastic_layers_move() -> None:
    """λ = κ: the vein is exactly one exemplar's vein in the training frame; λ = 0: it moves."""

    def off_vein(lam: float) -> list[int]:
        model = _model(lam=(lam, lam))
        spots = ndimage.binary_dilation(np.any([per[1] for per in model.masks], axis=0), iterations=4)
        moved = []
        for seed in range(6):
            rgba = straight(
                synth._training_frame(
                    model,
                    synth._mixes(3, 2, 0, seed + 1)[seed],
                    np.random.default_rng(seed),
                    [2.0, 2.0, 3.0],
                    [lam / 1.5] * 2,
                    1,
                )
            )
            vein = (np.abs(rgba[..., :3] - VEIN).max(axis=2) < 0.05) & (rgba[..., 3] > 0.5)
            assert vein.sum() > 50
            moved.append(min(int(((vein ^ per[0]) & ~spots).sum()) for per in model.masks))
        return moved

    assert max(off_vein(1.5)) == 0
    assert min(off_vein(0.0)) > 0


def test_texture_correction_is_applied_when_available(monkeypatch: pytest.MonkeyPatch) -> None:
    seen = []

    def fake(warped: np.ndarray, source: np.ndarray, field: np.ndarray, **kw: object) -> np.ndarray:
        seen.append((warped.shape, source.shape, field.shape, sorted(kw)))
        out = warped.copy()
        out[..., :3] = 0.5
        out[..., 3] = 1.0  # must not leak: the alpha stays the warped one
        return out

    plain = synthesize(_model(), seed=2)[0]
    monkeypatch.setattr(synth, "_corrector", lambda: fake)
    leaf = synthesize(_model(), seed=2)[0]
    assert seen == [((H, W, 4), (H, W, 4), (H, W, 2), ["seed", "threads"])]
    assert np.array_equal(leaf[..., 3], plain[..., 3])
    assert np.allclose(leaf[leaf[..., 3] > 0, :3], 0.5)


def test_undefined_dissimilarity_off_the_leaf_weighs_nothing() -> None:
    """``leaves.induce`` leaves D NaN off each exemplar's leaf: it must not reach a colour."""
    model = _model()
    off = [leaf[..., 3] <= 0.5 for leaf in model.background]
    nan = [[np.where(o, np.float32(np.nan), d) for d in per] for o, per in zip(off, model.dissimilarity, strict=True)]
    far = [[np.where(o, np.float32(1e4), d) for d in per] for o, per in zip(off, model.dissimilarity, strict=True)]
    with_nan = synthesize(LeafModel(**{**model.__dict__, "dissimilarity": nan}), count=3, seed=4)
    with_far = synthesize(LeafModel(**{**model.__dict__, "dissimilarity": far}), count=3, seed=4)
    assert all(np.isfinite(a).all() and np.array_equal(a, b) for a, b in zip(with_nan, with_far, strict=True))


def _with_scale(model: LeafModel, scale: list[float]) -> LeafModel:
    """The model with the analysis' per-exemplar pose scales (a field of the lead's model;
    set directly so this works with and without it)."""
    out = LeafModel(**model.__dict__)
    object.__setattr__(out, "scale", scale)
    return out


def test_pose_scales_set_the_new_leaves_size(monkeypatch: pytest.MonkeyPatch) -> None:
    """Exemplars 1 and 2 were scaled by 1/2 to the training leaf's size, so they are twice
    its size: each new leaf is resized by Eq. 7's mean coefficients over the leaf applied to
    the sizes (1, 2, 2), and its area grows by that factor squared."""
    model = _model()
    plain = synthesize(model, count=4, seed=6)
    same = synthesize(_with_scale(model, [1.0, 1.0, 1.0]), count=4, seed=6)
    assert all(np.array_equal(a, b) for a, b in zip(plain, same, strict=True))
    factors: list[float] = []
    size_factor = synth._size_factor

    def recorded(coefficients: np.ndarray, leaf: np.ndarray, sizes: np.ndarray) -> float:
        assert np.allclose(sizes, [1.0, 2.0, 2.0])
        a = coefficients[leaf].mean(axis=0)
        factors.append(size_factor(coefficients, leaf, sizes))
        assert factors[-1] == pytest.approx(1.0 + (a[1] + a[2]) / a.sum())
        return factors[-1]

    monkeypatch.setattr(synth, "_size_factor", recorded)
    big = synthesize(_with_scale(model, [1.0, 0.5, 0.5]), count=4, seed=6)
    assert len(factors) == 4
    for a, b, k in zip(plain, big, factors, strict=True):
        ratio = (b[..., 3] > 0.5).sum() / (a[..., 3] > 0.5).sum()
        assert ratio == pytest.approx(k**2, rel=0.05)
        assert ndimage.label(b[..., 3] > 0.5)[1] == 1
    with pytest.raises(ValueError, match="model: expected 3 scale values"):
        synthesize(_with_scale(model, [1.0, 0.5]))
    with pytest.raises(ValueError, match="model: expected finite positive scales"):
        synthesize(_with_scale(model, [1.0, 0.0, 1.0]))


def test_bad_input() -> None:
    model = _model()
    with pytest.raises(ValueError, match="count"):
        synthesize(model, count=0)
    with pytest.raises(ValueError, match="model: expected at least two exemplars"):
        synthesize(_model(n=1))
    with pytest.raises(TypeError, match="model"):
        synthesize("model")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="model"):
        synthesize(LeafModel(**{**model.__dict__, "lam": [1.0]}))
    with pytest.raises(TypeError, match="progress"):
        synthesize(model, progress=3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="magnitude"):
        random_warp(10, -1.0, smoothness=3.0)
    with pytest.raises(ValueError, match="smoothness"):
        random_warp(10, 1.0, smoothness=0.5)


def test_only_the_largest_leaf_is_kept() -> None:
    alpha = np.zeros((40, 60), np.float32)
    alpha[5:30, 5:30] = 1.0
    alpha[4, 5:30] = 0.3  # its soft rim stays
    alpha[2:6, 40:44] = 1.0  # a crumb of another component goes (labelled first)
    alpha[20, 50] = 0.4  # and so does a stray rim pixel far away
    out = synth._one_leaf(alpha)
    assert ndimage.label(out > 0)[1] == 1
    assert np.array_equal(out[:35, :35], alpha[:35, :35]) and out[:, 35:].max() == 0
    alpha[2:6, 40:44] = 0.0  # one solid component: stray soft pixels still go
    assert np.array_equal(synth._one_leaf(alpha), out)


SIDE = 640


def _patch_distance(leaf: np.ndarray, others: list[np.ndarray]) -> float:
    """Patch coherence of ``leaf``'s inner pixels against ``others`` laid side by side, all
    premultiplied and shrunk to a ``SIDE`` px longest side (the contact sheet uses 320 px, at which
    the test below would not see colour noise)."""
    import phloem

    def small(x: np.ndarray) -> np.ndarray:
        k = SIDE / max(x.shape[:2])
        y = cv2.resize(x, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
        return np.concatenate([y[..., :3] * y[..., 3:], y[..., 3:]], axis=2)

    parts = [small(o) for o in others]
    h = max(p.shape[0] for p in parts)
    strip = np.concatenate([np.pad(p, ((0, h - p.shape[0]), (0, 4), (0, 0))) for p in parts], axis=1)
    q = small(leaf)
    inner = cv2.erode((q[..., 3] > 0.99).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    return phloem.metrics.patch_coherence(q[..., :3], strip[..., :3], mask=inner)


def test_real_scans_give_new_single_leaves() -> None:
    """The four leaves of one ``leafarea`` scan, registered by TPS-RPM, the background layer only
    (no induction here): Eq. 7 with real inverse fields gives single leaves in the exemplars'
    area range that are not copies of any, and whose patches are as near the exemplars' as the
    exemplars' are to each other's (issue 17's coherence check)."""
    import phloem
    from phloem.leaves import extract, register
    from phloem.testing import shared_file

    scan = phloem.io.read_image(shared_file("leaves", "leafarea_A2.jpeg"))
    found = extract(scan)
    size = (max(f.shape[0] for f in found) + 40, max(f.shape[1] for f in found) + 40)
    placed = []
    for leaf in found:
        canvas = np.zeros(size + (4,), np.float32)
        y, x = (size[0] - leaf.shape[0]) // 2, (size[1] - leaf.shape[1]) // 2
        canvas[y : y + leaf.shape[0], x : x + leaf.shape[1]] = leaf
        placed.append(canvas)
    zero = np.zeros(size + (2,), np.float32)
    regs = [register(p, placed[0], threads=2) for p in placed[1:]]
    aligned = [placed[0]] + [r.warp(p) for r, p in zip(regs, placed[1:], strict=True)]
    n = len(placed)
    model = LeafModel(
        training=0,
        order=[1],
        leaves=placed,
        forward=[zero] + [r.forward for r in regs],
        inverse=[zero] + [r.inverse for r in regs],
        residual=[0.0] + [r.residual for r in regs],
        aligned=aligned,
        masks=[[] for _ in range(n)],
        dissimilarity=[[] for _ in range(n)],
        layers=[[] for _ in range(n)],
        background=aligned,
        lam=[],
        delta=[],
        objective=[],
    )
    areas = [int((p[..., 3] > 0.5).sum()) for p in placed]
    own = [_patch_distance(e, placed[:i] + placed[i + 1 :]) for i, e in enumerate(placed)]
    for leaf in synthesize(model, count=4, seed=0, threads=2):
        # New leaves are made of the exemplars' patches (figures in docs/pipelines/leaves.md).
        assert _patch_distance(leaf, placed) <= max(own)
        solid = leaf[..., 3] > 0.5
        assert ndimage.label(solid)[1] == 1
        assert min(areas) <= solid.sum() <= max(areas)
        for ex in placed:
            shape = (max(leaf.shape[0], size[0]), max(leaf.shape[1], size[1]))
            a, b = _centred(leaf, shape)[..., 3] > 0.5, _centred(ex, shape)[..., 3] > 0.5
            assert (a & b).sum() / (a | b).sum() < 0.95  # 0.82–0.91 measured
