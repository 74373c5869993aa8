"""phloem.leaves.extract: synthetic scans with planted masks, RGBA input, errors, the shared scans."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import phloem
from phloem.leaves import extract
from phloem.testing import shared_file

GREEN = (0.2, 0.45, 0.15)
PETIOLE = (0.4, 0.3, 0.1)


def _scan(
    centres: list[tuple[int, int]],
    *,
    size: tuple[int, int] = (400, 600),
    paper: tuple[float, float, float] = (0.94, 0.94, 0.92),
    shadow: float = 0.0,
    seed: int = 0,
) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Leaf polygons with a 2 px petiole on paper, with noise and dark specks. Returns the scan, each
    leaf's planted mask (blade + petiole) and each petiole's mask."""
    rng = np.random.default_rng(seed)
    h, w = size
    img = np.empty((h, w, 3), np.float32)
    img[:] = paper
    masks, petioles = [], []
    for cx, cy in centres:
        t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
        r = 1 + 0.08 * np.sin(7 * t)  # serrated outline
        pts = np.stack([cx + 28 * r * np.cos(t), cy - 60 + 60 * r * np.sin(t)], 1).round().astype(np.int32)
        if shadow:  # a soft shadow beside the leaf, `shadow` darker at its centre, same hue
            sh = np.zeros((h, w), np.float32)
            cv2.fillPoly(sh, [pts + np.array([14, 10], np.int32)], 1.0)
            sh = cv2.GaussianBlur(sh, (0, 0), 6)
            img *= (1 - shadow * sh)[..., None]
        m = np.zeros((h, w), np.uint8)
        cv2.fillPoly(m, [pts], 1)
        p = np.zeros((h, w), np.uint8)
        cv2.line(p, (cx, cy - 12), (cx + 6, cy + 40), 1, 2)  # from inside the blade
        p &= 1 - m
        masks.append((m | p) > 0)
        petioles.append(p > 0)
        img[m > 0] = GREEN
        img[p > 0] = PETIOLE
    img += rng.normal(0, 0.015, img.shape).astype(np.float32)
    for _ in range(25):  # dust specks of 1-3 px
        y, x = rng.integers(0, h), rng.integers(0, w)
        img[y : y + rng.integers(1, 4), x : x + rng.integers(1, 4)] = 0.25
    return np.clip(img, 0, 1), masks, petioles


def _placed(leaf: np.ndarray, full_mask: np.ndarray) -> np.ndarray:
    """The leaf's alpha >= 0.5 placed back in the image frame by matching its mask to the planted one."""
    m = (leaf[..., 3] >= 0.5).astype(np.float32)
    res = cv2.matchTemplate(np.pad(full_mask.astype(np.float32), 8), m, cv2.TM_SQDIFF)
    _, _, (x, y), _ = cv2.minMaxLoc(res)
    out = np.zeros((full_mask.shape[0] + 16, full_mask.shape[1] + 16), bool)
    out[y : y + m.shape[0], x : x + m.shape[1]] = m > 0
    return out[8:-8, 8:-8]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.mark.parametrize("n", [1, 2, 4])
def test_leaves_found_with_petioles_and_without_specks(n: int) -> None:
    centres = [(80 + 140 * i, 150) for i in range(n)]
    scan, masks, petioles = _scan(centres)
    leaves = extract(scan)
    assert len(leaves) == n
    for leaf, mask, pet in zip(leaves, masks, petioles, strict=True):  # reading order = left to right
        assert leaf.dtype == np.float32 and leaf.ndim == 3 and leaf.shape[2] == 4
        placed = _placed(leaf, mask)
        assert _iou(placed, mask) >= 0.95
        assert placed[pet].mean() >= 0.95  # the petiole is kept
        assert leaf[0, :, 3].max() == 0 and leaf[-1, :, 3].max() == 0  # a transparent margin
        soft = (leaf[..., 3] > 0) & (leaf[..., 3] < 1)
        assert soft.sum() > 0.2 * cv2.arcLength(cv2.findContours(mask.astype(np.uint8), 0, 2)[0][0], True)


def test_two_rows_in_reading_order() -> None:
    scan, masks, _ = _scan([(450, 100), (100, 110), (300, 300)], size=(420, 600))
    leaves = extract(scan)
    sizes = [m.sum() for m in masks]
    assert len(leaves) == 3
    # Row 1 (the two upper leaves, left to right), then row 2.
    got = [_iou(_placed(lf, masks[i]), masks[i]) for lf, i in zip(leaves, [1, 0, 2], strict=True)]
    assert min(got) >= 0.95, (got, sizes)


