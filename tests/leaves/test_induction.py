"""Layer induction (Assa & Cohen-Or §4, Eqs. 2–6) on synthetic leaves with planted layers.

The leaf: a green ellipse with a midrib and six side veins (pale), brown spots and pale blotches
of the veins' own colour (so colour alone cannot tell a vein from a blotch). The exemplar is the
same venation moved by a known smooth warp (up to 2 px), with blotches and spots elsewhere: the
veins are structural, the spots are not. The leaf is 160 px wide, so ε is scaled down from the
paper's 40 px (for 2 Mpx scans) to 10 px.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest
from scipy import ndimage  # type: ignore[import-untyped]

from phloem import metrics
from phloem.leaves import Induction, induce
from phloem.leaves.induction import best_threshold, liberal_layer, spatial_term

BLADE, VEIN, SPOT = (0.25, 0.55, 0.15), (0.80, 0.82, 0.45), (0.45, 0.25, 0.10)
H, W = 120, 160
EPS = 10.0


def _outline() -> np.ndarray:
    yy, xx = np.mgrid[:H, :W]
    return ((yy - H / 2) / (H / 2.3)) ** 2 + ((xx - W / 2) / (W / 2.2)) ** 2 <= 1


def _veins(width: int = 10) -> np.ndarray:
    m = np.zeros((H, W), np.uint8)
    cv2.line(m, (12, H // 2), (W - 12, H // 2), 1, width)
    for x0 in (45, 80, 115):
        cv2.line(m, (x0, H // 2), (x0 + 22, H // 2 - 35), 1, width - 2)
        cv2.line(m, (x0, H // 2), (x0 + 22, H // 2 + 35), 1, width - 2)
    return m.astype(bool) & _outline()


def _discs(rng: np.random.Generator, n: int, radius: int, avoid: np.ndarray) -> np.ndarray:
    """``n`` discs wholly on the leaf, clear of ``avoid`` by a few pixels."""
    keep_out = cv2.dilate(avoid.astype(np.uint8), np.ones((2 * radius + 5,) * 2, np.uint8)).astype(bool)
    inside = cv2.erode(_outline().astype(np.uint8), np.ones((2 * radius + 5,) * 2, np.uint8)).astype(bool)
    ys, xs = np.nonzero(inside & ~keep_out)
    m = np.zeros((H, W), np.uint8)
    for i in rng.choice(len(ys), n, replace=False):
        cv2.circle(m, (int(xs[i]), int(ys[i])), radius, 1, -1)
    return m.astype(bool) & _outline() & ~avoid


def _render(veins: np.ndarray, spots: np.ndarray, blotches: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    img = np.zeros((H, W, 4), np.float32)
    leaf = _outline()
    img[leaf] = (*BLADE, 1.0)
    img[blotches] = (*VEIN, 1.0)
    img[spots] = (*SPOT, 1.0)
    img[veins] = (*VEIN, 1.0)
    img[..., :3] = np.clip(img[..., :3] + rng.normal(0, 0.02, (H, W, 3)), 0, 1)
    img[~leaf] = 0
    return img


def _warp(mask: np.ndarray, amp: float = 2.0) -> np.ndarray:
    yy, xx = np.mgrid[:H, :W].astype(np.float32)
    dx, dy = amp * np.sin(2 * np.pi * yy / H), amp * np.cos(2 * np.pi * xx / W)
    return np.asarray(cv2.remap(mask.astype(np.float32), xx + dx, yy + dy, cv2.INTER_LINEAR) > 0.5)


def _pair(seed: int = 0) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    v_t = _veins()
    v_e = _warp(v_t)
    b_t, b_e = _discs(rng, 8, 7, v_t), _discs(rng, 8, 7, v_e)
    s_t = _discs(rng, 5, 6, v_t | b_t)
    s_e = _discs(rng, 5, 6, v_e | b_e | cv2.dilate(s_t.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool))
    return {
        "training": _render(v_t, s_t, b_t, rng),
        "exemplar": _render(v_e, s_e, b_e, rng),
        "veins": (v_t, v_e),
        "spots": (s_t, s_e),
    }


@pytest.fixture(scope="module")
def pair() -> dict[str, Any]:
    return _pair()


@pytest.fixture(scope="module")
def veins(pair: dict[str, Any]) -> Induction:
    return induce(pair["training"], pair["veins"][0], [pair["training"], pair["exemplar"]], epsilon=EPS)


def test_planted_veins_are_recovered_and_colour_alone_is_clearly_worse(pair: dict[str, Any], veins: Induction) -> None:
    t, e, (v_t, v_e) = pair["training"], pair["exemplar"], pair["veins"]
    with_f = metrics.layer_iou(veins.masks[1], v_e)
    colour = induce(t, v_t, [t, e], epsilon=EPS, kappa=0.0)
    without = metrics.layer_iou(colour.masks[1], v_e)
    assert colour.lam == 0.0
    assert with_f >= 0.8, with_f
    assert without <= with_f - 0.1, (without, with_f)
    # Colour alone takes the pale blotches far from any vein; the spatial term drops them.
    far = ~cv2.dilate(v_e.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    assert (colour.masks[1] & far).sum() > 200
    assert (veins.masks[1] & far).sum() < 0.1 * (colour.masks[1] & far).sum()


def test_structural_veins_get_a_large_lam_and_spots_a_small_one(pair: dict[str, Any], veins: Induction) -> None:
    t, e = pair["training"], pair["exemplar"]
    spots = induce(t, pair["spots"][0], [e], epsilon=EPS)
    assert veins.lam > 0.5 * 1.5, veins.lam  # the veins' liberal layers overlap by more than half
    assert spots.lam < 0.1 * 1.5, spots.lam
    # Spots are then found by colour, wherever they are on the exemplar.
    assert metrics.layer_iou(spots.masks[0], pair["spots"][1]) >= 0.7


def test_veins_thinner_than_the_window_are_still_structural() -> None:
    # No 8 × 8 window fits inside a 5 px vein, so S never falls below the printed 0.1 on it: the
    # liberal layers are the colour-only induced layers instead (see the docs), and they overlap.
    rng = np.random.default_rng(4)
    lines = np.zeros((H, W), np.uint8)
    for y in (35, 60, 85):  # parallel, so no crossing gives a window of vein alone
        cv2.line(lines, (20, y), (W - 20, y), 1, 3)
    v_t = lines.astype(bool) & _outline()
    v_e = _warp(v_t, amp=1.0)
    none = np.zeros((H, W), bool)
    t, e = _render(v_t, none, none, rng), _render(v_e, none, none, rng)
    result = induce(t, v_t, [e], epsilon=EPS)
    assert np.nanmin(result.color[0]) > 0.1
    assert result.lam > 0.5 * 1.5, result.lam
    assert metrics.layer_iou(result.masks[0], v_e) >= 0.6


def test_delta_maximises_the_objective_by_brute_force(pair: dict[str, Any], veins: Induction) -> None:
    v_t = pair["veins"][0]
    d_t = veins.dissimilarity[0]  # the training leaf was passed as exemplar 0
    got = metrics.layer_objective(d_t, v_t, veins.delta)
    assert got == pytest.approx(veins.objective, abs=1e-12)
    values = np.unique(d_t[np.isfinite(d_t)])
    candidates = np.concatenate([values, np.nextafter(values, np.float32(np.inf)), np.linspace(0, 2.5, 400)])
    best = max(metrics.layer_objective(d_t, v_t, float(x)) for x in candidates)
    assert veins.objective == pytest.approx(best, abs=1e-12)
    # The training leaf's own induced layer is the best reproduction found.
    assert metrics.layer_iou(veins.masks[0], v_t) == pytest.approx(veins.objective, abs=1e-12)
    assert 0.85 <= veins.objective <= 1.0


def test_best_threshold_splits_ties_and_separates_adjacent_floats() -> None:
    leaf = np.ones((1, 6), bool)
    layer = np.array([[True, True, False, True, False, False]])
    d = np.array([[0.1, 0.1, 0.3, 0.2, 0.5, 0.5]], np.float32)
    delta, obj = best_threshold(d, layer, leaf)
    assert obj == 1.0 and 0.2 < delta <= 0.3 and delta == pytest.approx(0.25)
    # Equal values are never split, even where splitting would score better.
    delta, obj = best_threshold(
        np.array([[0.1, 0.1, 0.4]], np.float32), np.array([[True, False, False]]), np.ones((1, 3), bool)
    )
    assert obj == 0.5 and 0.1 < delta <= 0.4
    # Two values one float32 step apart still get a threshold between them.
    a = np.float32(0.5)
    b = np.nextafter(a, np.float32(1))
    delta, obj = best_threshold(np.array([[a, b]], np.float32), np.array([[True, False]]), np.ones((1, 2), bool))
    assert obj == 1.0 and a < np.float32(delta) <= b


def test_spatial_term_is_eq3_with_the_training_separability() -> None:
    layer = np.zeros((5, 9), bool)
    layer[2, 0] = True
    d = ndimage.distance_transform_edt(~layer)
    s_t = np.tile(np.linspace(0.0, 1.0, 9, dtype=np.float32), (5, 1))
    s_t[2, 0] = 1.0  # a layer pixel unlike its own layer: F is still 1 there
    leaf = np.ones((5, 9), bool)
    leaf[:, 7:] = False  # off the training leaf: S^t of the nearest leaf pixel (column 6)
    s_t[:, 7:] = np.nan
    f = spatial_term(d, s_t, leaf, 4.0)
    filled = s_t.copy()
    filled[:, 7:] = s_t[:, 6:7]
    with np.errstate(divide="ignore", invalid="ignore"):
        want = np.exp(-(d**2) / (16.0 * (1.0 - filled.astype(np.float64))))
    want[layer] = 1.0
    np.testing.assert_allclose(f, want, rtol=1e-12, atol=0)
    assert f[2, 1] > 0.9 and f[2, 6] < f[2, 1]  # well separated (S^t near 1): a narrower falloff
    s_t[:, 1:7] = 1.0
    assert (spatial_term(d, s_t, leaf, 4.0)[:, 1:] == 0.0).all()  # S^t = 1: no width, F = 0 off the layer


def test_liberal_layer_is_eq6_read_as_distance_below_two_epsilon() -> None:
    s = np.array([[0.05, 0.05, 0.05, 0.1, np.nan, 0.25]], np.float32)
    d = np.array([[0.0, 19.9, 20.1, 0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(liberal_layer(s, d, 10.0), [[True, True, False, False, False, False]])
    np.testing.assert_array_equal(liberal_layer(s, d, 10.0, 0.3), [[True, True, False, True, False, True]])


def test_maps_and_their_relations(pair: dict[str, Any], veins: Induction) -> None:
    e = pair["exemplar"]
    leaf = e[..., 3] > 0.5
    d, s, f = veins.dissimilarity[1], veins.color[1], veins.spatial[1]
    for m in (d, s, f):
        assert m.shape == (H, W) and m.dtype == np.float32
        assert np.isfinite(m[leaf]).all() and np.isnan(m[~leaf]).all()
    np.testing.assert_allclose(d[leaf], (veins.lam * (1 - f) + s)[leaf], atol=1e-6)
    assert f[pair["veins"][0] & leaf].min() == 1.0  # F is 1 on the user's layer
    assert f[leaf].min() >= 0.0 and f[leaf].max() <= 1.0
    # F falls with the distance from the layer (at most the Gaussian of width ε): far pixels are near 0.
    dist = ndimage.distance_transform_edt(~pair["veins"][0])
    far = leaf & (dist > 2 * EPS)
    assert far.sum() > 300 and f[far].max() <= np.exp(-4) + 1e-6
    assert (f[leaf] <= np.exp(-(dist[leaf] ** 2) / EPS**2) + 1e-6).all()
    np.testing.assert_array_equal(veins.masks[1], leaf & (d < np.float32(veins.delta)))
    # Inside the training leaf F is Eq. 3 with the training leaf's own S^t (exemplar 0 here).
    s_t = veins.color[0].astype(np.float64)
    both = leaf & np.isfinite(s_t)
    with np.errstate(divide="ignore", invalid="ignore"):
        want = np.exp(-(dist**2) / (EPS**2 * (1.0 - s_t)))
    want[pair["veins"][0]] = 1.0
    np.testing.assert_allclose(f[both], want[both], atol=1e-6)


def test_passing_the_training_leaf_as_an_exemplar_changes_nothing(pair: dict[str, Any], veins: Induction) -> None:
    alone = induce(pair["training"], pair["veins"][0], [pair["exemplar"]], epsilon=EPS)
    assert alone.lam == veins.lam and alone.delta == veins.delta and alone.objective == veins.objective
    np.testing.assert_array_equal(alone.masks[0], veins.masks[1])
    np.testing.assert_array_equal(alone.dissimilarity[0], veins.dissimilarity[1])


def test_one_and_two_threads_agree() -> None:
    p = _pair(seed=3)
    one = induce(p["training"], p["veins"][0], [p["exemplar"]], epsilon=EPS, threads=1, seed=5)
    two = induce(p["training"], p["veins"][0], [p["exemplar"]], epsilon=EPS, threads=2, seed=5)
    assert (one.lam, one.delta, one.objective) == (two.lam, two.delta, two.objective)
    for a, b in zip(
        [*one.masks, *one.dissimilarity, *one.color, *one.spatial],
        [*two.masks, *two.dissimilarity, *two.color, *two.spatial],
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)


def _bad(pair: dict[str, Any], **over: Any) -> dict[str, Any]:
    args: dict[str, Any] = {
        "training": pair["training"],
        "layer": pair["veins"][0],
        "exemplars": [pair["exemplar"]],
    }
    args.update(over)
    return args


@pytest.mark.parametrize(
    ("over", "error", "message"),
    [
        ({"training": np.zeros((H, W, 3), np.float32)}, ValueError, r"^training: expected an RGBA leaf"),
        ({"training": np.zeros((H, W, 4), np.float32)}, ValueError, r"^training: the leaf has no pixels"),
        ({"layer": np.zeros((H, W + 1), bool)}, ValueError, r"^layer: expected shape"),
        ({"layer": np.zeros((H, W), bool)}, ValueError, r"^layer: the layer has no pixels"),
        ({"layer": np.ones((H, W), bool)}, ValueError, r"^layer: \d+ pixel\(s\) lie off the training leaf"),
        ({"exemplars": []}, ValueError, r"^exemplars: expected at least one"),
        ({"exemplars": np.zeros((2, H, W, 4), np.float32)}, TypeError, r"^exemplars: expected a list"),
        ({"exemplars": [np.zeros((H, W + 2, 4), np.float32)]}, ValueError, r"^exemplars\[0\]: expected shape"),
        ({"exemplars": [np.zeros((H, W, 4), np.float32)]}, ValueError, r"^exemplars\[0\]: the leaf has no pixels"),
        ({"epsilon": 0.0}, ValueError, r"^epsilon: expected a finite value > 0"),
        ({"kappa": -1.0}, ValueError, r"^kappa: expected a finite value >= 0"),
        ({"window": 0}, ValueError, r"^window:"),
        ({"n_bins": 1}, ValueError, r"^n_bins:"),
        ({"seed": -1}, ValueError, r"^seed:"),
    ],
)
def test_bad_input_gives_one_line_errors(pair: dict[str, Any], over: dict[str, Any], error: type, message: str) -> None:
    args = _bad(pair, **over)
    with pytest.raises(error, match=message) as info:
        induce(args.pop("training"), args.pop("layer"), args.pop("exemplars"), **args)
    assert "\n" not in str(info.value)


def test_real_spots_are_found_by_colour_with_a_small_lam() -> None:
    """Optional, on a shared scan: the orange leaf-miner trails of two leaves of one species."""
    import phloem
    from phloem.leaves import extract, register
    from phloem.testing import shared_file

    scan = phloem.io.read_image(shared_file("leaves", "leafarea_A300-2.jpeg"))
    leaves = extract(scan)
    h, w = max(x.shape[0] for x in leaves) + 40, max(x.shape[1] for x in leaves) + 40

    def place(leaf: np.ndarray) -> np.ndarray:
        canvas = np.zeros((h, w, 4), np.float32)
        y, x = (h - leaf.shape[0]) // 2, (w - leaf.shape[1]) // 2
        canvas[y : y + leaf.shape[0], x : x + leaf.shape[1]] = leaf
        return canvas

    def trails(leaf: np.ndarray) -> np.ndarray:  # a colour rule that sees the orange, not the green
        m = (leaf[..., 3] > 0.5) & (leaf[..., 0] > leaf[..., 1] + 0.04) & (leaf[..., 0] > 0.25)
        return cv2.morphologyEx(m.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)).astype(bool)

    training, moving = place(leaves[0]), place(leaves[1])
    aligned = register(moving, training).warp(moving)
    result = induce(training, trails(training), [aligned], threads=2)
    assert result.lam < 0.15, result.lam  # trails lie in different places on each leaf
    assert result.objective >= 0.6
    assert metrics.layer_iou(result.masks[0], trails(aligned)) >= 0.6
