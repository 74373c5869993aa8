"""The colour term S of layer induction (Assa & Cohen-Or, Eq. 1) against POT's exact EMD."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import metrics
from phloem.leaves import color, color_distance

ot = pytest.importorskip("ot")

COLOURS = np.array(
    [[0.2, 0.5, 0.1], [0.3, 0.6, 0.2], [0.8, 0.8, 0.3], [0.5, 0.3, 0.1], [0.9, 0.2, 0.2], [0.1, 0.2, 0.6]],
    np.float32,
)


def _leaf(h: int = 40, w: int = 56, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Blobs of six colours (fewer than the palette, so the palette is exactly these) and a mask."""
    rng = np.random.default_rng(seed)
    idx = ((np.arange(h)[:, None] // 9 + np.arange(w)[None, :] // 11) % 4).astype(int)
    noise = rng.random((h, w)) < 0.15
    idx[noise] = rng.integers(0, len(COLOURS), noise.sum())
    yy, xx = np.mgrid[:h, :w]
    mask = ((yy - h / 2) / (h / 2.1)) ** 2 + ((xx - w / 2) / (w / 2.1)) ** 2 <= 1
    return COLOURS[idx], mask


def _reference(image: np.ndarray, mask: np.ndarray, layer: np.ndarray, points: list[tuple[int, int]]) -> list[float]:
    """S at `points` straight from the definition, with ot.emd2 as the transport solver."""
    lab = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2Lab).astype(np.float64)
    pal, inv = np.unique(lab.reshape(-1, 3)[(mask | layer).ravel()], axis=0, return_inverse=True)
    labels = np.full(mask.size, -1)
    labels[(mask | layer).ravel()] = inv.ravel()
    labels = labels.reshape(mask.shape)
    ground = np.sqrt(((pal[:, None] - pal[None]) ** 2).sum(-1))
    target = np.bincount(labels[layer], minlength=len(pal)).astype(np.float64)
    target /= target.sum()
    out = []
    for y, x in points:
        win = labels[max(y - 4, 0) : y + 4, max(x - 4, 0) : x + 4]
        win = win[win >= 0]
        if not mask[y, x]:
            out.append(np.nan)
            continue
        hist = np.bincount(win, minlength=len(pal)).astype(np.float64)
        out.append(float(ot.emd2(hist / hist.sum(), target, ground)) / ground.max())
    return out


def test_the_map_agrees_with_pot_on_sampled_pixels() -> None:
    image, mask = _leaf()
    layer = np.zeros(mask.shape, bool)
    layer[14:24, 20:34] = True
    got = color_distance(image, layer, mask=mask, threads=2)
    assert got.shape == mask.shape and got.dtype == np.float32
    rng = np.random.default_rng(0)
    points = [(int(y), int(x)) for y, x in zip(rng.integers(0, 40, 150), rng.integers(0, 56, 150), strict=True)]
    want = _reference(image, mask, layer, points)
    for (y, x), w in zip(points, want, strict=True):
        if np.isnan(w):
            assert np.isnan(got[y, x])
        else:
            assert abs(float(got[y, x]) - w) < 1e-6, (y, x)
    inside = got[mask]
    assert np.isfinite(inside).all() and inside.min() >= 0 and inside.max() <= 1


def test_a_window_of_the_layers_colours_is_a_match() -> None:
    image = np.tile(COLOURS[0], (24, 24, 1))
    image[:, 12:] = COLOURS[4]
    layer = np.zeros((24, 24), bool)
    layer[:, :12] = True
    s = color_distance(image, layer)
    assert s[:, :7].max() < 1e-6  # windows wholly in the layer's colour
    assert s[:, 17:].min() > 0.99  # windows wholly in the other colour: all mass moves the whole way


def test_a_separate_reference_supplies_the_layer() -> None:
    image, mask = _leaf(seed=2)
    ref, _ = _leaf(seed=3)
    layer = np.zeros(mask.shape, bool)
    layer[5:15, 5:15] = True
    got = color_distance(image, layer, reference=ref, mask=mask)
    lab_ref = cv2.cvtColor(np.ascontiguousarray(ref), cv2.COLOR_RGB2Lab)
    # The same layer read off the image instead describes different colours.
    assert not np.allclose(np.nan_to_num(got), np.nan_to_num(color_distance(image, layer, mask=mask)))
    assert lab_ref.shape[:2] == mask.shape


def test_the_result_is_the_same_for_one_and_two_threads() -> None:
    rng = np.random.default_rng(5)
    image = rng.random((90, 70, 3)).astype(np.float32)  # many colours: the k-means palette runs
    image[30:60] *= 0.4
    layer = np.zeros((90, 70), bool)
    layer[35:50, 10:40] = True
    one = color_distance(image, layer, threads=1, seed=3)
    two = color_distance(image, layer, threads=2, seed=3)
    np.testing.assert_array_equal(one, two)
    assert np.isfinite(one).all()


def _nearest_numpy(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """The NumPy assignment the Rust one replaced: a running minimum of cc − 2 ⟨p, c⟩ in float32."""
    c = centres.astype(np.float32)
    cc = (c**2).sum(1)
    x, y, z = (np.ascontiguousarray(points[:, d], dtype=np.float32) for d in range(3))
    best = np.full(len(points), np.inf, np.float32)
    idx = np.zeros(len(points), np.int32)
    for k in range(len(c)):
        d = cc[k] - 2.0 * (x * c[k, 0] + y * c[k, 1] + z * c[k, 2])
        closer = d < best
        best[closer] = d[closer]
        idx[closer] = k
    return idx


def test_palette_assignment_equals_the_numpy_expression_bit_for_bit() -> None:
    rng = np.random.default_rng(8)
    centres = rng.uniform([0, -80, -80], [100, 80, 80], (16, 3))
    centres[9] = centres[4]  # a repeated colour: the first wins
    # Random colours, the centres themselves and midpoints of pairs (near-ties, where the order
    # of the float32 operations decides).
    mid = (centres[:, None] + centres[None]).reshape(-1, 3) / 2
    points = np.concatenate([rng.uniform([0, -90, -90], [100, 90, 90], (30_000, 3)), centres, mid])
    points = points.astype(np.float32)
    want = _nearest_numpy(points, centres)
    assert 9 not in want
    for threads in (1, 2):
        np.testing.assert_array_equal(color._nearest(points, centres, threads), want)


def test_lab_of_the_leaf_pixels_equals_converting_the_whole_image() -> None:
    rng = np.random.default_rng(9)
    image = rng.random((61, 83, 4)).astype(np.float32)
    image[:5] = 0.0
    image[-5:] = 1.0
    image[5:9] *= 1.4  # out of range: both clip
    mask = rng.random((61, 83)) < 0.4
    full = color._lab(image)
    np.testing.assert_array_equal(color._lab_of(image, mask), full[mask])
    gray = np.ascontiguousarray(image[..., :2])  # gray + alpha: the gray is repeated
    full = color._lab(gray)
    np.testing.assert_array_equal(color._lab_of(gray, mask), full[mask])


def test_metrics_emd_agrees_with_pot() -> None:
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 16, 32):
        pts = rng.random((n, 3)) * 50
        ground = np.sqrt(((pts[:, None] - pts[None]) ** 2).sum(-1))
        a = rng.random(n) * (rng.random(n) < 0.7)
        b = rng.random(n)
        a[0] += 0.1
        want = float(ot.emd2(a / a.sum(), b / b.sum(), ground))
        assert abs(metrics.emd(a, b, ground) - want) < 1e-6
        top = ground.max()
        assert abs(metrics.emd(a, b, ground, normalized=True) - (want / top if top > 0 else 0.0)) < 1e-6


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"layer_mask": np.zeros((20, 20), bool)}, "layer_mask: the layer has no pixels"),
        ({"layer_mask": np.ones((20, 21), bool)}, "layer_mask: expected shape"),
        ({"mask": np.zeros((20, 20), bool)}, "mask: the leaf has no pixels"),
        ({"mask": np.ones((3, 20), bool)}, "mask: expected shape"),
        ({"window": 0}, "window: expected an integer >= 1"),
        ({"n_bins": 1}, "n_bins: expected 2 to 32"),
        ({"n_bins": 33}, "n_bins: expected 2 to 32"),
        ({"image": np.zeros((0, 20, 3))}, "image: expected a non-empty image"),
    ],
)
def test_bad_input_is_a_one_line_error(kwargs: dict, message: str) -> None:
    args = {"image": np.random.default_rng(0).random((20, 20, 3)), "layer_mask": np.ones((20, 20), bool)} | kwargs
    with pytest.raises(ValueError, match=message) as e:
        color_distance(args.pop("image"), args.pop("layer_mask"), **args)
    assert "\n" not in str(e.value)


def test_bad_histograms_are_one_line_errors() -> None:
    g = np.array([[0.0, 1.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="hist_a: the histogram is empty"):
        metrics.emd([0.0, 0.0], [1.0, 1.0], g)
    with pytest.raises(ValueError, match="ground: expected shape"):
        metrics.emd([1.0, 0.0], [1.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="hist_b: expected finite"):
        metrics.emd([1.0, 0.0], [-1.0, 1.0], g)