def test_blue_cloth() -> None:
    scan, masks, pets = _scan([(150, 150), (400, 160)], paper=(0.15, 0.35, 0.8), seed=1)
    leaves = extract(scan)
    assert len(leaves) == 2
    for leaf, mask, pet in zip(leaves, masks, pets, strict=True):
        placed = _placed(leaf, mask)
        assert _iou(placed, mask) >= 0.95 and placed[pet].mean() >= 0.95


@pytest.mark.parametrize("strength", [0.35, 0.5])
def test_soft_shadow_is_background(strength: float) -> None:
    scan, masks, _ = _scan([(200, 150)], shadow=strength, seed=2)
    (leaf,) = extract(scan)
    assert _iou(_placed(leaf, masks[0]), masks[0]) >= 0.95


def test_given_background_colour() -> None:
    scan, masks, _ = _scan([(200, 150)])
    (leaf,) = extract(scan, background=(0.94, 0.94, 0.92))
    assert _iou(_placed(leaf, masks[0]), masks[0]) >= 0.95


def test_holes_large_kept_small_filled() -> None:
    scan, masks, _ = _scan([(200, 150)])
    scan[95:110, 195:210] = 0.94  # insect damage (225 px, ~3 % of the leaf) shows the paper
    scan[130:132, 200:202] = 0.94  # a 4 px glint
    (leaf,) = extract(scan)
    placed = _placed(leaf, masks[0])
    assert not placed[98:107, 198:207].any()
    assert placed[130:132, 200:202].all()
    (filled,) = extract(scan, holes=0.1)
    assert _placed(filled, masks[0])[98:107, 198:207].all()


def test_colour_outside_alpha_is_leaf_colour() -> None:
    scan, _, _ = _scan([(200, 150)])
    (leaf,) = extract(scan)
    clear = leaf[..., 3] == 0
    assert np.isfinite(leaf).all()
    # Leaf colours, not the white paper's, under zero alpha (no fringe when composited or resized).
    far = np.abs(leaf[clear][:, :3] - np.array((0.94, 0.94, 0.92), np.float32)).max(-1) > 0.3
    assert far.mean() > 0.99


def test_rgba_input_taken_as_it_is() -> None:
    rgba = np.zeros((60, 90, 4), np.float32)
    rgba[10:30, 10:25] = (0.2, 0.5, 0.1, 1.0)
    rgba[10:30, 9, 3] = 0.3  # a soft edge, kept
    rgba[35:55, 50:80] = (0.3, 0.4, 0.1, 0.8)
    leaves = extract(rgba, margin=2)
    assert len(leaves) == 2
    a, b = leaves
    assert a.shape == (24, 20, 4) and b.shape == (24, 34, 4)
    np.testing.assert_array_equal(a[2:-2, 2:-2], rgba[10:30, 9:25])
    np.testing.assert_array_equal(b[2:-2, 2:-2], rgba[35:55, 50:80])


def test_gray_and_uint8() -> None:
    scan, masks, _ = _scan([(200, 150)])
    (leaf,) = extract((scan * 255).round().astype(np.uint8))
    assert _iou(_placed(leaf, masks[0]), masks[0]) >= 0.95
    gray = scan.mean(-1)
    assert len(extract(gray)) == 1


@pytest.mark.parametrize(
    ("image", "kwargs", "word"),
    [
        (np.full((100, 100, 3), 0.9, np.float32), {}, "image: found no leaf"),
        (np.random.default_rng(0).normal(0.9, 0.01, (100, 100, 3)).astype(np.float32), {}, "image: found no leaf"),
        (np.zeros((100, 100, 4), np.float32), {}, "image: found no leaf"),
        (np.zeros((10, 10, 5), np.float32), {}, "image:"),
        (np.zeros((10,), np.float32), {}, "image:"),
        (np.zeros((4, 4, 3), np.float32), {}, "image:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"background": (1, 1)}, "background:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"background": (1, 1, 2)}, "background:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"min_area": 2}, "min_area:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"holes": -1}, "holes:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"margin": -1}, "margin:"),
        (np.full((50, 50, 3), 0.5, np.float32), {"threshold": 0}, "threshold:"),
        (np.full((50, 50, 3), 0.2, np.float32), {"background": (1, 1, 1)}, "image: all foreground"),
    ],
)
def test_errors(image: np.ndarray, kwargs: dict[str, object], word: str) -> None:
    with pytest.raises(ValueError, match=word) as e:
        extract(image, **kwargs)  # type: ignore[arg-type]
    assert "\n" not in str(e.value)


