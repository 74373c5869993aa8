"""phloem.trees.contours: the overall contour, pin points, resampling and the simplified contour (§4.2, §4.4-4.6)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phloem import trees


def _chords(cr: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(np.vstack([cr, cr[:1]]), axis=0), axis=1)


@pytest.fixture(scope="module")
def prepared(disk_tree):
    img, _ = disk_tree()
    norm = trees.normalize(img, size=512)
    c = trees.contour(norm)
    trunk = trees.segment(norm)
    return norm, c, trunk, trees.pin_points(c, trunk)


def test_contour_longest_exterior_ccw_on_boundary():
    m = np.zeros((120, 160), np.uint8)
    cv2.circle(m, (50, 60), 40, 1, -1)  # big blob...
    # ...with a star-shaped hole whose outline (an interior contour) is longer than the disk's
    star = [
        (50 + r * np.cos(a), 60 + r * np.sin(a))
        for a, r in zip(np.linspace(0, 2 * np.pi, 24, endpoint=False), [34, 6] * 12, strict=True)
    ]
    cv2.fillPoly(m, [np.round(star).astype(np.int32)], 0)
    cv2.rectangle(m, (110, 20), (150, 100), 1, -1)  # second, smaller blob (perimeter 160)
    mask = m > 0
    c = trees.contour(mask)
    assert trees.signed_area(c) > 0
    # It is the big disk's outline: centred on it and about 2*pi*40 long.
    assert np.allclose(c.mean(axis=0), (50, 60), atol=1.0)
    per = np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum()
    assert 220 < per < 270
    # Every point is an opaque pixel with a transparent 4-neighbour.
    xi, yi = c[:, 0].astype(int), c[:, 1].astype(int)
    assert mask[yi, xi].all()
    padded = np.pad(mask, 1)
    interior = padded[yi, xi + 1] & padded[yi + 2, xi + 1] & padded[yi + 1, xi] & padded[yi + 1, xi + 2]
    assert not interior.any()


def test_contour_ccw_is_screen_ccw(disk_tree):
    # Screen-CCW from the bottom point goes right first: x grows just after the lowest point.
    img, _ = disk_tree()
    c = trees.contour(img)
    b = int(np.argmax(c[:, 1]))
    assert c[(b + 3) % len(c), 0] > c[b, 0] or c[(b + 3) % len(c), 1] < c[b, 1]
    assert trees.signed_area(c) > 0
    assert trees.signed_area(c[::-1]) < 0


def test_contour_accepts_rgba_and_threshold_and_errors():
    img = np.zeros((20, 20, 4), np.float32)
    img[5:15, 5:15, 3] = 0.4
    with pytest.raises(ValueError, match=r"^alpha: .*empty"):
        trees.contour(img)
    assert len(trees.contour(img, alpha_threshold=0.3)) == 36
    with pytest.raises(ValueError, match=r"^alpha"):
        trees.contour(np.ones((5, 5, 3), np.float32))


def test_pin_points_position_and_order(prepared):
    _, c, trunk, (b, l_, r) = prepared
    n = len(c)
    # B is the lowest point, in the middle of the trunk's foot.
    assert c[b, 1] == c[:, 1].max()
    xs = c[c[:, 1] == c[:, 1].max(), 0]
    assert abs(c[b, 0] - np.median(xs)) <= 1
    # L on the left, R on the right, both at the crown baseline just above the trunk.
    top = np.flatnonzero(trunk.any(axis=1))[0]
    assert c[l_, 0] < c[b, 0] < c[r, 0]
    assert abs(c[l_, 1] - (top - 1)) <= 1 and abs(c[r, 1] - (top - 1)) <= 1
    # Counter-clockwise from B: R comes first, then L.
    assert (r - b) % n < (l_ - b) % n


def test_pin_points_without_trunk(prepared):
    _, c, trunk, _ = prepared
    b, l_, r = trees.pin_points(c, np.zeros_like(trunk))
    assert b == l_ == r


def test_resample_counts_pins_and_uniform_chords(prepared):
    _, c, _, (b, l_, r) = prepared
    cr = trees.resample(c, (b, l_, r))
    assert cr.shape == (2000, 2)
    assert np.array_equal(cr[0], c[r]) and np.array_equal(cr[1600], c[l_]) and np.array_equal(cr[1800], c[b])
    d = _chords(cr)
    for lo, hi in ((0, 1600), (1600, 1800), (1800, 2000)):
        seg = d[lo:hi]
        # Equal chords within the segment, the last gap (to the next pin) included.
        assert seg.max() / seg.min() < 1.5, (lo, seg.min(), seg.max())
        assert np.median(seg) > 0
    assert trees.signed_area(cr) > 0


def test_resample_jagged_contour_exact_count_no_repeats():
    # A disk with thin spokes: the equal-chord walk skips a spoke and comes one point short at
    # n=50; the missing point must still be a new point on the contour.
    rng = np.random.default_rng(1)
    m = np.zeros((200, 200), np.uint8)
    cv2.circle(m, (100, 100), 60, 1, -1)
    for a in rng.uniform(0, 2 * np.pi, 40):
        cv2.line(m, (100, 100), (int(100 + 90 * np.cos(a)), int(100 + 90 * np.sin(a))), 1, 1)
    c = trees.contour(m > 0)
    for n in (50, 100, 300):
        cr = trees.resample(c, (0, 0, 0), split=(n, 1, 1))
        d = _chords(cr[:n])[:-1]
        assert cr.shape == (n + 2, 2) and d.min() > 0.5
        assert np.percentile(d, 95) / np.percentile(d, 5) < 1.01


def test_resample_split_and_errors(prepared):
    _, c, _, pins = prepared
    cr = trees.resample(c, pins, split=(50, 7, 9))
    assert cr.shape == (66, 2)
    with pytest.raises(ValueError, match=r"^pins"):
        trees.resample(c, (0, 1, len(c)))
    with pytest.raises(ValueError, match=r"^split"):
        trees.resample(c, pins, split=(10, 0, 5))
    with pytest.raises(TypeError, match=r"^pins"):
        trees.resample(c, 3)  # type: ignore[arg-type]


def test_resample_no_trunk_gives_whole_loop_to_crown(prepared):
    _, c, _, (b, _, _) = prepared
    cr = trees.resample(c, (b, b, b))
    assert np.all(cr[1600:] == c[b])
    per = np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum()
    d = _chords(cr)[:1599]
    assert abs(d.sum() - per) / per < 0.05


def test_simplify_dilates_and_has_m_points():
    mask = np.zeros((100, 100), bool)
    cv2.circle(mask.view(np.uint8), (50, 50), 30, 1, -1)
    cs = trees.simplify(mask, m=100, dilation=8)
    assert cs.shape == (100, 2)
    r = np.linalg.norm(cs - 50, axis=1)
    assert np.all(r > 37) and np.all(r < 30 + 8 * np.sqrt(2) + 0.5)  # 8 dilations by a 3x3 square
    d = _chords(cs)
    assert d.max() / d.min() < 1.5
    assert trees.signed_area(cs) > 0
    with pytest.raises(ValueError, match=r"^mask"):
        trees.simplify(np.zeros((5, 5), bool))