def test_all_leaf_photo_refused() -> None:
    rng = np.random.default_rng(3)
    img = np.empty((200, 200, 3), np.float32)
    img[:] = GREEN
    img += cv2.GaussianBlur(rng.normal(0, 0.3, (200, 200)).astype(np.float32), (0, 0), 1.5)[..., None]
    with pytest.raises(ValueError, match="image: no plain background"):
        extract(np.clip(img, 0, 1))
    # A smooth leaf-only photo is indistinguishable from a blank green backdrop.
    with pytest.raises(ValueError, match="image: found no leaf"):
        extract(np.clip(np.full((100, 100, 3), GREEN, np.float32), 0, 1))


def test_dtype_refused() -> None:
    with pytest.raises(TypeError, match="image:"):
        extract(np.zeros((20, 20, 3), np.int64))


@pytest.mark.parametrize(
    ("name", "count"),
    [("A1-01", 2), ("A1-02", 1), ("A123-01", 1), ("A123-02", 2), ("A2", 4), ("A300-1", 1), ("A300-2", 2)],
)
def test_shared_scans(name: str, count: int) -> None:
    img = phloem.io.read_image(shared_file("leaves", f"leafarea_{name}.jpeg"))
    leaves = extract(img)
    assert len(leaves) == count
    frame = img.shape[0] * img.shape[1]
    for leaf in leaves:
        area = (leaf[..., 3] >= 0.5).sum()
        # Each leaf covers 4-30 % of the A4 scan and most of its (elongated) bounding box.
        assert 0.04 * frame < area < 0.3 * frame
        assert area > 0.25 * leaf.shape[0] * leaf.shape[1]


def test_faint_antialiased_petiole_kept_whole() -> None:
    # A 1.2 px pale stalk drawn at 4x and averaged down: its partly covered pixels fall below the
    # threshold, hysteresis keeps them joined to the blade.
    scan, masks, _ = _scan([(200, 150)])
    big = np.zeros((scan.shape[0] * 4, scan.shape[1] * 4), np.uint8)
    cv2.line(big, (800, 560), (944, 940), 255, 5)
    line = cv2.resize(big, scan.shape[1::-1], interpolation=cv2.INTER_AREA).astype(np.float32) / 255
    line[masks[0]] = 0
    pale = np.array((0.7, 0.68, 0.5), np.float32)
    scan = scan * (1 - line[..., None]) + pale * line[..., None]
    (leaf,) = extract(scan)
    stalk = line >= 0.6
    placed = _placed(leaf, masks[0] | stalk)
    assert placed[stalk].mean() >= 0.9
    assert placed[225:236].any()  # its tip, 90 px below the blade, is still attached


def test_feather_is_the_outer_soft_edge() -> None:
    scan, _, _ = _scan([(200, 150)])
    (soft,) = extract(scan)
    (hard,) = extract(scan, feather=0)
    ring = lambda a: ((a > 0) & (a < 0.5)).sum()  # noqa: E731
    assert ring(hard[..., 3]) < 20  # only stray pixels that hysteresis joined and matting found pale
    assert ring(soft[..., 3]) > 100


def test_full_output_gives_each_leaf_its_box_in_the_image() -> None:
    img, _, _ = _scan([(150, 150), (400, 160)], seed=1)
    res = extract(img, full_output=True)
    assert len(res.leaves) == len(res.boxes) == 2
    for leaf, (y0, y1, x0, x1) in zip(res.leaves, res.boxes):
        assert leaf.shape[:2] == (y1 - y0, x1 - x0)
        inside = cv2.erode((leaf[..., 3] == 1.0).astype(np.uint8), np.ones((11, 11), np.uint8)) > 0
        ys, xs = np.nonzero(inside)
        assert len(ys) > 1000
        # the leaf's interior (away from its re-coloured soft edge) is the scan at the box's place
        assert np.allclose(leaf[ys, xs, :3], img[ys + y0, xs + x0, :3], atol=1e-6)
    assert [a.shape for a in res.leaves] == [a.shape for a in extract(img)]
